//! Trials that hold two outliers, which a run may never see, and what they would do to each
//! estimator.
//!
//! An estimator that suppresses single outliers (a sample at or above `n mu`, [Z] eq. 4)
//! leaves no trace of them in its errors; what it does with two in one trial is what its truth
//! may rest on. When the run expects fewer than [`TAIL_EVENTS`] such trials, its own trials
//! cannot tell (the audit's `caustic` cells at n = 16: two 2000x spikes in one trial, expected
//! 0.1 times per run, move Zirr's true bias by 0.7% where its standard error is 0.16%). The law
//! is known, so the harness asks the estimator directly: [`PAIR_TRIALS`] trials drawn with two
//! samples from the law above `n mu` at random positions and the rest from the law, each fed
//! to a fresh estimator. Their mean errors, weighted by how often such trials occur, say how
//! far the unseen trials could move each metric; a metric they could move by more than its
//! standard error is marked tail-dominated instead of printing an interval that would not
//! hold.

use super::experiment::Distribution;
use super::metrics::{CellMetrics, Interval, Metric, TAIL_EVENTS};
use super::runner::BuildFn;
use crate::estimators::EstimatorSpec;
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// Pair-conditioned trials per cell: the conditional mean errors need only their order of
/// magnitude, which 256 trials give to about 1/16 of their spread.
pub const PAIR_TRIALS: usize = 256;

/// What trials with two outliers do to one estimator at one sample count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairEffect {
    /// Probability that a trial holds two or more samples at or above `n mu` (bounded above by
    /// the number of pairs times `P(S >= n mu)^2`).
    pub probability: f64,
    /// Such trials the run expects.
    pub expected: f64,
    /// Mean over the pair-conditioned trials of the relative error `X / mu - 1`.
    pub error: f64,
    /// Mean of its square.
    pub squared_error: f64,
    /// Mean of its absolute value.
    pub abs_error: f64,
}

impl PairEffect {
    /// Whether trials the run does not expect to see could move `metric` of `cell` by more
    /// than its standard error (`mu` converts the cell's units to relative ones).
    pub fn could_move(&self, metric: Metric, cell: &CellMetrics, mu: f64) -> bool {
        if !(self.expected < TAIL_EVENTS) {
            return false;
        }
        let relative = |iv: &Interval, scale: f64| Some((iv.value / scale, iv.se? / scale));
        let (conditional, (observed, se)) = match metric {
            Metric::Bias | Metric::RelativeBias => match relative(&cell.bias, mu) {
                Some(v) => (self.error, v),
                None => return false,
            },
            Metric::Mse | Metric::RelativeRmse => match relative(&cell.mse, mu * mu) {
                Some(v) => (self.squared_error, v),
                None => return false,
            },
            // The variance moves with the squared error's mean.
            Metric::Variance => match (relative(&cell.mse, mu * mu), cell.variance.se) {
                (Some((mse, _)), Some(se)) => (self.squared_error, (mse, se / (mu * mu))),
                _ => return false,
            },
            Metric::MeanAbsRelError => match relative(&cell.mean_abs_rel_error, 1.0) {
                Some(v) => (self.abs_error, v),
                None => return false,
            },
            _ => return false,
        };
        let shift = self.probability * (conditional - observed).abs();
        shift.is_finite() && shift > se
    }
}

/// Every estimator's [`PairEffect`] at sample count `n` (estimator order), or `None` when the
/// law has no mass at or above `n mu` or the run expects enough such trials to see them.
pub fn effects(
    d: &Distribution,
    estimators: &[EstimatorSpec],
    build: BuildFn,
    n: usize,
    trials: u64,
    seed: u64,
) -> Vec<Option<PairEffect>> {
    let none = || vec![None; estimators.len()];
    let mu = d.dist.mean();
    let level = n as f64 * mu;
    let q = d.dist.mass_from(level);
    let nf = n as f64;
    let probability = (nf * (nf - 1.0) / 2.0 * q * q).min(1.0);
    let expected = probability * trials as f64;
    if n < 2 || !(q > 0.0) || !(expected < TAIL_EVENTS) {
        return none();
    }
    let above = d.dist.above(level);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut samples = vec![0.0; n];
    let mut sums = vec![[0.0f64; 3]; estimators.len()];
    for _ in 0..PAIR_TRIALS {
        for s in samples.iter_mut() {
            *s = d.dist.sample(&mut rng);
        }
        let first = rng.random_range(0..n);
        let second = (first + rng.random_range(1..n)) % n;
        samples[first] = above.sample(&mut rng);
        samples[second] = above.sample(&mut rng);
        for (spec, sum) in estimators.iter().zip(&mut sums) {
            let Ok(mut e) = build(spec) else {
                return none();
            };
            e.push_slice(&samples);
            let Ok(x) = e.estimate() else {
                return none();
            };
            let err = x / mu - 1.0;
            sum[0] += err;
            sum[1] += err * err;
            sum[2] += err.abs();
        }
    }
    let k = PAIR_TRIALS as f64;
    sums.into_iter()
        .map(|[e, e2, a]| {
            Some(PairEffect {
                probability,
                expected,
                error: e / k,
                squared_error: e2 / k,
                abs_error: a / k,
            })
        })
        .collect()
}
