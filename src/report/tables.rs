//! Tables of a run: the tidy `results.csv` (one row per distribution, estimator, n and
//! metric), the readable `summary.md`, and `manifest.json` with what produced them.

use crate::error::{Error, Num, Result};
use crate::estimators::{EstimatorSpec, MeanSpec};
use crate::harness::law;
use crate::harness::metrics::{Caveat, Interval, LEVEL, Metric};
use crate::harness::{CheckResult, Experiment, RunOutput};
use serde::Serialize;
use std::collections::HashMap;
use std::fmt::Write as _;

pub use crate::harness::metrics::Row;

/// Every metric of every cell, plus state sizes at the largest n. Nothing here depends on
/// timing or thread count, so a run's `results.csv` is byte-identical however it was split.
///
/// The plain mean's bias interval comes from the law's null of its grand mean, and its exact
/// variance `sigma^2 / n` is a row of its own. A metric whose truth is infinite is written as
/// `inf` (`-inf` for a difference against the mean) with no interval; a tail-dominated one keeps
/// the run's value but no interval, and its caveat says why.
pub fn rows(exp: &Experiment, out: &RunOutput) -> Vec<Row> {
    let cps = &exp.file.checkpoints;
    let mut rows = Vec::new();
    for d in &out.dists {
        let infinite_variance = d.variance.is_none();
        for (e, spec) in exp.estimators.iter().enumerate() {
            let is_mean = *spec == EstimatorSpec::Mean(MeanSpec);
            for (i, &n) in cps.iter().enumerate() {
                let Some(mut m) = d.cells[e * cps.len() + i].metrics(d.mu) else {
                    continue;
                };
                let mean_law = d.mean_laws[i].as_ref();
                if let (true, Some(l)) = (is_mean, mean_law) {
                    m.bias = l.bias_interval(m.bias, d.mu);
                }
                let mut push = |metric: Metric, iv: Interval| {
                    let caveat = law::caveat(
                        metric,
                        &m,
                        mean_law,
                        Some(&d.tail_effects[e * cps.len() + i]),
                        d.mu,
                        is_mean,
                        infinite_variance,
                    );
                    let value = match caveat {
                        Some(Caveat::InfiniteTruth) if metric == Metric::PairedMseVsMean => {
                            f64::NEG_INFINITY
                        }
                        Some(Caveat::InfiniteTruth) => f64::INFINITY,
                        _ => iv.value,
                    };
                    let held = caveat.is_none();
                    let interval = held && iv.low.is_some() && iv.high.is_some();
                    rows.push(Row {
                        distribution: d.label.clone(),
                        estimator: spec.to_string(),
                        n,
                        metric,
                        value,
                        ci_low: if interval { iv.low } else { None },
                        ci_high: if interval { iv.high } else { None },
                        se: if held { iv.se } else { None },
                        level: interval.then_some(LEVEL),
                        caveat,
                    });
                };
                let relative = |iv: Interval| iv.map(|v| v / d.mu, iv.se.map(|s| s / d.mu));
                push(Metric::Bias, m.bias);
                push(Metric::RelativeBias, relative(m.bias));
                push(Metric::Variance, m.variance);
                if let (true, Some(l)) = (is_mean, mean_law) {
                    let exact = l
                        .relative_variance
                        .map_or(f64::INFINITY, |v| v * d.mu * d.mu);
                    push(Metric::ExactVariance, Interval::bare(exact));
                }
                push(Metric::Mse, m.mse);
                push(Metric::RelativeRmse, m.relative_rmse);
                push(Metric::MedianAbsRelError, m.median_abs_rel_error);
                push(Metric::MeanAbsRelError, m.mean_abs_rel_error);
                for (metric, v) in m.rel_error_quantiles {
                    push(metric, Interval::bare(v));
                }
                push(Metric::FireflyRate, m.firefly_rate);
                push(
                    Metric::OutlierTrials,
                    Interval::bare(m.outlier_trials as f64),
                );
                if let Some(r) = m.rejection_rate {
                    push(Metric::RejectionRate, r);
                }
                push(Metric::PairedAbsRelVsMean, m.paired_abs_rel_vs_mean);
                push(Metric::PairedMseVsMean, m.paired_mse_vs_mean);
            }
            let n = exp.max_n();
            let mut push_bare = |metric: Metric, value: f64| {
                rows.push(bare_row(&d.label, spec.to_string(), n, metric, value));
            };
            push_bare(Metric::StateBytesMax, d.state_bytes_max[e] as f64);
            push_bare(
                Metric::StateBytesMean,
                d.state_bytes_sum[e] as f64 / out.trials as f64,
            );
        }
    }
    rows
}

/// A row with a value only.
fn bare_row(distribution: &str, estimator: String, n: usize, metric: Metric, value: f64) -> Row {
    Row {
        distribution: distribution.to_string(),
        estimator,
        n,
        metric,
        value,
        ci_low: None,
        ci_high: None,
        se: None,
        level: None,
        caveat: None,
    }
}

/// Measured costs at the largest n (`speed.csv`): per estimator `ns_per_sample` (push and
/// estimate, one thread), and per distribution `generate_ns_per_sample` under the estimator
/// name `(generator)`.
pub fn speed_rows(exp: &Experiment, out: &RunOutput) -> Vec<Row> {
    let n = exp.max_n();
    let row = |d: &str, estimator: String, metric: Metric, value: f64| {
        bare_row(d, estimator, n, metric, value)
    };
    let mut rows = Vec::new();
    for d in &out.dists {
        for (e, spec) in exp.estimators.iter().enumerate() {
            rows.push(row(
                &d.label,
                spec.to_string(),
                Metric::NsPerSample,
                d.ns_per_sample(e),
            ));
        }
        rows.push(row(
            &d.label,
            "(generator)".to_string(),
            Metric::GenerateNsPerSample,
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

/// A row as the summary prints it: value, interval, or the caveat that replaces it.
fn fmt_row(r: Option<&Row>, scale: f64, unit: &str) -> String {
    let Some(r) = r else {
        return "–".into();
    };
    let v = |x: f64| {
        if x.is_infinite() {
            if x > 0.0 { "inf".into() } else { "-inf".into() }
        } else {
            format!("{:.3e}{unit}", x * scale)
        }
    };
    match (r.ci_low, r.ci_high, r.caveat) {
        (_, _, Some(c)) => format!("{} ({})", v(r.value), c.label()),
        (Some(l), Some(h), None) => format!("{} [{}, {}]", v(r.value), v(l), v(h)),
        _ => v(r.value),
    }
}

/// `summary.md`: per distribution, every estimator at the largest n; then every check.
pub fn summary_md(
    exp: &Experiment,
    out: &RunOutput,
    rows: &[Row],
    checks: &[CheckResult],
) -> String {
    let cps = &exp.file.checkpoints;
    let last = *cps.last().expect("checked non-empty");
    let index: HashMap<(&str, &str, usize, Metric), &Row> = rows
        .iter()
        .map(|r| {
            (
                (r.distribution.as_str(), r.estimator.as_str(), r.n, r.metric),
                r,
            )
        })
        .collect();
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
        "Primary metric: median absolute relative error; its 95% interval runs between the \
         order statistics that bound it, read from a histogram (bins 2.3% wide, a value placed \
         inside its bin by its rank; an error of exactly 0 or 1 is exact). The plain mean's bias interval comes from \
         the law's own null of its grand mean (normal body, simulated rare tail), so it holds on \
         heavy tails; other bias intervals are normal-theory. Variance and MSE intervals are \
         scaled chi-square (never below 0) with a fourth-moment standard error. \
         **tail-dominated**: more than half of the metric's spread comes from events the run \
         expects fewer than {} times (by the law, for the mean; by the run's own {} largest \
         errors, for every estimator): the value is what this run saw and no interval is given. \
         **inf**: the true value is infinite. `paired` is the mean over trials of this \
         estimator's absolute relative error minus the mean's on the same samples (negative: \
         better than the mean).\n",
        crate::harness::metrics::TAIL_EVENTS,
        crate::harness::metrics::TAIL_EVENTS
    );
    if !exp.warnings.is_empty() {
        let _ = writeln!(s, "**Checks that cannot run:**\n");
        for w in &exp.warnings {
            let _ = writeln!(s, "- {w}");
        }
        let _ = writeln!(s);
    }
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
            "At n = {last} samples per pixel:\n\n| estimator | median abs rel error | bias | relative RMSE | firefly rate | rejection rate | paired vs mean | ns/sample | state bytes |\n|---|---|---|---|---|---|---|---|---|"
        );
        for (e, spec) in exp.estimators.iter().enumerate() {
            let est = spec.to_string();
            let get = |m: Metric| {
                index
                    .get(&(d.label.as_str(), est.as_str(), last, m))
                    .copied()
            };
            if get(Metric::Bias).is_none() {
                continue;
            }
            let rejection = match get(Metric::RejectionRate) {
                Some(r) => format!(
                    "{} of {}",
                    fmt_row(Some(r), 100.0, "%"),
                    get(Metric::OutlierTrials).map_or(0.0, |o| o.value)
                ),
                None => "– (0 outlier trials)".to_string(),
            };
            let _ = writeln!(
                s,
                "| `{spec}` | {} | {} | {} | {} | {} | {} | {:.2} | {} |",
                fmt_row(get(Metric::MedianAbsRelError), 1.0, ""),
                fmt_row(get(Metric::Bias), 1.0, ""),
                fmt_row(get(Metric::RelativeRmse), 1.0, ""),
                fmt_row(get(Metric::FireflyRate), 100.0, "%"),
                rejection,
                fmt_row(get(Metric::PairedAbsRelVsMean), 1.0, ""),
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
        "| verdict | check | distribution | estimator | n | claim | observed | p | Holm level | catches |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    let mut sorted: Vec<&CheckResult> = checks.iter().collect();
    sorted.sort_by_key(|c| c.passed);
    for c in sorted {
        let _ = writeln!(
            s,
            "| {} | {} | {} | `{}` | {} | {} | {} | {:.3e} | {} | {} |",
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
            c.holm_alpha.map_or("–".to_string(), |a| format!("{a:.2e}")),
            c.detects.as_deref().unwrap_or("–")
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
    /// Firefly threshold: an estimate above `(1 + tau) mu` is a firefly.
    pub tau: f64,
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
    /// Largest resident memory of the process so far, bytes (Linux; `None` elsewhere).
    pub peak_rss_bytes: Option<u64>,
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
        tau: exp.file.tau,
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
        peak_rss_bytes: crate::limits::peak_rss_bytes(),
        checks: checks.len(),
        checks_failed: checks.iter().filter(|c| !c.passed).count(),
    };
    serde_json::to_string_pretty(&m).unwrap_or_default()
}
