//! The scene as the loader describes it: plain data, no acceleration structures.
//!
//! [`super::mitsuba`] turns an XML file into a [`SceneDesc`]; [`super::world`] builds the
//! renderable world (BVH, lights, camera) from it. Keeping the two apart lets tests build scenes
//! in code and lets the loader be tested without rendering.

use super::bsdfs::Bsdf;
use super::emitters::Emitter;
use glam::{Mat4, Vec2, Vec3};
use std::sync::Arc;

/// Linear RGB radiance, reflectance or weight.
pub type Rgb = Vec3;

/// Everything a render needs, as read from a scene file.
#[derive(Debug, Clone)]
pub struct SceneDesc {
    /// The `path` integrator's settings.
    pub integrator: IntegratorDesc,
    /// The perspective sensor with its film and sampler.
    pub camera: CameraDesc,
    /// Shapes in file order; each may carry an area emitter.
    pub shapes: Vec<ShapeDesc>,
    /// Emitters that are not attached to a shape (`point`, `constant`, `envmap`; at most one
    /// of them at infinity).
    pub emitters: Vec<Arc<dyn Emitter>>,
}

/// Mitsuba's `path` integrator parameters, with Mitsuba's meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IntegratorDesc {
    /// Longest path, in segments: 1 = emitters seen directly, 2 = direct illumination;
    /// `None` is Mitsuba's `-1` (unbounded). Mitsuba's default is `-1`.
    pub max_depth: Option<u32>,
    /// Depth at which Russian roulette starts (Mitsuba's default 5).
    pub rr_depth: u32,
}

impl Default for IntegratorDesc {
    fn default() -> Self {
        IntegratorDesc {
            max_depth: None,
            rr_depth: 5,
        }
    }
}

/// Which extent of the image `fov` spans (Mitsuba's `fov_axis`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FovAxis {
    /// Horizontal (Mitsuba's default).
    X,
    /// Vertical.
    Y,
    /// Diagonal.
    Diagonal,
    /// The smaller of width and height.
    Smaller,
    /// The larger of width and height.
    Larger,
}

/// A `perspective` sensor with an `hdrfilm` (box filter) and an `independent` sampler.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraDesc {
    /// Camera to world; the camera looks down its local `+z`, local `+x` is image left and
    /// local `+y` image up (Mitsuba's convention, as `lookat` builds it).
    pub to_world: Mat4,
    /// Field of view in degrees along `fov_axis`.
    pub fov_deg: f32,
    /// Which extent `fov_deg` spans.
    pub fov_axis: FovAxis,
    /// Film width in pixels.
    pub width: u32,
    /// Film height in pixels.
    pub height: u32,
    /// The sampler's `sample_count` (a default the command line may override).
    pub spp: u32,
    /// The reconstruction filter the file asked for when the `--rfilter box` override replaced
    /// it (`None`: the file asked for a box filter).
    pub replaced_filter: Option<String>,
    /// Distance of the near clipping plane along the view axis (Mitsuba's default 0.01).
    pub near_clip: f32,
    /// Distance of the far clipping plane along the view axis (Mitsuba's default 10000).
    pub far_clip: f32,
}

/// One shape with its material and optional area emitter.
#[derive(Debug, Clone)]
pub struct ShapeDesc {
    /// Geometry in world space (transforms already applied where the shape allows).
    pub geometry: GeometryDesc,
    /// Its BSDF (Mitsuba's default is a diffuse BSDF of reflectance 0.5, or 0 on a shape with
    /// an area emitter).
    pub bsdf: Arc<dyn Bsdf>,
    /// Radiance of its `area` emitter, emitted from the front side only.
    pub emission: Option<Rgb>,
}

/// Shape geometry. Fronts are where the normal points (Mitsuba's orientation).
#[derive(Debug, Clone, PartialEq)]
pub enum GeometryDesc {
    /// A triangle mesh in world space (`rectangle`, `cube` and `obj` all become meshes:
    /// Mitsuba's rectangle is the square `[-1,1]²` at `z = 0` facing `+z`, its cube the mesh of
    /// `[-1,1]³` with outward normals).
    Mesh(MeshDesc),
    /// A sphere; its front is the outside.
    Sphere {
        /// Centre in world space.
        center: Vec3,
        /// Radius (> 0).
        radius: f32,
    },
    /// Mitsuba's `disk`: the unit disk at `z = 0` facing `+z`, mapped by `to_world`
    /// (an affine map; a non-uniform scale makes an ellipse).
    Disk {
        /// Object to world.
        to_world: Mat4,
    },
}

/// A triangle mesh in world space.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshDesc {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (unit length), or `None` for flat shading.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates, if the mesh has them.
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles as vertex indices; counter-clockwise seen from the front.
    pub indices: Vec<[u32; 3]>,
}
