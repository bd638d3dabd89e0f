//! Sample streams as text: whitespace- or newline-separated decimal numbers, the format a
//! renderer's per-pixel dump is easiest to write. Read in blocks so a file of any length is
//! evaluated in constant memory; every error names the file and line.

use crate::error::{Error, Result};
use std::io::BufRead;

/// Samples handed to the callback at a time.
pub const BLOCK: usize = 4096;

/// Reads every sample of `reader` (named `name` in errors) and hands them on in blocks of at
/// most [`BLOCK`], in order. Returns the number of samples read.
pub fn for_each_block(
    name: &str,
    mut reader: impl BufRead,
    mut on_block: impl FnMut(&[f64]) -> Result<()>,
) -> Result<u64> {
    let mut line = String::new();
    let mut block = Vec::with_capacity(BLOCK);
    let (mut line_no, mut index) = (0usize, 0u64);
    loop {
        line.clear();
        let read = reader
            .read_line(&mut line)
            .map_err(|e| Error::io(name, &e))?;
        if read == 0 {
            break;
        }
        line_no += 1;
        for token in line.split_whitespace() {
            let value: f64 = token.parse().map_err(|_| Error::MalformedNumber {
                file: name.to_string(),
                line: line_no,
                token: token.to_string(),
            })?;
            if !(value >= 0.0 && value.is_finite()) {
                return Err(Error::InvalidSampleInFile {
                    file: name.to_string(),
                    line: line_no,
                    index,
                    value,
                });
            }
            block.push(value);
            index += 1;
            if block.len() == BLOCK {
                on_block(&block)?;
                block.clear();
            }
        }
    }
    if !block.is_empty() {
        on_block(&block)?;
    }
    Ok(index)
}

/// Reads a whole stream into memory.
pub fn read_all(name: &str, reader: impl BufRead) -> Result<Vec<f64>> {
    let mut all = Vec::new();
    for_each_block(name, reader, |b| {
        all.extend_from_slice(b);
        Ok(())
    })?;
    Ok(all)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_mixed_separators_and_names_bad_tokens() {
        let xs = read_all("a.txt", "0.6 1.5\n0\n\n 2.2\t4.8 3.5e2\n4.1".as_bytes()).unwrap();
        assert_eq!(xs, vec![0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1]);
        let e = read_all("a.txt", "1\n2 x3\n".as_bytes()).unwrap_err();
        assert_eq!(e.to_string(), "a.txt:2: malformed number 'x3'");
        let e = read_all("-", "1\n2\n-3".as_bytes()).unwrap_err();
        assert_eq!(e.to_string(), "-:3: invalid sample at index 2: -3");
        let e = read_all("f", "1 nan".as_bytes()).unwrap_err();
        assert_eq!(e.to_string(), "f:1: invalid sample at index 1: NaN");
    }

    #[test]
    fn long_streams_arrive_in_ordered_blocks() {
        let text: String = (0..10_000).map(|i| format!("{i}\n")).collect();
        let mut seen = Vec::new();
        let n = for_each_block("t", text.as_bytes(), |b| {
            assert!(b.len() <= BLOCK);
            seen.extend_from_slice(b);
            Ok(())
        })
        .unwrap();
        assert_eq!(n, 10_000);
        assert!(seen.iter().enumerate().all(|(i, &x)| x == i as f64));
    }
}
