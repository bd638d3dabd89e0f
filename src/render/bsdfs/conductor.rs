//! Mitsuba's `conductor`: a smooth metal, front side only, reflecting with the conductor
//! Fresnel factor of its complex index of refraction `eta + i k` times `specular_reflectance`.
//!
//! The index comes from `eta`/`k` (Mitsuba's defaults 0 and 1) or from a named `material`
//! (Mitsuba's spectral presets, as its RGB variants convert them: [`super::ior`]); not both.
//! `material="none"` (the default) is `0 + 1i`, whose reflectance is exactly 1 at every angle.

use super::fresnel::fresnel_conductor;
use super::ior::{conductor_names, conductor_preset};
use super::{Bsdf, BsdfSample, NONE, SurfacePoint, reflect_z};
use crate::error::Result;
use crate::limits::shorten;
use crate::render::mitsuba::Params;
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A conductor's complex index of refraction, per colour channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ComplexIor {
    /// `material="none"` (`0 + 1i`): reflectance exactly 1, no Fresnel evaluation needed.
    Perfect,
    /// `eta + i k`.
    Rgb {
        /// Real part.
        eta: Vec3,
        /// Imaginary part (extinction).
        k: Vec3,
    },
}

impl ComplexIor {
    /// The Fresnel reflectance at `cos_theta_i`.
    #[inline]
    pub fn fresnel(self, cos_theta_i: f32) -> Rgb {
        match self {
            ComplexIor::Perfect => Rgb::ONE,
            ComplexIor::Rgb { eta, k } => fresnel_conductor(cos_theta_i, eta, k),
        }
    }
}

/// Reads `eta`, `k` and `material` as Mitsuba's conductors do.
pub(super) fn read_complex_ior(p: &mut Params) -> Result<ComplexIor> {
    let eta = p.spectrum("eta")?;
    let k = p.spectrum("k")?;
    let material = p.string("material")?;
    match material {
        Some((name, at)) if name != "none" => {
            if let Some((_, given)) = eta.or(k) {
                return Err(p.err(
                    Some(given),
                    "give either eta and k or a material, not both (as Mitsuba requires)",
                ));
            }
            let (eta, k) = conductor_preset(&name).ok_or_else(|| {
                p.err(
                    Some(at),
                    format!(
                        "unknown conductor material \"{}\"; Mitsuba's presets: {}",
                        shorten(&name),
                        conductor_names()
                    ),
                )
            })?;
            Ok(ComplexIor::Rgb { eta, k })
        }
        _ if eta.is_none() && k.is_none() => Ok(ComplexIor::Perfect),
        _ => Ok(ComplexIor::Rgb {
            eta: eta.map_or(Vec3::ZERO, |(e, _)| e),
            k: k.map_or(Vec3::ONE, |(k, _)| k),
        }),
    }
}

/// A smooth conductor.
#[derive(Debug, Clone)]
pub struct Conductor {
    /// Complex index of refraction.
    pub ior: ComplexIor,
    /// Tint (Mitsuba's default 1).
    pub specular_reflectance: Spectrum,
}

impl Conductor {
    /// A perfect mirror (`material="none"`) of constant tint.
    pub fn mirror(tint: Rgb) -> Conductor {
        Conductor {
            ior: ComplexIor::Perfect,
            specular_reflectance: Spectrum::Constant(tint),
        }
    }
}

/// Reads `<bsdf type="conductor">`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let ior = read_complex_ior(p)?;
    let tint = p.texture("specular_reflectance")?;
    p.finish()?;
    Ok(Arc::new(Conductor {
        ior,
        specular_reflectance: tint.map_or(Spectrum::grey(1.0), |(t, _)| t),
    }))
}

impl Bsdf for Conductor {
    fn has_smooth_lobe(&self) -> bool {
        false
    }

    fn uses_uv(&self) -> bool {
        self.specular_reflectance.is_textured()
    }

    /// The reflectance at normal incidence, `F(1) · specular_reflectance`: the metal's own
    /// colour (gold is yellow), bounded by 1, and the same from every direction.
    fn albedo(&self, at: &SurfacePoint) -> Rgb {
        self.ior.fresnel(1.0) * self.specular_reflectance.eval(at.uv)
    }

    fn eval_pdf(&self, _at: &SurfacePoint, _wi: Vec3, _wo: Vec3) -> (Rgb, f32) {
        NONE
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, _u_lobe: f32, _u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wo: reflect_z(wi),
            weight: self.specular_reflectance.eval(at.uv) * self.ior.fresnel(wi.z),
            pdf: f32::INFINITY,
            delta: true,
            eta: 1.0,
        })
    }
}
