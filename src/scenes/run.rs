//! One scene of the experiment: its reference (made, extended or reused from the cache), one
//! render with every estimator read at every checkpoint, every image's metrics, the estimators'
//! costs ([`super::cost`]) and Pajot et al.'s delayed fractions.

use super::cost::{self, CostReport, process_cpu_seconds};
use super::experiment::{Scene, ScenesExperiment};
use super::tables::{CostRow, DelayedRow, MetricRow, SceneInfo, label};
use crate::error::{Error, Result};
use crate::estimators::{Estimator, EstimatorSpec, Extra, MeanSpec, luminance};
use crate::image::Image;
use crate::image::metrics::{FireflyRule, Metrics, display_luma};
use crate::limits::MemoryLimit;
use crate::render::film::{self, FilmConfig};
use crate::render::integrator::{pushable, radiance};
use crate::render::mitsuba;
use crate::render::reference::{REFERENCE_SEED, Reference, SceneKey, scene_hash, sidecar};
use crate::render::sampler::SampleStream;
use crate::render::world::World;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// A reference run saves its state at least this often.
const SAVE_EVERY: Duration = Duration::from_secs(600);

/// Passes a reference run is split into (for progress and saving).
const REFERENCE_PASSES: u64 = 16;

/// Everything one scene produced: the rows of the tables and the images of the figures.
#[derive(Debug, Clone)]
pub struct SceneResult {
    /// Size, budget, reference and timings.
    pub info: SceneInfo,
    /// One row per estimator and checkpoint.
    pub rows: Vec<MetricRow>,
    /// One row per estimator.
    pub costs: Vec<CostRow>,
    /// One row per Pajot estimator of the delayed table.
    pub delayed: Vec<DelayedRow>,
    /// The reference image.
    pub reference: Image,
    /// Labels and images of the bias-map estimators at the largest spp.
    pub bias_images: Vec<(String, Image)>,
    /// Labels and images of the crop estimators at the crops' spp.
    pub crop_images: Vec<(String, Image)>,
    /// The crop `[x, y, size]`.
    pub crop: [u32; 3],
    /// The crops' spp.
    pub crop_spp: u32,
}

/// Where a scene's cached reference lives: `DIR/<name>-<w>x<h>.exr`, with `.state` and `.json`
/// appended for its statistics and report (the layout of `fireflies reference`).
pub fn reference_path(dir: &Path, scene: &Scene) -> PathBuf {
    dir.join(format!(
        "{}-{}x{}.exr",
        scene.name, scene.width, scene.height
    ))
}

/// Loads the scene at the experiment's size.
pub fn load_world(scene: &Scene) -> Result<World> {
    let mut desc = mitsuba::load_file_with(
        &scene.file,
        mitsuba::LoadOptions {
            box_filter: scene.box_filter,
        },
    )?;
    desc.camera.width = scene.width;
    desc.camera.height = scene.height;
    Ok(World::new(&desc))
}

/// Wall seconds a reference took to trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceTime {
    /// In this run (0 when the cache had enough samples).
    pub this_run_s: f64,
    /// In every run that traced it, as its JSON records (`trace_wall_s`); `None` when a cached
    /// reference does not say.
    pub total_s: Option<f64>,
}

/// The `trace_wall_s` a reference's JSON records, if any.
fn recorded_trace_time(exr: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(sidecar(exr, ".json")).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    json.get("trace_wall_s")?.as_f64()
}

/// The scene's reference with at least `scene.reference_spp` samples per pixel: read from
/// `dir` if there, traced further if it has fewer, made otherwise. Returns it and the wall
/// seconds spent tracing it.
///
/// # Errors
///
/// A cached reference of another scene text, size, filter or seed (the message says to remove
/// it), or a file that cannot be read or written.
pub fn ensure_reference(
    scene: &Scene,
    world: &World,
    dir: &Path,
    memory: MemoryLimit,
    log: &mut dyn FnMut(String),
) -> Result<(Reference, ReferenceTime)> {
    let text =
        std::fs::read_to_string(&scene.file).map_err(|e| Error::io(scene.file.display(), &e))?;
    let key = SceneKey {
        path: scene.file.display().to_string(),
        hash: scene_hash(&text),
        box_filter: scene.box_filter,
    };
    let exr = reference_path(dir, scene);
    let state = sidecar(&exr, ".state");
    let earlier = if state.exists() {
        recorded_trace_time(&exr)
    } else {
        Some(0.0)
    };
    let mut reference = if state.exists() {
        let bytes = std::fs::read(&state).map_err(|e| Error::io(state.display(), &e))?;
        let r = Reference::from_bytes(&bytes, &state.display().to_string())?;
        let stale = r.scene().hash != key.hash
            || r.scene().box_filter != key.box_filter
            || (r.width(), r.height()) != (scene.width, scene.height)
            || r.seed() != REFERENCE_SEED;
        if stale {
            return Err(Error::Io {
                path: state.display().to_string(),
                message: format!(
                    "is a reference of another scene text, size, filter or seed than {} at \
                     {}x{}; remove it (and its .exr and .json) to make a new one",
                    scene.file.display(),
                    scene.width,
                    scene.height
                ),
            });
        }
        r
    } else {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir.display(), &e))?;
        Reference::new(key, scene.width, scene.height, REFERENCE_SEED, memory)?
    };
    let have = reference.spp();
    if have >= scene.reference_spp {
        log(format!(
            "{}: reference reused from {} ({have} spp)",
            scene.name,
            exr.display()
        ));
        return Ok((
            reference,
            ReferenceTime {
                this_run_s: 0.0,
                total_s: earlier,
            },
        ));
    }
    let (start, end) = (
        reference.next_start(),
        reference.next_start() + (scene.reference_spp - have),
    );
    log(format!(
        "{}: tracing reference samples [{start}, {end}) at {}x{} into {}",
        scene.name,
        scene.width,
        scene.height,
        exr.display()
    ));
    let started = Instant::now();
    let mut saved = Instant::now();
    let pass = (end - start).div_ceil(REFERENCE_PASSES).max(1);
    let mut done = start;
    while done < end {
        let next = (done + pass).min(end);
        reference.trace(world, done..next)?;
        done = next;
        log(format!(
            "{}: reference {} of {} spp ({:.0} s)",
            scene.name,
            reference.spp(),
            scene.reference_spp,
            started.elapsed().as_secs_f64()
        ));
        if done < end && saved.elapsed() >= SAVE_EVERY {
            let total = earlier.map(|t| t + started.elapsed().as_secs_f64());
            save_reference(&reference, &exr, total)?;
            saved = Instant::now();
        }
    }
    let this_run_s = started.elapsed().as_secs_f64();
    let total_s = earlier.map(|t| t + this_run_s);
    save_reference(&reference, &exr, total_s)?;
    Ok((
        reference,
        ReferenceTime {
            this_run_s,
            total_s,
        },
    ))
}

/// Writes the reference's files, with the wall seconds spent tracing it so far (when known).
fn save_reference(reference: &Reference, exr: &Path, trace_wall_s: Option<f64>) -> Result<()> {
    let mut extra = serde_json::Map::new();
    extra.insert("trace_wall_s".into(), serde_json::json!(trace_wall_s));
    reference.save(exr, extra)
}

/// Both images of one size, and a window that fits in them.
fn check_window(test: &Image, reference: &Image, size: usize) -> Result<()> {
    let (w, h) = (test.width(), test.height());
    if (reference.width(), reference.height()) != (w, h) {
        return Err(Error::param(
            "reference",
            format!("{}x{}", reference.width(), reference.height()),
            format!("the image is {w}x{h}"),
        ));
    }
    if size == 0 || size > w || size > h {
        return Err(Error::param(
            "crop size",
            size,
            format!("must be in 1..={}", w.min(h)),
        ));
    }
    Ok(())
}

/// The `size x size` window (inside the image) holding the most firefly pixels of `test` by
/// `rule` (the metrics' definition), ties broken by the positive excess of its display luma
/// over the reference's: where the test image's fireflies are. A count, not a sum of values,
/// so that a window of many fireflies beats one extreme sample. Returns `[x, y, size]` (the
/// first best window in row-major order).
///
/// # Errors
///
/// The images differ in size, or `size` is 0 or larger than a side.
pub fn firefly_window(
    test: &Image,
    reference: &Image,
    size: usize,
    rule: FireflyRule,
) -> Result<[u32; 3]> {
    let (w, h) = (test.width(), test.height());
    check_window(test, reference, size)?;
    // The excess is at most 1 per pixel, so 1e-6 of it never outweighs a firefly in windows
    // under 10^6 pixels.
    let lum = |p: [f32; 3]| luminance(p.map(f64::from));
    Ok(best_window(w, h, size, |x, y| {
        let (t, r) = (test.get(x, y), reference.get(x, y));
        let firefly = f64::from(u8::from(rule.is_firefly(lum(t), lum(r))));
        firefly + 1e-6 * (display_luma(t) - display_luma(r)).max(0.0)
    }))
}

/// The `size`² window of `test` with the largest sum of per-pixel relative squared error
/// against `reference` (the mean over channels of `(x − r)² / (r² + 0.01)`, relMSE's terms):
/// where `test` is worst, wherever that is. Returns `[x, y, size]`.
///
/// # Errors
///
/// As [`firefly_window`].
pub fn worst_window(test: &Image, reference: &Image, size: usize) -> Result<[u32; 3]> {
    let (w, h) = (test.width(), test.height());
    check_window(test, reference, size)?;
    Ok(best_window(w, h, size, |x, y| {
        pixel_relmse(test.get(x, y), reference.get(x, y))
    }))
}

/// One pixel's term of relMSE: the mean over channels of `(x − r)² / (r² + 0.01)`.
pub fn pixel_relmse(x: [f32; 3], r: [f32; 3]) -> f64 {
    (0..3)
        .map(|c| {
            let (x, r) = (f64::from(x[c]), f64::from(r[c]));
            (x - r) * (x - r) / (r * r + 0.01)
        })
        .sum::<f64>()
        / 3.0
}

/// The first `size`² window in row-major order with the largest sum of `score`, by a
/// summed-area table (a zero row and column in front).
fn best_window(w: usize, h: usize, size: usize, score: impl Fn(usize, usize) -> f64) -> [u32; 3] {
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0.0;
        for x in 0..w {
            row += score(x, y);
            sat[(y + 1) * (w + 1) + x + 1] = sat[y * (w + 1) + x + 1] + row;
        }
    }
    let at = |x: usize, y: usize| sat[y * (w + 1) + x];
    let mut best = (f64::NEG_INFINITY, 0, 0);
    for y in 0..=h - size {
        for x in 0..=w - size {
            let s = at(x + size, y + size) - at(x, y + size) - at(x + size, y) + at(x, y);
            if s > best.0 {
                best = (s, x, y);
            }
        }
    }
    [best.1 as u32, best.2 as u32, size as u32]
}

/// The automatic crop size: a third of the shorter side, between 12 and 48 pixels.
pub(crate) fn crop_size(width: u32, height: u32) -> usize {
    let side = width.min(height) as usize;
    (side / 3).clamp(12, 48).min(side)
}

/// Pajot et al.'s Table 4: traces samples `[0, spp)` of every pixel with the render's seed
/// (the same streams as the render), feeds their luminances to each Pajot estimator of
/// `specs` (the RGB film's Pajot estimators decide on exactly this luminance stream), and sums
/// the samples still delayed at the end.
pub fn delayed_fractions(
    world: &World,
    seed: u64,
    spp: u32,
    specs: &[EstimatorSpec],
    scene: &str,
) -> Result<Vec<DelayedRow>> {
    let (width, height) = (world.camera.width(), world.camera.height());
    let k = specs.len();
    // Per row: valid samples, then per spec the delayed samples and pixels with any.
    let per_row: Vec<(u64, Vec<(u64, u64)>)> = (0..height)
        .into_par_iter()
        .map(|y| -> Result<(u64, Vec<(u64, u64)>)> {
            let mut valid = 0u64;
            let mut sums = vec![(0u64, 0u64); k];
            for x in 0..width {
                let mut ests: Vec<Box<dyn Estimator>> = specs
                    .iter()
                    .map(EstimatorSpec::build)
                    .collect::<Result<_>>()?;
                let index = u64::from(y) * u64::from(width) + u64::from(x);
                for s in 0..spp {
                    let mut rng = SampleStream::new(seed, index, u64::from(s));
                    if let Some(v) = pushable(radiance(world, x, y, &mut rng)) {
                        valid += 1;
                        let lum = luminance(v);
                        for e in &mut ests {
                            e.push(lum);
                        }
                    }
                }
                for (e, sum) in ests.iter().zip(&mut sums) {
                    let delayed = e
                        .extras()
                        .iter()
                        .find_map(|(key, v)| match (key, v) {
                            (&"delayed", Extra::Int(n)) => Some(*n),
                            _ => None,
                        })
                        .unwrap_or(0);
                    sum.0 += delayed;
                    sum.1 += u64::from(delayed > 0);
                }
            }
            Ok((valid, sums))
        })
        .collect::<Result<_>>()?;
    let samples: u64 = per_row.iter().map(|r| r.0).sum();
    let pixels = u64::from(width) * u64::from(height);
    Ok(specs
        .iter()
        .enumerate()
        .map(|(i, spec)| {
            let delayed: u64 = per_row.iter().map(|r| r.1[i].0).sum();
            let with: u64 = per_row.iter().map(|r| r.1[i].1).sum();
            DelayedRow {
                scene: scene.to_string(),
                estimator: spec.to_string(),
                label: label(spec),
                spp,
                pixels,
                samples,
                delayed,
                fraction: delayed as f64 / samples.max(1) as f64,
                pixels_with_delayed: with as f64 / pixels.max(1) as f64,
            }
        })
        .collect())
}

/// Runs one scene on the current rayon pool: reference, render, metrics, costs, delayed
/// fractions. `references` is the reference cache folder.
///
/// # Errors
///
/// Anything loading, rendering, measuring or writing the reference fails with.
pub fn run_scene(
    exp: &ScenesExperiment,
    scene: &Scene,
    references: &Path,
    memory: MemoryLimit,
    log: &mut dyn FnMut(String),
) -> Result<SceneResult> {
    let world = load_world(scene)?;
    let (reference, reference_time) = ensure_reference(scene, &world, references, memory, log)?;
    let accuracy = reference.accuracy();
    let ref_image = reference.image();
    drop(reference);

    log(format!(
        "{}: rendering {}x{} at {} spp with {} estimators, read at {:?}",
        scene.name,
        scene.width,
        scene.height,
        scene.spp,
        exp.estimators.len(),
        scene.checkpoints
    ));
    let cfg = FilmConfig {
        estimators: exp.estimators.clone(),
        spp: scene.spp,
        checkpoints: scene.checkpoints.clone(),
        seed: exp.file.seed,
        dump_pixels: Vec::new(),
        memory,
    };
    let (wall0, cpu0) = (Instant::now(), process_cpu_seconds());
    let out = film::render(&world, &cfg, |_| {})?;
    let (render_wall_s, render_cpu_s) =
        (wall0.elapsed().as_secs_f64(), process_cpu_seconds() - cpu0);
    log(format!(
        "{}: rendered in {render_wall_s:.1} s wall, {render_cpu_s:.1} s CPU",
        scene.name
    ));

    // The whole bank's cost inside a real render: the same scene with the mean alone.
    let mean_render = match exp.file.cost.mean_render_spp.min(scene.spp) {
        0 => None,
        spp => {
            let cfg = FilmConfig {
                estimators: vec![EstimatorSpec::Mean(MeanSpec)],
                spp,
                checkpoints: Vec::new(),
                ..cfg.clone()
            };
            let cpu0 = process_cpu_seconds();
            let out = film::render(&world, &cfg, |_| {})?;
            let cpu = process_cpu_seconds() - cpu0;
            Some((spp, cpu * 1e9 / out.samples.max(1) as f64))
        }
    };

    let analysis = Instant::now();
    let costs = cost::measure(
        &world,
        exp.file.seed,
        &exp.estimators,
        exp.file.cost.pixels,
        exp.file.cost.spp.min(scene.spp),
        exp.file.cost.repeats,
    )?;
    let pixels = f64::from(scene.width) * f64::from(scene.height);
    let metrics: Vec<Metrics> = out
        .images
        .par_iter()
        .map(|img| Metrics::compute(&img.image, &ref_image, exp.rule))
        .collect::<Result<_>>()?;
    let rows: Vec<MetricRow> = out
        .images
        .iter()
        .zip(metrics)
        .map(|(img, m)| {
            let spec = &exp.estimators[img.estimator];
            let c = &costs.estimators[img.estimator];
            let n = pixels * f64::from(img.spp);
            let estimator_cpu_s = (n * c.push_ns_per_sample + pixels * c.read_ns_per_pixel) * 1e-9;
            MetricRow {
                scene: scene.name.clone(),
                estimator: spec.to_string(),
                label: label(spec),
                spp: img.spp,
                rmse: m.rmse,
                relmse: m.relmse,
                psnr_db: m.psnr_db,
                ssim: m.ssim,
                mean_bias: m.mean_bias,
                mean_bias_relative: m.mean_bias_relative,
                firefly_pixels: m.firefly_pixels,
                firefly_fraction: m.firefly_fraction,
                render_cpu_s: n * costs.trace_ns_per_sample * 1e-9 + estimator_cpu_s,
                estimator_cpu_s,
            }
        })
        .collect();
    let cost_rows = cost_rows(&scene.name, &exp.estimators, &costs, &out.state_bytes);

    let delayed = if exp.delayed_estimators.is_empty() {
        Vec::new()
    } else {
        delayed_fractions(
            &world,
            exp.file.seed,
            exp.file.delayed_spp,
            &exp.delayed_estimators,
            &scene.name,
        )?
    };

    let image_at = |e: usize, spp: u32| {
        out.images
            .iter()
            .find(|i| i.estimator == e && i.spp == spp)
            .map(|i| i.image.clone())
    };
    let bias_images: Vec<(String, Image)> = exp
        .bias_maps
        .iter()
        .filter_map(|&e| image_at(e, scene.spp).map(|i| (label(&exp.estimators[e]), i)))
        .collect();
    let crop_spp = exp.crop_spp(scene);
    let crop_images: Vec<(String, Image)> = exp
        .crops
        .iter()
        .filter_map(|&e| image_at(e, crop_spp).map(|i| (label(&exp.estimators[e]), i)))
        .collect();
    let crop = match scene.crop {
        Some(c) => c,
        None => {
            // Where the plain mean (else the first crop estimator) has its fireflies.
            let mean = exp
                .estimators
                .iter()
                .position(|s| *s == EstimatorSpec::Mean(MeanSpec));
            let probe = mean
                .and_then(|e| image_at(e, crop_spp))
                .or_else(|| crop_images.first().map(|c| c.1.clone()));
            match probe {
                Some(img) => firefly_window(
                    &img,
                    &ref_image,
                    crop_size(scene.width, scene.height),
                    exp.rule,
                )?,
                None => [0, 0, crop_size(scene.width, scene.height) as u32],
            }
        }
    };

    let trace = costs.trace_ns_per_sample;
    let pushes: f64 = costs.estimators.iter().map(|c| c.push_ns_per_sample).sum();
    let reads_cpu: f64 = costs
        .estimators
        .iter()
        .map(|c| c.read_ns_per_pixel * pixels * scene.checkpoints.len() as f64 * 1e-9)
        .sum();
    let info = SceneInfo {
        scene: scene.name.clone(),
        file: scene.file.display().to_string(),
        width: scene.width,
        height: scene.height,
        spp: scene.spp,
        checkpoints: scene
            .checkpoints
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(";"),
        rfilter_box_override: scene.box_filter,
        reference_spp: accuracy.spp,
        reference_pixel_relative_se: accuracy.pixel_relative_se_rms,
        reference_image_mean_relative_se: accuracy.image_mean_relative_se,
        reference_expected_relmse: accuracy.expected_relmse,
        reference_wall_s: reference_time.this_run_s,
        reference_total_wall_s: reference_time.total_s,
        threads: rayon::current_num_threads(),
        render_wall_s,
        render_cpu_s,
        render_estimate_wall_s: out.estimate_seconds,
        samples: out.samples,
        invalid_samples: out.invalid_samples,
        measured_ns_per_sample: (render_cpu_s - reads_cpu).max(0.0) * 1e9
            / (out.samples.max(1) as f64),
        mean_render_ns_per_sample: mean_render.map(|m| m.1),
        mean_render_spp: mean_render.map(|m| m.0),
        trace_ns_per_sample: trace,
        modelled_ns_per_sample: trace + pushes,
        analysis_wall_s: analysis.elapsed().as_secs_f64(),
        crop: format!("[{}, {}, {}] at {crop_spp} spp", crop[0], crop[1], crop[2]),
    };
    Ok(SceneResult {
        info,
        rows,
        costs: cost_rows,
        delayed,
        reference: ref_image,
        bias_images,
        crop_images,
        crop,
        crop_spp,
    })
}

fn cost_rows(
    scene: &str,
    specs: &[EstimatorSpec],
    costs: &CostReport,
    state_bytes: &[f64],
) -> Vec<CostRow> {
    let trace = costs.trace_ns_per_sample;
    let bank: f64 = trace
        + costs
            .estimators
            .iter()
            .map(|c| c.push_ns_per_sample)
            .sum::<f64>();
    specs
        .iter()
        .zip(&costs.estimators)
        .enumerate()
        .map(|(i, (spec, c))| CostRow {
            scene: scene.to_string(),
            estimator: spec.to_string(),
            label: label(spec),
            push_ns_per_sample: c.push_ns_per_sample,
            read_ns_per_pixel: c.read_ns_per_pixel,
            trace_ns_per_sample: trace,
            fraction_alone: c.push_ns_per_sample / (trace + c.push_ns_per_sample),
            fraction_of_bank: c.push_ns_per_sample / bank,
            state_bytes_per_pixel: state_bytes.get(i).copied().unwrap_or(f64::NAN),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn firefly_window_finds_the_cluster_of_bright_pixels() {
        let reference = Image::from_pixels(16, 12, vec![[0.1; 3]; 16 * 12]).unwrap();
        let mut px = vec![[0.1f32; 3]; 16 * 12];
        // One extreme sample at (1, 1) and three moderate fireflies around (10, 7).
        px[16 + 1] = [1e6; 3];
        for (x, y) in [(10, 7), (11, 8), (12, 7)] {
            px[y * 16 + x] = [5.0; 3];
        }
        let test = Image::from_pixels(16, 12, px).unwrap();
        let rule = FireflyRule::default();
        let [x, y, s] = firefly_window(&test, &reference, 4, rule).unwrap();
        assert_eq!(s, 4);
        assert!((9..=10).contains(&x) && (5..=7).contains(&y), "{x},{y}");
        assert!(firefly_window(&test, &reference, 13, rule).is_err());
        // Without fireflies the display excess decides: a faint glow at (2, 8).
        let mut px = vec![[0.1f32; 3]; 16 * 12];
        px[8 * 16 + 2] = [0.2; 3];
        let glow = Image::from_pixels(16, 12, px).unwrap();
        assert_eq!(
            firefly_window(&glow, &reference, 4, rule).unwrap(),
            [0, 5, 4]
        );
        assert_eq!(crop_size(128, 128), 42);
        assert_eq!(crop_size(32, 32), 12);
        assert_eq!(crop_size(11, 40), 11);
    }
}
