//! The tail QQ plot of `fireflies fit`: every sample above the tail threshold against the fitted
//! law's quantile at the same plotting position, both axes logarithmic. Points on the diagonal
//! mean the fitted tail has the samples' shape; a bend away from it at the top is a tail the
//! fit makes too light (points above) or too heavy (points below).
//!
//! The points are computed by [`crate::dist::fit::Fit::tail_qq`]; this module only draws them.

use crate::error::{Error, Result};
use crate::report::plots::{Coord, FONT, fmt_tick, register_fonts, ticks};
use crate::report::write_atomic;
use plotters::prelude::*;
use std::path::Path;

/// Image size in pixels.
const SIZE: (u32, u32) = (720, 680);
/// Marker radius in pixels.
const DOT: i32 = 3;

/// Draws the QQ plot of `points` (`(fitted quantile, sample)` pairs, both > 0) into `path` as
/// a PNG, atomically. `title` names the stream; `notes` (short lines) say what was fitted.
///
/// # Errors
///
/// [`Error::InvalidParameter`] naming `points` when there is no point to draw or one is not
/// finite and positive; [`Error::Io`] naming `path` when drawing or writing fails.
pub fn write_tail_qq(
    path: &Path,
    points: &[(f64, f64)],
    title: &str,
    notes: &[String],
) -> Result<()> {
    if points.is_empty() {
        return Err(Error::param(
            "points",
            0,
            "no sample lies above the tail threshold: nothing to plot",
        ));
    }
    if let Some(&(x, y)) = points
        .iter()
        .find(|(x, y)| !(*x > 0.0 && x.is_finite() && *y > 0.0 && y.is_finite()))
    {
        return Err(Error::param(
            "points",
            format!("({x}, {y})"),
            "QQ points must be finite and > 0 (log axes)",
        ));
    }
    register_fonts()?;
    let png = render(points, title, notes).map_err(|message| Error::Io {
        path: path.display().to_string(),
        message,
    })?;
    write_atomic(path, &png)
}

/// The shared range of both axes: every point, padded by a tenth of a decade each side.
fn range(points: &[(f64, f64)]) -> (f64, f64) {
    let (lo, hi) = points
        .iter()
        .flat_map(|&(x, y)| [x, y])
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    let pad = 10f64.powf(0.1);
    let (lo, hi) = (lo / pad, hi * pad);
    // A single value still needs a range to draw in.
    if hi / lo < 1.5 {
        (lo / 1.25, hi * 1.25)
    } else {
        (lo, hi)
    }
}

fn render(
    points: &[(f64, f64)],
    title: &str,
    notes: &[String],
) -> std::result::Result<Vec<u8>, String> {
    let (w, h) = SIZE;
    let mut buf = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        draw(&root, points, title, notes).map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    crate::report::plots::encode_png(&buf, w, h)
}

/// A log axis over `lo..hi` with the report plots' ticks.
fn log_axis(lo: f64, hi: f64) -> Coord {
    Coord {
        log: true,
        lo,
        hi,
        ticks: ticks(true, lo, hi),
    }
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

fn draw(
    root: &Area<'_>,
    points: &[(f64, f64)],
    title: &str,
    notes: &[String],
) -> std::result::Result<
    (),
    DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>,
> {
    root.fill(&WHITE)?;
    let font = |size: f64| FontDesc::new(FontFamily::Name(FONT), size, FontStyle::Normal);
    let bold = FontDesc::new(FontFamily::Name(FONT), 22.0, FontStyle::Bold);
    root.draw_text(title, &bold.into_text_style(root), (16, 12))?;
    for (i, note) in notes.iter().enumerate() {
        let y = 42 + 20 * i as i32;
        root.draw_text(note, &font(15.0).into_text_style(root), (16, y))?;
    }
    let area = root.margin(50 + 20 * notes.len() as u32, 16, 16, 24);
    let (lo, hi) = range(points);
    let mut chart = ChartBuilder::on(&area)
        .x_label_area_size(56)
        .y_label_area_size(80)
        .build_cartesian_2d(log_axis(lo, hi), log_axis(lo, hi))?;
    chart
        .configure_mesh()
        .x_desc("fitted quantile of luminance above the threshold (scene units, log scale)")
        .y_desc("sample luminance (scene units, log scale)")
        .axis_desc_style(font(16.0))
        .label_style(font(14.0))
        .x_label_formatter(&|v| fmt_tick(*v))
        .y_label_formatter(&|v| fmt_tick(*v))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    let grey = RGBColor(120, 120, 120);
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(lo, lo), (hi, hi)],
        grey.stroke_width(1),
    )))?;
    let blue = RGBColor(0, 114, 178);
    chart.draw_series(
        points
            .iter()
            .map(|&(x, y)| Circle::new((x, y), DOT, blue.mix(0.7).filled())),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_pads_and_widens() {
        let (lo, hi) = range(&[(1.0, 2.0), (10.0, 100.0)]);
        assert!((lo - 10f64.powf(-0.1)).abs() < 1e-12 && (hi - 10f64.powf(2.1)).abs() < 1e-9);
        let (lo, hi) = range(&[(5.0, 5.0)]);
        assert!(lo < 5.0 / 1.25 && hi > 5.0 * 1.25);
    }
}
