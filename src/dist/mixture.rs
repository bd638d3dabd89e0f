//! Finite mixtures: a pixel's sample is one of several kinds of light path, each with its own
//! law (black, ordinary body, rare light hit, power-law tail), chosen with fixed probabilities.

use std::fmt;

use rand::Rng;
use rand_distr::Distribution;

use super::special::unit_f64;
use super::{Dist, TruncatedMoments};
use crate::error::{Error, Num, Result};

/// `S = S_i` with probability `w_i`.
///
/// Weights are normalised: any finite, non-negative weights with a positive finite sum are
/// accepted and divided by their sum (so `[9, 1]` means 90% / 10%; `Display` shows the
/// normalised values). Weights that already sum to 1 within 1e-14 are kept exactly as
/// written, so that `0.45, 0.54955, 0.00045` stays readable. Zero-weight components are
/// dropped, and nested mixtures are flattened into their parent, so every stored component is
/// a single law.
#[derive(Clone, Debug, PartialEq)]
pub struct Mixture {
    components: Vec<Dist>,
    weights: Vec<f64>,
    /// Running sums of `weights`; the last is exactly 1.
    cumulative: Vec<f64>,
    mean: f64,
    variance: Option<f64>,
}

impl Mixture {
    /// Checked constructor from `(weight, law)` pairs. A negative, NaN or infinite weight is an
    /// [`Error::Component`] naming its index and value.
    pub fn new(components: Vec<(f64, Dist)>) -> Result<Self> {
        if components.is_empty() {
            return Err(Error::param(
                "components",
                0,
                "a mixture needs at least one component",
            ));
        }
        let mut sum = 0.0;
        for (i, &(w, _)) in components.iter().enumerate() {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(Error::Component {
                    component: i,
                    reason: format!("weight = {w}: must be finite and >= 0"),
                });
            }
            sum += w;
        }
        if !(sum > 0.0 && sum.is_finite()) {
            return Err(Error::param(
                "weights",
                sum,
                "the weights must have a positive, finite sum",
            ));
        }
        let norm = if (sum - 1.0).abs() <= 1e-14 { 1.0 } else { sum };
        let mut flat: Vec<(f64, Dist)> = Vec::with_capacity(components.len());
        for (w, d) in components {
            let w = w / norm;
            if w == 0.0 {
                continue;
            }
            match d {
                Dist::Mixture(m) => {
                    for (&wi, di) in m.weights.iter().zip(m.components) {
                        flat.push((w * wi, di));
                    }
                }
                other => flat.push((w, other)),
            }
        }
        let (weights, components): (Vec<f64>, Vec<Dist>) = flat.into_iter().unzip();
        let mut cumulative = Vec::with_capacity(weights.len());
        let mut acc = 0.0;
        for &w in &weights {
            acc += w;
            cumulative.push(acc);
        }
        if let Some(last) = cumulative.last_mut() {
            *last = 1.0;
        }
        let mean: f64 = weights
            .iter()
            .zip(&components)
            .map(|(w, d)| w * d.mean())
            .sum();
        // Law of total variance: E[Var(S | i)] + Var(E[S | i]), free of cancellation.
        let variance = weights
            .iter()
            .zip(&components)
            .map(|(w, d)| {
                d.variance().map(|v| {
                    let dm = d.mean() - mean;
                    w * (v + dm * dm)
                })
            })
            .sum::<Option<f64>>();
        Ok(Mixture {
            components,
            weights,
            cumulative,
            mean,
            variance,
        })
    }

    /// The component laws (never mixtures themselves), in order.
    pub fn components(&self) -> &[Dist] {
        &self.components
    }

    /// The normalised weights, one per component, summing to 1.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Exact mean `sum w_i mean_i`.
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Exact variance by the law of total variance; `None` (infinite) as soon as one component
    /// with positive weight has infinite variance.
    pub fn variance(&self) -> Option<f64> {
        self.variance
    }

    /// `P(S <= x) = sum w_i F_i(x)`, taken as `1 - sf(x)` above 1/2 so that it reaches 1
    /// exactly although the weights sum to 1 only within rounding.
    pub fn cdf(&self, x: f64) -> f64 {
        if x.is_nan() {
            return f64::NAN;
        }
        let c = self.weighted(|d| d.cdf(x));
        if c <= 0.5 {
            c
        } else {
            1.0 - self.weighted(|d| d.sf(x)).min(1.0)
        }
    }

    /// `P(S > x) = sum w_i sf_i(x)`, summed directly so that a 1e-5 tail keeps its digits
    /// (and taken as `1 - cdf(x)` above 1/2, like [`Mixture::cdf`]).
    pub fn sf(&self, x: f64) -> f64 {
        if x.is_nan() {
            return f64::NAN;
        }
        let s = self.weighted(|d| d.sf(x));
        if s <= 0.5 {
            s
        } else {
            1.0 - self.weighted(|d| d.cdf(x)).min(1.0)
        }
    }

    fn weighted(&self, f: impl Fn(&Dist) -> f64) -> f64 {
        self.weights
            .iter()
            .zip(&self.components)
            .map(|(w, d)| w * f(d))
            .sum()
    }

    /// Probability, mean and variance of `S` given `S < t`, combining the components'
    /// conditional moments by the law of total variance.
    pub fn truncated_moments(&self, t: f64) -> TruncatedMoments {
        if t.is_nan() {
            return TruncatedMoments::NAN;
        }
        let all: Vec<(f64, TruncatedMoments)> = self
            .weights
            .iter()
            .zip(&self.components)
            .map(|(&w, d)| (w, d.truncated_moments(t)))
            .collect();
        let parts: Vec<&(f64, TruncatedMoments)> = all
            .iter()
            .filter(|(w, m)| w * m.probability > 0.0)
            .collect();
        let mut probability: f64 = parts.iter().map(|(w, m)| w * m.probability).sum();
        if !(probability > 0.0) {
            return TruncatedMoments::EMPTY;
        }
        if probability > 0.5 {
            // Through the complement, so that it is exactly 1 above every sample although
            // the weights sum to 1 only within rounding.
            let above: f64 = all.iter().map(|(w, m)| w * (1.0 - m.probability)).sum();
            probability = 1.0 - above;
        }
        let mean: f64 = parts
            .iter()
            .map(|(w, m)| w * m.probability / probability * m.mean)
            .sum();
        let variance: f64 = parts
            .iter()
            .map(|(w, m)| {
                let dm = m.mean - mean;
                w * m.probability / probability * (m.variance + dm * dm)
            })
            .sum();
        TruncatedMoments {
            probability,
            mean,
            variance,
        }
    }

    /// `P(S >= t) = sum w_i P_i(S >= t)`.
    pub fn mass_from(&self, t: f64) -> f64 {
        self.weighted(|d| d.mass_from(t))
    }

    /// `ln E[(S / c)^k]`, combined in log space.
    pub fn ln_moment(&self, k: f64, c: f64) -> f64 {
        ln_weighted_sum(self.parts(k, c).map(|(lw, _)| lw))
    }

    /// The share of `E[S^k]` carried by `S >= t`: the components' shares weighted by their
    /// parts of the moment.
    pub fn upper_share(&self, k: f64, t: f64) -> f64 {
        let parts: Vec<(f64, &Dist)> = self.parts(k, self.mean).collect();
        let total = ln_weighted_sum(parts.iter().map(|p| p.0));
        if total == f64::INFINITY {
            // An infinite moment: the components with it carry all of it.
            let infinite: Vec<&Dist> = parts
                .iter()
                .filter(|p| p.0 == f64::INFINITY)
                .map(|p| p.1)
                .collect();
            return infinite
                .iter()
                .map(|d| d.upper_share(k, t))
                .fold(0.0, f64::max);
        }
        parts
            .iter()
            .map(|(lw, d)| (lw - total).exp() * d.upper_share(k, t))
            .sum::<f64>()
            .min(1.0)
    }

    /// `(ln(w_i E_i[(S / c)^k]), component)` of the components with positive weight.
    fn parts(&self, k: f64, c: f64) -> impl Iterator<Item = (f64, &Dist)> {
        self.weights
            .iter()
            .zip(&self.components)
            .filter(|(w, _)| **w > 0.0)
            .map(move |(w, d)| (w.ln() + d.ln_moment(k, c), d))
    }

    /// Index of the component a uniform `u` in [0, 1) selects.
    #[inline(always)]
    fn pick(&self, u: f64) -> usize {
        let last = self.cumulative.len() - 1;
        self.cumulative[..last]
            .iter()
            .position(|&c| u < c)
            .unwrap_or(last)
    }

    /// One draw: a 53-bit uniform chosen against the cumulative weights picks the component,
    /// which then draws with fresh randomness of its own. (Reusing the uniform's leftover would
    /// leave a 1e-5-weight tail only ~36 bits, truncating a shape-1.1 Pareto's mean by a few
    /// percent; a second draw costs about a nanosecond.)
    #[inline]
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        let u = unit_f64(rng);
        match &self.components[self.pick(u)] {
            Dist::Pareto(d) => d.sample(rng),
            Dist::TruncatedPareto(d) => d.sample(rng),
            Dist::LogNormal(d) => d.sample(rng),
            Dist::PointMass(d) => d.value(),
            // Flattened at construction; kept for totality.
            Dist::Mixture(m) => m.sample(rng),
        }
    }
}

/// `ln sum exp(x_i)`, stable for large terms; `-inf` for no terms.
fn ln_weighted_sum(xs: impl Iterator<Item = f64>) -> f64 {
    let xs: Vec<f64> = xs.collect();
    let max = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return max;
    }
    max + xs.iter().map(|x| (x - max).exp()).sum::<f64>().ln()
}

impl fmt::Display for Mixture {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("mixture(")?;
        for (i, (w, d)) in self.weights.iter().zip(&self.components).enumerate() {
            if i > 0 {
                f.write_str(" + ")?;
            }
            write!(f, "{}*{d}", Num(*w))?;
        }
        f.write_str(")")
    }
}

impl Distribution<f64> for Mixture {
    fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        Mixture::sample(self, rng)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dist::{LogNormal, Pareto, PointMass};

    fn zero() -> Dist {
        PointMass::ZERO.into()
    }

    #[test]
    fn normalises_flattens_and_drops_zero_weights() {
        let inner = Mixture::new(vec![
            (1.0, zero()),
            (3.0, PointMass::new(4.0).unwrap().into()),
        ])
        .unwrap();
        let m = Mixture::new(vec![
            (2.0, inner.into()),
            (0.0, Pareto::new(1.0, 1.5).unwrap().into()),
            (2.0, LogNormal::new(0.0, 1.0).unwrap().into()),
        ])
        .unwrap();
        assert_eq!(m.weights(), &[0.125, 0.375, 0.5]);
        assert_eq!(m.components().len(), 3);
        // The dropped Pareto does not make the variance infinite.
        assert!(m.variance().is_some());
        assert_eq!(m.pick(0.0), 0);
        assert_eq!(m.pick(0.125), 1);
        assert_eq!(m.pick(0.999_999_999), 2);
        assert_eq!(
            m.to_string(),
            "mixture(0.125*point(value=0) + 0.375*point(value=4) + 0.5*lognormal(mu=0,sigma=1))"
        );
    }

    #[test]
    fn moments_by_total_variance() {
        let m = Mixture::new(vec![
            (0.5, zero()),
            (0.5, PointMass::new(2.0).unwrap().into()),
        ])
        .unwrap();
        assert_eq!((m.mean(), m.variance()), (1.0, Some(1.0)));
        let below = m.truncated_moments(2.0);
        assert_eq!(
            (below.probability, below.mean, below.variance),
            (0.5, 0.0, 0.0)
        );
        let heavy = Mixture::new(vec![
            (0.9, zero()),
            (0.1, Pareto::new(1.0, 1.5).unwrap().into()),
        ])
        .unwrap();
        assert_eq!(heavy.variance(), None);
        assert!((heavy.mean() - 0.3).abs() < 1e-15);
    }

    #[test]
    fn bad_weights_name_index_and_value() {
        for (w, text) in [(-0.5, "-0.5"), (f64::NAN, "NaN"), (f64::INFINITY, "inf")] {
            let e = Mixture::new(vec![(1.0, zero()), (w, zero())]).unwrap_err();
            assert!(matches!(e, Error::Component { component: 1, .. }), "{e:?}");
            let s = e.to_string();
            assert!(s.contains("component 1") && s.contains(text), "{s}");
        }
        assert!(Mixture::new(vec![]).is_err());
        assert!(Mixture::new(vec![(0.0, zero())]).is_err());
    }
}
