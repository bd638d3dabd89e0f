//! Building world-space triangle meshes: Mitsuba's built-in rectangle and cube, transforms,
//! and the vertex normals Mitsuba computes for meshes without them.

use super::triangle_normal;
use crate::render::scene::MeshDesc;
use glam::{Mat3, Mat4, Vec2, Vec3};

/// Mitsuba's rectangle: the square `[-1,1]²` at `z = 0`, counter-clockwise seen from `+z`, with
/// Mitsuba's texture coordinates `((x + 1) / 2, (y + 1) / 2)`.
pub fn rectangle_mesh() -> (Vec<Vec3>, Vec<Vec2>, Vec<[u32; 3]>) {
    let positions = vec![
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    ];
    let uvs = positions
        .iter()
        .map(|p| Vec2::new((p.x + 1.0) * 0.5, (p.y + 1.0) * 0.5))
        .collect();
    (positions, uvs, vec![[0, 1, 2], [0, 2, 3]])
}

/// Mitsuba's cube: `[-1,1]³` as 6 faces of 2 triangles, each counter-clockwise seen from
/// outside (4 vertices per face, as in Mitsuba's mesh), with Mitsuba's texture coordinates
/// ([`cube_uv`]).
pub fn cube_mesh() -> (Vec<Vec3>, Vec<Vec2>, Vec<[u32; 3]>) {
    let mut positions = Vec::with_capacity(24);
    let mut uvs = Vec::with_capacity(24);
    let mut indices = Vec::with_capacity(12);
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let normal = Vec3::AXES[axis] * sign;
            // (u, v, normal) is right-handed, so corners in (u, v) order wind around `normal`.
            let (mut u, mut v) = (Vec3::AXES[(axis + 1) % 3], Vec3::AXES[(axis + 2) % 3]);
            if sign < 0.0 {
                std::mem::swap(&mut u, &mut v);
            }
            let first = positions.len() as u32;
            let corners = [
                normal - u - v,
                normal + u - v,
                normal + u + v,
                normal - u + v,
            ];
            uvs.extend(corners.map(|p| cube_face_uv(axis, sign < 0.0, p)));
            positions.extend(corners);
            indices.push([first, first + 1, first + 2]);
            indices.push([first, first + 2, first + 3]);
        }
    }
    (positions, uvs, indices)
}

/// The texture coordinates of Mitsuba 3.9.1's cube at the point `p` of one of its faces (the
/// face whose axis has the largest `|p|` component), linear on each face.
pub fn cube_uv(p: Vec3) -> Vec2 {
    let a = p.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    cube_face_uv(axis, p[axis] < 0.0, p)
}

/// The texture coordinates on the cube's face `axis` (0 = x), on its negative side if
/// `negative`, at the point `p` of that face. Read off Mitsuba by intersecting its cube
/// (`si.uv`) on a 4x4 grid per face; `tests/render_formats.rs` checks them. The face must be
/// named: at a corner vertex every axis has `|p| = 1`.
fn cube_face_uv(axis: usize, negative: bool, p: Vec3) -> Vec2 {
    let half = |a: f32| (a + 1.0) * 0.5;
    let flip = |a: f32| (1.0 - a) * 0.5;
    match (axis, negative) {
        (0, true) => Vec2::new(half(p.y), half(p.z)),
        (0, false) => Vec2::new(half(p.y), flip(p.z)),
        (1, true) => Vec2::new(half(p.z), half(p.x)),
        (1, false) => Vec2::new(flip(p.x), flip(p.z)),
        (_, true) => Vec2::new(flip(p.y), half(p.x)),
        (_, false) => Vec2::new(half(p.y), half(p.x)),
    }
}

/// Maps an object-space mesh to world space. Normals transform with the inverse transpose;
/// since `(M a) × (M b) = det(M) · M⁻ᵀ (a × b)`, a mirroring map (`det < 0`) would turn each
/// triangle's winding against its transformed normal, so the winding is reversed then to keep
/// triangles counter-clockwise seen from the front.
pub fn transform_mesh(
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    uvs: Option<Vec<Vec2>>,
    indices: Vec<[u32; 3]>,
    to_world: Mat4,
) -> MeshDesc {
    let linear = Mat3::from_mat4(to_world);
    let normal_matrix = linear.inverse().transpose();
    let mirrored = linear.determinant() < 0.0;
    MeshDesc {
        positions: positions
            .into_iter()
            .map(|p| to_world.transform_point3(p))
            .collect(),
        normals: normals.map(|ns| {
            ns.into_iter()
                .map(|n| (normal_matrix * n).normalize())
                .collect()
        }),
        uvs,
        indices: indices
            .into_iter()
            .map(|[a, b, c]| if mirrored { [a, c, b] } else { [a, b, c] })
            .collect(),
    }
}

/// The angle between two edges. glam's `angle_between` divides by `sqrt(|a|²·|b|²)`, which
/// overflows for edges beyond about 1e9 (a 1e10 ground plane got right angles everywhere), so
/// such edges are normalised first.
fn corner_angle(a: Vec3, b: Vec3) -> f32 {
    if (a.length_squared() * b.length_squared()).is_finite() {
        a.angle_between(b)
    } else {
        a.normalize_or_zero().angle_between(b.normalize_or_zero())
    }
}

/// Mitsuba's vertex normals for meshes without them: each triangle adds its unit normal weighted
/// by its angle at the vertex (Thürmer and Wüthrich 1998). Vertices touched only by degenerate
/// triangles get `+z` (those triangles have no area and are never hit).
pub fn angle_weighted_normals(positions: &[Vec3], indices: &[[u32; 3]]) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for tri in indices {
        let p = tri.map(|i| positions[i as usize]);
        // The plain cross product first (bit-identical normals for ordinary triangles), the
        // scale-safe one for triangles whose cross product overflows or underflows.
        let Some(normal) = (p[1] - p[0])
            .cross(p[2] - p[0])
            .try_normalize()
            .or_else(|| triangle_normal(&p))
        else {
            continue;
        };
        for k in 0..3 {
            let angle = corner_angle(p[(k + 1) % 3] - p[k], p[(k + 2) % 3] - p[k]);
            sums[tri[k] as usize] += normal * angle;
        }
    }
    sums.into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Z))
        .collect()
}
