//! RGB images: the film's output, read back for comparisons. EXR holds linear floats; PNG is a
//! tone-mapped preview for people. Both are written atomically. [`metrics`] compares an image
//! with a reference.

pub mod metrics;
pub mod read;

use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use std::io::Cursor;
use std::path::Path;

/// A linear RGB image, row-major from the top-left pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    pixels: Vec<[f32; 3]>,
}

impl Image {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        Image {
            width,
            height,
            pixels: vec![[0.0; 3]; width * height],
        }
    }

    /// An image from its pixels; an error when the count is not `width·height`.
    pub fn from_pixels(width: usize, height: usize, pixels: Vec<[f32; 3]>) -> Result<Self> {
        if pixels.len() != width * height {
            return Err(Error::param(
                "pixels",
                pixels.len(),
                format!("a {width}x{height} image needs {} pixels", width * height),
            ));
        }
        Ok(Image {
            width,
            height,
            pixels,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// All pixels, row-major.
    pub fn pixels(&self) -> &[[f32; 3]] {
        &self.pixels
    }

    /// The pixel at column `x`, row `y`.
    pub fn get(&self, x: usize, y: usize) -> [f32; 3] {
        self.pixels[y * self.width + x]
    }

    /// Per-channel mean over all pixels (f64 sums).
    pub fn mean(&self) -> [f64; 3] {
        let mut s = [0.0f64; 3];
        for p in &self.pixels {
            for c in 0..3 {
                s[c] += p[c] as f64;
            }
        }
        let n = self.pixels.len().max(1) as f64;
        s.map(|v| v / n)
    }

    /// Writes a 32-bit float RGB OpenEXR file.
    pub fn write_exr(&self, path: &Path) -> Result<()> {
        use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2, WritableImage};
        let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
            let p = self.pixels[y * self.width + x];
            (p[0], p[1], p[2])
        });
        let mut buf = Cursor::new(Vec::new());
        ExrImage::from_channels((self.width, self.height), channels)
            .write()
            .to_buffered(&mut buf)
            .map_err(|e| Error::Io {
                path: path.display().to_string(),
                message: format!("encoding EXR: {e}"),
            })?;
        write_atomic(path, buf.get_ref())
    }

    /// Reads the first RGB(A) layer of an OpenEXR file (alpha ignored).
    pub fn read_exr(path: &Path) -> Result<Self> {
        use exr::prelude::{RgbaChannels, Vec2};
        let img = exr::prelude::read_first_rgba_layer_from_file(
            path,
            |res: Vec2<usize>, _: &RgbaChannels| Image::new(res.width(), res.height()),
            |img: &mut Image, pos: Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
                let w = img.width;
                img.pixels[pos.y() * w + pos.x()] = [r, g, b];
            },
        )
        .map_err(|e| Error::Io {
            path: path.display().to_string(),
            message: format!("reading EXR: {e}"),
        })?;
        Ok(img.layer_data.channel_data.pixels)
    }

    /// Writes an 8-bit sRGB PNG preview: linear values times `exposure`, clipped to [0, 1],
    /// then the sRGB transfer curve.
    pub fn write_png(&self, path: &Path, exposure: f32) -> Result<()> {
        let mut rgb = Vec::with_capacity(self.pixels.len() * 3);
        for p in &self.pixels {
            for &c in p {
                rgb.push(to_srgb8(c * exposure));
            }
        }
        let buf = ::image::RgbImage::from_raw(self.width as u32, self.height as u32, rgb)
            .ok_or_else(|| Error::param("pixels", self.pixels.len(), "buffer size mismatch"))?;
        let mut bytes = Cursor::new(Vec::new());
        buf.write_to(&mut bytes, ::image::ImageFormat::Png)
            .map_err(|e| Error::Io {
                path: path.display().to_string(),
                message: format!("encoding PNG: {e}"),
            })?;
        write_atomic(path, bytes.get_ref())
    }
}

/// Linear value to an 8-bit sRGB code (NaN and negatives map to 0).
fn to_srgb8(v: f32) -> u8 {
    let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trips_exactly() {
        let px: Vec<[f32; 3]> = (0..12)
            .map(|i| [i as f32 * 0.5, 1e-30 * i as f32, 3e30 + i as f32])
            .collect();
        let img = Image::from_pixels(4, 3, px).unwrap();
        let dir = std::env::temp_dir().join(format!("fireflies-exr-{}", std::process::id()));
        let path = dir.join("a.exr");
        img.write_exr(&path).unwrap();
        assert_eq!(Image::read_exr(&path).unwrap(), img);
        img.write_png(&dir.join("a.png"), 1.0).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn srgb_endpoints() {
        assert_eq!(to_srgb8(0.0), 0);
        assert_eq!(to_srgb8(f32::NAN), 0);
        assert_eq!(to_srgb8(1.0), 255);
        assert_eq!(to_srgb8(7.0), 255);
        assert_eq!(to_srgb8(0.5), 188);
    }

    #[test]
    fn wrong_pixel_count_is_an_error() {
        assert!(Image::from_pixels(2, 2, vec![[0.0; 3]; 3]).is_err());
    }
}
