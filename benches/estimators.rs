//! Per-sample `push` cost of every estimator and of a Bank of all constant-memory ones,
//! on a pre-drawn heavy-tailed block so only the estimator is timed.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use fireflies::estimators::{Bank, EstimatorSpec};
use rand::SeedableRng;
use rand_distr::{Distribution, Pareto};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::hint::black_box;

const BLOCK: usize = 4096;

/// Every constant-memory estimator at the parameters a user would start from.
const CONSTANT_MEMORY: &[&str] = &fireflies::estimators::CONSTANT_MEMORY_SET;

fn block() -> Vec<f64> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
    let pareto = Pareto::new(1.0, 1.5).expect("valid Pareto");
    (0..BLOCK).map(|_| pareto.sample(&mut rng)).collect()
}

fn per_estimator(c: &mut Criterion) {
    let samples = block();
    let mut group = c.benchmark_group("push_slice");
    group.throughput(Throughput::Elements(BLOCK as u64));
    for text in CONSTANT_MEMORY {
        let spec: EstimatorSpec = text.parse().expect("valid spec");
        let mut est = spec.build().expect("valid estimator");
        group.bench_function(BenchmarkId::from_parameter(text), |b| {
            b.iter(|| est.push_slice(black_box(&samples)))
        });
    }
    group.finish();
}

fn bank(c: &mut Criterion) {
    let samples = block();
    let specs: Vec<EstimatorSpec> = CONSTANT_MEMORY
        .iter()
        .map(|t| t.parse().expect("valid spec"))
        .collect();
    let mut group = c.benchmark_group("bank");
    group.throughput(Throughput::Elements(BLOCK as u64));
    let mut all = Bank::new(&specs).expect("valid bank");
    group.bench_function("all-constant-memory", |b| {
        b.iter(|| all.push_slice(black_box(&samples)).expect("valid samples"))
    });
    let mut mean_only = Bank::new(&specs[..1]).expect("valid bank");
    group.bench_function("mean-only", |b| {
        b.iter(|| {
            mean_only
                .push_slice(black_box(&samples))
                .expect("valid samples")
        })
    });
    group.finish();
}

criterion_group!(benches, per_estimator, bank);
criterion_main!(benches);
