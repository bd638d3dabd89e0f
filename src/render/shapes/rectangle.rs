//! Mitsuba's `rectangle`: the square `[-1,1]²` at `z = 0` facing `+z`, mapped by `to_world`,
//! with texture coordinates.

use super::mesh::{rectangle_mesh, transform_mesh};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::GeometryDesc;

/// Reads `<shape type="rectangle">`.
pub fn load(p: &mut Params) -> Result<GeometryDesc> {
    let to_world = p.transform("to_world")?;
    p.finish()?;
    let to_world = p.loader().affine(to_world)?;
    let (positions, uvs, indices) = rectangle_mesh();
    Ok(GeometryDesc::Mesh(transform_mesh(
        positions,
        None,
        Some(uvs),
        indices,
        to_world,
    )))
}
