//! The path tracer's cost per camera sample and what the film's estimator banks add to it
//! (issue 6: all constant-memory estimators together should cost at most 5% over the mean
//! alone; Buisine et al. report 1.17% for G-MoN in pbrt-v4).
//!
//! One group, the Cornell box of `experiments/scenes/cbox.xml` at its 128x128 resolution and
//! 16 spp on 2 threads, three film configurations: the mean only, the nine constant-memory
//! estimators, and those nine plus the three Pajot variants (not constant memory). Throughput is
//! in camera samples per second, so the ratios read directly as overheads.
//!
//! A second group times the BVH alone on the same scene, one thread: closest hits of the camera
//! rays through every pixel centre, and occlusion of the segments from each camera hit to a
//! point under the ceiling light (throughput in rays per second).
//!
//! Run with `cargo bench --bench render -- --warm-up-time 1 --measurement-time 10`.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use fireflies::estimators::{CONSTANT_MEMORY_SET, EstimatorSpec};
use fireflies::render::film::{self, FilmConfig};
use fireflies::render::mitsuba::load_file;
use fireflies::render::shapes::Ray;
use fireflies::render::world::World;
use glam::{Vec2, Vec3};
use std::hint::black_box;
use std::path::Path;

/// Worker threads (the CI machine's cores).
const THREADS: usize = 2;
/// Samples per pixel per iteration.
const SPP: u32 = 16;

fn specs(names: &[&str]) -> Vec<EstimatorSpec> {
    names
        .iter()
        .map(|s| s.parse().expect("valid spec"))
        .collect()
}

fn bench(c: &mut Criterion) {
    let scene = load_file(Path::new("experiments/scenes/cbox.xml")).expect("cbox loads");
    let world = World::new(&scene);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(THREADS)
        .build()
        .expect("thread pool");
    let mut all = CONSTANT_MEMORY_SET.to_vec();
    all.extend(["pajot-rot", "pajot-adr", "pajot-hybrid"]);
    let configs = [
        ("mean", specs(&["mean"])),
        ("constant-memory-9", specs(&CONSTANT_MEMORY_SET)),
        ("all-12", specs(&all)),
    ];
    let samples =
        u64::from(world.camera.width()) * u64::from(world.camera.height()) * u64::from(SPP);
    let mut group = c.benchmark_group("render-cbox");
    group.throughput(Throughput::Elements(samples));
    group.sample_size(10);
    for (name, estimators) in configs {
        let cfg = FilmConfig {
            estimators,
            spp: SPP,
            checkpoints: vec![],
            seed: 1,
            dump_pixels: vec![],
            memory: Default::default(),
        };
        group.bench_with_input(BenchmarkId::new("film", name), &cfg, |b, cfg| {
            b.iter(|| {
                pool.install(|| black_box(film::render(&world, cfg, |_| {}).expect("renders")))
            })
        });
    }
    group.finish();
}

fn traversal(c: &mut Criterion) {
    let scene = load_file(Path::new("experiments/scenes/cbox.xml")).expect("cbox loads");
    let world = World::new(&scene);
    let (w, h) = (world.camera.width(), world.camera.height());
    let camera: Vec<(Ray, f32, f32)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let r = world.camera.ray(x, y, Vec2::splat(0.5));
            (r.ray, r.tmin, r.tmax)
        })
        .collect();
    // Just under the light of cbox.xml (at y = 0.99, under the ceiling at y = 1).
    let light = Vec3::new(0.0, 0.95, 0.0);
    let shadow: Vec<(Ray, f32)> = camera
        .iter()
        .filter_map(|(r, t0, t1)| world.bvh.intersect(r, *t0, *t1))
        .filter_map(|hit| {
            let to = light - hit.p;
            let len = to.length();
            let o = hit.p + hit.ng * 1e-4 * hit.ng.dot(to).signum();
            (len > 1e-3).then(|| (Ray::new(o, to / len), len * 0.999))
        })
        .collect();
    let mut group = c.benchmark_group("bvh-cbox");
    group.throughput(Throughput::Elements(camera.len() as u64));
    group.bench_function("closest-hit", |b| {
        b.iter(|| {
            camera
                .iter()
                .filter(|(r, t0, t1)| world.bvh.intersect(r, *t0, *t1).is_some())
                .count()
        })
    });
    group.throughput(Throughput::Elements(shadow.len() as u64));
    group.bench_function("occluded", |b| {
        b.iter(|| {
            shadow
                .iter()
                .filter(|(r, t)| world.bvh.occluded(r, 0.0, *t))
                .count()
        })
    });
    group.finish();
}

criterion_group!(benches, bench, traversal);
criterion_main!(benches);
