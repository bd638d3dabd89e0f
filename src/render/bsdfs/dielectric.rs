//! Mitsuba's `dielectric`: a smooth glass interface, two-sided by nature. Exact unpolarised
//! Fresnel; reflection is chosen with probability `F`; the transmission weight is scaled by
//! `(1/η_it)²` (radiance transport: radiance is compressed into the smaller solid angle of the
//! denser medium), as in Mitsuba's radiance mode.

use super::fresnel::fresnel_dielectric;
use super::{Bsdf, BsdfSample, NONE, SurfacePoint, reflect_z};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// Mitsuba's default interior index (`bk7`).
pub const DEFAULT_INT_IOR: f32 = 1.5046;
/// Mitsuba's default exterior index (`air`).
pub const DEFAULT_EXT_IOR: f32 = 1.000277;

/// A smooth dielectric interface.
#[derive(Debug, Clone)]
pub struct Dielectric {
    /// `int_ior / ext_ior`.
    pub eta: f32,
    /// Reflection tint (Mitsuba's default 1).
    pub specular_reflectance: Spectrum,
    /// Transmission tint (Mitsuba's default 1).
    pub specular_transmittance: Spectrum,
}

impl Dielectric {
    /// Untinted glass of relative index `int_ior / ext_ior`.
    pub fn new(int_ior: f32, ext_ior: f32) -> Dielectric {
        Dielectric {
            eta: int_ior / ext_ior,
            specular_reflectance: Spectrum::grey(1.0),
            specular_transmittance: Spectrum::grey(1.0),
        }
    }
}

/// Reads what a smooth interface takes (`dielectric`, `thindielectric`): `int_ior`, `ext_ior`
/// (numbers or Mitsuba's names; defaults bk7 and air), `specular_reflectance`,
/// `specular_transmittance` (default 1).
pub(super) fn read_smooth(p: &mut Params) -> Result<Dielectric> {
    let int_ior = p.ior("int_ior")?;
    let ext_ior = p.ior("ext_ior")?;
    let reflect = p.texture("specular_reflectance")?;
    let transmit = p.texture("specular_transmittance")?;
    p.finish()?;
    let int_ior = int_ior.map_or(DEFAULT_INT_IOR, |(v, _)| v);
    let ext_ior = ext_ior.map_or(DEFAULT_EXT_IOR, |(v, _)| v);
    Ok(Dielectric {
        eta: int_ior / ext_ior,
        specular_reflectance: reflect.map_or(Spectrum::grey(1.0), |(t, _)| t),
        specular_transmittance: transmit.map_or(Spectrum::grey(1.0), |(t, _)| t),
    })
}

/// Reads `<bsdf type="dielectric">`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    Ok(Arc::new(read_smooth(p)?))
}

impl Bsdf for Dielectric {
    fn has_smooth_lobe(&self) -> bool {
        false
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

    fn eval_pdf(&self, _at: &SurfacePoint, _wi: Vec3, _wo: Vec3) -> (Rgb, f32) {
        NONE
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, u_lobe: f32, _u: Vec2) -> Option<BsdfSample> {
        let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.z, self.eta);
        if u_lobe < f {
            // Reflection chosen with probability F: weight F·tint / F.
            Some(BsdfSample {
                wo: reflect_z(wi),
                weight: self.specular_reflectance.eval(at.uv),
                pdf: f32::INFINITY,
                delta: true,
                eta: 1.0,
            })
        } else {
            // Transmission chosen with probability 1 − F; radiance scales by η_ti².
            let wo = Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
            Some(BsdfSample {
                wo: wo.try_normalize().unwrap_or(wo),
                weight: self.specular_transmittance.eval(at.uv) * (eta_ti * eta_ti),
                pdf: f32::INFINITY,
                delta: true,
                eta: eta_it,
            })
        }
    }
}
