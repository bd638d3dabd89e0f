//! Warps from the unit square to the shapes the renderer samples, with their densities.
//!
//! Each warp takes uniform numbers in `[0, 1)` and is measure-preserving up to its stated pdf.
//! They are tested where they are used: the cosine hemisphere by the BSDF chi-square tests
//! (`tests/render_bsdf.rs`), the cone, disk and triangle maps by the solid-angle and pdf checks
//! of the shape samplers (`tests/render_geometry.rs`), the sphere by the white furnaces
//! (`tests/render.rs`).

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// An orthonormal basis whose `z` axis is a given unit normal (local shading frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// First tangent.
    pub s: Vec3,
    /// Second tangent.
    pub t: Vec3,
    /// The normal.
    pub n: Vec3,
}

impl Frame {
    /// A right-handed frame around the unit vector `n` (Duff et al. 2017, branchless).
    pub fn new(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Frame {
            s: Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            t: Vec3::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    /// World vector to local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local coordinates to a world vector.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// Uniform point on the unit disk (Shirley–Chiu concentric map; keeps strata compact).
pub fn square_to_disk(u: Vec2) -> Vec2 {
    let a = 2.0 * u - Vec2::ONE;
    if a.x == 0.0 && a.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, phi) = if a.x.abs() > a.y.abs() {
        (a.x, (PI / 4.0) * (a.y / a.x))
    } else {
        (a.y, PI / 2.0 - (PI / 4.0) * (a.x / a.y))
    };
    Vec2::new(r * phi.cos(), r * phi.sin())
}

/// Cosine-weighted direction on the `+z` hemisphere.
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Density of [`square_to_cosine_hemisphere`] per unit solid angle.
pub fn cosine_hemisphere_pdf(v: Vec3) -> f32 {
    if v.z > 0.0 { v.z * FRAC_1_PI } else { 0.0 }
}

/// Uniform direction on the unit sphere.
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`square_to_uniform_sphere`] per unit solid angle.
pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform direction in the cone of half-angle `acos(cos_max)` around `+z`.
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let z = 1.0 - u.y * (1.0 - cos_max);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`square_to_uniform_cone`] per unit solid angle (inside the cone).
pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Uniform barycentrics `(b1, b2)` on a triangle (the point is `(1−b1−b2)·p0 + b1·p1 + b2·p2`).
pub fn square_to_triangle(u: Vec2) -> Vec2 {
    // Heitz 2019, "A low-distortion map between triangle and square": no square root.
    if u.x < u.y {
        let b0 = u.x / 2.0;
        Vec2::new(b0, u.y - b0)
    } else {
        let b1 = u.y / 2.0;
        Vec2::new(u.x - b1, b1)
    }
}

/// Veach's power heuristic (exponent 2) for a strategy of density `a` against one of `b`.
#[inline]
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        // Infinite densities (a delta) win outright.
        if a2.is_infinite() {
            return 1.0;
        }
        a2 / (a2 + b2)
    } else {
        0.0
    }
}
