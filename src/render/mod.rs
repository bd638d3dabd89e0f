//! A reference path tracer for the subset of Mitsuba 3 scenes this project needs.
//!
//! Layers, top to bottom: [`film`] (per-pixel estimator banks) and [`integrator`] (unidirectional
//! path tracing with next-event estimation and MIS) over [`world`] (the built scene: [`bvh`],
//! [`shapes`], [`light`], [`camera`], [`bsdf`]) over [`scene`] (plain description, produced by
//! [`mitsuba`] from XML, with [`obj`] reading meshes) and [`sampling`] (warps and frames).

pub mod bsdf;
pub mod bvh;
pub mod camera;
pub mod film;
pub mod integrator;
pub mod light;
pub mod mitsuba;
pub mod obj;
pub mod sampler;
pub mod sampling;
pub mod scene;
pub mod shapes;
pub mod world;

pub use scene::{BsdfDesc, CameraDesc, GeometryDesc, IntegratorDesc, Rgb, SceneDesc, ShapeDesc};
