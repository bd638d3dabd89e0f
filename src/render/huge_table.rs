//! Tables read at random places, kept on transparent huge pages.
//!
//! Why: the living room's sky is 134 MB of environment-map cells and 16 MB of alias buckets, and
//! each draw reads one of each at a random place. With 4 KB pages such a read misses the TLB
//! as well as the caches, and the page walk's own reads miss too; 2 MB pages cover the tables
//! with a few dozen TLB entries. On Linux a table is an anonymous mapping advised
//! `MADV_HUGEPAGE`, which the kernel honours where transparent huge pages are `always` or
//! `madvise` (the default of most distributions); elsewhere, or when refused, it is ordinary
//! memory. What a table holds never depends on it.

use crate::error::{Error, Result};
use bytemuck::Pod;
use memmap2::MmapMut;
use std::fmt;
use std::marker::PhantomData;
use std::ops::{Deref, DerefMut};

/// A fixed-length array of plain-data items on its own (huge-page advised) mapping.
pub struct HugeTable<T> {
    /// `None` for an empty table (a mapping cannot be empty).
    map: Option<MmapMut>,
    items: PhantomData<T>,
}

impl<T: Pod> HugeTable<T> {
    /// `len` all-zero items; `what` names the table in an error (the mapping failing means the
    /// machine is out of memory).
    pub fn zeroed(len: usize, what: &str) -> Result<Self> {
        let bytes = len
            .checked_mul(size_of::<T>())
            .ok_or_else(|| Error::param("table length", len, format!("{what}: too large")))?;
        let map = if bytes == 0 {
            None
        } else {
            let map = MmapMut::map_anon(bytes).map_err(|e| Error::io(what, &e))?;
            // Only a hint: a kernel without transparent huge pages refuses it, and the table
            // works the same on small pages.
            #[cfg(target_os = "linux")]
            let _ = map.advise(memmap2::Advice::HugePage);
            Some(map)
        };
        Ok(HugeTable {
            map,
            items: PhantomData,
        })
    }

    /// A table holding a copy of `items`.
    pub fn from_slice(items: &[T], what: &str) -> Result<Self> {
        let mut table = Self::zeroed(items.len(), what)?;
        table.copy_from_slice(items);
        Ok(table)
    }
}

impl<T> Default for HugeTable<T> {
    fn default() -> Self {
        HugeTable {
            map: None,
            items: PhantomData,
        }
    }
}

impl<T: Pod> Deref for HugeTable<T> {
    type Target = [T];

    #[inline(always)]
    fn deref(&self) -> &[T] {
        match &self.map {
            // A mapping is page-aligned and a whole number of items long, so the cast cannot
            // fail.
            Some(map) => bytemuck::cast_slice(&map[..]),
            None => &[],
        }
    }
}

impl<T: Pod> DerefMut for HugeTable<T> {
    #[inline(always)]
    fn deref_mut(&mut self) -> &mut [T] {
        match &mut self.map {
            Some(map) => bytemuck::cast_slice_mut(&mut map[..]),
            None => &mut [],
        }
    }
}

impl<T: Pod> Clone for HugeTable<T> {
    /// A copy on a mapping of its own. Panics only where allocating the copy would abort
    /// anyway (out of memory), as cloning a `Vec` does.
    fn clone(&self) -> Self {
        Self::from_slice(self, "cloned table").expect("memory for a copy of a table")
    }
}

impl<T: Pod> fmt::Debug for HugeTable<T> {
    /// The length only: the contents run to megabytes.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("HugeTable")
            .field("len", &self.len())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Holds what was written, item by item, at every length including 0; a copy is equal and
    /// independent.
    #[test]
    fn holds_its_items() {
        for len in [0usize, 1, 3, 4096, 300_000] {
            let items: Vec<[u32; 2]> = (0..len as u32).map(|i| [i, i ^ 0xdead]).collect();
            let table = HugeTable::from_slice(&items, "test table").expect("mapping");
            assert_eq!(&table[..], &items[..]);
            let mut copy = table.clone();
            if len > 0 {
                copy[0] = [7, 7];
                assert_eq!(table[0], items[0]);
            }
            assert_eq!(copy.len(), len);
        }
        assert!(HugeTable::<f32>::default().is_empty());
    }
}
