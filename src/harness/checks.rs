//! Claims about estimators checked against a run, each a hypothesis test whose null is "the
//! claim holds"; Holm's step-down procedure across the whole family keeps the probability
//! that any check fails while every claim holds at `family_alpha`.
//!
//! - **Unbiased mean**: the grand mean's relative bias against the law's own null
//!   ([`super::law::GrandMeanNull`]: a normal body and the exact tail, simulated), not a
//!   z-test, whose normal grand mean is wrong on the heavy tails this project exists for. A law
//!   without spread is checked against a rounding tolerance instead.
//! - **Chebyshev** for the mean: `P(|mean - mu| > k sigma/sqrt(n)) <= 1/k^2`, exact binomial
//!   test of the exceedance count.
//! - **Median-of-means deviation bound**: with `M = ceil(8 ln(1/delta))` sets,
//!   `P(|MoN - mu| > sigma sqrt(32 ln(1/delta)/n)) <= delta` (finite variance, `n >= M`),
//!   exact binomial test.
//! - **Zirr et al.'s variance bound** (their eq. 10): `Var F' < Var[S | S < n mu/kappa]/n +
//!   mu^2/kappa`, with the exact truncated variance; one-sided z-test of the sample variance.
//! - **Firefly rate** of each robust estimator at the largest n: below a ceiling (exact
//!   binomial test) and not above the mean's on the same trials (exact McNemar test).
//!
//! The Chebyshev and median-of-means bounds hold for every law, so on a given law they are
//! loose: each such check states the smallest exceedance rate it would catch ([`CheckResult::detects`]).
//! A NaN p-value fails its check. Checks the configuration asks for but the experiment cannot
//! run are listed by [`super::claims::unreachable`].

use super::claims::{CheckKind, ROUNDING_TOLERANCE};
use super::experiment::Experiment;
use super::law::GrandMeanNull;
use super::runner::RunOutput;
use crate::estimators::{EstimatorSpec, MeanSpec, ZirrSpec};
use serde::Serialize;
use statrs::distribution::{Binomial, ContinuousCDF, DiscreteCDF, Normal};

/// Outcome of one check.
#[derive(Debug, Clone, Serialize)]
pub struct CheckResult {
    /// Which claim.
    pub check: CheckKind,
    /// Distribution label.
    pub distribution: String,
    /// Estimator spec string.
    pub estimator: String,
    /// Sample count.
    pub n: usize,
    /// The claim, in words with numbers.
    pub claim: String,
    /// What was observed.
    pub observed: String,
    /// p-value under the claim (NaN fails the check, whatever Holm's order).
    pub p_value: f64,
    /// Holm's threshold this p-value was compared with (`None` once a smaller p passed).
    pub holm_alpha: Option<f64>,
    /// Whether the claim survived.
    pub passed: bool,
    /// Whether a failure fails the run (false: the check is a reported finding).
    pub gating: bool,
    /// The smallest defect the check could have caught here, where that is far from what a
    /// correct estimator shows (a bound that is loose for this law).
    pub detects: Option<String>,
}

impl CheckResult {
    /// A failure that fails the run.
    pub fn fails_run(&self) -> bool {
        !self.passed && self.gating
    }
}

fn normal_sf(z: f64) -> f64 {
    let std = Normal::new(0.0, 1.0).expect("standard normal");
    std.sf(z)
}

/// `P(Bin(trials, p) >= k)`.
fn binomial_upper(k: u64, trials: u64, p: f64) -> f64 {
    if k == 0 {
        return 1.0;
    }
    match Binomial::new(p, trials) {
        Ok(b) => b.sf(k - 1),
        Err(_) => f64::NAN,
    }
}

/// Evaluates every configured check on a run and applies Holm's procedure.
pub fn evaluate(exp: &Experiment, out: &RunOutput) -> Vec<CheckResult> {
    let cfg = &exp.file.checks;
    let cps = &exp.file.checkpoints;
    let t = out.trials;
    let mut results = Vec::new();
    // (index, bound, observed rate) of the deviation-bound checks, whose power is stated.
    let mut bounds = Vec::new();
    let robust: Vec<EstimatorSpec> = cfg.robust.iter().filter_map(|r| r.parse().ok()).collect();
    for (d, dist) in out.dists.iter().zip(&exp.distributions) {
        for (e, spec) in exp.estimators.iter().enumerate() {
            for (i, &n) in cps.iter().enumerate() {
                let cell = &d.cells[e * cps.len() + i];
                let mut push = |check: CheckKind,
                                claim: String,
                                observed: String,
                                p_value: f64,
                                detects: Option<String>| {
                    results.push(CheckResult {
                        check,
                        distribution: d.label.clone(),
                        estimator: spec.to_string(),
                        n,
                        claim,
                        observed,
                        p_value,
                        holm_alpha: None,
                        passed: true,
                        gating: !cfg.findings.contains(&check),
                        detects,
                    });
                    results.len() - 1
                };
                // Relative units (X / mu): finite at any scale of the law.
                let moments = cell.relative_estimate_moments();
                if let (EstimatorSpec::Mean(MeanSpec), true) = (spec, cfg.unbiased_mean) {
                    let bias = moments.mean() - 1.0;
                    let null = d.mean_laws[i].as_ref().and_then(|l| l.null.as_ref());
                    let rel_var = dist.dist.relative_variance();
                    if let Some((observed, p_value)) = unbiased(bias, null, rel_var, n as u64 * t) {
                        push(
                            CheckKind::Unbiased,
                            "E[mean] = mu".into(),
                            observed,
                            p_value,
                            None,
                        );
                    }
                }
                if let Some((threshold, exceed)) = cell.exceedances() {
                    let (check, bound) = match spec {
                        EstimatorSpec::Mean(MeanSpec) => {
                            (CheckKind::Chebyshev, 1.0 / (cfg.chebyshev_k.powi(2)))
                        }
                        _ => (CheckKind::MonBound, cfg.mon_delta),
                    };
                    let rate = exceed as f64 / t as f64;
                    let at = push(
                        check,
                        format!("P(|X - mu| > {threshold:.4e}) <= {bound:.4}"),
                        format!("{exceed}/{t} = {rate:.4}"),
                        binomial_upper(exceed, t, bound),
                        None,
                    );
                    bounds.push((at, bound, rate));
                }
                if let (EstimatorSpec::Zirr(ZirrSpec(p)), true) = (spec, cfg.zirr_bound) {
                    let trunc = dist.dist.truncated_moments(n as f64 * d.mu / p.kappa);
                    // Bound and variance both divided by mu^2.
                    let bound = trunc.variance / d.mu / d.mu / n as f64 + 1.0 / p.kappa;
                    let s2 = moments.sample_variance();
                    let m4 = moments.m4();
                    let tf = t as f64;
                    let se = ((m4 - s2 * s2 * (tf - 3.0) / (tf - 1.0)) / tf)
                        .max(0.0)
                        .sqrt();
                    let p_value = if se > 0.0 {
                        normal_sf((s2 - bound) / se)
                    } else if s2 > bound {
                        0.0
                    } else {
                        1.0
                    };
                    push(
                        CheckKind::ZirrBound,
                        format!("Var/mu^2 < {bound:.4e} (eq. 10)"),
                        format!("Var/mu^2 = {s2:.4e} ± {se:.2e}"),
                        p_value,
                        None,
                    );
                }
                if i + 1 == cps.len() && robust.contains(spec) {
                    let fireflies = cell.fireflies();
                    push(
                        CheckKind::FireflyCeiling,
                        format!("P(X > (1+tau) mu) <= {}", cfg.firefly_ceiling),
                        format!("{fireflies}/{t}"),
                        binomial_upper(fireflies, t, cfg.firefly_ceiling),
                        None,
                    );
                    let (only_here, only_mean) = cell.firefly_discordance();
                    push(
                        CheckKind::FireflyVsMean,
                        "no more fireflies than the mean on the same trials".into(),
                        format!(
                            "{only_here} trials firefly here only, {only_mean} under the mean only"
                        ),
                        binomial_upper(only_here, only_here + only_mean, 0.5),
                        None,
                    );
                }
            }
        }
    }
    // A bound far above what the law gives catches only gross defects: say how gross.
    let strictest = cfg.family_alpha / results.len().max(1) as f64;
    for (i, bound, rate) in bounds {
        let least = smallest_detectable(t, bound, strictest);
        let floor = rate.max(1.0 / t as f64);
        if least > 2.0 * floor {
            results[i].detects = Some(format!(
                "fails only when the rate reaches {least:.4}, {:.0}x the rate observed here",
                least / floor
            ));
        }
    }
    holm(&mut results, cfg.family_alpha);
    results
}

/// The unbiasedness verdict on the grand mean of `samples` draws with relative bias `bias`:
/// from the law's null when there is one; against a rounding tolerance on a law without
/// spread; with the exact standard error (normal theory) where the null is left out (laws
/// beyond 1e±150); none when the variance is infinite and there is no null.
fn unbiased(
    bias: f64,
    null: Option<&GrandMeanNull>,
    relative_variance: Option<f64>,
    samples: u64,
) -> Option<(String, f64)> {
    Some(match (null, relative_variance) {
        (Some(null), _) => (
            format!(
                "relative bias {bias:.3e}; the law's null of the grand mean of {samples} samples"
            ),
            null.p_two_sided(bias),
        ),
        (None, Some(0.0)) => (
            format!(
                "relative bias {bias:.3e} on a law without spread (tolerance {ROUNDING_TOLERANCE:.1e})"
            ),
            if bias.abs() <= ROUNDING_TOLERANCE {
                1.0
            } else {
                0.0
            },
        ),
        (None, Some(v)) => {
            let se = (v / samples as f64).sqrt();
            (
                format!(
                    "relative bias {bias:.3e}, exact SE {se:.3e} (normal theory: no null at this scale)"
                ),
                (2.0 * normal_sf((bias / se).abs())).min(1.0),
            )
        }
        (None, None) => return None,
    })
}

/// The smallest exceedance rate whose expected count the one-sided binomial test against
/// `bound` rejects at `alpha` over `trials` trials.
fn smallest_detectable(trials: u64, bound: f64, alpha: f64) -> f64 {
    let (mut lo, mut hi) = (0u64, trials);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if binomial_upper(mid, trials, bound) <= alpha {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    lo as f64 / trials as f64
}

/// Holm's step-down procedure: reject in ascending p order while `p <= alpha / (m - rank)`.
/// A NaN p-value fails its check outright, wherever Holm's order would have put it.
fn holm(results: &mut [CheckResult], alpha: f64) {
    let m = results.len();
    for r in results.iter_mut().filter(|r| r.p_value.is_nan()) {
        r.passed = false;
    }
    let mut order: Vec<usize> = (0..m).filter(|&i| !results[i].p_value.is_nan()).collect();
    order.sort_by(|&a, &b| results[a].p_value.total_cmp(&results[b].p_value));
    for (rank, &i) in order.iter().enumerate() {
        let level = alpha / (m - rank) as f64;
        results[i].holm_alpha = Some(level);
        if results[i].p_value <= level {
            results[i].passed = false;
        } else {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(p: f64) -> CheckResult {
        CheckResult {
            check: CheckKind::Unbiased,
            distribution: String::new(),
            estimator: String::new(),
            n: 1,
            claim: String::new(),
            observed: String::new(),
            p_value: p,
            holm_alpha: None,
            passed: true,
            gating: true,
            detects: None,
        }
    }

    #[test]
    fn a_nan_p_value_fails_even_after_holm_stops() {
        let mut r: Vec<_> = [0.5, f64::NAN, 0.9].into_iter().map(result).collect();
        holm(&mut r, 0.05);
        assert_eq!(
            r.iter().map(|c| c.passed).collect::<Vec<_>>(),
            [true, false, true]
        );
    }

    #[test]
    fn smallest_detectable_rate_is_where_the_test_starts_rejecting() {
        // Bound 1/9 over 4096 trials at alpha 1e-4: the count k* with P(Bin >= k*) <= 1e-4.
        let least = smallest_detectable(4096, 1.0 / 9.0, 1e-4);
        let k = (least * 4096.0).round() as u64;
        assert!(binomial_upper(k, 4096, 1.0 / 9.0) <= 1e-4);
        assert!(binomial_upper(k - 1, 4096, 1.0 / 9.0) > 1e-4);
        assert!(least > 1.0 / 9.0 && least < 0.14, "{least}");
    }

    #[test]
    fn holm_stops_at_the_first_survivor() {
        let mut r: Vec<_> = [0.001, 0.04, 0.012, 0.5].into_iter().map(result).collect();
        holm(&mut r, 0.05);
        // Thresholds 0.0125, 0.0167, 0.025: 0.001 and 0.012 rejected, 0.04 > 0.025 stops.
        assert_eq!(
            r.iter().map(|c| c.passed).collect::<Vec<_>>(),
            [false, true, false, true]
        );
    }

    #[test]
    fn binomial_tail_matches_hand_value() {
        // P(Bin(4, 0.5) >= 3) = 5/16.
        assert!((binomial_upper(3, 4, 0.5) - 5.0 / 16.0).abs() < 1e-12);
        assert_eq!(binomial_upper(0, 4, 0.5), 1.0);
    }
}
