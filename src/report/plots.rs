//! Plots for people, drawn with `plotters` from the tidy rows of `results.csv` and nothing else:
//! analysis writes data, plotting only reads it.
//!
//! Each figure is a grid of panels (one per distribution) with one colour per estimator, the
//! same colour in every figure, and one shared legend above the grid. Every figure is written
//! twice, as PNG and SVG, each atomically through [`crate::report::write_atomic`].
//!
//! Text is drawn with DejaVu Sans embedded from the `dejavu` crate and registered with
//! plotters' `ab_glyph` renderer, so drawing needs no system fonts and no fontconfig.
//!
//! The work is split in two: builders turn rows into a `Figure`, a plain description of
//! panels, axes and marks; one renderer draws any figure on any plotters backend.

use crate::error::{Error, Result};
use crate::harness::metrics::Metric;
use crate::report::tables::Row;
use crate::report::write_atomic;
use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Font family name under which the embedded DejaVu Sans is registered. SVG files name it in
/// `font-family`, so a viewer without DejaVu still picks its own sans-serif face.
pub(crate) const FONT: &str = "sans-serif";
/// Size of one panel in pixels for the per-distribution figures.
pub(crate) const PANEL: (u32, u32) = (480, 360);
/// Size of one panel of the error-quantile fans, whose grid has a panel per estimator too.
const FAN_PANEL: (u32, u32) = (400, 300);
/// Outer margin of a figure, pixels.
const MARGIN: i32 = 16;
/// Opacity of a 95% confidence band.
pub(crate) const CI_ALPHA: f64 = 0.18;
/// Grey of reference lines (zero, 1/n) and neutral legend swatches.
pub(crate) const REF_GREY: RGBColor = RGBColor(110, 110, 110);
/// Grey of grid lines.
const GRID_GREY: RGBColor = RGBColor(228, 228, 228);

/// Colour of the plain mean, the baseline every robust estimator is judged against.
pub(crate) const MEAN_COLOUR: RGBColor = RGBColor(40, 40, 40);
/// Colours of the other estimators, in order of first appearance in the rows: the Okabe-Ito
/// colour-blind-safe palette (yellow darkened to read on white), then a few distinct extras.
pub(crate) const PALETTE: [RGBColor; 10] = [
    RGBColor(0, 114, 178),
    RGBColor(230, 159, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(213, 94, 0),
    RGBColor(86, 180, 233),
    RGBColor(160, 140, 0),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(23, 190, 207),
];

/// Draws every figure from `rows` into `dir` as PNG and SVG and returns the paths written, in
/// a fixed order. Figures whose metrics are absent from `rows` are skipped; no rows, no files.
///
/// Files: `median_error`, `bias`, `variance_mse`, `firefly_rate`, `error_quantiles` and
/// `speed_vs_error`, each `.png` and `.svg`.
pub fn write_plots(dir: &Path, rows: &[Row]) -> Result<Vec<PathBuf>> {
    register_fonts()?;
    let data = Data::new(rows);
    let figures = [
        median_error(&data),
        bias(&data),
        variance_mse(&data),
        firefly_rate(&data),
        error_quantiles(&data),
        speed_vs_error(&data),
    ];
    let mut written = Vec::new();
    for fig in figures.into_iter().flatten() {
        written.extend(write_figure(dir, &fig, true)?);
    }
    Ok(written)
}

/// Draws one figure into `dir` as `<name>.png` and, with `svg`, `<name>.svg`; returns the
/// paths written. Fonts must be registered ([`register_fonts`]).
pub(crate) fn write_figure(dir: &Path, fig: &Figure, svg: bool) -> Result<Vec<PathBuf>> {
    let layout = Layout::of(fig)?;
    let png = dir.join(format!("{}.png", fig.name));
    let bytes = render_png(fig, &layout).map_err(|message| Error::Io {
        path: png.display().to_string(),
        message,
    })?;
    write_atomic(&png, &bytes)?;
    let mut written = vec![png];
    if svg {
        let path = dir.join(format!("{}.svg", fig.name));
        let text = render_svg(fig, &layout).map_err(|message| Error::Io {
            path: path.display().to_string(),
            message,
        })?;
        write_atomic(&path, text.as_bytes())?;
        written.push(path);
    }
    Ok(written)
}

/// Registers DejaVu Sans (regular and bold) with plotters once per process.
pub(crate) fn register_fonts() -> Result<()> {
    static REGISTERED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            let faces = [
                (FontStyle::Normal, dejavu::sans::regular()),
                (FontStyle::Bold, dejavu::sans::bold()),
            ];
            for (style, bytes) in faces {
                plotters::style::register_font(FONT, style, bytes).map_err(|_| {
                    format!(
                        "embedded DejaVu Sans ({}) is not a valid font",
                        style.as_str()
                    )
                })?;
            }
            Ok(())
        })
        .clone()
        .map_err(|message| Error::Io {
            path: "<embedded fonts>".into(),
            message,
        })
}

// ---------------------------------------------------------------------------------------------
// Reading the rows
// ---------------------------------------------------------------------------------------------

/// One value of one metric at one sample count, with its interval if the CSV has one.
#[derive(Debug, Clone, Copy)]
struct Pt {
    n: f64,
    v: f64,
    ci: Option<(f64, f64)>,
}

/// The rows indexed by distribution, estimator and metric, in order of first appearance.
struct Data<'a> {
    dists: Vec<&'a str>,
    ests: Vec<&'a str>,
    /// Keyed by (distribution, estimator, metric), sorted by n.
    series: HashMap<(String, String, Metric), Vec<Pt>>,
}

impl<'a> Data<'a> {
    fn new(rows: &'a [Row]) -> Self {
        let mut dists = Vec::new();
        let mut ests = Vec::new();
        let mut series: HashMap<_, Vec<Pt>> = HashMap::new();
        for r in rows {
            if !dists.contains(&r.distribution.as_str()) {
                dists.push(r.distribution.as_str());
            }
            if !ests.contains(&r.estimator.as_str()) {
                ests.push(r.estimator.as_str());
            }
            if !r.value.is_finite() {
                continue;
            }
            let ci = match (r.ci_low, r.ci_high) {
                (Some(l), Some(h)) if l.is_finite() && h.is_finite() => Some((l, h)),
                _ => None,
            };
            series
                .entry((r.distribution.clone(), r.estimator.clone(), r.metric))
                .or_default()
                .push(Pt {
                    n: r.n as f64,
                    v: r.value,
                    ci,
                });
        }
        for pts in series.values_mut() {
            pts.sort_by(|a, b| a.n.total_cmp(&b.n));
        }
        Data {
            dists,
            ests,
            series,
        }
    }

    fn get(&self, dist: &str, est: &str, metric: Metric) -> &[Pt] {
        self.series
            .get(&(dist.to_string(), est.to_string(), metric))
            .map_or(&[], Vec::as_slice)
    }

    fn has_metric(&self, metric: Metric) -> bool {
        self.series.keys().any(|k| k.2 == metric)
    }

    /// Colour of an estimator: the mean in near-black, the others through the palette.
    fn colour(&self, est: &str) -> RGBColor {
        if est == "mean" {
            return MEAN_COLOUR;
        }
        let k = self
            .ests
            .iter()
            .filter(|e| **e != "mean")
            .position(|e| *e == est)
            .unwrap_or(0);
        PALETTE[k % PALETTE.len()]
    }

    /// Sorted distinct sample counts of a metric: the tick marks of an n axis.
    fn ns(&self, metric: Metric) -> Vec<f64> {
        let mut ns: Vec<f64> = self
            .series
            .iter()
            .filter(|(k, _)| k.2 == metric)
            .flat_map(|(_, pts)| pts.iter().map(|p| p.n))
            .collect();
        ns.sort_by(f64::total_cmp);
        ns.dedup();
        ns
    }

    fn estimator_legend(&self, ests: &[&str]) -> Vec<Legend> {
        ests.iter()
            .map(|e| Legend {
                label: (*e).to_string(),
                colour: self.colour(e),
                kind: LegendKind::Line,
            })
            .collect()
    }

    /// A note naming the series with values of zero or below in `metrics`, which a log axis
    /// cannot show.
    fn zero_note(&self, metrics: &[Metric]) -> Option<String> {
        let mut parts = Vec::new();
        for e in &self.ests {
            let dists: Vec<&str> = self
                .dists
                .iter()
                .copied()
                .filter(|d| {
                    metrics
                        .iter()
                        .any(|&m| self.get(d, e, m).iter().any(|p| p.v <= 0.0))
                })
                .collect();
            if !dists.is_empty() {
                parts.push(format!("{e} on {}", dists.join(", ")));
            }
        }
        if parts.is_empty() {
            return None;
        }
        Some(format!(
            "Values of zero cannot sit on a log axis and are left out, breaking the line: {}.",
            parts.join("; ")
        ))
    }

    /// "mean on firefly, infinite-variance" for every series of `metric` that has values but
    /// lacks an interval at some n.
    fn missing_ci(&self, metric: Metric, ests: &[&str]) -> Option<String> {
        let mut by_est: Vec<(String, Vec<&str>)> = Vec::new();
        for e in ests {
            let dists: Vec<&str> = self
                .dists
                .iter()
                .copied()
                .filter(|d| self.get(d, e, metric).iter().any(|p| p.ci.is_none()))
                .collect();
            if !dists.is_empty() {
                by_est.push(((*e).to_string(), dists));
            }
        }
        if by_est.is_empty() {
            return None;
        }
        let parts: Vec<String> = by_est
            .iter()
            .map(|(e, ds)| format!("{e} on {}", ds.join(", ")))
            .collect();
        Some(parts.join("; "))
    }
}

// ---------------------------------------------------------------------------------------------
// Figure description
// ---------------------------------------------------------------------------------------------

/// A whole figure: title, shared legend, notes and a grid of panels filled row by row.
pub(crate) struct Figure {
    pub(crate) name: &'static str,
    pub(crate) title: String,
    pub(crate) legend: Vec<Legend>,
    pub(crate) notes: Vec<String>,
    pub(crate) cols: usize,
    pub(crate) panel: (u32, u32),
    pub(crate) panels: Vec<Panel>,
}

pub(crate) struct Legend {
    pub(crate) label: String,
    pub(crate) colour: RGBColor,
    pub(crate) kind: LegendKind,
}

pub(crate) enum LegendKind {
    Line,
    Dashed,
    Band(f64),
    Point,
    Bar,
}

pub(crate) struct Panel {
    pub(crate) title: String,
    /// A remark written in the top left corner of the plotting area.
    pub(crate) note: Option<String>,
    pub(crate) x: Axis,
    pub(crate) y: Axis,
    pub(crate) marks: Vec<Mark>,
}

#[derive(Clone)]
pub(crate) struct Axis {
    pub(crate) label: String,
    pub(crate) log: bool,
    /// Fixed tick positions (the sample counts of an n axis); otherwise chosen from the range.
    pub(crate) ticks: Option<Vec<f64>>,
    /// Fixed range; otherwise fitted to the marks.
    pub(crate) range: Option<(f64, f64)>,
    /// Keep zero inside a fitted linear range (bias, rates).
    pub(crate) include_zero: bool,
}

impl Axis {
    pub(crate) fn log(label: impl Into<String>) -> Self {
        Axis {
            label: label.into(),
            log: true,
            ticks: None,
            range: None,
            include_zero: false,
        }
    }

    pub(crate) fn linear(label: impl Into<String>) -> Self {
        Axis {
            log: false,
            include_zero: true,
            ..Axis::log(label)
        }
    }

    /// Log axis of sample counts with a tick at each count present.
    fn n(ns: &[f64]) -> Self {
        Axis {
            ticks: Some(ns.to_vec()),
            ..Axis::log("samples per pixel n")
        }
    }

    fn usable(&self, v: f64) -> bool {
        v.is_finite() && (!self.log || v > 0.0)
    }
}

pub(crate) enum Mark {
    /// A shaded band between `lo` and `hi` over `x`; lower ends below a log axis are pinned to
    /// its floor.
    Band {
        x: Vec<f64>,
        lo: Vec<f64>,
        hi: Vec<f64>,
        colour: RGBColor,
        alpha: f64,
    },
    /// A polyline, broken where a point cannot be drawn (zero on a log axis).
    Line {
        pts: Vec<(f64, f64)>,
        colour: RGBColor,
        width: u32,
        dashed: bool,
        markers: bool,
    },
    /// A horizontal line across the whole panel.
    HLine { y: f64, colour: RGBColor },
    /// A labelled point with an optional vertical 95% interval.
    Point {
        x: f64,
        y: f64,
        ci: Option<(f64, f64)>,
        colour: RGBColor,
        label: String,
    },
}

/// How a series shows its 95% intervals.
#[derive(Clone, Copy, PartialEq)]
enum Spread {
    /// A shaded band along the line.
    Band,
    /// An error bar at each point, the estimators nudged apart along a log x axis by this
    /// many decades each so that bars of equal intervals (every rate of zero has the same
    /// Wilson interval) stay visible side by side instead of piling up into one dark block.
    Bars(f64),
}

/// The line of one estimator's series and, where the CSV has intervals, its bands or bars.
fn series_marks(pts: &[Pt], colour: RGBColor, spread: Spread) -> Vec<Mark> {
    let mut marks = Vec::new();
    if let Spread::Bars(shift) = spread {
        let f = 10f64.powf(shift);
        for p in pts {
            marks.push(Mark::Point {
                x: p.n * f,
                y: p.v,
                ci: p.ci,
                colour,
                label: String::new(),
            });
        }
        marks.push(Mark::Line {
            pts: pts.iter().map(|p| (p.n * f, p.v)).collect(),
            colour,
            width: 2,
            dashed: false,
            markers: false,
        });
        return marks;
    }
    // One band per run of consecutive points that all have an interval; a lone point with an
    // interval would make a band of zero width, so it gets an error bar instead.
    for run in pts.split(|p| p.ci.is_none()).filter(|r| !r.is_empty()) {
        if let [p] = run {
            marks.push(Mark::Point {
                x: p.n,
                y: p.v,
                ci: p.ci,
                colour,
                label: String::new(),
            });
            continue;
        }
        marks.push(Mark::Band {
            x: run.iter().map(|p| p.n).collect(),
            lo: run.iter().map(|p| p.ci.map_or(p.v, |c| c.0)).collect(),
            hi: run.iter().map(|p| p.ci.map_or(p.v, |c| c.1)).collect(),
            colour,
            alpha: CI_ALPHA,
        });
    }
    marks.push(Mark::Line {
        pts: pts.iter().map(|p| (p.n, p.v)).collect(),
        colour,
        width: 2,
        dashed: false,
        markers: true,
    });
    marks
}

/// Columns of a grid of `k` per-distribution panels: at most four, as square as is readable.
pub(crate) fn grid_cols(k: usize) -> usize {
    match k {
        0..=3 => k.max(1),
        4 => 2,
        5 | 6 | 9 => 3,
        _ => 4,
    }
}

/// Bands are drawn first, then lines, then points, so that no band hides a line; estimators
/// keep their order within each layer.
pub(crate) fn layered(mut marks: Vec<Mark>) -> Vec<Mark> {
    marks.sort_by_key(|m| match m {
        Mark::HLine { .. } => 0,
        Mark::Band { .. } => 1,
        Mark::Line { .. } => 2,
        Mark::Point { .. } => 3,
    });
    marks
}

const BAND_LEGEND: &str = "shaded: 95% confidence interval";
/// Nudge between neighbouring estimators' error bars, decades of n.
const DODGE: f64 = 0.045;

/// Says where a figure draws no band because `results.csv` has no interval.
fn ci_note(data: &Data, metric: Metric, what: &str) -> Option<String> {
    data.missing_ci(metric, &data.ests).map(|who| {
        format!(
            "No band for {who}: results.csv gives no {what} interval there (its caveat \
             column says why: the spread rests on events seen fewer than 10 times, or the true \
             value is infinite)."
        )
    })
}

/// A figure of one panel per distribution plotting `metric` against n for every estimator.
fn per_distribution(data: &Data, metric: Metric, y: Axis, bars: bool) -> Vec<Panel> {
    let x = Axis::n(&data.ns(metric));
    data.dists
        .iter()
        .map(|d| {
            let mut marks = Vec::new();
            let k = data.ests.len() as f64;
            for (i, e) in data.ests.iter().enumerate() {
                let spread = if bars {
                    Spread::Bars(DODGE * (i as f64 - 0.5 * (k - 1.0)))
                } else {
                    Spread::Band
                };
                marks.extend(series_marks(data.get(d, e, metric), data.colour(e), spread));
            }
            Panel {
                title: (*d).to_string(),
                x: x.clone(),
                y: y.clone(),
                marks: layered(marks),
                note: None,
            }
        })
        .collect()
}

fn with_band_legend(data: &Data) -> Vec<Legend> {
    let mut legend = data.estimator_legend(&data.ests);
    legend.push(Legend {
        label: BAND_LEGEND.into(),
        colour: REF_GREY,
        kind: LegendKind::Band(0.35),
    });
    legend
}

/// The primary metric: median absolute relative error against n, log-log, with its interval.
fn median_error(data: &Data) -> Option<Figure> {
    const M: Metric = Metric::MedianAbsRelError;
    if !data.has_metric(M) {
        return None;
    }
    let panels = per_distribution(data, M, Axis::log("median |estimate − μ| / μ"), false);
    let mut notes = vec![
        "Primary metric: median over trials of the absolute relative error; band: its \
         order-statistic 95% interval."
            .to_string(),
    ];
    notes.extend(data.zero_note(&[M]));
    notes.extend(ci_note(data, M, "median"));
    Some(Figure {
        name: "median_error",
        title: "Median absolute relative error against samples per pixel".into(),
        legend: with_band_legend(data),
        notes,
        cols: grid_cols(panels.len()),
        panel: PANEL,
        panels,
    })
}

/// Signed bias against n on a linear axis, with a zero line.
fn bias(data: &Data) -> Option<Figure> {
    const M: Metric = Metric::Bias;
    if !data.has_metric(M) {
        return None;
    }
    let mut panels = per_distribution(
        data,
        M,
        Axis::linear("bias: E[estimate] − μ (pixel value)"),
        false,
    );
    for p in &mut panels {
        p.marks.insert(
            0,
            Mark::HLine {
                y: 0.0,
                colour: REF_GREY,
            },
        );
    }
    let mut notes = vec![
        "Bias in the pixel's own units (μ is the true mean of each distribution).".to_string(),
    ];
    notes.extend(ci_note(data, M, "bias"));
    Some(Figure {
        name: "bias",
        title: "Bias against samples per pixel".into(),
        legend: with_band_legend(data),
        notes,
        cols: grid_cols(panels.len()),
        panel: PANEL,
        panels,
    })
}

/// Variance and MSE side by side for each distribution, log-log, with a 1/n reference.
fn variance_mse(data: &Data) -> Option<Figure> {
    if !data.has_metric(Metric::Variance) && !data.has_metric(Metric::Mse) {
        return None;
    }
    let x = Axis::n(&data.ns(Metric::Variance));
    let mut panels = Vec::new();
    for d in &data.dists {
        let mut pair = Vec::new();
        for (metric, name) in [(Metric::Variance, "variance"), (Metric::Mse, "MSE")] {
            let mut marks = Vec::new();
            for e in &data.ests {
                marks.extend(series_marks(
                    data.get(d, e, metric),
                    data.colour(e),
                    Spread::Band,
                ));
            }
            // The mean's exact variance sigma^2 / n (also its exact MSE): a curve parallel to
            // it converges at the Monte Carlo rate.
            let exact: Vec<(f64, f64)> = data
                .get(d, "mean", Metric::ExactVariance)
                .iter()
                .map(|p| (p.n, p.v))
                .collect();
            if exact.len() >= 2 {
                marks.push(Mark::Line {
                    pts: exact,
                    colour: REF_GREY,
                    width: 2,
                    dashed: true,
                    markers: false,
                });
            }
            pair.push(Panel {
                title: format!("{d}: {name}"),
                x: x.clone(),
                y: Axis::log(format!("{name} (pixel value²)")),
                marks: layered(marks),
                note: None,
            });
        }
        // Share the y range within the pair so variance and MSE compare by eye.
        let (lo, hi) = union_range(&pair, |p| &p.y);
        for p in &mut pair {
            p.y.range = lo.zip(hi);
        }
        panels.extend(pair);
    }
    let mut legend = with_band_legend(data);
    legend.push(Legend {
        label: "σ²/n: the mean's exact variance (from the law)".into(),
        colour: REF_GREY,
        kind: LegendKind::Dashed,
    });
    let mut notes = vec![
        "Left of each pair: variance over trials; right: mean squared error = variance + bias². \
         A curve parallel to the dashed line converges at the Monte Carlo rate 1/n."
            .to_string(),
    ];
    notes.push(
        "A band cut at the bottom edge reaches down to zero, or more than tenfold below the \
         lowest point."
            .to_string(),
    );
    notes.extend(data.zero_note(&[Metric::Variance, Metric::Mse]));
    notes.extend(ci_note(data, Metric::Variance, "variance"));
    let k = data.dists.len();
    Some(Figure {
        name: "variance_mse",
        title: "Variance and mean squared error against samples per pixel".into(),
        legend,
        notes,
        cols: if k >= 2 { 4 } else { 2 },
        panel: PANEL,
        panels,
    })
}

/// Firefly rate against n, linear from zero, with Wilson intervals.
fn firefly_rate(data: &Data) -> Option<Figure> {
    const M: Metric = Metric::FireflyRate;
    if !data.has_metric(M) {
        return None;
    }
    let mut panels = per_distribution(
        data,
        M,
        Axis::linear("firefly rate (fraction of trials)"),
        true,
    );
    for (p, d) in panels.iter_mut().zip(&data.dists) {
        let none = data
            .ests
            .iter()
            .all(|e| data.get(d, e, M).iter().all(|q| q.v == 0.0));
        if none {
            p.note = Some("no firefly in any trial".into());
        }
    }
    let notes = vec![
        "Firefly: a trial whose estimate exceeds (1 + τ)·μ. Bars: Wilson 95% intervals, each \
         estimator nudged sideways so that none hides another; where no trial had a firefly \
         the rate is 0 and the bar still reaches up to the largest rate the trials allow."
            .to_string(),
    ];
    let mut legend = data.estimator_legend(&data.ests);
    legend.push(Legend {
        label: "bar: Wilson 95% interval".into(),
        colour: REF_GREY,
        kind: LegendKind::Bar,
    });
    Some(Figure {
        name: "firefly_rate",
        title: "Firefly rate against samples per pixel".into(),
        legend,
        notes,
        cols: grid_cols(panels.len()),
        panel: PANEL,
        panels,
    })
}

/// Quantile fans of |X − μ|/μ: one row per distribution, one column per estimator.
fn error_quantiles(data: &Data) -> Option<Figure> {
    let q = |k: &str| match k {
        "05" => Metric::RelErrorQ05,
        "25" => Metric::RelErrorQ25,
        "75" => Metric::RelErrorQ75,
        "95" => Metric::RelErrorQ95,
        _ => Metric::RelErrorQ50,
    };
    if !data.has_metric(q("50")) {
        return None;
    }
    let x = Axis::n(&data.ns(q("50")));
    let mut panels = Vec::new();
    for d in &data.dists {
        let mut row = Vec::new();
        for e in &data.ests {
            let colour = data.colour(e);
            let mut marks = Vec::new();
            for (lo, hi, alpha) in [("05", "95", 0.16), ("25", "75", 0.38)] {
                let (l, h) = (data.get(d, e, q(lo)), data.get(d, e, q(hi)));
                let pairs: Vec<(f64, f64, f64)> = l
                    .iter()
                    .filter_map(|a| h.iter().find(|b| b.n == a.n).map(|b| (a.n, a.v, b.v)))
                    .collect();
                if pairs.len() >= 2 {
                    marks.push(Mark::Band {
                        x: pairs.iter().map(|p| p.0).collect(),
                        lo: pairs.iter().map(|p| p.1).collect(),
                        hi: pairs.iter().map(|p| p.2).collect(),
                        colour,
                        alpha,
                    });
                }
            }
            if *e != "mean" {
                let mean_median = data.get(d, "mean", q("50"));
                if !mean_median.is_empty() {
                    marks.push(Mark::Line {
                        pts: mean_median.iter().map(|p| (p.n, p.v)).collect(),
                        colour: MEAN_COLOUR,
                        width: 1,
                        dashed: true,
                        markers: false,
                    });
                }
            }
            marks.push(Mark::Line {
                pts: data.get(d, e, q("50")).iter().map(|p| (p.n, p.v)).collect(),
                colour,
                width: 2,
                dashed: false,
                markers: true,
            });
            row.push(Panel {
                title: format!("{d} · {e}"),
                x: x.clone(),
                y: Axis::log("|estimate − μ| / μ"),
                marks,
                note: None,
            });
        }
        // One y range per distribution so estimators compare along the row.
        let (lo, hi) = union_range(&row, |p| &p.y);
        for p in &mut row {
            p.y.range = lo.zip(hi);
        }
        panels.extend(row);
    }
    let colour = data
        .ests
        .iter()
        .map(|e| data.colour(e))
        .find(|c| *c != MEAN_COLOUR);
    let colour = colour.unwrap_or(MEAN_COLOUR);
    let legend = vec![
        Legend {
            label: "median".into(),
            colour,
            kind: LegendKind::Line,
        },
        Legend {
            label: "25–75% of trials".into(),
            colour,
            kind: LegendKind::Band(0.38 + 0.16),
        },
        Legend {
            label: "5–95% of trials".into(),
            colour,
            kind: LegendKind::Band(0.16),
        },
        Legend {
            label: "median of the plain mean, for comparison".into(),
            colour: MEAN_COLOUR,
            kind: LegendKind::Dashed,
        },
    ];
    let notes = vec![
        "Rows: distributions; columns: estimators (each in its own colour). The spread of \
         |estimate − μ| / μ over trials; quantiles from a log histogram (exact to 2.3%). Zeros \
         cannot sit on a log axis: a band reaching zero is cut at the bottom edge."
            .to_string(),
    ];
    Some(Figure {
        name: "error_quantiles",
        title: "Relative error quantiles against samples per pixel".into(),
        legend,
        notes,
        cols: data.ests.len().max(1),
        panel: FAN_PANEL,
        panels,
    })
}

/// Time per sample against relative RMSE at the largest n: one labelled point per estimator.
fn speed_vs_error(data: &Data) -> Option<Figure> {
    if !data.has_metric(Metric::NsPerSample) || !data.has_metric(Metric::RelativeRmse) {
        return None;
    }
    let n_max = data.ns(Metric::RelativeRmse).last().copied()?;
    let mut panels = Vec::new();
    for d in &data.dists {
        let mut marks = Vec::new();
        for e in &data.ests {
            let speed = data.get(d, e, Metric::NsPerSample).last().copied();
            let err = data
                .get(d, e, Metric::RelativeRmse)
                .iter()
                .find(|p| p.n == n_max)
                .copied();
            if let (Some(s), Some(r)) = (speed, err) {
                marks.push(Mark::Point {
                    x: s.v,
                    y: r.v,
                    ci: r.ci,
                    colour: data.colour(e),
                    label: (*e).to_string(),
                });
            }
        }
        panels.push(Panel {
            title: (*d).to_string(),
            x: Axis::log("time per sample (ns)"),
            y: Axis::log(format!("relative RMSE at n = {n_max}")),
            marks,
            note: None,
        });
    }
    let mut legend = data.estimator_legend(&data.ests);
    for l in &mut legend {
        l.kind = LegendKind::Point;
    }
    let mut notes = vec![format!(
        "Lower left is better: faster and more accurate. Time per sample as measured in the run; relative RMSE = \
         √MSE / μ at n = {n_max}, bar: 95% interval."
    )];
    if let Some(who) = data.missing_ci(Metric::RelativeRmse, &data.ests) {
        notes.push(format!(
            "No bar for {who}: results.csv gives no interval there (its caveat column says \
             why: tail-dominated, or an infinite true value)."
        ));
    }
    Some(Figure {
        name: "speed_vs_error",
        title: format!("Speed against error at n = {n_max}"),
        legend,
        notes,
        cols: grid_cols(panels.len()),
        panel: PANEL,
        panels,
    })
}

// ---------------------------------------------------------------------------------------------
// Ranges and ticks
// ---------------------------------------------------------------------------------------------

/// Smallest and largest value an axis must show for the marks of a panel. On a log axis the
/// lower ends of intervals may reach down at most a factor 10 below the lowest value; further
/// down they are cut at the edge rather than squashing the data into a corner.
fn extent(marks: &[Mark], axis: &Axis, vertical: bool) -> (Option<f64>, Option<f64>) {
    let mut vals: Vec<f64> = Vec::new();
    let mut lows: Vec<f64> = Vec::new();
    for m in marks {
        match m {
            Mark::Band { x, lo, hi, .. } => {
                if vertical {
                    vals.extend(hi);
                    lows.extend(lo);
                } else {
                    vals.extend(x);
                }
            }
            Mark::Line { pts, .. } => {
                vals.extend(pts.iter().map(|p| if vertical { p.1 } else { p.0 }));
            }
            Mark::HLine { y, .. } => {
                if vertical {
                    vals.push(*y);
                }
            }
            Mark::Point { x, y, ci, .. } => {
                if vertical {
                    vals.push(*y);
                    if let Some((l, h)) = ci {
                        lows.push(*l);
                        vals.push(*h);
                    }
                } else {
                    vals.push(*x);
                }
            }
        }
    }
    if axis.include_zero && !axis.log {
        vals.push(0.0);
    }
    let usable = |v: &&f64| axis.usable(**v);
    let mut lo = vals.iter().filter(usable).copied().reduce(f64::min);
    let hi = vals.iter().filter(usable).copied().reduce(f64::max);
    let low_floor = match (axis.log, lo) {
        (true, Some(l)) => l / 10.0,
        _ => f64::NEG_INFINITY,
    };
    for l in lows.iter().filter(usable) {
        let l = l.max(low_floor);
        lo = Some(lo.map_or(l, |x| x.min(l)));
    }
    (lo, hi)
}

fn union_range(panels: &[Panel], axis: impl Fn(&Panel) -> &Axis) -> (Option<f64>, Option<f64>) {
    let mut lo: Option<f64> = None;
    let mut hi: Option<f64> = None;
    for p in panels {
        let (l, h) = extent(&p.marks, axis(p), true);
        lo = match (lo, l) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        hi = match (hi, h) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
    }
    (lo, hi)
}

/// The final range of an axis: its fixed range or the marks' extent, padded by 6% of the span
/// (in log space on a log axis) and widened when the data sit on a single value.
fn resolve_range(axis: &Axis, marks: &[Mark], vertical: bool) -> (f64, f64) {
    let (lo, hi) = match axis.range {
        Some(r) => (Some(r.0), Some(r.1)),
        None => extent(marks, axis, vertical),
    };
    let (lo, hi) = match (lo, hi) {
        (Some(l), Some(h)) => (l, h),
        _ if axis.log => (0.1, 10.0),
        _ => (0.0, 1.0),
    };
    let t = |v: f64| if axis.log { v.log10() } else { v };
    let inv = |v: f64| if axis.log { 10f64.powf(v) } else { v };
    let (mut a, mut b) = (t(lo), t(hi));
    let min_span = if axis.log {
        0.3
    } else {
        (a.abs().max(b.abs()) * 0.2).max(1e-3)
    };
    if b - a < min_span {
        let mid = 0.5 * (a + b);
        a = mid - 0.5 * min_span;
        b = mid + 0.5 * min_span;
    }
    let pad = 0.06 * (b - a);
    (inv(a - pad), inv(b + pad))
}

/// Tick positions for `lo..hi`: powers of ten (thinned, or with 2 and 5 between) on a log
/// axis, multiples of 1, 2, 2.5 or 5 times a power of ten on a linear one.
pub(crate) fn ticks(log: bool, lo: f64, hi: f64) -> Vec<f64> {
    if log {
        let (a, b) = (lo.log10().ceil() as i32, hi.log10().floor() as i32);
        let decades = (b - a + 1).max(0) as usize;
        if decades >= 3 {
            let step = decades.div_ceil(7).max(1);
            return (a..=b)
                .filter(|k| (k - a) as usize % step == 0)
                .map(|k| 10f64.powi(k))
                .collect();
        }
        for mantissas in [&[1.0, 2.0, 5.0][..], &[1.0, 2.0, 3.0, 5.0, 7.0][..]] {
            let t: Vec<f64> = (a - 1..=b + 1)
                .flat_map(|k| mantissas.iter().map(move |m| m * 10f64.powi(k)))
                .filter(|v| *v >= lo && *v <= hi)
                .collect();
            if t.len() >= 3 {
                return t;
            }
        }
    }
    let raw = (hi - lo) / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last)
        .map(|k| k as f64 * step)
        .filter(|v| !log || *v > 0.0)
        .collect()
}

/// Tick labels: plain decimals from 0.001 to 99999, else a power of ten in superscript.
pub(crate) fn fmt_tick(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        if (v - v.round()).abs() < 1e-9 * a.max(1.0) {
            return format!("{}", v.round() as i64);
        }
        let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        let s = format!("{v:.decimals$}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        return s.to_string();
    }
    let e = a.log10().floor() as i32;
    let m = v / 10f64.powi(e);
    let sup: String = e
        .to_string()
        .chars()
        .map(|c| match c {
            '-' => '⁻',
            d => ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'][d as usize - '0' as usize],
        })
        .collect();
    if (m.abs() - 1.0).abs() < 1e-9 {
        format!("{}10{sup}", if m < 0.0 { "-" } else { "" })
    } else {
        format!("{}×10{sup}", fmt_tick((m * 100.0).round() / 100.0))
    }
}

/// A linear or logarithmic axis with explicit ticks, as a plotters coordinate. Values outside
/// the range are pinned to its edge, which is how the lower end of an interval below a log
/// axis is drawn.
#[derive(Clone)]
pub(crate) struct Coord {
    pub(crate) log: bool,
    pub(crate) lo: f64,
    pub(crate) hi: f64,
    pub(crate) ticks: Vec<f64>,
}

impl Coord {
    fn of(axis: &Axis, marks: &[Mark], vertical: bool) -> Self {
        let (lo, hi) = resolve_range(axis, marks, vertical);
        let ticks = match &axis.ticks {
            Some(t) => t.iter().copied().filter(|v| *v >= lo && *v <= hi).collect(),
            None => ticks(axis.log, lo, hi),
        };
        Coord {
            log: axis.log,
            lo,
            hi,
            ticks,
        }
    }

    fn t(&self, v: f64) -> f64 {
        if self.log { v.log10() } else { v }
    }

    /// The value at the bottom of the axis, where unplottable lower ends are drawn.
    fn floor(&self, v: f64) -> f64 {
        if v.is_finite() && (!self.log || v > 0.0) {
            v
        } else {
            self.lo
        }
    }
}

impl Ranged for Coord {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let f = (self.t(*value) - self.t(self.lo)) / (self.t(self.hi) - self.t(self.lo));
        let f = if f.is_nan() { 0.0 } else { f.clamp(0.0, 1.0) };
        limit.0 + (f * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

// ---------------------------------------------------------------------------------------------
// Rendering
// ---------------------------------------------------------------------------------------------

pub(crate) fn font(size: f64) -> FontDesc<'static> {
    FontDesc::new(FontFamily::Name(FONT), size, FontStyle::Normal)
}

pub(crate) fn bold(size: f64) -> FontDesc<'static> {
    FontDesc::new(FontFamily::Name(FONT), size, FontStyle::Bold)
}

const TITLE_SIZE: f64 = 24.0;
const LEGEND_SIZE: f64 = 16.0;
const NOTE_SIZE: f64 = 14.0;
const LEGEND_ROW: i32 = 26;
const NOTE_ROW: i32 = 20;
const SWATCH: i32 = 30;

/// Where the header items go and how big the image is, worked out before any drawing since
/// the image height depends on how many legend and note lines wrap.
struct Layout {
    size: (u32, u32),
    legend: Vec<(i32, i32)>,
    notes: Vec<(String, i32)>,
    header: i32,
    rows: usize,
}

impl Layout {
    fn of(fig: &Figure) -> Result<Self> {
        let width_of = |f: &FontDesc, s: &str| -> Result<i32> {
            f.box_size(s).map(|b| b.0 as i32).map_err(|e| Error::Io {
                path: format!("{}.png", fig.name),
                message: format!("cannot lay out text '{s}': {e}"),
            })
        };
        let cols = fig.cols.max(1);
        let rows = fig.panels.len().div_ceil(cols).max(1);
        let width = cols as i32 * fig.panel.0 as i32;
        let usable = width - 2 * MARGIN;
        let mut y = MARGIN + 34;
        let mut legend = Vec::new();
        let mut x = MARGIN;
        y += LEGEND_ROW / 2;
        for item in &fig.legend {
            let w = SWATCH + 8 + width_of(&font(LEGEND_SIZE), &item.label)? + 28;
            if x > MARGIN && x + w > MARGIN + usable {
                x = MARGIN;
                y += LEGEND_ROW;
            }
            legend.push((x, y));
            x += w;
        }
        y += LEGEND_ROW / 2 + 4;
        let mut notes = Vec::new();
        for note in &fig.notes {
            let mut line = String::new();
            for word in note.split_whitespace() {
                let candidate = if line.is_empty() {
                    word.to_string()
                } else {
                    format!("{line} {word}")
                };
                if !line.is_empty() && width_of(&font(NOTE_SIZE), &candidate)? > usable {
                    notes.push((std::mem::take(&mut line), y));
                    y += NOTE_ROW;
                    line = word.to_string();
                } else {
                    line = candidate;
                }
            }
            if !line.is_empty() {
                notes.push((line, y));
                y += NOTE_ROW;
            }
        }
        let header = y + 10;
        let height = header + rows as i32 * fig.panel.1 as i32 + MARGIN / 2;
        Ok(Layout {
            size: (width as u32, height as u32),
            legend,
            notes,
            header,
            rows,
        })
    }
}

type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// PNG bytes of an RGB8 buffer `w` pixels wide and `h` high.
pub(crate) fn encode_png(rgb: &[u8], w: u32, h: u32) -> std::result::Result<Vec<u8>, String> {
    let mut png = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut png),
        rgb,
        w,
        h,
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| e.to_string())?;
    Ok(png)
}

fn render_png(fig: &Figure, layout: &Layout) -> std::result::Result<Vec<u8>, String> {
    let (w, h) = layout.size;
    let mut buf = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        draw_figure(&root, fig, layout).map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    encode_png(&buf, w, h)
}

fn render_svg(fig: &Figure, layout: &Layout) -> std::result::Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, layout.size).into_drawing_area();
        draw_figure(&root, fig, layout).map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

fn draw_figure<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
    layout: &Layout,
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    root.draw_text(
        &fig.title,
        &TextStyle::from(bold(TITLE_SIZE)).color(&BLACK),
        (MARGIN, MARGIN),
    )?;
    let label_style = TextStyle::from(font(LEGEND_SIZE))
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    for (item, &(x, y)) in fig.legend.iter().zip(&layout.legend) {
        draw_swatch(root, item, x, y)?;
        root.draw_text(&item.label, &label_style, (x + SWATCH + 8, y))?;
    }
    let note_style = TextStyle::from(font(NOTE_SIZE))
        .color(&RGBColor(60, 60, 60))
        .pos(Pos::new(HPos::Left, VPos::Center));
    for (line, y) in &layout.notes {
        root.draw_text(line, &note_style, (MARGIN, *y))?;
    }
    let (_, body) = root.split_vertically(layout.header);
    let cells = body.split_evenly((layout.rows, fig.cols.max(1)));
    for (panel, cell) in fig.panels.iter().zip(&cells) {
        draw_panel(cell, panel)?;
    }
    Ok(())
}

fn draw_swatch<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    item: &Legend,
    x: i32,
    y: i32,
) -> DrawResult<DB> {
    let c = item.colour;
    match item.kind {
        LegendKind::Line => {
            root.draw(&PathElement::new(
                vec![(x, y), (x + SWATCH, y)],
                c.stroke_width(3),
            ))?;
            root.draw(&Circle::new((x + SWATCH / 2, y), 4, c.filled()))?;
        }
        LegendKind::Dashed => {
            root.draw(&DashedPathElement::new(
                vec![(x, y), (x + SWATCH, y)],
                7,
                4,
                c.stroke_width(2),
            ))?;
        }
        LegendKind::Band(alpha) => {
            root.draw(&Rectangle::new(
                [(x, y - 7), (x + SWATCH, y + 7)],
                c.mix(alpha).filled(),
            ))?;
        }
        LegendKind::Point => {
            root.draw(&Circle::new((x + SWATCH / 2, y), 6, c.filled()))?;
        }
        LegendKind::Bar => {
            let m = x + SWATCH / 2;
            root.draw(&PathElement::new(
                vec![(m, y - 9), (m, y + 9)],
                c.stroke_width(2),
            ))?;
            for e in [y - 9, y + 9] {
                root.draw(&PathElement::new(
                    vec![(m - 4, e), (m + 4, e)],
                    c.stroke_width(2),
                ))?;
            }
        }
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, p: &Panel) -> DrawResult<DB> {
    let x = Coord::of(&p.x, &p.marks, false);
    let y = Coord::of(&p.y, &p.marks, true);
    // Shrink a long caption ("infinite-variance · jung:sigma_image=1,m_max=17") to fit.
    let room = area.dim_in_pixel().0 as f64 - 24.0;
    let mut caption = 16.0;
    while caption > 11.0
        && bold(caption)
            .box_size(&p.title)
            .map_or(0.0, |b| f64::from(b.0))
            > room
    {
        caption -= 1.0;
    }
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, bold(caption))
        .margin(10)
        .margin_right(18)
        .x_label_area_size(48)
        .y_label_area_size(78)
        .build_cartesian_2d(x.clone(), y.clone())?;
    let fmt = |v: &f64| fmt_tick(*v);
    chart
        .configure_mesh()
        .x_desc(p.x.label.as_str())
        .y_desc(p.y.label.as_str())
        .x_label_formatter(&fmt)
        .y_label_formatter(&fmt)
        .label_style(font(13.0))
        .axis_desc_style(font(14.0))
        .bold_line_style(GRID_GREY.stroke_width(1))
        .light_line_style(TRANSPARENT)
        .draw()?;
    let usable = |c: &Coord, v: f64| v.is_finite() && (!c.log || v > 0.0);
    let mut labels = Vec::new();
    // Pixel boxes (x, y, w, h) relative to `area` that labels must not cover.
    let mut obstacles: Vec<(i32, i32, i32, i32)> = Vec::new();
    for m in &p.marks {
        match m {
            Mark::Band {
                x: xs,
                lo,
                hi,
                colour,
                alpha,
            } => {
                let mut upper = Vec::new();
                let mut lower = Vec::new();
                for i in 0..xs.len() {
                    if usable(&x, xs[i]) && usable(&y, hi[i]) {
                        upper.push((xs[i], hi[i]));
                        lower.push((xs[i], y.floor(lo[i])));
                    }
                }
                if upper.len() >= 2 {
                    lower.reverse();
                    upper.extend(lower);
                    chart.draw_series(std::iter::once(Polygon::new(
                        upper,
                        colour.mix(*alpha).filled(),
                    )))?;
                }
            }
            Mark::Line {
                pts,
                colour,
                width,
                dashed,
                markers,
            } => {
                let style = colour.stroke_width(*width);
                let ok = |q: &&(f64, f64)| usable(&x, q.0) && usable(&y, q.1);
                // Break the line wherever a point cannot be drawn.
                let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
                for q in pts {
                    if ok(&q) {
                        if let Some(run) = runs.last_mut() {
                            run.push(*q);
                        }
                    } else if runs.last().is_some_and(|r| !r.is_empty()) {
                        runs.push(Vec::new());
                    }
                }
                for run in runs.into_iter().filter(|r| r.len() >= 2) {
                    if *dashed {
                        chart.draw_series(std::iter::once(DashedPathElement::new(
                            run, 8, 5, style,
                        )))?;
                    } else {
                        chart.draw_series(std::iter::once(PathElement::new(run, style)))?;
                    }
                }
                if *markers {
                    chart.draw_series(
                        pts.iter()
                            .filter(ok)
                            .map(|q| Circle::new(*q, 3, colour.filled())),
                    )?;
                }
            }
            Mark::HLine { y: level, colour } => {
                if usable(&y, *level) {
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![(x.lo, *level), (x.hi, *level)],
                        colour.stroke_width(1),
                    )))?;
                }
            }
            Mark::Point {
                x: px,
                y: py,
                ci,
                colour,
                label,
            } => {
                if !(usable(&x, *px) && usable(&y, *py)) {
                    continue;
                }
                let base = area.get_base_pixel();
                let pixel = |v: (f64, f64)| {
                    let c = chart.backend_coord(&v);
                    (c.0 - base.0, c.1 - base.1)
                };
                let (cx, cy) = pixel((*px, *py));
                let r = if label.is_empty() { 3 } else { 6 };
                if let Some((l, h)) = ci {
                    let (l, h) = (y.floor(*l), if usable(&y, *h) { *h } else { *py });
                    let (bottom, top) = (pixel((*px, l)).1, pixel((*px, h)).1);
                    area.draw(&PathElement::new(
                        vec![(cx, bottom), (cx, top)],
                        colour.stroke_width(2),
                    ))?;
                    for end in [bottom, top] {
                        area.draw(&PathElement::new(
                            vec![(cx - 3, end), (cx + 3, end)],
                            colour.stroke_width(2),
                        ))?;
                    }
                    obstacles.push((cx - 5, top.min(bottom), 10, (bottom - top).abs()));
                }
                area.draw(&Circle::new((cx, cy), r, colour.filled()))?;
                obstacles.push((cx - r - 2, cy - r - 2, 2 * r + 4, 2 * r + 4));
                if !label.is_empty() {
                    labels.push(((cx, cy), label.as_str(), *colour));
                }
            }
        }
    }
    let note = if p.marks.is_empty() {
        Some("no data")
    } else {
        p.note.as_deref()
    };
    if let Some(note) = note {
        // On a white card, so that it reads over whatever it covers.
        let (nx, ny) = chart.plotting_area().get_base_pixel();
        let base = area.get_base_pixel();
        let (nx, ny) = (nx - base.0 + 10, ny - base.1 + 8);
        let (w, h) = font(14.0).box_size(note).unwrap_or((0, 0));
        area.draw(&Rectangle::new(
            [(nx - 5, ny - 4), (nx + w as i32 + 5, ny + h as i32 + 4)],
            WHITE.mix(0.9).filled(),
        ))?;
        area.draw_text(
            note,
            &TextStyle::from(font(14.0)).color(&RGBColor(60, 60, 60)),
            (nx, ny),
        )?;
    }
    if !labels.is_empty() {
        let plot = chart.plotting_area();
        let (px0, py0) = plot.get_base_pixel();
        let (pw, ph) = plot.dim_in_pixel();
        let base = area.get_base_pixel();
        place_labels(
            area,
            &labels,
            obstacles,
            (px0 - base.0, py0 - base.1, pw as i32, ph as i32),
        )?;
    }
    Ok(())
}

/// Writes point labels beside their points. Each label tries positions right and left of its
/// point, then further up or down, and takes the first that stays inside the plotting
/// rectangle and covers no point, error bar or earlier label; failing that, the one covering
/// least. A label set away from its point gets a leader line.
fn place_labels<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    labels: &[((i32, i32), &str, RGBColor)],
    mut taken: Vec<(i32, i32, i32, i32)>,
    plot: (i32, i32, i32, i32),
) -> DrawResult<DB> {
    const SIZE: f64 = 13.0;
    const LINE: i32 = 16;
    const GAP: i32 = 10;
    let (x0, y0, w, h) = plot;
    let overlap = |a: (i32, i32, i32, i32), b: (i32, i32, i32, i32)| -> i64 {
        let dx = (a.0 + a.2).min(b.0 + b.2) - a.0.max(b.0);
        let dy = (a.1 + a.3).min(b.1 + b.3) - a.1.max(b.1);
        if dx > 0 && dy > 0 {
            i64::from(dx) * i64::from(dy)
        } else {
            0
        }
    };
    // Place labels from left to right, so that crowded clusters resolve the same way each run.
    let mut order: Vec<usize> = (0..labels.len()).collect();
    order.sort_by_key(|&i| (labels[i].0.0, labels[i].0.1));
    for i in order {
        let ((ax, ay), text, colour) = labels[i];
        let tw = font(SIZE)
            .box_size(text)
            .map_or(8 * text.len() as i32, |b| b.0 as i32);
        let mut candidates = Vec::new();
        for k in 0..8 {
            for dy in [k * LINE, -k * LINE] {
                candidates.push((ax + GAP, ay - LINE / 2 + dy));
                candidates.push((ax - GAP - tw, ay - LINE / 2 + dy));
                if k > 0 {
                    // Centred above or below the point.
                    candidates.push((ax - tw / 2, ay - LINE / 2 + dy));
                }
            }
        }
        let inside =
            |c: &&(i32, i32)| c.0 >= x0 && c.0 + tw <= x0 + w && c.1 >= y0 && c.1 + LINE <= y0 + h;
        let cost = |c: &&(i32, i32)| -> i64 {
            taken
                .iter()
                .map(|t| overlap((c.0, c.1, tw, LINE), *t))
                .sum()
        };
        // The first candidate covering nothing, else the one covering least (min_by_key keeps
        // the first of equals).
        let (lx, top) = candidates
            .iter()
            .filter(inside)
            .min_by_key(cost)
            .copied()
            .unwrap_or((ax + GAP, ay - LINE / 2));
        taken.push((lx, top, tw, LINE));
        let mid = top + LINE / 2;
        let beside = (mid - ay).abs() <= LINE / 2 && (lx == ax + GAP || lx + tw == ax - GAP);
        if !beside {
            // Leader from the point to the nearest point of the label's box.
            let end = (ax.clamp(lx, lx + tw), ay.clamp(top, top + LINE));
            area.draw(&PathElement::new(
                vec![(ax, ay), end],
                colour.mix(0.7).stroke_width(1),
            ))?;
        }
        let style = TextStyle::from(font(SIZE))
            .color(&colour)
            .pos(Pos::new(HPos::Left, VPos::Center));
        area.draw_text(text, &style, (lx, mid))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short_and_exact() {
        assert_eq!(fmt_tick(4096.0), "4096");
        assert_eq!(fmt_tick(0.25), "0.25");
        assert_eq!(fmt_tick(-0.5), "-0.5");
        assert_eq!(fmt_tick(0.001), "0.001");
        assert_eq!(fmt_tick(1e-5), "10⁻⁵");
        assert_eq!(fmt_tick(2e-5), "2×10⁻⁵");
        assert_eq!(fmt_tick(1e6), "10⁶");
        assert_eq!(fmt_tick(0.0), "0");
    }

    #[test]
    fn ticks_cover_narrow_and_wide_log_ranges() {
        // Within one decade there is no power of ten: fall back to 1-2-5 or finer steps.
        let t = ticks(true, 0.11, 0.95);
        assert!(t.len() >= 3, "{t:?}");
        assert!(t.iter().all(|v| (0.11..=0.95).contains(v)));
        // Twelve decades: at most about seven ticks, all powers of ten.
        let t = ticks(true, 1e-9, 1e3);
        assert!(t.len() <= 7 && t.len() >= 3, "{t:?}");
        // Linear: round steps including zero.
        let t = ticks(false, -0.93, 0.21);
        assert!(t.contains(&0.0), "{t:?}");
    }

    #[test]
    fn log_axis_drops_zero_and_bounds_interval_floors() {
        let marks = vec![Mark::Band {
            x: vec![16.0, 64.0],
            lo: vec![-3.0, 1e-12],
            hi: vec![2.0, 0.5],
            colour: BLACK,
            alpha: 0.2,
        }];
        let (lo, hi) = extent(&marks, &Axis::log("v"), true);
        // The lowest drawable value is 0.5; interval lows go at most a factor 10 below it.
        assert_eq!(lo, Some(0.05));
        assert_eq!(hi, Some(2.0));
    }
}
