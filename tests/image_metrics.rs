//! Image metrics (src/image/metrics.rs): every metric on hand-made images with values worked
//! out by hand, and SSIM plus the others against scikit-image and numpy on the fixture written
//! by `tests/data/ssim/make_fixture.py`.

use fireflies::image::Image;
use fireflies::image::metrics::{self, FireflyRule, Metrics};

/// Asserts `|actual − expected| ≤ tol · |expected|`.
#[track_caller]
fn assert_rel(actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol * expected.abs(),
        "{actual:?} vs {expected:?}: relative error {:e}",
        (actual - expected).abs() / expected.abs()
    );
}

/// Hand-computed values below are exact up to a few roundings of f64.
const HAND: f64 = 1e-13;

/// The sRGB curve at the grey levels the hand-made cases use:
/// `T(v) = 1.055 v^(1/2.4) − 0.055` (all above the linear segment's 0.0031308).
const T_0_25: f64 = 0.537_098_730_483_194_2;
const T_0_375: f64 = 0.646_076_625_908_932_8;
const T_0_5: f64 = 0.735_356_983_052_449_5;

/// SSIM's `C1 = (0.01 · 1)²`.
const C1: f64 = 1e-4;

fn grey(width: usize, height: usize, v: f32) -> Image {
    Image::from_pixels(width, height, vec![[v; 3]; width * height]).unwrap()
}

fn with_pixel(
    mut pixels: Vec<[f32; 3]>,
    width: usize,
    x: usize,
    y: usize,
    v: [f32; 3],
) -> Vec<[f32; 3]> {
    pixels[y * width + x] = v;
    pixels
}

#[test]
fn identical_images_have_no_error() {
    let px: Vec<[f32; 3]> = (0..12 * 11)
        .map(|i| [i as f32 * 0.01, 1.5 - i as f32 * 0.005, (i % 7) as f32])
        .collect();
    let img = Image::from_pixels(12, 11, px).unwrap();
    let m = Metrics::compute(&img, &img, FireflyRule::default()).unwrap();
    assert_eq!(m.rmse, 0.0);
    assert_eq!(m.relmse, 0.0);
    assert_eq!(m.psnr_db, f64::INFINITY);
    // Equal inputs make SSIM's numerator and denominator the same expression.
    assert_eq!(m.ssim, 1.0);
    assert_eq!(m.mean_bias, 0.0);
    assert_eq!(m.mean_bias_relative, Some(0.0));
    assert_eq!((m.firefly_pixels, m.firefly_fraction), (0, 0.0));
    assert_eq!((m.width, m.height), (12, 11));
    // JSON writes the infinite PSNR as null.
    let json = serde_json::to_value(&m).unwrap();
    assert!(json["psnr_db"].is_null(), "{json}");
}

/// Reference grey 0.25, test grey 0.375: a constant offset of 0.125 (all exact in f32).
#[test]
fn constant_offset() {
    let (r, x) = (grey(11, 11, 0.25), grey(11, 11, 0.375));
    let m = Metrics::compute(&x, &r, FireflyRule::default()).unwrap();
    assert_eq!(m.rmse, 0.125);
    // 0.125² / (0.25² + 0.01) = 0.015625 / 0.0725.
    assert_rel(m.relmse, 0.015_625 / 0.0725, HAND);
    // PSNR = −20 log10(T(0.375) − T(0.25)) = 19.2532... dB.
    assert_rel(m.psnr_db, 19.253_231_668_372_838, HAND);
    assert_rel(m.psnr_db, -20.0 * (T_0_375 - T_0_25).log10(), HAND);
    // Flat windows: no variance, so SSIM is its luminance term (2ab + C1) / (a² + b² + C1).
    let ssim = (2.0 * T_0_375 * T_0_25 + C1) / (T_0_375 * T_0_375 + T_0_25 * T_0_25 + C1);
    assert_rel(m.ssim, ssim, 1e-12);
    assert_rel(m.ssim, 0.983_177_975_888_223_4, 1e-12);
    assert_eq!(m.mean_luminance, 0.375);
    assert_eq!(m.reference_mean_luminance, 0.25);
    assert_eq!(m.mean_bias, 0.125);
    assert_eq!(m.mean_bias_relative, Some(0.5));
    // 0.375 is not above 4 · 0.25 + 0.1.
    assert_eq!(m.firefly_pixels, 0);
    // Each metric also on its own.
    assert_eq!(metrics::rmse(&x, &r).unwrap(), m.rmse);
    assert_eq!(metrics::relmse(&x, &r).unwrap(), m.relmse);
    assert_eq!(metrics::psnr(&x, &r).unwrap(), m.psnr_db);
    assert_eq!(metrics::ssim(&x, &r).unwrap(), m.ssim);
}

/// One pixel of 10 in an 11×11 grey-0.25 reference.
#[test]
fn one_firefly_pixel() {
    let r = grey(11, 11, 0.25);
    let x =
        Image::from_pixels(11, 11, with_pixel(r.pixels().to_vec(), 11, 3, 7, [10.0; 3])).unwrap();
    let m = Metrics::compute(&x, &r, FireflyRule::default()).unwrap();
    assert_eq!((m.firefly_pixels, m.firefly_fraction), (1, 1.0 / 121.0));
    // One pixel off by 9.75 in each channel: RMSE = sqrt(3 · 9.75² / 363) = 9.75 / 11.
    assert_rel(m.rmse, 9.75 / 11.0, HAND);
    assert_rel(m.relmse, 9.75 * 9.75 / 0.0725 / 121.0, HAND);
    // The firefly shows as white: MSE_D = (1 − T(0.25))² / 121.
    assert_rel(
        m.psnr_db,
        -10.0 * ((1.0 - T_0_25).powi(2) / 121.0).log10(),
        HAND,
    );
    assert_rel(m.psnr_db, 27.518_086_266_234_256, HAND);
    assert_rel(m.mean_bias, 9.75 / 121.0, HAND);
    assert_rel(m.mean_bias_relative.unwrap(), 9.75 / 121.0 / 0.25, HAND);
    assert!(m.ssim < 1.0 && m.ssim > 0.0, "{}", m.ssim);
    // The pixel is at (3, 7), not (7, 3): move it to a pixel of the reference's level and
    // nothing is left.
    let back =
        Image::from_pixels(11, 11, with_pixel(x.pixels().to_vec(), 11, 3, 7, [0.25; 3])).unwrap();
    assert_eq!(
        metrics::firefly_pixels(&back, &r, FireflyRule::default()).unwrap(),
        0
    );
}

/// The rule is strict and reads luminance: with factor 4 and floor 0.125 over grey 0.25 the
/// threshold is exactly 1.125.
#[test]
fn firefly_threshold_is_strict_and_on_luminance() {
    let rule = FireflyRule::new(4.0, 0.125).unwrap();
    assert_eq!((rule.factor(), rule.floor()), (4.0, 0.125));
    let r = grey(3, 1, 0.25);
    // Luminance 1.125 exactly (grey), 1.25, and a red pixel of 1.25 whose luminance is
    // 0.2126 · 1.25 + 0.7152 · 0.25 + 0.0722 · 0.25 < 1.125.
    let x = Image::from_pixels(3, 1, vec![[1.125; 3], [1.25; 3], [1.25, 0.25, 0.25]]).unwrap();
    assert_eq!(metrics::firefly_pixels(&x, &r, rule).unwrap(), 1);
    assert!(rule.is_firefly(1.25, 0.25) && !rule.is_firefly(1.125, 0.25));
    for (factor, floor) in [
        (0.5, 0.1),
        (f64::NAN, 0.1),
        (f64::INFINITY, 0.1),
        (4.0, -1.0),
        (4.0, f64::NAN),
    ] {
        let e = FireflyRule::new(factor, floor).unwrap_err().to_string();
        assert!(e.contains("firefly-"), "{e}");
    }
    assert_eq!(FireflyRule::default(), FireflyRule::new(4.0, 0.1).unwrap());
}

/// Black reference, grey-0.5 test: relMSE's ε is the whole denominator, and there is no
/// relative bias.
#[test]
fn zero_reference() {
    let (r, x) = (grey(11, 11, 0.0), grey(11, 11, 0.5));
    let m = Metrics::compute(&x, &r, FireflyRule::default()).unwrap();
    assert_eq!(m.rmse, 0.5);
    assert_rel(m.relmse, 0.25 / 0.01, HAND);
    assert_rel(m.psnr_db, -20.0 * T_0_5.log10(), HAND);
    assert_rel(m.psnr_db, 2.670_035_582_064_635, HAND);
    // (0 + C1) / (T(0.5)² + 0 + C1), the structure term being C2 / C2.
    assert_rel(m.ssim, C1 / (T_0_5 * T_0_5 + C1), 1e-10);
    assert_eq!(m.mean_bias, 0.5);
    assert_eq!(m.mean_bias_relative, None);
    // 0.5 > 4 · 0 + 0.1 everywhere.
    assert_eq!((m.firefly_pixels, m.firefly_fraction), (121, 1.0));
    let json = serde_json::to_value(&m).unwrap();
    assert!(json["mean_bias_relative"].is_null(), "{json}");
}

#[test]
fn bad_inputs_are_errors_naming_the_problem() {
    let e = Metrics::compute(
        &grey(12, 11, 0.0),
        &grey(11, 13, 0.0),
        FireflyRule::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("12x11") && e.contains("11x13"), "{e}");
    let e = metrics::rmse(&grey(2, 2, 0.0), &grey(2, 3, 0.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("2x2") && e.contains("2x3"), "{e}");
    // SSIM needs its whole 11×11 window.
    let e = metrics::ssim(&grey(10, 40, 0.0), &grey(10, 40, 0.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("10x40") && e.contains("11x11"), "{e}");
    assert!(metrics::rmse(&grey(10, 40, 0.0), &grey(10, 40, 0.0)).is_ok());
    // A non-finite value names its image and pixel.
    let bad = Image::from_pixels(
        11,
        11,
        with_pixel(vec![[0.0; 3]; 121], 11, 4, 9, [0.0, f32::NAN, 0.0]),
    )
    .unwrap();
    let e = Metrics::compute(&grey(11, 11, 0.0), &bad, FireflyRule::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("reference") && e.contains("(4, 9)"), "{e}");
    let e = metrics::relmse(&bad, &grey(11, 11, 0.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("test") && e.contains("(4, 9)"), "{e}");
    let e = metrics::ssim_gray(&[0.0; 120], &[0.0; 121], 11, 11)
        .unwrap_err()
        .to_string();
    assert!(e.contains("120"), "{e}");
}

#[test]
fn tone_map_is_the_clamped_srgb_curve() {
    assert_eq!(metrics::tone_map(-3.0), 0.0);
    assert_eq!(metrics::tone_map(0.0), 0.0);
    assert_eq!(metrics::tone_map(0.002), 12.92 * 0.002);
    assert_rel(metrics::tone_map(0.25), T_0_25, HAND);
    assert_rel(metrics::tone_map(1.0), 1.0, HAND);
    assert_eq!(metrics::tone_map(50.0), metrics::tone_map(1.0));
    // Luma weighs the tone-mapped channels: a pure red of 4 is 0.2126 · T(1).
    assert_rel(metrics::display_luma([4.0, 0.0, 0.0]), 0.2126, HAND);
}

/// Agreement with scikit-image's SSIM and numpy's other metrics. Both sides compute in f64
/// from the same exactly representable pixel values; what differs is summation order and the
/// separable filter's rounding, about 1e-14 (seen: at most 7.8e-15 on SSIM).
const FIXTURE_TOL: f64 = 1e-10;

#[test]
fn metrics_agree_with_scikit_image_and_numpy() {
    let text = std::fs::read_to_string("tests/data/ssim/fixture.json").unwrap();
    let fixture: serde_json::Value = serde_json::from_str(&text).unwrap();
    let scale = fixture["scale"].as_f64().unwrap();
    let rule = FireflyRule::new(
        fixture["firefly_factor"].as_f64().unwrap(),
        fixture["firefly_floor"].as_f64().unwrap(),
    )
    .unwrap();
    let image = |name: &str| {
        let o = &fixture["images"][name];
        let (w, h) = (
            o["width"].as_u64().unwrap() as usize,
            o["height"].as_u64().unwrap() as usize,
        );
        let codes: Vec<f32> = o["codes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| (c.as_u64().unwrap() as f64 * scale) as f32)
            .collect();
        let px = codes.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        Image::from_pixels(w, h, px).unwrap()
    };
    let pairs = fixture["pairs"].as_array().unwrap();
    assert_eq!(pairs.len(), 8);
    for p in pairs {
        let (t, r) = (
            p["test"].as_str().unwrap(),
            p["reference"].as_str().unwrap(),
        );
        let m = Metrics::compute(&image(t), &image(r), rule).unwrap();
        let close = |name: &str, ours: f64| {
            let theirs = p[name].as_f64().unwrap();
            assert!(
                (ours - theirs).abs() <= FIXTURE_TOL * theirs.abs().max(1.0),
                "{t} vs {r}: {name} {ours} here, {theirs} in the fixture"
            );
        };
        close("ssim", m.ssim);
        close("rmse", m.rmse);
        close("relmse", m.relmse);
        close("mean_luminance", m.mean_luminance);
        close("reference_mean_luminance", m.reference_mean_luminance);
        close("mean_bias", m.mean_bias);
        match p["psnr_db"].as_f64() {
            Some(_) => close("psnr_db", m.psnr_db),
            None => assert_eq!(m.psnr_db, f64::INFINITY),
        }
        assert_eq!(
            m.firefly_pixels,
            p["firefly_pixels"].as_u64().unwrap(),
            "{t} vs {r}"
        );
    }
    // The fixture is not degenerate: its SSIMs span the range.
    let ssims: Vec<f64> = pairs.iter().map(|p| p["ssim"].as_f64().unwrap()).collect();
    assert!(ssims.iter().any(|&s| s < 0.1) && ssims.iter().any(|&s| s > 0.9 && s < 1.0));
}
