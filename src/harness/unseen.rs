//! Trials a run may never see, and what they would do to each estimator.
//!
//! Two kinds, both asked of the estimator directly because the law is known:
//!
//! - **Two outliers in one trial** ([`PairEffect`]). An estimator that suppresses single
//!   outliers (a sample at or above `n mu`, [Z] eq. 4) leaves no trace of them in its errors;
//!   what it does with two in one trial is what its truth may rest on. When the run expects
//!   fewer than [`TAIL_EVENTS`] such trials, its own trials cannot tell (the audit's `caustic`
//!   cells at n = 16: two 2000x spikes in one trial, expected 0.1 times per run, move Zirr's
//!   true bias by 0.7% where its standard error is 0.16%). [`PAIR_TRIALS`] trials drawn with
//!   two samples from the law above `n mu` at random positions and the rest from the law, each
//!   fed to a fresh estimator, give mean errors; weighted by how often such trials occur, they
//!   say how far the unseen trials could move each metric's value.
//! - **The tail the run reaches about once** ([`Unseen`]). A run's standard error is its own
//!   trials' spread, so it misses whatever the run's rarest trials would add. For one and for
//!   two samples in the law's tail, the level a run of `T` trials exceeds about once (`T C(n,
//!   k) q^k = 1` with `q = P(S >= level)`) is simulated the same way; the spread those trials
//!   add to each metric, against the spread the run saw, says whether the run's interval could
//!   hold. An estimator that keeps two samples of a power-law tail has errors with about twice
//!   the law's tail index: `pajot-rot` on `mirror-lit` (index 1.2) at n = 256, or
//!   `pajot-hybrid` on `infinite-variance` (1.5) at n = 64, whose squared errors have no finite
//!   variance. Their runs' intervals covered 89% and 84% of 400 seeds, and which seeds the
//!   run's own top-share test marked depended on whether they saw those trials, so the seeds
//!   left printing an interval were the ones that had not.
//!
//! A metric either kind could move by more than its standard error, or whose spread the
//! unseen trials would raise by more than [`UNSEEN_SHARE`], is marked tail-dominated instead of
//! printing an interval that would not hold.

use super::experiment::Distribution;
use super::law::threshold_for_count;
use super::metrics::{CellMetrics, Interval, Metric, TAIL_EVENTS};
use super::runner::BuildFn;
use crate::estimators::EstimatorSpec;
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;

/// Conditioned trials per cell and kind: the conditional errors and spreads need only their
/// order of magnitude, which 256 trials give to about 1/16 of their spread.
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

/// What the run cannot see, for one cell: its pair effect and its unseen tail strata.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TailEffects {
    /// Trials with two outliers, when the run expects too few of them ([`PairEffect`]).
    pub pairs: Option<PairEffect>,
    /// Trials with one or two samples beyond the level the run reaches about once.
    pub unseen: Vec<Unseen>,
}

impl TailEffects {
    /// Whether what the run cannot see makes `metric`'s interval for `cell` untrustworthy.
    pub fn dominate(&self, metric: Metric, cell: &CellMetrics, mu: f64) -> bool {
        self.pairs.is_some_and(|p| p.could_move(metric, cell, mu))
            || self.unseen.iter().any(|u| u.widens(metric, cell, mu))
    }
}

/// Share of a run's observed spread that trials it expects about once may add before its
/// interval stops holding: at a quarter more variance the printed standard error is 11% too
/// small and a 95% interval covers about 92.5%, below the calibration's 93% floor.
pub const UNSEEN_SHARE: f64 = 0.25;

/// Trials holding `k` samples at or above `level`, which the run expects about once, and the
/// relative errors `X / mu - 1` one estimator makes on [`PAIR_TRIALS`] of them.
#[derive(Debug, Clone, PartialEq)]
pub struct Unseen {
    /// Samples in the tail (1 or 2).
    pub k: usize,
    /// The level.
    pub level: f64,
    /// `C(n, k) P(S >= level)^k`, the probability of such a trial (an upper bound).
    pub probability: f64,
    /// The estimator's relative errors on the simulated trials.
    pub errors: Vec<f64>,
}

impl Unseen {
    /// Whether these trials would add more than [`UNSEEN_SHARE`] of the per-trial spread that
    /// `metric`'s standard error rests on: the squared deviation from the run's value of the
    /// quantity the metric averages (the error for bias, its square for the MSE, its absolute
    /// value for the mean absolute error, the squared deviation for the variance).
    pub fn widens(&self, metric: Metric, cell: &CellMetrics, mu: f64) -> bool {
        let t = cell.trials as f64;
        let mu2 = mu * mu;
        let (iv, scale) = match metric {
            Metric::Bias | Metric::RelativeBias => (&cell.bias, mu),
            Metric::Variance => (&cell.variance, mu2),
            Metric::Mse | Metric::RelativeRmse => (&cell.mse, mu2),
            Metric::MeanAbsRelError => (&cell.mean_abs_rel_error, 1.0),
            _ => return false,
        };
        let Some(se) = iv.se else {
            return false;
        };
        let observed = (se / scale).powi(2) * t;
        let centre = iv.value / scale;
        let bias = cell.bias.value / mu;
        let quantity = |e: f64| match metric {
            Metric::Bias | Metric::RelativeBias => e,
            Metric::Variance => (e - bias).powi(2),
            Metric::Mse | Metric::RelativeRmse => e * e,
            _ => e.abs(),
        };
        let added = self.probability
            * self
                .errors
                .iter()
                .map(|&e| (quantity(e) - centre).powi(2))
                .sum::<f64>()
            / self.errors.len() as f64;
        // An infinite or NaN addition (errors beyond f64) is what the run cannot have seen.
        !(added <= UNSEEN_SHARE * observed)
    }
}

/// Every estimator's [`TailEffects`] at sample count `n` (estimator order). Pairs at or above
/// `n mu` are simulated when the run expects fewer than [`TAIL_EVENTS`] of them; the unseen
/// strata whenever the law has mass beyond their level. An estimator that cannot be built or
/// read leaves its cell without effects (the run itself reports the error).
pub fn effects(
    d: &Distribution,
    estimators: &[EstimatorSpec],
    build: BuildFn,
    n: usize,
    trials: u64,
    seed: u64,
) -> Vec<TailEffects> {
    let mut out = vec![TailEffects::default(); estimators.len()];
    if let Some(pairs) = pair_effects(d, estimators, build, n, trials, seed) {
        for (o, p) in out.iter_mut().zip(pairs) {
            o.pairs = Some(p);
        }
    }
    for k in 1..=2usize.min(n) {
        let Some(strata) = unseen(d, estimators, build, n, k, trials, seed) else {
            continue;
        };
        for (o, u) in out.iter_mut().zip(strata) {
            o.unseen.push(u);
        }
    }
    out
}

/// Every estimator's [`PairEffect`] at `n`, or `None` when the law has no mass at or above
/// `n mu` or the run expects enough such trials to see them.
fn pair_effects(
    d: &Distribution,
    estimators: &[EstimatorSpec],
    build: BuildFn,
    n: usize,
    trials: u64,
    seed: u64,
) -> Option<Vec<PairEffect>> {
    let mu = d.dist.mean();
    let level = n as f64 * mu;
    let q = d.dist.mass_from(level);
    let nf = n as f64;
    let probability = (nf * (nf - 1.0) / 2.0 * q * q).min(1.0);
    let expected = probability * trials as f64;
    if n < 2 || !(q > 0.0) || !(expected < TAIL_EVENTS) {
        return None;
    }
    let errors = simulate(d, estimators, build, n, 2, level, seed)?;
    let k = PAIR_TRIALS as f64;
    Some(
        errors
            .into_iter()
            .map(|errs| PairEffect {
                probability,
                expected,
                error: errs.iter().sum::<f64>() / k,
                squared_error: errs.iter().map(|e| e * e).sum::<f64>() / k,
                abs_error: errs.iter().map(|e| e.abs()).sum::<f64>() / k,
            })
            .collect(),
    )
}

/// Every estimator's [`Unseen`] stratum of `k` tail samples at `n`, or `None` when the law
/// has no mass beyond the level a run of `trials` trials reaches about once.
fn unseen(
    d: &Distribution,
    estimators: &[EstimatorSpec],
    build: BuildFn,
    n: usize,
    k: usize,
    trials: u64,
    seed: u64,
) -> Option<Vec<Unseen>> {
    let ways = if k == 1 {
        n as f64
    } else {
        n as f64 * (n as f64 - 1.0) / 2.0
    };
    // The smallest level with `P(S >= level) <= q`, where `trials ways q^k = 1`.
    let q = (1.0 / (trials as f64 * ways)).powf(1.0 / k as f64);
    let level = threshold_for_count(&d.dist, 1.0 / q, 1.0);
    let mass = d.dist.mass_from(level);
    if !(mass > 0.0) {
        return None;
    }
    let probability = (ways * mass.powi(k as i32)).min(1.0);
    // Its own stream: the pair simulation above may use `seed` at another level.
    let salt = 0x756e_7365_656e_0000 | k as u64;
    let errors = simulate(d, estimators, build, n, k, level, seed ^ salt)?;
    Some(
        errors
            .into_iter()
            .map(|errors| Unseen {
                k,
                level,
                probability,
                errors,
            })
            .collect(),
    )
}

/// Samples held at once by [`simulate`] (8 MB): its memory stays bounded for any `n`.
const SIMULATED_SAMPLES: usize = 1 << 20;

/// Per estimator, its relative errors on [`PAIR_TRIALS`] trials whose `k` (1 or 2) samples at
/// random positions come from the law above `level` and the rest from the law. The trials are
/// drawn in batches of at most [`SIMULATED_SAMPLES`] samples, one stream in trial order, and the
/// estimators run on each batch in parallel (the largest checkpoint holds most of the work, so
/// parallel checkpoints alone leave a core idle); the errors do not depend on the thread count.
fn simulate(
    d: &Distribution,
    estimators: &[EstimatorSpec],
    build: BuildFn,
    n: usize,
    k: usize,
    level: f64,
    seed: u64,
) -> Option<Vec<Vec<f64>>> {
    let batch = (SIMULATED_SAMPLES / n).clamp(1, PAIR_TRIALS);
    simulate_in_batches(d, estimators, build, n, k, level, seed, batch)
}

/// [`simulate`] with `batch` trials drawn at a time; the errors do not depend on `batch`.
#[allow(clippy::too_many_arguments)]
fn simulate_in_batches(
    d: &Distribution,
    estimators: &[EstimatorSpec],
    build: BuildFn,
    n: usize,
    k: usize,
    level: f64,
    seed: u64,
    batch: usize,
) -> Option<Vec<Vec<f64>>> {
    let mu = d.dist.mean();
    let above = d.dist.above(level);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut samples = vec![0.0; n * batch];
    let mut errors = vec![Vec::with_capacity(PAIR_TRIALS); estimators.len()];
    let mut done = 0;
    while done < PAIR_TRIALS {
        let trials = batch.min(PAIR_TRIALS - done);
        let drawn = &mut samples[..n * trials];
        for trial in drawn.chunks_exact_mut(n) {
            d.dist.fill(&mut rng, trial);
            let first = rng.random_range(0..n);
            if k == 2 {
                let second = (first + rng.random_range(1..n)) % n;
                trial[first] = above.sample(&mut rng);
                trial[second] = above.sample(&mut rng);
            } else {
                trial[first] = above.sample(&mut rng);
            }
        }
        let drawn = &samples[..n * trials];
        errors
            .par_iter_mut()
            .zip(estimators)
            .try_for_each(|(errs, spec)| {
                // One estimator a batch, reset between trials (tests/hard_cases.rs checks that
                // a reset estimator is a new one), so no trial pays for an allocation.
                let mut e = build(spec).ok()?;
                for trial in drawn.chunks_exact(n) {
                    e.reset();
                    e.push_slice(trial);
                    errs.push(e.estimate().ok()? / mu - 1.0);
                }
                Some(())
            })?;
        done += trials;
    }
    Some(errors)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dist::Preset;

    /// Memory is bounded by drawing the trials in batches (an `n` of a million would otherwise
    /// hold 256 million samples); the batch size must not change a single error. Fails if a
    /// batch restarts the stream, drops or repeats a trial, or reorders the errors.
    #[test]
    fn batches_do_not_change_the_errors() {
        let d = Distribution {
            label: "glossy".into(),
            dist: Preset::Glossy.dist(),
        };
        let estimators: Vec<EstimatorSpec> = ["mean", "mon:M=5", "zirr", "pajot-rot:learn=8"]
            .iter()
            .map(|s| s.parse().unwrap())
            .collect();
        let build: BuildFn = |s| s.build();
        for k in [1, 2] {
            let whole = simulate_in_batches(&d, &estimators, build, 33, k, 20.0, 7, PAIR_TRIALS);
            let whole = whole.unwrap();
            assert_eq!(whole.len(), estimators.len());
            assert!(whole.iter().all(|e| e.len() == PAIR_TRIALS));
            for batch in [1, 7, 100] {
                let parts = simulate_in_batches(&d, &estimators, build, 33, k, 20.0, 7, batch);
                assert_eq!(parts.as_ref(), Some(&whole), "batch {batch}, k {k}");
            }
        }
    }
}
