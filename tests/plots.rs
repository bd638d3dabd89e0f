//! Plots are drawn from tidy rows alone: every figure is written as PNG and SVG, the PNG decodes
//! at the size the layout promises, and a directory that cannot be written is an error naming
//! it. `render_results_csv` (ignored) draws the plots of a real run for a person to look at.

use fireflies::report::plots::write_plots;
use fireflies::report::tables::{Row, read_results_csv};
use std::path::{Path, PathBuf};

const FIGURES: [&str; 6] = [
    "median_error",
    "bias",
    "variance_mse",
    "firefly_rate",
    "error_quantiles",
    "speed_vs_error",
];

fn row(d: &str, e: &str, n: usize, metric: &str, value: f64, ci: Option<(f64, f64)>) -> Row {
    Row {
        distribution: d.into(),
        estimator: e.into(),
        n,
        metric: metric.parse().unwrap(),
        value,
        ci_low: ci.map(|c| c.0),
        ci_high: ci.map(|c| c.1),
        se: ci.map(|c| (c.1 - c.0) / 3.92),
        level: ci.map(|_| 0.95),
        caveat: None,
    }
}

/// 2 distributions x 3 estimators x 4 sample counts of plausible values. The plain mean on the
/// infinite-variance law has no interval for bias, variance, MSE and relative RMSE, as in a
/// real run; one firefly rate is zero and one variance is zero (not drawable on a log axis).
fn synthetic() -> Vec<Row> {
    let ns = [16, 64, 256, 1024];
    let mut rows = Vec::new();
    for (di, d) in ["diffuse", "infinite-variance"].into_iter().enumerate() {
        for (ei, e) in ["mean", "mon:M=21", "gmon:M=21,threshold=0.25"]
            .into_iter()
            .enumerate()
        {
            let no_ci = di == 1 && e == "mean";
            let spread = 1.0 + di as f64 * 3.0 + ei as f64 * 0.2;
            for &n in &ns {
                let nf = n as f64;
                let ci = |v: f64, w: f64| if no_ci { None } else { Some((v - w, v + w)) };
                let var = if di == 0 && ei == 1 && n == 16 {
                    0.0
                } else {
                    spread / nf
                };
                let bias = -0.3 * ei as f64 / nf.sqrt() + 0.01 * di as f64;
                let mse = var + bias * bias;
                let med = 0.67 * (spread / nf).sqrt();
                rows.push(row(d, e, n, "bias", bias, ci(bias, 0.02)));
                rows.push(row(d, e, n, "variance", var, ci(var, 0.2 * var)));
                rows.push(row(d, e, n, "mse", mse, ci(mse, 0.2 * mse)));
                rows.push(row(
                    d,
                    e,
                    n,
                    "relative_rmse",
                    mse.sqrt(),
                    ci(mse.sqrt(), 0.01),
                ));
                rows.push(row(
                    d,
                    e,
                    n,
                    "median_abs_rel_error",
                    med,
                    Some((0.9 * med, 1.1 * med)),
                ));
                for (q, f) in [
                    (5, 0.06),
                    (25, 0.3),
                    (50, 1.0),
                    (75, 1.7),
                    (95, 3.0),
                    (99, 4.0),
                ] {
                    rows.push(row(d, e, n, &format!("rel_error_q{q:02}"), f * med, None));
                }
                let rate = if ei == 0 {
                    0.05 / (1.0 + di as f64)
                } else {
                    0.0
                };
                rows.push(row(
                    d,
                    e,
                    n,
                    "firefly_rate",
                    rate,
                    Some((0.0, rate + 0.0075)),
                ));
            }
            let n = *ns.last().unwrap();
            rows.push(row(d, e, n, "ns_per_sample", 2.0 + 3.0 * ei as f64, None));
            rows.push(row(d, e, n, "state_bytes_max", 200.0, None));
        }
    }
    rows
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fireflies-plots-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn check_written(dir: &Path, written: &[PathBuf]) {
    for name in FIGURES {
        for ext in ["png", "svg"] {
            let path = dir.join(format!("{name}.{ext}"));
            assert!(written.contains(&path), "{} not reported", path.display());
            let bytes = std::fs::read(&path).unwrap();
            assert!(
                bytes.len() > 1000,
                "{} has {} bytes",
                path.display(),
                bytes.len()
            );
        }
        let png = image::open(dir.join(format!("{name}.png"))).unwrap();
        // Panels are at least 400 px wide and there are at least two per row (two
        // distributions), plus a header above them.
        assert!(png.width() >= 800, "{name}: width {}", png.width());
        assert!(png.height() >= 300 + 60, "{name}: height {}", png.height());
        let svg = std::fs::read_to_string(dir.join(format!("{name}.svg"))).unwrap();
        assert!(
            svg.starts_with("<svg"),
            "{name}.svg does not start with <svg"
        );
        assert!(svg.contains("mon:M=21"), "{name}.svg lacks the legend");
    }
    assert_eq!(written.len(), 2 * FIGURES.len(), "{written:?}");
    // Nothing but the figures: no temporary files left behind.
    assert_eq!(std::fs::read_dir(dir).unwrap().count(), written.len());
}

#[test]
fn every_figure_is_written_as_png_and_svg() {
    let dir = scratch("synthetic");
    let written = write_plots(&dir, &synthetic()).unwrap();
    check_written(&dir, &written);
    // Panel grids: two distributions side by side at 480 px; the fans have one column per
    // estimator at 400 px; variance and MSE sit side by side for each distribution.
    let width = |name: &str| {
        image::open(dir.join(format!("{name}.png")))
            .unwrap()
            .width()
    };
    assert_eq!(width("bias"), 2 * 480);
    assert_eq!(width("error_quantiles"), 3 * 400);
    assert_eq!(width("variance_mse"), 4 * 480);
    // The missing interval is said in the figure, not silently dropped.
    let bias_svg = std::fs::read_to_string(dir.join("bias.svg")).unwrap();
    assert!(
        bias_svg.contains("No band for mean on infinite-variance"),
        "note missing"
    );
    // Writing again replaces the files in place.
    let again = write_plots(&dir, &synthetic()).unwrap();
    assert_eq!(again, written);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn no_rows_no_files() {
    let dir = scratch("empty");
    assert!(write_plots(&dir, &[]).unwrap().is_empty());
}

#[test]
fn unwritable_directory_is_an_error_naming_the_path() {
    let e = write_plots(Path::new("/proc/fireflies-plots"), &synthetic()).unwrap_err();
    assert!(e.to_string().contains("/proc/fireflies-plots"), "{e}");
}

#[test]
fn figures_survive_a_csv_round_trip() {
    let dir = scratch("csv");
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("results.csv");
    let mut w = csv::Writer::from_path(&csv).unwrap();
    for r in synthetic() {
        w.serialize(r).unwrap();
    }
    w.flush().unwrap();
    drop(w);
    let rows = read_results_csv(&csv).unwrap();
    let out = dir.join("plots");
    let written = write_plots(&out, &rows).unwrap();
    check_written(&out, &written);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Draws the plots of a real run next to its CSV:
/// `FIREFLIES_RESULTS=reports/default/results.csv cargo test --test suite -- plots:: --ignored`.
#[test]
#[ignore = "needs FIREFLIES_RESULTS pointing at a results.csv"]
fn render_results_csv() {
    let Ok(csv) = std::env::var("FIREFLIES_RESULTS") else {
        panic!("set FIREFLIES_RESULTS to the path of a results.csv");
    };
    let csv = PathBuf::from(csv);
    let rows = read_results_csv(&csv).unwrap();
    let dir = csv.parent().unwrap_or(Path::new("."));
    for p in write_plots(dir, &rows).unwrap() {
        println!("{}", p.display());
    }
}
