//! Regression gating against a committed baseline: a `results.csv` of an earlier run, preceded
//! by `# key = value` lines naming the run that produced it ([`Identity`]).
//!
//! A change is a regression when a one-sided test rejects "the worsening is at most the
//! margin": `z = (worsening - margin) / s`, with `s` from the two rows' stored standard errors
//! (never rebuilt from interval widths, which differ from `Z se` for Wilson and order-statistic
//! intervals), Holm across every gated comparison at `family_alpha`. So unchanged code fails the
//! gate with probability at most `family_alpha` (less, as long as it stays inside the margins),
//! and the gate prints for each comparison the smallest worsening it would flag.
//!
//! Which metrics are gated, which way is worse and whether the margin is absolute or relative
//! is decided in one exhaustive `match` ([`rule`]): a new metric does not compile until it has
//! a decision. Nothing is skipped silently: a gated row missing on either side, duplicated, NaN
//! or without a standard error, and a baseline of another experiment are failures listed by
//! name ([`Problem`]); a row whose value carries no trustworthy interval (its caveat says why) is
//! listed as not gated.

use super::Experiment;
use super::checks::CheckResult;
use super::claims::CheckKind;
use super::metrics::{Caveat, Metric, Row};
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, Normal};
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::Path;

/// Practical margins and the family-wise level of the gate (`[gate]` of an experiment).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GateConfig {
    /// Probability that unchanged code fails the gate (Holm across all gated comparisons).
    pub family_alpha: f64,
    /// Smallest growth of `|relative bias|` that counts, absolute (0.005 = 0.5% of the true
    /// mean).
    pub relative_bias_margin: f64,
    /// Smallest relative growth of the variance that counts (0.1 = 10%).
    pub variance_margin: f64,
    /// Smallest relative growth of the median absolute relative error that counts.
    pub median_error_margin: f64,
    /// Smallest relative growth of the firefly rate that counts (0.25 = a quarter more).
    pub firefly_rate_margin: f64,
    /// ... and its absolute floor: a firefly rate must also grow by this much (a rate of 0 has
    /// no relative margin).
    pub firefly_rate_floor: f64,
}

impl Default for GateConfig {
    fn default() -> Self {
        GateConfig {
            family_alpha: 0.01,
            relative_bias_margin: 0.005,
            variance_margin: 0.10,
            median_error_margin: 0.10,
            firefly_rate_margin: 0.25,
            firefly_rate_floor: 1e-3,
        }
    }
}

impl GateConfig {
    /// Checks every value; the error names the key (`gate.family_alpha`, ...).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] when `family_alpha` is outside (0, 1), a margin is negative
    /// or not finite, or the firefly floor is outside [0, 1).
    ///
    /// ```
    /// use fireflies::harness::gate::GateConfig;
    /// let cfg = GateConfig { family_alpha: 5.0, ..GateConfig::default() };
    /// assert!(cfg.validate().unwrap_err().to_string().contains("gate.family_alpha"));
    /// ```
    pub fn validate(&self) -> Result<()> {
        if !(self.family_alpha > 0.0 && self.family_alpha < 1.0) {
            return Err(Error::param(
                "gate.family_alpha",
                self.family_alpha,
                "must be in (0, 1)",
            ));
        }
        let margins = [
            ("gate.relative_bias_margin", self.relative_bias_margin),
            ("gate.variance_margin", self.variance_margin),
            ("gate.median_error_margin", self.median_error_margin),
            ("gate.firefly_rate_margin", self.firefly_rate_margin),
        ];
        for (name, m) in margins {
            if !(m >= 0.0 && m.is_finite()) {
                return Err(Error::param(name, m, "must be finite and >= 0"));
            }
        }
        if !(self.firefly_rate_floor >= 0.0 && self.firefly_rate_floor < 1.0) {
            return Err(Error::param(
                "gate.firefly_rate_floor",
                self.firefly_rate_floor,
                "must be in [0, 1) (a rate)",
            ));
        }
        Ok(())
    }
}

/// How the gate judges a metric: which way is worse and how much worse matters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rule {
    /// Worse is further from 0 (`|now| - |baseline|`); matters beyond `margin`, in the
    /// metric's own units.
    AwayFromZero {
        /// Absolute margin.
        margin: f64,
    },
    /// Worse is larger; matters beyond `margin` times the baseline.
    Relative {
        /// Relative margin.
        margin: f64,
    },
    /// Worse is larger; matters beyond `margin` times the baseline *and* beyond `floor`.
    RelativeWithFloor {
        /// Relative margin.
        margin: f64,
        /// Absolute floor.
        floor: f64,
    },
}

/// The gate's decision for each metric (`None`: not gated, and why in a comment).
pub fn rule(metric: Metric, cfg: &GateConfig) -> Option<Rule> {
    match metric {
        Metric::RelativeBias => Some(Rule::AwayFromZero {
            margin: cfg.relative_bias_margin,
        }),
        Metric::Variance => Some(Rule::Relative {
            margin: cfg.variance_margin,
        }),
        Metric::MedianAbsRelError => Some(Rule::Relative {
            margin: cfg.median_error_margin,
        }),
        Metric::FireflyRate => Some(Rule::RelativeWithFloor {
            margin: cfg.firefly_rate_margin,
            floor: cfg.firefly_rate_floor,
        }),
        // The same as relative_bias in the law's units.
        Metric::Bias => None,
        // Exact from the law: no sampling, nothing an estimator change moves.
        Metric::ExactVariance => None,
        // Bias and variance together, each gated on its own.
        Metric::Mse | Metric::RelativeRmse => None,
        // Summaries of the error law whose centre (the median) is gated; their tails are
        // what the variance and firefly rate gate.
        Metric::MeanAbsRelError
        | Metric::RelErrorQ05
        | Metric::RelErrorQ25
        | Metric::RelErrorQ50
        | Metric::RelErrorQ75
        | Metric::RelErrorQ95
        | Metric::RelErrorQ99 => None,
        // Properties of the samples (outliers drawn) or conditional on them (rejections among
        // outlier trials, a few hundred at most): the firefly rate gates the outcome.
        Metric::OutlierTrials | Metric::RejectionRate => None,
        // Differences against the mean, which is gated itself.
        Metric::PairedAbsRelVsMean | Metric::PairedMseVsMean => None,
        // Memory and speed are not statistical; `speed.csv` is not gated.
        Metric::StateBytesMax
        | Metric::StateBytesMean
        | Metric::NsPerSample
        | Metric::GenerateNsPerSample => None,
    }
}

/// The metrics [`rule`] gates, in table order.
pub fn gated_metrics(cfg: &GateConfig) -> Vec<Metric> {
    Metric::ALL
        .into_iter()
        .filter(|&m| rule(m, cfg).is_some())
        .collect()
}

/// One inequality the gate tests: regression if `now' - c baseline' - d > 0`, where `now'`
/// and `baseline'` are the values (their magnitudes for [`Rule::AwayFromZero`]).
#[derive(Debug, Clone, Copy)]
struct Contrast {
    c: f64,
    d: f64,
}

impl Rule {
    /// The inequalities that must all be significant for a regression (an intersection-union
    /// test: its p-value is the largest of theirs, and it keeps their level).
    fn contrasts(self) -> Vec<Contrast> {
        match self {
            Rule::AwayFromZero { margin } => vec![Contrast { c: 1.0, d: margin }],
            Rule::Relative { margin } => vec![Contrast {
                c: 1.0 + margin,
                d: 0.0,
            }],
            Rule::RelativeWithFloor { margin, floor } => vec![
                Contrast {
                    c: 1.0 + margin,
                    d: 0.0,
                },
                Contrast { c: 1.0, d: floor },
            ],
        }
    }

    fn prepare(self, v: f64) -> f64 {
        match self {
            Rule::AwayFromZero { .. } => v.abs(),
            Rule::Relative { .. } | Rule::RelativeWithFloor { .. } => v,
        }
    }
}

/// A gated cell and metric: distribution, estimator, n, metric.
pub type Key = (String, String, usize, Metric);

fn key(r: &Row) -> Key {
    (r.distribution.clone(), r.estimator.clone(), r.n, r.metric)
}

/// Which table a problem was found in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Side {
    /// The committed baseline.
    Baseline,
    /// The current run.
    Results,
}

impl fmt::Display for Side {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Side::Baseline => "baseline",
            Side::Results => "results",
        })
    }
}

/// Something that makes a comparison impossible; any one fails the gate.
#[derive(Debug, Clone, PartialEq)]
pub enum Problem {
    /// The baseline was produced by another experiment (or other settings).
    Identity {
        /// The field that differs.
        field: &'static str,
        /// Its value in the baseline.
        baseline: String,
        /// Its value in the current run.
        now: String,
    },
    /// Gated metrics of a cell the experiment has but one table lacks.
    Missing {
        /// The table lacking them.
        side: Side,
        /// Distribution, estimator, n.
        cell: (String, String, usize),
        /// The missing metrics.
        metrics: Vec<Metric>,
    },
    /// Gated rows of a cell the experiment does not have.
    Unexpected {
        /// The table holding them.
        side: Side,
        /// Distribution, estimator, n.
        cell: (String, String, usize),
        /// The metrics.
        metrics: Vec<Metric>,
    },
    /// A gated row that appears more than once.
    Duplicate {
        /// The table holding it.
        side: Side,
        /// The row's key.
        key: Key,
    },
    /// A gated row whose value is NaN, or (without a caveat) infinite or lacking a finite,
    /// non-negative standard error.
    NotANumber {
        /// The table holding it.
        side: Side,
        /// The row's key.
        key: Key,
        /// What is wrong, with the value.
        what: String,
    },
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Identity {
                field,
                baseline,
                now,
            } => write!(
                f,
                "another experiment: {field} is {baseline} in the baseline, {now} now"
            ),
            Problem::Missing {
                side,
                cell,
                metrics,
            } => write!(f, "missing from the {side}: {}", cell_text(cell, metrics)),
            Problem::Unexpected {
                side,
                cell,
                metrics,
            } => write!(
                f,
                "not a cell of the experiment, in the {side}: {}",
                cell_text(cell, metrics)
            ),
            Problem::Duplicate { side, key } => write!(
                f,
                "duplicated row in the {side}: {} / {} / n = {}: {}",
                key.0, key.1, key.2, key.3
            ),
            Problem::NotANumber { side, key, what } => write!(
                f,
                "{what} in the {side}: {} / {} / n = {}: {}",
                key.0, key.1, key.2, key.3
            ),
        }
    }
}

/// `glossy / mean / n = 16: relative_bias, variance`.
fn cell_text(cell: &(String, String, usize), metrics: &[Metric]) -> String {
    let names: Vec<&str> = metrics.iter().map(|m| m.name()).collect();
    format!(
        "{} / {} / n = {}: {}",
        cell.0,
        cell.1,
        cell.2,
        names.join(", ")
    )
}

/// The run that produced a table: the gate compares only runs of the same experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Identity {
    /// Experiment name.
    pub experiment: String,
    /// Seed of the run (expected to differ between the baseline and a gate run).
    pub seed: u64,
    /// Trials per distribution.
    pub trials: u64,
    /// Checkpoints.
    pub checkpoints: Vec<usize>,
    /// Firefly threshold.
    pub tau: f64,
    /// Estimator spec strings, canonical.
    pub estimators: Vec<String>,
    /// Distribution labels and laws.
    pub distributions: Vec<(String, String)>,
    /// `fireflies` version that wrote it (printed, not compared: versions are what a gate
    /// compares).
    pub crate_version: String,
}

/// What of a run's `manifest.json` names it (the manifest does not record `tau`).
#[derive(Deserialize)]
struct ManifestIdentity {
    experiment: String,
    seed: u64,
    trials: u64,
    checkpoints: Vec<usize>,
    /// Absent from manifests written before it was recorded: then the experiment's is assumed.
    tau: Option<f64>,
    estimators: Vec<String>,
    distributions: Vec<(String, String)>,
    crate_version: String,
}

impl Identity {
    /// The identity of a run of `exp` with `trials` trials, by this binary.
    pub fn of(exp: &Experiment, trials: u64) -> Self {
        Identity {
            experiment: exp.name.clone(),
            seed: exp.file.seed,
            trials,
            checkpoints: exp.file.checkpoints.clone(),
            tau: exp.file.tau,
            estimators: exp.estimators.iter().map(ToString::to_string).collect(),
            distributions: exp
                .distributions
                .iter()
                .map(|d| (d.label.clone(), d.dist.to_string()))
                .collect(),
            crate_version: env!("CARGO_PKG_VERSION").to_string(),
        }
    }

    /// The identity of an existing report, from its `manifest.json`. The manifest does not
    /// record `tau`, so the report must be of `exp` (name, checkpoints, estimators and
    /// distributions) and `tau` is taken from it.
    ///
    /// # Errors
    /// [`Error::Io`] when the manifest cannot be read or parsed, or is of another experiment.
    pub fn from_manifest(path: &Path, exp: &Experiment) -> Result<Self> {
        let io = |message: String| Error::Io {
            path: path.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path.display(), &e))?;
        let m: ManifestIdentity =
            serde_json::from_str(&text).map_err(|e| io(format!("not a report manifest: {e}")))?;
        let id = Identity {
            experiment: m.experiment,
            seed: m.seed,
            trials: m.trials,
            checkpoints: m.checkpoints,
            tau: m.tau.unwrap_or(exp.file.tau),
            estimators: m.estimators,
            distributions: m.distributions,
            crate_version: m.crate_version,
        };
        let differences = Identity::of(exp, id.trials).differences(&id);
        if differences.is_empty() {
            Ok(id)
        } else {
            let list: Vec<String> = differences.iter().map(ToString::to_string).collect();
            Err(io(format!(
                "the report is not of experiment {}: {}",
                exp.name,
                list.join("; ")
            )))
        }
    }

    /// What makes `now` a run of another experiment than `self` (the baseline). The seed and
    /// version may differ.
    pub fn differences(&self, now: &Identity) -> Vec<Problem> {
        let mut out = Vec::new();
        let mut field = |field: &'static str, a: String, b: String| {
            if a != b {
                out.push(Problem::Identity {
                    field,
                    baseline: a,
                    now: b,
                });
            }
        };
        let json = |v: &dyn erased::Json| v.json();
        field("experiment", json(&self.experiment), json(&now.experiment));
        field("trials", json(&self.trials), json(&now.trials));
        field(
            "checkpoints",
            json(&self.checkpoints),
            json(&now.checkpoints),
        );
        field("tau", json(&self.tau), json(&now.tau));
        field("estimators", json(&self.estimators), json(&now.estimators));
        field(
            "distributions",
            json(&self.distributions),
            json(&now.distributions),
        );
        out
    }

    /// The gated rows a complete table of this run holds.
    pub fn expected(&self, cfg: &GateConfig) -> BTreeSet<Key> {
        let metrics = gated_metrics(cfg);
        let mut keys = BTreeSet::new();
        for (label, _) in &self.distributions {
            for e in &self.estimators {
                for &n in &self.checkpoints {
                    for &m in &metrics {
                        keys.insert((label.clone(), e.clone(), n, m));
                    }
                }
            }
        }
        keys
    }

    fn header(&self) -> String {
        let mut s = String::from(
            "# fireflies gate baseline: the run below (results.csv rows) and what produced it\n",
        );
        let mut line =
            |k: &str, v: &dyn erased::Json| s.push_str(&format!("# {k} = {}\n", v.json()));
        line("experiment", &self.experiment);
        line("seed", &self.seed);
        line("trials", &self.trials);
        line("checkpoints", &self.checkpoints);
        line("tau", &self.tau);
        line("estimators", &self.estimators);
        line("distributions", &self.distributions);
        line("crate_version", &self.crate_version);
        s
    }
}

/// One-line JSON of the identity's values, for the header and for messages.
mod erased {
    pub trait Json {
        fn json(&self) -> String;
    }
    impl<T: serde::Serialize> Json for T {
        fn json(&self) -> String {
            serde_json::to_string(self).unwrap_or_default()
        }
    }
}

/// A table as the gate sees it: the run that produced it and its rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    /// Who produced it.
    pub identity: Identity,
    /// Its rows (`results.csv`).
    pub rows: Vec<Row>,
    /// Exact tests of the run against the truth that replace a comparison with the baseline
    /// (see [`exact_tests`]); empty for a baseline.
    pub exact: ExactTests,
}

/// p-values of exact tests against the truth, by gated key.
pub type ExactTests = BTreeMap<Key, f64>;

/// The plain mean's relative bias is tested against its truth, 0, with the `unbiased` check's
/// p-value (the law's own null of the grand mean, `checks.json`) instead of a normal z-test
/// against the baseline: on an infinite-variance law such as `firefly` one rare giant sample
/// moves the grand mean far more often than a normal law allows (2 false alarms in 80 seeds,
/// where Holm promised at most 1%). The mean has no practical margin: any bias is a defect.
///
/// Reads the run's `checks.json`; a report without one (written before the file existed) has
/// no exact tests, and its mean is compared with the baseline like every other row.
///
/// # Errors
/// When the file exists but cannot be read or is not a list of checks.
pub fn read_exact_tests(path: &Path) -> Result<ExactTests> {
    #[derive(Deserialize)]
    struct Check {
        check: String,
        distribution: String,
        estimator: String,
        n: usize,
        p_value: Option<f64>,
    }
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(ExactTests::new()),
        Err(e) => return Err(Error::io(path.display(), &e)),
    };
    let checks: Vec<Check> = serde_json::from_str(&text).map_err(|e| Error::Io {
        path: path.display().to_string(),
        message: format!("not a list of checks: {e}"),
    })?;
    Ok(checks
        .into_iter()
        .filter_map(|c| {
            // A NaN p-value is written as null: that comparison stays with the baseline's.
            exact_entry(&c.check, c.distribution, c.estimator, c.n, c.p_value?)
        })
        .collect())
}

/// [`read_exact_tests`] from checks in memory.
pub fn exact_tests(checks: &[CheckResult]) -> ExactTests {
    checks
        .iter()
        .filter_map(|c| {
            let (d, e) = (c.distribution.clone(), c.estimator.clone());
            exact_entry(c.check.name(), d, e, c.n, c.p_value)
        })
        .collect()
}

/// The gated key an `unbiased` check of the plain mean replaces, with its p-value.
fn exact_entry(
    check: &str,
    distribution: String,
    estimator: String,
    n: usize,
    p: f64,
) -> Option<(Key, f64)> {
    (check == CheckKind::Unbiased.name() && estimator == "mean" && !p.is_nan())
        .then_some(((distribution, estimator, n, Metric::RelativeBias), p))
}

impl Snapshot {
    /// The baseline file: `# key = value` lines (JSON values) naming the run, then its
    /// `results.csv`.
    ///
    /// # Errors
    /// [`Error::Io`] when a row cannot be written.
    pub fn to_csv(&self) -> Result<Vec<u8>> {
        let err = |e: csv::Error| Error::Io {
            path: "baseline".into(),
            message: e.to_string(),
        };
        let mut w = csv::Writer::from_writer(self.identity.header().into_bytes());
        for r in &self.rows {
            w.serialize(r).map_err(err)?;
        }
        w.into_inner().map_err(|e| err(e.into_error().into()))
    }

    /// Reads a baseline written by [`Snapshot::to_csv`]; `source` names it in errors.
    ///
    /// # Errors
    /// [`Error::Io`] naming the source and line: no identity header (a baseline from before
    /// the header, or a plain `results.csv`), a malformed header line, or a row that does not
    /// parse (an unknown metric name included).
    pub fn parse(text: &str, source: &str) -> Result<Self> {
        let at = |line: usize, message: String| Error::Io {
            path: format!("{source}:{line}"),
            message,
        };
        let mut fields = serde_json::Map::new();
        let mut body = 0;
        let mut header_lines = 0;
        for line in text.split_inclusive('\n') {
            let Some(rest) = line.strip_prefix('#') else {
                break;
            };
            header_lines += 1;
            body += line.len();
            let Some((k, v)) = rest.split_once(" = ") else {
                continue; // prose
            };
            let value: serde_json::Value = serde_json::from_str(v.trim()).map_err(|e| {
                at(
                    header_lines,
                    format!("header value of {} is not JSON: {e}", k.trim()),
                )
            })?;
            fields.insert(k.trim().to_string(), value);
        }
        if fields.is_empty() {
            return Err(at(
                1,
                "no `# key = value` header naming the run that produced it (a plain \
                 results.csv, or a baseline from an older fireflies); write it with `fireflies \
                 gate EXPERIMENT --baseline FILE --update`"
                    .into(),
            ));
        }
        let identity: Identity = serde_json::from_value(serde_json::Value::Object(fields))
            .map_err(|e| at(header_lines, format!("header: {e}")))?;
        let mut reader = csv::Reader::from_reader(&text.as_bytes()[body..]);
        let rows = reader
            .deserialize()
            .enumerate()
            .map(|(i, row)| row.map_err(|e| at(header_lines + i + 2, e.to_string())))
            .collect::<Result<Vec<Row>>>()?;
        Ok(Snapshot {
            identity,
            rows,
            exact: ExactTests::new(),
        })
    }

    /// [`Snapshot::parse`] of a file.
    ///
    /// # Errors
    /// As [`Snapshot::parse`], and when the file cannot be read.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path.display(), &e))?;
        Self::parse(&text, &path.display().to_string())
    }
}

/// The gate's word on one comparison.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Verdict {
    /// Significantly worse than the baseline by more than the margin.
    Regression,
    /// Not shown to be worse by more than the margin.
    Ok,
    /// One side carries no interval to test with; the caveat says why.
    NotGated(Caveat),
}

/// One compared metric.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// Distribution label.
    pub distribution: String,
    /// Estimator spec string.
    pub estimator: String,
    /// Sample count.
    pub n: usize,
    /// Metric.
    pub metric: Metric,
    /// Baseline value.
    pub baseline: f64,
    /// Current value.
    pub now: f64,
    /// Change in the "worse" direction (positive: worse).
    pub worsening: f64,
    /// The worsening that counts, in the metric's units (a relative margin times the
    /// baseline; with a floor, the larger).
    pub margin: f64,
    /// `(worsening - margin) / s` (for a floored margin, of the binding inequality).
    pub z: Option<f64>,
    /// One-sided p-value of "worsening <= margin" (`None`: not gated).
    pub p_value: Option<f64>,
    /// Holm level it was compared with (the level of its rank, also past Holm's stop).
    pub holm_alpha: Option<f64>,
    /// The smallest worsening that a lone regression here needs to be flagged half the time:
    /// the margin plus `z(family_alpha / m)` standard errors, `m` the gated comparisons.
    pub detectable: Option<f64>,
    /// The gate's word.
    pub verdict: Verdict,
}

impl Comparison {
    /// Whether this comparison fails the gate.
    pub fn regression(&self) -> bool {
        self.verdict == Verdict::Regression
    }
}

/// Everything the gate found.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    /// Every comparison of a gated metric present and valid on both sides.
    pub comparisons: Vec<Comparison>,
    /// Everything that made a comparison impossible.
    pub problems: Vec<Problem>,
}

impl Outcome {
    /// Regressions.
    pub fn regressions(&self) -> usize {
        self.comparisons.iter().filter(|c| c.regression()).count()
    }

    /// The gate fails on any regression or any problem.
    pub fn failed(&self) -> bool {
        self.regressions() > 0 || !self.problems.is_empty()
    }
}

/// What is wrong with a gated row, if anything: NaN anywhere; without a caveat, an infinite
/// value or a missing, infinite or negative standard error.
fn invalid(r: &Row) -> Option<String> {
    if r.value.is_nan() {
        return Some("value NaN".into());
    }
    if r.se.is_some_and(f64::is_nan) {
        return Some("standard error NaN".into());
    }
    if r.caveat.is_some() {
        return None;
    }
    if !r.value.is_finite() {
        return Some(format!("value {} without a caveat", r.value));
    }
    match r.se {
        None => Some("no standard error".into()),
        Some(se) if !(se >= 0.0 && se.is_finite()) => Some(format!("standard error {se}")),
        Some(_) => None,
    }
}

/// Keys grouped by cell, as problems.
fn by_cell(
    keys: Vec<&Key>,
    problem: impl Fn((String, String, usize), Vec<Metric>) -> Problem,
) -> Vec<Problem> {
    let mut cells: BTreeMap<(String, String, usize), Vec<Metric>> = BTreeMap::new();
    for k in keys {
        cells
            .entry((k.0.clone(), k.1.clone(), k.2))
            .or_default()
            .push(k.3);
    }
    cells.into_iter().map(|(c, m)| problem(c, m)).collect()
}

/// The gated rows of a table by key, with duplicates and rows outside `expected` reported.
fn index<'a>(
    rows: &'a [Row],
    side: Side,
    expected: &BTreeSet<Key>,
    cfg: &GateConfig,
    problems: &mut Vec<Problem>,
) -> BTreeMap<Key, &'a Row> {
    let mut map = BTreeMap::new();
    for r in rows.iter().filter(|r| rule(r.metric, cfg).is_some()) {
        if map.insert(key(r), r).is_some() {
            problems.push(Problem::Duplicate { side, key: key(r) });
        }
    }
    let unexpected: Vec<&Key> = map.keys().filter(|k| !expected.contains(*k)).collect();
    problems.extend(by_cell(unexpected, |cell, metrics| Problem::Unexpected {
        side,
        cell,
        metrics,
    }));
    map
}

/// The cells of `expected` that `table` lacks, grouped by cell.
fn missing(expected: &BTreeSet<Key>, table: &BTreeMap<Key, &Row>, side: Side) -> Vec<Problem> {
    let absent: Vec<&Key> = expected
        .iter()
        .filter(|k| !table.contains_key(*k))
        .collect();
    by_cell(absent, |cell, metrics| Problem::Missing {
        side,
        cell,
        metrics,
    })
}

/// Why `snapshot` cannot be a baseline: the gated rows of its identity that it lacks, holds
/// twice, or holds as NaN or without a standard error. Empty when it is complete.
pub fn incomplete(snapshot: &Snapshot, cfg: &GateConfig) -> Vec<Problem> {
    let expected = snapshot.identity.expected(cfg);
    let mut problems = Vec::new();
    let table = index(&snapshot.rows, Side::Results, &expected, cfg, &mut problems);
    problems.extend(missing(&expected, &table, Side::Results));
    for (k, r) in &table {
        if let Some(what) = invalid(r) {
            problems.push(Problem::NotANumber {
                side: Side::Results,
                key: k.clone(),
                what,
            });
        }
    }
    problems
}

/// Compares a run with the baseline: identities, completeness of both tables against the
/// experiment's cells, then every gated metric ([`compare`]).
pub fn gate(baseline: &Snapshot, now: &Snapshot, cfg: &GateConfig) -> Outcome {
    let mut out = compare_expected(
        &baseline.rows,
        &now.rows,
        &now.identity.expected(cfg),
        &now.exact,
        cfg,
    );
    let mut problems = baseline.identity.differences(&now.identity);
    problems.append(&mut out.problems);
    out.problems = problems;
    out
}

/// Compares every gated metric of two tables, without identities: a gated row on one side
/// only, duplicated or invalid is a problem; the rest are tested against their margins, Holm
/// across all gated comparisons at `cfg.family_alpha`.
pub fn compare(baseline: &[Row], now: &[Row], cfg: &GateConfig) -> Outcome {
    let keys: BTreeSet<Key> = baseline
        .iter()
        .chain(now)
        .filter(|r| rule(r.metric, cfg).is_some())
        .map(key)
        .collect();
    compare_expected(baseline, now, &keys, &ExactTests::new(), cfg)
}

/// [`compare`], where both tables must hold exactly the gated rows `expected`.
fn compare_expected(
    baseline: &[Row],
    now: &[Row],
    expected: &BTreeSet<Key>,
    exact: &ExactTests,
    cfg: &GateConfig,
) -> Outcome {
    let mut problems = Vec::new();
    let base = index(baseline, Side::Baseline, expected, cfg, &mut problems);
    let cur = index(now, Side::Results, expected, cfg, &mut problems);
    problems.extend(missing(expected, &base, Side::Baseline));
    problems.extend(missing(expected, &cur, Side::Results));
    let std = Normal::new(0.0, 1.0).expect("standard normal");
    let mut out = Vec::new();
    // (comparison index, standard errors of each contrast) for the detectable worsening.
    let mut spreads: Vec<Vec<(f64, f64)>> = Vec::new();
    for (k, r) in &cur {
        let Some(b) = base.get(k) else { continue };
        let mut bad = false;
        for (side, row) in [(Side::Baseline, *b), (Side::Results, *r)] {
            if let Some(what) = invalid(row) {
                problems.push(Problem::NotANumber {
                    side,
                    key: k.clone(),
                    what,
                });
                bad = true;
            }
        }
        if bad {
            continue;
        }
        let rule = rule(r.metric, cfg).expect("indexed rows are gated");
        let (vb, vn) = (rule.prepare(b.value), rule.prepare(r.value));
        let contrasts = rule.contrasts();
        let margin = contrasts
            .iter()
            .map(|c| (c.c - 1.0) * vb + c.d)
            .fold(f64::NEG_INFINITY, f64::max);
        let mut c = Comparison {
            distribution: r.distribution.clone(),
            estimator: r.estimator.clone(),
            n: r.n,
            metric: r.metric,
            baseline: b.value,
            now: r.value,
            worsening: vn - vb,
            margin,
            z: None,
            p_value: None,
            holm_alpha: None,
            detectable: None,
            verdict: Verdict::Ok,
        };
        if let Some(caveat) = b.caveat.or(r.caveat) {
            c.verdict = Verdict::NotGated(caveat);
            out.push(c);
            spreads.push(Vec::new());
            continue;
        }
        if let Some(&p) = exact.get(k) {
            // Two-sided against the truth; z is its normal equivalent, for the table.
            c.margin = 0.0;
            c.z = Some(std.inverse_cdf(1.0 - p / 2.0));
            c.p_value = Some(p);
            out.push(c);
            spreads.push(Vec::new());
            continue;
        }
        let (sn, sb) = (r.se.unwrap_or(0.0), b.se.unwrap_or(0.0));
        let mut spread = Vec::new();
        // The binding inequality is the least significant one.
        let mut worst: Option<(f64, f64)> = None;
        for k in &contrasts {
            let excess = vn - k.c * vb - k.d;
            let s = (sn * sn + k.c * k.c * sb * sb).sqrt();
            let z = if s > 0.0 {
                excess / s
            } else if excess > 0.0 {
                f64::INFINITY
            } else {
                f64::NEG_INFINITY
            };
            let p = std.sf(z);
            spread.push(((k.c - 1.0) * vb + k.d, s));
            if worst.is_none_or(|(_, wp)| p > wp) {
                worst = Some((z, p));
            }
        }
        let (z, p) = worst.expect("every rule has a contrast");
        c.z = Some(z);
        c.p_value = Some(p);
        out.push(c);
        spreads.push(spread);
    }
    // Holm over the gated comparisons.
    let mut order: Vec<usize> = (0..out.len())
        .filter(|&i| out[i].p_value.is_some())
        .collect();
    order.sort_by(|&a, &b| out[a].p_value.unwrap().total_cmp(&out[b].p_value.unwrap()));
    let m = order.len();
    let z_first = std.inverse_cdf(1.0 - cfg.family_alpha / m.max(1) as f64);
    let mut rejecting = true;
    for (rank, &i) in order.iter().enumerate() {
        let level = cfg.family_alpha / (m - rank) as f64;
        let c = &mut out[i];
        c.holm_alpha = Some(level);
        rejecting = rejecting && c.p_value.unwrap() <= level;
        if rejecting && c.z.unwrap() > 0.0 {
            c.verdict = Verdict::Regression;
        }
        c.detectable = spreads[i]
            .iter()
            .map(|&(margin, s)| margin + z_first * s)
            .reduce(f64::max);
    }
    Outcome {
        comparisons: out,
        problems,
    }
}

/// A number for the table: short, with `inf` spelled out.
fn num(x: f64) -> String {
    if x.is_infinite() {
        if x > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        format!("{x:.3e}")
    }
}

/// The problems, one a line, then every comparison: regressions first, then the gated ones
/// from the least to the most comfortable, then those not gated.
pub fn table(outcome: &Outcome) -> String {
    let mut s = String::new();
    if !outcome.problems.is_empty() {
        s.push_str(&format!(
            "The gate fails: {} problem(s) make comparisons impossible:\n\n",
            outcome.problems.len()
        ));
        for p in &outcome.problems {
            s.push_str(&format!("- {p}\n"));
        }
        s.push('\n');
    }
    let mut rows: Vec<&Comparison> = outcome.comparisons.iter().collect();
    let rank = |c: &Comparison| match c.verdict {
        Verdict::Regression => 0,
        Verdict::Ok => 1,
        Verdict::NotGated(_) => 2,
    };
    rows.sort_by(|a, b| {
        rank(a).cmp(&rank(b)).then(
            a.p_value
                .unwrap_or(1.0)
                .total_cmp(&b.p_value.unwrap_or(1.0)),
        )
    });
    s.push_str(
        "| verdict | distribution | estimator | n | metric | baseline | now | worse by | margin | z | p | Holm level | flags from |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let opt = |x: Option<f64>, f: &dyn Fn(f64) -> String| x.map_or("–".to_string(), f);
    for c in rows {
        let verdict = match c.verdict {
            Verdict::Regression => "**REGRESSION**".to_string(),
            Verdict::Ok => "ok".to_string(),
            Verdict::NotGated(caveat) => format!("not gated ({})", caveat.label()),
        };
        s.push_str(&format!(
            "| {verdict} | {} | `{}` | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            c.distribution,
            c.estimator,
            c.n,
            c.metric,
            num(c.baseline),
            num(c.now),
            num(c.worsening),
            num(c.margin),
            opt(c.z, &|z| format!("{z:.2}")),
            opt(c.p_value, &|p| format!("{p:.2e}")),
            opt(c.holm_alpha, &|a| format!("{a:.2e}")),
            opt(c.detectable, &num),
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::harness::metrics::{Z, wilson};

    fn row(metric: Metric, value: f64, se: f64) -> Row {
        Row {
            distribution: "d".into(),
            estimator: "mean".into(),
            n: 16,
            metric,
            value,
            ci_low: Some(value - Z * se),
            ci_high: Some(value + Z * se),
            se: Some(se),
            level: Some(0.95),
            caveat: None,
        }
    }

    fn one(base: Row, now: Row, cfg: &GateConfig) -> Comparison {
        let out = compare(&[base], &[now], cfg);
        assert!(out.problems.is_empty(), "{:?}", out.problems);
        out.comparisons[0].clone()
    }

    /// A worsening of exactly the margin is not a regression however small its standard
    /// error; one a few standard errors beyond it is. The old gate tested against 0 and only
    /// then required the worsening to exceed the margin, so a worsening just beyond the margin
    /// with a tiny standard error failed it.
    #[test]
    fn the_test_is_one_sided_against_the_margin() {
        let cfg = GateConfig {
            relative_bias_margin: 0.01,
            ..GateConfig::default()
        };
        let b = row(Metric::RelativeBias, 0.0, 0.001);
        // 1.1% against a 1% margin with s = 0.0014: z = 0.71, p = 0.24.
        let c = one(b.clone(), row(Metric::RelativeBias, 0.011, 0.001), &cfg);
        let s = 0.001 * 2f64.sqrt();
        assert!((c.z.unwrap() - 0.001 / s).abs() < 1e-9, "{c:?}");
        assert!((c.p_value.unwrap() - 0.2398).abs() < 1e-3, "{c:?}");
        assert_eq!(c.verdict, Verdict::Ok);
        // 2% with the same spread: z = 7.07.
        let c = one(b.clone(), row(Metric::RelativeBias, 0.02, 0.001), &cfg);
        assert_eq!(c.verdict, Verdict::Regression, "{c:?}");
        // Away from zero either way: -2% is as bad as +2%; towards zero is an improvement.
        let c = one(b, row(Metric::RelativeBias, -0.02, 0.001), &cfg);
        assert_eq!(c.verdict, Verdict::Regression);
        let c = one(
            row(Metric::RelativeBias, 0.05, 0.001),
            row(Metric::RelativeBias, -0.01, 0.001),
            &cfg,
        );
        assert!(c.verdict == Verdict::Ok && c.worsening < 0.0);
    }

    /// A relative margin tests `now - (1 + m) b > 0` with variance `se_now^2 + (1+m)^2 se_b^2`.
    #[test]
    fn relative_margins_scale_the_baseline_and_its_standard_error() {
        let cfg = GateConfig::default();
        let c = one(
            row(Metric::Variance, 10.0, 0.3),
            row(Metric::Variance, 12.0, 0.4),
            &cfg,
        );
        let s = (0.4f64.powi(2) + 1.21 * 0.3f64.powi(2)).sqrt();
        assert!((c.z.unwrap() - (12.0 - 11.0) / s).abs() < 1e-12, "{c:?}");
        assert!((c.margin - 1.0).abs() < 1e-12);
        assert_eq!(c.verdict, Verdict::Ok); // z = 2.19 < 2.33
    }

    /// The standard error comes from the rows, not from their interval widths: an interval
    /// four times as wide as `Z se` (as an order-statistic interval on coarse bins can be)
    /// changes nothing.
    #[test]
    fn standard_errors_are_the_rows_not_the_interval_widths() {
        let cfg = GateConfig::default();
        let mut b = row(Metric::MedianAbsRelError, 0.10, 0.001);
        let mut n = row(Metric::MedianAbsRelError, 0.12, 0.001);
        let c0 = one(b.clone(), n.clone(), &cfg);
        for r in [&mut b, &mut n] {
            r.ci_low = Some(r.value - 4.0 * Z * 0.001);
            r.ci_high = Some(r.value + 4.0 * Z * 0.001);
        }
        let c1 = one(b, n, &cfg);
        assert_eq!(c0.z, c1.z);
        // (0.12 - 1.1 * 0.1) / sqrt(0.001^2 (1 + 1.21)) = 6.73.
        assert!((c1.z.unwrap() - 0.01 / (0.001 * 2.21f64.sqrt())).abs() < 1e-9);
        assert_eq!(c1.verdict, Verdict::Regression);
    }

    /// A firefly rate from 0 to 0.9% at the gate's 32768 trials is caught: 295 fireflies
    /// against none, Wilson standard errors. The old absolute margin of 0.01 let it through.
    #[test]
    fn a_firefly_rate_from_zero_to_nine_per_mille_is_caught() {
        let cfg = GateConfig::default();
        let rate = |k: u64| {
            let w = wilson(k, 32768);
            let mut r = row(Metric::FireflyRate, w.value, w.se.unwrap());
            (r.ci_low, r.ci_high) = (w.low, w.high);
            r
        };
        let c = one(rate(0), rate(295), &cfg);
        assert_eq!(c.verdict, Verdict::Regression, "{c:?}");
        assert_eq!(c.margin, cfg.firefly_rate_floor);
        // Below the floor: 0 to 20 fireflies (0.06%) is not a practical change.
        assert_eq!(one(rate(0), rate(20), &cfg).verdict, Verdict::Ok);
        // Doubling from 1.3% (432 of 32768) to 2.6% is caught: beyond the 25% relative margin.
        let c = one(rate(432), rate(864), &cfg);
        assert_eq!(c.verdict, Verdict::Regression, "{c:?}");
        assert!((c.margin - 0.25 * 432.0 / 32768.0).abs() < 1e-12);
        // A quarter more (432 to 540) is within the margin.
        assert_eq!(one(rate(432), rate(540), &cfg).verdict, Verdict::Ok);
    }

    /// The plain mean's relative bias takes the `unbiased` check's exact p-value: a jump that
    /// the normal comparison calls a regression (z = 20) is not one when the law's null says
    /// it is common (p = 0.3), and it stays one when the null rejects it too (p = 1e-9). Only
    /// the `unbiased` check of the plain mean is read as an exact test.
    #[test]
    fn the_means_bias_is_tested_exactly_against_the_truth() {
        let cfg = GateConfig::default();
        let (base, now) = (
            row(Metric::RelativeBias, 0.0, 0.001),
            row(Metric::RelativeBias, 0.03, 0.001),
        );
        let run = |p: f64| {
            let exact: ExactTests = [(key(&now), p)].into();
            let keys: BTreeSet<Key> = [key(&now)].into();
            compare_expected(
                std::slice::from_ref(&base),
                std::slice::from_ref(&now),
                &keys,
                &exact,
                &cfg,
            )
            .comparisons[0]
                .clone()
        };
        let common = run(0.3);
        assert_eq!(
            (common.verdict, common.p_value, common.margin),
            (Verdict::Ok, Some(0.3), 0.0)
        );
        assert!((common.z.unwrap() - 1.036).abs() < 1e-3, "{:?}", common.z);
        assert_eq!(run(1e-9).verdict, Verdict::Regression);
        assert_eq!(
            compare(
                std::slice::from_ref(&base),
                std::slice::from_ref(&now),
                &cfg
            )
            .comparisons[0]
                .verdict,
            Verdict::Regression
        );
        // The check's p-values are read from checks.json: only `unbiased` of `mean` counts.
        let dir = std::env::temp_dir().join(format!("fireflies-exact-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("checks.json");
        std::fs::write(
            &path,
            r#"[{"check":"unbiased","distribution":"glossy","estimator":"mean","n":16,"p_value":0.25},
                {"check":"unbiased","distribution":"glossy","estimator":"mean","n":64,"p_value":null},
                {"check":"unbiased","distribution":"glossy","estimator":"clamp:c=10","n":16,"p_value":0.5},
                {"check":"chebyshev","distribution":"glossy","estimator":"mean","n":16,"p_value":0.5}]"#,
        )
        .unwrap();
        let read = read_exact_tests(&path).unwrap();
        let want: ExactTests = [(
            ("glossy".into(), "mean".into(), 16, Metric::RelativeBias),
            0.25,
        )]
        .into();
        assert_eq!(read, want);
        assert!(
            read_exact_tests(&dir.join("missing.json"))
                .unwrap()
                .is_empty()
        );
        std::fs::write(&path, "{").unwrap();
        let e = read_exact_tests(&path).unwrap_err().to_string();
        assert!(
            e.contains("checks.json") && e.contains("not a list of checks"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn holm_orders_by_p_and_stops_at_the_first_acceptance() {
        let cfg = GateConfig {
            relative_bias_margin: 0.0,
            family_alpha: 0.05,
            ..GateConfig::default()
        };
        let mk = |est: &str, v: f64| {
            let mut r = row(Metric::RelativeBias, v, 1.0 / 2f64.sqrt());
            r.estimator = est.into();
            r
        };
        let base: Vec<Row> = ["a", "b", "c"].iter().map(|e| mk(e, 0.0)).collect();
        // z = 3.0, 2.2, 2.0 (s = 1): p = 0.00135, 0.0139, 0.0228; levels 0.0167, 0.025, 0.05.
        let now = vec![mk("a", 3.0), mk("b", 2.2), mk("c", 2.0)];
        let out = compare(&base, &now, &cfg);
        let v: Vec<_> = out.comparisons.iter().map(|c| c.regression()).collect();
        assert_eq!(v, [true, true, true]);
        let levels: Vec<_> = out
            .comparisons
            .iter()
            .map(|c| c.holm_alpha.unwrap())
            .collect();
        assert!((levels[0] - 0.05 / 3.0).abs() < 1e-12 && (levels[2] - 0.05).abs() < 1e-12);
        // z = 3.0, 1.8, 1.9: p = 0.00135, 0.0359, 0.0287. c ranks second and fails its level
        // 0.025, so Holm stops: b is not a regression although its p is below its level 0.05.
        let now = vec![mk("a", 3.0), mk("b", 1.8), mk("c", 1.9)];
        let out = compare(&base, &now, &cfg);
        let v: Vec<_> = out.comparisons.iter().map(|c| c.regression()).collect();
        assert_eq!(v, [true, false, false]);
    }

    #[test]
    fn caveats_are_listed_not_gated_and_nan_is_a_problem() {
        let cfg = GateConfig::default();
        let mut tail = row(Metric::Variance, 5.0, 0.0);
        (tail.ci_low, tail.ci_high, tail.se, tail.level) = (None, None, None, None);
        tail.caveat = Some(Caveat::TailDominated);
        let out = compare(
            std::slice::from_ref(&tail),
            &[row(Metric::Variance, 50.0, 1.0)],
            &cfg,
        );
        assert!(out.problems.is_empty());
        assert_eq!(
            out.comparisons[0].verdict,
            Verdict::NotGated(Caveat::TailDominated)
        );
        assert!(table(&out).contains("not gated (tail-dominated)"));
        // NaN value, NaN se, a missing se without a caveat: problems, never "not gated".
        let mut no_se = row(Metric::Variance, 5.0, 0.1);
        no_se.se = None;
        for bad in [
            row(Metric::Variance, f64::NAN, 0.1),
            row(Metric::Variance, 5.0, f64::NAN),
            no_se,
        ] {
            let out = compare(
                &[row(Metric::Variance, 5.0, 0.1)],
                std::slice::from_ref(&bad),
                &cfg,
            );
            assert!(out.failed(), "{bad:?}");
            assert!(
                matches!(
                    &out.problems[..],
                    [Problem::NotANumber {
                        side: Side::Results,
                        ..
                    }]
                ),
                "{:?}",
                out.problems
            );
            assert!(out.comparisons.is_empty());
        }
    }

    #[test]
    fn rows_on_one_side_only_are_problems() {
        let cfg = GateConfig::default();
        let mut other = row(Metric::Variance, 1.0, 0.1);
        other.distribution = "glossy".into();
        let out = compare(
            &[row(Metric::Variance, 1.0, 0.1), other],
            &[row(Metric::Variance, 1.0, 0.1)],
            &cfg,
        );
        assert_eq!(out.problems.len(), 1);
        assert_eq!(
            out.problems[0].to_string(),
            "missing from the results: glossy / mean / n = 16: variance"
        );
    }

    #[test]
    fn config_values_are_validated_by_name() {
        assert!(GateConfig::default().validate().is_ok());
        let bad = [
            (
                GateConfig {
                    family_alpha: 5.0,
                    ..GateConfig::default()
                },
                "gate.family_alpha",
            ),
            (
                GateConfig {
                    family_alpha: f64::NAN,
                    ..GateConfig::default()
                },
                "gate.family_alpha",
            ),
            (
                GateConfig {
                    variance_margin: -0.1,
                    ..GateConfig::default()
                },
                "gate.variance_margin",
            ),
            (
                GateConfig {
                    relative_bias_margin: f64::INFINITY,
                    ..GateConfig::default()
                },
                "gate.relative_bias_margin",
            ),
            (
                GateConfig {
                    firefly_rate_floor: 1.0,
                    ..GateConfig::default()
                },
                "gate.firefly_rate_floor",
            ),
        ];
        for (cfg, name) in bad {
            let e = cfg.validate().unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
    }

    fn identity() -> Identity {
        Identity {
            experiment: "gate".into(),
            seed: 1,
            trials: 100,
            checkpoints: vec![16],
            tau: 1.0,
            estimators: vec!["mean".into(), "gmonb:M=21,threshold=0.25".into()],
            distributions: vec![("d".into(), "LogNormal(mu=0, sigma=1)".into())],
            crate_version: "0.1.0".into(),
        }
    }

    #[test]
    fn a_snapshot_round_trips_through_its_file() {
        let id = identity();
        let rows = vec![row(Metric::Variance, 1.5, 0.25), {
            let mut r = row(Metric::FireflyRate, 0.0, 3e-5);
            r.estimator = "gmonb:M=21,threshold=0.25".into();
            r
        }];
        let snap = Snapshot {
            identity: id.clone(),
            rows,
            exact: ExactTests::new(),
        };
        let bytes = snap.to_csv().unwrap();
        let text = String::from_utf8(bytes).unwrap();
        assert!(text.starts_with("# fireflies gate baseline"), "{text}");
        assert!(text.contains("\n# seed = 1\n"), "{text}");
        assert_eq!(Snapshot::parse(&text, "b.csv").unwrap(), snap);
        // A plain results.csv has no identity; a renamed metric is an error naming it.
        let body = &text[text.find("distribution,").unwrap()..];
        let e = Snapshot::parse(body, "b.csv").unwrap_err().to_string();
        assert!(e.contains("b.csv:1") && e.contains("header"), "{e}");
        let renamed = text.replace(",variance,", ",variance_of_estimates,");
        let e = Snapshot::parse(&renamed, "b.csv").unwrap_err().to_string();
        assert!(
            e.contains("unknown metric") && e.contains("variance_of_estimates"),
            "{e}"
        );
    }

    #[test]
    fn identities_differ_by_experiment_not_by_seed_or_version() {
        let a = identity();
        let mut b = a.clone();
        b.seed = 2;
        b.crate_version = "9.9.9".into();
        assert!(a.differences(&b).is_empty());
        b.estimators.pop();
        b.trials = 200;
        let d: Vec<String> = a.differences(&b).iter().map(ToString::to_string).collect();
        assert_eq!(d.len(), 2, "{d:?}");
        assert!(
            d[0].contains("trials is 100 in the baseline, 200 now"),
            "{d:?}"
        );
        assert!(d[1].contains("estimators"), "{d:?}");
    }
}
