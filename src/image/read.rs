//! Reading texture images (PNG, JPEG, OpenEXR, Radiance HDR) into linear `f32` data, decoded the
//! way Mitsuba 3.9.1's `bitmap` texture decodes them, so that a texture lookup here and in
//! Mitsuba return the same number.
//!
//! # Mitsuba's rules (checked against Mitsuba 3.9.1, see `tests/data/textures/`)
//!
//! * **Which data is sRGB-encoded.** Every 8- and 16-bit image (PNG of any colour type, JPEG) is
//!   taken as sRGB-encoded, whatever its `gAMA`/`sRGB`/`iCCP` chunks say; OpenEXR and Radiance
//!   HDR data are linear. With `raw = true` the sRGB decoding is skipped (for normal maps and
//!   other non-colour data); float data is unaffected by `raw`.
//! * **The curve** is the exact sRGB transfer function (IEC 61966-2-1):
//!   `c / 12.92` for `c ≤ 0.04045`, else `((c + 0.055) / 1.055)^2.4`, with `c = code / 255` (or
//!   `/ 65535`). Mitsuba evaluates it with a rational approximation in `f32`; we evaluate it
//!   exactly (in `f64`, rounded once to `f32`). Over the 256 8-bit codes the two differ by at
//!   most 4.2e-7 (38 ulp near 1). Raw 8-bit codes are `code · f32(1/255)`, bit for bit as
//!   Mitsuba.
//! * **Storage precision.** Mitsuba keeps 8-bit images as bytes and decodes each texel on
//!   lookup (the values of our 256-entry table, to within the 4.2e-7 above), stores 16-bit
//!   images as **half floats** after decoding, and float images at their own precision. We round 16-bit data through `f16` too,
//!   so that values agree to the bit (all but about 1 in 2000 codes, which differ by one half
//!   ulp where Mitsuba's own `f32` rounding tips a tie).
//! * **Channels.** Grey images (PNG `Y`/`YA`, grey JPEG, EXR `Y`) stay one channel; everything
//!   else becomes RGB.
//! * **Alpha is dropped**: not applied, not premultiplied or unpremultiplied, and not available
//!   to the texture. A transparent PNG pixel contributes its stored RGB as if opaque (Mitsuba's
//!   `mask` BSDF gets its opacity from the luminance of the RGB, not from alpha).
//!   [`TextureData::alpha_dropped`] says when this happened, for a warning.
//! * **Orientation.** Row 0 is the top row of the file (the first stored scanline).

use crate::error::{Error, Result};
use exr::prelude::f16;
use std::path::Path;

/// A decoded image: linear values, row-major from the top-left pixel, channels interleaved.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureData {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// `width · height · channels` linear values.
    pub data: Vec<f32>,
    /// Whether the file had an alpha channel, which was discarded (as Mitsuba does).
    pub alpha_dropped: bool,
}

/// The file formats [`read_texture`] recognises, by their first bytes (as Mitsuba does).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Png,
    Jpeg,
    Exr,
    Hdr,
}

/// Reads a texture image, decoding 8/16-bit data from sRGB to linear unless `raw`.
///
/// Errors name the file: unreadable, of an unrecognised format, or with a channel layout or
/// sample type a texture cannot use.
pub fn read_texture(path: &Path, raw: bool) -> Result<TextureData> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path.display(), &e))?;
    let fail = |message: String| Error::Io {
        path: path.display().to_string(),
        message,
    };
    let format = detect(&bytes).ok_or_else(|| {
        fail("not a PNG, JPEG, OpenEXR or Radiance HDR file (unrecognised first bytes)".into())
    })?;
    match format {
        Format::Exr => read_exr(path, &bytes),
        Format::Jpeg => read_jpeg(&bytes, raw).map_err(fail),
        Format::Png | Format::Hdr => {
            let kind = match format {
                Format::Png => ::image::ImageFormat::Png,
                _ => ::image::ImageFormat::Hdr,
            };
            let bytes = if format == Format::Hdr {
                radiance_signature(bytes)
            } else {
                bytes
            };
            let image = ::image::load_from_memory_with_format(&bytes, kind)
                .map_err(|e| fail(format!("decoding {kind:?}: {e}")))?;
            from_dynamic(image, raw).map_err(fail)
        }
    }
}

fn detect(bytes: &[u8]) -> Option<Format> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some(Format::Png)
    } else if bytes.starts_with(&[0xFF, 0xD8]) {
        Some(Format::Jpeg)
    } else if bytes.starts_with(&[0x76, 0x2F, 0x31, 0x01]) {
        Some(Format::Exr)
    } else if bytes.starts_with(b"#?") {
        Some(Format::Hdr)
    } else {
        None
    }
}

/// Replaces the first line of an RGBE file by `#?RADIANCE`. Writers put other program names
/// there (Mitsuba writes `#?RGBE`); readers, Mitsuba's included, accept any `#?` line, but the
/// `image` crate wants this one.
fn radiance_signature(bytes: Vec<u8>) -> Vec<u8> {
    const SIGNATURE: &[u8] = b"#?RADIANCE";
    match bytes.iter().position(|&b| b == b'\n') {
        Some(end) if &bytes[..end] != SIGNATURE => {
            let mut fixed = Vec::with_capacity(bytes.len() + SIGNATURE.len());
            fixed.extend_from_slice(SIGNATURE);
            fixed.extend_from_slice(&bytes[end..]);
            fixed
        }
        _ => bytes,
    }
}

/// The exact sRGB decoding curve on a value in [0, 1].
fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear value of every 8-bit code.
fn table_8bit(raw: bool) -> [f32; 256] {
    let mut t = [0.0f32; 256];
    for (code, v) in t.iter_mut().enumerate() {
        *v = if raw {
            // Mitsuba multiplies by the f32 reciprocal; `code / 255` would differ by 1 ulp.
            code as f32 * (1.0f32 / 255.0)
        } else {
            srgb_to_linear(code as f64 / 255.0) as f32
        };
    }
    t
}

/// Linear value of a 16-bit code, rounded through half precision as Mitsuba stores it.
fn decode_16bit(code: u16, raw: bool) -> f32 {
    let c = code as f64 / 65535.0;
    let v = if raw { c } else { srgb_to_linear(c) };
    f16::from_f32(v as f32).to_f32()
}

/// Keeps the first `keep` of every `stride` samples, decoded by `decode`.
fn gather<T: Copy>(
    samples: &[T],
    stride: usize,
    keep: usize,
    decode: impl Fn(T) -> f32,
) -> Vec<f32> {
    samples
        .chunks_exact(stride)
        .flat_map(|px| px[..keep].iter().map(|&s| decode(s)))
        .collect()
}

fn from_dynamic(
    image: ::image::DynamicImage,
    raw: bool,
) -> std::result::Result<TextureData, String> {
    use ::image::DynamicImage as D;
    let (width, height) = (image.width() as usize, image.height() as usize);
    let t8 = table_8bit(raw);
    let d8 = |c: u8| t8[c as usize];
    let d16 = |c: u16| decode_16bit(c, raw);
    let (channels, alpha_dropped, data) = match &image {
        D::ImageLuma8(b) => (1, false, gather(b.as_raw(), 1, 1, d8)),
        D::ImageLumaA8(b) => (1, true, gather(b.as_raw(), 2, 1, d8)),
        D::ImageRgb8(b) => (3, false, gather(b.as_raw(), 3, 3, d8)),
        D::ImageRgba8(b) => (3, true, gather(b.as_raw(), 4, 3, d8)),
        D::ImageLuma16(b) => (1, false, gather(b.as_raw(), 1, 1, d16)),
        D::ImageLumaA16(b) => (1, true, gather(b.as_raw(), 2, 1, d16)),
        D::ImageRgb16(b) => (3, false, gather(b.as_raw(), 3, 3, d16)),
        D::ImageRgba16(b) => (3, true, gather(b.as_raw(), 4, 3, d16)),
        // Radiance HDR: linear floats, already decoded as Mitsuba does (code · 2^(e−136)).
        D::ImageRgb32F(b) => (3, false, b.as_raw().clone()),
        D::ImageRgba32F(b) => (3, true, gather(b.as_raw(), 4, 3, |v| v)),
        other => return Err(format!("unsupported pixel layout {:?}", other.color())),
    };
    Ok(TextureData {
        width,
        height,
        channels,
        data,
        alpha_dropped,
    })
}

/// JPEG, decoded by libjpeg-turbo's decoder (as MozJPEG builds it, without its assembly): the
/// integer IDCT, the "fancy" chroma upsampling and the colour conversion of the libjpeg-turbo
/// Mitsuba decodes with, so that texels are the same bytes (checked on every JPEG of the
/// repository: `tests/render_textures.rs`). The `image` crate's decoder, used before, rounded
/// 4:2:0 chroma upward twice: +0.17 codes on average on `experiments/scenes/features`'
/// planks texture and +0.24% on its linear mean, which the cross-check against Mitsuba found at
/// 256 spp. Grey JPEGs stay one channel; colour ones (YCbCr, RGB) become RGB; CMYK and other
/// colour spaces are refused, as Mitsuba refuses them.
fn read_jpeg(bytes: &[u8], raw: bool) -> std::result::Result<TextureData, String> {
    use mozjpeg::ColorSpace;
    // libjpeg reports a corrupt stream from inside the decoder, which MozJPEG turns into an
    // unwind carrying the message (without the panic hook): caught here, it is our error.
    let decoded =
        std::panic::catch_unwind(|| -> std::io::Result<(usize, usize, usize, Vec<u8>)> {
            let jpeg = mozjpeg::Decompress::new_mem(bytes)?;
            let (width, height) = (jpeg.width(), jpeg.height());
            let (channels, mut started) = match jpeg.color_space() {
                ColorSpace::JCS_GRAYSCALE => (1, jpeg.grayscale()?),
                ColorSpace::JCS_YCbCr | ColorSpace::JCS_RGB => (3, jpeg.rgb()?),
                other => {
                    return Err(std::io::Error::other(format!(
                        "JPEG colour space {other:?}: a texture needs grey, YCbCr or RGB"
                    )));
                }
            };
            let codes: Vec<u8> = started.read_scanlines()?;
            started.finish()?;
            Ok((width, height, channels, codes))
        });
    let (width, height, channels, codes) = match decoded {
        Ok(result) => result.map_err(|e| format!("decoding JPEG: {e}"))?,
        Err(unwound) => {
            let message = unwound
                .downcast_ref::<String>()
                .cloned()
                .unwrap_or_else(|| "the decoder failed".into());
            return Err(format!("decoding JPEG: {message}"));
        }
    };
    if codes.len() != width * height * channels {
        return Err(format!(
            "decoding JPEG: {} values for a {width}x{height} image of {channels} channel(s)",
            codes.len()
        ));
    }
    let table = table_8bit(raw);
    Ok(TextureData {
        width,
        height,
        channels,
        data: codes.iter().map(|&c| table[c as usize]).collect(),
        alpha_dropped: false,
    })
}

/// OpenEXR: the first layer's `R`,`G`,`B` (or `Y`) channels, half or float, alpha dropped.
fn read_exr(path: &Path, bytes: &[u8]) -> Result<TextureData> {
    use exr::prelude::{FlatSamples, ReadChannels, ReadLayers};
    let fail = |message: String| Error::Io {
        path: path.display().to_string(),
        message,
    };
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| fail(format!("reading EXR: {e}")))?;
    let layer = &image.layer_data;
    let (width, height) = (layer.size.width(), layer.size.height());
    let list = &layer.channel_data.list;
    let find = |name: &str| list.iter().find(|c| c.name.eq(name));
    let names = || {
        list.iter()
            .map(|c| c.name.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let wanted: Vec<_> = match (find("R"), find("G"), find("B"), find("Y")) {
        (Some(r), Some(g), Some(b), _) => vec![r, g, b],
        (None, None, None, Some(y)) => vec![y],
        _ => {
            return Err(fail(format!(
                "EXR channels [{}]: a texture needs R, G, B or Y",
                names()
            )));
        }
    };
    let mut planes = Vec::with_capacity(wanted.len());
    for c in &wanted {
        let plane: Vec<f32> = match &c.sample_data {
            FlatSamples::F16(v) => v.iter().map(|h| h.to_f32()).collect(),
            FlatSamples::F32(v) => v.clone(),
            FlatSamples::U32(_) => {
                return Err(fail(format!(
                    "EXR channel {} holds 32-bit integers, not colour",
                    c.name
                )));
            }
        };
        planes.push(plane);
    }
    let channels = planes.len();
    let mut data = Vec::with_capacity(width * height * channels);
    for i in 0..width * height {
        data.extend(planes.iter().map(|p| p[i]));
    }
    Ok(TextureData {
        width,
        height,
        channels,
        data,
        alpha_dropped: find("A").is_some(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_curve_hits_known_points() {
        let t = table_8bit(false);
        assert_eq!(t[0], 0.0);
        assert_eq!(t[255], 1.0);
        // 10/255 = 0.0392 is on the linear segment.
        assert_eq!(t[10], (10.0 / 255.0 / 12.92) as f32);
        // Mid grey: 188 ↦ 0.5029...
        assert!((t[188] - 0.502_886).abs() < 1e-6);
        // Strictly increasing: no branch seam.
        assert!(t.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn raw_codes_are_linear() {
        let t = table_8bit(true);
        assert_eq!(t[255], 1.0);
        assert_eq!(t[51], 51.0 * (1.0f32 / 255.0));
    }

    #[test]
    fn sixteen_bit_values_are_half_precision() {
        for code in [1u16, 300, 4403, 30000, 65535] {
            let v = decode_16bit(code, false);
            assert_eq!(f16::from_f32(v).to_f32(), v);
        }
        assert_eq!(decode_16bit(65535, true), 1.0);
    }

    #[test]
    fn unknown_files_are_errors_naming_the_file() {
        let dir = std::env::temp_dir().join(format!("fireflies-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("not-an-image.png");
        std::fs::write(&p, b"hello").unwrap();
        let e = read_texture(&p, false).unwrap_err().to_string();
        assert!(
            e.contains("not-an-image.png") && e.contains("unrecognised"),
            "{e}"
        );
        let missing = dir.join("missing.png");
        let e = read_texture(&missing, false).unwrap_err().to_string();
        assert!(e.contains("missing.png"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A 4x2 CMYK JPEG, written by the same library.
    fn cmyk_jpeg() -> Vec<u8> {
        let mut c = mozjpeg::Compress::new(mozjpeg::ColorSpace::JCS_CMYK);
        c.set_size(4, 2);
        let mut c = c.start_compress(Vec::new()).unwrap();
        c.write_scanlines(&[128u8; 4 * 2 * 4]).unwrap();
        c.finish().unwrap()
    }

    /// libjpeg's fatal errors unwind out of the decoder; they must come back as an error
    /// naming the file, as must a colour space a texture cannot use.
    #[test]
    fn bad_jpegs_are_errors_naming_the_file() {
        let dir = std::env::temp_dir().join(format!("fireflies-jpeg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let planks = std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("experiments/scenes/features/textures/planks.jpg"),
        )
        .unwrap();
        // The start-of-image marker, then a frame header cut short and garbage.
        let mut corrupt = planks[..2].to_vec();
        corrupt.extend_from_slice(&[0xFF, 0xC0, 0x00, 0x11, 0x08, 0xFF, 0xFF, 0x13, 0x37]);
        for (name, bytes, want) in [
            ("corrupt.jpg", corrupt, "decoding JPEG"),
            ("cmyk.jpg", cmyk_jpeg(), "JCS_CMYK"),
        ] {
            let p = dir.join(name);
            std::fs::write(&p, &bytes).unwrap();
            let e = read_texture(&p, false).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(want), "{e}");
        }
        // The good file still decodes: 128x64 RGB.
        let p = dir.join("planks.jpg");
        std::fs::write(&p, &planks).unwrap();
        let t = read_texture(&p, false).unwrap();
        assert_eq!(
            (t.width, t.height, t.channels, t.data.len()),
            (128, 64, 3, 128 * 64 * 3)
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
