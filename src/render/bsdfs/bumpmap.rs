//! Mitsuba's `bumpmap`: the nested BSDF evaluated in a shading frame tilted by the gradient of
//! a height texture (Blinn, "Simulation of wrinkled surfaces", SIGGRAPH 1978, dropping the term
//! in the derivative of the normal, as Mitsuba does; so adding a constant to the height changes
//! nothing). Mitsuba 3.9.1's version, checked numerically against it
//! (`tests/data/bumpmap/make_fixture.py`, `tests/render_bumpmap.rs`).
//!
//! # The bumped frame
//!
//! With `g = scale · ∇h(uv)` (the texture's [`Texture::eval_1_grad`]) and `n` the shading
//! normal, the surface is displaced along `n` so that its tangents become
//! `∂p/∂u' = ∂p/∂u + n·(g.u − n·∂p/∂u)` and likewise for `v` (their normal components replaced
//! by the height's slope); the bumped normal is `∂p/∂u' × ∂p/∂v'`, negated if it points away
//! from the geometric normal. Then, with `flip_invalid_normals` (default true; Schüssler et al.,
//! "Microfacet-based normal mapping for robust Monte Carlo path tracing", SIGGRAPH Asia 2017,
//! as Mitsuba cites it), a bumped normal that sees `wi` from the other side than the shading
//! normal does is mirrored about the shading normal (its tangential part negated). `wi` and
//! `wo` are rotated into the frame of the normalised result and handed to the nested BSDF.
//!
//! # What changes the value
//!
//! * A direction the bump turns to the other side of the surface is refused: `eval` and `pdf`
//!   are zero, and a sample is dropped, when `wo` lies on different sides of the shading normal
//!   and the bumped one.
//! * With `use_shadowing_function` (default true), the value (not the pdf) and a sample's weight
//!   are multiplied by the shadowing term of Conty Estevez, Lecocq and Stein, "A Microfacet-Based
//!   Shadowing Function to Solve the Bump Terminator Problem" (Ray Tracing Gems, 2019):
//!   `G = 2 / (1 + sqrt(1 + α² tan² θo))`, `α² = min(tan² θb / 8, 1)`, with `θb` the bumped
//!   normal's and `θo` `wo`'s angle to the shading normal.
//!
//! # Differences that do not change the image
//!
//! * The bumped frame's tangents: Mitsuba orthogonalises the shading frame's first tangent
//!   against the new normal, we take [`Frame::new`] of it. The two differ by a rotation about
//!   the normal, which every BSDF here ignores (all are isotropic: `roughconductor` refuses
//!   `alpha_u`/`alpha_v`). An anisotropic nested BSDF would need Mitsuba's tangent (and the
//!   integrator Mitsuba's shading tangent, which follows `∂p/∂u`).
//! * A `bumpmap` nested in a `bumpmap` sees the outer one's bumped frame as its shading frame,
//!   as in Mitsuba.

use super::{Bsdf, BsdfSample, NONE, SurfacePoint};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::sampling::Frame;
use crate::render::scene::Rgb;
use crate::render::textures::Texture;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A BSDF with a bump map.
#[derive(Debug, Clone)]
pub struct BumpMap {
    /// The height field, read through its gradient only.
    pub height: Arc<dyn Texture>,
    /// Multiplier of the gradient (Mitsuba's `scale`, default 1).
    pub scale: f32,
    /// The BSDF evaluated in the bumped frame.
    pub nested: Arc<dyn Bsdf>,
    /// Mirror a bumped normal that faces `wi` from the wrong side (Mitsuba's
    /// `flip_invalid_normals`, default true).
    pub flip_invalid_normals: bool,
    /// Attenuate by the bump-terminator shadowing term (Mitsuba's `use_shadowing_function`,
    /// default true).
    pub use_shadowing_function: bool,
}

/// Reads `<bsdf type="bumpmap">`: one nested `<texture>` (the height; Mitsuba takes it under any
/// name or none), `scale`, `flip_invalid_normals`, `use_shadowing_function`, and one nested
/// BSDF.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let scale = p.float_or("scale", 1.0)?;
    let flip_invalid_normals = p.boolean("flip_invalid_normals")?.is_none_or(|(b, _)| b);
    let use_shadowing_function = p.boolean("use_shadowing_function")?.is_none_or(|(b, _)| b);
    let textures = p.objects(&["texture"]);
    let nested = p.nested_bsdfs()?;
    p.finish()?;
    // Mitsuba's order of complaints: the BSDF first, then the texture.
    let nested = match nested.as_slice() {
        [] => return Err(p.err(None, "bumpmap needs one nested <bsdf>")),
        [(bsdf, _)] => bsdf.clone(),
        [_, (_, second), ..] => {
            return Err(p.err(Some(*second), "a bumpmap takes exactly one nested bsdf"));
        }
    };
    let node = match textures.as_slice() {
        [] => {
            return Err(p.err(
                None,
                "bumpmap needs one nested <texture> (the height map, e.g. a bitmap)",
            ));
        }
        [node] => *node,
        [_, second, ..] => {
            return Err(p.err(Some(*second), "a bumpmap takes exactly one nested texture"));
        }
    };
    let height = p.loader().texture(node)?;
    if !height.has_eval_1_grad() {
        return Err(p.err(
            Some(node),
            "this texture has no gradient (Mitsuba implements eval_1_grad only for bitmap), so \
             it cannot be a bump map",
        ));
    }
    Ok(Arc::new(BumpMap {
        height,
        scale,
        nested,
        flip_invalid_normals,
        use_shadowing_function,
    }))
}

impl BumpMap {
    /// A bump map with Mitsuba's defaults (`flip_invalid_normals` and `use_shadowing_function`
    /// on).
    pub fn new(height: Arc<dyn Texture>, scale: f32, nested: Arc<dyn Bsdf>) -> BumpMap {
        BumpMap {
            height,
            scale,
            nested,
            flip_invalid_normals: true,
            use_shadowing_function: true,
        }
    }

    /// The bumped frame for incident direction `wi`, in the local coordinates of `at.frame`
    /// (whose `z` is the shading normal).
    pub fn local_frame(&self, at: &SurfacePoint, wi: Vec3) -> Frame {
        let g = self.scale * self.height.eval_1_grad(at.uv);
        let n = at.frame.n;
        let dp_du = at.dp_du + n * (g.x - n.dot(at.dp_du));
        let dp_dv = at.dp_dv + n * (g.y - n.dot(at.dp_dv));
        let mut bumped = dp_du.cross(dp_dv);
        if bumped.dot(at.ng) < 0.0 {
            bumped = -bumped;
        }
        let mut local = at.frame.to_local(bumped);
        if self.flip_invalid_normals && wi.z * wi.dot(local) <= 0.0 {
            local = Vec3::new(-local.x, -local.y, local.z);
        }
        // A degenerate bump (parallel tangents, overflow) keeps the shading normal, as Mitsuba.
        Frame::new(local.try_normalize().unwrap_or(Vec3::Z))
    }

    /// The bump-terminator shadowing term for the bumped normal `bumped` and `wo` (both in the
    /// shading frame), or 1 without `use_shadowing_function`.
    #[inline]
    fn shadowing(&self, bumped: Vec3, wo: Vec3) -> f32 {
        if !self.use_shadowing_function {
            return 1.0;
        }
        let alpha2 = (0.125 * tan2_theta(bumped)).min(1.0);
        2.0 / (1.0 + (1.0 + alpha2 * tan2_theta(wo)).sqrt())
    }

    /// What the nested BSDF is told about the point: the same, in the bumped frame.
    fn nested_point(at: &SurfacePoint, local: &Frame) -> SurfacePoint {
        SurfacePoint {
            frame: Frame {
                s: at.frame.to_world(local.s),
                t: at.frame.to_world(local.t),
                n: at.frame.to_world(local.n),
            },
            ..*at
        }
    }
}

/// `tan² θ` of a unit vector in a local frame (infinite at the horizon).
#[inline]
fn tan2_theta(v: Vec3) -> f32 {
    (1.0 - v.z * v.z).max(0.0) / (v.z * v.z)
}

impl Bsdf for BumpMap {
    fn has_smooth_lobe(&self) -> bool {
        self.nested.has_smooth_lobe()
    }

    fn uses_uv(&self) -> bool {
        true
    }

    fn reads_tangents(&self) -> bool {
        true
    }

    fn transmits(&self) -> bool {
        self.nested.transmits()
    }

    /// The nested albedo at the same point: the bump tilts the frame, not the colour.
    fn albedo(&self, at: &SurfacePoint) -> Rgb {
        self.nested.albedo(at)
    }

    fn feature_normal(&self, at: &SurfacePoint, wi: Vec3) -> Option<Vec3> {
        Some(self.local_frame(at, wi).n)
    }

    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        let local = self.local_frame(at, wi);
        let bumped_wo = local.to_local(wo);
        if !(wo.z * bumped_wo.z > 0.0) {
            return NONE;
        }
        let inner = Self::nested_point(at, &local);
        let (value, pdf) = self.nested.eval_pdf(&inner, local.to_local(wi), bumped_wo);
        (value * self.shadowing(local.n, wo), pdf)
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let local = self.local_frame(at, wi);
        let inner = Self::nested_point(at, &local);
        let mut s = self.nested.sample(&inner, local.to_local(wi), u_lobe, u)?;
        let wo = local.to_world(s.wo);
        // Mitsuba zeroes the weight of such a sample: the path ends either way.
        if !(wo.z * s.wo.z > 0.0) || s.weight.max_element() <= 0.0 {
            return None;
        }
        s.wo = wo;
        s.weight *= self.shadowing(local.n, wo);
        Some(s)
    }
}
