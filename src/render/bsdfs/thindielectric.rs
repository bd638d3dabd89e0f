//! Mitsuba's `thindielectric`: a pane of glass so thin that it has no thickness — two parallel
//! smooth interfaces with every internal bounce summed in closed form, as Mitsuba 3.9.1 does.
//!
//! With `F` the Fresnel reflectance of one interface at `|cos θi|` (always evaluated from the
//! outside, relative index `int_ior / ext_ior`), the slab reflects the geometric series
//! `R = F + (1−F)² F (1 + F² + F⁴ + …) = F + (1−F)² F / (1 − F²) = 2F / (1 + F)` (Mitsuba's
//! `r *= 2 / (1 + r)`) and transmits `1 − R`, neglecting absorption. Transmission is straight
//! through (`wo = −wi`: the two refractions cancel), so no medium changes and the sample's `eta`
//! is 1 for both lobes. Mitsuba picks reflection with probability `R`, so the weights are just
//! the tints.
//!
//! Mitsuba classes the transmission as a *null* interaction (a delta lobe the path integrator
//! treats like any other bounce); its shadow rays, like ours, see the pane as opaque.

use super::fresnel::fresnel_dielectric;
use super::{Bsdf, BsdfSample, NONE, SurfacePoint, reflect_z};
use crate::error::Result;
use crate::render::mitsuba::Params;
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// A thin dielectric slab.
#[derive(Debug, Clone)]
pub struct ThinDielectric {
    /// `int_ior / ext_ior`.
    pub eta: f32,
    /// Reflection tint (Mitsuba's default 1).
    pub specular_reflectance: Spectrum,
    /// Transmission tint (Mitsuba's default 1).
    pub specular_transmittance: Spectrum,
}

impl ThinDielectric {
    /// An untinted pane of relative index `int_ior / ext_ior`.
    pub fn new(int_ior: f32, ext_ior: f32) -> ThinDielectric {
        ThinDielectric {
            eta: int_ior / ext_ior,
            specular_reflectance: Spectrum::grey(1.0),
            specular_transmittance: Spectrum::grey(1.0),
        }
    }

    /// The slab's total reflectance `R = 2F / (1 + F)` for `wi` on either side.
    pub fn reflectance(&self, wi: Vec3) -> f32 {
        let f = fresnel_dielectric(wi.z.abs(), self.eta).0;
        f * (2.0 / (1.0 + f))
    }
}

/// Reads `<bsdf type="thindielectric">`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let smooth = super::dielectric::read_smooth(p)?;
    Ok(Arc::new(ThinDielectric {
        eta: smooth.eta,
        specular_reflectance: smooth.specular_reflectance,
        specular_transmittance: smooth.specular_transmittance,
    }))
}

impl Bsdf for ThinDielectric {
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
        let f = self.reflectance(Vec3::Z);
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
        let r = self.reflectance(wi);
        if !(r >= 0.0) {
            return None;
        }
        // Reflection chosen with probability R (Mitsuba's `sample1 <= r`): weight R·tint / R.
        let (wo, weight) = if u_lobe <= r {
            (reflect_z(wi), self.specular_reflectance.eval(at.uv))
        } else {
            (-wi, self.specular_transmittance.eval(at.uv))
        };
        Some(BsdfSample {
            wo,
            weight,
            pdf: f32::INFINITY,
            delta: true,
            eta: 1.0,
        })
    }
}
