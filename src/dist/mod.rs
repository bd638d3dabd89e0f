//! Generators with exact truth: heavy-tailed sample laws shaped like path-tracing pixel
//! luminance, each knowing its exact mean, variance (`None` when infinite), CDF, survival
//! function and conditional moments below a threshold, so that an estimator's bias and error
//! can be measured against the truth rather than against another estimate.
//!
//! The laws are [`Pareto`], [`TruncatedPareto`], [`LogNormal`], [`PointMass`] and finite
//! [`Mixture`]s of them, gathered in the [`Dist`] enum that the harness names and samples;
//! [`Preset`] holds the named pixel kinds and [`DistSpec`] the serde form for experiment files.
//!
//! Sampling is built for billions of draws: `fill` dispatches on the law once per block, and
//! each law draws with one or two machine words (ziggurat normal or exponential, or a 53-bit
//! uniform), so a draw costs about as much as a bare `rand_distr::Pareto` draw or less.
//!
//! All samples are >= 0 and finite, as luminance is. Exact quantities are pure functions of
//! the parameters; `NaN` arguments give `NaN` results.

use std::fmt;

use rand::Rng;
use serde::{Deserialize, Serialize};

mod exp;
pub mod fit;
mod lognormal;
mod mixture;
mod pareto;
mod point;
mod presets;
mod spec;
pub(crate) mod special;

pub use lognormal::{LogNormal, LogNormalAbove};
pub use mixture::Mixture;
pub use pareto::{Pareto, TruncatedPareto};
pub use point::PointMass;
pub use presets::{Preset, preset};
pub use spec::{ComponentSpec, DistSpec};

use crate::error::{Error, Result};

/// The law of `S` conditioned on `S < t` (strictly below: an atom at `t` is excluded), as
/// needed by variance bounds on estimators that treat samples above `t` differently.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruncatedMoments {
    /// `P(S < t)`.
    pub probability: f64,
    /// `E[S | S < t]`; 0 when `probability` is exactly 0 because `t` is at or below the
    /// bottom of the support, so that `probability * mean` is still the partial expectation.
    pub mean: f64,
    /// `Var[S | S < t]`; 0 when `probability` is exactly 0 for the same reason, and infinite
    /// for an untruncated Pareto with `shape <= 2` and `t = inf`.
    pub variance: f64,
}

impl TruncatedMoments {
    /// Nothing lies below the threshold.
    pub const EMPTY: TruncatedMoments = TruncatedMoments {
        probability: 0.0,
        mean: 0.0,
        variance: 0.0,
    };

    /// Answer to a NaN threshold.
    pub const NAN: TruncatedMoments = TruncatedMoments {
        probability: f64::NAN,
        mean: f64::NAN,
        variance: f64::NAN,
    };

    /// `E[S; S < t] = probability * mean`, the part of the mean carried below `t`.
    pub fn partial_mean(&self) -> f64 {
        self.probability * self.mean
    }

    /// `E[S^2; S < t] = probability * (variance + mean^2)`.
    pub fn partial_second_moment(&self) -> f64 {
        self.probability * (self.variance + self.mean * self.mean)
    }
}

/// Any generator: one of the laws above. `Display` gives a compact, readable description such
/// as `pareto(scale=1,shape=1.5)`; serde goes through [`DistSpec`], so deserialising checks
/// the parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "DistSpec", into = "DistSpec")]
pub enum Dist {
    /// Untruncated Pareto, shape > 1.
    Pareto(Pareto),
    /// Pareto bounded above.
    TruncatedPareto(TruncatedPareto),
    /// Lognormal.
    LogNormal(LogNormal),
    /// Point mass.
    PointMass(PointMass),
    /// Finite mixture of the above.
    Mixture(Mixture),
}

/// Calls `$body` with `$d` bound to the inner law, whatever the variant.
macro_rules! dispatch {
    ($self:expr, $d:ident => $body:expr) => {
        match $self {
            Dist::Pareto($d) => $body,
            Dist::TruncatedPareto($d) => $body,
            Dist::LogNormal($d) => $body,
            Dist::PointMass($d) => $body,
            Dist::Mixture($d) => $body,
        }
    };
}

impl Dist {
    /// Exact mean (always finite: laws with infinite mean cannot be built).
    pub fn mean(&self) -> f64 {
        dispatch!(self, d => d.mean())
    }

    /// Exact variance, `None` when it is infinite (a Pareto with `shape <= 2`, or a mixture
    /// containing one).
    pub fn variance(&self) -> Option<f64> {
        dispatch!(self, d => d.variance())
    }

    /// `Var S / (E S)^2`, `None` when the variance is infinite. Scale-free, so exact where
    /// the variance itself does not fit in an f64 (laws at scale 1e300 or 1e-300).
    pub fn relative_variance(&self) -> Option<f64> {
        match self {
            Dist::LogNormal(d) => Some(d.relative_variance()),
            Dist::PointMass(_) => Some(0.0),
            Dist::Mixture(m) => {
                let mu = m.mean();
                let v = m.variance()?;
                if v > 0.0 && v.is_finite() {
                    return Some(v / mu / mu);
                }
                // The variance over- or underflowed: recombine scale-free component moments.
                let mut second = 0.0;
                for (&w, d) in m.weights().iter().zip(m.components()) {
                    if w == 0.0 {
                        continue;
                    }
                    let ratio = d.mean() / mu;
                    second += w * ratio * ratio * (1.0 + d.relative_variance()?);
                }
                Some((second - 1.0).max(0.0))
            }
            Dist::Pareto(_) | Dist::TruncatedPareto(_) => {
                let m = self.mean();
                self.variance().map(|v| v / m / m)
            }
        }
    }

    /// `P(S <= x)`.
    pub fn cdf(&self, x: f64) -> f64 {
        dispatch!(self, d => d.cdf(x))
    }

    /// `P(S > x)`, computed directly (not as `1 - cdf`) to keep accuracy in the far tail.
    pub fn sf(&self, x: f64) -> f64 {
        dispatch!(self, d => d.sf(x))
    }

    /// `P(S > t)`: how often a sample exceeds a firefly threshold `t`. Same as [`Dist::sf`].
    pub fn tail_probability(&self, t: f64) -> f64 {
        self.sf(t)
    }

    /// Probability, mean and variance of `S` given `S < t`; see [`TruncatedMoments`].
    pub fn truncated_moments(&self, t: f64) -> TruncatedMoments {
        dispatch!(self, d => d.truncated_moments(t))
    }

    /// `P(S >= t)`: the mass at or above `t`, atoms at `t` included.
    pub fn mass_from(&self, t: f64) -> f64 {
        dispatch!(self, d => d.mass_from(t))
    }

    /// The law conditioned on `S >= t` (needs `mass_from(t) > 0`), for simulating only the
    /// rare part of a law: each law's own tail (a Pareto is memoryless in `ln S`, so its tail
    /// is a Pareto from `t`), built once and drawn from many times.
    pub fn above(&self, t: f64) -> Above {
        match self {
            Dist::PointMass(d) => Above::Point(d.value()),
            Dist::Pareto(d) => Pareto::new(t.max(d.scale()), d.shape())
                .map_or(Above::Point(t), |p| Above::Law(Box::new(p.into()))),
            Dist::TruncatedPareto(d) => {
                TruncatedPareto::new(t.max(d.scale()), d.shape(), d.upper())
                    .map_or(Above::Point(d.upper()), |p| Above::Law(Box::new(p.into())))
            }
            Dist::LogNormal(d) => Above::LogNormal(LogNormalAbove::new(d, t)),
            Dist::Mixture(m) => {
                let mut total = 0.0;
                let mut parts = Vec::new();
                for (&w, d) in m.weights().iter().zip(m.components()) {
                    let mass = w * d.mass_from(t);
                    if mass > 0.0 {
                        total += mass;
                        parts.push((total, d.above(t)));
                    }
                }
                Above::Mixture(parts)
            }
        }
    }

    /// `ln E[(S / c)^k]` (`inf` when the moment is infinite), scale-free for any `c > 0`.
    pub fn ln_moment(&self, k: f64, c: f64) -> f64 {
        dispatch!(self, d => d.ln_moment(k, c))
    }

    /// The share of `E[S^k]` that samples at or above `t` carry (1 when the moment is
    /// infinite and `t` is finite). How much a rare part of the law weighs in a moment.
    pub fn upper_share(&self, k: f64, t: f64) -> f64 {
        dispatch!(self, d => d.upper_share(k, t))
    }

    /// Smallest and largest value a sample can take (`inf` when unbounded).
    pub fn support(&self) -> (f64, f64) {
        match self {
            Dist::Pareto(d) => (d.scale(), f64::INFINITY),
            Dist::TruncatedPareto(d) => (d.scale(), d.upper()),
            Dist::LogNormal(_) => (0.0, f64::INFINITY),
            Dist::PointMass(d) => (d.value(), d.value()),
            Dist::Mixture(m) => m
                .components()
                .iter()
                .map(Dist::support)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (l, h)| {
                    (lo.min(l), hi.max(h))
                }),
        }
    }

    /// The atoms `(value, probability)` — the point masses, weighted — in component order; the
    /// rest of the law is continuous. Used to place test cells and firefly thresholds.
    pub fn atoms(&self) -> Vec<(f64, f64)> {
        match self {
            Dist::PointMass(d) => vec![(d.value(), 1.0)],
            Dist::Mixture(m) => m
                .weights()
                .iter()
                .zip(m.components())
                .flat_map(|(&w, d)| d.atoms().into_iter().map(move |(v, p)| (v, w * p)))
                .collect(),
            _ => Vec::new(),
        }
    }

    /// One draw.
    #[inline]
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        dispatch!(self, d => d.sample(rng))
    }

    /// Fills `out` with independent draws, dispatching on the law once per block; the stream
    /// is identical to calling [`Dist::sample`] `out.len()` times.
    pub fn fill<R: Rng + ?Sized>(&self, rng: &mut R, out: &mut [f64]) {
        match self {
            Dist::Pareto(d) => d.fill(rng, out),
            Dist::LogNormal(d) => d.fill(rng, out),
            Dist::TruncatedPareto(d) => d.fill(rng, out),
            Dist::PointMass(d) => out.fill_with(|| d.sample(rng)),
            Dist::Mixture(d) => out.fill_with(|| d.sample(rng)),
        }
    }
}

/// A law conditioned on `S >= t`: see [`Dist::above`].
#[derive(Clone, Debug)]
pub enum Above {
    /// Everything above `t` is one value.
    Point(f64),
    /// A law of its own (a Pareto or truncated Pareto starting at `t`).
    Law(Box<Dist>),
    /// A lognormal's tail.
    LogNormal(LogNormalAbove),
    /// Components with their cumulative masses above `t` (not normalised).
    Mixture(Vec<(f64, Above)>),
}

impl Above {
    /// One draw of `S` given `S >= t`.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        match self {
            Above::Point(v) => *v,
            Above::Law(d) => d.sample(rng),
            Above::LogNormal(d) => d.sample(rng),
            Above::Mixture(parts) => {
                let total = parts.last().map_or(0.0, |p| p.0);
                let u = special::unit_f64(rng) * total;
                let i = parts
                    .iter()
                    .position(|p| u < p.0)
                    .unwrap_or(parts.len() - 1);
                parts[i].1.sample(rng)
            }
        }
    }
}

impl fmt::Display for Dist {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        dispatch!(self, d => fmt::Display::fmt(d, f))
    }
}

impl rand_distr::Distribution<f64> for Dist {
    fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        Dist::sample(self, rng)
    }
}

impl From<Pareto> for Dist {
    fn from(d: Pareto) -> Self {
        Dist::Pareto(d)
    }
}

impl From<TruncatedPareto> for Dist {
    fn from(d: TruncatedPareto) -> Self {
        Dist::TruncatedPareto(d)
    }
}

impl From<LogNormal> for Dist {
    fn from(d: LogNormal) -> Self {
        Dist::LogNormal(d)
    }
}

impl From<PointMass> for Dist {
    fn from(d: PointMass) -> Self {
        Dist::PointMass(d)
    }
}

impl From<Mixture> for Dist {
    fn from(d: Mixture) -> Self {
        Dist::Mixture(d)
    }
}

/// Checks `x > 0` and finite, written so that NaN fails too.
fn check_positive_finite(name: &'static str, x: f64) -> Result<()> {
    if !(x > 0.0 && x.is_finite()) {
        return Err(Error::param(name, x, "must be finite and > 0"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    #[test]
    fn fill_equals_repeated_sample() {
        // Beyond the presets: the laws whose fill has its own two passes, the truncated Pareto
        // with each of its two ways to draw (wide and narrow cut), a mixture with every kind of
        // component.
        let laws: Vec<Dist> = vec![
            Pareto::new(0.5, 1.2).unwrap().into(),
            TruncatedPareto::new(1.0, 1.5, 1e4).unwrap().into(),
            TruncatedPareto::new(1.0, 0.5, 1.5).unwrap().into(),
            LogNormal::new(-1.0, 2.5).unwrap().into(),
            Dist::Mixture(
                Mixture::new(vec![
                    (0.3, TruncatedPareto::new(2.0, 0.8, 50.0).unwrap().into()),
                    (0.3, PointMass::new(0.0).unwrap().into()),
                    (0.4, Pareto::new(1.0, 1.1).unwrap().into()),
                ])
                .unwrap(),
            ),
        ];
        for (p, d) in Preset::ALL
            .iter()
            .map(|p| (p.to_string(), p.dist()))
            .chain(laws.into_iter().map(|d| (d.to_string(), d)))
        {
            let mut a = Xoshiro256PlusPlus::seed_from_u64(7);
            let mut b = a.clone();
            let mut block = vec![0.0; 1000];
            d.fill(&mut a, &mut block);
            let one: Vec<f64> = (0..1000).map(|_| d.sample(&mut b)).collect();
            let bits = |xs: &[f64]| xs.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&block), bits(&one), "{p}");
            assert_eq!(a, b, "{p}: the same randomness consumed");
        }
    }

    #[test]
    fn display_support_atoms() {
        let d = Dist::from(Pareto::new(1.0, 1.5).unwrap());
        assert_eq!(d.to_string(), "pareto(scale=1,shape=1.5)");
        assert_eq!(d.support(), (1.0, f64::INFINITY));
        let c = Preset::Caustic.dist();
        assert_eq!(c.support(), (0.0, f64::INFINITY));
        assert_eq!(c.atoms(), vec![(0.0, 0.45), (2000.0, 0.00045)]);
        assert!(
            c.to_string()
                .starts_with("mixture(0.45*point(value=0) + 0.54955*lognormal(mu=-1.98")
        );
        let m = Preset::MirrorLit.dist();
        assert!((m.support().1 - 198053.0).abs() < 1.0);
    }

    #[test]
    fn dist_is_shareable() {
        fn assert_traits<T: Clone + Send + Sync + fmt::Debug + fmt::Display + 'static>() {}
        assert_traits::<Dist>();
    }
}
