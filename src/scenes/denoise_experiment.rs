//! The TOML schema of the denoising experiment (`experiments/denoise.toml`, issue 15): which
//! scenes, at which sample counts, which colour sources go into NFOR with which variance, and the
//! check of NFOR's own MSE estimate over seeds. Unknown keys are errors naming the key and line;
//! a bad entry names the file and the entry.
//!
//! Every scene and spp is rendered `repeats` times, repeat `r` with seed
//! `seed + r · 2³²` ([`DenoiseExperiment::repeat_seed`]): repeat 0 is the run of one repeat, and
//! no repeat meets the MSE check's seeds `seed + 1 ..= seed + seeds` (`seeds` is a `u32`).
//!
//! ```toml
//! seed = 0
//! repeats = 4
//! spp = [4, 16, 64]
//! montage_spp = 16
//!
//! [[sources]]
//! estimator = "mean"
//! variance = ["halves", "sample"]
//!
//! [[sources]]
//! estimator = "gmon:M=5"
//! variance = ["halves"]
//!
//! [mse_check]
//! scene = "cbox"
//! spp = 16
//! seeds = 16
//! variance = ["sample", "halves"]
//!
//! [quick]
//! resolution = 0.25
//! spp = [4, 16]
//! reference_spp = 256
//! seeds = 4
//! repeats = 2
//!
//! [[scenes]]
//! name = "cbox"
//! file = "scenes/cbox.xml"
//! width = 128
//! height = 128
//! reference_spp = 16384
//! ```

use super::experiment::{MIN_SIDE, Scene, plain_name};
use super::nfor_input::{ColorSource, VarianceSource};
use super::tables::label;
use crate::error::{Error, Result};
use crate::estimators::{EstimatorSpec, MeanSpec};
use crate::image::metrics::FireflyRule;
use crate::limits::shorten;
use crate::render::film::MIN_NFOR_SPP;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One colour source as written: an estimator the render runs on each half, and the variances
/// NFOR is given for it (each a separate NFOR run).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceEntry {
    /// `mean` or an estimator spec (`gmon:M=5`).
    pub estimator: String,
    /// `sample` and/or `halves` (see [`VarianceSource`]).
    pub variance: Vec<String>,
}

/// The check of NFOR's first-pass MSE estimate as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MseCheckEntry {
    /// Name of one of the scenes.
    pub scene: String,
    /// Samples per pixel of each render.
    pub spp: u32,
    /// Renders, seeds `seed + 1 ..= seed + seeds` (at least 2, for an interval).
    pub seeds: u32,
    /// The source denoised (one of `sources`; default the mean).
    #[serde(default = "default_mean")]
    pub estimator: String,
    /// Its variances, each checked on the same renders (default `["sample"]`).
    #[serde(default = "default_sample")]
    pub variance: Vec<String>,
}

fn default_mean() -> String {
    "mean".into()
}
fn default_sample() -> Vec<String> {
    vec!["sample".into()]
}
fn default_one() -> u32 {
    1
}
fn default_factor() -> f64 {
    FireflyRule::DEFAULT_FACTOR
}
fn default_floor() -> f64 {
    FireflyRule::DEFAULT_FLOOR
}

/// How `--quick` scales the experiment down.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuickEntry {
    /// Factor applied to every width and height (each stays at least [`MIN_SIDE`]).
    pub resolution: f64,
    /// Sample counts of every scene (replacing theirs).
    pub spp: Vec<u32>,
    /// Cap on every reference's spp.
    pub reference_spp: u64,
    /// Cap on the MSE check's seeds.
    pub seeds: u32,
    /// Cap on `repeats` (default 1).
    #[serde(default = "default_one")]
    pub repeats: u32,
}

/// One scene as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DenoiseSceneEntry {
    /// Name in tables and file names (a plain file name).
    pub name: String,
    /// Scene file, relative to the experiment file's folder.
    pub file: PathBuf,
    /// Rendered width in pixels (replaces the film's).
    pub width: u32,
    /// Rendered height in pixels.
    pub height: u32,
    /// Samples per pixel of the reference (more are used if the cached one has more).
    pub reference_spp: u64,
    /// `"box"` replaces the film's reconstruction filter with a box, as `render --rfilter box`.
    #[serde(default)]
    pub rfilter: Option<String>,
    /// This scene's sample counts (default: the file's `spp`).
    #[serde(default)]
    pub spp: Option<Vec<u32>>,
}

/// A denoising experiment file as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DenoiseFile {
    /// One line on what the experiment shows.
    #[serde(default)]
    pub description: String,
    /// Seed of the first repeat's renders (the MSE check uses the next `seeds` seeds; see
    /// [`DenoiseExperiment::repeat_seed`] for the other repeats).
    pub seed: u64,
    /// Independent renders per scene and spp (default 1), for intervals over repeats.
    #[serde(default = "default_one")]
    pub repeats: u32,
    /// Sample counts of each render (`repeats` renders per count), unless a scene gives its own.
    pub spp: Vec<u32>,
    /// Samples per pixel of the crops in `montage.png` (one of every scene's counts).
    pub montage_spp: u32,
    /// Firefly pixels: luminance above `factor` times the reference's plus `floor`.
    #[serde(default = "default_factor")]
    pub firefly_factor: f64,
    /// See `firefly_factor`.
    #[serde(default = "default_floor")]
    pub firefly_floor: f64,
    /// What NFOR denoises.
    pub sources: Vec<SourceEntry>,
    /// The MSE estimate's check.
    pub mse_check: MseCheckEntry,
    /// What `--quick` does.
    pub quick: QuickEntry,
    /// The scenes.
    pub scenes: Vec<DenoiseSceneEntry>,
}

/// A checked colour source.
#[derive(Debug, Clone, PartialEq)]
pub struct Source {
    /// The estimator the film runs (the mean for [`ColorSource::Mean`]).
    pub spec: EstimatorSpec,
    /// What [`super::nfor_input::nfor_input`] is asked for.
    pub color: ColorSource,
    /// Short name in tables and legends.
    pub label: String,
    /// Variances NFOR is run with, in file order.
    pub variances: Vec<VarianceSource>,
}

/// A checked scene: the scene experiment's [`Scene`] (its `spp` is the largest count, its
/// checkpoints unused) and the counts rendered.
#[derive(Debug, Clone)]
pub struct DenoiseScene {
    /// Name, file, size, reference spp, filter.
    pub scene: Scene,
    /// Sample counts, ascending and distinct; `repeats` renders each.
    pub spps: Vec<u32>,
}

/// The checked MSE check.
#[derive(Debug, Clone, PartialEq)]
pub struct MseCheck {
    /// Index into the scenes.
    pub scene: usize,
    /// Samples per pixel.
    pub spp: u32,
    /// Number of seeds.
    pub seeds: u32,
    /// Index into the sources.
    pub source: usize,
    /// The variances, each an NFOR run on every render.
    pub variances: Vec<VarianceSource>,
}

/// A checked denoising experiment.
#[derive(Debug, Clone)]
pub struct DenoiseExperiment {
    /// The file as given (names it in errors and the manifest).
    pub source: String,
    /// The file as parsed.
    pub file: DenoiseFile,
    /// Whether `--quick` scaled it down.
    pub quick: bool,
    /// The colour sources, in file order.
    pub sources: Vec<Source>,
    /// Firefly rule of the metrics.
    pub rule: FireflyRule,
    /// The scenes.
    pub scenes: Vec<DenoiseScene>,
    /// The MSE check.
    pub mse_check: MseCheck,
    /// Samples per pixel of the montage's crops.
    pub montage_spp: u32,
    /// Renders per scene and spp (after `--quick`'s cap), at least 1.
    pub repeats: u32,
}

/// Distance between the seeds of consecutive repeats: larger than any MSE-check offset
/// (`seeds` is a `u32`), so a repeat's render never reuses an MSE-check render's seed.
pub const REPEAT_SEED_STRIDE: u64 = 1 << 32;

/// Parses a variance name.
pub fn parse_variance(text: &str) -> Option<VarianceSource> {
    match text {
        "sample" => Some(VarianceSource::Sample),
        "halves" => Some(VarianceSource::Halves),
        _ => None,
    }
}

/// The name of a variance source, as the file and the CSV write it.
pub fn variance_name(v: VarianceSource) -> &'static str {
    match v {
        VarianceSource::Sample => "sample",
        VarianceSource::Halves => "halves",
    }
}

/// Checks a list of sample counts: non-empty, each at least [`MIN_NFOR_SPP`]; returns them
/// sorted and distinct. `entry` names the list in errors.
fn check_spps(list: &[u32], entry: &str) -> std::result::Result<Vec<u32>, (String, String)> {
    if list.is_empty() {
        return Err((
            format!("{entry} = []"),
            "give at least one sample count".into(),
        ));
    }
    for (i, &n) in list.iter().enumerate() {
        if n < MIN_NFOR_SPP {
            return Err((
                format!("{entry}[{i}] = {n}"),
                format!(
                    "NFOR needs at least {MIN_NFOR_SPP} samples per pixel (two per half, so that \
                     each half has a variance)"
                ),
            ));
        }
    }
    let mut v = list.to_vec();
    v.sort_unstable();
    v.dedup();
    Ok(v)
}

impl DenoiseExperiment {
    /// Reads and checks an experiment file; with `quick`, scales it down as its `[quick]`
    /// section says. Scene files are resolved against the experiment file's folder and must
    /// exist.
    ///
    /// # Errors
    ///
    /// [`Error::Io`] if the file cannot be read; [`Error::Experiment`] naming the file and the
    /// entry (or the TOML line) for anything it rejects.
    pub fn load(path: &Path, quick: bool) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path.display(), &e))?;
        let dir = path.parent().unwrap_or_else(|| Path::new(""));
        Self::from_toml(&text, &path.display().to_string(), dir, quick)
    }

    /// [`DenoiseExperiment::load`] from text; `source` names it in errors, `dir` is where
    /// scene paths are resolved.
    ///
    /// # Errors
    ///
    /// [`Error::Experiment`] naming `source` and the entry at fault.
    pub fn from_toml(text: &str, source: &str, dir: &Path, quick: bool) -> Result<Self> {
        let file: DenoiseFile = toml::from_str(text).map_err(|e| Error::Experiment {
            file: source.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let mut exp = Self::check(file, dir, quick).map_err(|(entry, why)| Error::Experiment {
            file: source.to_string(),
            message: format!("{entry}: {why}"),
        })?;
        exp.source = source.to_string();
        Ok(exp)
    }

    fn check(
        file: DenoiseFile,
        dir: &Path,
        quick: bool,
    ) -> std::result::Result<Self, (String, String)> {
        if file.sources.is_empty() {
            return Err((
                "sources".into(),
                "give at least one [[sources]] entry".into(),
            ));
        }
        let mut sources: Vec<Source> = Vec::new();
        for (i, s) in file.sources.iter().enumerate() {
            let entry = format!("sources[{i}].estimator = \"{}\"", shorten(&s.estimator));
            let spec: EstimatorSpec = s
                .estimator
                .parse()
                .map_err(|e: Error| (entry.clone(), e.to_string()))?;
            spec.build().map_err(|e| (entry.clone(), e.to_string()))?;
            if sources.iter().any(|o| o.spec == spec) {
                return Err((entry, format!("repeats the estimator {spec}")));
            }
            let color = if spec == EstimatorSpec::Mean(MeanSpec) {
                ColorSource::Mean
            } else {
                ColorSource::Estimator(spec.to_string())
            };
            if s.variance.is_empty() {
                return Err((
                    format!("sources[{i}].variance = []"),
                    "give \"sample\", \"halves\" or both".into(),
                ));
            }
            let mut variances = Vec::new();
            for (j, v) in s.variance.iter().enumerate() {
                let entry = format!("sources[{i}].variance[{j}] = \"{}\"", shorten(v));
                let parsed = parse_variance(v)
                    .ok_or_else(|| (entry.clone(), "must be \"sample\" or \"halves\"".into()))?;
                if variances.contains(&parsed) {
                    return Err((entry, "is listed twice".into()));
                }
                variances.push(parsed);
            }
            sources.push(Source {
                label: label(&spec),
                spec,
                color,
                variances,
            });
        }
        let rule = FireflyRule::new(file.firefly_factor, file.firefly_floor)
            .map_err(|e| ("firefly_factor/firefly_floor".to_string(), e.to_string()))?;
        let default_spps = check_spps(&file.spp, "spp")?;
        let q = &file.quick;
        if !(q.resolution > 0.0 && q.resolution <= 1.0) || q.reference_spp < 2 || q.seeds < 2 {
            return Err((
                format!(
                    "quick = {{ resolution = {}, reference_spp = {}, seeds = {} }}",
                    q.resolution, q.reference_spp, q.seeds
                ),
                "resolution must be in (0, 1], reference_spp and seeds at least 2".into(),
            ));
        }
        let quick_spps = check_spps(&q.spp, "quick.spp")?;
        for (key, v) in [("repeats", file.repeats), ("quick.repeats", q.repeats)] {
            if v < 1 {
                return Err((
                    format!("{key} = {v}"),
                    "must be at least 1 (renders per scene and sample count)".into(),
                ));
            }
        }
        let repeats = if quick {
            file.repeats.min(q.repeats)
        } else {
            file.repeats
        };
        if file.scenes.is_empty() {
            return Err(("scenes".into(), "give at least one [[scenes]] entry".into()));
        }
        let mut scenes: Vec<DenoiseScene> = Vec::new();
        for (i, s) in file.scenes.iter().enumerate() {
            let entry = |key: &str, value: &dyn std::fmt::Display| {
                format!("scenes[{i}] (\"{}\").{key} = {value}", shorten(&s.name))
            };
            if !plain_name(&s.name) {
                return Err((
                    format!("scenes[{i}].name = \"{}\"", shorten(&s.name)),
                    "must be a plain file name (it names the scene's files)".into(),
                ));
            }
            if scenes.iter().any(|o| o.scene.name == s.name) {
                return Err((
                    entry("name", &s.name),
                    "repeats another scene's name".into(),
                ));
            }
            let path = dir.join(&s.file);
            if !path.is_file() {
                return Err((
                    entry("file", &s.file.display()),
                    format!("{} is not a file", path.display()),
                ));
            }
            for (key, v) in [("width", s.width), ("height", s.height)] {
                if v < MIN_SIDE {
                    return Err((
                        entry(key, &v),
                        format!("must be at least {MIN_SIDE} (SSIM's window)"),
                    ));
                }
            }
            if s.reference_spp < 2 {
                return Err((
                    entry("reference_spp", &s.reference_spp),
                    "must be at least 2 (a reference's error needs two samples)".into(),
                ));
            }
            let box_filter = match s.rfilter.as_deref() {
                None => false,
                Some("box") => true,
                Some(other) => {
                    return Err((
                        entry("rfilter", &format!("\"{}\"", shorten(other))),
                        "the only override is \"box\"".into(),
                    ));
                }
            };
            let mut spps = match &s.spp {
                Some(list) => check_spps(list, &format!("scenes[{i}] (\"{}\").spp", s.name))?,
                None => default_spps.clone(),
            };
            let (mut width, mut height, mut reference_spp) = (s.width, s.height, s.reference_spp);
            if quick {
                let scale = |v: u32| ((f64::from(v) * q.resolution).round() as u32).max(MIN_SIDE);
                (width, height) = (scale(width), scale(height));
                reference_spp = reference_spp.min(q.reference_spp);
                spps = quick_spps.clone();
            }
            scenes.push(DenoiseScene {
                scene: Scene {
                    name: s.name.clone(),
                    file: path,
                    width,
                    height,
                    spp: spps.last().copied().unwrap_or(MIN_NFOR_SPP),
                    reference_spp,
                    box_filter,
                    crop: None,
                    checkpoints: Vec::new(),
                },
                spps,
            });
        }
        // A quick run shows its largest count when the file's is not among its counts.
        let montage_spp = match quick_spps.last() {
            Some(&last) if quick && !quick_spps.contains(&file.montage_spp) => last,
            _ => file.montage_spp,
        };
        for s in &scenes {
            if !s.spps.contains(&montage_spp) {
                return Err((
                    format!("montage_spp = {montage_spp}"),
                    format!(
                        "is not a sample count of scene \"{}\" ({:?})",
                        s.scene.name, s.spps
                    ),
                ));
            }
        }
        let m = &file.mse_check;
        let scene = scenes
            .iter()
            .position(|s| s.scene.name == m.scene)
            .ok_or_else(|| {
                (
                    format!("mse_check.scene = \"{}\"", shorten(&m.scene)),
                    format!(
                        "is not a scene of the experiment; its scenes: {}",
                        scenes
                            .iter()
                            .map(|s| s.scene.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })?;
        let spp = check_spps(&[m.spp], "mse_check.spp")?[0];
        let spp = if quick {
            // The quick run checks at its largest count.
            quick_spps.last().copied().unwrap_or(spp)
        } else {
            spp
        };
        let seeds = if quick { m.seeds.min(q.seeds) } else { m.seeds };
        if seeds < 2 {
            return Err((
                format!("mse_check.seeds = {}", m.seeds),
                "must be at least 2 (an interval over seeds needs two)".into(),
            ));
        }
        let entry = format!("mse_check.estimator = \"{}\"", shorten(&m.estimator));
        let spec: EstimatorSpec = m
            .estimator
            .parse()
            .map_err(|e: Error| (entry.clone(), e.to_string()))?;
        let source = sources
            .iter()
            .position(|s| s.spec == spec)
            .ok_or_else(|| (entry, "is not one of `sources`".to_string()))?;
        if m.variance.is_empty() {
            return Err((
                "mse_check.variance = []".into(),
                "give \"sample\", \"halves\" or both".into(),
            ));
        }
        let mut variances = Vec::new();
        for (j, v) in m.variance.iter().enumerate() {
            let entry = format!("mse_check.variance[{j}] = \"{}\"", shorten(v));
            let parsed = parse_variance(v).ok_or_else(|| {
                (
                    entry.clone(),
                    "must be \"sample\" or \"halves\"".to_string(),
                )
            })?;
            if variances.contains(&parsed) {
                return Err((entry, "is listed twice".into()));
            }
            variances.push(parsed);
        }
        let mse_check = MseCheck {
            scene,
            spp,
            seeds,
            source,
            variances,
        };
        Ok(DenoiseExperiment {
            source: String::new(),
            file,
            quick,
            sources,
            rule,
            scenes,
            mse_check,
            montage_spp,
            repeats,
        })
    }

    /// The seed of repeat `r` (from 0): `seed + r · 2³²`, wrapping. Repeat 0 keeps `seed`.
    pub fn repeat_seed(&self, r: u32) -> u64 {
        self.file
            .seed
            .wrapping_add(u64::from(r).wrapping_mul(REPEAT_SEED_STRIDE))
    }

    /// The estimators every render runs: each source's, in file order.
    pub fn estimators(&self) -> Vec<EstimatorSpec> {
        self.sources.iter().map(|s| s.spec).collect()
    }
}
