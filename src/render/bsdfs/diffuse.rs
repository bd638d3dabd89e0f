//! Mitsuba's `diffuse`: Lambertian reflection, front side only, cosine-weighted sampling.

use super::{Bsdf, BsdfSample, NONE, SurfacePoint};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

/// A Lambertian BSDF.
#[derive(Debug, Clone)]
pub struct Diffuse {
    /// Albedo (Mitsuba's default 0.5).
    pub reflectance: Spectrum,
}

impl Diffuse {
    /// A diffuse BSDF of constant albedo.
    pub fn new(reflectance: Rgb) -> Diffuse {
        Diffuse {
            reflectance: Spectrum::Constant(reflectance),
        }
    }
}

/// Reads `<bsdf type="diffuse">`: `reflectance` (a colour or a texture; default 0.5). Files
/// older than Mitsuba 2 may call it `diffuse_reflectance`, which Mitsuba 3 renames.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let mut reflectance = p.texture("reflectance")?;
    if p.loader().upgrades_names() {
        if let Some((old, at)) = p.texture("diffuse_reflectance")? {
            if reflectance.is_some() {
                return Err(p.err(
                    Some(at),
                    "diffuse_reflectance (the old name of reflectance) given as well",
                ));
            }
            reflectance = Some((old, at));
        }
    }
    p.finish()?;
    Ok(Arc::new(Diffuse {
        reflectance: reflectance.map_or(Spectrum::grey(0.5), |(r, _)| r),
    }))
}

impl Bsdf for Diffuse {
    fn has_smooth_lobe(&self) -> bool {
        true
    }

    fn uses_uv(&self) -> bool {
        self.reflectance.is_textured()
    }

    /// The reflectance.
    fn albedo(&self, at: &SurfacePoint) -> Rgb {
        self.reflectance.eval(at.uv)
    }

    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return NONE;
        }
        let pdf = wo.z * FRAC_1_PI;
        (self.reflectance.eval(at.uv) * pdf, pdf)
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, _u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let wo = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wo);
        (pdf > 0.0).then(|| BsdfSample {
            wo,
            weight: self.reflectance.eval(at.uv),
            pdf,
            delta: false,
            eta: 1.0,
        })
    }
}
