//! `fireflies reference` and `fireflies compare`, and the library's reference accumulator
//! (src/render/reference.rs): resuming equals one run, merging equals one run up to rounding,
//! threads do not matter, and wrong resumes and unwritable outputs are errors.

use fireflies::image::Image;
use fireflies::limits::MemoryLimit;
use fireflies::render::mitsuba::load_str;
use fireflies::render::reference::{Reference, SceneKey, scene_hash};
use fireflies::render::world::World;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fireflies"))
}

/// The caustic scene at 16x12 pixels: glass, a tiny light, fireflies; fast in a debug build.
fn tiny_scene() -> String {
    std::fs::read_to_string("experiments/scenes/caustic.xml")
        .unwrap()
        .replace(r#"name="width" value="128""#, r#"name="width" value="16""#)
        .replace(
            r#"name="height" value="128""#,
            r#"name="height" value="12""#,
        )
}

/// A fresh folder for one test, with the tiny scene in it.
fn folder(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fireflies-ref-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("scene.xml"), tiny_scene()).unwrap();
    dir
}

fn reference(dir: &Path, out: &str, extra: &[&str]) -> Output {
    bin()
        .arg("reference")
        .arg(dir.join("scene.xml"))
        .arg("--out")
        .arg(dir.join(out))
        .args(extra)
        .output()
        .unwrap()
}

#[track_caller]
fn ok(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The error message of a run that must fail with exit code 2.
#[track_caller]
fn fails(o: &Output) -> String {
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// 3 spp then 3 more equals 6 at once, bit for bit, whatever the thread counts: a resume
/// continues every pixel's accumulator at the next sample index.
#[test]
fn resuming_equals_one_run_on_any_threads() {
    let dir = folder("resume");
    ok(&reference(&dir, "a.exr", &["--spp", "3", "--threads", "1"]));
    let first = json(&dir.join("a.exr.json"));
    assert_eq!(first["spp"], 3);
    ok(&reference(
        &dir,
        "a.exr",
        &["--spp", "3", "--resume", "--threads", "2"],
    ));
    ok(&reference(&dir, "b.exr", &["--spp", "6", "--threads", "2"]));
    let state = |n: &str| std::fs::read(dir.join(n)).unwrap();
    assert!(state("a.exr.state") == state("b.exr.state"));
    assert_eq!(
        Image::read_exr(&dir.join("a.exr")).unwrap(),
        Image::read_exr(&dir.join("b.exr")).unwrap()
    );
    let (a, b) = (json(&dir.join("a.exr.json")), json(&dir.join("b.exr.json")));
    assert_eq!(a["spp"], 6);
    assert_eq!(a["sample_ranges"], serde_json::json!([[0, 6]]));
    assert_eq!(a["last_run"]["sample_range"], serde_json::json!([3, 6]));
    assert_eq!(a["accuracy"], b["accuracy"]);
    assert_eq!(a["scene_hash"], scene_hash(&tiny_scene()).as_str());
    // More samples, smaller error (the caustic scene is noisy at every pixel).
    let rel = |v: &serde_json::Value| v["accuracy"]["pixel_relative_se_rms"].as_f64().unwrap();
    assert!(rel(&a) > 0.0 && rel(&a) < rel(&first), "{a}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn wrong_resumes_are_errors() {
    let dir = folder("wrong");
    // Nothing to resume.
    let e = fails(&reference(&dir, "r.exr", &["--spp", "1", "--resume"]));
    assert!(
        e.contains("r.exr.state") && e.contains("nothing to resume"),
        "{e}"
    );
    ok(&reference(&dir, "r.exr", &["--spp", "2"]));
    let before = std::fs::read(dir.join("r.exr.state")).unwrap();
    // A second fresh run would throw the first away.
    let e = fails(&reference(&dir, "r.exr", &["--spp", "1"]));
    assert!(e.contains("--resume"), "{e}");
    // Samples already in the reference.
    let e = fails(&reference(
        &dir,
        "r.exr",
        &["--spp", "2", "--resume", "--seed-start", "1"],
    ));
    assert!(e.contains("[1, 3)") && e.contains("[0, 2)"), "{e}");
    // Another seed.
    let e = fails(&reference(
        &dir,
        "r.exr",
        &["--spp", "1", "--resume", "--seed", "5"],
    ));
    assert!(e.contains("seed"), "{e}");
    // Another filter setting.
    let e = fails(&reference(
        &dir,
        "r.exr",
        &["--spp", "1", "--resume", "--rfilter", "box"],
    ));
    assert!(e.contains("rfilter"), "{e}");
    // Another scene: one light brighter.
    let other = tiny_scene().replace("1600.0, 1440.0, 1200.0", "1700.0, 1440.0, 1200.0");
    std::fs::write(dir.join("scene.xml"), &other).unwrap();
    let e = fails(&reference(&dir, "r.exr", &["--spp", "1", "--resume"]));
    assert!(
        e.contains("another scene")
            && e.contains(&scene_hash(&other))
            && e.contains(&scene_hash(&tiny_scene())),
        "{e}"
    );
    // None of these touched the reference.
    assert!(std::fs::read(dir.join("r.exr.state")).unwrap() == before);
    // A gap is allowed: samples [10, 12) are as independent as [2, 4).
    std::fs::write(dir.join("scene.xml"), tiny_scene()).unwrap();
    ok(&reference(
        &dir,
        "r.exr",
        &["--spp", "2", "--resume", "--seed-start", "10"],
    ));
    let j = json(&dir.join("r.exr.json"));
    assert_eq!(j["sample_ranges"], serde_json::json!([[0, 2], [10, 12]]));
    assert_eq!(j["spp"], 4);
    let e = fails(&reference(&dir, "r.exr", &["--spp", "0"]));
    assert!(e.contains("spp"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn unwritable_output_is_an_error_before_rendering() {
    let dir = folder("unwritable");
    std::fs::write(dir.join("file"), b"not a folder").unwrap();
    let e = fails(&reference(&dir, "file/r.exr", &["--spp", "1000000"]));
    assert!(e.contains("file/r.exr"), "{e}");
    let e = fails(&reference(&dir, "", &["--spp", "1"]));
    assert!(e.contains("directory") || e.contains("not a file"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn world() -> World {
    World::new(&load_str(&tiny_scene(), Path::new("experiments/scenes"), "tiny.xml").unwrap())
}

fn empty(world: &World, seed: u64) -> Reference {
    let key = SceneKey {
        path: "tiny.xml".into(),
        hash: scene_hash(&tiny_scene()),
        box_filter: false,
    };
    let (w, h) = (world.camera.width(), world.camera.height());
    Reference::new(key, w, h, seed, MemoryLimit(1 << 30)).unwrap()
}

/// Samples [0, 4) and [4, 9) traced apart and merged (Chan et al.) equal samples [0, 9) traced
/// at once up to rounding; traced on 1 and 2 threads, bit for bit.
#[test]
fn merging_two_ranges_matches_one_run() {
    let w = world();
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let mut whole = empty(&w, 11);
    pool(2).install(|| whole.trace(&w, 0..9)).unwrap();
    let mut one_thread = empty(&w, 11);
    pool(1).install(|| one_thread.trace(&w, 0..9)).unwrap();
    assert_eq!(whole, one_thread);

    let (mut a, mut b) = (empty(&w, 11), empty(&w, 11));
    a.trace(&w, 0..4).unwrap();
    b.trace(&w, 4..9).unwrap();
    a.merge(&b).unwrap();
    assert_eq!(a.ranges(), &[[0, 9]]);
    assert_eq!(a.spp(), 9);
    let mut worst = 0.0f64;
    for (p, q) in a.pixels().iter().zip(whole.pixels()) {
        assert_eq!(p.count(), q.count());
        let (pm, qm) = (p.mean_rgb(), q.mean_rgb());
        for c in 0..3 {
            worst = worst.max((pm[c] - qm[c]).abs() / qm[c].abs().max(1e-300));
        }
        for (x, y) in p.m2().iter().zip(q.m2()) {
            worst = worst.max((x - y).abs() / y.abs().max(1e-300));
        }
    }
    assert!(worst <= 1e-12, "worst relative difference {worst:e}");
    // Merging overlapping ranges or another seed is refused.
    let e = a.merge(&b).unwrap_err().to_string();
    assert!(e.contains("[4, 9)"), "{e}");
    let mut c = empty(&w, 12);
    c.trace(&w, 20..21).unwrap();
    assert!(a.merge(&c).is_err());
    // The state file keeps all of it.
    assert_eq!(Reference::from_bytes(&a.to_bytes(), "a").unwrap(), a);
}

/// A scene of nothing but a constant environment: every sample is its radiance, so the mean is
/// exact and the standard errors are 0.
#[test]
fn constant_scene_has_exact_mean_and_no_error() {
    let dir = folder("constant");
    let scene = r#"<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="4"/></integrator>
        <sensor type="perspective">
            <float name="fov" value="40"/>
            <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="11"/><rfilter type="box"/></film>
            <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        </sensor>
        <emitter type="constant"><rgb name="radiance" value="0.5, 0.25, 2.0"/></emitter>
    </scene>"#;
    std::fs::write(dir.join("scene.xml"), scene).unwrap();
    ok(&reference(&dir, "c.exr", &["--spp", "5"]));
    let img = Image::read_exr(&dir.join("c.exr")).unwrap();
    assert_eq!((img.width(), img.height()), (12, 11));
    assert!(img.pixels().iter().all(|&p| p == [0.5, 0.25, 2.0]));
    let a = &json(&dir.join("c.exr.json"))["accuracy"];
    assert_eq!(a["spp"], 5);
    for k in [
        "pixel_relative_se_rms",
        "image_mean_relative_se",
        "expected_rmse",
        "expected_relmse",
    ] {
        assert_eq!(a[k], 0.0, "{k}: {a}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `compare` reads two EXRs and prints the metrics of tests/image_metrics.rs's constant-offset
/// case: grey 0.375 against grey 0.25.
#[test]
fn compare_prints_the_metrics_of_two_exrs() {
    let dir = folder("compare");
    let grey = |v: f32| Image::from_pixels(11, 12, vec![[v; 3]; 132]).unwrap();
    grey(0.375).write_exr(&dir.join("x.exr")).unwrap();
    grey(0.25).write_exr(&dir.join("r.exr")).unwrap();
    let run = |args: &[&str]| {
        bin()
            .arg("compare")
            .arg(dir.join("x.exr"))
            .arg("--reference")
            .arg(dir.join("r.exr"))
            .args(args)
            .output()
            .unwrap()
    };
    let o = run(&["--json"]);
    ok(&o);
    let text = String::from_utf8(o.stdout).unwrap();
    assert_eq!(text.lines().count(), 1);
    let m: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(m["image"].as_str().unwrap().ends_with("x.exr"));
    assert_eq!(m["rmse"], 0.125);
    assert_eq!(m["mean_bias"], 0.125);
    assert_eq!(m["mean_bias_relative"], 0.5);
    assert_eq!(m["firefly_pixels"], 0);
    assert_eq!(
        (m["width"].as_u64(), m["height"].as_u64()),
        (Some(11), Some(12))
    );
    assert!(
        (m["ssim"].as_f64().unwrap() - 0.983_177_975_888_223_4).abs() < 1e-12,
        "{m}"
    );
    // A factor of 1 and no floor count every brighter pixel.
    let o = run(&["--json", "--firefly-factor", "1", "--firefly-floor", "0"]);
    ok(&o);
    let m: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(m["firefly_pixels"], 132);
    let o = run(&[]);
    ok(&o);
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(text.contains("ssim") && text.contains("+50.000%"), "{text}");
    let e = fails(&run(&["--firefly-factor", "0.5"]));
    assert!(e.contains("firefly-factor"), "{e}");
    // Sizes differ: both are named.
    Image::new(11, 13).write_exr(&dir.join("r.exr")).unwrap();
    let e = fails(&run(&[]));
    assert!(e.contains("11x12") && e.contains("11x13"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
