//! Per-sample cost of the generators: each preset's `fill` on a block, against the bare
//! `rand_distr::Pareto` draw the issue uses as its yardstick (goal: within 1.5x of it).
//! Run with `cargo bench --bench generators`; throughput reads as samples per second.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use fireflies::dist::{Dist, LogNormal, Pareto, Preset, TruncatedPareto};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// Samples per block: the size a harness trial fills at a time.
const BLOCK: usize = 4096;

fn generators(c: &mut Criterion) {
    let mut group = c.benchmark_group("generators");
    group.throughput(Throughput::Elements(BLOCK as u64));
    let mut out = vec![0.0f64; BLOCK];

    // The yardstick: rand_distr's Pareto, drawn one by one into the same block.
    let bare = rand_distr::Pareto::new(1.0, 1.5).expect("valid parameters");
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
    group.bench_function(BenchmarkId::new("rand_distr-pareto", BLOCK), |b| {
        b.iter(|| {
            for x in out.iter_mut() {
                *x = rng.sample(bare);
            }
            black_box(&mut out);
        })
    });

    let mut laws: Vec<(String, Dist)> = Preset::ALL
        .iter()
        .map(|p| (p.name().to_string(), p.dist()))
        .collect();
    laws.push((
        "pareto".into(),
        Pareto::new(1.0, 1.5).expect("valid parameters").into(),
    ));
    laws.push((
        "truncated-pareto".into(),
        TruncatedPareto::new(1.0, 1.2, 1e4)
            .expect("valid parameters")
            .into(),
    ));
    laws.push((
        "lognormal".into(),
        LogNormal::new(0.0, 1.0).expect("valid parameters").into(),
    ));
    for (name, dist) in &laws {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        group.bench_function(BenchmarkId::new(name.as_str(), BLOCK), |b| {
            b.iter(|| {
                dist.fill(&mut rng, &mut out);
                black_box(&mut out);
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    // No plots: they need system fonts that CI machines may lack, and the numbers are the point.
    config = Criterion::default().without_plots();
    targets = generators
}
criterion_main!(benches);
