//! Mitsuba's `conductor`: a smooth metal, front side only, reflecting with the conductor
//! Fresnel factor of its complex index of refraction times `specular_reflectance`.

use super::{Bsdf, BsdfSample, NONE, SurfacePoint, reflect_z};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A smooth conductor.
#[derive(Debug, Clone)]
pub struct Conductor {
    /// Tint (Mitsuba's default 1).
    pub specular_reflectance: Spectrum,
}

/// Reads `<bsdf type="conductor">`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    super::roughconductor::reject_complex_ior(p)?;
    let material = p.string("material")?;
    let tint = p.texture("specular_reflectance")?;
    p.finish()?;
    super::roughconductor::check_material(p, material)?;
    Ok(Arc::new(Conductor {
        specular_reflectance: tint.map_or(Spectrum::grey(1.0), |(t, _)| t),
    }))
}

impl Bsdf for Conductor {
    fn has_smooth_lobe(&self) -> bool {
        false
    }

    fn uses_uv(&self) -> bool {
        self.specular_reflectance.is_textured()
    }

    fn eval_pdf(&self, _at: &SurfacePoint, _wi: Vec3, _wo: Vec3) -> (Rgb, f32) {
        NONE
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, _u_lobe: f32, _u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wo: reflect_z(wi),
            weight: self.specular_reflectance.eval(at.uv),
            pdf: f32::INFINITY,
            delta: true,
            eta: 1.0,
        })
    }
}
