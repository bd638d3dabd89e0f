//! The plain sample mean ([B] eq. 1): unbiased, and the reference every robust method is
//! compared with. Compensated summation keeps it exact over 10^8-sample streams, and the
//! sum's rescaling keeps it finite for any finite samples (`[1e308; 3]` has mean `1e308`).

use super::numeric::{ScaledSum, add_all_rgb};
use super::{Estimator, EstimatorSpec, Key, Method, RgbEstimator, empty};
use crate::error::Result;
use std::fmt;

/// `mean`: no keys.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanSpec;

impl Method for MeanSpec {
    const NAME: &'static str = "mean";
    const KEYS: &'static [Key<Self>] = &[];
    const DEFAULT: Self = MeanSpec;

    fn build(&self) -> Result<Box<dyn Estimator>> {
        Ok(Box::new(Mean::new()))
    }

    fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
        Ok(Box::new(MeanRgb::default()))
    }
}

/// Neumaier sum of the samples divided by their count.
#[derive(Debug, Clone, Default)]
pub struct Mean {
    sum: ScaledSum,
    n: u64,
}

impl Mean {
    /// An empty mean (there are no parameters to check).
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds samples given as an iterator (what [`super::Clamp`] feeds after clamping).
    #[inline]
    pub(super) fn push_iter(&mut self, samples: impl ExactSizeIterator<Item = f64> + Clone) {
        self.n += samples.len() as u64;
        self.sum.add_all(samples);
    }
}

impl fmt::Display for Mean {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Mean")
    }
}

impl Estimator for Mean {
    #[inline]
    fn push(&mut self, sample: f64) {
        self.sum.add(sample);
        self.n += 1;
    }

    fn push_slice(&mut self, samples: &[f64]) {
        self.push_iter(samples.iter().copied());
    }

    fn count(&self) -> u64 {
        self.n
    }

    fn estimate(&self) -> Result<f64> {
        if self.n == 0 {
            return Err(empty(self));
        }
        Ok(self.sum.mean(self.n))
    }

    fn state_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
    }

    fn spec(&self) -> EstimatorSpec {
        EstimatorSpec::Mean(MeanSpec)
    }

    fn reset(&mut self) {
        *self = Self::default();
    }
}

/// The mean of an RGB stream: in each channel bit for bit the [`Mean`] of that channel's
/// stream (the same compensated sums, in the same order), with the three channels' sums
/// updated together ([`add_all_rgb`]). The film pushes every sample of a render through it;
/// as three scalar means behind the per-channel split it cost about 70 instructions a sample.
#[derive(Debug, Clone, Default)]
struct MeanRgb {
    sums: [ScaledSum; 3],
    n: u64,
}

impl fmt::Display for MeanRgb {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Mean[RGB]")
    }
}

impl RgbEstimator for MeanRgb {
    fn push_slice(&mut self, samples: &[[f64; 3]]) {
        add_all_rgb(&mut self.sums, samples);
        self.n += samples.len() as u64;
    }

    fn count(&self) -> u64 {
        self.n
    }

    fn estimate(&self) -> Result<[f64; 3]> {
        if self.n == 0 {
            return Err(empty(self));
        }
        Ok(self.sums.map(|s| s.mean(self.n)))
    }

    fn state_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
    }

    fn spec(&self) -> EstimatorSpec {
        EstimatorSpec::Mean(MeanSpec)
    }
}
