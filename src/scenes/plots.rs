//! The scene experiment's figures, drawn from its rows and images only: convergence (SSIM and
//! relMSE against spp), Zirr et al.'s Figure 6 (RMSE against κ), speed against error, signed
//! bias maps, and firefly crops side by side. Line figures use the house renderer of
//! [`crate::report::plots`] (same fonts, palette, axes and legends); image figures are drawn
//! here on the same fonts. Every figure is a PNG.

use super::run::SceneResult;
use super::tables::{MetricRow, ZirrPoint};
use crate::error::{Error, Result};
use crate::image::Image;
use crate::image::metrics::tone_map;
use crate::report::plots::{
    Axis, Figure, Legend, LegendKind, MEAN_COLOUR, Mark, PALETTE, PANEL, Panel, bold, font,
    grid_cols, layered, register_fonts, write_figure,
};
use crate::report::write_atomic;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};

/// The colour of the `k`-th plotted estimator (the mean in near-black).
fn colour(estimator: &str, plotted: &[String]) -> RGBColor {
    if estimator == "mean" {
        return MEAN_COLOUR;
    }
    let k = plotted
        .iter()
        .filter(|e| *e != "mean")
        .position(|e| e == estimator)
        .unwrap_or(0);
    PALETTE[k % PALETTE.len()]
}

/// Sorted distinct spp of the rows.
fn spps(rows: &[MetricRow]) -> Vec<f64> {
    let mut v: Vec<f64> = rows.iter().map(|r| f64::from(r.spp)).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// Scenes in order of first appearance.
fn scenes(rows: &[MetricRow]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for r in rows {
        if !out.contains(&r.scene) {
            out.push(r.scene.clone());
        }
    }
    out
}

fn legend(plotted: &[String], labels: &[String]) -> Vec<Legend> {
    plotted
        .iter()
        .zip(labels)
        .map(|(e, l)| Legend {
            label: l.clone(),
            colour: colour(e, plotted),
            kind: LegendKind::Line,
        })
        .collect()
}

/// One panel per scene of `metric` against spp (or against `x`) for the plotted estimators.
fn per_scene(
    rows: &[MetricRow],
    plotted: &[String],
    x: impl Fn(&MetricRow) -> f64,
    y: impl Fn(&MetricRow) -> f64,
    x_axis: impl Fn(&[MetricRow]) -> Axis,
    y_axis: Axis,
) -> Vec<Panel> {
    scenes(rows)
        .into_iter()
        .map(|scene| {
            let own: Vec<MetricRow> = rows.iter().filter(|r| r.scene == scene).cloned().collect();
            let mut marks = Vec::new();
            for e in plotted {
                let mut pts: Vec<(f64, f64)> = own
                    .iter()
                    .filter(|r| &r.estimator == e)
                    .map(|r| (x(r), y(r)))
                    .collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                if !pts.is_empty() {
                    marks.push(Mark::Line {
                        pts,
                        colour: colour(e, plotted),
                        width: 2,
                        dashed: false,
                        markers: true,
                    });
                }
            }
            Panel {
                title: scene.clone(),
                note: None,
                x: x_axis(&own),
                y: y_axis.clone(),
                marks: layered(marks),
            }
        })
        .collect()
}

/// The n axis: log, ticks at the powers of two present.
fn spp_axis(rows: &[MetricRow]) -> Axis {
    let mut a = Axis::log("samples per pixel (spp)");
    a.ticks = Some(
        spps(rows)
            .into_iter()
            .filter(|v| (*v as u32).is_power_of_two())
            .collect(),
    );
    a
}

/// Writes every figure into `dir` and returns the paths.
///
/// # Errors
///
/// A figure that cannot be laid out or written.
pub fn write_plots(
    dir: &Path,
    rows: &[MetricRow],
    plotted: &[String],
    zirr: &[ZirrPoint],
    results: &[SceneResult],
    quick: bool,
) -> Result<Vec<PathBuf>> {
    register_fonts()?;
    let tag = if quick { " (quick run)" } else { "" };
    let labels: Vec<String> = plotted
        .iter()
        .map(|e| {
            rows.iter()
                .find(|r| &r.estimator == e)
                .map_or_else(|| e.clone(), |r| r.label.clone())
        })
        .collect();
    let mut written = Vec::new();
    let mut figures = Vec::new();

    let mut ssim_axis = Axis::linear("SSIM of the display luma");
    ssim_axis.include_zero = false;
    let panels = per_scene(
        rows,
        plotted,
        |r| f64::from(r.spp),
        |r| r.ssim,
        spp_axis,
        ssim_axis,
    );
    figures.push(Figure {
        name: "ssim_vs_spp",
        title: format!("SSIM against samples per pixel{tag}"),
        legend: legend(plotted, &labels),
        notes: vec![
            "Every estimator read within one render at each checkpoint, against the scene's \
             converged reference; higher is better. SSIM: Wang et al. 2004 on the luma of the \
             display image (clamped to [0, 1], sRGB curve), 11x11 Gaussian window, σ = 1.5."
                .into(),
        ],
        cols: grid_cols(panels.len()),
        panel: PANEL,
        panels,
    });

    let panels = per_scene(
        rows,
        plotted,
        |r| f64::from(r.spp),
        |r| r.relmse,
        spp_axis,
        Axis::log("relMSE (ε = 0.01)"),
    );
    figures.push(Figure {
        name: "relmse_vs_spp",
        title: format!("Relative MSE against samples per pixel{tag}"),
        legend: legend(plotted, &labels),
        notes: vec![
            "relMSE = mean over pixels and channels of (x − r)² / (r² + 0.01), linear radiance; \
             lower is better. Where the mean's variance is finite and its rare paths have been \
             sampled its error falls as 1/spp; a robust estimator's flattens where its bias takes \
             over from its variance."
                .into(),
        ],
        cols: grid_cols(panels.len()),
        panel: PANEL,
        panels,
    });

    let panels = per_scene(
        rows,
        plotted,
        |r| r.render_cpu_s,
        |r| r.relmse,
        |_| Axis::log("CPU seconds, render with this estimator alone"),
        Axis::log("relMSE (ε = 0.01)"),
    );
    figures.push(Figure {
        name: "speed_vs_error",
        title: format!("Render time against error{tag}"),
        legend: legend(plotted, &labels),
        notes: vec![
            "Each point is a checkpoint (1, 2, 4, ... spp). Time: measured CPU time per traced \
             sample plus the estimator's own per-sample and per-pixel cost (costs.csv), for the \
             whole image; lower left is better."
                .into(),
        ],
        cols: grid_cols(panels.len()),
        panel: PANEL,
        panels,
    });

    if let Some(fig) = zirr_figure(zirr, tag) {
        figures.push(fig);
    }
    for fig in &figures {
        written.extend(write_figure(dir, fig, false)?);
    }
    for r in results {
        written.push(bias_maps(dir, r, tag)?);
    }
    if !results.is_empty() {
        written.push(crops(dir, results, tag)?);
    }
    Ok(written)
}

/// Zirr et al.'s Figure 6: RMSE against κ, a line per b, the mean's RMSE dashed.
fn zirr_figure(points: &[ZirrPoint], tag: &str) -> Option<Figure> {
    if points.is_empty() {
        return None;
    }
    let mut scenes: Vec<&str> = Vec::new();
    let mut bs: Vec<f64> = Vec::new();
    for p in points {
        if !scenes.contains(&p.scene.as_str()) {
            scenes.push(&p.scene);
        }
        if !bs.contains(&p.b) {
            bs.push(p.b);
        }
    }
    bs.sort_by(f64::total_cmp);
    let b_colour = |b: f64| PALETTE[bs.iter().position(|&x| x == b).unwrap_or(0) % PALETTE.len()];
    let mut panels = Vec::new();
    for scene in &scenes {
        let own: Vec<&ZirrPoint> = points.iter().filter(|p| p.scene == *scene).collect();
        let mut marks = Vec::new();
        for &b in &bs {
            let pts: Vec<(f64, f64)> = own
                .iter()
                .filter(|p| p.b == b)
                .map(|p| (p.kappa, p.rmse))
                .collect();
            if !pts.is_empty() {
                marks.push(Mark::Line {
                    pts,
                    colour: b_colour(b),
                    width: 2,
                    dashed: false,
                    markers: true,
                });
            }
        }
        let (lo, hi) = own.iter().fold((f64::INFINITY, 0.0f64), |(l, h), p| {
            (l.min(p.kappa), h.max(p.kappa))
        });
        if let Some(m) = own.first().and_then(|p| p.mean_rmse) {
            marks.push(Mark::Line {
                pts: vec![(lo, m), (hi, m)],
                colour: MEAN_COLOUR,
                width: 2,
                dashed: true,
                markers: false,
            });
        }
        let mut x = Axis::log("κ (robustness)");
        let mut ks: Vec<f64> = own.iter().map(|p| p.kappa).collect();
        ks.sort_by(f64::total_cmp);
        ks.dedup();
        x.ticks = Some(ks);
        panels.push(Panel {
            title: format!("{scene}, {} spp", own.first().map_or(0, |p| p.spp)),
            note: None,
            x,
            y: Axis::log("RMSE (linear radiance)"),
            marks: layered(marks),
        });
    }
    let mut legend: Vec<Legend> = bs
        .iter()
        .map(|&b| Legend {
            label: format!("Zirr et al., b = {b}"),
            colour: b_colour(b),
            kind: LegendKind::Line,
        })
        .collect();
    legend.push(Legend {
        label: "mean, same spp".into(),
        colour: MEAN_COLOUR,
        kind: LegendKind::Dashed,
    });
    Some(Figure {
        name: "zirr_kappa",
        title: format!("RMSE against κ (Zirr et al., Fig. 6){tag}"),
        legend,
        notes: vec![
            "The paper's method (zirr: J grows on demand, κ_min = 1, u = 1) on the 3x3 \
             neighbourhood, at each scene's largest spp. A buffer's weight is min(1, N / (κ r)): \
             larger κ down-weights more."
                .into(),
        ],
        cols: grid_cols(panels.len()),
        panel: PANEL,
        panels,
    })
}

// ---------------------------------------------------------------------------------------------
// Image figures
// ---------------------------------------------------------------------------------------------

/// A diverging blue-white-red colour map (ColorBrewer RdBu anchors) of `t` in [-1, 1].
pub fn diverging(t: f64) -> [u8; 3] {
    const ANCHORS: [[f64; 3]; 5] = [
        [5.0, 48.0, 97.0],
        [67.0, 147.0, 195.0],
        [247.0, 247.0, 247.0],
        [214.0, 96.0, 77.0],
        [103.0, 0.0, 31.0],
    ];
    let t = if t.is_nan() { 0.0 } else { t.clamp(-1.0, 1.0) };
    let f = (t + 1.0) * 2.0;
    let i = (f.floor() as usize).min(3);
    let a = f - i as f64;
    let c = |k: usize| ANCHORS[i][k] + a * (ANCHORS[i + 1][k] - ANCHORS[i][k]);
    [c(0), c(1), c(2)].map(|v| v.round().clamp(0.0, 255.0) as u8)
}

/// The display colour of a linear pixel (clamped, sRGB curve), as the PNG previews show it.
fn display(p: [f32; 3]) -> [u8; 3] {
    p.map(|c| (tone_map(f64::from(c)) * 255.0).round() as u8)
}

/// A tile: a caption over an image given as a function of its pixels, scaled by nearest
/// neighbour.
pub(crate) struct Tile {
    caption: String,
    width: usize,
    height: usize,
    pixels: Vec<[u8; 3]>,
}

impl Tile {
    fn from_image(
        caption: String,
        img: &Image,
        window: [u32; 3],
        f: impl Fn([f32; 3]) -> [u8; 3],
    ) -> Self {
        let [x0, y0, s] = window.map(|v| v as usize);
        let (w, h) = (s.min(img.width() - x0), s.min(img.height() - y0));
        let mut pixels = Vec::with_capacity(w * h);
        for y in y0..y0 + h {
            for x in x0..x0 + w {
                pixels.push(f(img.get(x, y)));
            }
        }
        Tile {
            caption,
            width: w,
            height: h,
            pixels,
        }
    }
}

const CAPTION: i32 = 22;
const GAP: i32 = 14;
const TOP: i32 = 16;

/// A grid of tiles with a title, note lines, optional row labels and an optional colour bar
/// `(lo, hi, label)` of the diverging map; returns PNG bytes.
pub(crate) fn draw_tiles(
    title: &str,
    notes: &[String],
    rows: &[(String, Vec<Tile>)],
    scale: usize,
    colour_bar: Option<(f64, f64, String)>,
) -> std::result::Result<Vec<u8>, String> {
    let cols = rows.iter().map(|r| r.1.len()).max().unwrap_or(0).max(1);
    let tile_w = rows
        .iter()
        .flat_map(|r| r.1.iter().map(|t| t.width))
        .max()
        .unwrap_or(1) as i32
        * scale as i32;
    let tile_h = rows
        .iter()
        .flat_map(|r| r.1.iter().map(|t| t.height))
        .max()
        .unwrap_or(1) as i32
        * scale as i32;
    let measure = |f: &FontDesc, s: &str| f.box_size(s).map_or(8 * s.len() as i32, |b| b.0 as i32);
    let label_w = rows
        .iter()
        .map(|r| measure(&bold(15.0), &r.0))
        .max()
        .unwrap_or(0)
        + if rows.iter().any(|r| !r.0.is_empty()) {
            GAP
        } else {
            0
        };
    let bar_w = if colour_bar.is_some() { 150 } else { 0 };
    let cell_w = tile_w.max(120);
    let width = GAP + label_w + cols as i32 * (cell_w + GAP) + bar_w + GAP;
    // Notes wrap to the width.
    let mut lines = Vec::new();
    for note in notes {
        let mut line = String::new();
        for word in note.split_whitespace() {
            let candidate = if line.is_empty() {
                word.to_string()
            } else {
                format!("{line} {word}")
            };
            if !line.is_empty() && measure(&font(14.0), &candidate) > width - 2 * GAP {
                lines.push(std::mem::take(&mut line));
                line = word.to_string();
            } else {
                line = candidate;
            }
        }
        if !line.is_empty() {
            lines.push(line);
        }
    }
    let header = TOP + 34 + lines.len() as i32 * 20 + 8;
    let row_h = CAPTION + tile_h + GAP;
    let height = header + rows.len() as i32 * row_h + GAP;
    // Room under the colour bar for its two-line label.
    let bar_bottom = header + CAPTION + (rows.len() as i32 * row_h - CAPTION - GAP).max(100) + 50;
    let height = if colour_bar.is_some() {
        height.max(bar_bottom)
    } else {
        height
    };
    let (w, h) = (width as u32, height as u32);
    let mut buf = vec![255u8; w as usize * h as usize * 3];
    let tile_origin = |r: usize, c: usize| {
        (
            GAP + label_w + c as i32 * (cell_w + GAP),
            header + r as i32 * row_h + CAPTION,
        )
    };
    for (r, (_, tiles)) in rows.iter().enumerate() {
        for (c, t) in tiles.iter().enumerate() {
            let (ox, oy) = tile_origin(r, c);
            for ty in 0..t.height * scale {
                for tx in 0..t.width * scale {
                    let p = t.pixels[(ty / scale) * t.width + tx / scale];
                    let (x, y) = (ox as usize + tx, oy as usize + ty);
                    let i = (y * w as usize + x) * 3;
                    buf[i..i + 3].copy_from_slice(&p);
                }
            }
        }
    }
    let bar_geometry = (
        width - bar_w - GAP + 10,
        header + CAPTION,
        22,
        (rows.len() as i32 * row_h - CAPTION - GAP).max(100),
    );
    if colour_bar.is_some() {
        let (bx, by, bw, bh) = bar_geometry;
        for y in 0..bh {
            let t = 1.0 - 2.0 * f64::from(y) / f64::from(bh - 1);
            let p = diverging(t);
            for x in 0..bw {
                let i = ((by + y) as usize * w as usize + (bx + x) as usize) * 3;
                buf[i..i + 3].copy_from_slice(&p);
            }
        }
    }
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| e.to_string();
        root.draw_text(
            title,
            &TextStyle::from(bold(24.0)).color(&BLACK),
            (GAP, TOP),
        )
        .map_err(e)?;
        let note_style = TextStyle::from(font(14.0)).color(&RGBColor(60, 60, 60));
        for (i, line) in lines.iter().enumerate() {
            root.draw_text(line, &note_style, (GAP, TOP + 34 + i as i32 * 20))
                .map_err(e)?;
        }
        for (r, (name, tiles)) in rows.iter().enumerate() {
            let (_, oy) = tile_origin(r, 0);
            if !name.is_empty() {
                let style = TextStyle::from(bold(15.0))
                    .color(&BLACK)
                    .pos(Pos::new(HPos::Left, VPos::Center));
                root.draw_text(name, &style, (GAP, oy + tile_h / 2))
                    .map_err(e)?;
            }
            for (c, t) in tiles.iter().enumerate() {
                let (ox, oy) = tile_origin(r, c);
                let mut size = 14.0;
                while size > 9.0 && measure(&font(size), &t.caption) > cell_w {
                    size -= 1.0;
                }
                root.draw_text(
                    &t.caption,
                    &TextStyle::from(font(size)).color(&BLACK),
                    (ox, oy - CAPTION + 3),
                )
                .map_err(e)?;
                root.draw(&Rectangle::new(
                    [
                        (ox - 1, oy - 1),
                        (
                            ox + (t.width * scale) as i32,
                            oy + (t.height * scale) as i32,
                        ),
                    ],
                    RGBColor(150, 150, 150).stroke_width(1),
                ))
                .map_err(e)?;
            }
        }
        if let Some((lo, hi, label)) = &colour_bar {
            let (bx, by, bw, bh) = bar_geometry;
            root.draw(&Rectangle::new(
                [(bx - 1, by - 1), (bx + bw, by + bh)],
                BLACK.stroke_width(1),
            ))
            .map_err(e)?;
            let style = TextStyle::from(font(13.0))
                .color(&BLACK)
                .pos(Pos::new(HPos::Left, VPos::Center));
            for k in 0..=4 {
                let f = f64::from(k) / 4.0;
                let v = hi - f * (hi - lo);
                let y = by + (f * f64::from(bh - 1)).round() as i32;
                root.draw(&PathElement::new(
                    vec![(bx + bw, y), (bx + bw + 5, y)],
                    BLACK.stroke_width(1),
                ))
                .map_err(e)?;
                root.draw_text(&format!("{v:+.3}"), &style, (bx + bw + 8, y))
                    .map_err(e)?;
            }
            // The bar's label, below it.
            let style = TextStyle::from(font(13.0)).color(&BLACK);
            for (i, part) in label.split('\n').enumerate() {
                root.draw_text(part, &style, (bx - 8, by + bh + 10 + i as i32 * 17))
                    .map_err(e)?;
            }
        }
        root.present().map_err(e)?;
    }
    crate::report::plots::encode_png(&buf, w, h)
}

/// The luminance difference `L(x) − L(r)` per pixel.
fn luminance_difference(test: &Image, reference: &Image) -> Vec<f64> {
    let l = |p: [f32; 3]| crate::estimators::luminance(p.map(f64::from));
    test.pixels()
        .iter()
        .zip(reference.pixels())
        .map(|(a, b)| l(*a) - l(*b))
        .collect()
}

/// `bias_<scene>.png`: the reference, then each bias-map estimator's luminance difference
/// from it at the largest spp on one symmetric diverging scale (the 99th percentile of |d|
/// over the maps; beyond it colours saturate).
fn bias_maps(dir: &Path, r: &SceneResult, tag: &str) -> Result<PathBuf> {
    let (w, h) = (r.reference.width(), r.reference.height());
    let full = [0, 0, w.max(h) as u32];
    let diffs: Vec<Vec<f64>> = r
        .bias_images
        .iter()
        .map(|(_, img)| luminance_difference(img, &r.reference))
        .collect();
    let mut mags: Vec<f64> = diffs.iter().flatten().map(|d| d.abs()).collect();
    mags.sort_by(f64::total_cmp);
    let lim = mags
        .get(((mags.len() as f64 * 0.99) as usize).min(mags.len().saturating_sub(1)))
        .copied()
        .filter(|v| *v > 0.0)
        .unwrap_or(1.0);
    let scale = (360 / w.max(1)).max(1);
    let mut tiles = vec![Tile::from_image(
        "reference".into(),
        &r.reference,
        full,
        display,
    )];
    for ((label, img), d) in r.bias_images.iter().zip(&diffs) {
        let rel = img.mean();
        let refm = r.reference.mean();
        let lum = |c: [f64; 3]| crate::estimators::luminance(c);
        let bias = if lum(refm) > 0.0 {
            format!("{:+.2}%", 100.0 * (lum(rel) - lum(refm)) / lum(refm))
        } else {
            "n/a".into()
        };
        let pixels = d.iter().map(|v| diverging(v / lim)).collect();
        tiles.push(Tile {
            caption: format!("{label}: mean bias {bias}"),
            width: w,
            height: h,
            pixels,
        });
    }
    let cols = 3usize;
    let rows: Vec<(String, Vec<Tile>)> = {
        let mut out = Vec::new();
        let mut it = tiles.into_iter().peekable();
        while it.peek().is_some() {
            out.push((String::new(), it.by_ref().take(cols).collect()));
        }
        out
    };
    let spp = r.info.spp;
    let png = draw_tiles(
        &format!("Bias maps, {}, {spp} spp{tag}", r.info.scene),
        &[format!(
            "Luminance of each estimator's image minus the reference's ({} spp), linear \
             radiance; red: brighter than the reference, blue: darker. The scale is the 99th \
             percentile of |difference| over the maps, ±{lim:.3}; beyond it colours saturate. \
             The mean's map is noise only (it is unbiased); a robust estimator's shows where it \
             removes energy.",
            r.info.reference_spp
        )],
        &rows,
        scale,
        Some((-lim, lim, "luminance difference\n(test − reference)".into())),
    )
    .map_err(|message| Error::Io {
        path: format!("bias_{}.png", r.info.scene),
        message,
    })?;
    let path = dir.join(format!("bias_{}.png", r.info.scene));
    write_atomic(&path, &png)?;
    Ok(path)
}

/// One row of a crop figure: the reference's window, then each labelled image's.
pub(crate) fn crop_row(
    label: String,
    reference: &Image,
    crop: [u32; 3],
    images: &[(String, Image)],
) -> (String, Vec<Tile>) {
    let tiles = std::iter::once(Tile::from_image(
        "reference".into(),
        reference,
        crop,
        display,
    ))
    .chain(
        images
            .iter()
            .map(|(caption, img)| Tile::from_image(caption.clone(), img, crop, display)),
    )
    .collect();
    (label, tiles)
}

/// `crops.png`: per scene, the firefly crop of the reference and of each crop estimator at
/// the crops' spp, tone-mapped as the previews are.
fn crops(dir: &Path, results: &[SceneResult], tag: &str) -> Result<PathBuf> {
    let size = results.iter().map(|r| r.crop[2]).max().unwrap_or(1) as usize;
    let scale = (160 / size.max(1)).max(1);
    let rows: Vec<(String, Vec<Tile>)> = results
        .iter()
        .map(|r| {
            let label = format!("{} ({} spp)", r.info.scene, r.crop_spp);
            crop_row(label, &r.reference, r.crop, &r.crop_images)
        })
        .collect();
    let png = draw_tiles(
        &format!("Firefly crops{tag}"),
        &[
            "Per scene, the window holding the most firefly pixels of the mean (luminance above \
             the rule's factor times the reference's plus its floor; or the crop the experiment \
             sets), for the reference and each estimator at the spp shown; exposure 1, clamped, \
             sRGB curve, nearest-neighbour enlargement."
                .into(),
        ],
        &rows,
        scale,
        None,
    )
    .map_err(|message| Error::Io {
        path: "crops.png".into(),
        message,
    })?;
    let path = dir.join("crops.png");
    write_atomic(&path, &png)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::diverging;

    #[test]
    fn diverging_map_is_white_at_zero_and_saturates() {
        assert_eq!(diverging(0.0), [247, 247, 247]);
        assert_eq!(diverging(1.0), [103, 0, 31]);
        assert_eq!(diverging(-1.0), [5, 48, 97]);
        assert_eq!(diverging(7.0), diverging(1.0));
        assert_eq!(diverging(f64::NAN), diverging(0.0));
        assert_eq!(diverging(0.25), [231, 172, 162]);
    }
}
