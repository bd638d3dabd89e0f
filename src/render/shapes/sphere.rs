//! Mitsuba's `sphere`: the unit sphere mapped by `to_world · translate(center) · scale(radius)`.
//! Its texture coordinates are not modelled (the loader refuses textures on it).

use crate::error::Result;
use crate::render::mitsuba::{Params, SIMILARITY_TOLERANCE, num, value_or, vec_text};
use crate::render::scene::GeometryDesc;
use glam::{Mat3, Mat4, Vec3};

/// Reads `<shape type="sphere">`, which must map to a similarity (uniform scale, rotation,
/// translation) without mirroring.
pub fn load(p: &mut Params) -> Result<GeometryDesc> {
    let center = p.point("center")?;
    let radius = p.float("radius")?;
    let to_world = p.transform("to_world")?;
    p.finish()?;
    let node = p.owner();
    let ld = p.loader();
    let r = value_or(radius, 1.0);
    if !(r > 0.0) {
        let at = radius.map_or(node, |(_, at)| at);
        return Err(ld.err(
            at,
            format!(
                "radius = {}: must be > 0 (negative radii flip normals in Mitsuba, which \
                 is not modelled)",
                num(r)
            ),
        ));
    }
    let at = to_world.map_or(node, |(_, at)| at);
    let to_world = ld.affine(to_world)?;
    let full = to_world
        * Mat4::from_translation(value_or(center, Vec3::ZERO))
        * Mat4::from_scale(Vec3::splat(r));
    let linear = Mat3::from_mat4(full);
    let axes = [linear.x_axis, linear.y_axis, linear.z_axis];
    let lengths = Vec3::from_array(axes.map(Vec3::length));
    let world_radius = lengths.element_sum() / 3.0;
    let spread = lengths.max_element() - lengths.min_element();
    let skew = [
        axes[0].dot(axes[1]),
        axes[1].dot(axes[2]),
        axes[2].dot(axes[0]),
    ]
    .map(f32::abs)
    .into_iter()
    .fold(0.0, f32::max);
    if spread > SIMILARITY_TOLERANCE * world_radius
        || skew > SIMILARITY_TOLERANCE * world_radius * world_radius
    {
        return Err(ld.err(
            at,
            format!(
                "a sphere's to_world must be a uniform scale, rotation and translation; \
                 this one scales the axes by {} (non-uniform scale or shear)",
                vec_text(lengths)
            ),
        ));
    }
    if linear.determinant() < 0.0 {
        return Err(ld.err(
            at,
            "a sphere's to_world mirrors (negative determinant), which flips its normals \
             in Mitsuba; not modelled",
        ));
    }
    // radius × scale can underflow to 0 (radius 1e-45) or overflow: the renderer drops such
    // a sphere, so say so here instead.
    if !(world_radius > 0.0 && world_radius.is_finite()) {
        let at = radius.map_or(at, |(_, at)| at);
        return Err(ld.err(
            at,
            format!(
                "the sphere's world-space radius (radius {} times the to_world scale) is \
                 {}, not a positive finite f32",
                num(r),
                num(world_radius)
            ),
        ));
    }
    Ok(GeometryDesc::Sphere {
        center: full.w_axis.truncate(),
        radius: world_radius,
    })
}
