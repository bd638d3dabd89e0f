//! Mitsuba's `cube`: the mesh of `[-1,1]³` with outward normals, mapped by `to_world`. Its
//! texture coordinates are not modelled (the loader refuses textures on it).

use super::mesh::{cube_mesh, transform_mesh};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::GeometryDesc;

/// Reads `<shape type="cube">`.
pub fn load(p: &mut Params) -> Result<GeometryDesc> {
    let to_world = p.transform("to_world")?;
    p.finish()?;
    let to_world = p.loader().affine(to_world)?;
    let (positions, indices) = cube_mesh();
    Ok(GeometryDesc::Mesh(transform_mesh(
        positions, None, None, indices, to_world,
    )))
}
