//! The claims a run checks: their kinds, their configuration and the thresholds they count
//! trials against. The runner (which counts exceedances while it runs) and the checks (which
//! judge them) both read this module, and neither reads the other.

use crate::dist::Dist;
use crate::estimators::{EstimatorSpec, MeanSpec, MonSpec};
use serde::{Deserialize, Serialize};

/// Every kind of check, as named in results, `checks.json` and `checks.findings`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CheckKind {
    /// The plain mean is unbiased (p-value from the law's own null of the grand mean).
    Unbiased,
    /// Chebyshev's inequality for the mean.
    Chebyshev,
    /// The median-of-means deviation bound.
    MonBound,
    /// Zirr et al.'s variance bound (their eq. 10).
    ZirrBound,
    /// A robust estimator's firefly rate stays below a ceiling.
    FireflyCeiling,
    /// A robust estimator has no more fireflies than the mean on the same trials.
    FireflyVsMean,
}

impl CheckKind {
    /// Every kind.
    pub const ALL: [CheckKind; 6] = [
        CheckKind::Unbiased,
        CheckKind::Chebyshev,
        CheckKind::MonBound,
        CheckKind::ZirrBound,
        CheckKind::FireflyCeiling,
        CheckKind::FireflyVsMean,
    ];

    /// The name in files and tables.
    pub fn name(self) -> &'static str {
        match self {
            CheckKind::Unbiased => "unbiased",
            CheckKind::Chebyshev => "chebyshev",
            CheckKind::MonBound => "mon-bound",
            CheckKind::ZirrBound => "zirr-bound",
            CheckKind::FireflyCeiling => "firefly-ceiling",
            CheckKind::FireflyVsMean => "firefly-vs-mean",
        }
    }
}

impl std::fmt::Display for CheckKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Which claims to check, and at what family-wise error rate.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ChecksConfig {
    /// Probability that at least one check fails although every claim holds (Holm across
    /// the whole family).
    pub family_alpha: f64,
    /// Test the mean's unbiasedness on every distribution with finite variance.
    pub unbiased_mean: bool,
    /// Chebyshev for the mean: `P(|mean - mu| >= k sigma / sqrt(n)) <= 1/k^2`; 0 disables.
    pub chebyshev_k: f64,
    /// Median-of-means deviation bound with this delta, checked on the estimator
    /// `mon:M=ceil(8 ln(1/delta))` when the experiment runs it; 0 disables.
    pub mon_delta: f64,
    /// Zirr et al.'s variance bound (their eq. 10) on every `zirr` estimator.
    pub zirr_bound: bool,
    /// Estimators whose firefly rate at the largest n must stay below `firefly_ceiling` and
    /// not exceed the mean's on the same trials.
    pub robust: Vec<String>,
    /// Ceiling on the firefly rate `P(X > (1 + tau) mu)` of the `robust` estimators.
    pub firefly_ceiling: f64,
    /// Check kinds that test a paper's claim about its method rather than this
    /// implementation (e.g. `zirr-bound`): a failure is reported as a finding and does not
    /// make the run exit 1.
    pub findings: Vec<CheckKind>,
}

impl Default for ChecksConfig {
    fn default() -> Self {
        ChecksConfig {
            family_alpha: 0.01,
            unbiased_mean: true,
            chebyshev_k: 3.0,
            mon_delta: 0.05,
            zirr_bound: true,
            robust: Vec::new(),
            firefly_ceiling: 0.05,
            findings: Vec::new(),
        }
    }
}

/// Sets of the median-of-means bound for a failure probability `delta`.
pub fn mon_sets(delta: f64) -> usize {
    (8.0 * (1.0 / delta).ln()).ceil() as usize
}

/// Smallest relative deviation a deviation check counts: a law without spread gives exactly
/// `mu` up to rounding, which must not count as exceeding a bound of 0.
pub const ROUNDING_TOLERANCE: f64 = 64.0 * f64::EPSILON;

/// The bound on `|X - mu|` that a check counts exceedances of, for one cell.
pub fn deviation_threshold(
    cfg: &ChecksConfig,
    spec: &EstimatorSpec,
    dist: &Dist,
    n: usize,
) -> Option<f64> {
    let mu = dist.mean();
    let sigma = mu * dist.relative_variance()?.sqrt();
    let nf = n as f64;
    let floor = ROUNDING_TOLERANCE * mu;
    match *spec {
        EstimatorSpec::Mean(MeanSpec) if cfg.chebyshev_k > 0.0 => {
            Some((cfg.chebyshev_k * sigma / nf.sqrt()).max(floor))
        }
        EstimatorSpec::Mon(MonSpec { m })
            if cfg.mon_delta > 0.0 && m == mon_sets(cfg.mon_delta) && n >= m =>
        {
            Some((sigma * (32.0 * (1.0 / cfg.mon_delta).ln() / nf).sqrt()).max(floor))
        }
        _ => None,
    }
}

/// Checks the configuration asks for that cannot run on this experiment, in words naming the
/// estimator or setting; printed before a run and listed in the summary.
pub fn unreachable(
    cfg: &ChecksConfig,
    estimators: &[EstimatorSpec],
    checkpoints: &[usize],
) -> Vec<String> {
    let mut out = Vec::new();
    if cfg.mon_delta > 0.0 {
        let m = mon_sets(cfg.mon_delta);
        let mons: Vec<usize> = estimators
            .iter()
            .filter_map(|s| match s {
                EstimatorSpec::Mon(MonSpec { m }) => Some(*m),
                _ => None,
            })
            .collect();
        if mons.is_empty() {
            // Nothing to check: the bound is about median-of-means estimators only.
        } else if !mons.contains(&m) {
            out.push(format!(
                "checks.mon_delta = {} needs mon:M={m} (M = ceil(8 ln(1/delta))), which the \
                 experiment does not run (it runs {}): the median-of-means bound is not checked",
                cfg.mon_delta,
                mons.iter()
                    .map(|m| format!("mon:M={m}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        } else {
            let below: Vec<String> = checkpoints
                .iter()
                .filter(|&&n| n < m)
                .map(|n| n.to_string())
                .collect();
            if !below.is_empty() {
                out.push(format!(
                    "the median-of-means bound needs n >= M = {m}: not checked at n = {}",
                    below.join(", ")
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mon_sets_follow_the_bound() {
        assert_eq!(mon_sets(0.05), 24);
        assert_eq!(mon_sets(0.01), 37);
    }

    #[test]
    fn kinds_round_trip_through_their_names() {
        for k in CheckKind::ALL {
            let json = serde_json::to_string(&k).unwrap();
            assert_eq!(json, format!("\"{}\"", k.name()));
            assert_eq!(serde_json::from_str::<CheckKind>(&json).unwrap(), k);
        }
    }
}
