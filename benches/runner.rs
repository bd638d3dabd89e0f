//! The runner against the bare loop it wraps, side by side on 2 threads (issue 4, "Speed and
//! scale"): the goal is that `harness::run` with a Bank of every constant-memory estimator
//! sustains at least 60% of the throughput of a loop that only draws the same samples.
//!
//! Three benchmarks share one group, one seed, one distribution (the `infinite-variance`
//! preset, a pure Pareto of shape 1.5), one checkpoint n = 4096 and one trial count, so their
//! throughputs (samples per second) compare directly:
//!
//! - `generate-only`: per trial, `trial_rng` then `Dist::fill` into a reused buffer, rayon over
//!   trials; the runner's own sample stream with nothing done to it;
//! - `runner-all-constant-memory`: the whole runner with the nine constant-memory estimators;
//! - `runner-mean-mon21`: the runner with the mean and MoN(21), the task
//!   `experiments/numpy_baseline.py` does in NumPy.
//!
//! Run with `cargo bench --bench runner -- --warm-up-time 1 --measurement-time 5`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use fireflies::dist::{Dist, preset};
use fireflies::harness::runner::trial_rng;
use fireflies::harness::{Experiment, RunOptions, run};
use rayon::prelude::*;

/// Worker threads of every benchmark in the group (the issue's 2-core machine).
const THREADS: usize = 2;
/// Seed shared by the bare loop and the runner.
const SEED: u64 = 20261121;
/// Preset name, which is also the distribution label that seeds the trial streams.
const LABEL: &str = "infinite-variance";
/// Samples per trial: the single checkpoint.
const N: usize = 4096;
/// Trials per iteration: 33.6 M samples (32 of the runner's 256-trial chunks, 16 per thread).
/// On 2 idle cores that is about 0.17 s for the bare loop, 0.3 s for the mean and MoN(21) and
/// 1 s for all nine estimators (criterion then asks for a longer measurement time; the numbers
/// are still taken over 10 samples). On a shared VM the times can double: compare the three
/// throughputs of one run, not across runs.
const TRIALS: u64 = 8192;

/// Every constant-memory estimator at the parameters a user would start from.
const CONSTANT_MEMORY: &[&str] = &fireflies::estimators::CONSTANT_MEMORY_SET;

/// The NumPy-comparable task.
const MEAN_MON: &[&str] = &["mean", "mon:M=21"];

/// An in-memory experiment over `LABEL` at `N` with the given estimators and every check off,
/// so that only trials are timed.
fn experiment(name: &str, estimators: &[&str]) -> Experiment {
    let list = estimators
        .iter()
        .map(|e| format!("\"{e}\""))
        .collect::<Vec<_>>()
        .join(", ");
    let text = format!(
        r#"
seed = {SEED}
trials = {TRIALS}
checkpoints = [{N}]
estimators = [{list}]

[[distributions]]
dist = {{ kind = "preset", name = "{LABEL}" }}

[checks]
unbiased_mean = false
chebyshev_k = 0
mon_delta = 0
zirr_bound = false
"#
    );
    Experiment::from_toml(&text, "benches/runner.rs", name).expect("valid bench experiment")
}

/// The bare loop: draw every trial's samples with the runner's streams and sum them.
fn generate_only(dist: &Dist, pool: &rayon::ThreadPool) -> f64 {
    pool.install(|| {
        (0..TRIALS)
            .into_par_iter()
            .map_init(
                || vec![0.0f64; N],
                |buf, trial| {
                    let mut rng = trial_rng(SEED, LABEL, trial);
                    dist.fill(&mut rng, buf);
                    black_box(buf.iter().sum::<f64>())
                },
            )
            .sum()
    })
}

fn runner(c: &mut Criterion) {
    let dist = preset(LABEL).expect("known preset");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(THREADS)
        .build()
        .expect("thread pool");
    let all = experiment("all-constant-memory", CONSTANT_MEMORY);
    let mean_mon = experiment("mean-mon21", MEAN_MON);
    let opts = RunOptions {
        trials: Some(TRIALS),
        threads: Some(THREADS),
        progress: false,
        ..RunOptions::default()
    };

    let mut group = c.benchmark_group("runner");
    group.sample_size(10);
    group.throughput(Throughput::Elements(TRIALS * N as u64));
    group.bench_function(BenchmarkId::new("generate-only", THREADS), |b| {
        b.iter(|| generate_only(&dist, &pool))
    });
    group.bench_function(
        BenchmarkId::new("runner-all-constant-memory", THREADS),
        |b| b.iter(|| black_box(run(&all, &opts).expect("runner"))),
    );
    group.bench_function(BenchmarkId::new("runner-mean-mon21", THREADS), |b| {
        b.iter(|| black_box(run(&mean_mon, &opts).expect("runner")))
    });
    group.finish();
}

criterion_group! {
    name = benches;
    // No plots: criterion is built without plotters; the throughputs are the point.
    config = Criterion::default().without_plots();
    targets = runner
}
criterion_main!(benches);
