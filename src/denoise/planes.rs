//! Images as stacks of single-channel planes. NFOR filters each feature channel with its own
//! weights and stacks channels freely (colour, eight feature channels, MSE maps), so a planar
//! layout with any channel count is its working type; [`Image`] stays the file format.

use crate::error::{Error, Result};
use crate::image::Image;

/// Equally sized single-channel `f32` planes, row-major from the top-left pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Planes {
    width: usize,
    height: usize,
    planes: Vec<Vec<f32>>,
}

impl Planes {
    /// `channels` planes of zeros.
    pub fn zeros(width: usize, height: usize, channels: usize) -> Self {
        Planes {
            width,
            height,
            planes: vec![vec![0.0; width * height]; channels],
        }
    }

    /// Planes from row-major channel data; an error when a plane has the wrong length.
    pub fn from_planes(width: usize, height: usize, planes: Vec<Vec<f32>>) -> Result<Self> {
        if let Some((c, p)) = planes
            .iter()
            .enumerate()
            .find(|(_, p)| p.len() != width * height)
        {
            return Err(Error::param(
                "planes",
                format!("channel {c} of {} values", p.len()),
                format!("a {width}x{height} plane needs {} values", width * height),
            ));
        }
        Ok(Planes {
            width,
            height,
            planes,
        })
    }

    /// The three channels of an RGB image.
    pub fn from_rgb(image: &Image) -> Self {
        let planes = (0..3)
            .map(|c| image.pixels().iter().map(|p| p[c]).collect())
            .collect();
        Planes {
            width: image.width(),
            height: image.height(),
            planes,
        }
    }

    /// One channel of a grey image stored as RGB (its red channel, as `render --nfor` writes
    /// depth and visibility).
    pub fn from_grey(image: &Image) -> Self {
        Planes {
            width: image.width(),
            height: image.height(),
            planes: vec![image.pixels().iter().map(|p| p[0]).collect()],
        }
    }

    /// The planes as an RGB image: three channels as they are, one as grey.
    pub fn to_image(&self) -> Result<Image> {
        let pixels = match self.planes.len() {
            3 => (0..self.len())
                .map(|i| [self.planes[0][i], self.planes[1][i], self.planes[2][i]])
                .collect(),
            1 => self.planes[0].iter().map(|&v| [v; 3]).collect(),
            n => {
                return Err(Error::param(
                    "channels",
                    n,
                    "only 1 or 3 planes make an RGB image",
                ));
            }
        };
        Image::from_pixels(self.width, self.height, pixels)
    }

    /// Channels of `parts` one after the other; all must have one size.
    pub fn stack(parts: &[&Planes]) -> Result<Self> {
        let Some(first) = parts.first() else {
            return Err(Error::param("planes", 0, "nothing to stack"));
        };
        for p in parts {
            first.same_size(p, "stacked planes")?;
        }
        Ok(Planes {
            width: first.width,
            height: first.height,
            planes: parts
                .iter()
                .flat_map(|p| p.planes.iter().cloned())
                .collect(),
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

    /// Pixels per plane.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// Whether the planes hold no pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Number of channels.
    pub fn channels(&self) -> usize {
        self.planes.len()
    }

    /// Channel `c`.
    pub fn plane(&self, c: usize) -> &[f32] {
        &self.planes[c]
    }

    /// Channel `c`, writable.
    pub fn plane_mut(&mut self, c: usize) -> &mut [f32] {
        &mut self.planes[c]
    }

    /// All channels.
    pub fn all(&self) -> &[Vec<f32>] {
        &self.planes
    }

    /// An error naming `what` unless `other` has this size.
    pub fn same_size(&self, other: &Planes, what: &str) -> Result<()> {
        if (self.width, self.height) != (other.width, other.height) {
            return Err(Error::param(
                "planes",
                format!("{what} of {}x{}", other.width, other.height),
                format!("must be {}x{} like the colour", self.width, self.height),
            ));
        }
        Ok(())
    }

    /// `f(a, b)` value by value; both must have one shape (checked by the caller's pipeline).
    pub fn zip_map(&self, other: &Planes, f: impl Fn(f32, f32) -> f32) -> Planes {
        debug_assert_eq!(self.channels(), other.channels());
        Planes {
            width: self.width,
            height: self.height,
            planes: self
                .planes
                .iter()
                .zip(&other.planes)
                .map(|(a, b)| a.iter().zip(b).map(|(&x, &y)| f(x, y)).collect())
                .collect(),
        }
    }

    /// The first value that is not finite, as (channel, pixel).
    pub fn first_non_finite(&self) -> Option<(usize, usize)> {
        self.planes
            .iter()
            .enumerate()
            .find_map(|(c, p)| p.iter().position(|v| !v.is_finite()).map(|i| (c, i)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb_round_trips_and_grey_takes_red() {
        let img = Image::from_pixels(2, 1, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]).unwrap();
        let p = Planes::from_rgb(&img);
        assert_eq!(p.plane(1), &[2.0, 5.0]);
        assert_eq!(p.to_image().unwrap(), img);
        let g = Planes::from_grey(&img);
        assert_eq!(g.channels(), 1);
        assert_eq!(g.to_image().unwrap().get(1, 0), [4.0; 3]);
        let s = Planes::stack(&[&p, &g]).unwrap();
        assert_eq!(s.channels(), 4);
        assert!(s.to_image().is_err());
        let other = Planes::zeros(1, 2, 1);
        assert!(Planes::stack(&[&p, &other]).is_err());
    }
}
