//! Textures: spatially varying reflectances and opacities, looked up by texture coordinates.
//! One file per Mitsuba texture plugin; [`Spectrum`] is what BSDF parameters hold, so that a
//! constant colour costs no indirection.

pub mod bitmap;
pub mod checkerboard;

use super::mitsuba::Params;
use super::scene::Rgb;
use crate::error::Result;
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::fmt::Debug;
use std::sync::Arc;

/// A texture plugin.
pub trait Texture: Debug + Send + Sync {
    /// The RGB value at `uv` (Mitsuba's `eval` in its RGB variants).
    fn eval(&self, uv: Vec2) -> Rgb;
    /// The one-channel value at `uv` (Mitsuba's `eval_1`, e.g. a mask's opacity).
    fn eval_1(&self, uv: Vec2) -> f32;
    /// The texture's mean (Mitsuba's `mean()`; `plastic` weighs its lobes with it).
    fn mean(&self) -> f32;
    /// The gradient of [`Texture::eval_1`] with respect to `uv` (Mitsuba's `eval_1_grad`, which
    /// `bumpmap` reads). The default, zero, is a constant's gradient; a texture that computes
    /// one also says so in [`Texture::has_eval_1_grad`].
    fn eval_1_grad(&self, _uv: Vec2) -> Vec2 {
        Vec2::ZERO
    }
    /// Whether Mitsuba implements `eval_1_grad` for this plugin (its `bitmap` does; its
    /// `checkerboard` throws "not implemented"), so that `bumpmap` can refuse the others when
    /// the scene is read rather than render something Mitsuba cannot.
    fn has_eval_1_grad(&self) -> bool {
        false
    }
}

/// A BSDF parameter that Mitsuba lets be a constant or a texture.
#[derive(Debug, Clone)]
pub enum Spectrum {
    /// A constant `<rgb>` or `<float>`.
    Constant(Rgb),
    /// A nested `<texture>`.
    Texture(Arc<dyn Texture>),
}

impl Spectrum {
    /// A constant grey.
    pub fn grey(value: f32) -> Spectrum {
        Spectrum::Constant(Rgb::splat(value))
    }

    /// The value at `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Spectrum::Constant(c) => *c,
            Spectrum::Texture(t) => t.eval(uv),
        }
    }

    /// The one-channel value at `uv`: for a constant, the mean of its components (what
    /// Mitsuba's constant `rgb` texture returns from `eval_1`).
    #[inline]
    pub fn eval_1(&self, uv: Vec2) -> f32 {
        match self {
            Spectrum::Constant(c) => c.element_sum() / 3.0,
            Spectrum::Texture(t) => t.eval_1(uv),
        }
    }

    /// The mean: for a constant, the mean of its three components (as Mitsuba's `srgb`
    /// texture reports it in RGB mode).
    pub fn mean(&self) -> f32 {
        match self {
            Spectrum::Constant(c) => c.element_sum() / 3.0,
            Spectrum::Texture(t) => t.mean(),
        }
    }

    /// Whether it varies over the surface (and so needs texture coordinates).
    pub fn is_textured(&self) -> bool {
        matches!(self, Spectrum::Texture(_))
    }
}

/// Mitsuba's luminance of linear sRGB (the Y row of its sRGB-to-XYZ matrix).
#[inline]
pub fn luminance(c: Rgb) -> f32 {
    0.212671 * c.x + 0.715160 * c.y + 0.072169 * c.z
}

/// A texture's `to_uv` transform as Mitsuba reads it: the `<transform name="to_uv">` with its
/// `z` row and column dropped (a 2D affine map of `(u, v, 1)`). Files older than Mitsuba 2 give
/// `uoffset`, `voffset`, `uscale`, `vscale` instead, which Mitsuba 3 turns into `to_uv` (an
/// offset only when both are non-zero, a scale only when both differ from 1: its rule).
pub(crate) fn read_to_uv(p: &mut Params) -> Result<Mat3> {
    let given = p.transform("to_uv")?;
    let mut m = given.map_or(Mat4::IDENTITY, |(m, _)| m);
    if p.loader().upgrades_names() {
        let mut offset = Vec2::ZERO;
        let mut scale = Vec2::ONE;
        for (name, slot) in [
            ("uoffset", &mut offset.x),
            ("voffset", &mut offset.y),
            ("uscale", &mut scale.x),
            ("vscale", &mut scale.y),
        ] {
            if let Some((v, _)) = p.float(name)? {
                *slot = v;
            }
        }
        if offset.x != 0.0 && offset.y != 0.0 {
            m = Mat4::from_translation(offset.extend(0.0)) * m;
        }
        if scale.x != 1.0 && scale.y != 1.0 {
            m = Mat4::from_scale(Vec3::new(scale.x, scale.y, 1.0)) * m;
        }
    }
    // Rows and columns 0, 1 and 3 of the 4x4 matrix.
    let drop_z = |v: glam::Vec4| Vec3::new(v.x, v.y, v.w);
    Ok(Mat3::from_cols(
        drop_z(m.x_axis),
        drop_z(m.y_axis),
        drop_z(m.w_axis),
    ))
}
