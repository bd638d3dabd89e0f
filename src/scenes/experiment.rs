//! The TOML schema of a scene experiment (`experiments/scenes.toml`): which scenes, at which
//! resolution and sample budget, which estimators, and what the tables and figures show.
//! Unknown keys are errors naming the key and line; a bad entry names the file and the entry.
//!
//! ```toml
//! seed = 0
//! estimators = ["mean", "gmon:M=21", "zirr:b=8,kappa=1"]
//! plot_estimators = ["mean", "gmon:M=21"]
//! bias_map_estimators = ["mean", "gmon:M=21"]
//! crop_estimators = ["mean", "gmon:M=21"]
//!
//! [quick]
//! resolution = 0.25
//! spp = 64
//! reference_spp = 512
//!
//! [[scenes]]
//! name = "cbox"
//! file = "scenes/cbox.xml"
//! width = 128
//! height = 128
//! spp = 1024
//! reference_spp = 16384
//! ```

use crate::error::{Error, Result};
use crate::estimators::EstimatorSpec;
use crate::image::metrics::{FireflyRule, SSIM_RADIUS};
use crate::limits::shorten;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The smallest side a scene may be rendered at: SSIM needs a whole 11x11 window.
pub const MIN_SIDE: u32 = 2 * SSIM_RADIUS as u32 + 1;

/// One scene as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneEntry {
    /// Name in tables and file names (a plain file name).
    pub name: String,
    /// Scene file, relative to the experiment file's folder.
    pub file: PathBuf,
    /// Rendered width in pixels (replaces the film's).
    pub width: u32,
    /// Rendered height in pixels.
    pub height: u32,
    /// Samples per pixel of the render; estimates are read at every power of two up to it.
    pub spp: u32,
    /// Samples per pixel of the reference (more are used if the cached one has more).
    pub reference_spp: u64,
    /// `"box"` renders a scene whose film asks for another reconstruction filter with a box
    /// filter, as `fireflies render --rfilter box` does.
    #[serde(default)]
    pub rfilter: Option<String>,
    /// Firefly crop `[x, y, size]`; chosen automatically when absent.
    #[serde(default)]
    pub crop: Option<[u32; 3]>,
}

/// How `--quick` scales the experiment down.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuickEntry {
    /// Factor applied to every width and height (each stays at least [`MIN_SIDE`]).
    pub resolution: f64,
    /// Cap on every render's spp.
    pub spp: u32,
    /// Cap on every reference's spp.
    pub reference_spp: u64,
}

/// How estimator cost is measured (see [`super::cost`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CostEntry {
    /// Pixels traced, on a regular grid over the image.
    #[serde(default = "default_cost_pixels")]
    pub pixels: u32,
    /// Samples per pixel (at most the scene's spp).
    #[serde(default = "default_cost_spp")]
    pub spp: u32,
    /// Timed repetitions of each estimator; the fastest is kept.
    #[serde(default = "default_repeats")]
    pub repeats: u32,
    /// Samples per pixel of a second render with the mean alone (at most the scene's spp; 0:
    /// none), whose CPU time per sample against the full render's measures the whole bank's
    /// cost inside a real render.
    #[serde(default)]
    pub mean_render_spp: u32,
}

impl Default for CostEntry {
    fn default() -> Self {
        CostEntry {
            pixels: default_cost_pixels(),
            spp: default_cost_spp(),
            repeats: default_repeats(),
            mean_render_spp: 0,
        }
    }
}

fn default_cost_pixels() -> u32 {
    256
}
fn default_cost_spp() -> u32 {
    256
}
fn default_repeats() -> u32 {
    3
}
fn default_factor() -> f64 {
    FireflyRule::DEFAULT_FACTOR
}
fn default_floor() -> f64 {
    FireflyRule::DEFAULT_FLOOR
}
fn default_thresholds() -> Vec<f64> {
    vec![0.6, 0.7, 0.8]
}
fn default_delayed_spp() -> u32 {
    100
}
fn default_crop_spp() -> u32 {
    64
}

/// A scene experiment file as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenesFile {
    /// One line on what the experiment shows.
    #[serde(default)]
    pub description: String,
    /// Seed of every render's streams (references use their own fixed seed).
    pub seed: u64,
    /// Estimator spec strings, every one run in the same render.
    pub estimators: Vec<String>,
    /// Sample counts read besides the powers of two (each kept if at most a scene's spp).
    #[serde(default)]
    pub extra_checkpoints: Vec<u32>,
    /// Firefly pixels: luminance above `factor` times the reference's plus `floor`.
    #[serde(default = "default_factor")]
    pub firefly_factor: f64,
    /// See `firefly_factor`.
    #[serde(default = "default_floor")]
    pub firefly_floor: f64,
    /// SSIM levels of Buisine et al.'s Table 2.
    #[serde(default = "default_thresholds")]
    pub ssim_thresholds: Vec<f64>,
    /// Pajot et al.'s Table 4: samples per pixel at which the delayed fraction is read.
    #[serde(default = "default_delayed_spp")]
    pub delayed_spp: u32,
    /// Pajot estimators whose delayed fraction is measured (`pajot-*` specs).
    #[serde(default)]
    pub delayed_estimators: Vec<String>,
    /// Estimators drawn in the convergence and speed figures (at most 10, from `estimators`).
    pub plot_estimators: Vec<String>,
    /// Estimators whose bias maps are drawn (from `estimators`).
    pub bias_map_estimators: Vec<String>,
    /// Estimators whose firefly crops are drawn (from `estimators`).
    pub crop_estimators: Vec<String>,
    /// Samples per pixel of the crops (a power of two or an extra checkpoint).
    #[serde(default = "default_crop_spp")]
    pub crop_spp: u32,
    /// Cost measurement.
    #[serde(default)]
    pub cost: CostEntry,
    /// What `--quick` does.
    pub quick: QuickEntry,
    /// The scenes.
    pub scenes: Vec<SceneEntry>,
}

/// A checked scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Name in tables and file names.
    pub name: String,
    /// Scene file path (resolved against the experiment's folder).
    pub file: PathBuf,
    /// Rendered size.
    pub width: u32,
    /// Rendered size.
    pub height: u32,
    /// Render spp.
    pub spp: u32,
    /// Reference spp wanted.
    pub reference_spp: u64,
    /// Whether the film's filter is replaced by a box.
    pub box_filter: bool,
    /// Firefly crop `[x, y, size]`, if given.
    pub crop: Option<[u32; 3]>,
    /// Sample counts at which every estimator is read, ascending (the last is `spp`).
    pub checkpoints: Vec<u32>,
}

/// A checked scene experiment.
#[derive(Debug, Clone)]
pub struct ScenesExperiment {
    /// The file as given (names it in errors and the manifest).
    pub source: String,
    /// The file as parsed.
    pub file: ScenesFile,
    /// Whether `--quick` scaled it down.
    pub quick: bool,
    /// Parsed estimators, in file order.
    pub estimators: Vec<EstimatorSpec>,
    /// Parsed Pajot estimators of the delayed-fraction table.
    pub delayed_estimators: Vec<EstimatorSpec>,
    /// Indices into `estimators` of the plotted ones.
    pub plot: Vec<usize>,
    /// Indices into `estimators` of the bias maps.
    pub bias_maps: Vec<usize>,
    /// Indices into `estimators` of the crops.
    pub crops: Vec<usize>,
    /// Firefly rule of the metrics.
    pub rule: FireflyRule,
    /// The scenes.
    pub scenes: Vec<Scene>,
}

/// Powers of two up to `spp`, the extras at most `spp`, and `spp`, ascending and distinct.
pub fn checkpoints(spp: u32, extras: &[u32]) -> Vec<u32> {
    let mut c: Vec<u32> = (0..32)
        .map(|k| 1u32 << k)
        .take_while(|&p| p <= spp)
        .collect();
    c.extend(extras.iter().copied().filter(|&e| e >= 1 && e <= spp));
    c.push(spp);
    c.sort_unstable();
    c.dedup();
    c
}

/// A plain file name: no separators, not `.`/`..`, not empty, no surrounding spaces.
pub(crate) fn plain_name(name: &str) -> bool {
    !name.is_empty()
        && name.trim() == name
        && name != "."
        && name != ".."
        && !name.contains(['/', '\\', '\0'])
}

impl ScenesExperiment {
    /// Reads and checks an experiment file; with `quick`, scales it down as its `[quick]`
    /// section says. Scene files are resolved against the experiment file's folder and must
    /// exist.
    ///
    /// # Errors
    ///
    /// [`Error::Io`] if the file cannot be read; [`Error::Experiment`] naming the file and the
    /// entry for anything it rejects.
    pub fn load(path: &Path, quick: bool) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path.display(), &e))?;
        let dir = path.parent().unwrap_or_else(|| Path::new(""));
        Self::from_toml(&text, &path.display().to_string(), dir, quick)
    }

    /// [`ScenesExperiment::load`] from text; `source` names it in errors, `dir` is where
    /// scene paths are resolved.
    ///
    /// # Errors
    ///
    /// [`Error::Experiment`] naming `source` and the entry at fault.
    pub fn from_toml(text: &str, source: &str, dir: &Path, quick: bool) -> Result<Self> {
        let fail = |message: String| Error::Experiment {
            file: source.to_string(),
            message,
        };
        let file: ScenesFile =
            toml::from_str(text).map_err(|e| fail(e.to_string().trim_end().to_string()))?;
        Self::check(file, source, dir, quick).map_err(|e| match e {
            Error::Experiment { .. } => e,
            e => fail(e.to_string()),
        })
    }

    fn check(file: ScenesFile, source: &str, dir: &Path, quick: bool) -> Result<Self> {
        let at = |entry: String, what: &dyn std::fmt::Display| Error::Experiment {
            file: source.to_string(),
            message: format!("{entry}: {what}"),
        };
        if file.estimators.is_empty() {
            return Err(at("estimators".into(), &"give at least one estimator"));
        }
        let mut estimators: Vec<EstimatorSpec> = Vec::new();
        for (i, s) in file.estimators.iter().enumerate() {
            let spec: EstimatorSpec = s
                .parse()
                .map_err(|e| at(format!("estimators[{i}] = \"{}\"", shorten(s)), &e))?;
            spec.build()
                .map_err(|e| at(format!("estimators[{i}] = \"{}\"", shorten(s)), &e))?;
            if estimators.contains(&spec) {
                return Err(at(
                    format!("estimators[{i}] = \"{}\"", shorten(s)),
                    &format!("repeats the estimator {spec}"),
                ));
            }
            estimators.push(spec);
        }
        let pick = |key: &str, list: &[String]| -> Result<Vec<usize>> {
            let mut out = Vec::new();
            for (i, s) in list.iter().enumerate() {
                let entry = format!("{key}[{i}] = \"{}\"", shorten(s));
                let spec: EstimatorSpec = s.parse().map_err(|e| at(entry.clone(), &e))?;
                let k = estimators.iter().position(|e| *e == spec).ok_or_else(|| {
                    at(
                        entry.clone(),
                        &"is not one of `estimators` (compare spec strings)",
                    )
                })?;
                if out.contains(&k) {
                    return Err(at(entry, &"is listed twice"));
                }
                out.push(k);
            }
            Ok(out)
        };
        let plot = pick("plot_estimators", &file.plot_estimators)?;
        if plot.len() > 10 {
            return Err(at(
                "plot_estimators".into(),
                &format!("{} estimators; a figure tells at most 10 apart", plot.len()),
            ));
        }
        let bias_maps = pick("bias_map_estimators", &file.bias_map_estimators)?;
        let crops = pick("crop_estimators", &file.crop_estimators)?;
        let mut delayed_estimators = Vec::new();
        for (i, s) in file.delayed_estimators.iter().enumerate() {
            let entry = format!("delayed_estimators[{i}] = \"{}\"", shorten(s));
            let spec: EstimatorSpec = s.parse().map_err(|e| at(entry.clone(), &e))?;
            if !matches!(
                spec,
                EstimatorSpec::PajotRot(_)
                    | EstimatorSpec::PajotAdr(_)
                    | EstimatorSpec::PajotHybrid(_)
            ) {
                return Err(at(entry, &"only Pajot et al.'s estimators delay samples"));
            }
            spec.build().map_err(|e| at(entry.clone(), &e))?;
            delayed_estimators.push(spec);
        }
        let rule = FireflyRule::new(file.firefly_factor, file.firefly_floor)
            .map_err(|e| at("firefly_factor/firefly_floor".into(), &e))?;
        for (i, &t) in file.ssim_thresholds.iter().enumerate() {
            if !(t > -1.0 && t <= 1.0) {
                return Err(at(
                    format!("ssim_thresholds[{i}] = {t}"),
                    &"must be in (-1, 1]",
                ));
            }
        }
        if file.delayed_spp == 0 {
            return Err(at("delayed_spp = 0".into(), &"must be at least 1"));
        }
        if file.cost.pixels == 0 || file.cost.spp == 0 || file.cost.repeats == 0 {
            return Err(at(
                format!(
                    "cost = {{ pixels = {}, spp = {}, repeats = {} }}",
                    file.cost.pixels, file.cost.spp, file.cost.repeats
                ),
                &"each must be at least 1",
            ));
        }
        let q = &file.quick;
        if !(q.resolution > 0.0 && q.resolution <= 1.0) || q.spp == 0 || q.reference_spp == 0 {
            return Err(at(
                format!(
                    "quick = {{ resolution = {}, spp = {}, reference_spp = {} }}",
                    q.resolution, q.spp, q.reference_spp
                ),
                &"resolution must be in (0, 1], spp and reference_spp at least 1",
            ));
        }
        if file.scenes.is_empty() {
            return Err(at("scenes".into(), &"give at least one [[scenes]] entry"));
        }
        let mut scenes: Vec<Scene> = Vec::new();
        for (i, s) in file.scenes.iter().enumerate() {
            let entry = |key: &str, value: &dyn std::fmt::Display| {
                format!("scenes[{i}] (\"{}\").{key} = {value}", shorten(&s.name))
            };
            if !plain_name(&s.name) {
                return Err(at(
                    format!("scenes[{i}].name = \"{}\"", shorten(&s.name)),
                    &"must be a plain file name (it names the scene's files)",
                ));
            }
            if scenes.iter().any(|o| o.name == s.name) {
                return Err(at(entry("name", &s.name), &"repeats another scene's name"));
            }
            let path = dir.join(&s.file);
            if !path.is_file() {
                return Err(at(
                    entry("file", &s.file.display()),
                    &format!("{} is not a file", path.display()),
                ));
            }
            for (key, v) in [("width", s.width), ("height", s.height)] {
                if v < MIN_SIDE {
                    return Err(at(
                        entry(key, &v),
                        &format!("must be at least {MIN_SIDE} (SSIM's window)"),
                    ));
                }
            }
            if s.spp == 0 {
                return Err(at(entry("spp", &0), &"must be at least 1"));
            }
            if s.reference_spp < 2 {
                return Err(at(
                    entry("reference_spp", &s.reference_spp),
                    &"must be at least 2 (a reference's error needs two samples)",
                ));
            }
            let box_filter = match s.rfilter.as_deref() {
                None => false,
                Some("box") => true,
                Some(other) => {
                    return Err(at(
                        entry("rfilter", &format!("\"{}\"", shorten(other))),
                        &"the only override is \"box\"",
                    ));
                }
            };
            if let Some([x, y, size]) = s.crop {
                if size < 4 || x.saturating_add(size) > s.width || y.saturating_add(size) > s.height
                {
                    return Err(at(
                        entry("crop", &format!("[{x}, {y}, {size}]")),
                        &format!(
                            "must be [x, y, size] with size >= 4 inside the {}x{} image",
                            s.width, s.height
                        ),
                    ));
                }
            }
            scenes.push(Scene {
                name: s.name.clone(),
                file: path,
                width: s.width,
                height: s.height,
                spp: s.spp,
                reference_spp: s.reference_spp,
                box_filter,
                crop: s.crop,
                checkpoints: Vec::new(),
            });
        }
        if quick {
            for s in &mut scenes {
                let scale = |v: u32| ((f64::from(v) * q.resolution).round() as u32).max(MIN_SIDE);
                let (w, h) = (scale(s.width), scale(s.height));
                s.crop = s.crop.and_then(|[x, y, size]| {
                    let f = |v: u32| (f64::from(v) * q.resolution).round() as u32;
                    let size = f(size).max(4);
                    let (x, y) = (f(x), f(y));
                    (x + size <= w && y + size <= h).then_some([x, y, size])
                });
                s.width = w;
                s.height = h;
                s.spp = s.spp.min(q.spp);
                s.reference_spp = s.reference_spp.min(q.reference_spp).max(2);
            }
        }
        for s in &mut scenes {
            s.checkpoints = checkpoints(s.spp, &file.extra_checkpoints);
            let crop_spp = file.crop_spp.min(s.spp);
            if !s.checkpoints.contains(&crop_spp) {
                return Err(at(
                    format!("crop_spp = {}", file.crop_spp),
                    &format!(
                        "is not a checkpoint of scene \"{}\" ({:?}): use a power of two or an \
                         extra checkpoint",
                        s.name, s.checkpoints
                    ),
                ));
            }
        }
        Ok(ScenesExperiment {
            source: source.to_string(),
            file,
            quick,
            estimators,
            delayed_estimators,
            plot,
            bias_maps,
            crops,
            rule,
            scenes,
        })
    }

    /// The crops' spp for a scene (the file's `crop_spp`, at most the scene's spp).
    pub fn crop_spp(&self, scene: &Scene) -> u32 {
        self.file.crop_spp.min(scene.spp)
    }
}

#[cfg(test)]
mod tests {
    use super::checkpoints;

    #[test]
    fn checkpoints_are_powers_of_two_extras_and_the_budget() {
        assert_eq!(checkpoints(16, &[100, 3]), vec![1, 2, 3, 4, 8, 16]);
        assert_eq!(
            checkpoints(128, &[100]),
            vec![1, 2, 4, 8, 16, 32, 64, 100, 128]
        );
        assert_eq!(checkpoints(24, &[]), vec![1, 2, 4, 8, 16, 24]);
        assert_eq!(checkpoints(1, &[0]), vec![1]);
    }
}
