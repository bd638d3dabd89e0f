//! `fireflies scenes` (src/scenes/): the experiment file parses and its errors name the file
//! and the entry; a tiny run writes one metrics row per estimator and checkpoint, the tables
//! and the figures, and reuses its cached reference; Buisine et al.'s tables on hand-made rows.

use fireflies::Error;
use fireflies::scenes::ScenesExperiment;
use fireflies::scenes::tables::{
    Family, MetricRow, read_metrics_csv, spp_to_reach, table1, table2, zirr_points,
};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fireflies"))
}

/// A fresh folder for one test.
fn folder(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fireflies-scenes-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn the_experiment_file_parses_full_and_quick() {
    let path = Path::new("experiments/scenes.toml");
    let full = ScenesExperiment::load(path, false).unwrap();
    let names: Vec<&str> = full.scenes.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        names,
        ["cbox", "caustic", "mirror_room", "veach_mis", "living-room"]
    );
    // mean, 3 x 5 of the MoN family, Jung, 2 x 6 Zirr, zirr-ref, two Pajot.
    assert_eq!(full.estimators.len(), 32);
    assert_eq!(full.plot.len(), 9);
    let living = &full.scenes[4];
    assert!(living.box_filter);
    assert_eq!((living.width, living.height), (320, 180));
    let cbox = &full.scenes[0];
    assert!(cbox.checkpoints.contains(&100) && cbox.checkpoints.contains(&512));
    assert_eq!(cbox.checkpoints.last(), Some(&cbox.spp));

    let quick = ScenesExperiment::load(path, true).unwrap();
    assert!(quick.quick);
    for (q, f) in quick.scenes.iter().zip(&full.scenes) {
        assert!(q.width < f.width && q.height < f.height, "{}", q.name);
        assert!(q.width >= 11 && q.height >= 11);
        assert!(q.spp <= 64 && q.reference_spp <= 512);
        assert!(!q.checkpoints.contains(&100));
    }
}

/// The experiment text with one line replaced, parsed from the real folder.
fn parse_with(from: &str, to: &str) -> Result<ScenesExperiment, Error> {
    let text = std::fs::read_to_string("experiments/scenes.toml").unwrap();
    assert!(text.contains(from), "{from}");
    let text = text.replacen(from, to, 1);
    ScenesExperiment::from_toml(&text, "scenes-test.toml", Path::new("experiments"), false)
}

#[track_caller]
fn fails_naming(from: &str, to: &str, words: &[&str]) {
    let e = parse_with(from, to).unwrap_err().to_string();
    assert!(e.contains("scenes-test.toml"), "{e}");
    for w in words {
        assert!(e.contains(w), "'{w}' not in: {e}");
    }
}

#[test]
fn errors_name_the_file_and_the_entry() {
    fails_naming(
        r#""mon:M=5", "gmonb:M=5""#,
        r#""mon:M=0", "gmonb:M=5""#,
        &[r#"estimators[1] = "mon:M=0""#],
    );
    fails_naming(
        r#""mon:M=5", "gmonb:M=5""#,
        r#""mon:M=5", "mon:M=5""#,
        &["estimators[2]", "repeats"],
    );
    fails_naming(
        r#""mean", "mon:M=21", "gmonb:M=21", "gmon:M=21", "jung"#,
        r#""mean", "mon:M=22", "gmonb:M=21", "gmon:M=21", "jung"#,
        &[r#"plot_estimators[1] = "mon:M=22""#, "not one of"],
    );
    fails_naming(
        r#"delayed_estimators = ["pajot-hybrid"#,
        r#"delayed_estimators = ["mean", "pajot-hybrid"#,
        &["delayed_estimators[0]", "Pajot"],
    );
    fails_naming(
        "width = 160",
        "width = 5",
        &[r#"scenes[3] ("veach_mis").width = 5"#, "at least 11"],
    );
    fails_naming(
        r#"file = "scenes/caustic.xml""#,
        r#"file = "scenes/caustik.xml""#,
        &[r#"scenes[1] ("caustic").file"#, "caustik.xml"],
    );
    fails_naming(
        r#"rfilter = "box""#,
        r#"rfilter = "tent""#,
        &[r#"scenes[4] ("living-room").rfilter"#, "box"],
    );
    fails_naming(
        r#"name = "caustic""#,
        r#"name = "cbox""#,
        &[r#"scenes[1] ("cbox").name"#, "repeats"],
    );
    fails_naming(
        "crop_spp = 64",
        "crop_spp = 48",
        &["crop_spp = 48", "checkpoint"],
    );
    fails_naming("seed = 0", "seed = 0\nsede = 1", &["sede", "line"]);
    fails_naming(
        "resolution = 0.25",
        "resolution = 2",
        &["quick", "resolution"],
    );
}

/// A tiny experiment on the caustic scene at 16x12: four estimators, 16 spp, a 64-spp reference.
fn tiny_experiment(dir: &Path) -> PathBuf {
    let scene = std::fs::canonicalize("experiments/scenes/caustic.xml").unwrap();
    let text = format!(
        r#"seed = 3
estimators = ["mean", "gmon:M=5", "zirr:b=8,kappa=1", "pajot-hybrid:learn=50,T=2,delta=0"]
extra_checkpoints = [100, 12]
delayed_spp = 20
delayed_estimators = ["pajot-hybrid:learn=50,T=2,delta=0"]
plot_estimators = ["mean", "gmon:M=5"]
bias_map_estimators = ["mean", "gmon:M=5"]
crop_estimators = ["mean", "zirr:b=8,kappa=1"]
crop_spp = 8
cost = {{ pixels = 16, spp = 8, repeats = 1, mean_render_spp = 4 }}
quick = {{ resolution = 0.5, spp = 16, reference_spp = 64 }}

[[scenes]]
name = "tiny"
file = "{}"
width = 32
height = 24
spp = 64
reference_spp = 1024
"#,
        scene.display()
    );
    let path = dir.join("tiny.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn scenes(dir: &Path, exp: &Path) -> Output {
    bin()
        .arg("scenes")
        .arg(exp)
        .arg("--quick")
        .arg("--out")
        .arg(dir.join("report"))
        .args(["--threads", "2"])
        .output()
        .unwrap()
}

#[test]
fn a_tiny_quick_run_writes_rows_tables_and_figures_and_reuses_its_reference() {
    let dir = folder("tiny");
    let exp = tiny_experiment(&dir);
    let o = scenes(&dir, &exp);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{log}");
    assert!(log.contains("tracing reference"), "{log}");
    let report = dir.join("report");
    let text = std::fs::read_to_string(report.join("metrics.csv")).unwrap();
    let rows = read_metrics_csv(&text, "metrics.csv").unwrap();
    // Quick: 16x12 pixels, 16 spp; checkpoints 1, 2, 4, 8, 12, 16 (100 is beyond the budget).
    let checkpoints = [1, 2, 4, 8, 12, 16];
    assert_eq!(rows.len(), 4 * checkpoints.len());
    for est in [
        "mean",
        "gmon:M=5",
        "zirr:b=8,J=auto,kappa=1,kappa_min=1,u=1",
        "pajot-hybrid:learn=50,T=2,delta=0",
    ] {
        let spps: Vec<u32> = rows
            .iter()
            .filter(|r| r.estimator == est)
            .map(|r| r.spp)
            .collect();
        assert_eq!(spps, checkpoints, "{est}");
    }
    for r in &rows {
        assert_eq!(r.scene, "tiny");
        assert!(r.ssim.is_finite() && r.ssim <= 1.0, "{r:?}");
        assert!(r.rmse >= 0.0 && r.relmse >= 0.0);
        assert!(
            r.render_cpu_s > r.estimator_cpu_s && r.estimator_cpu_s > 0.0,
            "{r:?}"
        );
    }
    // More samples make the mean better on this scene.
    let mean = |spp| {
        rows.iter()
            .find(|r| r.estimator == "mean" && r.spp == spp)
            .unwrap()
            .relmse
    };
    assert!(mean(16) < mean(1));
    for f in [
        "costs.csv",
        "delayed.csv",
        "scenes.csv",
        "table1.csv",
        "table2.csv",
        "zirr_kappa.csv",
        "ranking.csv",
        "manifest.json",
        "ssim_vs_spp.png",
        "relmse_vs_spp.png",
        "speed_vs_error.png",
        "zirr_kappa.png",
        "bias_tiny.png",
        "crops.png",
    ] {
        let len = std::fs::metadata(report.join(f))
            .unwrap_or_else(|e| panic!("{f}: {e}"))
            .len();
        assert!(len > 0, "{f}");
    }
    let summary = std::fs::read_to_string(report.join("summary.md")).unwrap();
    assert!(summary.contains("QUICK RUN"), "{summary}");
    assert!(summary.contains("Table 1") && summary.contains("Table 4"));
    let info = std::fs::read_to_string(report.join("scenes.csv")).unwrap();
    let (head, values) = (
        info.lines().next().unwrap().split(',').collect::<Vec<_>>(),
        info.lines().nth(1).unwrap().split(',').collect::<Vec<_>>(),
    );
    let col = |name: &str| values[head.iter().position(|h| *h == name).unwrap()];
    assert_eq!(col("mean_render_spp"), "4");
    assert!(col("mean_render_ns_per_sample").parse::<f64>().unwrap() > 0.0);
    assert_eq!(col("reference_spp"), "64");
    let costs = std::fs::read_to_string(report.join("costs.csv")).unwrap();
    assert_eq!(costs.lines().count(), 1 + 4);
    let delayed = std::fs::read_to_string(report.join("delayed.csv")).unwrap();
    assert_eq!(delayed.lines().count(), 1 + 1);
    // Table 2 has one row per estimator, with a cell per threshold.
    let t2 = std::fs::read_to_string(report.join("table2.csv")).unwrap();
    assert_eq!(t2.lines().count(), 1 + 4);
    assert!(t2.lines().next().unwrap().ends_with("spp_to_ssim_0.8"));
    let reference = report.join("references").join("tiny-16x12.exr.state");
    assert!(reference.is_file());

    // A second run reuses the reference and renders the same images.
    let o = scenes(&dir, &exp);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{log}");
    assert!(log.contains("reference reused"), "{log}");
    let again = read_metrics_csv(
        &std::fs::read_to_string(report.join("metrics.csv")).unwrap(),
        "metrics.csv",
    )
    .unwrap();
    for (a, b) in rows.iter().zip(&again) {
        assert_eq!((a.rmse, a.ssim, a.spp), (b.rmse, b.ssim, b.spp));
    }
    // It traced nothing this time, and still knows what the reference took to trace.
    let info = std::fs::read_to_string(report.join("scenes.csv")).unwrap();
    let values: Vec<&str> = info.lines().nth(1).unwrap().split(',').collect();
    let col = |name: &str| values[head.iter().position(|h| *h == name).unwrap()];
    assert_eq!(col("reference_wall_s"), "0.0");
    assert!(col("reference_total_wall_s").parse::<f64>().unwrap() > 0.0);
    let summary = std::fs::read_to_string(report.join("summary.md")).unwrap();
    assert!(summary.contains("the references took"), "{summary}");
    let _ = std::fs::remove_dir_all(&dir);
}

fn row(scene: &str, estimator: &str, spp: u32, ssim: f64) -> MetricRow {
    MetricRow {
        scene: scene.into(),
        estimator: estimator.into(),
        label: estimator.into(),
        spp,
        rmse: 1.0 - ssim,
        relmse: 1.0 - ssim,
        psnr_db: 0.0,
        ssim,
        mean_bias: 0.0,
        mean_bias_relative: Some(0.0),
        firefly_pixels: 0,
        firefly_fraction: 0.0,
        render_cpu_s: 0.0,
        estimator_cpu_s: 0.0,
    }
}

#[test]
fn table2_reports_the_first_checkpoint_reaching_each_level_or_nr() {
    // Rising, dipping, rising: 0.6 is reached at 2 and stays reached after the dip at 4.
    let pts = [(8, 0.75), (1, 0.5), (4, 0.62), (2, 0.65), (16, 0.79)];
    assert_eq!(spp_to_reach(&pts, 0.6), Some(2));
    assert_eq!(spp_to_reach(&pts, 0.7), Some(8));
    assert_eq!(spp_to_reach(&pts, 0.8), None);
    // Exactly at the level counts as reached.
    assert_eq!(spp_to_reach(&pts, 0.79), Some(16));
    assert_eq!(spp_to_reach(&[], 0.1), None);

    let mut rows = vec![
        row("a", "mean", 1, 0.3),
        row("a", "mean", 2, 0.61),
        row("a", "mean", 4, 0.72),
        // 100 is not a power of two and is left out of Table 2.
        row("a", "mean", 100, 0.95),
        row("a", "gmon:M=5", 1, 0.65),
        row("a", "gmon:M=5", 2, 0.85),
        row("a", "gmon:M=5", 4, 0.9),
    ];
    rows.push(row("b", "mean", 1, 0.1));
    let t = table2(&rows, &[0.6, 0.7, 0.8]);
    assert_eq!(t.len(), 3);
    assert_eq!(
        (t[0].scene.as_str(), t[0].estimator.as_str()),
        ("a", "mean")
    );
    assert_eq!(t[0].reached, vec![Some(2), Some(4), None]);
    assert_eq!(t[1].reached, vec![Some(1), Some(2), Some(2)]);
    assert_eq!(t[2].reached, vec![None, None, None]);
}

#[test]
fn table1_ranks_the_four_methods_per_scene_and_m_at_the_largest_spp() {
    let mut rows = Vec::new();
    for (scene, mean, by_m) in [
        // Scene x: at M=5 G-MoN best, MoN and G-MoN_b tied second; at M=21 the mean best.
        (
            "x",
            0.70,
            [(5, [0.80, 0.80, 0.90]), (21, [0.60, 0.65, 0.68])],
        ),
        (
            "y",
            0.50,
            [(5, [0.40, 0.55, 0.45]), (21, [0.52, 0.51, 0.49])],
        ),
    ] {
        // An earlier checkpoint with other values must be ignored.
        rows.push(row(scene, "mean", 8, 0.99));
        rows.push(row(scene, "mean", 64, mean));
        for (m, [mon, gmonb, gmon]) in by_m {
            rows.push(row(scene, &format!("mon:M={m}"), 8, 0.0));
            rows.push(row(scene, &format!("mon:M={m}"), 64, mon));
            rows.push(row(
                scene,
                &format!("gmonb:M={m},threshold=0.25"),
                64,
                gmonb,
            ));
            rows.push(row(scene, &format!("gmon:M={m}"), 64, gmon));
        }
        rows.push(row(scene, "zirr:b=8,kappa=1", 64, 1.0));
    }
    let t = table1(&rows);
    assert_eq!(t.len(), 2 * 2 * 4);
    let rank = |scene: &str, m: usize, f: Family| {
        let r = t
            .iter()
            .find(|r| r.scene == scene && r.m == m && r.method == f)
            .unwrap();
        assert_eq!(r.spp, 64);
        (r.ssim, r.rank)
    };
    assert_eq!(rank("x", 5, Family::Gmon), (0.90, 1));
    assert_eq!(rank("x", 5, Family::Mon), (0.80, 2));
    assert_eq!(rank("x", 5, Family::GmonB), (0.80, 2));
    assert_eq!(rank("x", 5, Family::Mean), (0.70, 4));
    assert_eq!(rank("x", 21, Family::Mean), (0.70, 1));
    assert_eq!(rank("x", 21, Family::Mon), (0.60, 4));
    assert_eq!(rank("y", 5, Family::GmonB).1, 1);
    assert_eq!(rank("y", 5, Family::Mon).1, 4);
    assert_eq!(rank("y", 21, Family::Mon).1, 1);
    assert_eq!(rank("y", 21, Family::Mean).1, 3);
    assert_eq!(rank("y", 21, Family::Gmon).1, 4);
    // Zirr is not one of Table 1's methods; it is a point of the Zirr figure.
    let z = zirr_points(&rows);
    assert_eq!(z.len(), 2);
    assert_eq!((z[0].b, z[0].kappa, z[0].rmse), (8.0, 1.0, 0.0));
    assert_eq!(z[0].mean_rmse, Some(1.0 - 0.70));
}
