//! End-to-end tests of the path tracer: closed-form scenes, white furnaces, determinism and
//! the `render` command.
//!
//! Statistical tests compare a Monte Carlo mean with its exact value at 5 standard errors
//! (two-sided false-failure probability 5.7e-7 per test under the central limit theorem; the
//! sample counts are large and the per-sample values bounded or light-tailed here). Each test
//! states the smallest relative bias it would catch (about 5 standard errors).

use fireflies::estimators::EstimatorSpec;
use fireflies::render::film::{self, FilmConfig};
use fireflies::render::integrator::radiance;
use fireflies::render::mitsuba::load_str;
use fireflies::render::sampler::SampleStream;
use fireflies::render::world::World;
use std::path::Path;

/// Standard errors allowed between a Monte Carlo mean and its exact value.
const Z: f64 = 5.0;

fn world(xml: &str) -> World {
    let scene = load_str(xml, Path::new("."), "test.xml").expect("scene loads");
    World::new(&scene)
}

/// A camera at `origin` looking at `target`, `size`² pixels, box filter.
fn sensor(origin: &str, target: &str, up: &str, fov: f32, size: u32) -> String {
    format!(
        r#"<sensor type="perspective">
            <float name="fov" value="{fov}"/>
            <transform name="to_world"><lookat origin="{origin}" target="{target}" up="{up}"/></transform>
            <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/><rfilter type="box"/></film>
            <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        </sensor>"#
    )
}

/// Mean and standard error of `(r + g + b) / 3` over `n` samples of every pixel, and the number
/// of invalid (non-finite or negative) samples, which are left out.
fn pixel_stats(w: &World, n: u32, seed: u64) -> (f64, f64, u64) {
    let (width, height) = (w.camera.width(), w.camera.height());
    let (mut sum, mut sum2, mut count, mut bad) = (0.0f64, 0.0f64, 0u64, 0u64);
    for y in 0..height {
        for x in 0..width {
            for s in 0..n {
                let mut rng = SampleStream::new(seed, u64::from(y * width + x), u64::from(s));
                let l = radiance(w, x, y, &mut rng);
                let v = (f64::from(l.x) + f64::from(l.y) + f64::from(l.z)) / 3.0;
                if !v.is_finite() || v < 0.0 {
                    bad += 1;
                    continue;
                }
                sum += v;
                sum2 += v * v;
                count += 1;
            }
        }
    }
    let mean = sum / count as f64;
    let var = (sum2 / count as f64 - mean * mean).max(0.0);
    (mean, (var / count as f64).sqrt(), bad)
}

#[track_caller]
fn assert_mean(mean: f64, se: f64, exact: f64, max_rel_se: f64) {
    assert!(
        se <= max_rel_se * exact,
        "standard error {se} too large to be a useful test (exact {exact})"
    );
    assert!(
        (mean - exact).abs() <= Z * se,
        "mean {mean} vs exact {exact}: {:.2} standard errors (se {se})",
        (mean - exact) / se
    );
}

fn furnace(bsdf: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="-1"/></integrator>
            {}
            <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
            <shape type="sphere"><float name="radius" value="1"/>{bsdf}</shape>
        </scene>"#,
        sensor("0, 0, 5", "0, 0, 0", "0, 1, 0", 30.0, 12)
    )
}

/// A white diffuse sphere in a uniform environment of radiance 1 reflects exactly 1 everywhere.
/// 12x12 pixels x 96 samples; catches a relative energy error of about 1%.
#[test]
fn white_furnace_diffuse_sphere_renders_one() {
    let w = world(&furnace(
        r#"<bsdf type="diffuse"><rgb name="reflectance" value="1"/></bsdf>"#,
    ));
    let (mean, se, bad) = pixel_stats(&w, 96, 1);
    assert_eq!(bad, 0);
    assert_mean(mean, se, 1.0, 0.003);
}

/// Glass conserves energy too: Fresnel splits are chosen with their probability, and the
/// η² radiance scaling of a refraction into the sphere is undone on the way out.
#[test]
fn white_furnace_glass_sphere_renders_one() {
    let w = world(&furnace(
        r#"<bsdf type="dielectric"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/></bsdf>"#,
    ));
    let (mean, se, bad) = pixel_stats(&w, 64, 2);
    assert_eq!(bad, 0);
    // A path that is trapped beyond max RR survival can end early, so values vary a little.
    assert_mean(mean, se.max(1e-6), 1.0, 0.003);
}

/// A perfect mirror in the furnace returns exactly the environment on every sample.
#[test]
fn white_furnace_mirror_sphere_is_exact() {
    let w = world(&furnace(r#"<bsdf type="conductor"/>"#));
    for s in 0..16 {
        let mut rng = SampleStream::new(3, 77, s);
        let l = radiance(&w, 6, 6, &mut rng);
        assert!((l - glam::Vec3::ONE).abs().max_element() < 1e-6, "{l}");
    }
}

/// Direct light only (`max_depth` 2) on a 20x20 Lambertian floor of albedo 0.5 at `y = 0`
/// facing up, lit by `light` and seen by `camera` (one pixel).
fn lit_floor(light: &str, camera: &str) -> World {
    world(&format!(
        r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="2"/></integrator>
            {camera}
            {light}
            <shape type="rectangle">
                <transform name="to_world"><rotate x="1" angle="-90"/><scale value="10"/></transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
            </shape>
        </scene>"#
    ))
}

/// A one-pixel camera aimed at the floor point below the lights, from the side.
fn side_camera() -> String {
    sensor("0, 0.6, 2", "0, 0, 0", "0, 1, 0", 0.2, 1)
}

/// Lambertian floor of albedo 0.5 under a point light of intensity 10 at height 1, seen head-on
/// through a 0.2° field of view: Lo = ρ/π · I/h² exactly at the centre (the footprint changes it
/// by < 1e-5). No randomness reaches the value except the position inside the pixel.
#[test]
fn point_light_on_diffuse_floor_matches_closed_form() {
    let w = lit_floor(
        r#"<emitter type="point"><rgb name="intensity" value="10"/><point name="position" value="0, 1, 0"/></emitter>"#,
        &sensor("0, 3, 0", "0, 0, 0", "0, 0, 1", 0.2, 1),
    );
    let exact = 0.5 / std::f64::consts::PI * 10.0;
    let (mean, _, bad) = pixel_stats(&w, 64, 4);
    assert_eq!(bad, 0);
    assert!((mean - exact).abs() < 1e-4 * exact, "{mean} vs {exact}");
}

/// A downward-facing disk light of radius R = 0.5 and radiance 2 at height h = 1 over a floor of
/// albedo 0.5: Lo = ρ·L·R²/(R²+h²) = 0.2 at the point below its centre. Exercises light sampling
/// of the disk, BSDF sampling hitting it and their MIS weights together. 40000 samples;
/// catches a relative bias of about 1.5%.
#[test]
fn disk_light_on_diffuse_floor_matches_closed_form() {
    let w = lit_floor(
        r#"<shape type="disk">
            <transform name="to_world"><scale value="0.5"/><rotate x="1" angle="90"/><translate y="1"/></transform>
            <emitter type="area"><rgb name="radiance" value="2"/></emitter>
        </shape>"#,
        &side_camera(),
    );
    let exact = 0.5 * 2.0 * 0.25 / (0.25 + 1.0);
    let (mean, se, bad) = pixel_stats(&w, 40_000, 5);
    assert_eq!(bad, 0);
    assert_mean(mean, se, exact, 0.003);
}

/// A spherical light of radius R = 0.25 and radiance 3, centre at distance d = 1 above the floor
/// point: Lo = ρ·L·(R/d)² = 0.09375 (ρ = 0.5). Exercises cone sampling of the sphere.
/// 40000 samples; catches a relative bias of about 1.5%.
#[test]
fn sphere_light_on_diffuse_floor_matches_closed_form() {
    let w = lit_floor(
        r#"<shape type="sphere">
            <point name="center" value="0, 1, 0"/><float name="radius" value="0.25"/>
            <emitter type="area"><rgb name="radiance" value="3"/></emitter>
        </shape>"#,
        &side_camera(),
    );
    let exact = 0.5 * 3.0 * 0.0625;
    let (mean, se, bad) = pixel_stats(&w, 40_000, 6);
    assert_eq!(bad, 0);
    assert_mean(mean, se, exact, 0.003);
}

/// The emitter is black from behind (Mitsuba's area lights emit from the front only) and a
/// one-sided diffuse surface is black from behind.
#[test]
fn back_faces_are_black() {
    let xml = format!(
        r#"<scene version="3.0.0">
            {}
            <shape type="rectangle">
                <emitter type="area"><rgb name="radiance" value="1"/></emitter>
            </shape>
        </scene>"#,
        sensor("0, 0, -3", "0, 0, 0", "0, 1, 0", 10.0, 2)
    );
    let w = world(&xml);
    let (mean, _, _) = pixel_stats(&w, 4, 7);
    assert_eq!(mean, 0.0);
}

fn cbox() -> World {
    let scene = fireflies::render::mitsuba::load_file(Path::new("experiments/scenes/cbox.xml"))
        .expect("cbox loads");
    World::new(&scene)
}

fn film_config(spp: u32, checkpoints: Vec<u32>) -> FilmConfig {
    FilmConfig {
        estimators: [
            "mean",
            "gmon:M=5",
            "zirr",
            "pajot-rot",
            "jung:sigma_image=1",
        ]
        .iter()
        .map(|s| s.parse::<EstimatorSpec>().unwrap())
        .collect(),
        spp,
        checkpoints,
        seed: 11,
        dump_pixels: vec![(64, 64)],
        memory: Default::default(),
    }
}

/// The image is a pure function of (seed, pixel, sample index): 1 and 3 threads, with or without
/// checkpoints, give bit-identical images for every estimator.
#[test]
fn render_is_identical_for_any_thread_count_and_checkpoints() {
    let w = cbox();
    let run = |threads: usize, checkpoints: Vec<u32>| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| film::render(&w, &film_config(6, checkpoints), |_| {}))
            .unwrap()
    };
    let a = run(1, vec![]);
    let b = run(3, vec![2, 5]);
    let finals = |o: &film::FilmOutput| -> Vec<_> {
        o.images
            .iter()
            .filter(|i| i.spp == 6)
            .map(|i| i.image.clone())
            .collect()
    };
    assert_eq!(finals(&a), finals(&b));
    assert_eq!(a.dumps, b.dumps);
    assert_eq!(a.dumps[0].1.len(), 6);
    assert_eq!(b.images.len(), 15);
    assert_eq!(a.invalid_samples, 0);
    // The mean's image is not black and the Cornell box light is visible.
    assert!(finals(&a)[0].mean()[0] > 0.05);
}

/// Film configuration errors name the parameter.
#[test]
fn film_rejects_bad_configuration() {
    let w = cbox();
    let mut cfg = film_config(4, vec![8]);
    let e = film::render(&w, &cfg, |_| {}).unwrap_err().to_string();
    assert!(e.contains("checkpoints") && e.contains('8'), "{e}");
    cfg.checkpoints.clear();
    cfg.dump_pixels = vec![(500, 1)];
    let e = film::render(&w, &cfg, |_| {}).unwrap_err().to_string();
    assert!(e.contains("dump-pixels") && e.contains("500,1"), "{e}");
    cfg.dump_pixels.clear();
    cfg.spp = 0;
    assert!(film::render(&w, &cfg, |_| {}).is_err());
}

fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_fireflies"))
}

#[test]
fn render_command_writes_images_and_report() {
    let out = std::env::temp_dir().join(format!("fireflies-render-{}", std::process::id()));
    let status = bin()
        .args([
            "render",
            "experiments/scenes/cbox.xml",
            "--spp",
            "4",
            "--estimators",
            "mean,gmonb:M=5,threshold=0.3",
            "--checkpoints",
            "2",
            "--dump-pixels",
            "1,2;64,64",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(status.status.success(), "{status:?}");
    for f in [
        "mean.exr",
        "mean.png",
        "mean@2.exr",
        "gmonb_M=5_threshold=0.3.exr",
        "pixel_64_64.txt",
        "render.json",
    ] {
        assert!(out.join(f).exists(), "missing {f}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("render.json")).unwrap()).unwrap();
    assert_eq!(json["spp"], 4);
    assert!(json["samples_per_s"].as_f64().unwrap() > 0.0);
    assert_eq!(json["invalid_samples"], 0);
    assert!(json["state_bytes_per_pixel"]["mean"].as_f64().unwrap() > 0.0);
    let img = fireflies::image::Image::read_exr(&out.join("mean.exr")).unwrap();
    assert_eq!((img.width(), img.height()), (128, 128));
    let dumped = std::fs::read_to_string(out.join("pixel_64_64.txt")).unwrap();
    assert_eq!(dumped.lines().count(), 4);
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn render_command_errors_name_the_problem() {
    let run = |args: &[&str]| {
        let o = bin().args(args).output().unwrap();
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let e = run(&["render", "no/such/scene.xml", "--out", "/tmp/x"]);
    assert!(e.contains("no/such/scene.xml"), "{e}");
    let e = run(&[
        "render",
        "experiments/scenes/cbox.xml",
        "--estimators",
        "mean,bogus",
        "--out",
        "/tmp/x",
    ]);
    assert!(e.contains("bogus"), "{e}");
    let e = run(&[
        "render",
        "experiments/scenes/cbox.xml",
        "--spp",
        "1",
        "--out",
        "/proc/fireflies-cannot-write",
    ]);
    assert!(e.contains("/proc/fireflies-cannot-write"), "{e}");
}
