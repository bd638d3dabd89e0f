//! Mitsuba 3's `checkerboard` texture with constant colours, matching Mitsuba 3.9.1
//! (`scalar_rgb`) including its quirks, checked against it in `tests/textures.rs`.
//!
//! # Conventions
//!
//! * `p = to_uv · (u, v, 1)` (affine, bottom row ignored). Each axis is "high" where its
//!   fractional part `p − ⌊p⌋` is **strictly** above ½, so one checker is 1 unit wide in `p`
//!   (two squares per unit per axis) and a point exactly on ½ counts as low.
//! * [`Checkerboard::eval`] gives `color0` where both axes are low or both high (so
//!   `color0` at `p = (0.25, 0.25)`), `color1` elsewhere.
//! * [`Checkerboard::eval_1`] gives the **opposite** square: Mitsuba's `eval_1` tests
//!   "axes differ" for `color0`, where `eval` tests "axes agree". We reproduce this, since a
//!   checkerboard used as a scalar (e.g. a `mask` opacity or a roughness) sees it. Its value is
//!   the colour's channel average, which is what Mitsuba's constant `rgb` texture returns
//!   from `eval_1` (not the luminance).
//! * [`Checkerboard::mean`] is the average of the two colours' channel averages.
//! * Mitsuba's defaults are the greys [`DEFAULT_COLOR0`] = 0.4 and [`DEFAULT_COLOR1`] = 0.2.

use super::{Texture, read_to_uv};
use crate::error::Result;
use crate::render::mitsuba::Params;
use glam::{Mat3, Vec2, Vec3};
use std::sync::Arc;

/// Mitsuba's default `color0`.
pub const DEFAULT_COLOR0: Vec3 = Vec3::splat(0.4);
/// Mitsuba's default `color1`.
pub const DEFAULT_COLOR1: Vec3 = Vec3::splat(0.2);

/// A two-colour checkerboard in texture space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Checkerboard {
    color0: Vec3,
    color1: Vec3,
    /// Rows of the affine part of `to_uv`.
    to_uv: [f32; 6],
}

impl Checkerboard {
    /// A checkerboard of two constant linear RGB colours.
    pub fn new(color0: Vec3, color1: Vec3, to_uv: Mat3) -> Self {
        let (r0, r1) = (to_uv.row(0), to_uv.row(1));
        Checkerboard {
            color0,
            color1,
            to_uv: [r0.x, r0.y, r0.z, r1.x, r1.y, r1.z],
        }
    }

    /// Whether the two axes are on the same side of ½ at `uv` (`color0` under `eval`).
    fn axes_agree(&self, uv: Vec2) -> bool {
        let m = &self.to_uv;
        let p = Vec2::new(
            // Fused, in Mitsuba's order: a point on a square's edge falls on the same side.
            m[1].mul_add(uv.y, m[0].mul_add(uv.x, m[2])),
            m[4].mul_add(uv.y, m[3].mul_add(uv.x, m[5])),
        );
        let high = p - p.floor();
        (high.x > 0.5) == (high.y > 0.5)
    }

    /// Linear RGB at `uv`.
    pub fn eval(&self, uv: Vec2) -> Vec3 {
        if self.axes_agree(uv) {
            self.color0
        } else {
            self.color1
        }
    }

    /// Mitsuba's `eval_1`: the channel average of the square **opposite** to [`Self::eval`]'s
    /// (see the module documentation).
    pub fn eval_1(&self, uv: Vec2) -> f32 {
        if self.axes_agree(uv) {
            channel_mean(self.color1)
        } else {
            channel_mean(self.color0)
        }
    }

    /// Mitsuba's `mean()`: the average of the two colours' channel averages.
    pub fn mean(&self) -> f32 {
        0.5 * (channel_mean(self.color0) + channel_mean(self.color1))
    }
}

/// The scalar a constant Mitsuba colour gives from `eval_1`/`mean`: a grey (Mitsuba's `float`
/// value, a uniform spectrum) gives itself; an `rgb` value its channel average, times the
/// `f32` reciprocal of 3 as Mitsuba computes it (dividing differs in the last bit). An `rgb`
/// grey may differ from Mitsuba by that last bit.
fn channel_mean(c: Vec3) -> f32 {
    if c.x == c.y && c.y == c.z {
        c.x
    } else {
        (c.x + c.y + c.z) * (1.0 / 3.0)
    }
}

/// Reads `<texture type="checkerboard">`: constant `color0`, `color1` (Mitsuba's defaults 0.4
/// and 0.2), `to_uv`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Texture>> {
    let color0 = p.spectrum("color0")?;
    let color1 = p.spectrum("color1")?;
    let to_uv = read_to_uv(p)?;
    p.finish()?;
    Ok(Arc::new(Checkerboard::new(
        color0.map_or(DEFAULT_COLOR0, |(c, _)| c),
        color1.map_or(DEFAULT_COLOR1, |(c, _)| c),
        to_uv,
    )))
}

impl Texture for Checkerboard {
    fn eval(&self, uv: Vec2) -> Vec3 {
        Checkerboard::eval(self, uv)
    }

    fn eval_1(&self, uv: Vec2) -> f32 {
        Checkerboard::eval_1(self, uv)
    }

    fn mean(&self) -> f32 {
        Checkerboard::mean(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_follow_mitsuba_squares() {
        let c = Checkerboard::new(DEFAULT_COLOR0, DEFAULT_COLOR1, Mat3::IDENTITY);
        assert_eq!(c.eval(Vec2::new(0.25, 0.25)), DEFAULT_COLOR0);
        assert_eq!(c.eval(Vec2::new(0.75, 0.25)), DEFAULT_COLOR1);
        assert_eq!(c.eval(Vec2::new(0.75, 0.75)), DEFAULT_COLOR0);
        // Exactly ½ is "low".
        assert_eq!(c.eval(Vec2::new(0.5, 0.25)), DEFAULT_COLOR0);
        assert_eq!(c.eval(Vec2::new(-0.25, 0.25)), DEFAULT_COLOR1);
        // eval_1 swaps the squares.
        assert_eq!(c.eval_1(Vec2::new(0.25, 0.25)), 0.2);
        assert_eq!(c.eval_1(Vec2::new(0.75, 0.25)), 0.4);
        assert!((c.mean() - 0.3).abs() < 1e-7);
    }
}
