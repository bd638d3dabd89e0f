//! Mitsuba's `cube`: the mesh of `[-1,1]³` with outward normals and Mitsuba's texture
//! coordinates, mapped by `to_world`.

use super::mesh::{cube_mesh, transform_mesh};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::GeometryDesc;

/// Reads `<shape type="cube">`.
pub fn load(p: &mut Params) -> Result<GeometryDesc> {
    let to_world = p.transform("to_world")?;
    p.finish()?;
    let to_world = p.loader().affine(to_world)?;
    let (positions, uvs, indices) = cube_mesh();
    Ok(GeometryDesc::Mesh(transform_mesh(
        positions,
        None,
        Some(uvs),
        indices,
        to_world,
    )))
}
