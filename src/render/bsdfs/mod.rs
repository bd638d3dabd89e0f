//! Surface scattering: one file per Mitsuba BSDF plugin, each holding its parameter reading and
//! its `eval`/`sample`/`pdf`, behind the one [`Bsdf`] trait the integrator calls.
//!
//! # Why Mitsuba's exact formulas
//!
//! The renderer is a reference for comparing pixel estimators on heavy-tailed samples; its images
//! must agree with Mitsuba 3 renders of the same scene in expectation. So every choice that
//! changes the expected value (shadowing terms, Fresnel factors, radiance scaling across
//! refractive interfaces, one-sidedness) follows Mitsuba, and only choices that leave the
//! expectation alone (the warp used for visible normals, how degenerate inputs are rejected) are
//! our own.
//!
//! # Conventions (Mitsuba's)
//!
//! * Every direction is a unit vector in the **local shading frame**: `z` is the front normal.
//! * `wi` points from the surface toward the previous path vertex (toward the camera side);
//!   `wo` toward the next vertex.
//! * [`Bsdf::eval_pdf`] returns `f(wi, wo) · |cos θo|` — the cosine foreshortening is included,
//!   as in Mitsuba's `BSDF::eval` — and the solid-angle density of [`Bsdf::sample`].
//! * [`Bsdf::sample`] returns the weight `eval / pdf` for smooth lobes, so a path tracer
//!   multiplies its throughput by `weight` without touching `pdf`.
//! * Delta lobes (mirror, smooth glass, a mask's pass-through) evaluate to 0 and have pdf 0 under
//!   [`Bsdf::eval_pdf`]: no finite direction can hit them.
//!
//! ## The `pdf` of a delta sample
//!
//! Mitsuba reports the *discrete* probability of having picked the delta lobe (1 for a mirror,
//! `F` or `1 − F` for glass). We report **`f32::INFINITY`** instead, with `delta = true`: the
//! density of a Dirac lobe per unit solid angle is unbounded, the discrete lobe-selection
//! probability is already folded into `weight`, and [`super::sampling::power_heuristic`] then
//! gives a delta-sampled direction full weight against any finite light-sampling density even if
//! an integrator forgets to test `delta`. Integrators should still branch on `delta` (as
//! Mitsuba's `path` integrator does) and never multiply by this pdf.
//!
//! # Adding a plugin
//!
//! Write one file with a struct implementing [`Bsdf`] and a `load` function reading its
//! parameters, and add one row to the loader's table (`super::mitsuba::table`).

pub mod bumpmap;
pub mod conductor;
pub mod dielectric;
pub mod diffuse;
pub mod fresnel;
pub mod ior;
pub mod mask;
pub mod microfacet;
pub mod plastic;
pub mod roughconductor;
pub mod roughdielectric;
pub mod roughplastic;
pub mod thindielectric;
pub mod twosided;

use super::sampling::Frame;
use super::scene::Rgb;
use glam::{Vec2, Vec3};
use std::fmt::Debug;

/// What a BSDF may look up about the surface point it scatters at, besides directions.
///
/// Everything here is cheap to fill at every hit (a few dozen flops): BSDFs that do not read a
/// field pay only for copying it. The tangents are the exception, filled only in scenes that
/// read them ([`Bsdf::reads_tangents`]): leaving them out saved 1.2% of the instructions on
/// a ball of diffuse triangles, 1.0% on the living room.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// Texture coordinates (Mitsuba's `uv`; `(0, 0)` on shapes without them).
    pub uv: Vec2,
    /// The world-space shading frame the directions are expressed in (`frame.to_world` of a
    /// local direction is the world direction); its `n` is the shading normal.
    pub frame: Frame,
    /// Unit geometric normal of the shape's front, in world space (Mitsuba's `si.n`).
    pub ng: Vec3,
    /// World-space `∂p/∂u` (Mitsuba's `si.dp_du`): on a triangle with texture coordinates, from
    /// its uv parametrisation; elsewhere the first tangent of `ng`'s coordinate system, as
    /// Mitsuba's meshes without uvs have it. Zero in a scene whose BSDFs do not read it.
    pub dp_du: Vec3,
    /// World-space `∂p/∂v` (Mitsuba's `si.dp_dv`), likewise.
    pub dp_dv: Vec3,
}

impl Default for SurfacePoint {
    /// A point at the origin of texture space whose local frame is the world's (`+z` up).
    fn default() -> Self {
        SurfacePoint {
            uv: Vec2::ZERO,
            frame: Frame::new(Vec3::Z),
            ng: Vec3::Z,
            dp_du: Vec3::X,
            dp_dv: Vec3::Y,
        }
    }
}

/// The outcome of [`Bsdf::sample`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BsdfSample {
    /// Sampled outgoing direction (local frame, unit length).
    pub wo: Vec3,
    /// `eval(wi, wo) / pdf` for smooth lobes; for delta lobes the tint times the Fresnel or
    /// radiance-scaling factor, divided by the probability of having chosen the lobe.
    pub weight: Rgb,
    /// Solid-angle density of `wo` (> 0 and finite) for smooth lobes; `f32::INFINITY` for a delta
    /// lobe (see the module documentation).
    pub pdf: f32,
    /// Whether `wo` came from a delta (specular or null) lobe.
    pub delta: bool,
    /// Relative index of refraction `η_t / η_i` crossed by a transmission; 1 for reflection.
    pub eta: f32,
}

/// A BSDF ready for rendering. Shared between shapes (`Arc`) and threads.
pub trait Bsdf: Debug + Send + Sync {
    /// True if the BSDF has a non-delta lobe, i.e. [`Bsdf::eval_pdf`] can be non-zero; only then
    /// is next-event estimation worth doing (Mitsuba's `Smooth` flag).
    fn has_smooth_lobe(&self) -> bool;

    /// Whether the BSDF reads [`SurfacePoint::uv`] (a texture somewhere in it), so the loader
    /// can refuse it on a shape without texture coordinates.
    fn uses_uv(&self) -> bool {
        false
    }

    /// Whether the BSDF reads [`SurfacePoint::dp_du`] and [`SurfacePoint::dp_dv`] (a bump map
    /// somewhere in it): hits compute them only in a scene where some BSDF does.
    fn reads_tangents(&self) -> bool {
        false
    }

    /// Whether light can pass to the other side (Mitsuba's `Transmission` flags: glass, a
    /// mask's pass-through); `twosided` refuses such a BSDF, as Mitsuba does.
    fn transmits(&self) -> bool {
        false
    }

    /// Whether it is a `twosided` wrapper (which `twosided` refuses to wrap again).
    fn is_twosided(&self) -> bool {
        false
    }

    /// `f(wi, wo) · |cos θo|` and the solid-angle density with which [`Bsdf::sample`] produces
    /// `wo`; both 0 for delta lobes and for directions a one-sided BSDF ignores.
    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32);

    /// Samples an outgoing direction. `u_lobe` (in `[0, 1)`) chooses between lobes, `u` (in
    /// `[0, 1)²`) the direction within the lobe. `None` means the path ends here (the back of a
    /// one-sided BSDF, or a sample below the horizon).
    fn sample(&self, at: &SurfacePoint, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample>;

    /// `f(wi, wo) · |cos θo|` alone.
    fn eval(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> Rgb {
        self.eval_pdf(at, wi, wo).0
    }

    /// The density alone.
    fn pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> f32 {
        self.eval_pdf(at, wi, wo).1
    }

    /// The surface's colour at `at`, textures evaluated: the *albedo* feature of NFOR-style
    /// denoisers, which divide it out so that texture detail is not blurred. Each plugin says
    /// what it returns; the rule is the colour a user painted the surface with, in `[0, 1]` for
    /// physical inputs and independent of directions (a feature must not be noisy where the
    /// surface is not). Mitsuba 3's AOV integrator returns the diffuse reflectance for
    /// `diffuse` and the plastics but π·f(n, n) elsewhere, which is unbounded for a smooth
    /// rough conductor; Tungsten returns each BSDF's base colour. We follow Tungsten's rule.
    fn albedo(&self, at: &SurfacePoint) -> Rgb;

    /// The normal NFOR's *normal* feature records, in the shading frame's coordinates, for a
    /// viewer in direction `wi`; `None` for the shading normal itself. A bump map returns its
    /// bumped normal, so that a denoiser guided by the feature keeps the bumps the colour
    /// shows (wrappers pass the question on to the BSDF they wrap).
    fn feature_normal(&self, _at: &SurfacePoint, _wi: Vec3) -> Option<Vec3> {
        None
    }
}

/// `v` with its `z` negated (mirror through the tangent plane).
#[inline]
pub fn flip_z(v: Vec3) -> Vec3 {
    Vec3::new(v.x, v.y, -v.z)
}

/// Mirror reflection of `wi` about the normal `+z`.
#[inline]
pub fn reflect_z(wi: Vec3) -> Vec3 {
    Vec3::new(-wi.x, -wi.y, wi.z)
}

/// The (`value`, `pdf`) of a direction a BSDF does not scatter into.
pub const NONE: (Rgb, f32) = (Rgb::ZERO, 0.0);
