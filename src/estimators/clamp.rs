//! Clamping: every sample above `c` counts as `c`. Biased downwards by `E[(S - c)+]`, but
//! bounded variance; the cheapest firefly remedy renderers ship, and the baseline robust
//! methods must beat.

use super::mean::Mean;
use super::rgb::per_channel;
use super::{Estimator, EstimatorSpec, Key, Method, RgbEstimator, empty};
use crate::error::{Error, Result};
use std::fmt;

/// `clamp:c=` (required).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClampSpec {
    /// Clamping threshold.
    pub c: f64,
}

impl Method for ClampSpec {
    const NAME: &'static str = "clamp";
    const KEYS: &'static [Key<Self>] = &[Key::required(Key::float("c", |s| &mut s.c))];
    const DEFAULT: Self = ClampSpec { c: f64::NAN };

    fn build(&self) -> Result<Box<dyn Estimator>> {
        Ok(Box::new(Clamp::new(self.c)?))
    }

    fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
        per_channel(|| Clamp::new(self.c))
    }
}

/// Mean of `min(S, c)`: the plain [`Mean`] of the clamped stream.
#[derive(Debug, Clone)]
pub struct Clamp {
    c: f64,
    /// Its sum is rescaled before it overflows, so a clamp near `f64::MAX` stays finite.
    clamped: Mean,
}

impl Clamp {
    /// A clamp at `c`, which must be finite and positive.
    pub fn new(c: f64) -> Result<Self> {
        if !(c > 0.0 && c.is_finite()) {
            return Err(Error::param("c", c, "must be finite and > 0"));
        }
        Ok(Clamp {
            c,
            clamped: Mean::new(),
        })
    }

    /// The clamping threshold.
    pub fn threshold(&self) -> f64 {
        self.c
    }
}

impl fmt::Display for Clamp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Clamp(c={})", self.c)
    }
}

impl Estimator for Clamp {
    #[inline]
    fn push(&mut self, sample: f64) {
        self.clamped.push(sample.min(self.c));
    }

    fn push_slice(&mut self, samples: &[f64]) {
        let c = self.c;
        self.clamped.push_iter(samples.iter().map(|&s| s.min(c)));
    }

    fn count(&self) -> u64 {
        self.clamped.count()
    }

    fn estimate(&self) -> Result<f64> {
        if self.count() == 0 {
            return Err(empty(self));
        }
        self.clamped.estimate()
    }

    fn state_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
    }

    fn spec(&self) -> EstimatorSpec {
        ClampSpec { c: self.c }.into()
    }

    fn reset(&mut self) {
        self.clamped.reset();
    }
}
