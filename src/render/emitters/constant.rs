//! Mitsuba's `constant` emitter: the same radiance from every direction at infinity, sampled
//! uniformly over the sphere as Mitsuba does.

use super::{Emitter, LightSample};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::sampling::{UNIFORM_SPHERE_PDF, square_to_uniform_sphere};
use crate::render::scene::Rgb;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A constant environment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Constant {
    /// Radiance from every direction.
    pub radiance: Rgb,
}

/// Reads `<emitter type="constant">`: `radiance` (required).
pub fn load(p: &mut Params) -> Result<Arc<dyn Emitter>> {
    let radiance = p.spectrum("radiance")?;
    p.finish()?;
    let (radiance, _) = radiance
        .ok_or_else(|| p.err(None, "missing required parameter <rgb name=\"radiance\">"))?;
    Ok(Arc::new(Constant { radiance }))
}

impl Emitter for Constant {
    fn sample(&self, _from: Vec3, u: Vec2) -> Option<LightSample> {
        Some(LightSample::new(
            square_to_uniform_sphere(u),
            f32::INFINITY,
            self.radiance,
            UNIFORM_SPHERE_PDF,
            false,
        ))
    }

    fn is_infinite(&self) -> bool {
        true
    }

    fn eval_pdf_escaped(&self, _d: Vec3) -> (Rgb, f32) {
        (self.radiance, UNIFORM_SPHERE_PDF)
    }
}
