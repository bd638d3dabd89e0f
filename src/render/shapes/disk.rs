//! Mitsuba's `disk`: the unit disk at `z = 0` facing `+z`, mapped by an affine `to_world`.
//! Its texture coordinates are not modelled (the loader refuses textures on it).

use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::GeometryDesc;

/// Reads `<shape type="disk">`.
pub fn load(p: &mut Params) -> Result<GeometryDesc> {
    let to_world = p.transform("to_world")?;
    p.finish()?;
    Ok(GeometryDesc::Disk {
        to_world: p.loader().affine(to_world)?,
    })
}
