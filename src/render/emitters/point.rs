//! Mitsuba's `point` emitter: a delta in position, radiant intensity in W/sr.

use super::{Emitter, LightSample};
use crate::error::Result;
use crate::render::mitsuba::{Params, beyond_limit, beyond_message, vec_text};
use crate::render::scene::Rgb;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A point light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLight {
    /// Position in world space.
    pub position: Vec3,
    /// Radiant intensity (W/sr per channel).
    pub intensity: Rgb,
}

/// Reads `<emitter type="point">`: `intensity` (required), and `position` or `to_world`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Emitter>> {
    let intensity = p.spectrum("intensity")?;
    let position = p.point("position")?;
    let to_world = p.transform("to_world")?;
    p.finish()?;
    let (intensity, _) = intensity
        .ok_or_else(|| p.err(None, "missing required parameter <rgb name=\"intensity\">"))?;
    let position = match (position, to_world) {
        (Some(_), Some((_, at))) => {
            return Err(p.err(
                Some(at),
                "give either position or to_world for a point emitter, not both",
            ));
        }
        (Some((p, _)), None) => p,
        (None, to_world) => p.loader().affine(to_world)?.w_axis.truncate(),
    };
    if let Some(reach) = beyond_limit(position) {
        let what = format!("the point light at {}", vec_text(position));
        return Err(p.err(None, beyond_message(&what, reach)));
    }
    Ok(Arc::new(PointLight {
        position,
        intensity,
    }))
}

impl Emitter for PointLight {
    fn sample(&self, from: Vec3, _u: Vec2) -> Option<LightSample> {
        let to = self.position - from;
        let d2 = to.length_squared();
        if !(d2 > 0.0) {
            return None;
        }
        let dist = d2.sqrt();
        Some(LightSample::new(
            to / dist,
            dist,
            self.intensity / d2,
            1.0,
            true,
        ))
    }
}
