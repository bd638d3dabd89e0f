//! Do synthetic results transfer to scenes? For one real pixel: fit a generator to its
//! luminance stream, run the synthetic harness on the fitted generator, and set every
//! estimator's *predicted* error beside its error *measured* over many independent renders of
//! that pixel, against the pixel's own converged value (issue 14, item 5).
//!
//! Every stream of a pixel is a render with its own seed, exactly as `fireflies render --seed S`
//! would trace it (camera sample `i` of pixel `p` draws from `SampleStream::new(S, p, i)`;
//! invalid samples are dropped, as the film drops them):
//!
//! - render `r` (of `renders`) uses seed `seed + r`; estimates are read at each checkpoint `n`
//!   from the valid samples among its first `n` camera samples;
//! - the fit stream (`fit_spp` samples) uses seed [`fit_seed`]`(seed)`;
//! - the truth (`truth_spp` samples, its relative standard error reported) uses
//!   [`truth_seed`]`(seed)`.
//!
//! The measured side feeds the same scalar estimators the harness builds, and accumulates them in
//! the harness's own [`CellAccumulator`], so both sides compute relative RMSE and relative bias,
//! and their 95% intervals, with one piece of code; the predicted side is a harness row
//! ([`crate::report::tables::rows`]) of an in-memory experiment on the fitted law, whose truth
//! is the fitted mean. Renders run in parallel and are accumulated in render order, so nothing
//! depends on the thread count.
//!
//! The prediction error of a cell is `predicted / measured relative RMSE - 1`.

use super::experiment::plain_name;
use crate::dist::fit::fit;
use crate::dist::{Dist, DistSpec};
use crate::error::{Error, Result};
use crate::estimators::{Estimator, EstimatorSpec, Mean, luminance};
use crate::harness::experiment::{DistributionEntry, ExperimentFile};
use crate::harness::law;
use crate::harness::metrics::{CellAccumulator, Interval, Metric, Moments, Observation};
use crate::harness::{Experiment, RunOptions, run};
use crate::limits::{MemoryLimit, shorten};
use crate::render::integrator::{pushable, radiance};
use crate::render::mitsuba;
use crate::render::sampler::SampleStream;
use crate::render::world::World;
use crate::report::tables::rows;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Camera samples per parallel task of the truth: a fixed split, so the truth's sum is merged
/// in the same order on any number of threads.
const TRUTH_CHUNK: u64 = 1 << 16;

/// The fewest samples a fit is made from: the tail rule needs some hundreds to choose a
/// threshold at all.
pub const MIN_FIT_SPP: u64 = 256;

/// The `[quick]` section: the counts `--quick` uses instead of the file's.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuickEntry {
    /// Independent renders per pixel.
    pub renders: u64,
    /// Samples of the fit stream.
    pub fit_spp: u64,
    /// Samples of the truth.
    pub truth_spp: u64,
    /// Harness trials of the prediction.
    pub trials: u64,
    /// Sample counts at which every estimate is read.
    pub checkpoints: Vec<usize>,
}

/// One pixel as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PixelEntry {
    /// Scene file, relative to the experiment file's folder.
    pub scene: PathBuf,
    /// Column.
    pub x: u32,
    /// Row.
    pub y: u32,
    /// The kind of pixel (`plain`, `glossy`, `caustic`, `firefly`, ...): summaries group by it.
    pub class: String,
    /// Name in tables (a plain file name); default `<scene stem>_<x>_<y>`.
    #[serde(default)]
    pub label: Option<String>,
    /// Rendered width (replaces the film's; give `height` too).
    #[serde(default)]
    pub width: Option<u32>,
    /// Rendered height (replaces the film's; give `width` too).
    #[serde(default)]
    pub height: Option<u32>,
    /// `"box"` renders a scene whose film asks for another filter with a box filter.
    #[serde(default)]
    pub rfilter: Option<String>,
}

/// A transfer experiment file as written (`experiments/transfer.toml`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransferFile {
    /// One line on what the experiment shows.
    #[serde(default)]
    pub description: String,
    /// Seed of every render, of the fit and truth streams, and of the harness trials.
    pub seed: u64,
    /// Independent renders per pixel (the measured side's trials).
    pub renders: u64,
    /// Samples of the stream the generator is fitted to.
    pub fit_spp: u64,
    /// Samples of the pixel's converged value.
    pub truth_spp: u64,
    /// Harness trials of the prediction.
    pub trials: u64,
    /// Sample counts at which every estimate is read, ascending.
    pub checkpoints: Vec<usize>,
    /// Firefly threshold of the harness cells (`(1 + tau) mu`).
    #[serde(default = "default_tau")]
    pub tau: f64,
    /// Estimator spec strings (scalar, as the harness runs them).
    pub estimators: Vec<String>,
    /// What `--quick` uses instead.
    pub quick: QuickEntry,
    /// The pixels.
    pub pixels: Vec<PixelEntry>,
}

fn default_tau() -> f64 {
    1.0
}

/// A checked pixel.
#[derive(Debug, Clone)]
pub struct PixelSpec {
    /// Name in tables.
    pub label: String,
    /// Its class.
    pub class: String,
    /// Scene file (resolved against the experiment's folder).
    pub scene: PathBuf,
    /// The scene path as written (for tables).
    pub scene_text: String,
    /// Column.
    pub x: u32,
    /// Row.
    pub y: u32,
    /// Rendered size, if it replaces the film's.
    pub size: Option<(u32, u32)>,
    /// Whether the film's filter is replaced by a box.
    pub box_filter: bool,
}

/// The counts and estimators of one run (the file's, or its `[quick]` ones).
#[derive(Debug, Clone)]
pub struct Settings {
    /// Seed.
    pub seed: u64,
    /// Independent renders per pixel.
    pub renders: u64,
    /// Fit stream length.
    pub fit_spp: u64,
    /// Truth stream length.
    pub truth_spp: u64,
    /// Harness trials.
    pub trials: u64,
    /// Checkpoints, ascending.
    pub checkpoints: Vec<usize>,
    /// Firefly threshold factor.
    pub tau: f64,
    /// Estimator specs, in file order.
    pub estimators: Vec<EstimatorSpec>,
    /// Their spec strings as written (the harness experiment is built from them).
    pub estimator_texts: Vec<String>,
}

/// A checked transfer experiment.
#[derive(Debug, Clone)]
pub struct TransferExperiment {
    /// The file as given.
    pub source: String,
    /// The file as parsed.
    pub file: TransferFile,
    /// Whether `--quick` is in force.
    pub quick: bool,
    /// What this run uses.
    pub settings: Settings,
    /// The pixels.
    pub pixels: Vec<PixelSpec>,
}

impl TransferExperiment {
    /// Reads and checks a transfer experiment; scene paths are resolved against its folder.
    ///
    /// # Errors
    ///
    /// [`Error::Io`] if the file cannot be read; [`Error::Experiment`] naming the file, the
    /// entry and the parameter for anything it rejects (unknown keys included).
    pub fn load(path: &Path, quick: bool) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path.display(), &e))?;
        let dir = path.parent().unwrap_or_else(|| Path::new(""));
        Self::from_toml(&text, &path.display().to_string(), dir, quick)
    }

    /// [`TransferExperiment::load`] from text; `source` names it in errors.
    ///
    /// # Errors
    ///
    /// [`Error::Experiment`] naming `source` and the entry at fault.
    pub fn from_toml(text: &str, source: &str, dir: &Path, quick: bool) -> Result<Self> {
        let fail = |message: String| Error::Experiment {
            file: source.to_string(),
            message,
        };
        let file: TransferFile =
            toml::from_str(text).map_err(|e| fail(e.to_string().trim_end().to_string()))?;
        Self::check(file, source, dir, quick).map_err(|e| match e {
            Error::Experiment { .. } => e,
            e => fail(e.to_string()),
        })
    }

    fn check(file: TransferFile, source: &str, dir: &Path, quick: bool) -> Result<Self> {
        let at = |entry: String, what: &dyn std::fmt::Display| Error::Experiment {
            file: source.to_string(),
            message: format!("{entry}: {what}"),
        };
        let counts = |prefix: &str,
                      renders: u64,
                      fit_spp: u64,
                      truth_spp: u64,
                      trials: u64,
                      checkpoints: &[usize]|
         -> Result<()> {
            if renders < 4 {
                return Err(at(
                    format!("{prefix}renders = {renders}"),
                    &"must be at least 4 (an interval needs 4 renders, docs/estimators.md §7)",
                ));
            }
            if fit_spp < MIN_FIT_SPP {
                return Err(at(
                    format!("{prefix}fit_spp = {fit_spp}"),
                    &format!("must be at least {MIN_FIT_SPP}"),
                ));
            }
            if truth_spp < 2 {
                return Err(at(
                    format!("{prefix}truth_spp = {truth_spp}"),
                    &"must be at least 2 (its standard error needs two samples)",
                ));
            }
            if trials < 4 {
                return Err(at(
                    format!("{prefix}trials = {trials}"),
                    &"must be at least 4 (docs/estimators.md §7)",
                ));
            }
            if checkpoints.is_empty()
                || checkpoints[0] == 0
                || checkpoints.windows(2).any(|w| w[0] >= w[1])
            {
                return Err(at(
                    format!("{prefix}checkpoints = {checkpoints:?}"),
                    &"must be positive and strictly ascending",
                ));
            }
            Ok(())
        };
        counts(
            "",
            file.renders,
            file.fit_spp,
            file.truth_spp,
            file.trials,
            &file.checkpoints,
        )?;
        let q = &file.quick;
        counts(
            "quick.",
            q.renders,
            q.fit_spp,
            q.truth_spp,
            q.trials,
            &q.checkpoints,
        )?;
        if !(file.tau > 0.0 && file.tau.is_finite()) {
            return Err(at(format!("tau = {}", file.tau), &"must be finite and > 0"));
        }
        if file.estimators.is_empty() {
            return Err(at("estimators".into(), &"give at least one estimator"));
        }
        let mut estimators: Vec<EstimatorSpec> = Vec::new();
        for (i, s) in file.estimators.iter().enumerate() {
            let entry = || format!("estimators[{i}] = \"{}\"", shorten(s));
            let spec: EstimatorSpec = s.parse().map_err(|e| at(entry(), &e))?;
            spec.build().map_err(|e| at(entry(), &e))?;
            if estimators.contains(&spec) {
                return Err(at(entry(), &format!("repeats the estimator {spec}")));
            }
            estimators.push(spec);
        }
        if file.pixels.is_empty() {
            return Err(at("pixels".into(), &"give at least one [[pixels]] entry"));
        }
        let mut pixels: Vec<PixelSpec> = Vec::new();
        for (i, p) in file.pixels.iter().enumerate() {
            let label = p.label.clone().unwrap_or_else(|| {
                let stem = p
                    .scene
                    .file_stem()
                    .map_or("pixel".into(), |s| s.to_string_lossy().into_owned());
                format!("{stem}_{}_{}", p.x, p.y)
            });
            let entry = |key: &str, value: &dyn std::fmt::Display| {
                format!("pixels[{i}] (\"{}\").{key} = {value}", shorten(&label))
            };
            if !plain_name(&label) {
                return Err(at(
                    entry("label", &format!("\"{}\"", shorten(&label))),
                    &"must be a plain file name",
                ));
            }
            if pixels.iter().any(|o| o.label == label) {
                return Err(at(
                    entry("label", &format!("\"{}\"", shorten(&label))),
                    &"repeats another pixel's label",
                ));
            }
            if p.class.trim().is_empty() {
                return Err(at(entry("class", &"\"\""), &"name the kind of pixel"));
            }
            let path = dir.join(&p.scene);
            if !path.is_file() {
                return Err(at(
                    entry("scene", &p.scene.display()),
                    &format!("{} is not a file", path.display()),
                ));
            }
            let size = match (p.width, p.height) {
                (None, None) => None,
                (Some(w), Some(h)) if w > 0 && h > 0 => Some((w, h)),
                (w, h) => {
                    return Err(at(
                        entry("width/height", &format!("{w:?}/{h:?}")),
                        &"give both, each at least 1, or neither",
                    ));
                }
            };
            if let Some((w, h)) = size
                && (p.x >= w || p.y >= h)
            {
                return Err(at(
                    entry("x/y", &format!("{}/{}", p.x, p.y)),
                    &format!("outside the {w}x{h} image"),
                ));
            }
            let box_filter = match p.rfilter.as_deref() {
                None => false,
                Some("box") => true,
                Some(other) => {
                    return Err(at(
                        entry("rfilter", &format!("\"{}\"", shorten(other))),
                        &"the only override is \"box\"",
                    ));
                }
            };
            pixels.push(PixelSpec {
                label,
                class: p.class.clone(),
                scene: path,
                scene_text: p.scene.display().to_string(),
                x: p.x,
                y: p.y,
                size,
                box_filter,
            });
        }
        let (renders, fit_spp, truth_spp, trials, checkpoints) = if quick {
            (
                q.renders,
                q.fit_spp,
                q.truth_spp,
                q.trials,
                q.checkpoints.clone(),
            )
        } else {
            (
                file.renders,
                file.fit_spp,
                file.truth_spp,
                file.trials,
                file.checkpoints.clone(),
            )
        };
        let settings = Settings {
            seed: file.seed,
            renders,
            fit_spp,
            truth_spp,
            trials,
            checkpoints,
            tau: file.tau,
            estimators,
            estimator_texts: file.estimators.clone(),
        };
        Ok(TransferExperiment {
            source: source.to_string(),
            file,
            quick,
            settings,
            pixels,
        })
    }
}

impl TransferExperiment {
    /// The same experiment with the fit stream `fit_spp` long (`fireflies transfer
    /// --fit-spp`): how many samples the fit needs is a question of its own.
    ///
    /// # Errors
    ///
    /// [`Error::InvalidParameter`] naming `fit-spp` below [`MIN_FIT_SPP`].
    pub fn with_fit_spp(mut self, fit_spp: u64) -> Result<Self> {
        if fit_spp < MIN_FIT_SPP {
            return Err(Error::param(
                "fit-spp",
                fit_spp,
                format!("must be at least {MIN_FIT_SPP}"),
            ));
        }
        self.settings.fit_spp = fit_spp;
        Ok(self)
    }
}

/// Where one pixel's samples come from: camera sample `index` of a render with `seed`, as
/// luminance, `None` when the sample is invalid (NaN, infinite or negative) and the film would
/// drop it.
pub trait PixelSource: Sync {
    /// One sample.
    fn sample(&self, seed: u64, index: u64) -> Option<f64>;
}

/// A pixel of a scene, traced by the crate's path tracer.
pub struct ScenePixel {
    world: World,
    x: u32,
    y: u32,
    index: u64,
}

impl ScenePixel {
    /// Loads the pixel's scene (at its size and filter) and checks the pixel lies in the image.
    ///
    /// # Errors
    ///
    /// Whatever loading the scene fails with; [`Error::InvalidParameter`] naming `x/y` when
    /// the pixel lies outside the image.
    pub fn load(p: &PixelSpec) -> Result<Self> {
        let mut desc = mitsuba::load_file_with(
            &p.scene,
            mitsuba::LoadOptions {
                box_filter: p.box_filter,
            },
        )?;
        if let Some((w, h)) = p.size {
            desc.camera.width = w;
            desc.camera.height = h;
        }
        let world = World::new(&desc);
        let (w, h) = (world.camera.width(), world.camera.height());
        if p.x >= w || p.y >= h {
            return Err(Error::param(
                "x/y",
                format!("{}/{} of pixel {}", p.x, p.y, p.label),
                format!("outside the {w}x{h} image of {}", p.scene.display()),
            ));
        }
        Ok(ScenePixel {
            world,
            x: p.x,
            y: p.y,
            index: u64::from(p.y) * u64::from(w) + u64::from(p.x),
        })
    }
}

impl PixelSource for ScenePixel {
    fn sample(&self, seed: u64, index: u64) -> Option<f64> {
        let mut rng = SampleStream::new(seed, self.index, index);
        pushable(radiance(&self.world, self.x, self.y, &mut rng)).map(luminance)
    }
}

/// A synthetic "pixel": independent draws of a known law, sample `index` of stream `seed` from
/// its own generator. Tests use it to check the loop where the answer is known.
pub struct DistPixel(pub Dist);

impl PixelSource for DistPixel {
    fn sample(&self, seed: u64, index: u64) -> Option<f64> {
        let key = mix(mix(seed) ^ index);
        Some(self.0.sample(&mut Xoshiro256PlusPlus::seed_from_u64(key)))
    }
}

/// SplitMix64's finaliser.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Seed of render `r`.
pub fn render_seed(seed: u64, r: u64) -> u64 {
    seed.wrapping_add(r)
}

/// Seed of the fit stream: apart from every render's (`seed + r`) but by a 2^-64 chance.
pub fn fit_seed(seed: u64) -> u64 {
    mix(seed ^ 0x6669_745f_7374_7265)
}

/// Seed of the truth stream.
pub fn truth_seed(seed: u64) -> u64 {
    mix(seed ^ 0x7472_7574_685f_7374)
}

/// A pixel's converged value: the mean of `samples` valid samples of one long render.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Truth {
    /// Seed of its render.
    pub seed: u64,
    /// Camera samples traced.
    pub spp: u64,
    /// Valid samples averaged.
    pub samples: u64,
    /// Their mean.
    pub mean: f64,
    /// Its standard error.
    pub se: f64,
}

impl Truth {
    /// Standard error over the mean.
    pub fn relative_se(&self) -> f64 {
        self.se / self.mean
    }
}

/// The truth: `spp` camera samples in fixed chunks, merged in chunk order.
fn truth(source: &dyn PixelSource, seed: u64, spp: u64) -> Truth {
    let chunks = spp.div_ceil(TRUTH_CHUNK);
    let parts: Vec<Moments> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut m = Moments::default();
            for i in c * TRUTH_CHUNK..((c + 1) * TRUTH_CHUNK).min(spp) {
                if let Some(v) = source.sample(seed, i) {
                    m.push(v);
                }
            }
            m
        })
        .collect();
    let mut total = Moments::default();
    for p in &parts {
        total.merge(p);
    }
    Truth {
        seed,
        spp,
        samples: total.count(),
        mean: total.mean(),
        se: total.standard_error(),
    }
}

/// What the fit made of the fit stream.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitInfo {
    /// Seed of the fit stream.
    pub seed: u64,
    /// Valid samples fitted.
    pub samples: u64,
    /// The fitted law as an experiment file spells it.
    pub spec: DistSpec,
    /// The fitted mean (the fit stream's mean).
    pub mean: f64,
    /// The fit stream's own standard error of its mean.
    pub se: f64,
    /// Components of the fitted mixture.
    pub components: usize,
    /// Hill's tail index, when a Pareto tail was kept.
    pub tail_shape: Option<f64>,
}

/// One estimator at one sample count on one pixel: measured and predicted.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Cell {
    /// Estimator spec (its `Display` form, as the harness rows name it).
    pub estimator: String,
    /// Camera samples.
    pub n: usize,
    /// Relative RMSE over the renders against the truth.
    pub measured_rmse: Interval,
    /// Whether the measured RMSE's spread rests on a handful of renders (no interval then).
    pub measured_rmse_caveat: Option<String>,
    /// Relative bias over the renders.
    pub measured_bias: Interval,
    /// The harness's relative RMSE on the fitted law.
    pub predicted_rmse: Interval,
    /// The harness row's caveat.
    pub predicted_rmse_caveat: Option<String>,
    /// The harness's relative bias on the fitted law.
    pub predicted_bias: Interval,
}

impl Cell {
    /// `predicted / measured relative RMSE - 1` (NaN when the measured one is 0).
    pub fn prediction_error(&self) -> f64 {
        self.predicted_rmse.value / self.measured_rmse.value - 1.0
    }

    /// Standard error of [`Cell::prediction_error`] by the delta method, from both sides'
    /// standard errors (independent runs); `None` when either side has none.
    pub fn prediction_error_se(&self) -> Option<f64> {
        let (p, m) = (self.predicted_rmse.value, self.measured_rmse.value);
        let (sp, sm) = (self.predicted_rmse.se?, self.measured_rmse.se?);
        let r = p / m;
        Some(r * ((sp / p).powi(2) + (sm / m).powi(2)).sqrt())
    }

    /// `|predicted - measured relative bias|`.
    pub fn bias_difference(&self) -> f64 {
        (self.predicted_bias.value - self.measured_bias.value).abs()
    }
}

/// Everything one pixel produced.
#[derive(Debug, Clone)]
pub struct PixelResult {
    /// Label.
    pub label: String,
    /// Class.
    pub class: String,
    /// The converged value.
    pub truth: Truth,
    /// The fit.
    pub fit: FitInfo,
    /// Renders and the camera samples each traced.
    pub renders: u64,
    /// Camera samples per render.
    pub render_spp: usize,
    /// Invalid samples dropped (fit, truth and renders together).
    pub invalid_samples: u64,
    /// Harness trials.
    pub trials: u64,
    /// Cells, estimator-major, checkpoints ascending.
    pub cells: Vec<Cell>,
    /// Wall seconds: truth, fit (trace and fit), renders, harness.
    pub wall_s: [f64; 4],
}

impl PixelResult {
    /// `(fitted mean - truth) / truth`.
    pub fn fit_error(&self) -> f64 {
        (self.fit.mean - self.truth.mean) / self.truth.mean
    }

    /// Standard error of [`PixelResult::fit_error`]: the spread of a mean of the fit stream's
    /// length, taken from the truth's far longer stream (the fit stream's own spread misses
    /// what it did not see: a stream without the pixel's rare spike looks tame), and the
    /// truth's own standard error.
    pub fn fit_error_se(&self) -> f64 {
        let sd = self.truth.se * (self.truth.samples as f64).sqrt();
        let fit = sd / (self.fit.samples.max(1) as f64).sqrt();
        (fit * fit + self.truth.se * self.truth.se).sqrt() / self.truth.mean
    }
}

/// One render's estimates at every checkpoint: per estimator, then the plain mean's (for the
/// paired columns of the cells), then whether a sample reached `n * truth`.
struct RenderEstimates {
    estimates: Vec<f64>,
    means: Vec<f64>,
    outliers: Vec<bool>,
    invalid: u64,
}

/// Render `r`: its first `max n` camera samples, every estimator read at every checkpoint.
fn one_render(
    source: &dyn PixelSource,
    s: &Settings,
    seed: u64,
    mu: f64,
    estimators: &mut [Box<dyn Estimator>],
    samples: &mut Vec<f64>,
) -> Result<RenderEstimates> {
    let cps = &s.checkpoints;
    let max_n = *cps.last().expect("checked non-empty");
    samples.clear();
    let mut valid_at = Vec::with_capacity(cps.len());
    let mut next = 0;
    for i in 0..max_n {
        if let Some(v) = source.sample(seed, i as u64) {
            samples.push(v);
        }
        if i + 1 == cps[next] {
            valid_at.push(samples.len());
            next += 1;
        }
    }
    let read = |e: &mut dyn Estimator, out: &mut Vec<f64>| -> Result<()> {
        e.reset();
        let mut from = 0;
        for (&to, &n) in valid_at.iter().zip(cps) {
            e.push_slice(&samples[from..to]);
            from = to;
            // A render whose first n samples were all invalid shows 0, as the film does.
            let x = if to == 0 { 0.0 } else { e.estimate()? };
            if !x.is_finite() {
                return Err(Error::param(
                    "estimate",
                    x,
                    format!("{e} gave a non-finite estimate at n = {n}, render seed {seed}"),
                ));
            }
            out.push(x);
        }
        Ok(())
    };
    let mut estimates = Vec::with_capacity(estimators.len() * cps.len());
    for e in estimators.iter_mut() {
        read(e.as_mut(), &mut estimates)?;
    }
    let mut means = Vec::with_capacity(cps.len());
    read(&mut Mean::new(), &mut means)?;
    let mut max = 0.0f64;
    let mut from = 0;
    let outliers = valid_at
        .iter()
        .zip(cps)
        .map(|(&to, &n)| {
            max = samples[from..to].iter().fold(max, |m, &x| m.max(x));
            from = to;
            max >= n as f64 * mu
        })
        .collect();
    Ok(RenderEstimates {
        estimates,
        means,
        outliers,
        invalid: (max_n - samples.len()) as u64,
    })
}

/// The measured side: every render's estimates, accumulated in render order against `mu`.
fn measure(source: &dyn PixelSource, s: &Settings, mu: f64) -> Result<(Vec<CellAccumulator>, u64)> {
    let per_render: Vec<RenderEstimates> = (0..s.renders)
        .into_par_iter()
        .map_init(
            || {
                let built: Result<Vec<Box<dyn Estimator>>> =
                    s.estimators.iter().map(EstimatorSpec::build).collect();
                (built, Vec::new())
            },
            |(built, samples), r| {
                let estimators = built.as_mut().map_err(|e| e.clone())?;
                one_render(source, s, render_seed(s.seed, r), mu, estimators, samples)
            },
        )
        .collect::<Result<_>>()?;
    let cps = s.checkpoints.len();
    let mut cells = vec![CellAccumulator::default(); s.estimators.len() * cps];
    let mut invalid = 0;
    for r in &per_render {
        invalid += r.invalid;
        for (k, cell) in cells.iter_mut().enumerate() {
            let i = k % cps;
            let o = Observation {
                estimate: r.estimates[k],
                mean_estimate: r.means[i],
                outlier: r.outliers[i],
            };
            cell.push(o, mu, s.tau);
        }
    }
    Ok((cells, invalid))
}

/// The harness experiment on the fitted law: the same estimators, checkpoints, trials and seed.
pub fn prediction_experiment(s: &Settings, label: &str, spec: &DistSpec) -> Result<Experiment> {
    let file = ExperimentFile {
        name: Some(label.to_string()),
        description: format!("the generator fitted to pixel {label}"),
        seed: s.seed,
        trials: s.trials,
        checkpoints: s.checkpoints.clone(),
        tau: s.tau,
        estimators: s.estimator_texts.clone(),
        distributions: vec![DistributionEntry {
            label: Some(label.to_string()),
            dist: spec.clone(),
        }],
        checks: Default::default(),
        gate: Default::default(),
    };
    let text = toml::to_string(&file)
        .map_err(|e| Error::param("fitted law", label, format!("cannot be written: {e}")))?;
    Experiment::from_toml(&text, &format!("(the fitted law of pixel {label})"), label)
}

/// Relative bias of a cell's metrics: the bias interval over `mu`.
fn relative(iv: Interval, mu: f64) -> Interval {
    iv.map(|v| v / mu, iv.se.map(|s| s / mu))
}

/// One pixel through the whole loop: truth, fit, renders, harness, comparison.
///
/// # Errors
///
/// [`Error::InvalidParameter`] when the truth or the fit stream is black (mean 0: relative
/// errors are undefined) or an estimator gives a non-finite estimate; whatever the harness
/// refuses (the memory limit).
pub fn transfer_pixel(
    source: &dyn PixelSource,
    label: &str,
    class: &str,
    s: &Settings,
    threads: Option<usize>,
    memory: MemoryLimit,
) -> Result<PixelResult> {
    let t0 = Instant::now();
    let truth = truth(source, truth_seed(s.seed), s.truth_spp);
    if !(truth.mean > 0.0) {
        return Err(Error::param(
            "truth",
            truth.mean,
            format!(
                "pixel {label} is black over {} samples: relative errors are undefined",
                truth.spp
            ),
        ));
    }
    let t1 = Instant::now();
    let seed = fit_seed(s.seed);
    let stream: Vec<f64> = (0..s.fit_spp)
        .into_par_iter()
        .filter_map(|i| source.sample(seed, i))
        .collect();
    let fit_invalid = s.fit_spp - stream.len() as u64;
    let mut moments = Moments::default();
    stream.iter().for_each(|&v| moments.push(v));
    let fitted = fit(&stream)?;
    if !(fitted.mean() > 0.0) {
        return Err(Error::param(
            "fit_spp",
            s.fit_spp,
            format!("the fit stream of pixel {label} is black: no law to run the harness on"),
        ));
    }
    let fit_info = FitInfo {
        seed,
        samples: stream.len() as u64,
        spec: fitted.spec(),
        mean: fitted.mean(),
        se: moments.standard_error(),
        components: fitted.components.len(),
        tail_shape: fitted.tail.and_then(|t| t.fitted).map(|t| t.shape),
    };
    drop(stream);
    let t2 = Instant::now();
    let (measured, render_invalid) = measure(source, s, truth.mean)?;
    let t3 = Instant::now();
    let exp = prediction_experiment(s, label, &fit_info.spec)?;
    let out = run(
        &exp,
        &RunOptions {
            threads,
            memory,
            ..RunOptions::default()
        },
    )?;
    let predicted = rows(&exp, &out);
    let t4 = Instant::now();

    let mut cells = Vec::new();
    let cps = &s.checkpoints;
    for (e, spec) in s.estimators.iter().enumerate() {
        let name = spec.to_string();
        for (i, &n) in cps.iter().enumerate() {
            let acc = &measured[e * cps.len() + i];
            let m = acc.metrics(truth.mean).ok_or_else(|| {
                Error::param("renders", s.renders, "too few renders for an interval")
            })?;
            // A real pixel has no known law: only the run's own tail-dominance applies.
            let caveat = |metric| law::caveat(metric, &m, None, None, truth.mean, false, false);
            let rmse_caveat = caveat(Metric::RelativeRmse);
            let bias_caveat = caveat(Metric::RelativeBias);
            let strip = |iv: Interval, caveat: bool| {
                if caveat {
                    // As the harness rows do: no interval and no standard error.
                    Interval {
                        low: None,
                        high: None,
                        se: None,
                        ..iv
                    }
                } else {
                    iv
                }
            };
            let find = |metric: Metric| {
                predicted
                    .iter()
                    .find(|r| r.estimator == name && r.n == n && r.metric == metric)
                    .ok_or_else(|| {
                        Error::param(
                            "estimator",
                            name.as_str(),
                            format!("the harness wrote no {metric} row at n = {n}"),
                        )
                    })
            };
            let (pr, pb) = (find(Metric::RelativeRmse)?, find(Metric::RelativeBias)?);
            let interval = |r: &crate::report::tables::Row| Interval {
                value: r.value,
                low: r.ci_low,
                high: r.ci_high,
                se: r.se,
            };
            cells.push(Cell {
                estimator: name.clone(),
                n,
                measured_rmse: strip(m.relative_rmse, rmse_caveat.is_some()),
                measured_rmse_caveat: rmse_caveat.map(|c| c.label().to_string()),
                measured_bias: strip(relative(m.bias, truth.mean), bias_caveat.is_some()),
                predicted_rmse: interval(pr),
                predicted_rmse_caveat: pr.caveat.map(|c| c.label().to_string()),
                predicted_bias: interval(pb),
            });
        }
    }
    Ok(PixelResult {
        label: label.to_string(),
        class: class.to_string(),
        truth,
        fit: fit_info,
        renders: s.renders,
        render_spp: *cps.last().expect("checked non-empty"),
        invalid_samples: fit_invalid + render_invalid + (truth.spp - truth.samples),
        trials: out.trials,
        cells,
        wall_s: [
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            (t3 - t2).as_secs_f64(),
            (t4 - t3).as_secs_f64(),
        ],
    })
}

/// Ranks with ties sharing their average rank (1-based).
fn ranks(v: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..v.len()).collect();
    order.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    let mut r = vec![0.0; v.len()];
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && v[order[j + 1]] == v[order[i]] {
            j += 1;
        }
        let avg = (i + j) as f64 / 2.0 + 1.0;
        for &k in &order[i..=j] {
            r[k] = avg;
        }
        i = j + 1;
    }
    r
}

/// Spearman's rank correlation (Pearson's on average ranks); NaN with fewer than 2 values or
/// when either side is constant.
pub fn spearman(a: &[f64], b: &[f64]) -> f64 {
    let (ra, rb) = (ranks(a), ranks(b));
    let n = ra.len() as f64;
    if ra.len() < 2 || ra.len() != rb.len() {
        return f64::NAN;
    }
    let (ma, mb) = (ra.iter().sum::<f64>() / n, rb.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in ra.iter().zip(&rb) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

/// Pairs the two orders put the other way round (ties on either side are not swaps).
pub fn rank_swaps(a: &[f64], b: &[f64]) -> usize {
    let mut swaps = 0;
    for i in 0..a.len() {
        for j in i + 1..a.len() {
            if (a[i] - a[j]) * (b[i] - b[j]) < 0.0 {
                swaps += 1;
            }
        }
    }
    swaps
}

/// How the estimators' order by relative RMSE at one n agrees between the two sides.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Ranking {
    /// Camera samples.
    pub n: usize,
    /// Spearman's rho between predicted and measured relative RMSE.
    pub spearman: f64,
    /// Pairs of estimators ordered the other way round.
    pub swaps: usize,
    /// Pairs compared.
    pub pairs: usize,
    /// Whether both sides pick the same best estimator.
    pub same_best: bool,
}

/// The ranking agreement of one pixel at each checkpoint.
pub fn rankings(p: &PixelResult) -> Vec<Ranking> {
    let mut ns: Vec<usize> = p.cells.iter().map(|c| c.n).collect();
    ns.sort_unstable();
    ns.dedup();
    ns.into_iter()
        .map(|n| {
            let at: Vec<&Cell> = p.cells.iter().filter(|c| c.n == n).collect();
            let pred: Vec<f64> = at.iter().map(|c| c.predicted_rmse.value).collect();
            let meas: Vec<f64> = at.iter().map(|c| c.measured_rmse.value).collect();
            let best = |v: &[f64]| {
                (0..v.len())
                    .min_by(|&a, &b| v[a].total_cmp(&v[b]))
                    .unwrap_or(0)
            };
            Ranking {
                n,
                spearman: spearman(&pred, &meas),
                swaps: rank_swaps(&pred, &meas),
                pairs: at.len() * at.len().saturating_sub(1) / 2,
                same_best: best(&pred) == best(&meas),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dist::LogNormal;

    #[test]
    fn ranks_share_ties() {
        assert_eq!(ranks(&[3.0, 1.0, 3.0, 2.0]), vec![3.5, 1.0, 3.5, 2.0]);
    }

    #[test]
    fn spearman_and_swaps_by_hand() {
        let a = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(spearman(&a, &[10.0, 20.0, 30.0, 40.0]), 1.0);
        assert_eq!(spearman(&a, &[4.0, 3.0, 2.0, 1.0]), -1.0);
        assert_eq!(rank_swaps(&a, &[4.0, 3.0, 2.0, 1.0]), 6);
        // One adjacent swap of 4: rho = 1 - 6 * 2 / (4 * 15) = 0.8.
        assert!((spearman(&a, &[2.0, 1.0, 3.0, 4.0]) - 0.8).abs() < 1e-15);
        assert_eq!(rank_swaps(&a, &[2.0, 1.0, 3.0, 4.0]), 1);
        assert_eq!(rank_swaps(&a, &[1.0, 1.0, 3.0, 4.0]), 0);
    }

    #[test]
    fn seeds_are_apart() {
        assert_eq!(render_seed(7, 3), 10);
        assert_ne!(fit_seed(7), truth_seed(7));
        assert!((0..1 << 16).all(|r| render_seed(7, r) != fit_seed(7)));
    }

    /// When the "pixel" is a known law, the harness on its fit must predict the plain mean's
    /// relative RMSE. The law is lognormal(0, 0.5): light enough that the fit recovers its
    /// variance from 16384 samples to about 1.7% (the sample variance's relative SE,
    /// sqrt((kurtosis - 1) / N), kurtosis 5.9), i.e. 0.9% on an RMSE. The measured RMSE over 1024
    /// renders has relative SE sqrt(1 / (2 * 1024)) = 2.2% (normal errors), the predicted over
    /// 4096 trials 1.1%: together about 2.6%. The tolerance of 12% is 4.6 such SEs: a false
    /// failure has probability about 1e-5 per n (4 checkpoints); it catches any defect that
    /// scales one side by 15% or more — reading the estimate at n/2 samples (+41%), measuring
    /// against a truth off by the mean's own error, or a fit whose variance is 30% off.
    #[test]
    fn the_mean_is_predicted_on_a_known_law() {
        let law: Dist = LogNormal::new(0.0, 0.5).unwrap().into();
        let s = Settings {
            seed: 11,
            renders: 1024,
            fit_spp: 16384,
            truth_spp: 1 << 18,
            trials: 4096,
            checkpoints: vec![4, 16, 64, 256],
            tau: 1.0,
            estimators: vec![crate::estimators::MeanSpec.into()],
            estimator_texts: vec!["mean".into()],
        };
        let r = transfer_pixel(
            &DistPixel(law.clone()),
            "lognormal",
            "test",
            &s,
            None,
            MemoryLimit::default(),
        )
        .unwrap();
        assert_eq!(r.cells.len(), 4);
        assert!((r.truth.mean / law.mean() - 1.0).abs() < 5.0 * r.truth.relative_se());
        for c in &r.cells {
            let pe = c.prediction_error();
            assert!(pe.abs() < 0.12, "n = {}: prediction error {pe}", c.n);
            // The exact value, sigma / (mu sqrt(n)), is inside the tolerance of both sides.
            let exact = (law.relative_variance().unwrap() / c.n as f64).sqrt();
            assert!(
                (c.measured_rmse.value / exact - 1.0).abs() < 0.12,
                "{c:?} vs {exact}"
            );
        }
    }
}
