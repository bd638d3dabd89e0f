//! Mitsuba's `area` emitter: constant radiance from the front of the shape it is nested in.

use super::LightSample;
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::{GeometryDesc, Rgb};
use crate::render::shapes::ShapeSampler;
use glam::{Vec2, Vec3};

/// An area emitter with the sampler of its shape.
#[derive(Debug, Clone)]
pub struct AreaLight {
    sampler: ShapeSampler,
    radiance: Rgb,
}

/// Reads `<emitter type="area">`: its `radiance` (required).
pub fn load(p: &mut Params) -> Result<Rgb> {
    let radiance = p.spectrum("radiance")?;
    p.finish()?;
    radiance
        .map(|(radiance, _)| radiance)
        .ok_or_else(|| p.err(None, "missing required parameter <rgb name=\"radiance\">"))
}

impl AreaLight {
    /// The emitter of radiance `radiance` on `geometry`.
    pub fn new(geometry: &GeometryDesc, radiance: Rgb) -> AreaLight {
        AreaLight {
            sampler: ShapeSampler::new(geometry),
            radiance,
        }
    }

    /// Radiance towards `-d` from a point of front normal `ng` (none from the back).
    #[inline]
    pub fn emitted(&self, ng: Vec3, d: Vec3) -> Option<Rgb> {
        (ng.dot(d) < 0.0).then_some(self.radiance)
    }

    /// Solid-angle density with which [`AreaLight::sample`] from `from` picks `p` (normal `n`).
    #[inline]
    pub fn pdf_hit(&self, from: Vec3, p: Vec3, n: Vec3) -> f32 {
        self.sampler.pdf_direction(from, p, n)
    }

    /// A point on the shape seen from `from`.
    #[inline]
    pub fn sample(&self, from: Vec3, u: Vec2) -> Option<LightSample> {
        let s = self.sampler.sample_direction(from, u)?;
        let to = s.p - from;
        let dist = to.length();
        if !(dist > 0.0 && s.pdf > 0.0) {
            return None;
        }
        let wi = to / dist;
        if s.n.dot(wi) >= 0.0 {
            return None; // the back of the emitter
        }
        Some(LightSample::new(wi, dist, self.radiance, s.pdf, false))
    }
}
