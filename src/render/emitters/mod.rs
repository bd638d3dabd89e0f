//! Emitters and next-event estimation. One file per Mitsuba emitter plugin: `area` (on shapes,
//! front side only), `point`, `constant` and `envmap` (at infinity). An emitter is chosen
//! uniformly, as Mitsuba does; the choice only changes variance, never the expected value.

pub mod area;
pub mod constant;
pub mod envmap;
pub mod point;

use super::scene::{Rgb, SceneDesc};
use area::AreaLight;
use glam::{Vec2, Vec3};
use std::fmt::Debug;
use std::sync::Arc;

/// A next-event sample: where the light comes from, and what it brings, read through
/// [`Lights::resolve`] once the shadow ray has passed.
///
/// Why a separate read: an emitter may defer it. An environment map does: reading a drawn
/// texel misses the cache, and a blocked shadow ray then never pays for it.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    /// Unit direction from the shading point towards the emitter.
    pub wi: Vec3,
    /// Distance to the emitter point (`f32::INFINITY` for emitters at infinity).
    pub dist: f32,
    /// A point light: no other strategy can sample it.
    pub delta: bool,
    value: Value,
}

/// What a [`LightSample`] brings, or what its emitter needs to read it.
#[derive(Debug, Clone, Copy)]
enum Value {
    /// Incident radiance (for a point light, intensity / distance²) and solid-angle density
    /// (1 for deltas: unused in MIS), without the emitter choice.
    Known { radiance: Rgb, pdf: f32 },
    /// The emitter's key for [`Emitter::resolve`]; `emitter` is its index among the
    /// non-area emitters, set by [`Lights::sample`].
    Deferred { key: [u32; 3], emitter: u32 },
}

impl LightSample {
    /// A sample whose radiance and density (without the emitter choice) are known.
    pub fn new(wi: Vec3, dist: f32, radiance: Rgb, pdf: f32, delta: bool) -> LightSample {
        LightSample {
            wi,
            dist,
            delta,
            value: Value::Known { radiance, pdf },
        }
    }

    /// A direction towards an emitter at infinity (not a delta) whose radiance and density
    /// the emitter reads from `key` in [`Emitter::resolve`].
    pub fn deferred(wi: Vec3, key: [u32; 3]) -> LightSample {
        LightSample {
            wi,
            dist: f32::INFINITY,
            delta: false,
            value: Value::Deferred { key, emitter: 0 },
        }
    }
}

/// An emitter not attached to a shape.
pub trait Emitter: Debug + Send + Sync {
    /// A direction towards the emitter from `from`, drawn with `u`; `None` when it contributes
    /// nothing.
    fn sample(&self, from: Vec3, u: Vec2) -> Option<LightSample>;

    /// Starts loading what a later [`Emitter::sample`] with `u` will read first, if that is
    /// a random place in a large table (see [`crate::render::prefetch`]). Only a hint.
    fn prefetch(&self, _u: Vec2) {}

    /// Whether [`Emitter::prefetch`] does anything (so that callers skip computing its `u`).
    fn prefetches(&self) -> bool {
        false
    }

    /// Whether rays leaving the scene see it (an environment; at most one per scene).
    fn is_infinite(&self) -> bool {
        false
    }

    /// The `(radiance, pdf)` of a draw this emitter returned as [`LightSample::deferred`]
    /// with `key` (never called for an emitter that defers nothing).
    fn resolve(&self, _key: [u32; 3]) -> (Rgb, f32) {
        (Rgb::ZERO, 0.0)
    }
    /// Radiance arriving along a ray that left the scene in direction `d`, and the density
    /// with which [`Emitter::sample`] returns that direction.
    fn eval_pdf_escaped(&self, _d: Vec3) -> (Rgb, f32) {
        (Rgb::ZERO, 0.0)
    }
}

/// All emitters of a scene.
#[derive(Debug, Clone)]
pub struct Lights {
    /// Area emitters, in shape order.
    area: Vec<AreaLight>,
    /// Per shape: the index of its area emitter in `area`.
    by_shape: Vec<Option<u32>>,
    /// The other emitters, in file order.
    others: Vec<Arc<dyn Emitter>>,
    /// The one in `others` at infinity, if any.
    environment: Option<Arc<dyn Emitter>>,
    /// Whether any of `others` prefetches ([`Emitter::prefetches`]).
    prefetches: bool,
}

impl Lights {
    /// The emitters of a scene description.
    pub fn new(scene: &SceneDesc) -> Self {
        let mut area = Vec::new();
        let mut by_shape = Vec::with_capacity(scene.shapes.len());
        for shape in &scene.shapes {
            by_shape.push(shape.emission.map(|radiance| {
                area.push(AreaLight::new(&shape.geometry, radiance));
                (area.len() - 1) as u32
            }));
        }
        let environment = scene.emitters.iter().find(|e| e.is_infinite()).cloned();
        Lights {
            area,
            by_shape,
            others: scene.emitters.clone(),
            environment,
            prefetches: scene.emitters.iter().any(|e| e.prefetches()),
        }
    }

    /// Whether the scene has no emitter at all (the image is black).
    pub fn is_empty(&self) -> bool {
        self.area.is_empty() && self.others.is_empty()
    }

    /// Probability of choosing any one emitter.
    #[inline]
    fn choice_pdf(&self) -> f32 {
        1.0 / (self.area.len() + self.others.len()) as f32
    }

    /// The radiance leaving shape `shape` towards `-d` from a point with front normal `ng`
    /// (zero from the back: area emitters emit from the front only).
    #[inline]
    pub fn emitted(&self, shape: u32, ng: Vec3, d: Vec3) -> Option<Rgb> {
        let i = self.by_shape.get(shape as usize).copied().flatten()?;
        self.area[i as usize].emitted(ng, d)
    }

    /// Density with which [`Lights::sample`] from `from` would have chosen the point `p`
    /// (front normal `n`) on shape `shape`: what MIS weighs a BSDF-sampled hit against.
    #[inline]
    pub fn pdf_area_hit(&self, shape: u32, from: Vec3, p: Vec3, n: Vec3) -> f32 {
        match self.by_shape.get(shape as usize).copied().flatten() {
            Some(i) => self.choice_pdf() * self.area[i as usize].pdf_hit(from, p, n),
            None => 0.0,
        }
    }

    /// The environment's radiance along an escaping ray of direction `d`, if there is one,
    /// with the density with which [`Lights::sample`] would have chosen that direction.
    #[inline]
    pub fn environment(&self, d: Vec3) -> Option<(Rgb, f32)> {
        let (radiance, pdf) = self.environment.as_ref()?.eval_pdf_escaped(d);
        Some((radiance, self.choice_pdf() * pdf))
    }

    /// Chooses an emitter with `u_choice` and a point or direction on it with `u`.
    /// `None` when the choice contributes nothing (back side, degenerate sample).
    #[inline]
    pub fn sample(&self, from: Vec3, u_choice: f32, u: Vec2) -> Option<LightSample> {
        let i = self.choose(u_choice)?;
        let mut s = match self.area.get(i) {
            Some(light) => light.sample(from, u)?,
            None => self.others[i - self.area.len()].sample(from, u)?,
        };
        if let Value::Deferred { emitter, .. } = &mut s.value {
            *emitter = (i - self.area.len()) as u32;
        }
        Some(s)
    }

    /// Whether [`Lights::prefetch`] does anything.
    #[inline]
    pub fn prefetches(&self) -> bool {
        self.prefetches
    }

    /// Starts loading what [`Lights::sample`] with the same `u_choice` and `u` will read first:
    /// the integrator reads them ahead, before tracing the ray to the shading point, so the
    /// load overlaps the traversal. Only a hint; results do not depend on it.
    #[inline]
    pub fn prefetch(&self, u_choice: f32, u: Vec2) {
        let chosen = self.choose(u_choice);
        if let Some(other) = chosen.and_then(|i| self.others.get(i.checked_sub(self.area.len())?)) {
            other.prefetch(u);
        }
    }

    /// The emitter `u_choice` picks, uniformly (area emitters first, then the others); `None`
    /// when there is none.
    #[inline]
    fn choose(&self, u_choice: f32) -> Option<usize> {
        let n = self.area.len() + self.others.len();
        (n > 0).then(|| ((u_choice * n as f32) as usize).min(n - 1))
    }

    /// The incident radiance of a sample of [`Lights::sample`] and the density with which it
    /// was drawn, emitter choice included (for a delta light, the choice alone).
    #[inline]
    pub fn resolve(&self, s: &LightSample) -> (Rgb, f32) {
        let (radiance, pdf) = match s.value {
            Value::Known { radiance, pdf } => (radiance, pdf),
            Value::Deferred { key, emitter } => self.others[emitter as usize].resolve(key),
        };
        let choice = self.choice_pdf();
        (radiance, if s.delta { choice } else { pdf * choice })
    }
}
