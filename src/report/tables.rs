//! Tables of a run: the tidy `results.csv` (one row per distribution, estimator, n and
//! metric), the readable `summary.md`, and `manifest.json` with what produced them.

use crate::error::{Error, Num, Result};
use crate::harness::metrics::{CellMetrics, Interval};
use crate::harness::{CheckResult, Experiment, RunOutput};
use serde::Serialize;
use std::fmt::Write as _;

pub use crate::harness::metrics::Row;

/// Whether an estimator is the plain mean on a law of infinite variance, where variance and
/// MSE intervals mean nothing.
fn infinite_variance(spec: &crate::estimators::EstimatorSpec, variance: Option<f64>) -> bool {
    matches!(spec, crate::estimators::EstimatorSpec::Mean) && variance.is_none()
}

/// Every metric of every cell, plus state sizes at the largest n. Nothing here depends on
/// timing or thread count, so a run's `results.csv` is byte-identical however it was split.
pub fn rows(exp: &Experiment, out: &RunOutput) -> Vec<Row> {
    let cps = &exp.file.checkpoints;
    let mut rows = Vec::new();
    for d in &out.dists {
        for (e, spec) in exp.estimators.iter().enumerate() {
            let unbounded = infinite_variance(spec, d.variance);
            for (i, &n) in cps.iter().enumerate() {
                let Some(m) = d.cells[e * cps.len() + i].metrics(d.mu) else {
                    continue;
                };
                let mut push = |metric: &str, iv: Interval, drop_ci: bool| {
                    rows.push(Row {
                        distribution: d.label.clone(),
                        estimator: spec.to_string(),
                        n,
                        metric: metric.to_string(),
                        value: iv.value,
                        ci_low: if drop_ci { None } else { iv.low },
                        ci_high: if drop_ci { None } else { iv.high },
                    });
                };
                push("bias", m.bias, unbounded);
                let rel = |x: Option<f64>| x.map(|v| v / d.mu);
                push(
                    "relative_bias",
                    Interval {
                        value: m.bias.value / d.mu,
                        low: rel(m.bias.low),
                        high: rel(m.bias.high),
                    },
                    unbounded,
                );
                push("variance", m.variance, unbounded);
                push("mse", m.mse, unbounded);
                push("relative_rmse", m.relative_rmse, unbounded);
                push("median_abs_rel_error", m.median_abs_rel_error, false);
                push("mean_abs_rel_error", m.mean_abs_rel_error, false);
                for (q, v) in m.rel_error_quantiles {
                    push(
                        &format!("rel_error_q{:02}", (q * 100.0).round()),
                        Interval::bare(v),
                        false,
                    );
                }
                push("firefly_rate", m.firefly_rate, false);
                push(
                    "outlier_trials",
                    Interval::bare(m.outlier_trials as f64),
                    false,
                );
                if let Some(r) = m.rejection_rate {
                    push("rejection_rate", r, false);
                }
                push("paired_abs_rel_vs_mean", m.paired_abs_rel_vs_mean, false);
                push("paired_mse_vs_mean", m.paired_mse_vs_mean, unbounded);
            }
            let n = exp.max_n();
            let mut push_bare = |metric: &str, value: f64| {
                rows.push(Row {
                    distribution: d.label.clone(),
                    estimator: spec.to_string(),
                    n,
                    metric: metric.to_string(),
                    value,
                    ci_low: None,
                    ci_high: None,
                });
            };
            push_bare("state_bytes_max", d.state_bytes_max[e] as f64);
            push_bare(
                "state_bytes_mean",
                d.state_bytes_sum[e] as f64 / out.trials as f64,
            );
        }
    }
    rows
}

/// Measured costs at the largest n (`speed.csv`): per estimator `ns_per_sample` (push and
/// estimate, one thread), and per distribution `generate_ns_per_sample` under the estimator
/// name `(generator)`.
pub fn speed_rows(exp: &Experiment, out: &RunOutput) -> Vec<Row> {
    let n = exp.max_n();
    let row = |d: &str, estimator: String, metric: &str, value: f64| Row {
        distribution: d.to_string(),
        estimator,
        n,
        metric: metric.to_string(),
        value,
        ci_low: None,
        ci_high: None,
    };
    let mut rows = Vec::new();
    for d in &out.dists {
        for (e, spec) in exp.estimators.iter().enumerate() {
            rows.push(row(
                &d.label,
                spec.to_string(),
                "ns_per_sample",
                d.ns_per_sample(e),
            ));
        }
        rows.push(row(
            &d.label,
            "(generator)".to_string(),
            "generate_ns_per_sample",
            d.generate_ns_per_sample(),
        ));
    }
    rows
}

/// CSV text of tidy rows.
pub fn results_csv(rows: &[Row]) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.serialize(r).map_err(|e| Error::Io {
            path: "results.csv".into(),
            message: e.to_string(),
        })?;
    }
    w.into_inner().map_err(|e| Error::Io {
        path: "results.csv".into(),
        message: e.to_string(),
    })
}

/// Reads `results.csv` back (plots and gates read data, never the run).
pub fn read_results_csv(path: &std::path::Path) -> Result<Vec<Row>> {
    let mut r = csv::Reader::from_path(path).map_err(|e| Error::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    r.deserialize()
        .enumerate()
        .map(|(i, row)| {
            row.map_err(|e| Error::Io {
                path: format!("{}:{}", path.display(), i + 2),
                message: e.to_string(),
            })
        })
        .collect()
}

fn fmt_ci(iv: &Interval) -> String {
    match (iv.low, iv.high) {
        (Some(l), Some(h)) => format!("{:.3e} [{:.3e}, {:.3e}]", iv.value, l, h),
        _ => format!("{:.3e}", iv.value),
    }
}

fn pct(iv: &Interval) -> String {
    match (iv.low, iv.high) {
        (Some(l), Some(h)) => format!(
            "{:.2}% [{:.2}, {:.2}]",
            100.0 * iv.value,
            100.0 * l,
            100.0 * h
        ),
        _ => format!("{:.2}%", 100.0 * iv.value),
    }
}

/// `summary.md`: per distribution, every estimator at the largest n; then every check.
pub fn summary_md(exp: &Experiment, out: &RunOutput, checks: &[CheckResult]) -> String {
    let cps = &exp.file.checkpoints;
    let last = cps.len() - 1;
    let mut s = String::new();
    let _ = writeln!(s, "# {}\n", exp.name);
    if !exp.file.description.is_empty() {
        let _ = writeln!(s, "{}\n", exp.file.description);
    }
    let _ = writeln!(
        s,
        "{} trials per distribution, seed {}, firefly threshold (1 + {}) mu, {} threads, {:.1} s wall, {:.3e} samples/s.\n",
        out.trials,
        exp.file.seed,
        exp.file.tau,
        out.threads,
        out.wall_s,
        out.samples_per_s()
    );
    let _ = writeln!(
        s,
        "Primary metric: median absolute relative error with its order-statistic 95% interval \
         (quantiles from a log histogram, exact to 2.3%). Intervals are 95%. `paired` is the \
         mean over trials of this estimator's absolute relative error minus the mean's on the \
         same samples (negative: better than the mean). Variance, MSE and relative-RMSE \
         intervals are normal-theory and assume the estimate has a finite fourth moment; where \
         it does not (the mean on a tail of shape < 4) they are unreliable, and where the \
         variance itself is infinite they are omitted. No bootstrap is run: the runner keeps no \
         per-trial values, so that a million trials cost the memory of a thousand.\n"
    );
    for d in &out.dists {
        let var = d
            .variance
            .map_or("infinite".to_string(), |v| Num(v).to_string());
        let _ = writeln!(
            s,
            "## {}\n\n`{}`: mean {}, variance {}.\n",
            d.label,
            d.law,
            Num(d.mu),
            var
        );
        let _ = writeln!(
            s,
            "At n = {} samples per pixel:\n\n| estimator | median abs rel error | bias | relative RMSE | firefly rate | rejection rate | paired vs mean | ns/sample | state bytes |\n|---|---|---|---|---|---|---|---|---|",
            cps[last]
        );
        for (e, spec) in exp.estimators.iter().enumerate() {
            let Some(m): Option<CellMetrics> = d.cells[e * cps.len() + last].metrics(d.mu) else {
                continue;
            };
            let unbounded = infinite_variance(spec, d.variance);
            let (bias, rmse) = if unbounded {
                (
                    format!("{:.3e} (no CI: infinite variance)", m.bias.value),
                    format!("{:.3e} (no CI: infinite variance)", m.relative_rmse.value),
                )
            } else {
                (fmt_ci(&m.bias), fmt_ci(&m.relative_rmse))
            };
            let rejection = m
                .rejection_rate
                .map_or("– (0 outlier trials)".to_string(), |r| {
                    format!("{} of {}", pct(&r), m.outlier_trials)
                });
            let _ = writeln!(
                s,
                "| `{}` | {} | {} | {} | {} | {} | {} | {:.2} | {} |",
                spec,
                fmt_ci(&m.median_abs_rel_error),
                bias,
                rmse,
                pct(&m.firefly_rate),
                rejection,
                fmt_ci(&m.paired_abs_rel_vs_mean),
                d.ns_per_sample(e),
                d.state_bytes_max[e]
            );
        }
        let _ = writeln!(
            s,
            "\nDrawing samples: {:.2} ns/sample.\n",
            d.generate_ns_per_sample()
        );
    }
    let failed = checks.iter().filter(|c| !c.passed).count();
    let _ = writeln!(
        s,
        "## Checks\n\n{} checks, {} failed ({} of them findings about a method's published claim \
         rather than failures of this implementation). Each tests a claim that holds for a correct \
         estimator; Holm's procedure across all {} keeps the probability of any false failure \
         at {}.\n",
        checks.len(),
        failed,
        checks.iter().filter(|c| !c.passed && !c.gating).count(),
        checks.len(),
        exp.file.checks.family_alpha
    );
    let _ = writeln!(
        s,
        "| verdict | check | distribution | estimator | n | claim | observed | p | Holm level |\n|---|---|---|---|---|---|---|---|---|"
    );
    let mut sorted: Vec<&CheckResult> = checks.iter().collect();
    sorted.sort_by_key(|c| c.passed);
    for c in sorted {
        let _ = writeln!(
            s,
            "| {} | {} | {} | `{}` | {} | {} | {} | {:.3e} | {} |",
            match (c.passed, c.gating) {
                (true, _) => "pass",
                (false, true) => "**FAIL**",
                (false, false) => "**violated** (finding)",
            },
            c.check,
            c.distribution,
            c.estimator,
            c.n,
            c.claim,
            c.observed,
            c.p_value,
            c.holm_alpha.map_or("–".to_string(), |a| format!("{a:.2e}"))
        );
    }
    s
}

/// What produced a report, for `manifest.json`.
#[derive(Debug, Serialize)]
pub struct Manifest<'a> {
    /// Experiment name.
    pub experiment: &'a str,
    /// Seed of every stream.
    pub seed: u64,
    /// Trials per distribution.
    pub trials: u64,
    /// Checkpoints.
    pub checkpoints: &'a [usize],
    /// Estimator spec strings, canonical.
    pub estimators: Vec<String>,
    /// Distribution labels and laws.
    pub distributions: Vec<(String, String)>,
    /// `fireflies` version.
    pub crate_version: &'static str,
    /// The commit the binary was built from, if any.
    pub git_commit: Option<String>,
    /// Worker threads.
    pub threads: usize,
    /// Wall-clock seconds.
    pub wall_s: f64,
    /// Samples drawn per wall-clock second (each fed to every estimator).
    pub samples_per_s: f64,
    /// Checks run and failed.
    pub checks: usize,
    /// Checks failed.
    pub checks_failed: usize,
}

/// The commit the binary was built from (recorded by `build.rs`), if built from a checkout.
pub fn git_commit() -> Option<String> {
    let commit = env!("FIREFLIES_GIT_COMMIT");
    (!commit.is_empty()).then(|| commit.to_string())
}

/// `manifest.json` text.
pub fn manifest_json(exp: &Experiment, out: &RunOutput, checks: &[CheckResult]) -> String {
    let m = Manifest {
        experiment: &exp.name,
        seed: exp.file.seed,
        trials: out.trials,
        checkpoints: &exp.file.checkpoints,
        estimators: exp.estimators.iter().map(ToString::to_string).collect(),
        distributions: out
            .dists
            .iter()
            .map(|d| (d.label.clone(), d.law.clone()))
            .collect(),
        crate_version: env!("CARGO_PKG_VERSION"),
        git_commit: git_commit(),
        threads: out.threads,
        wall_s: out.wall_s,
        samples_per_s: out.samples_per_s(),
        checks: checks.len(),
        checks_failed: checks.iter().filter(|c| !c.passed).count(),
    };
    serde_json::to_string_pretty(&m).unwrap_or_default()
}
