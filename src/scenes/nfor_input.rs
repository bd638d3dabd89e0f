//! From a render's NFOR buffers ([`NforBuffers`]) to NFOR's input ([`NforInput`]): which colour
//! is denoised (the plain mean of each half, or a robust estimator run on each half) and where
//! its per-half variance comes from.

use crate::denoise::nfor::{Halves, NforInput};
use crate::denoise::planes::Planes;
use crate::error::{Error, Result};
use crate::render::nfor_buffers::{HalfBuffer, NforBuffers};

/// The colour NFOR denoises.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ColorSource {
    /// The mean of each half's samples.
    Mean,
    /// A robust estimator the render ran on each half, by spec (`gmon:M=21`) or file stem.
    Estimator(String),
}

impl ColorSource {
    /// `mean`, or an estimator's spec or stem.
    pub fn parse(text: &str) -> Self {
        if text == "mean" {
            ColorSource::Mean
        } else {
            ColorSource::Estimator(text.to_string())
        }
    }

    /// How the source is written on the command line and in reports.
    pub fn name(&self) -> &str {
        match self {
            ColorSource::Mean => "mean",
            ColorSource::Estimator(s) => s,
        }
    }
}

/// Where the variance of each half's colour comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum VarianceSource {
    /// The sample variance of the half's mean, as the renderer wrote it. Exact for the mean;
    /// for a robust estimator it is the variance of the mean of the same samples, which
    /// overstates the estimator's own where it removed outliers.
    Sample,
    /// `(a − b)²/2` per pixel and channel (unbiased for a half's variance when both halves
    /// have the same), averaged over a [`HALVES_BOX`]-pixel square so it is not a
    /// one-degree-of-freedom guess. Works for any estimator; blurs variance edges.
    Halves,
}

/// Side of the box that smooths the halves-difference variance.
pub const HALVES_BOX: usize = 7;

impl VarianceSource {
    /// The default for a colour source: the renderer's sample variance for the mean, the
    /// halves' difference for a robust estimator.
    pub fn default_for(source: &ColorSource) -> Self {
        match source {
            ColorSource::Mean => VarianceSource::Sample,
            ColorSource::Estimator(_) => VarianceSource::Halves,
        }
    }
}

/// NFOR's input from `buffers`: the colour of `source` with variances from `variance`, and
/// every feature buffer (normal, albedo, depth, visibility; the last two single-channel).
pub fn nfor_input(
    buffers: &NforBuffers,
    source: &ColorSource,
    variance: VarianceSource,
) -> Result<NforInput> {
    let rgb = |b: &HalfBuffer| Halves {
        mean: [Planes::from_rgb(&b.mean[0]), Planes::from_rgb(&b.mean[1])],
        var: [Planes::from_rgb(&b.var[0]), Planes::from_rgb(&b.var[1])],
    };
    let grey = |b: &HalfBuffer| Halves {
        mean: [Planes::from_grey(&b.mean[0]), Planes::from_grey(&b.mean[1])],
        var: [Planes::from_grey(&b.var[0]), Planes::from_grey(&b.var[1])],
    };
    let sample = rgb(&buffers.color);
    let mean = match source {
        ColorSource::Mean => sample.mean.clone(),
        ColorSource::Estimator(name) => {
            let e = buffers
                .estimators
                .iter()
                .find(|e| &e.spec == name || &e.stem == name)
                .ok_or_else(|| {
                    let have: Vec<&str> =
                        buffers.estimators.iter().map(|e| e.spec.as_str()).collect();
                    Error::param(
                        "estimator",
                        name,
                        format!(
                            "the render has no halves of it; it has: mean, {}",
                            have.join(", ")
                        ),
                    )
                })?;
            [Planes::from_rgb(&e.image[0]), Planes::from_rgb(&e.image[1])]
        }
    };
    let var = match variance {
        VarianceSource::Sample => sample.var,
        VarianceSource::Halves => {
            let v = halves_variance(&mean[0], &mean[1]);
            [v.clone(), v]
        }
    };
    Ok(NforInput {
        color: Halves { mean, var },
        counts: crate::render::nfor_buffers::half_counts(buffers.spp),
        features: vec![
            ("normal".into(), rgb(&buffers.normal)),
            ("albedo".into(), rgb(&buffers.albedo)),
            ("depth".into(), grey(&buffers.depth)),
            ("visibility".into(), grey(&buffers.visibility)),
        ],
    })
}

/// `(a − b)²/2`, box-averaged over [`HALVES_BOX`]² pixels (cut at the border).
pub fn halves_variance(a: &Planes, b: &Planes) -> Planes {
    let raw = a.zip_map(b, |x, y| 0.5 * (x - y) * (x - y));
    let (w, h) = (a.width(), a.height());
    let r = HALVES_BOX / 2;
    let mut out = Planes::zeros(w, h, raw.channels());
    for c in 0..raw.channels() {
        let src = raw.plane(c);
        // Horizontal then vertical running means, in f64 so long rows do not drift.
        let mut rows = vec![0.0f64; w * h];
        for y in 0..h {
            for x in 0..w {
                let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
                rows[y * w + x] = src[y * w + x0..y * w + x1]
                    .iter()
                    .map(|&v| f64::from(v))
                    .sum::<f64>();
            }
        }
        let dst = out.plane_mut(c);
        for y in 0..h {
            let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
            for x in 0..w {
                let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
                let s: f64 = (y0..y1).map(|yy| rows[yy * w + x]).sum();
                dst[y * w + x] = (s / ((y1 - y0) * (x1 - x0)) as f64) as f32;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_variance_is_the_boxed_half_squared_difference() {
        let a = Planes::from_planes(3, 1, vec![vec![1.0, 1.0, 1.0]]).unwrap();
        let b = Planes::from_planes(3, 1, vec![vec![3.0, 1.0, 1.0]]).unwrap();
        // Raw: [2, 0, 0]; a 7-wide box covers the whole row: mean 2/3 everywhere.
        let v = halves_variance(&a, &b);
        for &x in v.plane(0) {
            assert!((x - 2.0 / 3.0).abs() < 1e-6);
        }
    }

    #[test]
    fn sources_parse_and_default() {
        assert_eq!(ColorSource::parse("mean"), ColorSource::Mean);
        let g = ColorSource::parse("gmon:M=21");
        assert_eq!(g.name(), "gmon:M=21");
        assert_eq!(VarianceSource::default_for(&g), VarianceSource::Halves);
        assert_eq!(
            VarianceSource::default_for(&ColorSource::Mean),
            VarianceSource::Sample
        );
    }
}
