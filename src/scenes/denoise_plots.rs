//! The denoising experiment's figures, drawn from its rows and images only: relMSE and SSIM
//! against spp per scene (one colour per source, dashed its noisy estimate, solid NFOR's output)
//! with the house renderer of [`crate::report::plots`], and `montage.png`, crops of every image
//! at one spp, with the scene experiment's tiles ([`super::plots`]).

use super::denoise_experiment::{DenoiseExperiment, variance_name};
use super::denoise_run::{DenoiseRow, DenoiseSceneResult};
use super::plots::{Tile, crop_row, draw_tiles};
use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::report::plots::{
    Axis, Figure, Legend, LegendKind, MEAN_COLOUR, Mark, PALETTE, PANEL, Panel, grid_cols, layered,
    register_fonts, write_figure,
};
use plotters::style::RGBColor;
use std::path::{Path, PathBuf};

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
    rows: &[DenoiseRow],
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
        legend
    };
    let mut scenes: Vec<&str> = Vec::new();
    for r in rows {
        if !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
    }
    let panels = |y: &dyn Fn(&DenoiseRow) -> f64, axis: &Axis| -> Vec<Panel> {
        scenes
            .iter()
            .map(|scene| {
                let own: Vec<&DenoiseRow> = rows.iter().filter(|r| r.scene == *scene).collect();
                let mut marks = Vec::new();
                for src in &exp.sources {
                    let spec = src.spec.to_string();
                    let mut series: Vec<(String, usize, bool)> = vec![(String::new(), 0, true)];
                    for (j, &v) in src.variances.iter().enumerate() {
                        series.push((variance_name(v).to_string(), j, false));
                    }
                    for (variance, j, dashed) in series {
                        let mut pts: Vec<(f64, f64)> = own
                            .iter()
                            .filter(|r| r.source == spec && r.variance == variance)
                            .map(|r| (f64::from(r.spp), y(r)))
                            .collect();
                        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                        if !pts.is_empty() {
                            marks.push(Mark::Line {
                                pts,
                                colour: colour(exp, &spec, j),
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
    let relmse_axis = Axis::log("relMSE (ε = 0.01), log scale");
    let mut ssim_axis = Axis::linear("SSIM of the display luma");
    ssim_axis.include_zero = false;
    let figures = [
        Figure {
            name: "relmse_vs_spp",
            title: format!("relMSE against samples per pixel, before and after NFOR{tag}"),
            legend: legend(),
            notes: vec![
                "relMSE = mean over pixels and channels of (x − r)² / (r² + 0.01), linear \
                 radiance, against the scene's converged reference; lower is better. One render \
                 per spp; NFOR (Bitterli et al. 2016) denoises each source's two half images \
                 with the variance named."
                    .into(),
            ],
            cols: grid_cols(scenes.len()),
            panel: PANEL,
            panels: panels(&|r| r.relmse, &relmse_axis),
        },
        Figure {
            name: "ssim_vs_spp",
            title: format!("SSIM against samples per pixel, before and after NFOR{tag}"),
            legend: legend(),
            notes: vec![
                "SSIM: Wang et al. 2004 on the luma of the display image (clamped to [0, 1], \
                 sRGB curve), 11x11 Gaussian window, σ = 1.5; higher is better."
                    .into(),
            ],
            cols: grid_cols(scenes.len()),
            panel: PANEL,
            panels: panels(&|r| r.ssim, &ssim_axis),
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
            "Per scene, the window holding the most firefly pixels of the noisy mean (luminance \
             above the rule's factor times the reference's plus its floor), for the reference, \
             then each source's noisy estimate followed by NFOR's output on its halves with each \
             variance (\"+ NFOR\"); exposure 1, clamped, sRGB curve, nearest-neighbour \
             enlargement."
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
