//! Trials at scale: seeding, rayon over fixed-size trial chunks, estimates read at every
//! checkpoint within one pass over each trial's samples.
//!
//! A trial's random stream is a pure function of (experiment seed, distribution label, trial
//! index). Trials are grouped into chunks of [`CHUNK_TRIALS`] and chunks into blocks of
//! [`BLOCK_CHUNKS`] whatever the thread count; each chunk is accumulated sequentially, a block
//! folds its chunks in order and the run folds its blocks in order. That fixed merge tree
//! makes the floating point results bit-identical on 1 or 64 threads, and lets a run be split
//! into shards that own whole blocks and merge into the same bits ([`run_shard`], [`fold`]).

use super::claims;
use super::experiment::{Distribution, Experiment};
use super::law::MeanLaw;
use super::metrics::{CellAccumulator, Observation};
use super::unseen::{self, TailEffects};
use crate::error::{Error, Result};
use crate::estimators::{Estimator, EstimatorSpec, Mean, MeanSpec, validate_samples};
use crate::limits::{self, MemoryLimit};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::time::Instant;

/// Trials per chunk: the unit of parallel work.
pub const CHUNK_TRIALS: u64 = 256;

/// Chunks per block. A block is folded chunk by chunk, the run block by block: a fixed merge
/// tree, so shards owning whole blocks merge into the same bits as a single run.
pub const BLOCK_CHUNKS: u64 = 8;

/// Trials per block.
pub const BLOCK_TRIALS: u64 = CHUNK_TRIALS * BLOCK_CHUNKS;

/// Blocks run in parallel before they are folded (bounds memory on long runs).
const WAVE_BLOCKS: u64 = 16;

/// How to run an experiment.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Overrides the experiment's trial count.
    pub trials: Option<u64>,
    /// Worker threads (default: rayon's, one per core).
    pub threads: Option<usize>,
    /// Show a progress bar on stderr (drawn only when stderr is a terminal).
    pub progress: bool,
    /// Builds each estimator from its spec; `None` is [`EstimatorSpec::build`]. Tests use it to
    /// run a deliberately broken variant through the real harness.
    pub build: Option<BuildFn>,
    /// The most memory the run may plan to hold.
    pub memory: MemoryLimit,
}

/// How the runner turns a spec into an estimator.
pub type BuildFn = fn(&EstimatorSpec) -> Result<Box<dyn Estimator>>;

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
    /// Per checkpoint, what the law says about the plain mean's cell (`None` when the
    /// experiment does not run the mean).
    pub mean_laws: Vec<Option<MeanLaw>>,
    /// Per cell (estimator-major, like `cells`), what trials the run expects too few of to see
    /// would do to it ([`unseen`]).
    pub tail_effects: Vec<TailEffects>,
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

/// Mergeable statistics of a chunk or a block of trials of one distribution: everything a
/// report needs, no per-trial list.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BlockStats {
    cells: Vec<CellAccumulator>,
    estimator_nanos: Vec<u64>,
    generate_nanos: u64,
    state_bytes_max: Vec<usize>,
    state_bytes_sum: Vec<u64>,
}

impl BlockStats {
    fn empty(template: &[CellAccumulator], estimators: usize) -> Self {
        BlockStats {
            cells: template.to_vec(),
            estimator_nanos: vec![0; estimators],
            generate_nanos: 0,
            state_bytes_max: vec![0; estimators],
            state_bytes_sum: vec![0; estimators],
        }
    }

    fn merge(&mut self, r: &BlockStats) {
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

/// Which share of the blocks a run computes: shard `index` of `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// 0-based shard number.
    pub index: u64,
    /// Number of shards.
    pub count: u64,
}

impl Shard {
    /// The whole run.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Parses `i/k` (0 <= i < k).
    pub fn parse(text: &str) -> Result<Shard> {
        let bad = || Error::param("shard", text, "must be i/k with 0 <= i < k, e.g. 0/4");
        let (i, k) = text.split_once('/').ok_or_else(bad)?;
        let (index, count) = (
            i.trim().parse().map_err(|_| bad())?,
            k.trim().parse().map_err(|_| bad())?,
        );
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }

    /// The blocks this shard owns out of `blocks`: a contiguous range, the shards together
    /// covering every block once.
    pub fn blocks(&self, blocks: u64) -> Range<u64> {
        let share = |i: u64| (u128::from(i) * u128::from(blocks) / u128::from(self.count)) as u64;
        share(self.index)..share(self.index + 1)
    }
}

/// The statistics one shard computed: per distribution, one [`BlockStats`] per owned block.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShardOutput {
    /// Trials per distribution in the whole run.
    pub trials: u64,
    /// Which shard.
    pub shard: Shard,
    /// First block this shard owns.
    pub first_block: u64,
    /// Worker threads used.
    pub threads: usize,
    /// Wall-clock seconds of this shard.
    pub wall_s: f64,
    /// `blocks[d][b]`: distribution d, the shard's b-th block.
    pub blocks: Vec<Vec<BlockStats>>,
}

/// Runs every distribution of the experiment. Each wave of blocks is folded into the total as
/// soon as it is done, in block order: the same merge tree as [`fold`] over shards, so the same
/// bits, and memory that does not grow with the number of trials.
pub fn run(exp: &Experiment, opts: &RunOptions) -> Result<RunOutput> {
    let trials = trial_count(exp, opts)?;
    let blocks = 0..trials.div_ceil(BLOCK_TRIALS);
    let (pool, bar) = prepare(exp, opts, trials, 1, trials)?;
    let start = Instant::now();
    let totals = pool.install(|| {
        exp.distributions
            .iter()
            .map(|d| {
                bar.set_message(d.label.clone());
                let build = opts.build.unwrap_or(EstimatorSpec::build);
                let mut total = BlockStats::empty(&empty_cells(exp, d), exp.estimators.len());
                run_blocks(exp, d, trials, blocks.clone(), build, &bar, |b| {
                    total.merge(&b)
                })?;
                Ok(total)
            })
            .collect::<Result<Vec<_>>>()
    })?;
    bar.finish_and_clear();
    let dists = exp
        .distributions
        .iter()
        .zip(totals)
        .map(|(d, total)| {
            dist_result(
                exp,
                d,
                opts.build.unwrap_or(EstimatorSpec::build),
                trials,
                total,
            )
        })
        .collect();
    Ok(RunOutput {
        trials,
        threads: pool.current_num_threads(),
        wall_s: start.elapsed().as_secs_f64(),
        dists,
    })
}

/// The thread pool and progress bar of a run, after checking its memory plan (`held_blocks`
/// block statistics held at once per distribution).
fn prepare(
    exp: &Experiment,
    opts: &RunOptions,
    trials: u64,
    held_blocks: u64,
    bar_trials: u64,
) -> Result<(rayon::ThreadPool, ProgressBar)> {
    let threads = limits::threads(opts.threads)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::param("threads", threads, e.to_string()))?;
    check_memory(
        exp,
        trials,
        held_blocks + WAVE_BLOCKS,
        pool.current_num_threads(),
        opts.memory,
    )?;
    let bar = if opts.progress {
        let bar = ProgressBar::new(bar_trials * exp.distributions.len() as u64);
        if let Ok(style) = ProgressStyle::with_template(
            "{spinner} {msg:<18} [{bar:30}] {pos}/{len} trials ({eta} left)",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar
    } else {
        ProgressBar::hidden()
    };
    Ok((pool, bar))
}

/// One distribution's results from its folded statistics, with what the law says about the
/// mean's cells (seeded from the experiment's seed, the label and n, so it is reproducible).
fn dist_result(
    exp: &Experiment,
    d: &Distribution,
    build: BuildFn,
    trials: u64,
    total: BlockStats,
) -> DistResult {
    let runs_mean = exp.estimators.contains(&EstimatorSpec::Mean(MeanSpec));
    let mean_laws = exp
        .file
        .checkpoints
        .par_iter()
        .map(|&n| {
            runs_mean.then(|| {
                let seed = splitmix64(
                    splitmix64(exp.file.seed ^ fnv1a(&d.label)) ^ splitmix64(n as u64 ^ LAW_STREAM),
                );
                MeanLaw::new(&d.dist, n, trials, seed)
            })
        })
        .collect();
    DistResult {
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
        mean_laws,
        tail_effects: tail_effects(exp, d, build, trials),
    }
}

/// [`unseen::effects`] of every checkpoint, laid out like the cells (estimator-major), from a
/// stream of the experiment's seed, the label and n.
fn tail_effects(
    exp: &Experiment,
    d: &Distribution,
    build: BuildFn,
    trials: u64,
) -> Vec<TailEffects> {
    let cps = &exp.file.checkpoints;
    let per_n: Vec<Vec<TailEffects>> = cps
        .par_iter()
        .map(|&n| {
            let seed = splitmix64(
                splitmix64(exp.file.seed ^ fnv1a(&d.label)) ^ splitmix64(n as u64 ^ PAIR_STREAM),
            );
            unseen::effects(d, &exp.estimators, build, n, trials, seed)
        })
        .collect();
    (0..exp.estimators.len())
        .flat_map(|e| per_n.iter().map(move |v| v[e].clone()))
        .collect()
}

/// Salt of the streams of [`unseen::effects`].
const PAIR_STREAM: u64 = 0x7061_6972_735f_6f75;

/// Salt of the streams that simulate the law's null, apart from every trial's stream.
const LAW_STREAM: u64 = 0x6c61_775f_6e75_6c6c;

/// Trial count of a run: the option if given, else the experiment's.
fn trial_count(exp: &Experiment, opts: &RunOptions) -> Result<u64> {
    let trials = opts.trials.unwrap_or(exp.file.trials);
    if trials < 4 {
        return Err(Error::param(
            "trials",
            trials,
            "must be at least 4 (docs/estimators.md §7)",
        ));
    }
    Ok(trials)
}

/// Runs one shard's blocks of every distribution.
pub fn run_shard(exp: &Experiment, opts: &RunOptions, shard: Shard) -> Result<ShardOutput> {
    let trials = trial_count(exp, opts)?;
    let blocks = shard.blocks(trials.div_ceil(BLOCK_TRIALS));
    let shard_trials =
        (blocks.end * BLOCK_TRIALS).min(trials) - (blocks.start * BLOCK_TRIALS).min(trials);
    let (pool, bar) = prepare(exp, opts, trials, blocks.end - blocks.start, shard_trials)?;
    let start = Instant::now();
    let per_dist = pool.install(|| {
        exp.distributions
            .iter()
            .map(|d| {
                bar.set_message(d.label.clone());
                let build = opts.build.unwrap_or(EstimatorSpec::build);
                let mut out = Vec::with_capacity((blocks.end - blocks.start) as usize);
                run_blocks(exp, d, trials, blocks.clone(), build, &bar, |b| out.push(b))?;
                Ok(out)
            })
            .collect::<Result<Vec<_>>>()
    })?;
    bar.finish_and_clear();
    Ok(ShardOutput {
        trials,
        shard,
        first_block: blocks.start,
        threads: pool.current_num_threads(),
        wall_s: start.elapsed().as_secs_f64(),
        blocks: per_dist,
    })
}

/// Refuses a run that would hold more than the memory limit, before anything is allocated.
/// A single run holds its running total and one wave of blocks per distribution; a shard keeps
/// every block's statistics until the merge (that fixed merge tree is what makes shards merge
/// into the same bits), so a shard's memory grows with its share of the trials. Each worker
/// also holds one trial's samples up to the largest checkpoint and one of each estimator. The
/// estimate is a lower bound: a histogram holds at least one bin per cell.
fn check_memory(
    exp: &Experiment,
    trials: u64,
    blocks: u64,
    threads: usize,
    memory: MemoryLimit,
) -> Result<()> {
    /// Smallest heap a non-empty `BTreeMap<i32, u64>` holds: one leaf of 11 entries.
    const MIN_HISTOGRAM_BYTES: u128 = 11 * 12 + 16;
    let estimators = exp.estimators.len() as u128;
    let cells = estimators * exp.file.checkpoints.len() as u128;
    let per_block = size_of::<BlockStats>() as u128
        + cells * (size_of::<CellAccumulator>() as u128 + MIN_HISTOGRAM_BYTES)
        + estimators * 24;
    let held = u128::from(blocks) * exp.distributions.len() as u128 * per_block;
    memory.check(
        format!(
            "trials = {trials} ({} distributions x {cells} estimator-checkpoint cells)",
            exp.distributions.len()
        ),
        held,
    )?;
    let mut state = 0u128;
    for spec in &exp.estimators {
        state += spec.build()?.state_bytes() as u128;
    }
    let per_worker = exp.max_n() as u128 * 8 + cells * 8 + state;
    memory.check(
        format!(
            "largest checkpoint = {} with {threads} worker threads",
            exp.max_n()
        ),
        held + threads as u128 * per_worker,
    )
}

/// Folds shards (every block exactly once, any order given) into the run's results, block by
/// block in block order: the same bits as a single run.
pub fn fold(exp: &Experiment, shards: &[ShardOutput]) -> Result<RunOutput> {
    let first = shards
        .first()
        .ok_or_else(|| Error::param("shards", "[]", "need at least one shard"))?;
    let trials = first.trials;
    let total_blocks = trials.div_ceil(BLOCK_TRIALS);
    let mut ordered: Vec<&ShardOutput> = shards.iter().collect();
    ordered.sort_by_key(|s| s.first_block);
    let mut next = 0;
    for s in &ordered {
        let owned = s.blocks.first().map_or(0, |b| b.len() as u64);
        if s.trials != trials || s.blocks.len() != exp.distributions.len() || s.first_block != next
        {
            return Err(Error::param(
                "shards",
                format!("{}/{}", s.shard.index, s.shard.count),
                "does not fit the others (trials, distributions or block range differ)",
            ));
        }
        next += owned;
    }
    if next != total_blocks {
        return Err(Error::param(
            "shards",
            format!("{next} of {total_blocks} blocks"),
            "do not cover the run",
        ));
    }
    let mut dists = Vec::with_capacity(exp.distributions.len());
    for (i, d) in exp.distributions.iter().enumerate() {
        let template = empty_cells(exp, d);
        let mut total = BlockStats::empty(&template, exp.estimators.len());
        for s in &ordered {
            for b in &s.blocks[i] {
                if b.cells.len() != template.len() {
                    return Err(Error::param(
                        "shards",
                        format!("{}/{}", s.shard.index, s.shard.count),
                        "has a different number of cells than the experiment",
                    ));
                }
                total.merge(b);
            }
        }
        dists.push(dist_result(exp, d, EstimatorSpec::build, trials, total));
    }
    Ok(RunOutput {
        trials,
        threads: shards.iter().map(|s| s.threads).max().unwrap_or(1),
        wall_s: shards.iter().map(|s| s.wall_s).sum(),
        dists,
    })
}

/// Empty accumulators for one distribution, with each cell's deviation threshold set.
fn empty_cells(exp: &Experiment, d: &Distribution) -> Vec<CellAccumulator> {
    let mut cells = Vec::new();
    for spec in &exp.estimators {
        for &n in &exp.file.checkpoints {
            let threshold = claims::deviation_threshold(&exp.file.checks, spec, &d.dist, n);
            cells.push(CellAccumulator::with_deviation_threshold(threshold));
        }
    }
    cells
}

/// The given blocks of one distribution, each folded chunk by chunk in chunk order and handed
/// to `sink` in block order.
fn run_blocks(
    exp: &Experiment,
    d: &Distribution,
    trials: u64,
    blocks: Range<u64>,
    build: BuildFn,
    bar: &ProgressBar,
    mut sink: impl FnMut(BlockStats),
) -> Result<()> {
    let template = empty_cells(exp, d);
    let mut wave = blocks.start;
    while wave < blocks.end {
        let wave_end = (wave + WAVE_BLOCKS).min(blocks.end);
        let chunks =
            wave * BLOCK_CHUNKS..(wave_end * BLOCK_CHUNKS).min(trials.div_ceil(CHUNK_TRIALS));
        let results = chunks
            .clone()
            .into_par_iter()
            .map(|c| {
                let range = c * CHUNK_TRIALS..((c + 1) * CHUNK_TRIALS).min(trials);
                let r = run_chunk(exp, d, range.clone(), &template, build);
                bar.inc(range.end - range.start);
                r
            })
            .collect::<Result<Vec<_>>>()?;
        for block in results.chunks(BLOCK_CHUNKS as usize) {
            let mut stats = BlockStats::empty(&template, exp.estimators.len());
            for r in block {
                stats.merge(r);
            }
            sink(stats);
        }
        wave = wave_end;
    }
    Ok(())
}

fn run_chunk(
    exp: &Experiment,
    d: &Distribution,
    trials: Range<u64>,
    template: &[CellAccumulator],
    build: BuildFn,
) -> Result<BlockStats> {
    let checkpoints = &exp.file.checkpoints;
    let (mu, tau) = (d.dist.mean(), exp.file.tau);
    let mut estimators: Vec<Box<dyn Estimator>> =
        exp.estimators.iter().map(build).collect::<Result<_>>()?;
    let mut out = BlockStats::empty(template, estimators.len());
    let cps = checkpoints.len();
    // The paired differences need the plain mean of each trial: read it from the experiment's
    // own `mean` when it runs one, instead of computing it twice.
    let mean_index = exp
        .estimators
        .iter()
        .position(|s| *s == EstimatorSpec::Mean(MeanSpec));
    let mut samples = vec![0.0; exp.max_n()];
    let mut own_mean = vec![0.0; cps];
    let mut outlier = vec![false; cps];
    let mut estimates = vec![0.0; estimators.len() * cps];
    for trial in trials {
        let mut rng = trial_rng(exp.file.seed, &d.label, trial);
        let t0 = Instant::now();
        d.dist.fill(&mut rng, &mut samples);
        out.generate_nanos += t0.elapsed().as_nanos() as u64;
        validate_samples(&samples, 0)?;

        let (mut from, mut max) = (0, 0.0f64);
        for (i, &n) in checkpoints.iter().enumerate() {
            max = largest(&samples[from..n], max);
            outlier[i] = max >= n as f64 * mu;
            from = n;
        }

        for (e, est) in estimators.iter_mut().enumerate() {
            est.reset();
            let t0 = Instant::now();
            let mut from = 0;
            for (i, &n) in checkpoints.iter().enumerate() {
                est.push_slice(&samples[from..n]);
                let x = est.estimate()?;
                if !x.is_finite() {
                    return Err(Error::param(
                        "estimate",
                        x,
                        format!(
                            "{est} gave a non-finite estimate at n = {n}, trial {trial} of {}",
                            d.label
                        ),
                    ));
                }
                estimates[e * cps + i] = x;
                from = n;
            }
            out.estimator_nanos[e] += t0.elapsed().as_nanos() as u64;
            let bytes = est.state_bytes();
            out.state_bytes_max[e] = out.state_bytes_max[e].max(bytes);
            out.state_bytes_sum[e] += bytes as u64;
        }

        let mean_estimates = match mean_index {
            Some(m) => &estimates[m * cps..(m + 1) * cps],
            None => {
                let (mut mean, mut from) = (Mean::new(), 0);
                for (i, &n) in checkpoints.iter().enumerate() {
                    mean.push_slice(&samples[from..n]);
                    own_mean[i] = mean.estimate()?;
                    from = n;
                }
                &own_mean[..]
            }
        };
        for (cell, (&estimate, i)) in out
            .cells
            .iter_mut()
            .zip(estimates.iter().zip((0..cps).cycle()))
        {
            let o = Observation {
                estimate,
                mean_estimate: mean_estimates[i],
                outlier: outlier[i],
            };
            cell.push(o, mu, tau);
        }
    }
    Ok(out)
}

/// The largest of `init` and the validated (never NaN) `samples`, in eight running maxima that
/// vectorise: max is exact, so their order does not matter.
fn largest(samples: &[f64], init: f64) -> f64 {
    let mut lanes = [init; 8];
    let blocks = samples.chunks_exact(8);
    let rest = blocks.remainder();
    for block in blocks {
        for (m, &x) in lanes.iter_mut().zip(block) {
            *m = if x > *m { x } else { *m };
        }
    }
    lanes.iter().chain(rest).fold(init, |m, &x| m.max(x))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn largest_is_the_maximum_whatever_the_length() {
        let xs: Vec<f64> = (0..37).map(|i| ((i * 17) % 37) as f64).collect();
        for len in 0..=xs.len() {
            let want = xs[..len].iter().fold(-1.0, |m: f64, &x| m.max(x));
            assert_eq!(largest(&xs[..len], -1.0), want, "length {len}");
        }
    }

    #[test]
    fn streams_differ_by_trial_and_label_and_repeat_exactly() {
        let draw = |label: &str, trial| trial_rng(42, label, trial).next_u64();
        assert_eq!(draw("a", 0), draw("a", 0));
        assert_ne!(draw("a", 0), draw("a", 1));
        assert_ne!(draw("a", 0), draw("b", 0));
        assert_ne!(
            trial_rng(1, "a", 0).next_u64(),
            trial_rng(2, "a", 0).next_u64()
        );
    }
}
