//! Trials at scale: seeding, rayon over fixed-size trial chunks, estimates read at every
//! checkpoint within one pass over each trial's samples.
//!
//! A trial's random stream is a pure function of (experiment seed, distribution label, trial
//! index). Trials are grouped into chunks of [`CHUNK_TRIALS`] whatever the thread count; each
//! chunk is accumulated sequentially and chunks are merged in chunk order, so the floating
//! point results are bit-identical on 1 or 64 threads.

use super::checks;
use super::experiment::{Distribution, Experiment};
use super::metrics::{CellAccumulator, Observation};
use crate::error::{Error, Result};
use crate::estimators::{Estimator, Mean, validate_samples};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use std::ops::Range;
use std::time::Instant;

/// Trials per chunk: the unit of work and of deterministic merging.
pub const CHUNK_TRIALS: u64 = 256;

/// Chunks per block: run in parallel, then merged (bounds memory on long runs).
pub const BLOCK_CHUNKS: u64 = 64;

/// How to run an experiment.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Overrides the experiment's trial count.
    pub trials: Option<u64>,
    /// Worker threads (default: rayon's, one per core).
    pub threads: Option<usize>,
    /// Show a progress bar on stderr (drawn only when stderr is a terminal).
    pub progress: bool,
}

/// Results for one distribution.
#[derive(Debug, Clone)]
pub struct DistResult {
    /// Distribution label.
    pub label: String,
    /// Readable description of the law.
    pub law: String,
    /// Exact mean.
    pub mu: f64,
    /// Exact variance (`None`: infinite).
    pub variance: Option<f64>,
    /// Accumulators, index `estimator * checkpoints + checkpoint`.
    pub cells: Vec<CellAccumulator>,
    /// Nanoseconds each estimator spent pushing and estimating, summed over threads.
    pub estimator_nanos: Vec<u64>,
    /// Nanoseconds spent drawing samples, summed over threads.
    pub generate_nanos: u64,
    /// Samples drawn.
    pub samples: u64,
    /// Per estimator, the largest per-pixel state seen at the end of a trial, in bytes.
    pub state_bytes_max: Vec<usize>,
    /// Per estimator, the sum over trials of the end-of-trial state size (for the mean).
    pub state_bytes_sum: Vec<u64>,
}

impl DistResult {
    /// Nanoseconds per sample that estimator `e` cost (push and estimate, one thread).
    pub fn ns_per_sample(&self, e: usize) -> f64 {
        self.estimator_nanos[e] as f64 / self.samples as f64
    }

    /// Nanoseconds per sample drawing cost (one thread).
    pub fn generate_ns_per_sample(&self) -> f64 {
        self.generate_nanos as f64 / self.samples as f64
    }
}

/// Results of a run.
#[derive(Debug, Clone)]
pub struct RunOutput {
    /// Trials per distribution.
    pub trials: u64,
    /// Worker threads used.
    pub threads: usize,
    /// Wall-clock seconds of the whole run.
    pub wall_s: f64,
    /// One entry per distribution, in experiment order.
    pub dists: Vec<DistResult>,
}

impl RunOutput {
    /// Samples drawn per wall-clock second, every estimator fed each one.
    pub fn samples_per_s(&self) -> f64 {
        self.dists.iter().map(|d| d.samples).sum::<u64>() as f64 / self.wall_s
    }
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The random stream of one trial: depends only on (seed, distribution label, trial index).
pub fn trial_rng(seed: u64, label: &str, trial: u64) -> Xoshiro256PlusPlus {
    let stream = splitmix64(splitmix64(seed) ^ fnv1a(label));
    Xoshiro256PlusPlus::seed_from_u64(splitmix64(stream ^ splitmix64(trial)))
}

/// Per-chunk results, merged in chunk order.
struct ChunkResult {
    cells: Vec<CellAccumulator>,
    estimator_nanos: Vec<u64>,
    generate_nanos: u64,
    state_bytes_max: Vec<usize>,
    state_bytes_sum: Vec<u64>,
}

impl ChunkResult {
    fn empty(template: &[CellAccumulator], estimators: usize) -> Self {
        ChunkResult {
            cells: template.to_vec(),
            estimator_nanos: vec![0; estimators],
            generate_nanos: 0,
            state_bytes_max: vec![0; estimators],
            state_bytes_sum: vec![0; estimators],
        }
    }

    fn merge(&mut self, r: &ChunkResult) {
        for (a, b) in self.cells.iter_mut().zip(&r.cells) {
            a.merge(b);
        }
        for e in 0..self.estimator_nanos.len() {
            self.estimator_nanos[e] += r.estimator_nanos[e];
            self.state_bytes_max[e] = self.state_bytes_max[e].max(r.state_bytes_max[e]);
            self.state_bytes_sum[e] += r.state_bytes_sum[e];
        }
        self.generate_nanos += r.generate_nanos;
    }
}

/// Runs every distribution of the experiment.
pub fn run(exp: &Experiment, opts: &RunOptions) -> Result<RunOutput> {
    let trials = opts.trials.unwrap_or(exp.file.trials);
    if trials < 4 {
        return Err(Error::param("trials", trials, "must be at least 4 (spec §7)"));
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads.unwrap_or(0))
        .build()
        .map_err(|e| Error::param("threads", format!("{:?}", opts.threads), e.to_string()))?;
    let bar = if opts.progress {
        let bar = ProgressBar::new(trials * exp.distributions.len() as u64);
        if let Ok(style) = ProgressStyle::with_template(
            "{spinner} {msg:<18} [{bar:30}] {pos}/{len} trials ({eta} left)",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar
    } else {
        ProgressBar::hidden()
    };
    let start = Instant::now();
    let dists = pool.install(|| {
        exp.distributions
            .iter()
            .map(|d| {
                bar.set_message(d.label.clone());
                run_distribution(exp, d, trials, &bar)
            })
            .collect::<Result<Vec<_>>>()
    })?;
    bar.finish_and_clear();
    Ok(RunOutput {
        trials,
        threads: pool.current_num_threads(),
        wall_s: start.elapsed().as_secs_f64(),
        dists,
    })
}

/// Empty accumulators for one distribution, with each cell's deviation threshold set.
fn empty_cells(exp: &Experiment, d: &Distribution) -> Vec<CellAccumulator> {
    let mut cells = Vec::new();
    for spec in &exp.estimators {
        for &n in &exp.file.checkpoints {
            let threshold = checks::deviation_threshold(&exp.file.checks, spec, &d.dist, n);
            cells.push(CellAccumulator::with_deviation_threshold(threshold));
        }
    }
    cells
}

fn run_distribution(
    exp: &Experiment,
    d: &Distribution,
    trials: u64,
    bar: &ProgressBar,
) -> Result<DistResult> {
    let template = empty_cells(exp, d);
    let mut total = ChunkResult::empty(&template, exp.estimators.len());
    let chunks = trials.div_ceil(CHUNK_TRIALS);
    let mut wave_start = 0;
    while wave_start < chunks {
        let wave_end = (wave_start + BLOCK_CHUNKS).min(chunks);
        let results = (wave_start..wave_end)
            .into_par_iter()
            .map(|c| {
                let range = c * CHUNK_TRIALS..((c + 1) * CHUNK_TRIALS).min(trials);
                let r = run_chunk(exp, d, range.clone(), &template);
                bar.inc(range.end - range.start);
                r
            })
            .collect::<Result<Vec<_>>>()?;
        // A block is folded chunk by chunk, then the total block by block: a fixed merge tree,
        // so a shard that owns whole blocks can be merged into the same bits.
        let mut block = ChunkResult::empty(&template, exp.estimators.len());
        for r in &results {
            block.merge(r);
        }
        total.merge(&block);
        wave_start = wave_end;
    }
    Ok(DistResult {
        label: d.label.clone(),
        law: d.dist.to_string(),
        mu: d.dist.mean(),
        variance: d.dist.variance(),
        cells: total.cells,
        estimator_nanos: total.estimator_nanos,
        generate_nanos: total.generate_nanos,
        samples: trials * exp.max_n() as u64,
        state_bytes_max: total.state_bytes_max,
        state_bytes_sum: total.state_bytes_sum,
    })
}

fn run_chunk(
    exp: &Experiment,
    d: &Distribution,
    trials: Range<u64>,
    template: &[CellAccumulator],
) -> Result<ChunkResult> {
    let checkpoints = &exp.file.checkpoints;
    let (mu, tau) = (d.dist.mean(), exp.file.tau);
    let mut estimators: Vec<Box<dyn Estimator>> = exp
        .estimators
        .iter()
        .map(|s| s.build())
        .collect::<Result<_>>()?;
    let mut out = ChunkResult::empty(template, estimators.len());
    let mut samples = vec![0.0; exp.max_n()];
    let mut mean_estimates = vec![0.0; checkpoints.len()];
    let mut outlier = vec![false; checkpoints.len()];
    let mut estimates = vec![0.0; checkpoints.len()];
    for trial in trials {
        let mut rng = trial_rng(exp.file.seed, &d.label, trial);
        let t0 = Instant::now();
        d.dist.fill(&mut rng, &mut samples);
        out.generate_nanos += t0.elapsed().as_nanos() as u64;
        validate_samples(&samples, 0)?;

        let mut mean = Mean::new();
        let (mut from, mut max) = (0, 0.0f64);
        for (i, &n) in checkpoints.iter().enumerate() {
            let segment = &samples[from..n];
            mean.push_slice(segment);
            max = segment.iter().fold(max, |m, &x| m.max(x));
            mean_estimates[i] = mean.estimate()?;
            outlier[i] = max >= n as f64 * mu;
            from = n;
        }

        for (e, est) in estimators.iter_mut().enumerate() {
            est.reset();
            let t0 = Instant::now();
            let mut from = 0;
            for (i, &n) in checkpoints.iter().enumerate() {
                est.push_slice(&samples[from..n]);
                estimates[i] = est.estimate()?;
                from = n;
            }
            out.estimator_nanos[e] += t0.elapsed().as_nanos() as u64;
            let bytes = est.state_bytes();
            out.state_bytes_max[e] = out.state_bytes_max[e].max(bytes);
            out.state_bytes_sum[e] += bytes as u64;
            for i in 0..checkpoints.len() {
                let o = Observation {
                    estimate: estimates[i],
                    mean_estimate: mean_estimates[i],
                    outlier: outlier[i],
                };
                out.cells[e * checkpoints.len() + i].push(o, mu, tau);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn streams_differ_by_trial_and_label_and_repeat_exactly() {
        let draw = |label: &str, trial| trial_rng(42, label, trial).next_u64();
        assert_eq!(draw("a", 0), draw("a", 0));
        assert_ne!(draw("a", 0), draw("a", 1));
        assert_ne!(draw("a", 0), draw("b", 0));
        assert_ne!(trial_rng(1, "a", 0).next_u64(), trial_rng(2, "a", 0).next_u64());
    }
}
