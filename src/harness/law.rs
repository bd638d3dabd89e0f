//! What the known law says about the plain mean's cells, which the trials alone cannot: the
//! sampling law of its grand mean (for an interval and an unbiasedness test that hold on heavy
//! tails), its exact variance, and whether a metric's spread rests on events too rare for the
//! run to have seen.
//!
//! **The grand mean's null.** Over `T` trials of `n` samples the mean's estimates average
//! `N = T n` independent samples. Split the law at a threshold `t` that `N` samples exceed
//! about [`TAIL_COUNT`] times: below it, the body's sum is normal to a good approximation (its
//! moments are exact, from [`Dist::truncated_moments`]); above it, the count is binomial and the
//! values are drawn from the law's own tail ([`Dist::above`]), which is where a normal
//! approximation of the whole sum fails (the audit of issue 12 measured a 145-fold excess of
//! small p-values on `mirror-lit`). Each of [`REPLICATES`] draws of the tail leaves the body's
//! normal law in closed form, so the null CDF is an average of normal CDFs: smooth, and exact
//! up to the body's normality and the Monte Carlo error of the average.

use crate::dist::Dist;
use crate::harness::metrics::{Caveat, CellMetrics, Interval, Metric, TAIL_EVENTS, Z};
use crate::harness::unseen::TailEffects;
use rand::SeedableRng;
use rand_distr::{Binomial, Distribution};
use rand_xoshiro::Xoshiro256PlusPlus;

/// Tail draws of the null expected per replicate: enough that the body below the threshold is
/// light (its sum's skewness falls as the threshold does), few enough to stay cheap.
pub const TAIL_COUNT: f64 = 100.0;

/// Replicates of the tail in the null: the p-value's Monte Carlo relative error is about
/// `1/sqrt(REPLICATES p)` where the tail decides it, and far less where the body does.
pub const REPLICATES: usize = 20_000;

/// A metric's spread is tail-dominated when more than this share of it comes from events
/// expected fewer than [`TAIL_EVENTS`] times in the run.
pub const DOMINANCE: f64 = 0.5;

/// The sampling law of `D = grand mean / mu - 1` for an unbiased mean: a mixture of normals,
/// one per replicate of the tail.
#[derive(Debug, Clone)]
pub struct GrandMeanNull {
    /// Per replicate, the centre and standard deviation of `D` given that tail draw.
    parts: Vec<(f64, f64)>,
}

/// The threshold `t` that `samples` draws exceed (`S >= t`) about `count` times: the smallest
/// `t` (to about 1e-12 in `ln t`) with `samples P(S >= t) <= count`, by a fixed number of
/// bisection steps on `ln t` within 30 decades of the mean (so laws at 1e300 or 1e-300, whose
/// bracket would overflow or underflow as plain numbers, are handled and the search ends).
pub fn threshold_for_count(dist: &Dist, samples: f64, count: f64) -> f64 {
    let mu = dist.mean();
    let (low_support, high_support) = dist.support();
    let expected = |ln_t: f64| samples * dist.mass_from(ln_t.exp());
    let span = 30.0 * std::f64::consts::LN_10;
    let mut lo = mu.ln() - span;
    let mut hi = mu.ln() + span;
    if low_support > 0.0 {
        lo = lo.max(low_support.ln());
    }
    if high_support.is_finite() {
        hi = hi.min(high_support.ln());
    }
    if expected(lo) <= count {
        return lo.exp();
    }
    if expected(hi) > count {
        // Only the top of a bounded support (an atom) is that frequent: nothing lies above it.
        return hi.exp() * (1.0 + 1e-12);
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if expected(mid) <= count {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi.exp()
}

impl GrandMeanNull {
    /// The null of the mean of `samples` draws of `dist`, simulated with `seed`.
    pub fn new(dist: &Dist, samples: u64, seed: u64) -> Self {
        let mu = dist.mean();
        let n = samples as f64;
        let t = threshold_for_count(dist, n, TAIL_COUNT);
        let p_tail = dist.mass_from(t).clamp(0.0, 1.0);
        let body = dist.truncated_moments(t);
        let (m_body, v_body) = if body.probability > 0.0 {
            (body.mean / mu, body.variance / mu / mu)
        } else {
            (0.0, 0.0)
        };
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let count = Binomial::new(samples, p_tail).ok();
        let above = dist.above(t);
        let parts = (0..REPLICATES)
            .map(|_| {
                let k = count.as_ref().map_or(0, |b| b.sample(&mut rng));
                let tail: f64 = (0..k).map(|_| above.sample(&mut rng) / mu).sum();
                let rest = (samples - k) as f64;
                let centre = (rest * m_body + tail) / n - 1.0;
                let sd = (rest * v_body).sqrt() / n;
                (centre, sd)
            })
            .collect();
        GrandMeanNull { parts }
    }

    /// `P(D <= x)`.
    pub fn cdf(&self, x: f64) -> f64 {
        let sum: f64 = self.parts.iter().map(|&(c, s)| normal_cdf(x, c, s)).sum();
        sum / self.parts.len() as f64
    }

    /// `P(|D| >= |d|)`: the two-sided p-value of an observed relative bias `d`.
    pub fn p_two_sided(&self, d: f64) -> f64 {
        let d = d.abs();
        let sum: f64 = self
            .parts
            .iter()
            .map(|&(c, s)| normal_cdf(-d, c, s) + (1.0 - normal_cdf(d, c, s)))
            .sum();
        (sum / self.parts.len() as f64).min(1.0)
    }

    /// The `q`-quantile of `D`, by bisection on [`GrandMeanNull::cdf`].
    pub fn quantile(&self, q: f64) -> f64 {
        let spread = self.parts.iter().map(|p| p.1).fold(0.0, f64::max);
        let mut lo = self.parts.iter().map(|p| p.0).fold(f64::INFINITY, f64::min) - 10.0 * spread;
        let mut hi = self
            .parts
            .iter()
            .map(|p| p.0)
            .fold(f64::NEG_INFINITY, f64::max)
            + 10.0 * spread;
        for _ in 0..64 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if self.cdf(mid) < q {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }

    /// The 95% interval of the relative bias given the observed `d`: the pivot `D - bias` has
    /// the null's law, so `[d - q(0.975), d - q(0.025)]`.
    pub fn bias_interval(&self, d: f64) -> (f64, f64) {
        (d - self.quantile(0.975), d - self.quantile(0.025))
    }
}

/// `Phi((x - centre) / sd)`, a step when `sd` is 0.
fn normal_cdf(x: f64, centre: f64, sd: f64) -> f64 {
    if sd > 0.0 {
        half_erfc(-(x - centre) / (sd * std::f64::consts::SQRT_2))
    } else if x >= centre {
        1.0
    } else {
        0.0
    }
}

/// `erfc(z) / 2`, without calling `erfc` where its value is exactly 0 or 2, as it is for the
/// null's normals far from a quantile's bisection point: `erfc` was a third of a 200-trial
/// throughput run, whose fixed cost this took from 0.20 to 0.12 s. Bit-identical to the call (`half_erfc_is_statrs_bit_for_bit`): statrs
/// computes `erfc(z)` from `exp(-z^2)`, which is 0 for `z >= 28`, and `erfc(-z) = 2 - erfc(z)`,
/// which rounds to 2 once `erfc(z) < 2^-53`, true for `z >= 6`.
fn half_erfc(z: f64) -> f64 {
    if z >= 28.0 {
        0.0
    } else if z <= -6.0 {
        1.0
    } else {
        0.5 * statrs::function::erf::erfc(z)
    }
}

/// Everything the law says about the mean's cell at one sample count.
#[derive(Debug, Clone)]
pub struct MeanLaw {
    /// Trials `T` behind the grand mean.
    pub trials: u64,
    /// `Var[mean of n] / mu^2`, `None` when infinite.
    pub relative_variance: Option<f64>,
    /// The null of the grand mean; `None` for a law without spread, or at a scale beyond
    /// 1e±150.
    pub null: Option<GrandMeanNull>,
    /// The share of the trial mean's second and fourth moments carried by samples the run
    /// expects fewer than [`TAIL_EVENTS`] times.
    pub dominance: [f64; 2],
}

impl MeanLaw {
    /// The mean of `n` samples over `trials` trials of `dist`; `seed` drives the null's tail.
    pub fn new(dist: &Dist, n: usize, trials: u64, seed: u64) -> Self {
        let samples = trials * n as u64;
        let rel_var = dist.relative_variance();
        let spread = rel_var.is_none_or(|v| v > 0.0);
        let t = threshold_for_count(dist, samples as f64, TAIL_EVENTS);
        let mu = dist.mean();
        let share2 = dist.upper_share(2.0, t);
        // The fourth central moment of a mean of n is (m4 + 3 (n - 1) m2^2) / n^3: the tail
        // weighs in through m4 only.
        let m4 = dist.ln_moment(4.0, mu).exp();
        let m2 = dist.ln_moment(2.0, mu).exp();
        let nf = n as f64;
        let share4 = if m4.is_infinite() {
            dist.upper_share(4.0, t)
        } else {
            let tail = dist.upper_share(4.0, t) * m4;
            tail / (m4 + 3.0 * (nf - 1.0) * m2 * m2)
        };
        MeanLaw {
            trials,
            relative_variance: rel_var.map(|v| v / nf),
            // The body's moments are taken in the law's own units: at scales beyond 1e±150
            // their squares under- or overflow, and the null is left out (the check falls back
            // to the exact standard error).
            null: (spread && (1e-150..1e150).contains(&mu))
                .then(|| GrandMeanNull::new(dist, samples, seed)),
            dominance: [share2, share4],
        }
    }

    /// The mean's bias interval in the law's units, from the null; the observed one (which
    /// is then exact up to rounding) for a law without spread.
    pub fn bias_interval(&self, observed: Interval, mu: f64) -> Interval {
        let Some(null) = &self.null else {
            return observed;
        };
        let d = observed.value / mu;
        let (lo, hi) = null.bias_interval(d);
        // The exact standard error of the grand mean (sigma / sqrt(T n)) where finite, else
        // the interval's width over 2 Z.
        let exact = self
            .relative_variance
            .map(|v| (v / self.trials as f64).sqrt());
        Interval {
            value: observed.value,
            low: Some(lo * mu),
            high: Some(hi * mu),
            se: Some(exact.map_or((hi - lo) / (2.0 * Z), |s| s) * mu),
        }
    }
}

/// Which of a cell's metrics the law or the run says cannot carry an interval: infinite truths
/// first, then tail-dominance (law-based for the plain mean, and for every estimator's paired
/// differences against it; the run's own most extreme trials for every estimator). `law` is
/// what the law says about the plain mean at this n (`None` when the experiment does not run
/// it); `is_mean` says whether this cell is the plain mean's.
pub fn caveat(
    metric: Metric,
    cell: &CellMetrics,
    law: Option<&MeanLaw>,
    tail: Option<&TailEffects>,
    mu: f64,
    is_mean: bool,
    infinite_law_variance: bool,
) -> Option<Caveat> {
    match metric {
        Metric::Variance | Metric::Mse | Metric::RelativeRmse | Metric::ExactVariance
            if is_mean && infinite_law_variance =>
        {
            return Some(Caveat::InfiniteTruth);
        }
        Metric::PairedMseVsMean if !is_mean && infinite_law_variance => {
            return Some(Caveat::InfiniteTruth);
        }
        _ => {}
    }
    // What the run cannot see: trials with two outliers, and the tail it reaches about once
    // (the mean's own rare events are the law's dominance below).
    if !is_mean && tail.is_some_and(|t| t.dominate(metric, cell, mu)) {
        return Some(Caveat::TailDominated);
    }
    let top = &cell.top_share;
    let law_share = |power: usize| law.map_or(0.0, |l| l.dominance[power]);
    // (the law's share that applies, the run's top share) behind each metric.
    let (law, run) = match metric {
        // The mean's bias interval comes from the law's own null: it holds on any tail; its
        // paired differences against itself are exactly 0.
        Metric::Bias
        | Metric::RelativeBias
        | Metric::PairedAbsRelVsMean
        | Metric::PairedMseVsMean
            if is_mean =>
        {
            return None;
        }
        Metric::Bias | Metric::RelativeBias => (0.0, top.deviation[0]),
        Metric::Variance => (if is_mean { law_share(1) } else { 0.0 }, top.deviation[1]),
        Metric::Mse | Metric::RelativeRmse => {
            (if is_mean { law_share(1) } else { 0.0 }, top.error[1])
        }
        Metric::MeanAbsRelError => (if is_mean { law_share(0) } else { 0.0 }, top.error[0]),
        // A difference against the mean carries the mean's own rare errors.
        Metric::PairedAbsRelVsMean => (law_share(0), top.paired[0]),
        Metric::PairedMseVsMean => (law_share(1), top.paired[1]),
        _ => return None,
    };
    (law > DOMINANCE || run > DOMINANCE).then_some(Caveat::TailDominated)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dist::{LogNormal, preset};

    /// The shortcut must not change a bit: on both saturated ranges, densely, and across the
    /// thresholds, against the call it skips.
    #[test]
    fn half_erfc_is_statrs_bit_for_bit() {
        let grid = (0..=200_000).map(|i| -300.0 + 600.0 * (i as f64 / 200_000.0));
        // The 64 doubles on each side of each threshold.
        let edges = [-6.0f64, 28.0].into_iter().flat_map(|e| {
            (-64..=64).map(move |d| f64::from_bits(e.to_bits().wrapping_add_signed(d)))
        });
        for z in grid
            .chain(edges)
            .chain([f64::NAN, f64::INFINITY, f64::NEG_INFINITY])
        {
            let want = 0.5 * statrs::function::erf::erfc(z);
            assert_eq!(half_erfc(z).to_bits(), want.to_bits(), "z = {z:e}");
        }
    }

    #[test]
    fn threshold_search_ends_at_extreme_scales() {
        for mu in [-690.0, 690.0] {
            let d: Dist = LogNormal::new(mu, 1.0).unwrap().into();
            let t = threshold_for_count(&d, 1e6, 10.0);
            assert!(
                t > 0.0 && (1e6 * d.mass_from(t) / 10.0 - 1.0).abs() < 1e-6,
                "{mu}: {t}"
            );
        }
    }

    #[test]
    fn threshold_matches_the_tail_it_was_asked_for() {
        let d: Dist = LogNormal::new(0.0, 1.0).unwrap().into();
        let t = threshold_for_count(&d, 1e6, 10.0);
        assert!((1e6 * d.mass_from(t) / 10.0 - 1.0).abs() < 1e-6);
    }

    /// On a lognormal with a light body the null is nearly normal with the exact SE: its 97.5%
    /// quantile is 1.96 sigma / sqrt(N) within the Monte Carlo error (20000 replicates; the
    /// tail part is small, so the error is well under 1%).
    #[test]
    fn light_law_null_is_normal_with_the_exact_standard_error() {
        let d = preset("diffuse").unwrap();
        let samples = 16 * 4096;
        let null = GrandMeanNull::new(&d, samples, 7);
        let se = (d.relative_variance().unwrap() / samples as f64).sqrt();
        let q = null.quantile(0.975);
        assert!(
            (q / (1.959964 * se) - 1.0).abs() < 0.01,
            "{q} vs {}",
            1.96 * se
        );
        let p = null.p_two_sided(1.959964 * se);
        assert!((p - 0.05).abs() < 0.002, "{p}");
    }

    /// On mirror-lit at n = 16 and T = 4096 the grand mean is far from normal: most runs see
    /// none of the rare large samples, so the null's median lies below 0 and its upper tail is
    /// long. The normal approximation's 99.99% quantile is 3.72 SE; the null's is larger.
    #[test]
    fn heavy_law_null_is_skewed() {
        let d = preset("mirror-lit").unwrap();
        let samples = 16 * 4096;
        let null = GrandMeanNull::new(&d, samples, 7);
        let se = (d.relative_variance().unwrap() / samples as f64).sqrt();
        assert!(
            null.quantile(0.5) < -0.05 * se,
            "{}",
            null.quantile(0.5) / se
        );
        assert!(
            null.quantile(0.9999) > 4.5 * se,
            "{}",
            null.quantile(0.9999) / se
        );
    }
}
