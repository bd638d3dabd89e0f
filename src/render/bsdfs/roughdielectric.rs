//! Mitsuba's `roughdielectric`: a rough interface between two dielectrics, the microfacet model
//! of Walter, Marschner, Li & Torrance 2007, "Microfacet models for refraction through rough
//! surfaces", with Mitsuba 3.9.1's choices, each of which changes the expected image:
//!
//! * Smith's *separable* shadowing–masking `G = G1(wi, m) G1(wo, m)` with Mitsuba's `G1` (for
//!   Beckmann its rational fit, see [`super::microfacet`]).
//! * Radiance transport: transmitted values carry `(η_i/η_t)²` (Mitsuba's "missing term" of the
//!   paper: radiance is compressed into the smaller solid angle of the denser side).
//! * Both sides scatter. Seen from inside (`wi.z < 0`) the relative index is `1/η`, and Mitsuba
//!   evaluates the sampling density with `wi` mirrored to the front (`−wi`), the microfacet
//!   normal always on the front hemisphere.
//!
//! # Formulas (directions in the local frame, `η` the relative index across from `wi`'s side)
//!
//! The half vector is `m = ±normalize(wi + wo)` for reflection (`wi.z wo.z > 0`) and Walter's
//! generalised `m = ±normalize(wi + η wo)` for transmission, its sign chosen so that `m.z ≥ 0`;
//! pairs where either direction sees the back of `m` (`(v·m) v.z ≤ 0`) are dropped. With `F` the
//! Fresnel reflectance at `wi·m`:
//!
//! * reflection: `f·|cos θo| = F D G / (4 |cos θi|)`, Jacobian `dm/dwo = 1 / (4 |wo·m|)`;
//! * transmission: `f·|cos θo| = (1/η²) (1 − F) D G η² |wi·m| |wo·m| / (|cos θi| (wi·m + η wo·m)²)`,
//!   Jacobian `dm/dwo = η² |wo·m| / (wi·m + η wo·m)²`.
//!
//! Sampling draws `m` from the normals visible from `±wi` (Mitsuba's default
//! `sample_visible = true`), reflects with probability `F(wi·m)` and refracts otherwise, so the
//! density is `D_vis(m) · (F or 1 − F) · dm/dwo`.
//!
//! # Mitsuba's estimator, including for Beckmann
//!
//! The reported density uses Mitsuba's `D_vis` ([`Microfacet::pdf_visible_mitsuba`]), whose
//! Beckmann `G1(wi)` is the fit, and the weight is `eval / pdf` = tint · (`1/η²` on
//! transmission) · `G1(wo, m)`: exactly Mitsuba's weight. For GGX this is the true density of the
//! sampler. For Beckmann our sampler (like Mitsuba's) draws from the exact visible-normal
//! density, so the reported pdf is the true one times `G1_exact(wi) / G1_fit(wi)` (within 0.35%
//! of 1, constant for a given `wi`), and BSDF-sampled estimates carry that factor relative to
//! `eval` — as Mitsuba's do. This keeps the image Mitsuba's in expectation.
//!
//! Not modelled (rejected by the loader): anisotropic `alpha_u`/`alpha_v` (Mitsuba aligns them
//! with the uv parameterisation, which our shading frame does not follow), textured `alpha`,
//! and `sample_visible = false` (there Mitsuba samples a widened distribution, and as we read its
//! source its sample weight omits the ratio of the two `D`s, so it is not its own `eval / pdf`).

use super::dielectric::{DEFAULT_EXT_IOR, DEFAULT_INT_IOR};
use super::fresnel::fresnel_dielectric;
use super::microfacet::Microfacet;
use super::roughconductor::{read_distribution, require_visible_sampling};
use super::{Bsdf, BsdfSample, NONE, SurfacePoint};
use crate::error::{Num, Result};
use crate::render::mitsuba::Params;
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A rough dielectric interface.
#[derive(Debug, Clone)]
pub struct RoughDielectric {
    /// The microfacet distribution (isotropic when loaded from a scene).
    pub microfacet: Microfacet,
    /// `int_ior / ext_ior` (the relative index seen from the front).
    pub eta: f32,
    /// Reflection tint (Mitsuba's default 1).
    pub specular_reflectance: Spectrum,
    /// Transmission tint (Mitsuba's default 1).
    pub specular_transmittance: Spectrum,
}

impl RoughDielectric {
    /// Untinted rough glass with the given distribution and indices.
    pub fn new(microfacet: Microfacet, int_ior: f32, ext_ior: f32) -> RoughDielectric {
        RoughDielectric {
            microfacet,
            eta: int_ior / ext_ior,
            specular_reflectance: Spectrum::grey(1.0),
            specular_transmittance: Spectrum::grey(1.0),
        }
    }
}

/// Reads `<bsdf type="roughdielectric">`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let int_ior = p.ior("int_ior")?;
    let ext_ior = p.ior("ext_ior")?;
    let (microfacet, sample_visible) = read_distribution(p)?;
    let reflect = p.texture("specular_reflectance")?;
    let transmit = p.texture("specular_transmittance")?;
    p.finish()?;
    require_visible_sampling(p, sample_visible)?;

    let int_value = int_ior.as_ref().map_or(DEFAULT_INT_IOR, |(v, _)| *v);
    let ext_value = ext_ior.as_ref().map_or(DEFAULT_EXT_IOR, |(v, _)| *v);
    if int_value == ext_value {
        let at = int_ior.or(ext_ior).map(|(_, at)| at);
        return Err(p.err(
            at,
            format!(
                "int_ior = ext_ior = {}: the indices of refraction must differ (as Mitsuba \
                 requires); an index-matched interface scatters nothing",
                Num::from_f32(int_value)
            ),
        ));
    }
    Ok(Arc::new(RoughDielectric {
        microfacet,
        eta: int_value / ext_value,
        specular_reflectance: reflect.map_or(Spectrum::grey(1.0), |(t, _)| t),
        specular_transmittance: transmit.map_or(Spectrum::grey(1.0), |(t, _)| t),
    }))
}

impl RoughDielectric {
    /// `eta` and its reciprocal as seen from `wi`'s side (`cos_theta_i` ≠ 0).
    #[inline]
    fn eta_from(&self, cos_theta_i: f32) -> (f32, f32) {
        let inv = 1.0 / self.eta;
        if cos_theta_i > 0.0 {
            (self.eta, inv)
        } else {
            (inv, self.eta)
        }
    }
}

impl Bsdf for RoughDielectric {
    fn has_smooth_lobe(&self) -> bool {
        true
    }

    fn uses_uv(&self) -> bool {
        self.specular_reflectance.is_textured() || self.specular_transmittance.is_textured()
    }

    /// `F · specular_reflectance + (1 − F) · specular_transmittance` with `F` the interface's
    /// reflectance at normal incidence: the share of light it sends on, reflected or
    /// transmitted (1 for clear glass), without the radiance scaling of refraction.
    fn albedo(&self, at: &SurfacePoint) -> Rgb {
        let f = fresnel_dielectric(1.0, self.eta).0;
        self.specular_reflectance.eval(at.uv) * f
            + self.specular_transmittance.eval(at.uv) * (1.0 - f)
    }

    fn transmits(&self) -> bool {
        true
    }

    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        let (cos_i, cos_o) = (wi.z, wo.z);
        // Perfectly grazing wi (and NaN) scatter nothing, as in Mitsuba.
        if !(cos_i != 0.0) {
            return NONE;
        }
        let reflect = cos_i * cos_o > 0.0;
        let (eta, inv_eta) = self.eta_from(cos_i);
        let Some(m) = (wi + wo * if reflect { 1.0 } else { eta }).try_normalize() else {
            return NONE;
        };
        // The half vector on the front hemisphere (Mitsuba's `mulsign`: −0 counts as negative).
        let m = if m.z.is_sign_negative() { -m } else { m };
        let (dot_wi_m, dot_wo_m) = (wi.dot(m), wo.dot(m));
        // Both directions must see the side of m their macro-side sees (what G1 tests too).
        if !(dot_wi_m * cos_i > 0.0 && dot_wo_m * cos_o > 0.0) {
            return NONE;
        }
        let mf = &self.microfacet;
        let d = mf.d(m);
        if d == 0.0 {
            return NONE;
        }
        let f = fresnel_dielectric(dot_wi_m, self.eta).0;
        let g = mf.g(wi, wo, m);
        // Mitsuba's density of visible normals, seen from wi mirrored to the front.
        let pdf_m = mf.pdf_visible_mitsuba(if cos_i < 0.0 { -wi } else { wi }, m);
        let (value, pdf) = if reflect {
            let value = self.specular_reflectance.eval(at.uv) * (f * d * g / (4.0 * cos_i.abs()));
            (value, pdf_m * f * (1.0 / (4.0 * dot_wo_m)).abs())
        } else {
            let denom = dot_wi_m + eta * dot_wo_m;
            let denom2 = denom * denom;
            let scale = inv_eta * inv_eta;
            let t = ((scale * (1.0 - f) * d * g * eta * eta * dot_wi_m * dot_wo_m)
                / (cos_i * denom2))
                .abs();
            let value = self.specular_transmittance.eval(at.uv) * t;
            (
                value,
                pdf_m * (1.0 - f) * (eta * eta * dot_wo_m / denom2).abs(),
            )
        };
        if !(pdf.is_finite() && pdf > 0.0 && value.is_finite()) {
            return NONE;
        }
        (value, pdf)
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let cos_i = wi.z;
        if !(cos_i != 0.0) {
            return None;
        }
        let m = self
            .microfacet
            .sample_visible(if cos_i < 0.0 { -wi } else { wi }, u)?;
        let dot_wi_m = wi.dot(m);
        let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(dot_wi_m, self.eta);
        // Reflection with probability F of the sampled facet (Mitsuba's `sample1 <= F`).
        let reflect = u_lobe <= f;
        let wo = if reflect {
            2.0 * dot_wi_m * m - wi
        } else {
            m * (dot_wi_m * eta_ti + cos_t) - wi * eta_ti
        };
        let wo = wo.try_normalize()?;
        // Mitsuba's weight carries G1(wo, m), zero when wo leaves on the wrong side of the
        // macro-surface for its lobe (the energy lost by the separable model); and a direction
        // rounded onto the other lobe's side must not be evaluated as that lobe.
        let same_side = wo.z * cos_i > 0.0;
        if same_side != reflect || self.microfacet.g1(wo, m) == 0.0 {
            return None;
        }
        // Value and density at the half vector of the rounded `wo`, so that
        // `pdf == self.pdf(wi, wo)` and `weight == eval / pdf` hold exactly (they equal
        // Mitsuba's G1(wo, m)-based weight in exact arithmetic).
        let (value, pdf) = self.eval_pdf(at, wi, wo);
        let weight = value / pdf;
        if !(pdf.is_finite() && pdf > 0.0 && weight.is_finite()) {
            return None;
        }
        Some(BsdfSample {
            wo,
            weight,
            pdf,
            delta: false,
            eta: if reflect { 1.0 } else { eta_it },
        })
    }
}
