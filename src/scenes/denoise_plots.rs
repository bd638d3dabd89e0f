//! The denoising experiment's figures, drawn from its cells (`denoise_summary.csv`) and images
//! only: relMSE and SSIM against spp per scene (one colour per source, dashed its noisy
//! estimate, solid NFOR's output; the mean over repeats with its 95% interval shaded) with the
//! house renderer of [`crate::report::plots`], and `montage.png`, crops of every image of the
//! first repeat at one spp, with the scene experiment's tiles ([`super::plots`]).

use super::denoise_experiment::{DenoiseExperiment, variance_name};
use super::denoise_report::DenoiseCell;
use super::denoise_run::DenoiseSceneResult;
use super::plots::{Tile, crop_row, draw_tiles};
use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::report::plots::{
    Axis, CI_ALPHA, Figure, Legend, LegendKind, MEAN_COLOUR, Mark, PALETTE, PANEL, Panel, REF_GREY,
    grid_cols, layered, register_fonts, write_figure,
};
use plotters::style::RGBColor;
use std::path::{Path, PathBuf};

/// A point of a series: spp, mean over repeats, and its interval where the cell has one.
type Point = (f64, f64, Option<(f64, f64)>);

/// The colour of a source (the mean in near-black) and of its `j`-th extra variance.
fn colour(exp: &DenoiseExperiment, source: &str, variance_index: usize) -> RGBColor {
    let robust: Vec<String> = exp
        .sources
        .iter()
        .filter(|s| s.spec.to_string() != "mean")
        .map(|s| s.spec.to_string())
        .collect();
    if variance_index == 0 {
        if source == "mean" {
            return MEAN_COLOUR;
        }
        let k = robust.iter().position(|e| e == source).unwrap_or(0);
        return PALETTE[k % PALETTE.len()];
    }
    // Extra variances take the palette's colours after the robust sources', in source order.
    let mut extra = robust.len();
    for s in &exp.sources {
        for j in 1..s.variances.len() {
            if s.spec.to_string() == source && j == variance_index {
                return PALETTE[extra % PALETTE.len()];
            }
            extra += 1;
        }
    }
    PALETTE[extra % PALETTE.len()]
}

/// Writes `relmse_vs_spp.png`, `ssim_vs_spp.png` and `montage.png` into `dir`; returns the
/// paths.
///
/// # Errors
///
/// A figure that cannot be laid out or written.
pub fn write_plots(
    dir: &Path,
    exp: &DenoiseExperiment,
    cells: &[DenoiseCell],
    results: &[DenoiseSceneResult],
) -> Result<Vec<PathBuf>> {
    register_fonts()?;
    let tag = if exp.quick { " (quick run)" } else { "" };
    let legend = || {
        let mut legend = Vec::new();
        for src in &exp.sources {
            let spec = src.spec.to_string();
            legend.push(Legend {
                label: format!("{}: noisy", src.label),
                colour: colour(exp, &spec, 0),
                kind: LegendKind::Dashed,
            });
            for (j, &v) in src.variances.iter().enumerate() {
                legend.push(Legend {
                    label: format!("{}: NFOR, {} variance", src.label, variance_name(v)),
                    colour: colour(exp, &spec, j),
                    kind: LegendKind::Line,
                });
            }
        }
        if exp.repeats >= 2 {
            legend.push(Legend {
                label: format!(
                    "shaded: 95% Student-t interval of the mean over {} renders",
                    exp.repeats
                ),
                colour: REF_GREY,
                kind: LegendKind::Band(2.0 * CI_ALPHA),
            });
        }
        legend
    };
    let mut scenes: Vec<&str> = Vec::new();
    for r in cells {
        if !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
    }
    // `range` cuts the intervals' ends to what the metric can take.
    let panels = |y: &dyn Fn(&DenoiseCell) -> (f64, Option<f64>),
                  range: (f64, f64),
                  axis: &Axis|
     -> Vec<Panel> {
        scenes
            .iter()
            .map(|scene| {
                let own: Vec<&DenoiseCell> = cells.iter().filter(|r| r.scene == *scene).collect();
                let mut marks = Vec::new();
                for src in &exp.sources {
                    let spec = src.spec.to_string();
                    let mut series: Vec<(String, usize, bool)> = vec![(String::new(), 0, true)];
                    for (j, &v) in src.variances.iter().enumerate() {
                        series.push((variance_name(v).to_string(), j, false));
                    }
                    for (variance, j, dashed) in series {
                        let mut pts: Vec<Point> = own
                            .iter()
                            .filter(|r| r.source == spec && r.variance == variance)
                            .map(|r| {
                                let (m, h) = y(r);
                                let ci = h.map(|h| ((m - h).max(range.0), (m + h).min(range.1)));
                                (f64::from(r.spp), m, ci)
                            })
                            .collect();
                        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                        let colour = colour(exp, &spec, j);
                        marks.extend(spread(&pts, colour));
                        if !pts.is_empty() {
                            marks.push(Mark::Line {
                                pts: pts.iter().map(|&(x, m, _)| (x, m)).collect(),
                                colour,
                                width: 2,
                                dashed,
                                markers: true,
                            });
                        }
                    }
                }
                let mut x = Axis::log("samples per pixel (spp), log scale");
                let mut ticks: Vec<f64> = own.iter().map(|r| f64::from(r.spp)).collect();
                ticks.sort_by(f64::total_cmp);
                ticks.dedup();
                x.ticks = Some(ticks);
                let (w, h) = own.first().map_or((0, 0), |r| (r.width, r.height));
                Panel {
                    title: format!("{scene} ({w}x{h})"),
                    note: None,
                    x,
                    y: axis.clone(),
                    marks: layered(marks),
                }
            })
            .collect()
    };
    let repeats_note = if exp.repeats < 2 {
        "One render per spp, no interval".to_string()
    } else {
        format!(
            "Lines: mean over {} independent renders per spp; shaded: its 95% Student-t \
             interval (an error bar where a series has one spp), each render judged against \
             the same reference",
            exp.repeats
        )
    };
    let relmse_axis = Axis::log("relMSE (ε = 0.01), log scale");
    let mut ssim_axis = Axis::linear("SSIM of the display luma");
    ssim_axis.include_zero = false;
    let figures = [
        Figure {
            name: "relmse_vs_spp",
            title: format!("relMSE against samples per pixel, before and after NFOR{tag}"),
            legend: legend(),
            notes: vec![format!(
                "relMSE = mean over pixels and channels of (x − r)² / (r² + 0.01), linear \
                 radiance, against the scene's converged reference; lower is better. {}{}; NFOR \
                 (Bitterli et al. 2016) denoises each source's two half images with the \
                 variance named.",
                repeats_note,
                if exp.repeats < 2 {
                    ""
                } else {
                    " (a band whose lower end is at or below zero runs down to the panel's floor)"
                }
            )],
            cols: grid_cols(scenes.len()),
            panel: PANEL,
            panels: panels(
                &|r| (r.relmse_mean, r.relmse_ci95),
                (f64::NEG_INFINITY, f64::INFINITY),
                &relmse_axis,
            ),
        },
        Figure {
            name: "ssim_vs_spp",
            title: format!("SSIM against samples per pixel, before and after NFOR{tag}"),
            legend: legend(),
            notes: vec![format!(
                "SSIM: Wang et al. 2004 on the luma of the display image (clamped to [0, 1], \
                 sRGB curve), 11x11 Gaussian window, σ = 1.5; higher is better. {}{}.",
                repeats_note,
                if exp.repeats < 2 {
                    ""
                } else {
                    " (cut at SSIM's range, [−1, 1])"
                }
            )],
            cols: grid_cols(scenes.len()),
            panel: PANEL,
            panels: panels(&|r| (r.ssim_mean, r.ssim_ci95), (-1.0, 1.0), &ssim_axis),
        },
    ];
    let mut written = Vec::new();
    for fig in &figures {
        written.extend(write_figure(dir, fig, false)?);
    }
    if results.iter().any(|r| !r.montage.is_empty()) {
        written.push(montage(dir, exp, results, tag)?);
    }
    Ok(written)
}

/// Shaded bands of a series along each run of consecutive points with an interval; a lone
/// such point (a band of zero width) gets an error bar instead.
fn spread(pts: &[Point], colour: RGBColor) -> Vec<Mark> {
    let mut marks = Vec::new();
    for run in pts.split(|p| p.2.is_none()).filter(|r| !r.is_empty()) {
        if let [(x, y, ci)] = run {
            marks.push(Mark::Point {
                x: *x,
                y: *y,
                ci: *ci,
                colour,
                label: String::new(),
            });
            continue;
        }
        marks.push(Mark::Band {
            x: run.iter().map(|p| p.0).collect(),
            lo: run.iter().map(|p| p.2.map_or(p.1, |c| c.0)).collect(),
            hi: run.iter().map(|p| p.2.map_or(p.1, |c| c.1)).collect(),
            colour,
            alpha: CI_ALPHA,
        });
    }
    marks
}

/// `montage.png`: per scene the crop of the reference, each noisy estimate and each NFOR output
/// at the montage's spp.
fn montage(
    dir: &Path,
    exp: &DenoiseExperiment,
    results: &[DenoiseSceneResult],
    tag: &str,
) -> Result<PathBuf> {
    let size = results.iter().map(|r| r.crop[2]).max().unwrap_or(1) as usize;
    let scale = (200 / size.max(1)).max(1);
    let rows: Vec<(String, Vec<Tile>)> = results
        .iter()
        .map(|r| {
            let label = format!("{} ({} spp)", r.info.scene, exp.montage_spp);
            crop_row(label, &r.reference, r.crop, &r.montage)
        })
        .collect();
    let png = draw_tiles(
        &format!("Crops before and after NFOR{tag}"),
        &[
            "Per scene, the window where NFOR of the mean is worst (largest sum of relMSE's \
             per-pixel terms against the reference), for the reference, then each source's noisy \
             estimate followed by NFOR's output on its halves with each variance (\"+ NFOR\"); \
             exposure 1, clamped, sRGB curve, nearest-neighbour enlargement."
                .into(),
        ],
        &rows,
        scale,
        None,
    )
    .map_err(|message| Error::Io {
        path: "montage.png".into(),
        message,
    })?;
    let path = dir.join("montage.png");
    write_atomic(&path, &png)?;
    Ok(path)
}
