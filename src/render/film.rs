//! The film: per pixel, a bank of RGB estimators fed every camera sample of that pixel
//! (pbrt-v4's `Film::AddSample` is where pixel estimators live; here the whole stream is kept
//! by the estimators instead of a weighted sum).
//!
//! The render proceeds in passes between checkpoints. In each pass, rayon hands out rows; a
//! pixel draws its samples `[s0, s1)` in order, each from its own stream
//! ([`SampleStream`](super::sampler::SampleStream)), so the image does not depend on the
//! number of threads or on the checkpoints. After a pass, the image-wide per-channel sample σ (Jung's image mode, docs/estimators.md §4)
//! is merged in row order and handed to every pixel before the estimates are read.
//! Non-finite or negative radiance samples are counted and never pushed.
//!
//! With NFOR buffers on ([`render_with_nfor`]), every pixel also keeps two halves (A: even
//! sample indices, B: odd), each with its own estimator bank and the Welford moments of colour
//! and features ([`super::nfor_buffers`] describes the outputs). Features come from the same
//! path as the colour ([`radiance_features`]), so the full-render images do not change.

use super::integrator::{Features, pushable, radiance, radiance_features};
use super::nfor_buffers::{EstimatorHalves, HalfBuffer, NforBuffers};
use super::sampler::PixelStreams;
use super::world::World;
use crate::error::{Error, Result};
use crate::estimators::{EstimatorSpec, RgbBank, RgbEstimator, Welford, luminance};
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
    /// The NFOR buffers at the final spp, when asked for.
    pub nfor: Option<NforBuffers>,
}

/// The name of an estimator's image files (`gmonb:M=21,threshold=0.3` ->
/// `gmonb_M=21_threshold=0.3`).
pub fn file_stem(spec: &EstimatorSpec) -> String {
    spec.to_string().replace([':', ','], "_")
}

/// Per-pixel state: a bank of one RGB estimator per configured spec.
struct Pixel {
    bank: RgbBank,
}

/// Welford moments of `K` channels that see the same samples (one count for all).
#[derive(Debug, Clone, Copy)]
struct Moments<const K: usize> {
    count: u64,
    mean: [f64; K],
    m2: [f64; K],
}

impl<const K: usize> Moments<K> {
    const NEW: Self = Moments {
        count: 0,
        mean: [0.0; K],
        m2: [0.0; K],
    };

    #[inline]
    fn push(&mut self, x: &[f64; K]) {
        self.count += 1;
        let n = self.count as f64;
        for ((&x, mean), m2) in x.iter().zip(&mut self.mean).zip(&mut self.m2) {
            let d = x - *mean;
            *mean += d / n;
            *m2 += d * (x - *mean);
        }
    }

    /// Channel `k`'s mean and the variance of that mean (`s² / n`; 0 below two samples).
    fn mean_and_variance(&self, k: usize) -> (f64, f64) {
        let n = self.count as f64;
        let var = if self.count >= 2 {
            self.m2[k] / (n - 1.0) / n
        } else {
            0.0
        };
        (self.mean[k], var)
    }
}

/// Feature channels per sample: normal (3), albedo (3), depth, visibility.
const FEATURES: usize = 8;

/// The feature values of one sample as the moments take them.
#[inline]
fn feature_vector(f: &Features) -> [f64; FEATURES] {
    [
        f64::from(f.normal.x),
        f64::from(f.normal.y),
        f64::from(f.normal.z),
        f64::from(f.albedo.x),
        f64::from(f.albedo.y),
        f64::from(f.albedo.z),
        f64::from(f.depth),
        f64::from(f.visibility),
    ]
}

/// One half of a pixel's samples for NFOR: its estimator bank, the moments of its valid colour
/// samples and of the features of all its samples (features are finite wherever the path is;
/// a sample whose features are not is left out of them).
struct Half {
    bank: RgbBank,
    color: Moments<3>,
    features: Moments<FEATURES>,
}

/// A pixel's two halves: A (even sample indices) and B (odd).
struct NforPixel {
    halves: [Half; 2],
}

/// What one row of a pass reports back.
#[derive(Default)]
struct RowReport {
    invalid: u64,
    sigma: [Welford; 3],
    /// Per half, the image-wide σ of that half's samples (only with NFOR halves).
    half_sigma: [[Welford; 3]; 2],
    dumps: Vec<(usize, Vec<f64>)>,
}

/// Checks a film configuration against the camera's image.
fn check(cfg: &FilmConfig, width: u32, height: u32, nfor: bool) -> Result<Vec<u32>> {
    if cfg.spp == 0 {
        return Err(Error::param("spp", 0, "must be at least 1"));
    }
    if nfor && cfg.spp < MIN_NFOR_SPP {
        return Err(Error::param(
            "spp",
            cfg.spp,
            format!(
                "NFOR buffers need at least {MIN_NFOR_SPP} samples per pixel (two per half, \
                 so that each half has a variance)"
            ),
        ));
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

/// The fewest samples per pixel NFOR buffers accept.
pub const MIN_NFOR_SPP: u32 = 4;

/// Per-pixel bytes of the NFOR halves besides the full bank: two more banks of the same
/// estimators, the moments, and the final images (four per buffer, two per estimator).
pub fn nfor_bytes_per_pixel(bank_bytes: usize, estimators: usize) -> usize {
    let images = (4 * super::nfor_buffers::BUFFERS.len() + 2 * estimators) * size_of::<[f32; 3]>();
    size_of::<NforPixel>() + 2 * bank_bytes + images
}

/// Refuses a render whose pixel banks, kept images and dumped streams would not fit in the
/// memory limit, before anything is allocated. Each estimator is built once to read its real
/// per-pixel state (its parameters are capped, so this is small).
fn check_memory(
    cfg: &FilmConfig,
    width: u32,
    height: u32,
    stops: &[u32],
    nfor: bool,
) -> Result<usize> {
    let pixels = u128::from(width) * u128::from(height);
    let mut per_pixel = size_of::<Pixel>() as u128;
    let bank = RgbBank::new(&cfg.estimators)?.state_bytes();
    per_pixel += bank as u128;
    if nfor {
        per_pixel += nfor_bytes_per_pixel(bank, cfg.estimators.len()) as u128;
    }
    let kept = stops
        .iter()
        .filter(|&&s| cfg.checkpoints.contains(&s) || s == cfg.spp)
        .count() as u128;
    let images = kept * cfg.estimators.len() as u128 * size_of::<[f32; 3]>() as u128;
    let dumps = cfg.dump_pixels.len() as u128 * u128::from(cfg.spp) * 8;
    let needed = pixels * (per_pixel + images) + dumps;
    let parameter = format!(
        "film of {width}x{height} pixels with estimators {}{}",
        cfg.estimators
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(","),
        if nfor { " and NFOR buffers" } else { "" }
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
pub fn render(world: &World, cfg: &FilmConfig, on_pass: impl FnMut(u32)) -> Result<FilmOutput> {
    render_with_nfor(world, cfg, false, on_pass)
}

/// [`render`], and with `nfor` also the NFOR buffers at the final spp
/// ([`FilmOutput::nfor`]); everything else is bit-identical to [`render`]'s.
pub fn render_with_nfor(
    world: &World,
    cfg: &FilmConfig,
    nfor: bool,
    mut on_pass: impl FnMut(u32),
) -> Result<FilmOutput> {
    let (width, height) = (world.camera.width(), world.camera.height());
    let stops = check(cfg, width, height, nfor)?;
    let pixel_count = check_memory(cfg, width, height, &stops, nfor)?;
    let first = RgbBank::new(&cfg.estimators)?;
    let bank = || first.empty_like();
    let mut pixels = Vec::with_capacity(pixel_count);
    for _ in 0..pixel_count {
        pixels.push(Pixel { bank: bank()? });
    }
    let half = || -> Result<Half> {
        Ok(Half {
            bank: bank()?,
            color: Moments::NEW,
            features: Moments::NEW,
        })
    };
    let mut nfor_pixels = Vec::with_capacity(if nfor { pixel_count } else { 0 });
    if nfor {
        for _ in 0..pixel_count {
            nfor_pixels.push(NforPixel {
                halves: [half()?, half()?],
            });
        }
    }
    let dump_index: Vec<usize> = cfg
        .dump_pixels
        .iter()
        .map(|&(x, y)| y as usize * width as usize + x as usize)
        .collect();
    let mut dumps: Vec<Vec<f64>> = vec![Vec::new(); dump_index.len()];
    let mut sigma = [Welford::new(), Welford::new(), Welford::new()];
    let mut half_sigma = [[Welford::new(); 3]; 2];
    let mut invalid = 0u64;
    let mut images = Vec::new();
    let mut done = 0u32;
    let mut estimate_seconds = 0.0;
    // Only Jung's image mode reads the image-wide σ; its Welford update costs a division per
    // channel and sample, so the film skips it otherwise.
    let image_sigma = cfg
        .estimators
        .iter()
        .any(|s| matches!(s, EstimatorSpec::Jung(_)));

    for &stop in &stops {
        let mut nfor_rows: Vec<Option<&mut [NforPixel]>> = if nfor {
            nfor_pixels.chunks_mut(width as usize).map(Some).collect()
        } else {
            (0..height).map(|_| None).collect()
        };
        let reports: Vec<RowReport> = pixels
            .par_chunks_mut(width as usize)
            .zip(nfor_rows.par_iter_mut())
            .enumerate()
            .map(|(y, (row, nfor_row))| {
                let span = (done, stop);
                render_row(
                    world,
                    cfg.seed,
                    y as u32,
                    row,
                    nfor_row.as_deref_mut(),
                    span,
                    image_sigma,
                    &dump_index,
                )
            })
            .collect();
        drop(nfor_rows);
        for r in reports {
            invalid += r.invalid;
            for (acc, part) in sigma.iter_mut().zip(&r.sigma) {
                acc.merge(part);
            }
            for (accs, parts) in half_sigma.iter_mut().zip(&r.half_sigma) {
                for (acc, part) in accs.iter_mut().zip(parts) {
                    acc.merge(part);
                }
            }
            for (i, stream) in r.dumps {
                dumps[i].extend(stream);
            }
        }
        done = stop;
        if image_sigma {
            let sigma = [sigma[0].sigma(), sigma[1].sigma(), sigma[2].sigma()];
            pixels
                .par_iter_mut()
                .try_for_each(|p| p.bank.set_image_sigma(sigma))?;
            // Each half reads its own samples' spread, so that nothing couples the halves.
            let half_sigma = half_sigma.map(|s| [s[0].sigma(), s[1].sigma(), s[2].sigma()]);
            nfor_pixels.par_iter_mut().try_for_each(|p| {
                p.halves
                    .iter_mut()
                    .zip(half_sigma)
                    .try_for_each(|(h, s)| h.bank.set_image_sigma(s))
            })?;
        }
        if cfg.checkpoints.contains(&stop) || stop == cfg.spp {
            let start = Instant::now();
            for e in 0..cfg.estimators.len() {
                images.push(FilmImage {
                    estimator: e,
                    spp: stop,
                    image: read_image(pixels.len(), width, height, |i| {
                        pixels[i].bank.estimators()[e].as_ref()
                    })?,
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
                .map(|p| p.bank.estimators()[e].state_bytes() as f64)
                .sum::<f64>()
                / npix
        })
        .collect();
    images.sort_by_key(|i| (i.estimator, i.spp));
    let nfor = if nfor {
        Some(nfor_buffers(cfg, &nfor_pixels, width, height)?)
    } else {
        None
    };
    Ok(FilmOutput {
        images,
        invalid_samples: invalid,
        samples: (pixel_count as u64).saturating_mul(u64::from(cfg.spp)),
        state_bytes,
        dumps: cfg.dump_pixels.iter().copied().zip(dumps).collect(),
        estimate_seconds,
        nfor,
    })
}

/// Reads the NFOR halves of every pixel into images.
fn nfor_buffers(
    cfg: &FilmConfig,
    pixels: &[NforPixel],
    width: u32,
    height: u32,
) -> Result<NforBuffers> {
    let (w, h) = (width as usize, height as usize);
    // Mean and variance images of channels `channels` of a half's moments; one channel is
    // repeated into grey.
    let image = |half: usize, features: bool, channels: &[usize], variance: bool| {
        let values = pixels
            .iter()
            .map(|p| {
                let half = &p.halves[half];
                let at = |k: usize| {
                    let (m, v) = if features {
                        half.features.mean_and_variance(k)
                    } else {
                        half.color.mean_and_variance(k)
                    };
                    (if variance { v } else { m }) as f32
                };
                match channels {
                    [k] => [at(*k); 3],
                    _ => [at(channels[0]), at(channels[1]), at(channels[2])],
                }
            })
            .collect();
        Image::from_pixels(w, h, values)
    };
    let buffer = |features: bool, channels: &[usize]| -> Result<HalfBuffer> {
        Ok(HalfBuffer {
            mean: [
                image(0, features, channels, false)?,
                image(1, features, channels, false)?,
            ],
            var: [
                image(0, features, channels, true)?,
                image(1, features, channels, true)?,
            ],
        })
    };
    let mut estimators = Vec::with_capacity(cfg.estimators.len());
    for (e, spec) in cfg.estimators.iter().enumerate() {
        let half = |k: usize| {
            read_image(pixels.len(), width, height, |i| {
                pixels[i].halves[k].bank.estimators()[e].as_ref()
            })
        };
        estimators.push(EstimatorHalves {
            spec: spec.to_string(),
            stem: file_stem(spec),
            image: [half(0)?, half(1)?],
        });
    }
    Ok(NforBuffers {
        spp: cfg.spp,
        seed: cfg.seed,
        color: buffer(false, &[0, 1, 2])?,
        normal: buffer(true, &[0, 1, 2])?,
        albedo: buffer(true, &[3, 4, 5])?,
        depth: buffer(true, &[6])?,
        visibility: buffer(true, &[7])?,
        estimators,
    })
}

/// Traces samples `[s0, s1)` of every pixel of row `y` and pushes them into its estimators
/// (and, with `image_sigma`, into the row's per-channel Welford accumulators); with `nfor_row`,
/// also into the pixel's halves.
#[allow(clippy::too_many_arguments)]
fn render_row(
    world: &World,
    seed: u64,
    y: u32,
    row: &mut [Pixel],
    mut nfor_row: Option<&mut [NforPixel]>,
    (s0, s1): (u32, u32),
    image_sigma: bool,
    dump_index: &[usize],
) -> RowReport {
    let width = row.len();
    let mut report = RowReport::default();
    let mut samples: Vec<[f64; 3]> = Vec::with_capacity((s1 - s0) as usize);
    let mut half_samples: [Vec<[f64; 3]>; 2] = [Vec::new(), Vec::new()];
    for (x, pixel) in row.iter_mut().enumerate() {
        let index = y as usize * width + x;
        samples.clear();
        let mut halves = nfor_row.as_deref_mut().map(|r| &mut r[x].halves);
        let pixel_streams = PixelStreams::new(seed, index as u64);
        for s in s0..s1 {
            let mut rng = pixel_streams.sample(u64::from(s));
            let (l, features) = if halves.is_some() {
                let (l, f) = radiance_features(world, x as u32, y, &mut rng);
                (l, Some(f))
            } else {
                (radiance(world, x as u32, y, &mut rng), None)
            };
            let v = pushable(l);
            match v {
                Some(v) => samples.push(v),
                None => report.invalid += 1,
            }
            if let (Some(halves), Some(f)) = (halves.as_deref_mut(), features) {
                let k = (s % 2) as usize;
                let half = &mut halves[k];
                if let Some(v) = v {
                    half.color.push(&v);
                    half_samples[k].push(v);
                }
                let fv = feature_vector(&f);
                if fv.iter().all(|c| c.is_finite()) {
                    half.features.push(&fv);
                }
            }
        }
        if let Some(halves) = halves {
            for (k, (half, batch)) in halves.iter_mut().zip(&mut half_samples).enumerate() {
                if image_sigma {
                    for v in batch.iter() {
                        for (acc, &x) in report.half_sigma[k].iter_mut().zip(v) {
                            acc.push(x);
                        }
                    }
                }
                half.bank.push_slice(batch);
                batch.clear();
            }
        }
        if image_sigma {
            for v in &samples {
                for (acc, &x) in report.sigma.iter_mut().zip(v) {
                    acc.push(x);
                }
            }
        }
        pixel.bank.push_slice(&samples);
        for (i, _) in dump_index.iter().enumerate().filter(|(_, d)| **d == index) {
            report
                .dumps
                .push((i, samples.iter().map(|&v| luminance(v)).collect()));
        }
    }
    report
}

/// Reads one estimator of every pixel (`estimator(i)` is pixel `i`'s), with each pixel's 3×3
/// neighbourhood (Zirr §5.3.1).
fn read_image<'a, F>(count: usize, width: u32, height: u32, estimator: F) -> Result<Image>
where
    F: Sync + Fn(usize) -> &'a dyn RgbEstimator,
{
    let (w, h) = (width as i64, height as i64);
    let values: Vec<[f32; 3]> = (0..count)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i as i64 % w, i as i64 / w);
            let mut block: [Option<&dyn RgbEstimator>; 9] = [None; 9];
            for (k, slot) in block.iter_mut().enumerate() {
                let (nx, ny) = (x + k as i64 % 3 - 1, y + k as i64 / 3 - 1);
                if (0..w).contains(&nx) && (0..h).contains(&ny) {
                    *slot = Some(estimator((ny * w + nx) as usize));
                }
            }
            let centre = estimator(i);
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
