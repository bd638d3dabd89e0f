//! How far a rendered image is from a reference of the same size: RMSE, relMSE, PSNR, SSIM,
//! the image's mean bias and its firefly pixels, all read at once into one [`Metrics`] row so
//! that a convergence table holds one row per image and checkpoint.
//!
//! # Definitions
//!
//! `x` is the test image, `r` the reference, both linear RGB; sums run over the `P` pixels and,
//! where a channel index `c` appears, over the three channels.
//!
//! * **RMSE** `= sqrt( Σ (x − r)² / 3P )`, on linear values.
//! * **relMSE** `= Σ (x − r)² / (r² + ε) / 3P` with `ε = 0.01` ([`RELMSE_EPSILON`]), on linear
//!   values, per channel (the relative MSE of Rousselle et al. 2011 that the denoising literature
//!   reports; `ε` keeps black reference pixels from dominating).
//! * **The display image** `D = T(x)`, per channel, with `T(v)` the sRGB transfer curve
//!   (IEC 61966-2-1: `12.92 v` for `v ≤ 0.0031308`, else `1.055 v^(1/2.4) − 0.055`) of the value
//!   clamped to `[0, 1]`, exposure 1: what the PNG previews show, before 8-bit rounding.
//! * **PSNR** `= 10 log10(1 / MSE_D)` dB with `MSE_D = Σ (T(x) − T(r))² / 3P`: the peak is 1
//!   because `T` maps every value into `[0, 1]` (linear HDR values have no natural peak).
//!   `+inf` when the display images are equal (JSON writes it as `null`).
//! * **SSIM**: Wang et al. 2004 on the luma of the display image,
//!   `Y' = 0.2126 T(R) + 0.7152 T(G) + 0.0722 T(B)` (Rec. 709 weights of the tone-mapped
//!   channels, in `[0, 1]`), data range 1: Gaussian window of 11×11 taps with σ = 1.5
//!   (normalised over the 11 taps of each axis, as `scipy.ndimage` truncates at 3.5σ), `K1 =
//!   0.01`, `K2 = 0.03`, population (not sample) covariances. The SSIM map is averaged over the
//!   pixels whose whole window lies inside the image, that is with 5 pixels cropped from each
//!   side, which is scikit-image's `structural_similarity(x, r, gaussian_weights=True, sigma=1.5,
//!   use_sample_covariance=False, data_range=1)` (checked against it in
//!   `tests/image_metrics.rs`). Needs at least 11×11 pixels.
//! * **Mean bias** `= mean(L(x)) − mean(L(r))`, with `L` the Rec. 709 luminance of the linear
//!   pixel, and relative to `mean(L(r))` (none when that is 0).
//! * **Firefly pixels**: pixels with `L(x) > factor · L(r) + floor` ([`FireflyRule`], by
//!   default 4 and 0.1): much brighter than they should be, and by a visible amount.
//!
//! Every pixel of both images must be finite; negative values are allowed (`T` clamps them).

use super::Image;
use crate::error::{Error, Result};
use crate::estimators::luminance;
use serde::{Deserialize, Serialize};

/// `ε` of relMSE's denominator `r² + ε`.
pub const RELMSE_EPSILON: f64 = 0.01;

/// SSIM's Gaussian window: σ in pixels (Wang et al. 2004).
pub const SSIM_SIGMA: f64 = 1.5;

/// SSIM's window radius: 11 taps, `int(3.5 σ + 0.5)` as `scipy.ndimage` truncates a Gaussian.
pub const SSIM_RADIUS: usize = 5;

/// SSIM's `K1` (luminance term constant `C1 = (K1 · range)²`).
pub const SSIM_K1: f64 = 0.01;

/// SSIM's `K2` (contrast-structure constant `C2 = (K2 · range)²`).
pub const SSIM_K2: f64 = 0.03;

/// When a pixel counts as a firefly: `L(x) > factor · L(r) + floor`, luminances linear.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FireflyRule {
    factor: f64,
    floor: f64,
}

impl FireflyRule {
    /// Default `factor`: four times the reference is well beyond what ordinary noise of a mean
    /// with relative standard deviation ≤ 1 reaches (3 of its standard deviations above).
    pub const DEFAULT_FACTOR: f64 = 4.0;

    /// Default `floor`: a tenth of display white (sRGB code 89 of 255 over black), so that dark
    /// pixels a few times too bright but still black on screen do not count.
    pub const DEFAULT_FLOOR: f64 = 0.1;

    /// A rule with its factor and floor.
    ///
    /// # Errors
    ///
    /// `factor` must be finite and ≥ 1 (a firefly is brighter than its reference), `floor`
    /// finite and ≥ 0.
    ///
    /// ```
    /// use fireflies::image::metrics::FireflyRule;
    /// assert!(FireflyRule::new(4.0, 0.1).is_ok());
    /// assert!(FireflyRule::new(0.5, 0.1).is_err());
    /// assert!(FireflyRule::new(4.0, f64::NAN).is_err());
    /// ```
    pub fn new(factor: f64, floor: f64) -> Result<Self> {
        if !(factor.is_finite() && factor >= 1.0) {
            return Err(Error::param(
                "firefly-factor",
                factor,
                "must be finite and >= 1",
            ));
        }
        if !(floor.is_finite() && floor >= 0.0) {
            return Err(Error::param(
                "firefly-floor",
                floor,
                "must be finite and >= 0",
            ));
        }
        Ok(FireflyRule { factor, floor })
    }

    /// The factor on the reference's luminance.
    pub fn factor(&self) -> f64 {
        self.factor
    }

    /// The absolute margin added to it.
    pub fn floor(&self) -> f64 {
        self.floor
    }

    /// Whether a pixel of luminance `lum` is a firefly over a reference of luminance `ref_lum`.
    /// A negative reference (a denoiser's output can undershoot) counts as 0: otherwise a pixel
    /// equal to it, say −1 against −1, would pass `−1 > 4·(−1) + 0.1`.
    ///
    /// ```
    /// use fireflies::image::metrics::FireflyRule;
    /// let rule = FireflyRule::default();
    /// assert!(rule.is_firefly(0.5, 0.05));
    /// assert!(!rule.is_firefly(-1.0, -1.0));
    /// assert!(!rule.is_firefly(0.05, -1.0));
    /// ```
    pub fn is_firefly(&self, lum: f64, ref_lum: f64) -> bool {
        lum > self.factor * ref_lum.max(0.0) + self.floor
    }
}

impl Default for FireflyRule {
    fn default() -> Self {
        FireflyRule {
            factor: Self::DEFAULT_FACTOR,
            floor: Self::DEFAULT_FLOOR,
        }
    }
}

/// Every metric of one test image against its reference (see the module docs for formulas).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Root mean squared error over pixels and channels, linear.
    pub rmse: f64,
    /// Mean of `(x − r)² / (r² + 0.01)` over pixels and channels, linear.
    pub relmse: f64,
    /// PSNR in dB of the display images, peak 1 (`+inf`, JSON `null`, when they are equal).
    pub psnr_db: f64,
    /// SSIM of the display images' luma (Wang et al. 2004, scikit-image's convention).
    pub ssim: f64,
    /// Mean linear luminance of the test image.
    pub mean_luminance: f64,
    /// Mean linear luminance of the reference.
    pub reference_mean_luminance: f64,
    /// `mean_luminance − reference_mean_luminance`.
    pub mean_bias: f64,
    /// `mean_bias / reference_mean_luminance`; `None` when the reference is black on average.
    pub mean_bias_relative: Option<f64>,
    /// Pixels counted as fireflies by the rule below.
    pub firefly_pixels: u64,
    /// `firefly_pixels` over the number of pixels.
    pub firefly_fraction: f64,
    /// The rule's factor.
    pub firefly_factor: f64,
    /// The rule's floor.
    pub firefly_floor: f64,
}

impl Metrics {
    /// Every metric of `test` against `reference`.
    ///
    /// # Errors
    ///
    /// The images differ in size (the message names both sizes), either holds a non-finite
    /// value (the message names the pixel), or they are smaller than SSIM's 11×11 window.
    ///
    /// ```
    /// use fireflies::image::Image;
    /// use fireflies::image::metrics::{FireflyRule, Metrics};
    /// let r = Image::from_pixels(11, 11, vec![[0.5; 3]; 121]).unwrap();
    /// let m = Metrics::compute(&r, &r, FireflyRule::default()).unwrap();
    /// assert_eq!((m.rmse, m.ssim, m.firefly_pixels), (0.0, 1.0, 0));
    /// let small = Image::new(4, 4);
    /// assert!(Metrics::compute(&small, &r, FireflyRule::default()).is_err());
    /// ```
    pub fn compute(test: &Image, reference: &Image, rule: FireflyRule) -> Result<Metrics> {
        check_pair(test, reference)?;
        let (mean_luminance, reference_mean_luminance) = mean_luminances(test, reference);
        let mean_bias = mean_luminance - reference_mean_luminance;
        let firefly_pixels = count_fireflies(test, reference, rule);
        Ok(Metrics {
            width: test.width(),
            height: test.height(),
            rmse: mse(test, reference).sqrt(),
            relmse: relmse_unchecked(test, reference),
            psnr_db: psnr_unchecked(test, reference),
            ssim: ssim_unchecked(test, reference)?,
            mean_luminance,
            reference_mean_luminance,
            mean_bias,
            mean_bias_relative: relative(mean_bias, reference_mean_luminance),
            firefly_pixels,
            firefly_fraction: firefly_pixels as f64 / test.pixels().len() as f64,
            firefly_factor: rule.factor,
            firefly_floor: rule.floor,
        })
    }
}

/// The display transform `T`: the sRGB transfer curve of the value clamped to `[0, 1]`.
pub fn tone_map(v: f64) -> f64 {
    let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The luma SSIM reads: Rec. 709 weights of the tone-mapped channels, in `[0, 1]`.
pub fn display_luma(p: [f32; 3]) -> f64 {
    luminance(p.map(|c| tone_map(f64::from(c))))
}

/// Root mean squared error over pixels and channels.
///
/// # Errors
///
/// As [`Metrics::compute`], except that any size is allowed.
pub fn rmse(test: &Image, reference: &Image) -> Result<f64> {
    check_pair(test, reference)?;
    Ok(mse(test, reference).sqrt())
}

/// Mean of `(x − r)² / (r² + 0.01)` over pixels and channels.
///
/// # Errors
///
/// As [`rmse`].
pub fn relmse(test: &Image, reference: &Image) -> Result<f64> {
    check_pair(test, reference)?;
    Ok(relmse_unchecked(test, reference))
}

/// PSNR in dB of the display images, peak 1; `+inf` when they are equal.
///
/// # Errors
///
/// As [`rmse`].
pub fn psnr(test: &Image, reference: &Image) -> Result<f64> {
    check_pair(test, reference)?;
    Ok(psnr_unchecked(test, reference))
}

/// SSIM of the display images' luma (see the module docs).
///
/// # Errors
///
/// As [`Metrics::compute`].
pub fn ssim(test: &Image, reference: &Image) -> Result<f64> {
    check_pair(test, reference)?;
    ssim_unchecked(test, reference)
}

/// Number of firefly pixels of `test` over `reference` under `rule`.
///
/// # Errors
///
/// As [`rmse`].
pub fn firefly_pixels(test: &Image, reference: &Image, rule: FireflyRule) -> Result<u64> {
    check_pair(test, reference)?;
    Ok(count_fireflies(test, reference, rule))
}

/// Mean SSIM of two grey images with values in `[0, 1]` (data range 1), row-major,
/// `width × height` each: Wang et al.'s Gaussian SSIM averaged over the pixels at least
/// [`SSIM_RADIUS`] from every border.
///
/// # Errors
///
/// Either slice is not `width · height` long, or a side is shorter than the 11-pixel window.
pub fn ssim_gray(a: &[f64], b: &[f64], width: usize, height: usize) -> Result<f64> {
    let n = width
        .checked_mul(height)
        .ok_or_else(|| Error::param("ssim size", format!("{width}x{height}"), "too large"))?;
    for (name, img) in [("ssim image", a), ("ssim reference", b)] {
        if img.len() != n {
            return Err(Error::param(
                name,
                img.len(),
                format!("a {width}x{height} image needs {n} values"),
            ));
        }
    }
    let window = 2 * SSIM_RADIUS + 1;
    if width < window || height < window {
        return Err(Error::param(
            "ssim size",
            format!("{width}x{height}"),
            format!("SSIM's Gaussian window needs an image at least {window}x{window} pixels"),
        ));
    }
    let kernel = gaussian_kernel();
    let r = SSIM_RADIUS;
    let (inner_w, inner_h) = (width - 2 * r, height - 2 * r);
    // The five local moments, filtered along rows for every row at the inner columns.
    let mut rows = vec![[0.0f64; 5]; height * inner_w];
    for y in 0..height {
        for i in 0..inner_w {
            let mut m = [0.0f64; 5];
            for (k, &w) in kernel.iter().enumerate() {
                let j = y * width + i + k;
                let (p, q) = (a[j], b[j]);
                m[0] += w * p;
                m[1] += w * q;
                m[2] += w * p * p;
                m[3] += w * q * q;
                m[4] += w * p * q;
            }
            rows[y * inner_w + i] = m;
        }
    }
    let c1 = (SSIM_K1 * 1.0).powi(2);
    let c2 = (SSIM_K2 * 1.0).powi(2);
    let mut sum = 0.0f64;
    for y in 0..inner_h {
        for i in 0..inner_w {
            let mut m = [0.0f64; 5];
            for (k, &w) in kernel.iter().enumerate() {
                let row = &rows[(y + k) * inner_w + i];
                for (acc, v) in m.iter_mut().zip(row) {
                    *acc += w * v;
                }
            }
            let [ux, uy, uxx, uyy, uxy] = m;
            let (vx, vy, vxy) = (uxx - ux * ux, uyy - uy * uy, uxy - ux * uy);
            let num = (2.0 * ux * uy + c1) * (2.0 * vxy + c2);
            let den = (ux * ux + uy * uy + c1) * (vx + vy + c2);
            sum += num / den;
        }
    }
    Ok(sum / (inner_w * inner_h) as f64)
}

/// The 11 normalised taps of a Gaussian of σ = 1.5.
fn gaussian_kernel() -> [f64; 2 * SSIM_RADIUS + 1] {
    let mut k = [0.0f64; 2 * SSIM_RADIUS + 1];
    for (i, w) in k.iter_mut().enumerate() {
        let x = i as f64 - SSIM_RADIUS as f64;
        *w = (-0.5 * x * x / (SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let total: f64 = k.iter().sum();
    k.map(|w| w / total)
}

/// Equal sizes and finite values, or an error naming the sizes or the pixel.
fn check_pair(test: &Image, reference: &Image) -> Result<()> {
    let size = |i: &Image| format!("{}x{}", i.width(), i.height());
    if (test.width(), test.height()) != (reference.width(), reference.height()) {
        return Err(Error::param(
            "image size",
            format!("test {} vs reference {}", size(test), size(reference)),
            "metrics compare images of equal size",
        ));
    }
    for (name, img) in [("test image", test), ("reference image", reference)] {
        if let Some(i) = img
            .pixels()
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            let (x, y) = (i % img.width(), i / img.width());
            return Err(Error::param(
                name,
                format!("pixel ({x}, {y}) = {:?}", img.pixels()[i]),
                "metrics need finite values",
            ));
        }
    }
    Ok(())
}

/// Mean over pixels and channels of `f(x, r)`.
fn channel_mean(test: &Image, reference: &Image, f: impl Fn(f64, f64) -> f64) -> f64 {
    let mut sum = 0.0f64;
    for (p, q) in test.pixels().iter().zip(reference.pixels()) {
        for c in 0..3 {
            sum += f(f64::from(p[c]), f64::from(q[c]));
        }
    }
    sum / (3 * test.pixels().len().max(1)) as f64
}

fn mse(test: &Image, reference: &Image) -> f64 {
    channel_mean(test, reference, |x, r| (x - r) * (x - r))
}

fn relmse_unchecked(test: &Image, reference: &Image) -> f64 {
    channel_mean(test, reference, |x, r| {
        (x - r) * (x - r) / (r * r + RELMSE_EPSILON)
    })
}

fn psnr_unchecked(test: &Image, reference: &Image) -> f64 {
    let mse = channel_mean(test, reference, |x, r| {
        let d = tone_map(x) - tone_map(r);
        d * d
    });
    -10.0 * mse.log10()
}

fn ssim_unchecked(test: &Image, reference: &Image) -> Result<f64> {
    let luma = |i: &Image| i.pixels().iter().map(|&p| display_luma(p)).collect();
    let (a, b): (Vec<f64>, Vec<f64>) = (luma(test), luma(reference));
    ssim_gray(&a, &b, test.width(), test.height())
}

fn pixel_luminance(p: [f32; 3]) -> f64 {
    luminance(p.map(f64::from))
}

fn mean_luminances(test: &Image, reference: &Image) -> (f64, f64) {
    let n = test.pixels().len().max(1) as f64;
    let mean = |i: &Image| i.pixels().iter().map(|&p| pixel_luminance(p)).sum::<f64>() / n;
    (mean(test), mean(reference))
}

fn relative(diff: f64, base: f64) -> Option<f64> {
    (base != 0.0).then(|| diff / base)
}

fn count_fireflies(test: &Image, reference: &Image, rule: FireflyRule) -> u64 {
    test.pixels()
        .iter()
        .zip(reference.pixels())
        .filter(|&(&p, &q)| rule.is_firefly(pixel_luminance(p), pixel_luminance(q)))
        .count() as u64
}
