//! Mitsuba's `roughconductor`: the microfacet model of Walter et al. 2007, "Microfacet models
//! for refraction through rough surfaces", front side only, with Smith's *separable*
//! shadowing–masking `G = G1(wi)·G1(wo)` (Mitsuba's choice), GGX or Beckmann, and the conductor
//! Fresnel factor of [`super::conductor`].
//!
//! Sampling draws microfacet normals from the distribution of normals *visible* from `wi`
//! ([`super::microfacet`]). The reported density is Mitsuba's formula,
//! `D(m) G1(wi, m) (wi·m) / (cos θi · 4 wo·m)`, so that the weight `eval / pdf = F · G1(wo)` is
//! Mitsuba's weight. For GGX that is the sampler's exact density; for Beckmann Mitsuba's `G1` is
//! a rational fit, and the two differ by under 0.35% — a difference Mitsuba itself has, which we
//! keep so that both renderers estimate the same thing. Like Mitsuba, `alpha` is clamped below
//! at `1e-4`.

use super::conductor::{ComplexIor, read_complex_ior};
use super::microfacet::{DEFAULT_ALPHA, Distribution, Microfacet};
use super::{Bsdf, BsdfSample, NONE, SurfacePoint};
use crate::error::{Num, Result};
use crate::limits::shorten;
use crate::render::mitsuba::{At, Params};
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A rough conductor.
#[derive(Debug, Clone)]
pub struct RoughConductor {
    /// The microfacet distribution.
    pub distribution: Microfacet,
    /// Complex index of refraction.
    pub ior: ComplexIor,
    /// Tint (Mitsuba's default 1).
    pub specular_reflectance: Spectrum,
}

impl RoughConductor {
    /// A GGX mirror (`material="none"`) of roughness `alpha` (clamped to at least 1e-4) and
    /// constant tint.
    pub fn new(alpha: f32, specular_reflectance: Rgb) -> RoughConductor {
        RoughConductor {
            distribution: Microfacet::isotropic(Distribution::Ggx, alpha),
            ior: ComplexIor::Perfect,
            specular_reflectance: Spectrum::Constant(specular_reflectance),
        }
    }
}

/// Reads an isotropic microfacet distribution as Mitsuba's rough BSDFs do: `distribution`
/// (`beckmann`, Mitsuba's default, or `ggx`), `alpha` (default 0.1, > 0), and returns
/// `sample_visible` as given (each plugin decides what it supports). Anisotropic roughness is
/// refused: it needs Mitsuba's tangent frame (from `dp/du`), which the renderer does not model.
pub(super) fn read_distribution<'a, 'i>(
    p: &mut Params<'_, 'a, 'i>,
) -> Result<(Microfacet, At<'a, 'i, bool>)> {
    for name in ["alpha_u", "alpha_v"] {
        p.reject(
            name,
            "anisotropic roughness is not modelled; use <float name=\"alpha\">",
        )?;
    }
    let distribution = p.string("distribution")?;
    let alpha = p.float("alpha")?;
    let sample_visible = p.boolean("sample_visible")?;
    let kind = match distribution {
        None => Distribution::Beckmann,
        Some((d, at)) => Distribution::from_name(&d).ok_or_else(|| {
            p.err(
                Some(at),
                format!("distribution \"{}\": must be beckmann or ggx", shorten(&d)),
            )
        })?,
    };
    let alpha_value = alpha.as_ref().map_or(DEFAULT_ALPHA, |(a, _)| *a);
    if !(alpha_value > 0.0) {
        return Err(p.err(
            alpha.map(|(_, at)| at),
            format!(
                "alpha = {}: must be > 0 (use the smooth plugin for a perfectly smooth surface)",
                Num::from_f32(alpha_value)
            ),
        ));
    }
    Ok((Microfacet::isotropic(kind, alpha_value), sample_visible))
}

/// Refuses `sample_visible = false` where only Mitsuba's default is modelled.
pub(super) fn require_visible_sampling(p: &Params, sample_visible: At<bool>) -> Result<()> {
    match sample_visible {
        Some((false, at)) => Err(p.err(
            Some(at),
            "sample_visible = false is not modelled; only true (Mitsuba's default)",
        )),
        _ => Ok(()),
    }
}

/// Reads `<bsdf type="roughconductor">`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let ior = read_complex_ior(p)?;
    let (distribution, sample_visible) = read_distribution(p)?;
    let tint = p.texture("specular_reflectance")?;
    p.finish()?;
    require_visible_sampling(p, sample_visible)?;
    Ok(Arc::new(RoughConductor {
        distribution,
        ior,
        specular_reflectance: tint.map_or(Spectrum::grey(1.0), |(t, _)| t),
    }))
}

impl Bsdf for RoughConductor {
    fn has_smooth_lobe(&self) -> bool {
        true
    }

    fn uses_uv(&self) -> bool {
        self.specular_reflectance.is_textured()
    }

    /// The reflectance at normal incidence, `F(1) · specular_reflectance`: the metal's own
    /// colour (gold is yellow), bounded by 1, and the same from every direction.
    fn albedo(&self, at: &SurfacePoint) -> Rgb {
        self.ior.fresnel(1.0) * self.specular_reflectance.eval(at.uv)
    }

    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return NONE;
        }
        let md = &self.distribution;
        // Both directions are above the horizon, so wi + wo has z > 0 and the half vector is
        // well defined; it also faces both (wi·m = wo·m > 0).
        let Some(m) = (wi + wo).try_normalize() else {
            return NONE;
        };
        let d = md.d(m);
        if d == 0.0 {
            return NONE;
        }
        // pdf = D G1(wi) (wi·m) / (cos θi · 4 wo·m) = D G1(wi) / (4 cos θi), with wi·m = wo·m.
        let g1_wi = md.g1(wi, m);
        let pdf = d * g1_wi / (4.0 * wi.z);
        if !(pdf.is_finite() && pdf > 0.0) {
            return NONE;
        }
        // eval = F D G1(wi) G1(wo) / (4 cos θi) = pdf · F · G1(wo).
        let f = self.ior.fresnel(wi.dot(m));
        let value = self.specular_reflectance.eval(at.uv) * f * (pdf * md.g1(wo, m));
        (value, pdf)
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, _u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let m = self.distribution.sample_visible(wi, u)?;
        let cos_im = wi.dot(m);
        if cos_im <= 0.0 {
            return None;
        }
        let wo = (2.0 * cos_im * m - wi).try_normalize()?;
        if wo.z <= 0.0 {
            // Reflected below the macro-surface: the lost energy of the separable model.
            return None;
        }
        // Density and weight evaluated at the half vector of the rounded `wo` rather than at
        // `m`: identical in exact arithmetic, and this way `pdf == self.pdf(wi, wo)` and
        // `weight == eval / pdf` hold to the last bit (near grazing `wi` the half vector is
        // ill-conditioned, and a narrow lobe turns its rounding into a visible density
        // mismatch).
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
            eta: 1.0,
        })
    }
}
