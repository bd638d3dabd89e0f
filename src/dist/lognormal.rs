//! Lognormal: the body of an ordinary pixel, whose luminance is a product of many throughput
//! factors. All moments are finite, yet for large `sigma` the right tail is long enough to
//! mislead a small-sample estimator.

use std::fmt;

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::TruncatedMoments;
use super::exp::{exp, exp_affine_in_place};
use super::special::{ln_norm_cdf, norm_cdf, norm_inv_cdf, norm_sf, unit_f64};
use crate::error::{Error, Num, Result};

/// `S = exp(mu + sigma Z)` with `Z` standard normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogNormal {
    mu: f64,
    sigma: f64,
    mean: f64,
    variance: f64,
}

impl LogNormal {
    /// Checked constructor: `mu` finite, `sigma` finite and > 0 (a zero spread is a point
    /// mass), and the mean must be a positive f64. The variance may over- or underflow at
    /// extreme scales (mean near 1e300 or 1e-300); [`crate::dist::Dist::relative_variance`]
    /// stays exact there.
    pub fn new(mu: f64, sigma: f64) -> Result<Self> {
        if !mu.is_finite() {
            return Err(Error::param("mu", mu, "must be finite"));
        }
        if !(sigma > 0.0 && sigma.is_finite()) {
            return Err(Error::param(
                "sigma",
                sigma,
                "must be finite and > 0 (use a point mass for no spread)",
            ));
        }
        let s2 = sigma * sigma;
        let mean = (mu + 0.5 * s2).exp();
        let variance = s2.exp_m1() * (2.0 * mu + s2).exp();
        if !(s2 > 0.0) {
            return Err(Error::param(
                "sigma",
                sigma,
                "sigma^2 underflows to 0: use a point mass for no spread",
            ));
        }
        if !(mean > 0.0 && mean.is_finite() && s2.exp_m1().is_finite()) {
            return Err(Error::param(
                "mu",
                mu,
                format!("with sigma = {sigma} the mean does not fit in a positive f64"),
            ));
        }
        Ok(LogNormal {
            mu,
            sigma,
            mean,
            variance,
        })
    }

    /// Location of `ln S`.
    pub fn mu(&self) -> f64 {
        self.mu
    }

    /// Spread of `ln S`.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// Exact mean `exp(mu + sigma^2 / 2)`.
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Exact variance `expm1(sigma^2) exp(2 mu + sigma^2)` (finite; it can overflow to `inf` or
    /// underflow to 0 as an f64 at extreme scales).
    pub fn variance(&self) -> Option<f64> {
        Some(self.variance)
    }

    /// `Var / mean^2 = expm1(sigma^2)`: scale-free, exact at any scale.
    pub fn relative_variance(&self) -> f64 {
        (self.sigma * self.sigma).exp_m1()
    }

    fn standardise(&self, x: f64) -> f64 {
        (x.ln() - self.mu) / self.sigma
    }

    /// `P(S <= x) = Phi((ln x - mu) / sigma)`.
    pub fn cdf(&self, x: f64) -> f64 {
        if x.is_nan() {
            f64::NAN
        } else if x <= 0.0 {
            0.0
        } else {
            norm_cdf(self.standardise(x))
        }
    }

    /// `P(S > x)`, from the normal survival function so it keeps relative accuracy in the tail.
    pub fn sf(&self, x: f64) -> f64 {
        if x.is_nan() {
            f64::NAN
        } else if x <= 0.0 {
            1.0
        } else {
            norm_sf(self.standardise(x))
        }
    }

    /// Probability, mean and variance of `S` given `S < t`, from the partial expectations
    /// `E[S^k; S < t] = exp(k mu + k^2 sigma^2 / 2) Phi(d - k sigma)`, `d = (ln t - mu)/sigma`,
    /// taken as ratios in log space so they stay finite when the `Phi` values underflow.
    pub fn truncated_moments(&self, t: f64) -> TruncatedMoments {
        if t.is_nan() {
            return TruncatedMoments::NAN;
        }
        if !(t > 0.0) {
            return TruncatedMoments::EMPTY;
        }
        if t == f64::INFINITY {
            return TruncatedMoments {
                probability: 1.0,
                mean: self.mean,
                variance: self.variance,
            };
        }
        let (mu, s) = (self.mu, self.sigma);
        let d = self.standardise(t);
        let l0 = ln_norm_cdf(d);
        if l0 == f64::NEG_INFINITY {
            // Even ln P(S < t) underflows (|d| > 1e154): the conditional law is a point at t.
            return TruncatedMoments {
                probability: 0.0,
                mean: t,
                variance: 0.0,
            };
        }
        let l1 = ln_norm_cdf(d - s);
        let l2 = ln_norm_cdf(d - 2.0 * s);
        let mean = (mu + 0.5 * s * s + l1 - l0).exp();
        // Var = m^2 (E[S^2] / m^2 - 1): no cancellation when the cut is above the median.
        let mut variance = mean * (mean * (s * s + l2 + l0 - 2.0 * l1).exp_m1());
        if d < 0.0 {
            // Below the median the log-space terms are large and nearly cancel; the plain
            // difference loses only ~log10((d / sigma)^2) digits.
            let diff = (2.0 * mu + 2.0 * s * s + l2 - l0).exp() - mean * mean;
            if diff.is_finite() {
                variance = diff;
            }
        }
        TruncatedMoments {
            probability: norm_cdf(d),
            mean,
            variance: if variance.is_nan() {
                f64::INFINITY
            } else {
                variance.max(0.0)
            },
        }
    }

    /// `P(S >= t)` (continuous: the same as [`LogNormal::sf`]).
    pub fn mass_from(&self, t: f64) -> f64 {
        self.sf(t)
    }

    /// `ln E[(S / c)^k] = k (mu - ln c) + k^2 sigma^2 / 2`.
    pub fn ln_moment(&self, k: f64, c: f64) -> f64 {
        k * (self.mu - c.ln()) + 0.5 * k * k * self.sigma * self.sigma
    }

    /// The share of `E[S^k]` carried by `S >= t`: `P(Z > d - k sigma)`,
    /// `d = (ln t - mu) / sigma`.
    pub fn upper_share(&self, k: f64, t: f64) -> f64 {
        if !(t > 0.0) {
            return 1.0;
        }
        norm_sf(self.standardise(t) - k * self.sigma)
    }

    /// One draw, `exp(mu + sigma Z)` with `Z` from rand_distr's ziggurat normal.
    #[inline]
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        let z: f64 = StandardNormal.sample(rng);
        exp(self.mu + self.sigma * z)
    }

    /// Fills `out` with the draws of as many [`LogNormal::sample`] calls: the normals first,
    /// then their exponentials in one pass that vectorises.
    pub fn fill<R: Rng + ?Sized>(&self, rng: &mut R, out: &mut [f64]) {
        out.fill_with(|| StandardNormal.sample(rng));
        exp_affine_in_place(out, self.sigma, self.mu, 1.0);
    }
}

/// The lognormal law conditioned on `S >= t`, for drawing only its rare part: inverting the
/// normal survival function on the mass above `t`, accurate however far out `t` is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogNormalAbove {
    mu: f64,
    sigma: f64,
    from: f64,
    mass: f64,
}

impl LogNormalAbove {
    /// `law` given `S >= from`.
    pub fn new(law: &LogNormal, from: f64) -> Self {
        LogNormalAbove {
            mu: law.mu,
            sigma: law.sigma,
            from,
            mass: law.mass_from(from),
        }
    }

    /// One draw.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        let p = self.mass * (1.0 - unit_f64(rng));
        let z = -norm_inv_cdf(p);
        exp(self.mu + self.sigma * z).max(self.from)
    }
}

impl fmt::Display for LogNormal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "lognormal(mu={},sigma={})",
            Num(self.mu),
            Num(self.sigma)
        )
    }
}

impl Distribution<f64> for LogNormal {
    fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        LogNormal::sample(self, rng)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use statrs::distribution::ContinuousCDF;

    #[test]
    fn cdf_and_sf_match_statrs() {
        let d = LogNormal::new(-0.3, 1.5).unwrap();
        let oracle = statrs::distribution::LogNormal::new(-0.3, 1.5).unwrap();
        for x in [1e-6, 0.01, 0.5, 1.0, 3.0, 100.0, 1e5] {
            // statrs 0.19.1's erfc is good to ~1e-10 relative (see `special`).
            let (a, b) = (d.cdf(x), oracle.cdf(x));
            assert!(((a - b) / b).abs() < 1e-9, "x={x} {a} {b}");
            let (a, b) = (d.sf(x), oracle.sf(x));
            assert!(((a - b) / b).abs() < 1e-9, "x={x} {a} {b}");
        }
        assert_eq!((d.cdf(0.0), d.sf(0.0), d.cdf(-1.0)), (0.0, 1.0, 0.0));
        assert_eq!((d.cdf(f64::INFINITY), d.sf(f64::INFINITY)), (1.0, 0.0));
    }

    #[test]
    fn moments() {
        let d = LogNormal::new(-0.125, 0.5).unwrap();
        assert_eq!(d.mean(), 1.0);
        assert!((d.variance().unwrap() - 0.25f64.exp_m1()).abs() < 1e-15);
        let far = d.truncated_moments(1e6);
        assert!((far.mean - 1.0).abs() < 1e-14 && (far.variance - 0.25f64.exp_m1()).abs() < 1e-14);
        // Deep below the body the conditional law piles up just under t.
        let low = d.truncated_moments(1e-30);
        assert!(low.probability == 0.0 || low.probability < 1e-300);
        assert!(low.mean < 1e-30 && low.mean > 0.9e-30, "{}", low.mean);
        assert!(low.variance >= 0.0 && low.variance < 1e-62);
    }

    #[test]
    fn errors_name_parameter_and_value() {
        let e = LogNormal::new(0.0, -2.5).unwrap_err().to_string();
        assert!(e.contains("sigma") && e.contains("-2.5"), "{e}");
        let e = LogNormal::new(f64::INFINITY, 1.0).unwrap_err().to_string();
        assert!(e.contains("mu") && e.contains("inf"), "{e}");
        // The mean exp(714.5) overflows; exp(704.5) = 1e306 fits, its variance need not.
        let e = LogNormal::new(710.0, 3.0).unwrap_err().to_string();
        assert!(
            e.contains("mu") && e.contains("710") && e.contains("sigma = 3"),
            "{e}"
        );
        let huge = LogNormal::new(700.0, 3.0).unwrap();
        assert_eq!(huge.variance(), Some(f64::INFINITY));
        assert!((huge.relative_variance() - 9f64.exp_m1()).abs() < 1e-9 * 9f64.exp_m1());
    }
}
