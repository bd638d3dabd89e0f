//! The TOML schema of an experiment: what to sample, which estimators to run, where to read
//! their estimates, and which claims to check. Unknown keys are errors naming the key and line.
//!
//! ```toml
//! name = "default"
//! seed = 20261121
//! trials = 4000
//! checkpoints = [16, 64, 256, 1024, 4096]
//! tau = 1.0
//! estimators = ["mean", "mon:M=21", "gmon:M=21"]
//!
//! [[distributions]]
//! dist = { kind = "preset", name = "caustic" }
//!
//! [[distributions]]
//! label = "pareto-1.01"
//! dist = { kind = "truncated-pareto", scale = 1.0, shape = 1.01, upper = 1e6 }
//!
//! [checks]
//! family_alpha = 0.01
//! ```

use super::claims::ChecksConfig;
use crate::dist::{Dist, DistSpec};
use crate::error::{Error, Result};
use crate::estimators::EstimatorSpec;
use crate::limits::shorten;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The experiment shipped inside the binary and run by `cargo run --release`.
pub const DEFAULT_TOML: &str = include_str!("../../experiments/default.toml");

/// One distribution of an experiment.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DistributionEntry {
    /// Name in reports and the seed stream; defaults to the preset name or the law's text.
    pub label: Option<String>,
    /// The generator.
    pub dist: DistSpec,
}

/// An experiment file as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentFile {
    /// Report directory name; defaults to the file stem.
    pub name: Option<String>,
    /// One line on what the experiment shows.
    #[serde(default)]
    pub description: String,
    /// Seed of every random stream.
    pub seed: u64,
    /// Independent trials per distribution.
    pub trials: u64,
    /// Sample counts at which every estimate is read, ascending.
    pub checkpoints: Vec<usize>,
    /// Firefly threshold: an estimate above `(1 + tau) mu` is a firefly.
    #[serde(default = "default_tau")]
    pub tau: f64,
    /// Estimator spec strings.
    pub estimators: Vec<String>,
    /// Generators.
    pub distributions: Vec<DistributionEntry>,
    /// Checks.
    #[serde(default)]
    pub checks: ChecksConfig,
    /// Regression-gate margins (used by `fireflies gate`).
    #[serde(default)]
    pub gate: super::gate::GateConfig,
}

fn default_tau() -> f64 {
    1.0
}

/// A distribution ready to sample.
#[derive(Debug, Clone)]
pub struct Distribution {
    /// Name in reports and seed derivation.
    pub label: String,
    /// The generator.
    pub dist: Dist,
}

/// A checked experiment.
#[derive(Debug, Clone)]
pub struct Experiment {
    /// Report directory name.
    pub name: String,
    /// The file as parsed (for the manifest).
    pub file: ExperimentFile,
    /// The TOML text it was parsed from (shards carry it so a merge rebuilds the same run).
    pub source_toml: String,
    /// Parsed estimators, in file order.
    pub estimators: Vec<EstimatorSpec>,
    /// Built distributions, in file order.
    pub distributions: Vec<Distribution>,
    /// Checks the configuration asks for that this experiment cannot run (printed before a
    /// run and listed in the summary).
    pub warnings: Vec<String>,
}

/// A report directory name must be one plain path component, so that `name = "../x"` or
/// `name = "/abs/x"` cannot write outside `reports/`.
fn check_name(name: &str) -> Result<()> {
    let mut parts = Path::new(name).components();
    let plain = matches!(parts.next(), Some(std::path::Component::Normal(_)))
        && parts.next().is_none()
        && !name.contains(['/', '\\', '\0'])
        && name.trim() == name;
    if plain {
        Ok(())
    } else {
        Err(Error::param(
            "name",
            format!("\"{}\"", shorten(name)),
            "must be a plain file name (no path separators, no '..', not empty, no surrounding spaces): \
             it names the report directory under reports/",
        ))
    }
}

impl Experiment {
    /// Parses and checks an experiment; `source` names it in errors, `default_name` is used
    /// when the file sets none.
    pub fn from_toml(text: &str, source: &str, default_name: &str) -> Result<Self> {
        let in_file = |message: String| Error::Experiment {
            file: source.to_string(),
            message,
        };
        let file: ExperimentFile =
            toml::from_str(text).map_err(|e| in_file(e.to_string().trim_end().to_string()))?;
        Self::from_file(file, text, source, default_name).map_err(|e| match e {
            Error::Experiment { .. } => e,
            e => in_file(e.to_string()),
        })
    }

    /// Reads an experiment from disk.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path.display(), &e))?;
        let stem = path
            .file_stem()
            .map_or("experiment".into(), |s| s.to_string_lossy().into_owned());
        Self::from_toml(&text, &path.display().to_string(), &stem)
    }

    /// The embedded default experiment.
    pub fn default_experiment() -> Result<Self> {
        Self::from_toml(
            DEFAULT_TOML,
            "experiments/default.toml (embedded)",
            "default",
        )
    }

    fn from_file(
        file: ExperimentFile,
        text: &str,
        source: &str,
        default_name: &str,
    ) -> Result<Self> {
        // An entry's error names the file and the entry, e.g. `estimators[2] = "mon:M=0"`.
        let at = |entry: String, what: &dyn std::fmt::Display| Error::Experiment {
            file: source.to_string(),
            message: format!("{entry}: {what}"),
        };
        if file.trials < 4 {
            return Err(Error::param(
                "trials",
                file.trials,
                "must be at least 4 (docs/estimators.md §7)",
            ));
        }
        if file.checkpoints.is_empty()
            || file.checkpoints[0] == 0
            || file.checkpoints.windows(2).any(|w| w[0] >= w[1])
        {
            return Err(Error::param(
                "checkpoints",
                format!("{:?}", file.checkpoints),
                "must be positive and strictly ascending",
            ));
        }
        if !(file.tau > 0.0 && file.tau.is_finite()) {
            return Err(Error::param("tau", file.tau, "must be finite and > 0"));
        }
        let c = &file.checks;
        if !(c.family_alpha > 0.0 && c.family_alpha < 1.0) {
            return Err(Error::param(
                "checks.family_alpha",
                c.family_alpha,
                "must be in (0, 1)",
            ));
        }
        if !(c.mon_delta >= 0.0 && c.mon_delta < 1.0) {
            return Err(Error::param(
                "checks.mon_delta",
                c.mon_delta,
                "must be in [0, 1)",
            ));
        }
        if !(c.chebyshev_k == 0.0 || c.chebyshev_k > 1.0) {
            return Err(Error::param(
                "checks.chebyshev_k",
                c.chebyshev_k,
                "must be 0 or > 1",
            ));
        }
        if !(c.firefly_ceiling > 0.0 && c.firefly_ceiling <= 1.0) {
            return Err(Error::param(
                "checks.firefly_ceiling",
                c.firefly_ceiling,
                "must be in (0, 1]",
            ));
        }
        file.gate.validate()?;
        let entry = |list: &str, i: usize, text: &str, e: Error| {
            at(format!("{list}[{i}] = \"{}\"", shorten(text)), &e)
        };
        let mut estimators: Vec<EstimatorSpec> = Vec::with_capacity(file.estimators.len());
        for (i, text) in file.estimators.iter().enumerate() {
            let spec: EstimatorSpec = text.parse().map_err(|e| entry("estimators", i, text, e))?;
            spec.build().map_err(|e| entry("estimators", i, text, e))?;
            if let Some(j) = estimators.iter().position(|s| *s == spec) {
                return Err(at(
                    format!("estimators[{i}] = \"{}\"", shorten(text)),
                    &format!(
                        "the same estimator as estimators[{j}] = \"{}\"; list each once",
                        shorten(&file.estimators[j])
                    ),
                ));
            }
            estimators.push(spec);
        }
        if estimators.is_empty() {
            return Err(Error::param(
                "estimators",
                "[]",
                "name at least one estimator",
            ));
        }
        for (i, r) in c.robust.iter().enumerate() {
            let spec: EstimatorSpec = r.parse().map_err(|e| entry("checks.robust", i, r, e))?;
            if !estimators.contains(&spec) {
                return Err(Error::param(
                    "checks.robust",
                    r,
                    "is not among the experiment's estimators",
                ));
            }
        }
        let mut distributions = Vec::with_capacity(file.distributions.len());
        for (i, entry) in file.distributions.iter().enumerate() {
            let dist = entry
                .dist
                .build()
                .map_err(|e| at(format!("distributions[{i}]"), &e))?;
            if !(dist.mean() > 0.0) {
                return Err(at(
                    format!("distributions[{i}] = {dist}"),
                    &"its mean is 0 (every sample is 0): relative bias, relative error and the \
                      firefly threshold (1 + tau) mu are undefined",
                ));
            }
            let label = match (&entry.label, &entry.dist) {
                (Some(l), _) => l.clone(),
                (None, DistSpec::Preset { name }) => name.clone(),
                (None, _) => dist.to_string(),
            };
            if distributions
                .iter()
                .any(|d: &Distribution| d.label == label)
            {
                return Err(Error::param("distributions.label", label, "is used twice"));
            }
            distributions.push(Distribution { label, dist });
        }
        if distributions.is_empty() {
            return Err(Error::param(
                "distributions",
                "[]",
                "name at least one distribution",
            ));
        }
        let name = file
            .name
            .clone()
            .unwrap_or_else(|| default_name.to_string());
        check_name(&name)?;
        let warnings = super::claims::unreachable(&file.checks, &estimators, &file.checkpoints);
        Ok(Experiment {
            name,
            file,
            source_toml: text.to_string(),
            estimators,
            distributions,
            warnings,
        })
    }

    /// The largest checkpoint: samples drawn per trial.
    pub fn max_n(&self) -> usize {
        *self.file.checkpoints.last().expect("checked non-empty")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
seed = 1
trials = 8
checkpoints = [4, 16]
estimators = ["mean", "mon:M=3"]
[[distributions]]
dist = { kind = "preset", name = "diffuse" }
"#;

    #[test]
    fn minimal_file_parses_with_defaults() {
        let e = Experiment::from_toml(MINIMAL, "t.toml", "t").unwrap();
        assert_eq!(e.name, "t");
        assert_eq!(e.file.tau, 1.0);
        assert_eq!(e.distributions[0].label, "diffuse");
        assert_eq!(e.max_n(), 16);
    }

    #[test]
    fn unknown_key_names_key_and_line() {
        let text = MINIMAL.replace("trials = 8", "trials = 8\ntrails = 9");
        let e = Experiment::from_toml(&text, "t.toml", "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("trails") && e.contains("line 4"), "{e}");
    }

    #[test]
    fn bad_values_are_named() {
        let text = MINIMAL.replace("[4, 16]", "[16, 4]");
        let e = Experiment::from_toml(&text, "t.toml", "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("checkpoints"), "{e}");
        let text = MINIMAL.replace("mon:M=3", "mon:M=0");
        let e = Experiment::from_toml(&text, "t.toml", "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("M = 0"), "{e}");
        let text = MINIMAL.replace("\"diffuse\"", "\"difuse\"");
        let e = Experiment::from_toml(&text, "t.toml", "t")
            .unwrap_err()
            .to_string();
        assert!(e.contains("difuse"), "{e}");
    }

    #[test]
    fn embedded_default_is_valid() {
        Experiment::default_experiment().unwrap();
    }
}
