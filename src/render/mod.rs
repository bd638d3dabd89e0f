//! A reference path tracer for the subset of Mitsuba 3 scenes this project needs.
//!
//! Layers, top to bottom: [`film`] (per-pixel estimator banks), [`reference`] (converged means
//! with their standard errors) and [`integrator`] (unidirectional
//! path tracing with next-event estimation and MIS) over [`world`] (the built scene: [`bvh`],
//! [`camera`], and the plugins) over [`scene`] (plain description, produced by [`mitsuba`] from
//! XML) and [`sampling`] (warps and frames).
//!
//! Plugins have one home each: [`bsdfs`], [`textures`], [`emitters`] and [`shapes`] hold one file
//! per Mitsuba plugin, with its parameter reading and its maths; the loader dispatches to them
//! from one table ([`mitsuba::table`]).

pub mod bsdfs;
pub mod bvh;
pub mod camera;
pub mod emitters;
pub mod film;
pub mod huge_table;
pub mod integrator;
pub mod mitsuba;
pub mod nfor_buffers;
pub mod prefetch;
pub mod reference;
pub mod sampler;
pub mod sampling;
pub mod scene;
pub mod shapes;
pub mod slab;
pub mod textures;
pub mod world;

pub use scene::{CameraDesc, GeometryDesc, IntegratorDesc, Rgb, SceneDesc, ShapeDesc};
