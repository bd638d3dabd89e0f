//! The renderable scene built from a [`SceneDesc`]: BVH, per-shape BSDFs, emitters, camera.

use super::bsdfs::Bsdf;
use super::bvh::Bvh;
use super::camera::Camera;
use super::emitters::Lights;
use super::scene::{IntegratorDesc, SceneDesc};
use super::shapes::primitives;
use std::sync::Arc;

/// Everything the integrator reads; immutable while rendering, shared by all threads.
#[derive(Debug)]
pub struct World {
    /// Acceleration structure over every primitive of every shape.
    pub bvh: Bvh,
    /// One BSDF per shape, indexed by the shape index a hit carries.
    pub bsdfs: Vec<Arc<dyn Bsdf>>,
    /// The emitters.
    pub lights: Lights,
    /// The sensor.
    pub camera: Camera,
    /// Path length and Russian roulette settings.
    pub integrator: IntegratorDesc,
}

impl World {
    /// Builds the world of a scene description.
    pub fn new(scene: &SceneDesc) -> Self {
        let mut prims = Vec::new();
        for (i, shape) in scene.shapes.iter().enumerate() {
            prims.extend(primitives(i as u32, &shape.geometry));
        }
        let mut bvh = Bvh::build(prims);
        let bsdfs: Vec<Arc<dyn Bsdf>> = scene.shapes.iter().map(|s| s.bsdf.clone()).collect();
        bvh.set_tangents(bsdfs.iter().any(|b| b.reads_tangents()));
        World {
            bvh,
            bsdfs,
            lights: Lights::new(scene),
            camera: Camera::new(&scene.camera),
            integrator: scene.integrator,
        }
    }
}
