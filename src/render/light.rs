//! Emitters and next-event estimation: area lights on shapes (front side only, as Mitsuba),
//! point lights and a constant environment. An emitter is chosen uniformly, as Mitsuba does;
//! the choice only changes variance, never the expected value.

use super::sampling::{UNIFORM_SPHERE_PDF, square_to_uniform_sphere};
use super::scene::{Rgb, SceneDesc};
use super::shapes::ShapeSampler;
use glam::{Vec2, Vec3};

/// One emitter.
#[derive(Debug, Clone)]
enum Emitter {
    /// An `area` emitter; `sampler` draws points on its shape.
    Area {
        sampler: ShapeSampler,
        radiance: Rgb,
    },
    /// A `point` emitter (a delta in position).
    Point { position: Vec3, intensity: Rgb },
    /// The `constant` environment, sampled uniformly over the sphere as Mitsuba does.
    Environment { radiance: Rgb },
}

/// A next-event sample: where the light comes from and what it brings.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    /// Unit direction from the shading point towards the emitter.
    pub wi: Vec3,
    /// Distance to the emitter point (`f32::INFINITY` for the environment).
    pub dist: f32,
    /// Incident radiance (for a point light, intensity / distance²).
    pub radiance: Rgb,
    /// Solid-angle density including the emitter choice (1 for deltas: unused in MIS).
    pub pdf: f32,
    /// A point light: no other strategy can sample it.
    pub delta: bool,
}

/// All emitters of a scene.
#[derive(Debug, Clone)]
pub struct Lights {
    emitters: Vec<Emitter>,
    /// Per shape: the index of its area emitter in `emitters`.
    by_shape: Vec<Option<u32>>,
    environment: Option<u32>,
}

impl Lights {
    /// The emitters of a scene description.
    pub fn new(scene: &SceneDesc) -> Self {
        let mut emitters = Vec::new();
        let mut by_shape = Vec::with_capacity(scene.shapes.len());
        for shape in &scene.shapes {
            by_shape.push(shape.emission.map(|radiance| {
                emitters.push(Emitter::Area {
                    sampler: ShapeSampler::new(&shape.geometry),
                    radiance,
                });
                (emitters.len() - 1) as u32
            }));
        }
        for p in &scene.point_lights {
            emitters.push(Emitter::Point {
                position: p.position,
                intensity: p.intensity,
            });
        }
        let environment = scene.environment.map(|radiance| {
            emitters.push(Emitter::Environment { radiance });
            (emitters.len() - 1) as u32
        });
        Lights {
            emitters,
            by_shape,
            environment,
        }
    }

    /// Whether the scene has no emitter at all (the image is black).
    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty()
    }

    /// Probability of choosing any one emitter.
    #[inline]
    fn choice_pdf(&self) -> f32 {
        1.0 / self.emitters.len() as f32
    }

    /// The radiance leaving shape `shape` towards `-d` from a point with front normal `ng`
    /// (zero from the back: area emitters emit from the front only).
    #[inline]
    pub fn emitted(&self, shape: u32, ng: Vec3, d: Vec3) -> Option<Rgb> {
        let i = self.by_shape.get(shape as usize).copied().flatten()?;
        match &self.emitters[i as usize] {
            Emitter::Area { radiance, .. } if ng.dot(d) < 0.0 => Some(*radiance),
            _ => None,
        }
    }

    /// Density with which [`Lights::sample`] from `from` would have chosen the point `p`
    /// (front normal `n`) on shape `shape`: what MIS weighs a BSDF-sampled hit against.
    #[inline]
    pub fn pdf_area_hit(&self, shape: u32, from: Vec3, p: Vec3, n: Vec3) -> f32 {
        match self.by_shape.get(shape as usize).copied().flatten() {
            Some(i) => match &self.emitters[i as usize] {
                Emitter::Area { sampler, .. } => {
                    self.choice_pdf() * sampler.pdf_direction(from, p, n)
                }
                _ => 0.0,
            },
            None => 0.0,
        }
    }

    /// The environment's radiance, seen by a ray that escapes the scene.
    #[inline]
    pub fn environment(&self) -> Option<Rgb> {
        self.environment.map(|i| match &self.emitters[i as usize] {
            Emitter::Environment { radiance } => *radiance,
            _ => Rgb::ZERO,
        })
    }

    /// Density with which [`Lights::sample`] would have chosen an escaping direction.
    #[inline]
    pub fn pdf_environment(&self) -> f32 {
        if self.environment.is_some() {
            self.choice_pdf() * UNIFORM_SPHERE_PDF
        } else {
            0.0
        }
    }

    /// Chooses an emitter with `u_choice` and a point or direction on it with `u`.
    /// `None` when the choice contributes nothing (back side, degenerate sample).
    #[inline]
    pub fn sample(&self, from: Vec3, u_choice: f32, u: Vec2) -> Option<LightSample> {
        let n = self.emitters.len();
        if n == 0 {
            return None;
        }
        let i = ((u_choice * n as f32) as usize).min(n - 1);
        let choice = self.choice_pdf();
        match &self.emitters[i] {
            Emitter::Area { sampler, radiance } => {
                let s = sampler.sample_direction(from, u)?;
                let to = s.p - from;
                let dist = to.length();
                if !(dist > 0.0 && s.pdf > 0.0) {
                    return None;
                }
                let wi = to / dist;
                if s.n.dot(wi) >= 0.0 {
                    return None; // the back of the emitter
                }
                Some(LightSample {
                    wi,
                    dist,
                    radiance: *radiance,
                    pdf: choice * s.pdf,
                    delta: false,
                })
            }
            Emitter::Point {
                position,
                intensity,
            } => {
                let to = *position - from;
                let d2 = to.length_squared();
                if !(d2 > 0.0) {
                    return None;
                }
                let dist = d2.sqrt();
                Some(LightSample {
                    wi: to / dist,
                    dist,
                    radiance: *intensity / d2,
                    pdf: choice,
                    delta: true,
                })
            }
            Emitter::Environment { radiance } => Some(LightSample {
                wi: square_to_uniform_sphere(u),
                dist: f32::INFINITY,
                radiance: *radiance,
                pdf: choice * UNIFORM_SPHERE_PDF,
                delta: false,
            }),
        }
    }
}
