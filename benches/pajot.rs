//! Per-sample cost of Pajot et al.'s estimators against the plain mean (issue 3).
//!
//! Samples are drawn once per preset from a seeded Xoshiro256++ stream, outside the timed
//! loop, so only the estimators are measured. Each iteration feeds `PIXELS` pixels of `spp`
//! samples through one boxed estimator, in blocks of 64 (`push_slice`, as a bank or film
//! does), with `reset` between pixels and one `estimate` per pixel. Throughput is in samples,
//! so criterion's "elem/s" reads as samples per second; ns/sample is its inverse.
//!
//! The last function prints a table of ns/sample and ratios (ROT/mean, ADR/mean), from the
//! fastest of a few timed passes over the same data: the figures the README quotes, read in
//! one run; criterion's estimates above remain the reference.
//!
//! Run: `cargo bench --bench pajot -- --warm-up-time 1 --measurement-time 3`.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use fireflies::Estimator;
use fireflies::dist::Preset;
use fireflies::estimators::{Mean, PajotAdr, PajotHybrid, PajotRot};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::hint::black_box;
use std::time::Instant;

/// Pixels per iteration.
const PIXELS: usize = 32;
/// Samples per `push_slice` call.
const BLOCK: usize = 64;

type Make = fn() -> Box<dyn Estimator>;

const METHODS: [(&str, Make); 4] = [
    ("mean", || Box::new(Mean::new())),
    ("rot", || Box::new(PajotRot::new(50).expect("valid"))),
    ("adr", || Box::new(PajotAdr::new(50).expect("valid"))),
    ("hybrid", || {
        Box::new(PajotHybrid::new(50, 2, 0.0).expect("valid"))
    }),
];

fn samples(preset: Preset, spp: usize) -> Vec<f64> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(0xbe7c_4000 + spp as u64);
    let mut out = vec![0.0; spp * PIXELS];
    preset.dist().fill(&mut rng, &mut out);
    out
}

/// Runs every pixel of `data` through `e`; returns the sum of the estimates.
fn run(e: &mut dyn Estimator, data: &[f64], spp: usize) -> f64 {
    let mut acc = 0.0;
    for pixel in data.chunks(spp) {
        e.reset();
        for block in pixel.chunks(BLOCK) {
            e.push_slice(black_box(block));
        }
        acc += e.estimate().unwrap_or(0.0);
    }
    acc
}

/// Every method on the presets at 1024 samples per pixel.
fn presets(c: &mut Criterion) {
    let spp = 1024;
    for preset in [Preset::Caustic, Preset::Firefly, Preset::Diffuse] {
        let data = samples(preset, spp);
        let mut g = c.benchmark_group(format!("pajot/{}", preset.name()));
        g.throughput(Throughput::Elements(data.len() as u64));
        for (name, make) in METHODS {
            let mut e = make();
            g.bench_function(BenchmarkId::new(name, spp), |b| {
                b.iter(|| run(e.as_mut(), &data, spp))
            });
        }
        g.finish();
    }
}

/// How the cost per sample grows with the pixel's sample count (ADR's points grow with it).
fn sweep(c: &mut Criterion) {
    let mut g = c.benchmark_group("pajot/firefly-spp");
    for spp in [256, 4096] {
        let data = samples(Preset::Firefly, spp);
        g.throughput(Throughput::Elements(data.len() as u64));
        for (name, make) in METHODS {
            let mut e = make();
            g.bench_function(BenchmarkId::new(name, spp), |b| {
                b.iter(|| run(e.as_mut(), &data, spp))
            });
        }
    }
    g.finish();
}

/// ns/sample of every method on every configuration above, and the ratios to the mean.
fn summary(_: &mut Criterion) {
    const PASSES: usize = 7;
    println!(
        "\nns/sample, fastest of {PASSES} passes  {:>7} {:>7} {:>7} {:>7}  {:>8} {:>8}",
        "mean", "rot", "adr", "hybrid", "rot/mean", "adr/mean"
    );
    let configs = [
        (Preset::Caustic, 1024),
        (Preset::Firefly, 1024),
        (Preset::Diffuse, 1024),
        (Preset::Firefly, 256),
        (Preset::Firefly, 4096),
    ];
    for (preset, spp) in configs {
        let data = samples(preset, spp);
        let ns: Vec<f64> = METHODS
            .iter()
            .map(|(_, make)| {
                let mut e = make();
                (0..PASSES)
                    .map(|_| {
                        let t = Instant::now();
                        black_box(run(e.as_mut(), &data, spp));
                        t.elapsed().as_secs_f64() * 1e9 / data.len() as f64
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        println!(
            "{:<32} {:>7.2} {:>7.2} {:>7.2} {:>7.2}  {:>8.1} {:>8.1}",
            format!("{}/{spp}", preset.name()),
            ns[0],
            ns[1],
            ns[2],
            ns[3],
            ns[1] / ns[0],
            ns[2] / ns[0]
        );
    }
}

criterion_group!(benches, presets, sweep, summary);
criterion_main!(benches);
