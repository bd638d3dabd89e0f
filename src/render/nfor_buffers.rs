//! The buffers NFOR denoising reads (Bitterli et al., "Nonlinearly Weighted First-order
//! Regression for Denoising Monte Carlo Renderings", EGSR 2016): what `render --nfor` writes and
//! what [`NforBuffers::read`] loads back and checks, so that the format has one home.
//!
//! # What is in a render directory
//!
//! Every camera sample goes to one of two halves by its index: **A** takes the even indices,
//! **B** the odd ones, so the halves are statistically independent (disjoint random streams)
//! and hold `⌈spp/2⌉` and `⌊spp/2⌋` samples. For each buffer `<buf>` of [`BUFFERS`]:
//!
//! * `<buf>_a.exr`, `<buf>_b.exr`: the mean of the half's samples per pixel;
//! * `<buf>_a_var.exr`, `<buf>_b_var.exr`: the variance of that mean, i.e. the sample variance
//!   (denominator `n − 1`) divided by the half's count `n`, per channel.
//!
//! and for each estimator of the render `<stem>_a.exr`, `<stem>_b.exr`: the estimator run on
//! that half alone (its own bank, its own 3×3 neighbourhood and image-wide spread), so that a
//! robust estimate can be denoised with a valid error estimate (NFOR's cross-half MSE estimate
//! needs independent halves of the *same* estimator).
//!
//! Single-channel buffers (`depth`, `visibility`) are stored as grey RGB. The colour buffer
//! averages only valid samples (finite, non-negative), as every estimator does. What each
//! feature holds is [`super::integrator::Features`].
//!
//! Each file carries three EXR attributes, `fireflies.nfor.file` (its name without `.exr`),
//! `fireflies.nfor.spp` (the half's sample count) and `fireflies.nfor.seed`, so that a file left
//! from another render in the same directory is caught. `render.json` has a `nfor` object with
//! `format_version`, `spp`, `spp_a`, `spp_b`, `seed` and every file name.

use crate::error::{Error, Result};
use crate::image::Image;
use serde_json::{Value, json};
use std::path::Path;

/// Version of this layout, in `render.json`'s `nfor.format_version`.
pub const FORMAT_VERSION: u32 = 1;

/// The per-sample buffers, in the order of [`NforBuffers::buffers`].
pub const BUFFERS: [&str; 5] = ["color", "normal", "albedo", "depth", "visibility"];

/// Samples of halves A (even indices) and B (odd) out of `spp`.
pub fn half_counts(spp: u32) -> [u32; 2] {
    [spp.div_ceil(2), spp / 2]
}

/// One buffer in both halves.
#[derive(Debug, Clone, PartialEq)]
pub struct HalfBuffer {
    /// Per-pixel mean of the half's samples, A then B.
    pub mean: [Image; 2],
    /// Per-pixel variance of that mean (sample variance / count), A then B.
    pub var: [Image; 2],
}

/// One estimator run on each half.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorHalves {
    /// The canonical spec (`gmon:M=21`).
    pub spec: String,
    /// Its file stem (`gmon_M=21`), as its full-render image is named.
    pub stem: String,
    /// Its image from half A and from half B.
    pub image: [Image; 2],
}

/// Everything NFOR reads from one render.
#[derive(Debug, Clone, PartialEq)]
pub struct NforBuffers {
    /// Samples per pixel of the whole render.
    pub spp: u32,
    /// The render's seed.
    pub seed: u64,
    /// Colour (RGB radiance).
    pub color: HalfBuffer,
    /// World-space shading normal.
    pub normal: HalfBuffer,
    /// Albedo.
    pub albedo: HalfBuffer,
    /// Path length to the first non-specular hit.
    pub depth: HalfBuffer,
    /// Fraction of unoccluded shadow rays.
    pub visibility: HalfBuffer,
    /// The render's estimators, each on both halves.
    pub estimators: Vec<EstimatorHalves>,
}

const HALVES: [&str; 2] = ["a", "b"];
const ATTR_FILE: &str = "fireflies.nfor.file";
const ATTR_SPP: &str = "fireflies.nfor.spp";
const ATTR_SEED: &str = "fireflies.nfor.seed";

impl NforBuffers {
    /// The buffers with their names, in [`BUFFERS`] order.
    pub fn buffers(&self) -> [(&'static str, &HalfBuffer); 5] {
        [
            ("color", &self.color),
            ("normal", &self.normal),
            ("albedo", &self.albedo),
            ("depth", &self.depth),
            ("visibility", &self.visibility),
        ]
    }

    /// Writes every file into `dir` (each atomically) and returns the `nfor` object for
    /// `render.json`.
    pub fn write(&self, dir: &Path) -> Result<Value> {
        let counts = half_counts(self.spp);
        let mut buffers = serde_json::Map::new();
        for (name, buf) in self.buffers() {
            let mut files = serde_json::Map::new();
            for (h, half) in HALVES.iter().enumerate() {
                let mean = format!("{name}_{half}");
                let var = format!("{mean}_var");
                write_tagged(&buf.mean[h], dir, &mean, counts[h], self.seed)?;
                write_tagged(&buf.var[h], dir, &var, counts[h], self.seed)?;
                files.insert((*half).into(), json!(format!("{mean}.exr")));
                files.insert(format!("{half}_var"), json!(format!("{var}.exr")));
            }
            buffers.insert(name.into(), Value::Object(files));
        }
        let mut estimators = Vec::new();
        for e in &self.estimators {
            let mut entry = serde_json::Map::new();
            entry.insert("spec".into(), json!(e.spec));
            for (h, half) in HALVES.iter().enumerate() {
                let name = format!("{}_{half}", e.stem);
                write_tagged(&e.image[h], dir, &name, counts[h], self.seed)?;
                entry.insert((*half).into(), json!(format!("{name}.exr")));
            }
            estimators.push(Value::Object(entry));
        }
        Ok(json!({
            "format_version": FORMAT_VERSION,
            "spp": self.spp,
            "spp_a": counts[0],
            "spp_b": counts[1],
            "seed": self.seed.to_string(),
            "buffers": buffers,
            "estimators": estimators,
        }))
    }

    /// Loads and checks the NFOR outputs of the render in `dir`: `render.json` must have a
    /// `nfor` object of this [`FORMAT_VERSION`] whose `spp` and `seed` are the render's, and
    /// every file must exist, have the render's size, carry the attributes of its half (name,
    /// sample count, seed) and hold only finite values (variances also non-negative). Each
    /// error names the file at fault.
    pub fn read(dir: &Path) -> Result<NforBuffers> {
        let json_path = dir.join("render.json");
        let bad = |path: &Path, message: String| Error::Io {
            path: path.display().to_string(),
            message,
        };
        let text =
            std::fs::read_to_string(&json_path).map_err(|e| Error::io(json_path.display(), &e))?;
        let report: Value = serde_json::from_str(&text)
            .map_err(|e| bad(&json_path, format!("not valid JSON: {e}")))?;
        let field = |v: &Value, key: &str| -> Result<u64> {
            v.get(key).and_then(Value::as_u64).ok_or_else(|| {
                bad(
                    &json_path,
                    format!("missing or non-integer `{key}` in the render report"),
                )
            })
        };
        let nfor = report.get("nfor").ok_or_else(|| {
            bad(
                &json_path,
                "has no `nfor` object: render with `fireflies render --nfor`".into(),
            )
        })?;
        let version = field(nfor, "format_version")?;
        if version != u64::from(FORMAT_VERSION) {
            return Err(bad(
                &json_path,
                format!("nfor.format_version is {version}; this build reads {FORMAT_VERSION}"),
            ));
        }
        let spp = field(&report, "spp")?;
        let spp = u32::try_from(spp)
            .map_err(|_| bad(&json_path, format!("spp = {spp} is out of range")))?;
        let counts = half_counts(spp);
        for (key, want) in [("spp", spp), ("spp_a", counts[0]), ("spp_b", counts[1])] {
            let got = field(nfor, key)?;
            if got != u64::from(want) {
                return Err(bad(
                    &json_path,
                    format!("nfor.{key} = {got} does not match the render's spp = {spp}"),
                ));
            }
        }
        let seed = field(&report, "seed")?;
        let nfor_seed = nfor.get("seed").and_then(Value::as_str);
        if nfor_seed != Some(seed.to_string().as_str()) {
            return Err(bad(
                &json_path,
                format!("nfor.seed {nfor_seed:?} does not match the render's seed {seed}"),
            ));
        }
        let width = usize::try_from(field(&report, "width")?).unwrap_or(usize::MAX);
        let height = usize::try_from(field(&report, "height")?).unwrap_or(usize::MAX);
        let load = |name: &str, half: usize, variance: bool| -> Result<Image> {
            read_tagged(dir, name, (width, height), counts[half], seed, variance)
        };
        let buffer = |name: &str| -> Result<HalfBuffer> {
            let mut mean = Vec::with_capacity(2);
            let mut var = Vec::with_capacity(2);
            for (h, half) in HALVES.iter().enumerate() {
                mean.push(load(&format!("{name}_{half}"), h, false)?);
                var.push(load(&format!("{name}_{half}_var"), h, true)?);
            }
            let pair = |mut v: Vec<Image>| {
                let b = v.pop().expect("two halves");
                [v.pop().expect("two halves"), b]
            };
            Ok(HalfBuffer {
                mean: pair(mean),
                var: pair(var),
            })
        };
        let listed = nfor
            .get("estimators")
            .and_then(Value::as_array)
            .ok_or_else(|| {
                bad(
                    &json_path,
                    "nfor.estimators is missing or not a list".into(),
                )
            })?;
        let mut estimators = Vec::with_capacity(listed.len());
        for (i, entry) in listed.iter().enumerate() {
            let text = |key: &str| -> Result<String> {
                entry
                    .get(key)
                    .and_then(Value::as_str)
                    .map(str::to_string)
                    .ok_or_else(|| {
                        bad(
                            &json_path,
                            format!("nfor.estimators[{i}].{key} is missing or not a string"),
                        )
                    })
            };
            let spec = text("spec")?;
            let files = [text("a")?, text("b")?];
            let mut stem = String::new();
            let mut image = Vec::with_capacity(2);
            for (h, half) in HALVES.iter().enumerate() {
                let suffix = format!("_{half}.exr");
                let s = files[h].strip_suffix(&suffix).ok_or_else(|| {
                    bad(
                        &json_path,
                        format!("nfor.estimators[{i}].{half} must end in {suffix}"),
                    )
                })?;
                if s.is_empty() || s.contains(['/', '\\']) || (h == 1 && s != stem) {
                    return Err(bad(
                        &json_path,
                        format!(
                            "nfor.estimators[{i}]: file names {:?} are not <stem>_a.exr and \
                             <stem>_b.exr of one plain stem",
                            files
                        ),
                    ));
                }
                stem = s.to_string();
                image.push(load(&format!("{s}_{half}"), h, false)?);
            }
            let b = image.pop().expect("two halves");
            let a = image.pop().expect("two halves");
            estimators.push(EstimatorHalves {
                spec,
                stem,
                image: [a, b],
            });
        }
        Ok(NforBuffers {
            spp,
            seed,
            color: buffer("color")?,
            normal: buffer("normal")?,
            albedo: buffer("albedo")?,
            depth: buffer("depth")?,
            visibility: buffer("visibility")?,
            estimators,
        })
    }
}

/// Writes `image` as `dir/<name>.exr` with the attributes that tie it to its half.
fn write_tagged(image: &Image, dir: &Path, name: &str, spp: u32, seed: u64) -> Result<()> {
    use exr::meta::attribute::{AttributeValue, Text};
    use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2, WritableImage};
    let path = dir.join(format!("{name}.exr"));
    let text = |s: &str| {
        Text::new_or_none(s).ok_or_else(|| Error::Io {
            path: path.display().to_string(),
            message: format!("{s:?} cannot be an EXR text attribute"),
        })
    };
    let width = image.width();
    let pixels = image.pixels();
    let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
        let p = pixels[y * width + x];
        (p[0], p[1], p[2])
    });
    let mut exr = ExrImage::from_channels((width, image.height()), channels);
    let other = &mut exr.layer_data.attributes.other;
    for (key, value) in [
        (ATTR_FILE, name.to_string()),
        (ATTR_SPP, spp.to_string()),
        (ATTR_SEED, seed.to_string()),
    ] {
        other.insert(text(key)?, AttributeValue::Text(text(&value)?));
    }
    let mut buf = std::io::Cursor::new(Vec::new());
    exr.write().to_buffered(&mut buf).map_err(|e| Error::Io {
        path: path.display().to_string(),
        message: format!("encoding EXR: {e}"),
    })?;
    crate::atomic::write_atomic(&path, buf.get_ref())
}

/// Reads `dir/<name>.exr` and checks its size, attributes and values.
fn read_tagged(
    dir: &Path,
    name: &str,
    (width, height): (usize, usize),
    spp: u32,
    seed: u64,
    variance: bool,
) -> Result<Image> {
    use exr::meta::attribute::AttributeValue;
    use exr::prelude::{RgbaChannels, Vec2};
    let path = dir.join(format!("{name}.exr"));
    let bad = |message: String| Error::Io {
        path: path.display().to_string(),
        message,
    };
    if !path.is_file() {
        return Err(bad("missing (an NFOR buffer listed by render.json)".into()));
    }
    let exr = exr::prelude::read_first_rgba_layer_from_file(
        &path,
        |res: Vec2<usize>, _: &RgbaChannels| (res.width(), vec![[0.0f32; 3]; res.area()]),
        |(w, px): &mut (usize, Vec<[f32; 3]>),
         pos: Vec2<usize>,
         (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = [r, g, b];
        },
    )
    .map_err(|e| bad(format!("reading EXR: {e}")))?;
    let size = exr.layer_data.size;
    if (size.width(), size.height()) != (width, height) {
        return Err(bad(format!(
            "is {}x{} pixels; the render is {width}x{height}",
            size.width(),
            size.height()
        )));
    }
    let attrs = &exr.layer_data.attributes.other;
    for (key, want) in [
        (ATTR_FILE, name.to_string()),
        (ATTR_SPP, spp.to_string()),
        (ATTR_SEED, seed.to_string()),
    ] {
        let got = attrs.iter().find_map(|(k, v)| match v {
            AttributeValue::Text(t) if k.eq(key) => Some(t.to_string()),
            _ => None,
        });
        if got.as_deref() != Some(want.as_str()) {
            return Err(bad(format!(
                "attribute {key} is {got:?} but render.json implies {want:?} (a file from \
                 another render?)"
            )));
        }
    }
    let pixels = exr.layer_data.channel_data.pixels.1;
    for (i, p) in pixels.iter().enumerate() {
        if p.iter().any(|c| !c.is_finite() || (variance && *c < 0.0)) {
            return Err(bad(format!(
                "pixel ({}, {}) holds {p:?}: values must be finite{}",
                i % width,
                i / width,
                if variance { " and non-negative" } else { "" }
            )));
        }
    }
    Image::from_pixels(width, height, pixels)
}
