//! What each estimator costs, next to what tracing costs, measured on the scene's own samples.
//!
//! A render's time is tracing plus, per estimator, pushing every sample and reading every
//! pixel's estimate once per written image. Timing each estimator inside a render would put a
//! clock read around every pixel's push; instead this module traces the render's own samples
//! (same seed, same streams) of a regular grid of pixels once, on one thread, timing the
//! tracing; then, for each estimator, builds one per pixel, pushes the stored samples in the
//! film's pass schedule (blocks ending at powers of two) and reads every estimate once, timing
//! both. Clocks are the thread's CPU time (Linux; elsewhere the wall clock), so other work on a
//! shared machine does not count; each estimator is timed `repeats` times, interleaved with the
//! others, and the fastest is kept. Zirr reads its 3x3 block with the pixel itself standing in
//! for its neighbours (the values are meaningless, the work is the same).
//!
//! Jung's image mode also costs the film's per-sample update of the image σ, which is timed
//! here and added to Jung's push cost.
//!
//! The fraction of a render's time an estimator takes is then `push / (trace + push)` for a
//! render with that estimator alone, and `push / (trace + Σ push)` inside the full bank.

use crate::error::Result;
use crate::estimators::{EstimatorSpec, RgbEstimator, Welford, build_rgb};
use crate::render::integrator::{pushable, radiance};
use crate::render::sampler::SampleStream;
use crate::render::world::World;

/// CPU seconds of the calling thread (the wall clock where the platform has no such clock).
pub fn thread_cpu_seconds() -> f64 {
    #[cfg(target_os = "linux")]
    {
        let t = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
        t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
    }
    #[cfg(not(target_os = "linux"))]
    {
        wall_seconds()
    }
}

/// CPU seconds of the whole process, all threads (the wall clock elsewhere than Linux).
pub fn process_cpu_seconds() -> f64 {
    #[cfg(target_os = "linux")]
    {
        let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
        t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
    }
    #[cfg(not(target_os = "linux"))]
    {
        wall_seconds()
    }
}

#[cfg(not(target_os = "linux"))]
fn wall_seconds() -> f64 {
    use std::sync::OnceLock;
    static START: OnceLock<std::time::Instant> = OnceLock::new();
    START
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_secs_f64()
}

/// One estimator's measured cost.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorCost {
    /// CPU nanoseconds per RGB sample pushed (for Jung, with the film's image-σ update).
    pub push_ns_per_sample: f64,
    /// CPU nanoseconds to read one pixel's estimate.
    pub read_ns_per_pixel: f64,
}

/// The cost of tracing and of every estimator on one scene.
#[derive(Debug, Clone, PartialEq)]
pub struct CostReport {
    /// Pixels traced.
    pub pixels: usize,
    /// Samples per pixel traced.
    pub spp: u32,
    /// CPU nanoseconds per camera sample traced (one thread).
    pub trace_ns_per_sample: f64,
    /// Per estimator, in the order given.
    pub estimators: Vec<EstimatorCost>,
}

/// About `count` pixels on a regular grid over a `width x height` image, at cell centres,
/// row-major.
pub fn grid_pixels(width: u32, height: u32, count: u32) -> Vec<(u32, u32)> {
    let (w, h) = (f64::from(width), f64::from(height));
    let gx = ((f64::from(count) * w / h).sqrt().round() as u32).clamp(1, width);
    let gy = count.div_ceil(gx).clamp(1, height);
    let mut out = Vec::with_capacity((gx * gy) as usize);
    for j in 0..gy {
        for i in 0..gx {
            let x = ((f64::from(i) + 0.5) * w / f64::from(gx)) as u32;
            let y = ((f64::from(j) + 0.5) * h / f64::from(gy)) as u32;
            out.push((x.min(width - 1), y.min(height - 1)));
        }
    }
    out
}

/// Measures tracing and every estimator of `specs` on `spp` samples of `count` grid pixels
/// of `world`, on the calling thread (see the module docs).
///
/// # Errors
///
/// An estimator spec that does not build, or an estimate that fails.
pub fn measure(
    world: &World,
    seed: u64,
    specs: &[EstimatorSpec],
    count: u32,
    spp: u32,
    repeats: u32,
) -> Result<CostReport> {
    let (width, height) = (world.camera.width(), world.camera.height());
    let pixels = grid_pixels(width, height, count);
    let start = thread_cpu_seconds();
    let streams: Vec<Vec<[f64; 3]>> = pixels
        .iter()
        .map(|&(x, y)| {
            let index = u64::from(y) * u64::from(width) + u64::from(x);
            (0..spp)
                .filter_map(|s| {
                    let mut rng = SampleStream::new(seed, index, u64::from(s));
                    pushable(radiance(world, x, y, &mut rng))
                })
                .collect()
        })
        .collect();
    let trace_s = thread_cpu_seconds() - start;
    let samples: usize = streams.iter().map(Vec::len).sum();
    let traced = pixels.len() as f64 * f64::from(spp);
    // The image σ Jung's image mode reads after each pass, per channel, over the samples so far.
    // The film accumulates it only when a Jung estimator runs, so its cost is Jung's.
    let stops = super::experiment::checkpoints(spp, &[]);
    let sigma_start = thread_cpu_seconds();
    let mut sigmas = Vec::with_capacity(stops.len());
    let mut acc = [Welford::new(), Welford::new(), Welford::new()];
    let mut from = 0usize;
    for &stop in &stops {
        for stream in &streams {
            let end = (stop as usize).min(stream.len());
            for v in &stream[from.min(end)..end] {
                for (a, &c) in acc.iter_mut().zip(v) {
                    a.push(c);
                }
            }
        }
        from = stop as usize;
        sigmas.push([acc[0].sigma(), acc[1].sigma(), acc[2].sigma()]);
    }
    let sigma_s = thread_cpu_seconds() - sigma_start;

    let mut best = vec![(f64::INFINITY, f64::INFINITY); specs.len()];
    for _ in 0..repeats {
        for (spec, best) in specs.iter().zip(&mut best) {
            let mut bank: Vec<Box<dyn RgbEstimator>> = streams
                .iter()
                .map(|_| build_rgb(spec))
                .collect::<Result<_>>()?;
            let t0 = thread_cpu_seconds();
            let mut from = 0usize;
            for (&stop, &sigma) in stops.iter().zip(&sigmas) {
                for (e, stream) in bank.iter_mut().zip(&streams) {
                    let end = (stop as usize).min(stream.len());
                    e.push_slice(&stream[from.min(end)..end]);
                }
                for e in &mut bank {
                    e.set_image_sigma(sigma)?;
                }
                from = stop as usize;
            }
            let t1 = thread_cpu_seconds();
            let mut sink = 0.0;
            for e in &bank {
                if e.count() > 0 {
                    let me: &dyn RgbEstimator = e.as_ref();
                    sink += e.block_estimate(&[Some(me); 9])?[1];
                }
            }
            let t2 = thread_cpu_seconds();
            std::hint::black_box(sink);
            best.0 = best.0.min(t1 - t0);
            best.1 = best.1.min(t2 - t1);
        }
    }
    let per_sample = samples.max(1) as f64;
    let per_pixel = pixels.len().max(1) as f64;
    Ok(CostReport {
        pixels: pixels.len(),
        spp,
        trace_ns_per_sample: trace_s * 1e9 / traced.max(1.0),
        estimators: best
            .into_iter()
            .zip(specs)
            .map(|((push, read), spec)| EstimatorCost {
                push_ns_per_sample: (push
                    + if matches!(spec, EstimatorSpec::Jung(_)) {
                        sigma_s
                    } else {
                        0.0
                    })
                    * 1e9
                    / per_sample,
                read_ns_per_pixel: read * 1e9 / per_pixel,
            })
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::grid_pixels;

    #[test]
    fn grid_covers_the_image_at_cell_centres() {
        assert_eq!(grid_pixels(4, 4, 4), vec![(1, 1), (3, 1), (1, 3), (3, 3)]);
        let g = grid_pixels(320, 180, 256);
        assert!(g.len() >= 256 && g.len() < 300, "{}", g.len());
        assert!(g.iter().all(|&(x, y)| x < 320 && y < 180));
        assert_eq!(grid_pixels(11, 11, 10_000).len(), 121);
    }
}
