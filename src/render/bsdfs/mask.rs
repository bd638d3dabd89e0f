//! Mitsuba's `mask`: a cut-out. With probability `opacity` (a texture, clamped to `[0, 1]`) the
//! surface scatters with the nested BSDF; otherwise light passes straight through (Mitsuba's
//! *null* interaction: same direction, weight 1, counted as a bounce and treated as a delta
//! lobe by the path integrator, as Mitsuba's `path` does).
//!
//! `eval` and `pdf` are the nested BSDF's times the opacity. Like Mitsuba's shadow rays, ours
//! see a masked surface as opaque: next-event estimation through a cut-out finds it occluded.
//! That is what Mitsuba renders, so we keep it.

use super::{Bsdf, BsdfSample, SurfacePoint};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A BSDF with an opacity mask.
#[derive(Debug, Clone)]
pub struct Mask {
    /// Opacity in `[0, 1]` (Mitsuba's default 0.5), read with `eval_1`.
    pub opacity: Spectrum,
    /// The BSDF where the surface is opaque.
    pub nested: Arc<dyn Bsdf>,
}

/// Reads `<bsdf type="mask">`: `opacity` (a value or a texture) and one nested BSDF.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let opacity = p.texture("opacity")?;
    let nested = p.nested_bsdfs()?;
    p.finish()?;
    let nested = match nested.as_slice() {
        [] => return Err(p.err(None, "mask needs one nested <bsdf>")),
        [(bsdf, _)] => bsdf.clone(),
        [_, (_, second), ..] => {
            return Err(p.err(Some(*second), "a mask takes exactly one nested bsdf"));
        }
    };
    Ok(Arc::new(Mask {
        opacity: opacity.map_or(Spectrum::grey(0.5), |(o, _)| o),
        nested,
    }))
}

impl Mask {
    /// The opacity at `at`, clamped to `[0, 1]` as Mitsuba clamps it.
    #[inline]
    fn opacity(&self, at: &SurfacePoint) -> f32 {
        let o = self.opacity.eval_1(at.uv);
        if o > 0.0 { o.min(1.0) } else { 0.0 }
    }
}

impl Bsdf for Mask {
    fn has_smooth_lobe(&self) -> bool {
        self.nested.has_smooth_lobe()
    }

    fn uses_uv(&self) -> bool {
        self.opacity.is_textured() || self.nested.uses_uv()
    }

    fn reads_tangents(&self) -> bool {
        self.nested.reads_tangents()
    }

    /// `opacity` times the nested albedo: the pass-through reflects nothing.
    fn albedo(&self, at: &SurfacePoint) -> Rgb {
        self.nested.albedo(at) * self.opacity(at)
    }

    fn feature_normal(&self, at: &SurfacePoint, wi: Vec3) -> Option<Vec3> {
        self.nested.feature_normal(at, wi)
    }

    fn transmits(&self) -> bool {
        true
    }

    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        let opacity = self.opacity(at);
        let (value, pdf) = self.nested.eval_pdf(at, wi, wo);
        (value * opacity, pdf * opacity)
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let opacity = self.opacity(at);
        if u_lobe < opacity {
            // The nested lobe, chosen with probability `opacity`: its eval and pdf both carry
            // the factor, so the weight is the nested one.
            let mut s = self.nested.sample(at, wi, u_lobe / opacity, u)?;
            if !s.delta {
                s.pdf *= opacity;
            }
            Some(s)
        } else {
            // Pass-through, chosen with probability 1 − opacity, weight (1 − opacity) / itself.
            Some(BsdfSample {
                wo: -wi,
                weight: Rgb::ONE,
                pdf: f32::INFINITY,
                delta: true,
                eta: 1.0,
            })
        }
    }
}
