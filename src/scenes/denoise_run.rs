//! One scene of the denoising experiment ([`super::denoise_experiment`]): its reference (the
//! scene experiment's cache, [`ensure_reference`]), one render with NFOR buffers per sample
//! count, and per colour source the metrics of the noisy estimate and of NFOR's output for each
//! variance; and, for the chosen scene, NFOR's first-pass MSE estimate against the true error
//! over several seeds.

use super::denoise_experiment::{DenoiseExperiment, DenoiseScene, variance_name};
use super::nfor_input::{ColorSource, VarianceSource, nfor_input};
use super::run::{crop_size, ensure_reference, load_world, pixel_relmse, worst_window};
use crate::denoise::nfor::{NforParams, StageSeconds, nfor};
use crate::error::{Error, Result};
use crate::image::Image;
use crate::image::metrics::Metrics;
use crate::limits::{MemoryLimit, peak_rss_bytes};
use crate::render::film::{FilmConfig, FilmOutput, render_with_nfor};
use crate::render::nfor_buffers::NforBuffers;
use crate::render::world::World;
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// Stage of a row: the estimate straight from the render, or NFOR's output.
pub const NOISY: &str = "noisy";
/// See [`NOISY`].
pub const DENOISED: &str = "denoised";

/// One row of `denoise.csv`: an image of one scene, spp, repeat and source, noisy or denoised
/// (with the variance NFOR was given; empty for the noisy estimate, which has none).
#[derive(Debug, Clone, Serialize)]
pub struct DenoiseRow {
    /// Scene name.
    pub scene: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel of the render.
    pub spp: u32,
    /// Which render of this scene and spp (from 0; every source of a repeat comes from it).
    pub repeat: u32,
    /// Its seed.
    pub seed: u64,
    /// The source's estimator spec (`mean`, `gmon:M=5`).
    pub source: String,
    /// Its short label.
    pub label: String,
    /// `sample` or `halves` for NFOR's output; empty for the noisy estimate.
    pub variance: String,
    /// [`NOISY`] or [`DENOISED`].
    pub stage: String,
    /// Mean of `(x − r)² / (r² + 0.01)` over pixels and channels.
    pub relmse: f64,
    /// RMSE over pixels and channels, linear.
    pub rmse: f64,
    /// SSIM of the display luma.
    pub ssim: f64,
    /// Image-mean luminance minus the reference's.
    pub mean_bias: f64,
    /// The same over the reference's.
    pub mean_bias_relative: Option<f64>,
    /// Firefly pixels by the experiment's rule.
    pub firefly_pixels: u64,
    /// Their fraction of the image.
    pub firefly_fraction: f64,
    /// Denoised rows: the fraction of pixels NFOR made worse by more than a factor 2 (see
    /// [`worse_fraction`]); empty for the noisy estimate.
    pub worse_2x_fraction: Option<f64>,
    /// Wall seconds of the render (every source of this spp comes from the same one).
    pub render_wall_s: f64,
    /// Wall seconds of NFOR (denoised rows).
    pub nfor_s: Option<f64>,
    /// The same per megapixel.
    pub nfor_s_per_megapixel: Option<f64>,
    /// Feature prefiltering seconds.
    pub prefilter_s: Option<f64>,
    /// First-pass regression seconds.
    pub regression_s: Option<f64>,
    /// MSE filtering, selection and blending seconds.
    pub selection_s: Option<f64>,
    /// Second pass seconds.
    pub second_pass_s: Option<f64>,
    /// Peak resident memory of the process during this NFOR run (its high-water mark is reset
    /// before the run where Linux allows it; otherwise the process's peak so far).
    pub nfor_peak_rss_bytes: Option<u64>,
    /// Whether `nfor_peak_rss_bytes` was measured from a reset high-water mark.
    pub nfor_peak_rss_reset: Option<bool>,
}

/// One row of `mse_estimates.csv`: for one NFOR run and one first-pass bandwidth, the image
/// mean of NFOR's per-pixel MSE estimate (`noisy_mse`, before filtering) against the true
/// squared error of that candidate against the reference.
#[derive(Debug, Clone, Serialize)]
pub struct MseRow {
    /// `grid` (the experiment's renders, one seed per repeat) or `seeds` (the MSE check).
    pub study: String,
    /// Scene name.
    pub scene: String,
    /// Samples per pixel.
    pub spp: u32,
    /// Source estimator.
    pub source: String,
    /// Variance given to NFOR.
    pub variance: String,
    /// Render seed.
    pub seed: u64,
    /// First-pass bandwidth.
    pub k: f64,
    /// Mean over pixels and channels of NFOR's estimate.
    pub estimated_mse: f64,
    /// Mean over pixels and channels of `(filtered − reference)²`.
    pub true_mse: f64,
    /// `estimated_mse / true_mse`.
    pub ratio: f64,
    /// Mean over pixels and channels of the reference's own variance (its squared standard
    /// error), which `true_mse` holds on top of the candidate's MSE.
    pub reference_variance: f64,
}

/// Size, reference and timing of one scene, for the summary.
#[derive(Debug, Clone, Serialize)]
pub struct DenoiseSceneInfo {
    /// Scene name.
    pub scene: String,
    /// Scene file.
    pub file: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Whether the film's filter was replaced by a box.
    pub rfilter_box_override: bool,
    /// Sample counts rendered, `;`-separated.
    pub spps: String,
    /// Samples per pixel of the reference used.
    pub reference_spp: u64,
    /// What the reference's own noise adds to a relMSE against it.
    pub reference_expected_relmse: Option<f64>,
    /// The reference's mean squared standard error over pixels and channels.
    pub reference_variance: Option<f64>,
    /// Wall seconds spent tracing the reference in this run.
    pub reference_wall_s: f64,
    /// Wall seconds of the renders, all counts and repeats.
    pub render_wall_s: f64,
    /// Wall seconds of every NFOR run of the scene (grid and MSE check).
    pub nfor_wall_s: f64,
    /// Wall seconds of the whole scene.
    pub wall_s: f64,
}

/// Everything one scene produced.
#[derive(Debug, Clone)]
pub struct DenoiseSceneResult {
    /// Size, reference and timings.
    pub info: DenoiseSceneInfo,
    /// One row per spp, repeat, source and stage (and variance, for NFOR).
    pub rows: Vec<DenoiseRow>,
    /// NFOR's MSE estimate against the truth, per run and bandwidth.
    pub mse: Vec<MseRow>,
    /// The reference.
    pub reference: Image,
    /// The montage's crop `[x, y, size]`.
    pub crop: [u32; 3],
    /// Labelled images at the montage's spp, first repeat: per source the noisy estimate, then
    /// NFOR's output per variance.
    pub montage: Vec<(String, Image)>,
}

/// Above this per-pixel relative squared error (relMSE's term) an error is visible: a relative
/// error of about 10% on a pixel brighter than 0.1.
pub const VISIBLE_ERROR: f64 = 0.01;

/// The fraction of pixels NFOR made worse by more than a factor 2: its relative error at the
/// pixel (the square root of relMSE's term, [`pixel_relmse`]) more than twice the noisy
/// input's, and visible ([`VISIBLE_ERROR`]). The second condition keeps a pixel that the
/// noisy input happened to hit almost exactly from counting when NFOR is merely close.
pub fn worse_fraction(noisy: &Image, denoised: &Image, reference: &Image) -> f64 {
    let worse = noisy
        .pixels()
        .iter()
        .zip(denoised.pixels())
        .zip(reference.pixels())
        .filter(|((n, d), r)| {
            let (e_noisy, e_nfor) = (pixel_relmse(**n, **r), pixel_relmse(**d, **r));
            e_nfor > 4.0 * e_noisy && e_nfor > VISIBLE_ERROR
        })
        .count();
    worse as f64 / reference.pixels().len().max(1) as f64
}

/// Asks Linux to reset this process's peak resident memory (`VmHWM`), so that the next read
/// measures what follows. Returns whether it did.
fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", b"5").is_ok()
}

/// One NFOR run and what it cost.
struct NforRun {
    image: Image,
    seconds: f64,
    stages: StageSeconds,
    peak_rss: Option<u64>,
    peak_reset: bool,
    /// Per first-pass candidate: bandwidth, mean estimated MSE, mean true squared error.
    mse: Vec<(f64, f64, f64)>,
}

/// NFOR on `buffers` for one source and variance, judged against `reference`.
fn denoise(
    buffers: &NforBuffers,
    color: &ColorSource,
    variance: VarianceSource,
    params: &NforParams,
    reference: &Image,
) -> Result<NforRun> {
    let input = nfor_input(buffers, color, variance)?;
    let peak_reset = reset_peak_rss();
    let t = Instant::now();
    let out = nfor(&input, params)?;
    let seconds = t.elapsed().as_secs_f64();
    let peak_rss = peak_rss_bytes();
    let mse = out
        .candidates
        .iter()
        .map(|c| {
            let (mut est, mut truth, mut n) = (0.0f64, 0.0f64, 0.0f64);
            for ch in 0..3 {
                for (i, (&f, &e)) in c
                    .filtered
                    .plane(ch)
                    .iter()
                    .zip(c.noisy_mse.plane(ch))
                    .enumerate()
                {
                    let r = f64::from(reference.pixels()[i][ch]);
                    let d = f64::from(f) - r;
                    est += f64::from(e);
                    truth += d * d;
                    n += 1.0;
                }
            }
            (f64::from(c.k), est / n, truth / n)
        })
        .collect();
    Ok(NforRun {
        image: out.image.to_image()?,
        seconds,
        stages: out.seconds,
        peak_rss,
        peak_reset,
        mse,
    })
}

/// Renders `world` at `spp` with NFOR buffers and every source's estimator.
fn render(
    exp: &DenoiseExperiment,
    world: &World,
    spp: u32,
    seed: u64,
    memory: MemoryLimit,
) -> Result<(FilmOutput, NforBuffers, f64)> {
    let cfg = FilmConfig {
        estimators: exp.estimators(),
        spp,
        checkpoints: Vec::new(),
        seed,
        dump_pixels: Vec::new(),
        memory,
    };
    let t = Instant::now();
    let mut out = render_with_nfor(world, &cfg, true, |_| {})?;
    let wall = t.elapsed().as_secs_f64();
    let buffers = out.nfor.take().ok_or_else(|| Error::Io {
        path: "<render>".into(),
        message: "the film returned no NFOR buffers".into(),
    })?;
    Ok((out, buffers, wall))
}

/// Which NFOR run a set of [`MseRow`]s comes from.
struct RunKey<'a> {
    study: &'a str,
    scene: &'a str,
    spp: u32,
    source: String,
    variance: VarianceSource,
    seed: u64,
}

fn mse_rows(key: &RunKey, run: &NforRun, reference_variance: f64) -> Vec<MseRow> {
    run.mse
        .iter()
        .map(|&(k, est, truth)| MseRow {
            study: key.study.into(),
            scene: key.scene.into(),
            spp: key.spp,
            source: key.source.clone(),
            variance: variance_name(key.variance).into(),
            seed: key.seed,
            k,
            estimated_mse: est,
            true_mse: truth,
            ratio: est / truth,
            reference_variance,
        })
        .collect()
}

/// Runs one scene on the current rayon pool: reference, `repeats` renders per spp, NFOR per
/// render, source and variance, metrics; and the MSE check when the experiment names this scene.
///
/// # Errors
///
/// Anything loading, rendering, denoising, measuring or writing the reference fails with.
pub fn run_denoise_scene(
    exp: &DenoiseExperiment,
    index: usize,
    references: &Path,
    memory: MemoryLimit,
    log: &mut dyn FnMut(String),
) -> Result<DenoiseSceneResult> {
    let started = Instant::now();
    let DenoiseScene { scene, spps } = &exp.scenes[index];
    let world = load_world(scene)?;
    let (reference, reference_time) = ensure_reference(scene, &world, references, memory, log)?;
    let accuracy = reference.accuracy();
    let ref_image = reference.image();
    drop(reference);
    let reference_variance = accuracy.expected_rmse.map_or(f64::NAN, |r| r * r);
    let params = NforParams::paper();
    let megapixels = f64::from(scene.width) * f64::from(scene.height) / 1e6;
    let (mut rows, mut mse, mut montage) = (Vec::new(), Vec::new(), Vec::new());
    let (mut render_wall, mut nfor_wall) = (0.0, 0.0);
    let mut crop_probe: Option<Image> = None;
    for (&spp, repeat) in spps
        .iter()
        .flat_map(|spp| (0..exp.repeats).map(move |r| (spp, r)))
    {
        let seed = exp.repeat_seed(repeat);
        log(format!(
            "{}: rendering {}x{} at {spp} spp (repeat {}/{}, seed {seed}) with NFOR buffers and \
             {} estimators",
            scene.name,
            scene.width,
            scene.height,
            repeat + 1,
            exp.repeats,
            exp.sources.len()
        ));
        let (out, buffers, wall) = render(exp, &world, spp, seed, memory)?;
        render_wall += wall;
        let row = |source: &super::denoise_experiment::Source,
                   variance: &str,
                   stage: &str,
                   m: &Metrics| DenoiseRow {
            scene: scene.name.clone(),
            width: scene.width,
            height: scene.height,
            spp,
            repeat,
            seed,
            source: source.spec.to_string(),
            label: source.label.clone(),
            variance: variance.into(),
            stage: stage.into(),
            relmse: m.relmse,
            rmse: m.rmse,
            ssim: m.ssim,
            mean_bias: m.mean_bias,
            mean_bias_relative: m.mean_bias_relative,
            firefly_pixels: m.firefly_pixels,
            firefly_fraction: m.firefly_fraction,
            worse_2x_fraction: None,
            render_wall_s: wall,
            nfor_s: None,
            nfor_s_per_megapixel: None,
            prefilter_s: None,
            regression_s: None,
            selection_s: None,
            second_pass_s: None,
            nfor_peak_rss_bytes: None,
            nfor_peak_rss_reset: None,
        };
        for (e, source) in exp.sources.iter().enumerate() {
            let noisy = &out
                .images
                .iter()
                .find(|i| i.estimator == e && i.spp == spp)
                .ok_or_else(|| Error::Io {
                    path: "<render>".into(),
                    message: format!("no final image of {}", source.spec),
                })?
                .image;
            let m = Metrics::compute(noisy, &ref_image, exp.rule)?;
            let noisy_relmse = m.relmse;
            rows.push(row(source, "", NOISY, &m));
            // The montage and its crop show the first repeat.
            let at_montage = spp == exp.montage_spp && repeat == 0;
            if at_montage {
                montage.push((source.label.clone(), noisy.clone()));
            }
            for &v in &source.variances {
                let run = denoise(&buffers, &source.color, v, &params, &ref_image)?;
                nfor_wall += run.seconds;
                let m = Metrics::compute(&run.image, &ref_image, exp.rule)?;
                log(format!(
                    "{}: {spp} spp, repeat {}, {} with {} variance: relMSE {:.3e} noisy -> \
                     {:.3e} NFOR ({:.2} s)",
                    scene.name,
                    repeat + 1,
                    source.label,
                    variance_name(v),
                    noisy_relmse,
                    m.relmse,
                    run.seconds
                ));
                let mut r = row(source, variance_name(v), DENOISED, &m);
                r.worse_2x_fraction = Some(worse_fraction(noisy, &run.image, &ref_image));
                r.nfor_s = Some(run.seconds);
                r.nfor_s_per_megapixel = Some(run.seconds / megapixels);
                r.prefilter_s = Some(run.stages.prefilter);
                r.regression_s = Some(run.stages.regression);
                r.selection_s = Some(run.stages.selection);
                r.second_pass_s = Some(run.stages.second_pass);
                r.nfor_peak_rss_bytes = run.peak_rss;
                r.nfor_peak_rss_reset = Some(run.peak_reset);
                let key = RunKey {
                    study: "grid",
                    scene: &scene.name,
                    spp,
                    source: source.spec.to_string(),
                    variance: v,
                    seed,
                };
                mse.extend(mse_rows(&key, &run, reference_variance));
                rows.push(r);
                if at_montage {
                    if source.color == ColorSource::Mean && crop_probe.is_none() {
                        crop_probe = Some(run.image.clone());
                    }
                    montage.push((format!("+ NFOR, {} var.", variance_name(v)), run.image));
                }
            }
        }
    }

    if exp.mse_check.scene == index {
        let c = &exp.mse_check;
        let source = &exp.sources[c.source];
        for s in 1..=u64::from(c.seeds) {
            let seed = exp.file.seed.wrapping_add(s);
            let (_, buffers, wall) = render(exp, &world, c.spp, seed, memory)?;
            render_wall += wall;
            for &v in &c.variances {
                let run = denoise(&buffers, &source.color, v, &params, &ref_image)?;
                nfor_wall += run.seconds;
                let key = RunKey {
                    study: "seeds",
                    scene: &scene.name,
                    spp: c.spp,
                    source: source.spec.to_string(),
                    variance: v,
                    seed,
                };
                let rows = mse_rows(&key, &run, reference_variance);
                log(format!(
                    "{}: MSE check, seed {seed}, {} variance: estimated / true = {}",
                    scene.name,
                    variance_name(v),
                    rows.iter()
                        .map(|r| format!("{:.3} (k = {})", r.ratio, r.k))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
                mse.extend(rows);
            }
        }
    }

    // The montage shows where NFOR of the mean did worst, wherever that is.
    let crop = match &crop_probe {
        Some(img) => worst_window(img, &ref_image, crop_size(scene.width, scene.height))?,
        None => [0, 0, crop_size(scene.width, scene.height) as u32],
    };
    let info = DenoiseSceneInfo {
        scene: scene.name.clone(),
        file: scene.file.display().to_string(),
        width: scene.width,
        height: scene.height,
        rfilter_box_override: scene.box_filter,
        spps: spps
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(";"),
        reference_spp: accuracy.spp,
        reference_expected_relmse: accuracy.expected_relmse,
        reference_variance: accuracy.expected_rmse.map(|r| r * r),
        reference_wall_s: reference_time.this_run_s,
        render_wall_s: render_wall,
        nfor_wall_s: nfor_wall,
        wall_s: started.elapsed().as_secs_f64(),
    };
    Ok(DenoiseSceneResult {
        info,
        rows,
        mse,
        reference: ref_image,
        crop,
        montage,
    })
}
