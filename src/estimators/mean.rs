//! The plain sample mean ([B] eq. 1): unbiased, and the reference every robust method is
//! compared with. Compensated summation keeps it exact over 10^8-sample streams, and the
//! sum's rescaling keeps it finite for any finite samples (`[1e308; 3]` has mean `1e308`).

use super::numeric::ScaledSum;
use super::rgb::per_channel;
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
        per_channel(|| Ok(Mean::new()))
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
