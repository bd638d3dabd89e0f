//! Claims about estimators checked against a run, each a hypothesis test whose null is "the
//! claim holds"; Holm's step-down procedure across the whole family keeps the probability
//! that any check fails while every claim holds at `family_alpha`.
//!
//! - **Unbiased mean** (finite variance): z-test of the mean's bias with the *exact* standard
//!   error `sqrt(Var S / (n T))`, not the sample one, which underestimates the spread when
//!   rare large samples have not occurred yet.
//! - **Chebyshev** for the mean: `P(|mean - mu| > k sigma/sqrt(n)) <= 1/k^2`, exact binomial
//!   test of the exceedance count.
//! - **Median-of-means deviation bound**: with `M = ceil(8 ln(1/delta))` sets,
//!   `P(|MoN - mu| > sigma sqrt(32 ln(1/delta)/n)) <= delta` (finite variance, `n >= M`),
//!   exact binomial test.
//! - **Zirr et al.'s variance bound** (their eq. 10): `Var F' < Var[S | S < n mu/kappa]/n +
//!   mu^2/kappa`, with the exact truncated variance; one-sided z-test of the sample variance.
//! - **Firefly rate** of each robust estimator at the largest n: below a ceiling (exact
//!   binomial test) and not above the mean's on the same trials (exact McNemar test).

use super::experiment::{ChecksConfig, Experiment};
use super::runner::RunOutput;
use crate::dist::Dist;
use crate::estimators::EstimatorSpec;
use serde::Serialize;
use statrs::distribution::{Binomial, ContinuousCDF, DiscreteCDF, Normal};

/// Every check kind, as named in results and in `checks.findings`.
pub const KINDS: [&str; 6] = [
    "unbiased",
    "chebyshev",
    "mon-bound",
    "zirr-bound",
    "firefly-ceiling",
    "firefly-vs-mean",
];

/// Outcome of one check.
#[derive(Debug, Clone, Serialize)]
pub struct CheckResult {
    /// Which claim (`unbiased`, `chebyshev`, `mon-bound`, `zirr-bound`, `firefly-ceiling`,
    /// `firefly-vs-mean`).
    pub check: &'static str,
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
    /// p-value under the claim.
    pub p_value: f64,
    /// Holm's threshold this p-value was compared with (`None` once a smaller p passed).
    pub holm_alpha: Option<f64>,
    /// Whether the claim survived.
    pub passed: bool,
    /// Whether a failure fails the run (false: the check is a reported finding).
    pub gating: bool,
}

impl CheckResult {
    /// A failure that fails the run.
    pub fn fails_run(&self) -> bool {
        !self.passed && self.gating
    }
}

/// Sets of the median-of-means bound for a failure probability `delta`.
pub fn mon_sets(delta: f64) -> usize {
    (8.0 * (1.0 / delta).ln()).ceil() as usize
}

/// The bound on `|X - mu|` that a check counts exceedances of, for one cell.
pub fn deviation_threshold(
    cfg: &ChecksConfig,
    spec: &EstimatorSpec,
    dist: &Dist,
    n: usize,
) -> Option<f64> {
    let sigma = dist.mean() * dist.relative_variance()?.sqrt();
    let nf = n as f64;
    match *spec {
        EstimatorSpec::Mean if cfg.chebyshev_k > 0.0 => Some(cfg.chebyshev_k * sigma / nf.sqrt()),
        EstimatorSpec::Mon { m }
            if cfg.mon_delta > 0.0 && m == mon_sets(cfg.mon_delta) && n >= m =>
        {
            Some(sigma * (32.0 * (1.0 / cfg.mon_delta).ln() / nf).sqrt())
        }
        _ => None,
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
    let robust: Vec<EstimatorSpec> = cfg.robust.iter().filter_map(|r| r.parse().ok()).collect();
    for (d, dist) in out.dists.iter().zip(&exp.distributions) {
        for (e, spec) in exp.estimators.iter().enumerate() {
            for (i, &n) in cps.iter().enumerate() {
                let cell = &d.cells[e * cps.len() + i];
                let mut push =
                    |check: &'static str, claim: String, observed: String, p_value: f64| {
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
                            gating: !cfg.findings.iter().any(|f| f == check),
                        });
                    };
                // Relative units (X / mu): finite at any scale of the law.
                let moments = cell.relative_estimate_moments();
                if let (EstimatorSpec::Mean, true, Some(rel_var)) =
                    (spec, cfg.unbiased_mean, dist.dist.relative_variance())
                {
                    let se = (rel_var / (n as f64 * t as f64)).sqrt();
                    let bias = moments.mean() - 1.0;
                    let z = bias / se;
                    push(
                        "unbiased",
                        "E[mean] = mu".into(),
                        format!("relative bias {bias:.3e}, exact SE {se:.3e}, z = {z:.2}"),
                        (2.0 * normal_sf(z.abs())).min(1.0),
                    );
                }
                if let Some((threshold, exceed)) = cell.exceedances() {
                    let (check, bound) = match spec {
                        EstimatorSpec::Mean => ("chebyshev", 1.0 / (cfg.chebyshev_k.powi(2))),
                        _ => ("mon-bound", cfg.mon_delta),
                    };
                    push(
                        check,
                        format!("P(|X - mu| > {threshold:.4e}) <= {bound:.4}"),
                        format!("{exceed}/{t} = {:.4}", exceed as f64 / t as f64),
                        binomial_upper(exceed, t, bound),
                    );
                }
                if let (EstimatorSpec::Zirr(p), true) = (spec, cfg.zirr_bound) {
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
                        "zirr-bound",
                        format!("Var/mu^2 < {bound:.4e} (eq. 10)"),
                        format!("Var/mu^2 = {s2:.4e} ± {se:.2e}"),
                        p_value,
                    );
                }
                if i + 1 == cps.len() && robust.contains(spec) {
                    let fireflies = cell.fireflies();
                    push(
                        "firefly-ceiling",
                        format!("P(X > (1+tau) mu) <= {}", cfg.firefly_ceiling),
                        format!("{fireflies}/{t}"),
                        binomial_upper(fireflies, t, cfg.firefly_ceiling),
                    );
                    let (only_here, only_mean) = cell.firefly_discordance();
                    push(
                        "firefly-vs-mean",
                        "no more fireflies than the mean on the same trials".into(),
                        format!(
                            "{only_here} trials firefly here only, {only_mean} under the mean only"
                        ),
                        binomial_upper(only_here, only_here + only_mean, 0.5),
                    );
                }
            }
        }
    }
    holm(&mut results, cfg.family_alpha);
    results
}

/// Holm's step-down procedure: reject in ascending p order while `p <= alpha / (m - rank)`.
fn holm(results: &mut [CheckResult], alpha: f64) {
    let m = results.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| results[a].p_value.total_cmp(&results[b].p_value));
    for (rank, &i) in order.iter().enumerate() {
        let level = alpha / (m - rank) as f64;
        results[i].holm_alpha = Some(level);
        if results[i].p_value <= level || results[i].p_value.is_nan() {
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
            check: "unbiased",
            distribution: String::new(),
            estimator: String::new(),
            n: 1,
            claim: String::new(),
            observed: String::new(),
            p_value: p,
            holm_alpha: None,
            passed: true,
            gating: true,
        }
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
    fn mon_sets_follow_the_bound() {
        assert_eq!(mon_sets(0.05), 24);
        assert_eq!(mon_sets(0.01), 37);
    }

    #[test]
    fn binomial_tail_matches_hand_value() {
        // P(Bin(4, 0.5) >= 3) = 5/16.
        assert!((binomial_upper(3, 4, 0.5) - 5.0 / 16.0).abs() < 1e-12);
        assert_eq!(binomial_upper(0, 4, 0.5), 1.0);
    }
}
