//! The report of `fireflies transfer` ([`super::transfer`]): `transfer.csv` (one row per
//! pixel, estimator and n: measured and predicted relative RMSE and bias with their 95%
//! intervals, and the prediction error), `pixels.csv` (truth and fit per pixel), `summary.md`
//! and `predicted_vs_measured.png`. Every file is written atomically.

use super::transfer::{Cell, PixelResult, Ranking, TransferExperiment, rankings};
use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::harness::metrics::LEVEL;
use crate::report::plots::{Coord, FONT, PALETTE, REF_GREY, fmt_tick, register_fonts, ticks};
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// How the run was made, for the summary.
#[derive(Debug, Clone)]
pub struct RunInfo {
    /// The command line.
    pub command: String,
    /// Wall seconds so far.
    pub wall_s: f64,
    /// Worker threads.
    pub threads: usize,
    /// Pixels not yet done (a report written part-way says so).
    pub pending: Vec<String>,
}

/// One row of `transfer.csv`.
#[derive(Debug, Serialize)]
struct CsvRow<'a> {
    pixel: &'a str,
    class: &'a str,
    estimator: &'a str,
    n: usize,
    measured_rel_rmse: f64,
    measured_rel_rmse_low: Option<f64>,
    measured_rel_rmse_high: Option<f64>,
    measured_rel_rmse_se: Option<f64>,
    measured_rel_rmse_caveat: Option<&'a str>,
    predicted_rel_rmse: f64,
    predicted_rel_rmse_low: Option<f64>,
    predicted_rel_rmse_high: Option<f64>,
    predicted_rel_rmse_se: Option<f64>,
    predicted_rel_rmse_caveat: Option<&'a str>,
    prediction_error: f64,
    prediction_error_se: Option<f64>,
    measured_rel_bias: f64,
    measured_rel_bias_low: Option<f64>,
    measured_rel_bias_high: Option<f64>,
    predicted_rel_bias: f64,
    predicted_rel_bias_low: Option<f64>,
    predicted_rel_bias_high: Option<f64>,
    rel_bias_abs_difference: f64,
    renders: u64,
    trials: u64,
    level: f64,
}

/// One row of `pixels.csv`.
#[derive(Debug, Serialize)]
struct PixelRow<'a> {
    pixel: &'a str,
    class: &'a str,
    truth: f64,
    truth_rel_se: f64,
    truth_spp: u64,
    truth_seed: u64,
    fit_samples: u64,
    fit_seed: u64,
    fitted_mean: f64,
    fitted_mean_rel_error: f64,
    fitted_mean_rel_error_se: f64,
    fit_stream_rel_se: f64,
    fit_components: usize,
    fit_tail_shape: Option<f64>,
    fitted_law: String,
    renders: u64,
    render_spp: usize,
    trials: u64,
    invalid_samples: u64,
}

fn csv_bytes<T: Serialize>(name: &str, rows: impl IntoIterator<Item = T>) -> Result<Vec<u8>> {
    let fail = |e: &dyn std::fmt::Display| Error::Io {
        path: name.into(),
        message: e.to_string(),
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.serialize(r).map_err(|e| fail(&e))?;
    }
    w.into_inner().map_err(|e| fail(&e))
}

/// `transfer.csv`: nothing in it depends on timing or the thread count.
pub fn transfer_csv(results: &[PixelResult]) -> Result<Vec<u8>> {
    let rows = results.iter().flat_map(|p| {
        p.cells.iter().map(move |c| CsvRow {
            pixel: &p.label,
            class: &p.class,
            estimator: &c.estimator,
            n: c.n,
            measured_rel_rmse: c.measured_rmse.value,
            measured_rel_rmse_low: c.measured_rmse.low,
            measured_rel_rmse_high: c.measured_rmse.high,
            measured_rel_rmse_se: c.measured_rmse.se,
            measured_rel_rmse_caveat: c.measured_rmse_caveat.as_deref(),
            predicted_rel_rmse: c.predicted_rmse.value,
            predicted_rel_rmse_low: c.predicted_rmse.low,
            predicted_rel_rmse_high: c.predicted_rmse.high,
            predicted_rel_rmse_se: c.predicted_rmse.se,
            predicted_rel_rmse_caveat: c.predicted_rmse_caveat.as_deref(),
            prediction_error: c.prediction_error(),
            prediction_error_se: c.prediction_error_se(),
            measured_rel_bias: c.measured_bias.value,
            measured_rel_bias_low: c.measured_bias.low,
            measured_rel_bias_high: c.measured_bias.high,
            predicted_rel_bias: c.predicted_bias.value,
            predicted_rel_bias_low: c.predicted_bias.low,
            predicted_rel_bias_high: c.predicted_bias.high,
            rel_bias_abs_difference: c.bias_difference(),
            renders: p.renders,
            trials: p.trials,
            level: LEVEL,
        })
    });
    csv_bytes("transfer.csv", rows)
}

/// `pixels.csv`: per pixel, its truth and what the fit made of it.
pub fn pixels_csv(results: &[PixelResult]) -> Result<Vec<u8>> {
    let rows = results.iter().map(|p| PixelRow {
        pixel: &p.label,
        class: &p.class,
        truth: p.truth.mean,
        truth_rel_se: p.truth.relative_se(),
        truth_spp: p.truth.spp,
        truth_seed: p.truth.seed,
        fit_samples: p.fit.samples,
        fit_seed: p.fit.seed,
        fitted_mean: p.fit.mean,
        fitted_mean_rel_error: p.fit_error(),
        fitted_mean_rel_error_se: p.fit_error_se(),
        fit_stream_rel_se: p.fit.se / p.fit.mean,
        fit_components: p.fit.components,
        fit_tail_shape: p.fit.tail_shape,
        fitted_law: serde_json::to_string(&p.fit.spec).unwrap_or_default(),
        renders: p.renders,
        render_spp: p.render_spp,
        trials: p.trials,
        invalid_samples: p.invalid_samples,
    });
    csv_bytes("pixels.csv", rows)
}

/// Median and maximum of `|x|` over the finite values, with the index of the maximum.
fn median_max(values: &[f64]) -> Option<(f64, f64, usize)> {
    let mut finite: Vec<(f64, usize)> = values
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .map(|(i, v)| (v.abs(), i))
        .collect();
    if finite.is_empty() {
        return None;
    }
    finite.sort_by(|a, b| a.0.total_cmp(&b.0));
    let k = finite.len();
    let median = if k % 2 == 1 {
        finite[k / 2].0
    } else {
        (finite[k / 2 - 1].0 + finite[k / 2].0) / 2.0
    };
    let (max, at) = finite[k - 1];
    Some((median, max, at))
}

/// Summary of |prediction error| and |bias difference| over a set of cells.
#[derive(Debug, Clone, PartialEq)]
pub struct Agreement {
    /// Cells summarised.
    pub cells: usize,
    /// Median |prediction error|.
    pub median_pe: f64,
    /// Largest |prediction error| and where (pixel, estimator, n).
    pub max_pe: (f64, String),
    /// Cells whose prediction error lies more than 1.96 standard errors from 0.
    pub significant: usize,
    /// Cells with a standard error for the prediction error.
    pub with_se: usize,
    /// Median and largest |prediction error| over the cells where neither side is
    /// tail-dominated (their spread does not rest on a handful of trials or renders).
    pub held_pe: Option<(f64, f64)>,
    /// Cells where neither side is tail-dominated.
    pub held: usize,
    /// Median |predicted - measured relative bias|.
    pub median_bias: f64,
    /// Largest and where.
    pub max_bias: (f64, String),
}

/// [`Agreement`] over `cells` (each with its pixel label); `None` when no cell has a finite
/// prediction error.
pub fn agreement(cells: &[(&str, &Cell)]) -> Option<Agreement> {
    let where_ = |i: usize| {
        let (p, c) = cells[i];
        format!("{p}, {}, n = {}", c.estimator, c.n)
    };
    let pe: Vec<f64> = cells.iter().map(|(_, c)| c.prediction_error()).collect();
    let bias: Vec<f64> = cells.iter().map(|(_, c)| c.bias_difference()).collect();
    let (median_pe, max_pe, at_pe) = median_max(&pe)?;
    let held: Vec<f64> = cells
        .iter()
        .filter(|(_, c)| c.measured_rmse_caveat.is_none() && c.predicted_rmse_caveat.is_none())
        .map(|(_, c)| c.prediction_error())
        .collect();
    let held_pe = median_max(&held).map(|(m, x, _)| (m, x));
    let (median_bias, max_bias, at_bias) = median_max(&bias).unwrap_or((f64::NAN, f64::NAN, 0));
    let mut significant = 0;
    let mut with_se = 0;
    for (_, c) in cells {
        if let Some(se) = c.prediction_error_se()
            && se.is_finite()
            && c.prediction_error().is_finite()
        {
            with_se += 1;
            significant += usize::from(c.prediction_error().abs() > 1.96 * se);
        }
    }
    Some(Agreement {
        cells: cells.len(),
        median_pe,
        max_pe: (max_pe, where_(at_pe)),
        held_pe,
        held: held.len(),
        significant,
        with_se,
        median_bias,
        max_bias: (max_bias, where_(at_bias)),
    })
}

/// Classes in order of first appearance.
fn classes(results: &[PixelResult]) -> Vec<&str> {
    let mut out: Vec<&str> = Vec::new();
    for p in results {
        if !out.contains(&p.class.as_str()) {
            out.push(&p.class);
        }
    }
    out
}

fn pct(x: f64) -> String {
    if x.is_finite() {
        format!("{:+.1}%", 100.0 * x)
    } else {
        "–".into()
    }
}

fn abs_pct(x: f64) -> String {
    if x.is_finite() {
        format!("{:.1}%", 100.0 * x)
    } else {
        "–".into()
    }
}

/// A small percentage with two significant digits (a standard error of 0.006% stays visible).
fn small_pct(x: f64) -> String {
    if x.is_finite() && x > 0.0 {
        let digits = (1 - (100.0 * x).log10().floor() as i32).max(1) as usize;
        format!("{:.*}%", digits, 100.0 * x)
    } else {
        abs_pct(x)
    }
}

fn sci(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3e}")
    } else {
        "–".into()
    }
}

/// `summary.md`.
pub fn summary_md(exp: &TransferExperiment, results: &[PixelResult], info: &RunInfo) -> String {
    let s = &exp.settings;
    let mut md = String::new();
    let _ = writeln!(md, "# Do synthetic results transfer to scenes?\n");
    if !exp.file.description.is_empty() {
        let _ = writeln!(md, "{}\n", exp.file.description);
    }
    let _ = writeln!(
        md,
        "`{}` — {:.0} s wall on {} threads{}. For each pixel: the truth is the mean of {} camera \
         samples of one render; a generator is fitted to {} samples of another; the harness runs \
         {} trials on the fitted generator (its truth: the fitted mean) and predicts every \
         estimator's relative RMSE and bias; {} independent renders of the pixel (seeds {} + r) \
         measure them against the truth. Checkpoints {:?}. Prediction error = predicted / \
         measured relative RMSE − 1. Intervals are {:.0}%.\n",
        info.command,
        info.wall_s,
        info.threads,
        if exp.quick { " (--quick)" } else { "" },
        s.truth_spp,
        s.fit_spp,
        s.trials,
        s.renders,
        s.seed,
        s.checkpoints,
        100.0 * LEVEL,
    );
    if !info.pending.is_empty() {
        let _ = writeln!(
            md,
            "**Partial report**: still to run: {}.\n",
            info.pending.join(", ")
        );
    }

    let _ = writeln!(md, "## Transfer by pixel class\n");
    let _ = writeln!(
        md,
        "Over every estimator and n of the class's pixels: the median and largest |prediction \
         error| (also over the cells where neither side's relative RMSE is tail-dominated, i.e. rests on \
         a handful of trials or renders), how many cells' prediction error lies more than 1.96 \
         standard errors from 0 \
         (both sides' Monte Carlo error; the fit's own error is not in it), and the same for \
         |predicted − measured relative bias|.\n"
    );
    let _ = writeln!(
        md,
        "| class | pixels | cells | median abs. pred. error | largest (where) | median, largest where neither side is tail-dominated (cells) | beyond 1.96 SE | median abs. bias diff. | largest (where) |"
    );
    let _ = writeln!(md, "|---|---:|---:|---:|---|---|---:|---:|---|");
    let mut groups: Vec<(String, Vec<&PixelResult>)> = classes(results)
        .into_iter()
        .map(|c| {
            (
                c.to_string(),
                results.iter().filter(|p| p.class == c).collect(),
            )
        })
        .collect();
    groups.push(("**all**".into(), results.iter().collect()));
    for (name, pixels) in &groups {
        let cells: Vec<(&str, &Cell)> = pixels
            .iter()
            .flat_map(|p| p.cells.iter().map(move |c| (p.label.as_str(), c)))
            .collect();
        if let Some(a) = agreement(&cells) {
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} | {} ({}) | {} ({}) | {} of {} | {} | {} ({}) |",
                pixels.len(),
                a.cells,
                abs_pct(a.median_pe),
                abs_pct(a.max_pe.0),
                a.max_pe.1,
                a.held_pe.map_or("–".into(), |(m, x)| format!(
                    "{}, {}",
                    abs_pct(m),
                    abs_pct(x)
                )),
                a.held,
                a.significant,
                a.with_se,
                abs_pct(a.median_bias),
                abs_pct(a.max_bias.0),
                a.max_bias.1,
            );
        }
    }

    let _ = writeln!(md, "\n## Pixels: truth and fit\n");
    let _ = writeln!(
        md,
        "| pixel | class | scene (x, y) | truth | truth rel. SE | fitted mean − truth (± SE) | fit: parts, tail shape | invalid samples | wall s: truth, fit, renders, harness |"
    );
    let _ = writeln!(md, "|---|---|---|---:|---:|---:|---|---:|---|");
    for p in results {
        let spec = exp.pixels.iter().find(|q| q.label == p.label);
        let place = spec.map_or("–".into(), |q| {
            let size = q
                .size
                .map_or(String::new(), |(w, h)| format!(" at {w}x{h}"));
            format!("{} ({}, {}){size}", q.scene_text, q.x, q.y)
        });
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} ± {} | {}, {} | {} | {:.1}, {:.1}, {:.1}, {:.1} |",
            p.label,
            p.class,
            place,
            sci(p.truth.mean),
            small_pct(p.truth.relative_se()),
            pct(p.fit_error()),
            small_pct(p.fit_error_se()),
            p.fit.components,
            p.fit
                .tail_shape
                .map_or("none".into(), |a| format!("{a:.3}")),
            p.invalid_samples,
            p.wall_s[0],
            p.wall_s[1],
            p.wall_s[2],
            p.wall_s[3],
        );
    }
    let _ = writeln!(
        md,
        "\nThe fitted mean's standard error is that of a mean of the fit stream's length with \
         the spread of the truth's stream (the fit stream's own spread, `fit_stream_rel_se` in \
         `pixels.csv`, misses what the stream did not see). The truth's own error enters every measured relative RMSE: against a truth off by `d`, \
         an unbiased estimator's measured relative MSE gains about `d²`, and a biased one's \
         relative bias shifts by about `-d`."
    );

    let _ = writeln!(md, "\n## Transfer by estimator\n");
    let _ = writeln!(
        md,
        "Median |prediction error| of each estimator over n, per class and over every pixel.\n"
    );
    let names = classes(results);
    let _ = write!(md, "| estimator |");
    for c in &names {
        let _ = write!(md, " {c} |");
    }
    let _ = write!(md, " all |\n|---|");
    for _ in 0..=names.len() {
        let _ = write!(md, "---:|");
    }
    let _ = writeln!(md);
    let mut estimators: Vec<&str> = Vec::new();
    for c in results.iter().flat_map(|p| &p.cells) {
        if !estimators.contains(&c.estimator.as_str()) {
            estimators.push(&c.estimator);
        }
    }
    for e in estimators {
        let median = |class: Option<&str>| {
            let pe: Vec<f64> = results
                .iter()
                .filter(|p| class.is_none_or(|c| p.class == c))
                .flat_map(|p| &p.cells)
                .filter(|c| c.estimator == e)
                .map(Cell::prediction_error)
                .collect();
            median_max(&pe).map_or("–".into(), |(m, _, _)| abs_pct(m))
        };
        let _ = write!(md, "| {e} |");
        for c in &names {
            let _ = write!(md, " {} |", median(Some(c)));
        }
        let _ = writeln!(md, " {} |", median(None));
    }
    let _ = writeln!(md, "\n## Do the two sides rank the estimators alike?\n");
    let _ = writeln!(
        md,
        "Per pixel and n, the estimators ordered by relative RMSE, predicted against measured: \
         Spearman's rho, pairs ordered the other way round, and whether both pick the same best.\n"
    );
    let _ = writeln!(
        md,
        "| pixel | n | Spearman rho | swapped pairs | same best |"
    );
    let _ = writeln!(md, "|---|---:|---:|---:|---|");
    let mut total_swaps = 0;
    let mut total_pairs = 0;
    for p in results {
        for Ranking {
            n,
            spearman,
            swaps,
            pairs,
            same_best,
        } in rankings(p)
        {
            total_swaps += swaps;
            total_pairs += pairs;
            let _ = writeln!(
                md,
                "| {} | {n} | {} | {swaps} of {pairs} | {} |",
                p.label,
                if spearman.is_finite() {
                    format!("{spearman:.3}")
                } else {
                    "–".into()
                },
                if same_best { "yes" } else { "no" }
            );
        }
    }
    let _ = writeln!(
        md,
        "\nIn all: {total_swaps} of {total_pairs} pairs swapped.\n"
    );

    let _ = writeln!(md, "## Every cell\n");
    let _ = writeln!(
        md,
        "Prediction error per pixel, estimator and n, with measured → predicted relative RMSE \
         (`transfer.csv` has the intervals and the biases).\n"
    );
    for p in results {
        let _ = writeln!(md, "### {} ({})\n", p.label, p.class);
        let mut ns: Vec<usize> = p.cells.iter().map(|c| c.n).collect();
        ns.sort_unstable();
        ns.dedup();
        let _ = write!(md, "| estimator |");
        for n in &ns {
            let _ = write!(md, " n = {n} |");
        }
        let _ = write!(md, "\n|---|");
        for _ in &ns {
            let _ = write!(md, "---:|");
        }
        let _ = writeln!(md);
        let mut names: Vec<&str> = Vec::new();
        for c in &p.cells {
            if !names.contains(&c.estimator.as_str()) {
                names.push(&c.estimator);
            }
        }
        for name in names {
            let _ = write!(md, "| {name} |");
            for n in &ns {
                match p.cells.iter().find(|c| c.estimator == name && c.n == *n) {
                    Some(c) => {
                        let _ = write!(
                            md,
                            " {} ({:.3} → {:.3}) |",
                            pct(c.prediction_error()),
                            c.measured_rmse.value,
                            c.predicted_rmse.value
                        );
                    }
                    None => {
                        let _ = write!(md, " – |");
                    }
                }
            }
            let _ = writeln!(md);
        }
        let _ = writeln!(md);
    }
    let _ = writeln!(
        md,
        "Files: `transfer.csv` (one row per pixel, estimator and n), `pixels.csv` (truth and \
         fit per pixel), `predicted_vs_measured.png`."
    );
    md
}

/// Writes every file of the report into `dir` and returns their paths.
///
/// # Errors
///
/// [`Error::Io`] naming the file that could not be written or drawn.
pub fn write_report(
    dir: &Path,
    exp: &TransferExperiment,
    results: &[PixelResult],
    info: &RunInfo,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir.display(), &e))?;
    let mut files = crate::atomic::ReportFiles::new(dir);
    files.put("transfer.csv", &transfer_csv(results)?)?;
    files.put("pixels.csv", &pixels_csv(results)?)?;
    files.put("summary.md", summary_md(exp, results, info).as_bytes())?;
    let png = dir.join("predicted_vs_measured.png");
    if write_plot(&png, results)? {
        files.extend([png]);
    }
    Ok(files.into_paths())
}

/// Image size in pixels.
const SIZE: (u32, u32) = (900, 820);

/// One point of the figure: measured and predicted relative RMSE with their intervals.
struct Point {
    pixel: usize,
    x: f64,
    y: f64,
    x_interval: Option<(f64, f64)>,
    y_interval: Option<(f64, f64)>,
}

/// Draws `predicted_vs_measured.png`; `false` (nothing written) when no cell has two positive,
/// finite values.
fn write_plot(path: &Path, results: &[PixelResult]) -> Result<bool> {
    let names = classes(results);
    // One series per pixel: its shape says the class, its colour the pixel.
    let series: Vec<(String, usize)> = results
        .iter()
        .map(|p| {
            let class = names.iter().position(|c| *c == p.class).unwrap_or(0);
            (format!("{} ({})", p.label, p.class), class)
        })
        .collect();
    let ok = |v: f64| v > 0.0 && v.is_finite();
    let mut points = Vec::new();
    for (pixel, p) in results.iter().enumerate() {
        for c in &p.cells {
            let (x, y) = (c.measured_rmse.value, c.predicted_rmse.value);
            if !(ok(x) && ok(y)) {
                continue;
            }
            let interval = |low: Option<f64>, high: Option<f64>| match (low, high) {
                (Some(l), Some(h)) if ok(l) && ok(h) => Some((l, h)),
                _ => None,
            };
            points.push(Point {
                pixel,
                x,
                y,
                x_interval: interval(c.measured_rmse.low, c.measured_rmse.high),
                y_interval: interval(c.predicted_rmse.low, c.predicted_rmse.high),
            });
        }
    }
    if points.is_empty() {
        return Ok(false);
    }
    register_fonts()?;
    let (w, h) = SIZE;
    let mut buf = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        draw(&root, &points, &series)
            .and_then(|()| root.present())
            .map_err(|e| Error::Io {
                path: path.display().to_string(),
                message: e.to_string(),
            })?;
    }
    let png = crate::report::plots::encode_png(&buf, w, h).map_err(|message| Error::Io {
        path: path.display().to_string(),
        message,
    })?;
    write_atomic(path, &png)?;
    Ok(true)
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;
type DrawResult = std::result::Result<
    (),
    DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>,
>;

fn draw(root: &Area<'_>, points: &[Point], series: &[(String, usize)]) -> DrawResult {
    root.fill(&WHITE)?;
    let font = |size: f64| FontDesc::new(FontFamily::Name(FONT), size, FontStyle::Normal);
    let bold = FontDesc::new(FontFamily::Name(FONT), 22.0, FontStyle::Bold);
    root.draw_text(
        "Relative RMSE: predicted (harness on the fitted law) vs measured (renders)",
        &bold.into_text_style(root),
        (16, 12),
    )?;
    root.draw_text(
        "one point per pixel, estimator and n; bars: 95% intervals (none where a side is tail-dominated); solid: y = x; dashed: ±25%",
        &font(15.0).into_text_style(root),
        (16, 42),
    )?;
    let area = root.margin(70, 16, 16, 24);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for p in points {
        for v in [p.x, p.y] {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    let pad = 10f64.powf(0.1);
    let (lo, hi) = if hi / lo < 1.5 {
        (lo / 1.25, hi * 1.25)
    } else {
        (lo / pad, hi * pad)
    };
    let axis = || Coord {
        log: true,
        lo,
        hi,
        ticks: ticks(true, lo, hi),
    };
    let mut chart = ChartBuilder::on(&area)
        .x_label_area_size(56)
        .y_label_area_size(80)
        .build_cartesian_2d(axis(), axis())?;
    chart
        .configure_mesh()
        .x_desc("measured relative RMSE (renders of the pixel vs its truth, log scale)")
        .y_desc("predicted relative RMSE (harness on the fitted law, log scale)")
        .axis_desc_style(font(16.0))
        .label_style(font(14.0))
        .x_label_formatter(&|v| fmt_tick(*v))
        .y_label_formatter(&|v| fmt_tick(*v))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(lo, lo), (hi, hi)],
        REF_GREY.stroke_width(2),
    )))?;
    for f in [1.25, 0.8] {
        chart.draw_series(std::iter::once(DashedPathElement::new(
            vec![(lo, lo * f), (hi, hi * f)],
            6,
            4,
            REF_GREY.stroke_width(1),
        )))?;
    }
    for p in points {
        let colour = PALETTE[p.pixel % PALETTE.len()].mix(0.7);
        if let Some((l, h)) = p.x_interval {
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(l, p.y), (h, p.y)],
                colour.stroke_width(2),
            )))?;
        }
        if let Some((l, h)) = p.y_interval {
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(p.x, l), (p.x, h)],
                colour.stroke_width(2),
            )))?;
        }
    }
    for (i, (name, class)) in series.iter().enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        let at = points.iter().filter(|p| p.pixel == i).map(|p| (p.x, p.y));
        let name = name.clone();
        match class % 5 {
            0 => {
                chart
                    .draw_series(at.map(|c| Circle::new(c, 5, colour.filled())))?
                    .label(name)
                    .legend(move |c| Circle::new(c, 5, colour.filled()));
            }
            1 => {
                chart
                    .draw_series(at.map(|c| TriangleMarker::new(c, 7, colour.filled())))?
                    .label(name)
                    .legend(move |c| TriangleMarker::new(c, 7, colour.filled()));
            }
            2 => {
                let square = move |c| {
                    EmptyElement::at(c) + Rectangle::new([(-5, -5), (5, 5)], colour.filled())
                };
                chart
                    .draw_series(at.map(square))?
                    .label(name)
                    .legend(move |c| {
                        EmptyElement::at(c) + Rectangle::new([(-5, -5), (5, 5)], colour.filled())
                    });
            }
            3 => {
                chart
                    .draw_series(at.map(|c| Cross::new(c, 6, colour.stroke_width(3))))?
                    .label(name)
                    .legend(move |c| Cross::new(c, 6, colour.stroke_width(3)));
            }
            _ => {
                chart
                    .draw_series(at.map(|c| Circle::new(c, 6, colour.stroke_width(2))))?
                    .label(name)
                    .legend(move |c| Circle::new(c, 6, colour.stroke_width(2)));
            }
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font(font(16.0))
        .background_style(WHITE.mix(0.9))
        .border_style(REF_GREY)
        .draw()?;
    Ok(())
}
