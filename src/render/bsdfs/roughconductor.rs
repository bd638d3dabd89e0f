//! Mitsuba's `roughconductor`: the GGX microfacet model of Walter et al. 2007, "Microfacet
//! models for refraction through rough surfaces", front side only, with Smith's *separable*
//! shadowing–masking `G = G1(wi)·G1(wo)` (Mitsuba's choice).
//!
//! Sampling draws microfacet normals from the distribution of normals *visible* from `wi` (see
//! [`super::ggx`]); Mitsuba uses an older slope-space routine for the same density, so
//! expectations agree. The reflected direction's density is `D_wi(m) / (4 |wo·m|)` and the
//! sample weight simplifies to `F · G1(wo)`. Like Mitsuba, `alpha` is clamped below at `1e-4`.

use super::ggx::{Ggx, MIN_ALPHA};
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
    pub ggx: Ggx,
    /// Tint (Mitsuba's default 1).
    pub specular_reflectance: Spectrum,
}

impl RoughConductor {
    /// A GGX conductor of roughness `alpha` (clamped to at least [`MIN_ALPHA`]) and constant
    /// tint.
    pub fn new(alpha: f32, specular_reflectance: Rgb) -> RoughConductor {
        RoughConductor {
            // `max` also maps a NaN alpha to the bound.
            ggx: Ggx {
                alpha: alpha.max(MIN_ALPHA),
            },
            specular_reflectance: Spectrum::Constant(specular_reflectance),
        }
    }
}

/// Conductors model only Mitsuba's `material="none"`: complex indices are rejected.
pub(super) fn reject_complex_ior(p: &mut Params) -> Result<()> {
    for name in ["eta", "k"] {
        p.reject(
            name,
            "complex indices of refraction are not modelled; only material=\"none\" (a mirror \
             tinted by specular_reflectance)",
        )?;
    }
    Ok(())
}

/// A conductor's `material`, which may only be `none` (also Mitsuba 3's default).
pub(super) fn check_material(p: &Params, material: At<String>) -> Result<()> {
    match material {
        Some((name, at)) if name != "none" => Err(p.err(
            Some(at),
            format!(
                "material \"{}\" is not modelled; only \"none\" (a mirror tinted by \
                 specular_reflectance)",
                shorten(&name)
            ),
        )),
        _ => Ok(()),
    }
}

/// Reads `<bsdf type="roughconductor">`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    reject_complex_ior(p)?;
    for name in ["alpha_u", "alpha_v"] {
        p.reject(
            name,
            "anisotropic roughness is not modelled; use <float name=\"alpha\">",
        )?;
    }
    let distribution = p.string("distribution")?;
    let alpha = p.float("alpha")?;
    let material = p.string("material")?;
    let sample_visible = p.boolean("sample_visible")?;
    let tint = p.texture("specular_reflectance")?;
    p.finish()?;
    match distribution {
        None => {
            return Err(p.err(
                None,
                "missing <string name=\"distribution\" value=\"ggx\"/>: Mitsuba's default \
                 distribution is beckmann, which is not modelled; give ggx explicitly",
            ));
        }
        Some((d, at)) if d != "ggx" => {
            return Err(p.err(
                Some(at),
                format!(
                    "distribution \"{}\" is not modelled; only \"ggx\" is",
                    shorten(&d)
                ),
            ));
        }
        Some(_) => {}
    }
    if let Some((false, at)) = sample_visible {
        return Err(p.err(
            Some(at),
            "sample_visible = false is not modelled; only true (Mitsuba's default)",
        ));
    }
    check_material(p, material)?;
    let alpha_value = alpha.as_ref().map_or(0.1, |(a, _)| *a);
    if !(alpha_value > 0.0) {
        return Err(p.err(
            alpha.map(|(_, at)| at),
            format!(
                "alpha = {}: must be > 0 (use a conductor for a perfect mirror)",
                Num::from_f32(alpha_value)
            ),
        ));
    }
    Ok(Arc::new(RoughConductor {
        ggx: Ggx {
            alpha: alpha_value.max(MIN_ALPHA),
        },
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

    fn eval_pdf(&self, at: &SurfacePoint, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return NONE;
        }
        let ggx = self.ggx;
        // Both directions are above the horizon, so wi + wo has z > 0 and the half vector is
        // well defined; it also faces both (wi·m = wo·m > 0).
        let Some(m) = (wi + wo).try_normalize() else {
            return NONE;
        };
        let d = ggx.d(m);
        if d == 0.0 {
            return NONE;
        }
        // pdf = D_wi(m) / (4 wo·m) = G1(wi) (wi·m) D / (cos θi · 4 wo·m), with wi·m = wo·m.
        let pdf = d * ggx.g1_over_cos(wi) * 0.25;
        if !(pdf.is_finite() && pdf > 0.0) {
            return NONE;
        }
        // eval = F D G1(wi) G1(wo) / (4 cos θi) = pdf · F · G1(wo).
        let value = self.specular_reflectance.eval(at.uv) * (pdf * ggx.g1(wo, m));
        (value, pdf)
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, _u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let m = self.ggx.sample_visible(wi, u)?;
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
