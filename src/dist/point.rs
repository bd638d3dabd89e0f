//! Point mass: a sample that always takes one value. At 0 it is a black sample (the path
//! found no light); at a fixed high value it is a rare direct hit of a light, whose luminance
//! is the light's radiance times the surface albedo every time — a spike, not a power law.

use std::fmt;

use rand::Rng;
use rand_distr::Distribution;

use super::TruncatedMoments;
use crate::error::{Error, Num, Result};

/// All probability at `value`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointMass {
    value: f64,
}

impl PointMass {
    /// Checked constructor: `value` finite and >= 0 (luminance is never negative); `-0.0` is
    /// stored as `+0.0`.
    pub fn new(value: f64) -> Result<Self> {
        if !(value >= 0.0 && value.is_finite()) {
            return Err(Error::param("value", value, "must be finite and >= 0"));
        }
        Ok(PointMass { value: value + 0.0 })
    }

    /// A black sample.
    pub const ZERO: PointMass = PointMass { value: 0.0 };

    /// The value every draw takes.
    pub fn value(&self) -> f64 {
        self.value
    }

    /// The value itself.
    pub fn mean(&self) -> f64 {
        self.value
    }

    /// Always `Some(0.0)`.
    pub fn variance(&self) -> Option<f64> {
        Some(0.0)
    }

    /// `P(S <= x)`: 1 from `value` on.
    pub fn cdf(&self, x: f64) -> f64 {
        if x.is_nan() {
            f64::NAN
        } else if x >= self.value {
            1.0
        } else {
            0.0
        }
    }

    /// `P(S > x)`: 1 below `value`.
    pub fn sf(&self, x: f64) -> f64 {
        if x.is_nan() {
            f64::NAN
        } else if x < self.value {
            1.0
        } else {
            0.0
        }
    }

    /// Given `S < t`: the whole mass if `value < t`, else nothing.
    pub fn truncated_moments(&self, t: f64) -> TruncatedMoments {
        if t.is_nan() {
            TruncatedMoments::NAN
        } else if self.value < t {
            TruncatedMoments {
                probability: 1.0,
                mean: self.value,
                variance: 0.0,
            }
        } else {
            TruncatedMoments::EMPTY
        }
    }

    /// `P(S >= t)`.
    pub fn mass_from(&self, t: f64) -> f64 {
        if self.value >= t { 1.0 } else { 0.0 }
    }

    /// `ln E[(S / c)^k] = k ln(value / c)`.
    pub fn ln_moment(&self, k: f64, c: f64) -> f64 {
        if self.value == 0.0 {
            return if k > 0.0 { f64::NEG_INFINITY } else { 0.0 };
        }
        k * (self.value / c).ln()
    }

    /// 1 when the atom is at or above `t`, else 0.
    pub fn upper_share(&self, _k: f64, t: f64) -> f64 {
        self.mass_from(t)
    }

    /// Returns `value`; consumes no randomness.
    #[inline]
    pub fn sample<R: Rng + ?Sized>(&self, _rng: &mut R) -> f64 {
        self.value
    }
}

impl fmt::Display for PointMass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "point(value={})", Num(self.value))
    }
}

impl Distribution<f64> for PointMass {
    fn sample<R: Rng + ?Sized>(&self, _rng: &mut R) -> f64 {
        self.value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truth_and_edges() {
        let p = PointMass::new(2000.0).unwrap();
        assert_eq!(
            (p.cdf(1999.0), p.cdf(2000.0), p.sf(1999.0), p.sf(2000.0)),
            (0.0, 1.0, 1.0, 0.0)
        );
        assert_eq!(p.truncated_moments(2000.0), TruncatedMoments::EMPTY);
        assert_eq!(p.truncated_moments(2000.5).mean, 2000.0);
        assert_eq!(
            PointMass::new(-0.0).unwrap().value().to_bits(),
            0.0f64.to_bits()
        );
        let e = PointMass::new(-3.0).unwrap_err().to_string();
        assert!(e.contains("value") && e.contains("-3"), "{e}");
    }
}
