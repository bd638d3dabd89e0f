//! The `bitmap` and `checkerboard` textures against Mitsuba 3.9.1 (`scalar_rgb`): Mitsuba's own
//! `eval`, `eval_1` and `mean` on tiny images it wrote, and on the living-room scene's textures.
//! The fixture and the script that made it are in `tests/data/textures/`.
//!
//! Tolerances, and why:
//! * Float data (OpenEXR half/float, Radiance HDR), 16-bit PNG (both sides round to half) and
//!   raw 8-bit PNG: **bit-exact**. Positions, weights, blends and luminance use the fused
//!   multiply-adds Mitsuba's build uses, so any change of convention or arithmetic shows.
//! * sRGB 8-bit PNG: Mitsuba decodes with a rational approximation of the sRGB curve, we with
//!   the exact curve; over all 256 codes they differ by at most 4.2e-7 (`codes8.png`), so
//!   lookups, luminances and means must agree to [`SRGB8_TOL`] = 5e-7.
//! * JPEG: decoded by libjpeg-turbo's decoder, as Mitsuba decodes it, so the codes are equal
//!   and lookups must agree as for sRGB 8-bit PNG, to [`SRGB8_TOL`]. (The `image` crate's
//!   decoder, used before, differed on 1–26% of codes by up to 4, its 4:2:0 chroma rounded
//!   upward; the tolerance then was 0.036.)
//!
//! Each comparison is deterministic (no sampling), so no test here can fail by chance.

use fireflies::render::textures::bitmap::{Bitmap, Filter, Wrap};
use fireflies::render::textures::checkerboard::Checkerboard;
use glam::{Mat3, Vec2, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/textures")
}

fn real_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/scenes/living-room/textures")
}

/// Allowed difference for 8-bit sRGB lookups (see the module documentation).
const SRGB8_TOL: f32 = 5e-7;

fn rows(file: &str) -> Vec<HashMap<String, String>> {
    let mut reader = csv::Reader::from_path(data_dir().join(file)).unwrap();
    let headers = reader.headers().unwrap().clone();
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            headers
                .iter()
                .zip(r.iter())
                .map(|(h, v)| (h.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}

fn num(row: &HashMap<String, String>, key: &str) -> f32 {
    row[key].parse().unwrap()
}

/// The texture's `to_uv` from the six affine entries `m00..m12` (row-major).
fn to_uv(row: &HashMap<String, String>) -> Mat3 {
    let m = |k: &str| num(row, k);
    Mat3::from_cols(
        Vec3::new(m("m00"), m("m10"), 0.0),
        Vec3::new(m("m01"), m("m11"), 0.0),
        Vec3::new(m("m02"), m("m12"), 1.0),
    )
}

/// Allowed |ours − Mitsuba| for a texture read from `file` (see the module documentation).
fn tolerance(file: &str, raw: bool) -> f32 {
    let srgb8 = file.ends_with(".jpg") || (file.ends_with(".png") && !file.contains("16"));
    if srgb8 && !raw { SRGB8_TOL } else { 0.0 }
}

struct Worst {
    what: String,
    excess: f32,
}

fn check(worst: &mut Worst, what: impl Fn() -> String, ours: f32, theirs: f32, tol: f32) {
    // A NaN on our side is the worst possible disagreement.
    let excess = match (ours - theirs).abs() - tol {
        e if e.is_nan() => f32::INFINITY,
        e => e,
    };
    if excess > 0.0 && excess > worst.excess {
        worst.excess = excess;
        worst.what = format!("{}: ours {ours}, Mitsuba {theirs}, tol {tol}", what());
    }
}

#[test]
fn bitmap_lookups_and_means_match_mitsuba_on_the_fixture() {
    let cases = rows("cases.csv");
    let points = rows("points.csv");
    let mut worst = Worst {
        what: String::new(),
        excess: 0.0,
    };
    let mut compared = 0;
    for case in &cases {
        let file = &case["file"];
        let raw = case["raw"] == "1";
        let filter = match case["filter"].as_str() {
            "bilinear" => Filter::Bilinear,
            _ => Filter::Nearest,
        };
        let wrap = match case["wrap"].as_str() {
            "repeat" => Wrap::Repeat,
            "mirror" => Wrap::Mirror,
            _ => Wrap::Clamp,
        };
        let tex = Bitmap::load(&data_dir().join(file), raw, filter, wrap, to_uv(case)).unwrap();
        let id = &case["case"];
        assert_eq!(
            tex.size(),
            (
                case["width"].parse().unwrap(),
                case["height"].parse().unwrap()
            ),
            "case {id} {file}"
        );
        let mean = num(case, "mean");
        check(
            &mut worst,
            || format!("case {id} {file} mean"),
            tex.mean(),
            mean,
            tolerance(file, raw),
        );
        for p in points.iter().filter(|p| &p["case"] == id) {
            let uv = Vec2::new(num(p, "u"), num(p, "v"));
            let ours = tex.eval(uv);
            for (c, key) in ["r", "g", "b"].iter().enumerate() {
                let theirs = num(p, key);
                check(
                    &mut worst,
                    || format!("case {id} {file} {raw} {filter:?} {wrap:?} uv {uv} {key}"),
                    ours[c],
                    theirs,
                    tolerance(file, raw),
                );
            }
            let theirs = num(p, "eval_1");
            check(
                &mut worst,
                || format!("case {id} {file} uv {uv} eval_1"),
                tex.eval_1(uv),
                theirs,
                tolerance(file, raw),
            );
            compared += 1;
        }
    }
    assert!(compared > 1500, "only {compared} points compared");
    assert!(worst.excess <= 0.0, "worst: {}", worst.what);
}

#[test]
fn eight_bit_codes_decode_like_mitsuba() {
    // codes8.png holds code k in column k; cases 16 (sRGB) and 17 (raw) sample every column.
    let points = rows("points.csv");
    for (case, raw, tol) in [("16", false, 4.2e-7f32), ("17", true, 0.0)] {
        let tex = Bitmap::load(
            &data_dir().join("codes8.png"),
            raw,
            Filter::Nearest,
            Wrap::Repeat,
            Mat3::IDENTITY,
        )
        .unwrap();
        let mut n = 0;
        for p in points.iter().filter(|p| p["case"] == case) {
            let uv = Vec2::new(num(p, "u"), num(p, "v"));
            let theirs = num(p, "eval_1");
            let ours = tex.eval_1(uv);
            assert!(
                (ours - theirs).abs() <= tol,
                "raw={raw} uv {uv}: ours {ours}, Mitsuba {theirs}"
            );
            n += 1;
        }
        assert_eq!(n, 256);
    }
}

#[test]
fn alpha_is_dropped_not_applied() {
    // rgba8.png has pixels of alpha 0 and 77; the fixture's cases 8 and 9 already compare their
    // lookups with Mitsuba's. Here: the reader reports the dropped channel and keeps colour.
    let read = fireflies::image::read::read_texture;
    let rgba = read(&data_dir().join("rgba8.png"), true).unwrap();
    assert!(rgba.alpha_dropped);
    assert_eq!(rgba.channels, 3);
    let ya = read(&data_dir().join("ya16.png"), false).unwrap();
    assert!(ya.alpha_dropped);
    assert_eq!(ya.channels, 1);
    let exr = read(&data_dir().join("rgba_float.exr"), false).unwrap();
    assert!(exr.alpha_dropped);
    assert_eq!(exr.channels, 3);
}

#[test]
fn leaf_mask_opacity_is_rgb_luminance_not_alpha() {
    // Mitsuba's mask BSDF takes opacity = clamp(eval_1, 0, 1). In leaf.png, pixel (0, 0) is
    // white with alpha 0 and pixel (100, 100) is (251, 249, 250) with alpha 0: Mitsuba's
    // `1 − eval_null_transmission` there is 1 and 0.9516280889511108 (probe with
    // `mi.load_dict({'type': 'mask', ...})`), i.e. opaque where alpha says transparent.
    let leaf = Bitmap::load(
        &real_dir().join("leaf.png"),
        false,
        Filter::Bilinear,
        Wrap::Repeat,
        Mat3::IDENTITY,
    )
    .unwrap();
    let (w, h) = leaf.size();
    let centre = |x: f32, y: f32| Vec2::new((x + 0.5) / w as f32, (y + 0.5) / h as f32);
    assert_eq!(leaf.eval_1(centre(0.0, 0.0)), 1.0);
    assert!((leaf.eval_1(centre(100.0, 100.0)) - 0.951_628_1).abs() <= SRGB8_TOL);
}

#[test]
fn checkerboard_matches_mitsuba() {
    let mut n = 0;
    for row in rows("checker.csv") {
        let c0 = Vec3::new(num(&row, "c0r"), num(&row, "c0g"), num(&row, "c0b"));
        let c1 = Vec3::new(num(&row, "c1r"), num(&row, "c1g"), num(&row, "c1b"));
        let scale = Mat3::from_diagonal(Vec3::new(num(&row, "sx"), num(&row, "sy"), 1.0));
        let tex = Checkerboard::new(c0, c1, scale);
        let uv = Vec2::new(num(&row, "u"), num(&row, "v"));
        let theirs = Vec3::new(num(&row, "r"), num(&row, "g"), num(&row, "b"));
        assert_eq!(tex.eval(uv), theirs, "eval at {uv}");
        let e1 = num(&row, "eval_1");
        assert_eq!(tex.eval_1(uv), e1, "eval_1 at {uv}");
        assert_eq!(tex.mean(), num(&row, "mean"));
        n += 1;
    }
    assert_eq!(n, 126);
}

#[test]
fn living_room_textures_match_mitsuba() {
    let mut worst = Worst {
        what: String::new(),
        excess: 0.0,
    };
    let mut textures: HashMap<String, Bitmap> = HashMap::new();
    for row in rows("real.csv") {
        let file = row["file"].clone();
        let tex = textures.entry(file.clone()).or_insert_with(|| {
            Bitmap::load(
                &real_dir().join(&file),
                false,
                Filter::Bilinear,
                Wrap::Repeat,
                Mat3::IDENTITY,
            )
            .unwrap()
        });
        check(
            &mut worst,
            || format!("{file} mean"),
            tex.mean(),
            num(&row, "mean"),
            tolerance(&file, false),
        );
        let uv = Vec2::new(num(&row, "u"), num(&row, "v"));
        let ours = tex.eval(uv);
        for (c, key) in ["r", "g", "b"].iter().enumerate() {
            let theirs = num(&row, key);
            check(
                &mut worst,
                || format!("{file} uv {uv} {key}"),
                ours[c],
                theirs,
                tolerance(&file, false),
            );
        }
        let theirs = num(&row, "eval_1");
        check(
            &mut worst,
            || format!("{file} uv {uv} eval_1"),
            tex.eval_1(uv),
            theirs,
            tolerance(&file, false),
        );
    }
    assert_eq!(textures.len(), 4);
    assert!(worst.excess <= 0.0, "worst: {}", worst.what);
}
