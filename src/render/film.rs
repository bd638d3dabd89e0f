//! The film: per pixel, a bank of RGB estimators fed every camera sample of that pixel
//! (pbrt-v4's `Film::AddSample` is where pixel estimators live; here the whole stream is kept
//! by the estimators instead of a weighted sum).
//!
//! The render proceeds in passes between checkpoints. In each pass, rayon hands out rows; a
//! pixel draws its samples `[s0, s1)` in order, each from its own stream
//! ([`SampleStream`]), so the image does not depend on the number of threads or on the
//! checkpoints. After a pass, the image-wide per-channel sample σ (Jung's image mode, docs/estimators.md §4)
//! is merged in row order and handed to every pixel before the estimates are read.
//! Non-finite or negative radiance samples are counted and never pushed.

use super::integrator::radiance;
use super::sampler::SampleStream;
use super::world::World;
use crate::error::{Error, Result};
use crate::estimators::{EstimatorSpec, RgbEstimator, Welford, build_rgb, luminance};
use crate::image::Image;
use crate::limits::MemoryLimit;
use rayon::prelude::*;
use std::time::Instant;

/// What to render and what to keep.
#[derive(Debug, Clone)]
pub struct FilmConfig {
    /// Estimators each pixel runs.
    pub estimators: Vec<EstimatorSpec>,
    /// Samples per pixel in total.
    pub spp: u32,
    /// Sample counts at which every estimator's image is also kept (each ≤ `spp`).
    pub checkpoints: Vec<u32>,
    /// Seed of every random stream.
    pub seed: u64,
    /// Pixels `(x, y)` whose raw luminance streams are kept.
    pub dump_pixels: Vec<(u32, u32)>,
    /// The most memory the render may plan to hold.
    pub memory: MemoryLimit,
}

/// One estimator's image after a number of samples per pixel.
#[derive(Debug, Clone)]
pub struct FilmImage {
    /// Index of the estimator in [`FilmConfig::estimators`].
    pub estimator: usize,
    /// Samples per pixel behind it.
    pub spp: u32,
    /// The image.
    pub image: Image,
}

/// Everything a render produced.
#[derive(Debug, Clone)]
pub struct FilmOutput {
    /// Images at every checkpoint and at the end, estimator-major.
    pub images: Vec<FilmImage>,
    /// Samples the integrator returned that were NaN, infinite or negative (not pushed).
    pub invalid_samples: u64,
    /// Camera samples traced.
    pub samples: u64,
    /// Per estimator: mean per-pixel state in bytes at the end.
    pub state_bytes: Vec<f64>,
    /// The raw luminance stream of each dumped pixel, in sample order (valid samples only).
    pub dumps: Vec<((u32, u32), Vec<f64>)>,
    /// Wall-clock seconds spent reading estimates into images (all checkpoints), which is
    /// paid per pixel, not per sample; the rest of the render is tracing and pushing.
    pub estimate_seconds: f64,
}

/// Per-pixel state: one RGB estimator per configured spec.
struct Pixel {
    estimators: Vec<Box<dyn RgbEstimator>>,
}

/// What one row of a pass reports back.
#[derive(Default)]
struct RowReport {
    invalid: u64,
    sigma: [Welford; 3],
    dumps: Vec<(usize, Vec<f64>)>,
}

/// Checks a film configuration against the camera's image.
fn check(cfg: &FilmConfig, width: u32, height: u32) -> Result<Vec<u32>> {
    if cfg.spp == 0 {
        return Err(Error::param("spp", 0, "must be at least 1"));
    }
    if cfg.estimators.is_empty() {
        return Err(Error::param("estimators", "(none)", "give at least one"));
    }
    for &c in &cfg.checkpoints {
        if c == 0 || c > cfg.spp {
            return Err(Error::param(
                "checkpoints",
                c,
                format!("each checkpoint must be in 1..={}", cfg.spp),
            ));
        }
    }
    for &(x, y) in &cfg.dump_pixels {
        if x >= width || y >= height {
            return Err(Error::param(
                "dump-pixels",
                format!("{x},{y}"),
                format!("outside the {width}x{height} image"),
            ));
        }
    }
    let mut stops = cfg.checkpoints.clone();
    stops.push(cfg.spp);
    stops.sort_unstable();
    stops.dedup();
    Ok(stops)
}

/// Refuses a render whose pixel banks, kept images and dumped streams would not fit in the
/// memory limit, before anything is allocated. Each estimator is built once to read its real
/// per-pixel state (its parameters are capped, so this is small).
fn check_memory(cfg: &FilmConfig, width: u32, height: u32, stops: &[u32]) -> Result<usize> {
    let pixels = u128::from(width) * u128::from(height);
    let mut per_pixel = size_of::<Pixel>() as u128;
    for spec in &cfg.estimators {
        let e = build_rgb(spec)?;
        per_pixel += (e.state_bytes() + size_of::<Box<dyn RgbEstimator>>()) as u128;
    }
    let kept = stops
        .iter()
        .filter(|&&s| cfg.checkpoints.contains(&s) || s == cfg.spp)
        .count() as u128;
    let images = kept * cfg.estimators.len() as u128 * size_of::<[f32; 3]>() as u128;
    let dumps = cfg.dump_pixels.len() as u128 * u128::from(cfg.spp) * 8;
    let needed = pixels * (per_pixel + images) + dumps;
    let parameter = format!(
        "film of {width}x{height} pixels with estimators {}",
        cfg.estimators
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(",")
    );
    cfg.memory.check(parameter, needed)?;
    usize::try_from(pixels).map_err(|_| {
        Error::param(
            "film",
            format!("{width}x{height}"),
            "has more pixels than this machine can address",
        )
    })
}

/// Renders `world` into the configured estimators. `on_pass(done_spp)` is called after each pass
/// (for progress reporting).
pub fn render(world: &World, cfg: &FilmConfig, mut on_pass: impl FnMut(u32)) -> Result<FilmOutput> {
    let (width, height) = (world.camera.width(), world.camera.height());
    let stops = check(cfg, width, height)?;
    let pixel_count = check_memory(cfg, width, height, &stops)?;
    let mut pixels = Vec::with_capacity(pixel_count);
    for _ in 0..pixel_count {
        let estimators = cfg
            .estimators
            .iter()
            .map(build_rgb)
            .collect::<Result<Vec<_>>>()?;
        pixels.push(Pixel { estimators });
    }
    let dump_index: Vec<usize> = cfg
        .dump_pixels
        .iter()
        .map(|&(x, y)| y as usize * width as usize + x as usize)
        .collect();
    let mut dumps: Vec<Vec<f64>> = vec![Vec::new(); dump_index.len()];
    let mut sigma = [Welford::new(), Welford::new(), Welford::new()];
    let mut invalid = 0u64;
    let mut images = Vec::new();
    let mut done = 0u32;
    let mut estimate_seconds = 0.0;
    // Only Jung's image mode reads the image-wide σ; its Welford update costs a division per
    // channel and sample, so the film skips it otherwise.
    let image_sigma = cfg
        .estimators
        .iter()
        .any(|s| matches!(s, EstimatorSpec::Jung { .. }));

    for &stop in &stops {
        let reports: Vec<RowReport> = pixels
            .par_chunks_mut(width as usize)
            .enumerate()
            .map(|(y, row)| {
                let span = (done, stop);
                render_row(
                    world,
                    cfg.seed,
                    y as u32,
                    row,
                    span,
                    image_sigma,
                    &dump_index,
                )
            })
            .collect();
        for r in reports {
            invalid += r.invalid;
            for (acc, part) in sigma.iter_mut().zip(&r.sigma) {
                acc.merge(part);
            }
            for (i, stream) in r.dumps {
                dumps[i].extend(stream);
            }
        }
        done = stop;
        if image_sigma {
            let sigma = [sigma[0].sigma(), sigma[1].sigma(), sigma[2].sigma()];
            pixels.par_iter_mut().try_for_each(|p| {
                p.estimators
                    .iter_mut()
                    .try_for_each(|e| e.set_image_sigma(sigma))
            })?;
        }
        if cfg.checkpoints.contains(&stop) || stop == cfg.spp {
            let start = Instant::now();
            for e in 0..cfg.estimators.len() {
                images.push(FilmImage {
                    estimator: e,
                    spp: stop,
                    image: read_image(&pixels, width, height, e)?,
                });
            }
            estimate_seconds += start.elapsed().as_secs_f64();
        }
        on_pass(stop);
    }

    let npix = pixels.len().max(1) as f64;
    let state_bytes = (0..cfg.estimators.len())
        .map(|e| {
            pixels
                .iter()
                .map(|p| p.estimators[e].state_bytes() as f64)
                .sum::<f64>()
                / npix
        })
        .collect();
    images.sort_by_key(|i| (i.estimator, i.spp));
    Ok(FilmOutput {
        images,
        invalid_samples: invalid,
        samples: (pixel_count as u64).saturating_mul(u64::from(cfg.spp)),
        state_bytes,
        dumps: cfg.dump_pixels.iter().copied().zip(dumps).collect(),
        estimate_seconds,
    })
}

/// Traces samples `[s0, s1)` of every pixel of row `y` and pushes them into its estimators
/// (and, with `image_sigma`, into the row's per-channel Welford accumulators).
fn render_row(
    world: &World,
    seed: u64,
    y: u32,
    row: &mut [Pixel],
    (s0, s1): (u32, u32),
    image_sigma: bool,
    dump_index: &[usize],
) -> RowReport {
    let width = row.len();
    let mut report = RowReport::default();
    let mut samples: Vec<[f64; 3]> = Vec::with_capacity((s1 - s0) as usize);
    for (x, pixel) in row.iter_mut().enumerate() {
        let index = y as usize * width + x;
        samples.clear();
        for s in s0..s1 {
            let mut rng = SampleStream::new(seed, index as u64, u64::from(s));
            let l = radiance(world, x as u32, y, &mut rng);
            let v = [f64::from(l.x), f64::from(l.y), f64::from(l.z)];
            if v.iter().all(|c| c.is_finite() && *c >= 0.0) {
                samples.push(v);
            } else {
                report.invalid += 1;
            }
        }
        if image_sigma {
            for v in &samples {
                for (acc, &x) in report.sigma.iter_mut().zip(v) {
                    acc.push(x);
                }
            }
        }
        for e in &mut pixel.estimators {
            e.push_slice(&samples);
        }
        for (i, _) in dump_index.iter().enumerate().filter(|(_, d)| **d == index) {
            report
                .dumps
                .push((i, samples.iter().map(|&v| luminance(v)).collect()));
        }
    }
    report
}

/// Reads estimator `e` of every pixel, with each pixel's 3×3 neighbourhood (Zirr §5.3.1).
fn read_image(pixels: &[Pixel], width: u32, height: u32, e: usize) -> Result<Image> {
    let (w, h) = (width as i64, height as i64);
    let values: Vec<[f32; 3]> = (0..pixels.len())
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i as i64 % w, i as i64 / w);
            let mut block: [Option<&dyn RgbEstimator>; 9] = [None; 9];
            for (k, slot) in block.iter_mut().enumerate() {
                let (nx, ny) = (x + k as i64 % 3 - 1, y + k as i64 / 3 - 1);
                if (0..w).contains(&nx) && (0..h).contains(&ny) {
                    *slot = Some(pixels[(ny * w + nx) as usize].estimators[e].as_ref());
                }
            }
            let centre = &pixels[i].estimators[e];
            let v = if centre.count() == 0 {
                [0.0; 3]
            } else {
                centre.block_estimate(&block)?
            };
            Ok([v[0] as f32, v[1] as f32, v[2] as f32])
        })
        .collect::<Result<_>>()?;
    Image::from_pixels(width as usize, height as usize, values)
}
