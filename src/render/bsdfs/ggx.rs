//! The isotropic GGX (Trowbridge–Reitz) microfacet distribution with Smith's separable
//! shadowing, as Mitsuba evaluates it (Walter et al. 2007), and visible-normal sampling after
//! Heitz 2018, "Sampling the GGX distribution of visible normals" (JCGT 7(4)).

use crate::render::sampling::square_to_disk;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Smallest GGX roughness used (Mitsuba clamps `alpha` to the same bound).
pub const MIN_ALPHA: f32 = 1e-4;

/// The isotropic GGX distribution with Smith shadowing, as Mitsuba evaluates it.
#[derive(Debug, Clone, Copy)]
pub struct Ggx {
    /// Roughness (at least [`MIN_ALPHA`]).
    pub alpha: f32,
}

impl Ggx {
    /// Microfacet normal density `D(m)` per unit solid angle of `m`, normalised so that the
    /// projected facet area is one: `∫ D(m) cos θm dm = 1`.
    #[inline]
    pub fn d(self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let t = (m.x * m.x + m.y * m.y) / a2 + m.z * m.z;
        let d = 1.0 / (PI * a2 * t * t);
        // Mitsuba drops vanishing densities to keep later stages well-conditioned.
        if d * m.z > 1e-20 && d.is_finite() {
            d
        } else {
            0.0
        }
    }

    /// `G1(v) / cos θv` for `v.z > 0`: Smith's GGX masking divided by the cosine, in a form that
    /// stays finite as `v.z → 0` (the plain `2/(1+√(1+α² tan²θ))` overflows there).
    #[inline]
    pub fn g1_over_cos(self, v: Vec3) -> f32 {
        let a2 = self.alpha * self.alpha;
        2.0 / (v.z + (v.z * v.z + a2 * (v.x * v.x + v.y * v.y)).sqrt())
    }

    /// Smith's masking `G1(v, m)`: 0 if `v` sees the back of the facet `m` or lies below the
    /// horizon of the macro-surface (only `v.z > 0` is used here).
    #[inline]
    pub fn g1(self, v: Vec3, m: Vec3) -> f32 {
        if v.z <= 0.0 || v.dot(m) <= 0.0 {
            return 0.0;
        }
        (v.z * self.g1_over_cos(v)).min(1.0)
    }

    /// Draws a microfacet normal from the visible-normal distribution `D_wi` (requires
    /// `wi.z > 0`), following Heitz 2018: in the configuration stretched to `alpha = 1` the
    /// visible normals are those of a hemisphere, whose projection onto the plane orthogonal to
    /// the (stretched) view is a unit disk — half of it behind the hemisphere's rim foreshortened
    /// by `cos θ`. A uniform disk point is squeezed into that shape, lifted onto the hemisphere,
    /// and the normal unstretched.
    pub fn sample_visible(self, wi: Vec3, u: Vec2) -> Option<Vec3> {
        let a = self.alpha;
        // Stretch the view so the distribution becomes the alpha = 1 one.
        let vh = Vec3::new(a * wi.x, a * wi.y, wi.z).try_normalize()?;
        // Basis of the plane orthogonal to vh.
        let len_sq = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len_sq > 0.0 {
            Vec3::new(-vh.y, vh.x, 0.0) / len_sq.sqrt()
        } else {
            Vec3::X
        };
        let t2 = vh.cross(t1);
        // Uniform point on the unit disk (concentric map: keeps strata compact), then compress
        // its t2 half behind the rim to the projected area of the visible half-ellipse.
        let p = square_to_disk(u);
        let s = 0.5 * (1.0 + vh.z);
        let p1 = p.x;
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p.y;
        // Lift onto the hemisphere around vh.
        let lift = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        let nh = p1 * t1 + p2 * t2 + lift * vh;
        // Unstretch (normals transform with the inverse transpose).
        let m = Vec3::new(a * nh.x, a * nh.y, nh.z.max(0.0)).try_normalize()?;
        (m.z > 0.0).then_some(m)
    }
}
