//! Random numbers of a render: every number is a pure function of
//! (seed, pixel, sample index, dimension), so an image is bit-identical for any thread count,
//! tile order or checkpoint schedule (pbrt-v4's independent sampler works the same way).

use glam::Vec2;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro128PlusPlus;

/// SplitMix64's finaliser: a bijective 64-bit mix, so distinct keys give distinct streams.
#[inline]
fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The streams of one pixel's samples: the part of the key common to them mixed once, not
/// once per sample.
#[derive(Debug, Clone, Copy)]
pub struct PixelStreams {
    key: u64,
}

impl PixelStreams {
    /// The streams of pixel `pixel` (row-major index) under `seed`.
    #[inline]
    pub fn new(seed: u64, pixel: u64) -> Self {
        PixelStreams {
            key: mix64(mix64(seed) ^ pixel),
        }
    }

    /// [`SampleStream::new`]`(seed, pixel, index)`.
    #[inline]
    pub fn sample(&self, index: u64) -> SampleStream {
        SampleStream {
            rng: Xoshiro128PlusPlus::seed_from_u64(mix64(self.key ^ index)),
        }
    }
}

/// The stream of one camera sample; dimension `d` is the `d`-th number drawn from it.
#[derive(Debug, Clone)]
pub struct SampleStream {
    rng: Xoshiro128PlusPlus,
}

impl SampleStream {
    /// The stream of sample `index` of pixel `pixel` (row-major index) under `seed`.
    #[inline]
    pub fn new(seed: u64, pixel: u64, index: u64) -> Self {
        PixelStreams::new(seed, pixel).sample(index)
    }

    /// The next number, uniform on `[0, 1)` with 24 random bits (every value is exact in f32).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        (self.rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// The next two numbers.
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let x = self.next_1d();
        Vec2::new(x, self.next_1d())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pins the streams themselves: every image, reference file and checkpoint depends on
    /// them, so a change of the key mixing or of the generator's seeding must fail here.
    #[test]
    fn streams_are_pinned() {
        // The first three numbers of seed 1, pixel 2, sample 3: the same as before
        // `PixelStreams` (renders of all 23 test scenes identical before and after it).
        let pinned = [1020741088, 1059707464, 1055311362];
        let mut r = SampleStream::new(1, 2, 3);
        assert_eq!(
            [r.next_1d(), r.next_1d(), r.next_1d()].map(f32::to_bits),
            pinned
        );
        let mut p = PixelStreams::new(1, 2).sample(3);
        assert_eq!(
            [p.next_1d(), p.next_1d(), p.next_1d()].map(f32::to_bits),
            pinned
        );
    }

    #[test]
    fn streams_depend_on_every_key_part_and_nothing_else() {
        let draw = |s, p, i| {
            let mut r = SampleStream::new(s, p, i);
            [r.next_1d(), r.next_1d(), r.next_1d()]
        };
        assert_eq!(draw(1, 2, 3), draw(1, 2, 3));
        assert_ne!(draw(1, 2, 3), draw(2, 2, 3));
        assert_ne!(draw(1, 2, 3), draw(1, 3, 3));
        assert_ne!(draw(1, 2, 3), draw(1, 2, 4));
        // Swapping pixel and index must not give the same stream.
        assert_ne!(draw(1, 2, 3), draw(1, 3, 2));
        for v in draw(7, 8, 9) {
            assert!((0.0..1.0).contains(&v));
        }
    }
}
