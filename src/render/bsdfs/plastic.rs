//! Mitsuba's `plastic`: a diffuse base under a smooth dielectric coating, front side only
//! (Weidlich & Wilkie 2007, "Arbitrarily layered micro-facet surfaces", in the simplified form
//! of Mitsuba's `plastic` plugin).
//!
//! Two lobes:
//!
//! * a **delta mirror** lobe of weight `F(cos θi)` (Fresnel of the coating) times
//!   `specular_reflectance`;
//! * a **diffuse** lobe `ρ / (1 − F_dr) · (1/η²) · (1 − F(cos θi)) (1 − F(cos θo)) · cos θo / π`,
//!   where `ρ` is `diffuse_reflectance`, `F_dr = fresnel_diffuse_reflectance(1/η)` is the
//!   fraction of diffuse light the coating sends back down (accounting for all internal
//!   bounces as a geometric series), and `1/η²` is the radiance compression of entering and
//!   leaving the denser coating. With `nonlinear = true` the series also multiplies by `ρ` at
//!   each bounce: `ρ / (1 − ρ F_dr)`, which darkens and saturates the colour.
//!
//! Lobe selection follows Mitsuba: the specular lobe is chosen with probability
//! `p = F_i w / (F_i w + (1 − F_i)(1 − w))`, with the "specular sampling weight"
//! `w = s̄ / (d̄ + s̄)` from the means of the two reflectances (`s̄ = 1` when
//! `specular_reflectance` is not given). The diffuse lobe's pdf is `(1 − p) cos θo / π` — also
//! what [`Bsdf::eval_pdf`] reports, since no finite direction reaches the mirror lobe.
//!
//! Mitsuba reports the specular sample's `pdf` as `p`; we report `f32::INFINITY` (see the module
//! documentation of [`super`]) and fold `p` into the weight `F_i / p · specular_reflectance`.

use super::fresnel::{fresnel_dielectric, fresnel_diffuse_reflectance};
use super::{Bsdf, BsdfSample, NONE, SurfacePoint, reflect_z};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::sampling::square_to_cosine_hemisphere;
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

/// Mitsuba's default interior index for both plastics (`polypropylene`).
pub const DEFAULT_INT_IOR: f32 = 1.49;
/// Mitsuba's default exterior index (`air`).
pub const DEFAULT_EXT_IOR: f32 = 1.000277;

/// A smooth plastic.
#[derive(Debug, Clone)]
pub struct Plastic {
    /// `int_ior / ext_ior`.
    eta: f32,
    /// `1 / η²`.
    inv_eta2: f32,
    /// `F_dr(1/η)`: diffuse reflectance of the coating seen from inside.
    fdr_int: f32,
    /// Base colour (Mitsuba's default 0.5).
    diffuse_reflectance: Spectrum,
    /// Mirror tint (Mitsuba's default 1).
    specular_reflectance: Spectrum,
    /// `s̄ / (d̄ + s̄)`.
    specular_sampling_weight: f32,
    /// Mitsuba's `nonlinear`.
    nonlinear: bool,
}

/// Mitsuba's `s̄ / (d̄ + s̄)`, the prior weight of the specular lobe in lobe selection. A black
/// BSDF (both means 0, where Mitsuba divides 0 by 0) gets 1/2: it only changes how a zero is
/// sampled.
pub(super) fn specular_sampling_weight(diffuse: &Spectrum, specular: &Spectrum) -> f32 {
    let (d, s) = (diffuse.mean(), specular.mean());
    if d + s > 0.0 { s / (d + s) } else { 0.5 }
}

/// `ρ / (1 − F_int)`, or `ρ / (1 − ρ F_int)` when `nonlinear`: the diffuse base seen through
/// the coating after all internal bounces.
#[inline]
pub(super) fn internal_scattering(rho: Rgb, f_int: f32, nonlinear: bool) -> Rgb {
    if nonlinear {
        rho / (Rgb::ONE - rho * f_int)
    } else {
        rho / (1.0 - f_int)
    }
}

impl Plastic {
    /// A plastic of relative index `eta` (`int_ior / ext_ior`, > 0) with the given reflectances
    /// (`specular_reflectance` as Mitsuba's default 1 when `None`).
    pub fn new(
        eta: f32,
        diffuse_reflectance: Spectrum,
        specular_reflectance: Option<Spectrum>,
        nonlinear: bool,
    ) -> Plastic {
        let specular_reflectance = specular_reflectance.unwrap_or(Spectrum::grey(1.0));
        Plastic {
            eta,
            inv_eta2: 1.0 / (eta * eta),
            fdr_int: fresnel_diffuse_reflectance(1.0 / eta),
            specular_sampling_weight: specular_sampling_weight(
                &diffuse_reflectance,
                &specular_reflectance,
            ),
            diffuse_reflectance,
            specular_reflectance,
            nonlinear,
        }
    }

    /// Probability of choosing the specular lobe when the coating reflects `f_i`.
    #[inline]
    fn prob_specular(&self, f_i: f32) -> f32 {
        let w = self.specular_sampling_weight;
        let s = f_i * w;
        let d = (1.0 - f_i) * (1.0 - w);
        if s + d > 0.0 { s / (s + d) } else { 0.0 }
    }

    /// The diffuse lobe without its `cos θo / π` factor.
    #[inline]
    fn diffuse_term(&self, at: &SurfacePoint, f_i: f32, cos_o: f32) -> Rgb {
        let f_o = fresnel_dielectric(cos_o, self.eta).0;
        let rho = self.diffuse_reflectance.eval(at.uv);
        internal_scattering(rho, self.fdr_int, self.nonlinear)
            * (self.inv_eta2 * (1.0 - f_i) * (1.0 - f_o))
    }
}

/// Reads `<bsdf type="plastic">`: `int_ior`, `ext_ior` (numbers or Mitsuba's names; defaults
/// polypropylene and air), `diffuse_reflectance` (default 0.5), `specular_reflectance` (default
/// 1), `nonlinear` (default false).
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let int_ior = p.ior("int_ior")?;
    let ext_ior = p.ior("ext_ior")?;
    let diffuse = p.texture("diffuse_reflectance")?;
    let specular = p.texture("specular_reflectance")?;
    let nonlinear = p.boolean("nonlinear")?;
    p.finish()?;
    let int_ior = int_ior.map_or(DEFAULT_INT_IOR, |(v, _)| v);
    let ext_ior = ext_ior.map_or(DEFAULT_EXT_IOR, |(v, _)| v);
    Ok(Arc::new(Plastic::new(
        int_ior / ext_ior,
        diffuse.map_or(Spectrum::grey(0.5), |(d, _)| d),
        specular.map(|(s, _)| s),
        nonlinear.is_some_and(|(b, _)| b),
    )))
}

impl Bsdf for Plastic {
    fn has_smooth_lobe(&self) -> bool {
        true
    }

    fn uses_uv(&self) -> bool {
        self.diffuse_reflectance.is_textured() || self.specular_reflectance.is_textured()
    }

    /// `diffuse_reflectance`, the base colour: the coating is colourless unless
    /// `specular_reflectance` tints it, and its highlight depends on directions (Mitsuba's AOV
    /// integrator and Tungsten both take the diffuse colour).
    fn albedo(&self, at: &SurfacePoint) -> Rgb {
        self.diffuse_reflectance.eval(at.uv)
    }

    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return NONE;
        }
        let f_i = fresnel_dielectric(wi.z, self.eta).0;
        let cos_pdf = wo.z * FRAC_1_PI;
        let value = self.diffuse_term(at, f_i, wo.z) * cos_pdf;
        (value, (1.0 - self.prob_specular(f_i)) * cos_pdf)
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let f_i = fresnel_dielectric(wi.z, self.eta).0;
        let p_spec = self.prob_specular(f_i);
        if u_lobe < p_spec {
            return Some(BsdfSample {
                wo: reflect_z(wi),
                weight: self.specular_reflectance.eval(at.uv) * (f_i / p_spec),
                pdf: f32::INFINITY,
                delta: true,
                eta: 1.0,
            });
        }
        let p_diff = 1.0 - p_spec;
        let wo = square_to_cosine_hemisphere(u);
        let pdf = p_diff * wo.z * FRAC_1_PI;
        if !(pdf > 0.0) {
            return None;
        }
        // eval / pdf: the cos θo / π factors cancel.
        let weight = self.diffuse_term(at, f_i, wo.z) / p_diff;
        weight.is_finite().then_some(BsdfSample {
            wo,
            weight,
            pdf,
            delta: false,
            eta: 1.0,
        })
    }
}
