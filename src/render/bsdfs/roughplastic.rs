//! Mitsuba's `roughplastic`: a diffuse base under a *rough* dielectric coating, front side only
//! (the rough counterpart of [`super::plastic`], after Weidlich & Wilkie 2007 and Walter et al.
//! 2007, "Microfacet models for refraction through rough surfaces").
//!
//! Two lobes, both smooth:
//!
//! * **specular**: the microfacet reflection of the coating,
//!   `F(wi·h) D(h) G1(wi, h) G1(wo, h) / (4 cos θi)` times `specular_reflectance`, with
//!   `h = normalize(wi + wo)`, Mitsuba's `D` and `G1` (see [`super::microfacet`]) and the
//!   coating's Fresnel `F` of relative index `η = int_ior / ext_ior`;
//! * **diffuse**: `ρ / (1 − R) · (1/η²) · T(cos θi) T(cos θo) · cos θo / π` (or `ρ / (1 − ρ R)`
//!   with `nonlinear`), where `T(μ)` is the fraction of light arriving at cosine `μ` that the
//!   rough coating transmits (energy through all facets, shadowing included) and `R` the
//!   coating's cosine-weighted internal reflectance.
//!
//! # Mitsuba's tables, rebuilt at load
//!
//! `T` and `R` have no closed form; Mitsuba tabulates them once per material, and so do we, with
//! the same recipe so that the diffuse lobe equals Mitsuba's to rounding (a different but more
//! exact integration would shift expectations by up to a percent at grazing angles):
//!
//! * 64 cosines `μ_i = max(10⁻⁶, i/63)`, each with `wi = (√(1 − μ²), 0, μ)`;
//! * for each, a tensor Gauss–Legendre rule on `[0, 1]²` — 32×32 nodes when the relative index
//!   of the integral exceeds 1, else 128×128 — whose nodes are fed through the visible-normal
//!   sampler, so each node is a visible microfacet normal `m` with weight `w = w_x w_y / 4`:
//!   `T(μ) = Σ G1(wt, m) (1 − F(wi·m, η)) w`, `wt` the refraction of `wi` through `m` (terms where
//!   `wt` does not cross the surface are 0), and
//!   `R(μ) = Σ G1(wr, m) F(wi·m, 1/η) w` for the reflection `wr` from inside (0 below the
//!   horizon);
//! * `R = 2 · mean_i(R(μ_i) μ_i)` — a plain mean over the 64 cosines, as Mitsuba takes it;
//! * lookups interpolate linearly at `x = 63 μ` between entries `⌊x⌋` and `⌊x⌋ + 1` (with
//!   `⌊x⌋ ≤ 62`).
//!
//! Mitsuba 3.9.1 feeds the nodes through its own visible-normal warps; ours give the same normal
//! for GGX and one within 10⁻⁵ for Beckmann (see [`super::microfacet`]), far below what the
//! rule's own error leaves visible.
//!
//! # Sampling
//!
//! As Mitsuba: the specular lobe is chosen with probability `p ∝ (1 − T(cos θi)) w` against
//! `(1 − p) ∝ T(cos θi)(1 − w)`, with `w = s̄ / (d̄ + s̄)` from the reflectances' means; then a
//! visible normal is reflected, or a cosine-weighted direction drawn. The reported density is
//! the mixture `p D(h) G1(wi, h) / (4 cos θi) + (1 − p) cos θo / π` and the weight is
//! `eval / pdf`. For Beckmann this uses Mitsuba's fitted `G1`, which differs from the density of
//! the visible normals actually sampled by under 0.35%; we keep Mitsuba's formula on purpose,
//! so that our expectation is Mitsuba's (see [`super::microfacet`], "Which pdf to use").
//!
//! With `sample_visible = false` the normal is drawn from `D(m) cos θm` instead and the
//! specular density is `D(h) cos θh / (4 wo·h)` (the tables still use visible normals, as in
//! Mitsuba).

use super::fresnel::fresnel_dielectric;
use super::microfacet::{Distribution, Microfacet};
use super::plastic::{DEFAULT_EXT_IOR, DEFAULT_INT_IOR, internal_scattering};
use super::roughconductor::read_distribution;
use super::{Bsdf, BsdfSample, NONE, SurfacePoint};
use crate::dist::special::gauss_legendre_rule;
use crate::error::{Num, Result};
use crate::render::mitsuba::Params;
use crate::render::sampling::square_to_cosine_hemisphere;
use crate::render::scene::Rgb;
use crate::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

/// Entries of the transmittance table (Mitsuba's `MI_ROUGH_TRANSMITTANCE_RES`).
pub const TABLE_RES: usize = 64;

/// A rough plastic.
#[derive(Debug, Clone)]
pub struct RoughPlastic {
    /// The coating's microfacet distribution (isotropic).
    mf: Microfacet,
    /// Whether the specular lobe samples visible normals (Mitsuba's `sample_visible`).
    sample_visible: bool,
    /// `int_ior / ext_ior`.
    eta: f32,
    /// `1 / η²`.
    inv_eta2: f32,
    /// Base colour (Mitsuba's default 0.5).
    diffuse_reflectance: Spectrum,
    /// Tint of the specular lobe (Mitsuba's default 1).
    specular_reflectance: Spectrum,
    /// `s̄ / (d̄ + s̄)`.
    specular_sampling_weight: f32,
    /// Mitsuba's `nonlinear`.
    nonlinear: bool,
    /// `T(μ_i)`: transmittance of the coating at the 64 table cosines.
    transmittance: [f32; TABLE_RES],
    /// `R`: cosine-weighted internal reflectance of the coating.
    internal_reflectance: f32,
}

impl RoughPlastic {
    /// A rough plastic: `distribution` with roughness `alpha` (clamped to at least
    /// [`super::microfacet::MIN_ALPHA`]), relative index `eta = int_ior / ext_ior` (positive,
    /// not 1), the given reflectances (`specular_reflectance` 1 when `None`) and visible-normal
    /// sampling. Builds the coating tables: about 0.05 s for GGX and 0.5 s for Beckmann (release
    /// build, two cores).
    pub fn new(
        distribution: Distribution,
        alpha: f32,
        eta: f32,
        diffuse_reflectance: Spectrum,
        specular_reflectance: Option<Spectrum>,
        nonlinear: bool,
    ) -> RoughPlastic {
        let mf = Microfacet::isotropic(distribution, alpha);
        let specular_reflectance = specular_reflectance.unwrap_or(Spectrum::grey(1.0));
        let (transmittance, internal_reflectance) = coating_tables(&mf, eta);
        RoughPlastic {
            mf,
            sample_visible: true,
            eta,
            inv_eta2: 1.0 / (eta * eta),
            specular_sampling_weight: super::plastic::specular_sampling_weight(
                &diffuse_reflectance,
                &specular_reflectance,
            ),
            diffuse_reflectance,
            specular_reflectance,
            nonlinear,
            transmittance,
            internal_reflectance,
        }
    }

    /// The same material sampling normals from `D(m) cos θm` when `sample_visible` is false
    /// (Mitsuba's `sample_visible`).
    pub fn with_sample_visible(mut self, sample_visible: bool) -> RoughPlastic {
        self.sample_visible = sample_visible;
        self
    }

    /// The microfacet distribution.
    pub fn microfacet(&self) -> Microfacet {
        self.mf
    }

    /// The table `T(μ_i)` (for tests against Mitsuba).
    pub fn transmittance_table(&self) -> &[f32; TABLE_RES] {
        &self.transmittance
    }

    /// The internal reflectance `R`.
    pub fn internal_reflectance(&self) -> f32 {
        self.internal_reflectance
    }

    /// Probability that [`Bsdf::sample`] picks the specular lobe at incidence `wi` (`wi.z > 0`).
    pub fn specular_probability(&self, wi: Vec3) -> f32 {
        self.prob_specular(self.transmittance(wi.z))
    }

    /// `T(μ)` by Mitsuba's linear interpolation (`μ ∈ (0, 1]`).
    #[inline]
    fn transmittance(&self, mu: f32) -> f32 {
        let x = mu * (TABLE_RES - 1) as f32;
        // `as` saturates, so a NaN or negative x gives entry 0.
        let i = (x as usize).min(TABLE_RES - 2);
        let t = x - i as f32;
        (1.0 - t) * self.transmittance[i] + t * self.transmittance[i + 1]
    }

    /// Probability of choosing the specular lobe, given `T(cos θi)`.
    #[inline]
    fn prob_specular(&self, t_i: f32) -> f32 {
        let w = self.specular_sampling_weight;
        let s = (1.0 - t_i) * w;
        let d = t_i * (1.0 - w);
        if s + d > 0.0 { s / (s + d) } else { 0.0 }
    }
}

/// Mitsuba's choice of rule: 32 nodes per axis when the relative index exceeds 1, else 128
/// (total internal reflection makes the integrand of an index below 1 discontinuous).
fn rule_for(eta: f32) -> Vec<(f64, f64)> {
    gauss_legendre_rule(if eta > 1.0 { 32 } else { 128 })
}

/// Mitsuba's `eval_transmittance` (`transmit`) or `eval_reflectance` at one `wi`, with relative
/// index `eta`: the visible-normal integral described in the module documentation.
/// `rule` is the Gauss–Legendre rule Mitsuba picks for `eta` ([`rule_for`]).
fn coating_integral(
    mf: &Microfacet,
    wi: Vec3,
    eta: f32,
    rule: &[(f64, f64)],
    transmit: bool,
) -> f64 {
    let mut total = 0.0_f64;
    for &(x, wx) in rule {
        for &(y, wy) in rule {
            let u = Vec2::new((0.5 * x + 0.5) as f32, (0.5 * y + 0.5) as f32);
            let Some(m) = mf.sample_visible(wi, u) else {
                continue;
            };
            let cos_im = wi.dot(m);
            let (f, cos_t, _, eta_ti) = fresnel_dielectric(cos_im, eta);
            let value = if transmit {
                let wt = m * (cos_im * eta_ti + cos_t) - wi * eta_ti;
                if wt.z * wi.z >= 0.0 {
                    0.0
                } else {
                    mf.g1(wt, m) * (1.0 - f)
                }
            } else {
                let wr = 2.0 * cos_im * m - wi;
                if wr.z <= 0.0 || wi.z <= 0.0 {
                    0.0
                } else {
                    mf.g1(wr, m) * f
                }
            };
            total += f64::from(value) * wx * wy;
        }
    }
    0.25 * total
}

/// Mitsuba's precomputation: the transmittance table `T(μ_i)` of the coating seen from outside
/// and its internal reflectance `R = 2 mean(R(μ_i, 1/η) μ_i)`.
fn coating_tables(mf: &Microfacet, eta: f32) -> ([f32; TABLE_RES], f32) {
    let (rule_t, rule_r) = (rule_for(eta), rule_for(1.0 / eta));
    // The 64 entries are independent: computed in parallel (the Beckmann sampler inverts its
    // CDF iteratively, about a microsecond per node, and 1/η < 1 takes 128² nodes per entry).
    let entries: Vec<(f32, f64)> = (0..TABLE_RES)
        .into_par_iter()
        .map(|i| {
            let mu = (i as f32 / (TABLE_RES - 1) as f32).max(1e-6);
            let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            let t = coating_integral(mf, wi, eta, &rule_t, true) as f32;
            let r = coating_integral(mf, wi, 1.0 / eta, &rule_r, false) * f64::from(mu);
            (t, r)
        })
        .collect();
    let mut table = [0.0; TABLE_RES];
    for (slot, &(t, _)) in table.iter_mut().zip(&entries) {
        *slot = t;
    }
    let reflectance: f64 = entries.iter().map(|&(_, r)| r).sum();
    (table, (2.0 * reflectance / TABLE_RES as f64) as f32)
}

/// Reads `<bsdf type="roughplastic">`: `distribution` (`beckmann`, Mitsuba's default, or
/// `ggx`), `alpha` (default 0.1, > 0), `sample_visible` (default true), `int_ior`, `ext_ior`
/// (defaults polypropylene and air; must differ, as Mitsuba requires), `diffuse_reflectance`
/// (default 0.5), `specular_reflectance` (default 1), `nonlinear` (default false). Anisotropic
/// roughness is refused, as Mitsuba refuses it for this plugin.
pub fn load(p: &mut Params) -> Result<Arc<dyn Bsdf>> {
    let (microfacet, sample_visible) = read_distribution(p)?;
    let int_ior = p.ior("int_ior")?;
    let ext_ior = p.ior("ext_ior")?;
    let diffuse = p.texture("diffuse_reflectance")?;
    let specular = p.texture("specular_reflectance")?;
    let nonlinear = p.boolean("nonlinear")?;
    p.finish()?;
    let int = int_ior.map_or(DEFAULT_INT_IOR, |(v, _)| v);
    let ext = ext_ior.as_ref().map_or(DEFAULT_EXT_IOR, |(v, _)| *v);
    if int == ext {
        return Err(p.err(
            ext_ior.map(|(_, at)| at),
            format!(
                "int_ior and ext_ior are both {}: Mitsuba's roughplastic requires them to differ",
                Num::from_f32(int)
            ),
        ));
    }
    Ok(Arc::new(
        RoughPlastic::new(
            microfacet.distribution(),
            microfacet.alpha_u(),
            int / ext,
            diffuse.map_or(Spectrum::grey(0.5), |(d, _)| d),
            specular.map(|(s, _)| s),
            nonlinear.is_some_and(|(b, _)| b),
        )
        .with_sample_visible(sample_visible.is_none_or(|(b, _)| b)),
    ))
}

impl Bsdf for RoughPlastic {
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
        let (cos_i, cos_o) = (wi.z, wo.z);
        if !(cos_i > 0.0 && cos_o > 0.0) {
            return NONE;
        }
        let t_i = self.transmittance(cos_i);
        let p_spec = self.prob_specular(t_i);
        // Both directions are above the horizon, so wi + wo is not zero.
        let Some(h) = (wi + wo).try_normalize() else {
            return NONE;
        };
        let d = self.mf.d(h);
        let g1_i = self.mf.g1(wi, h);
        let spec_pdf = if self.sample_visible {
            d * g1_i / (4.0 * cos_i)
        } else {
            self.mf.pdf_all(h) / (4.0 * wo.dot(h))
        };
        let pdf = p_spec * spec_pdf + (1.0 - p_spec) * cos_o * FRAC_1_PI;

        let f = fresnel_dielectric(wi.dot(h), self.eta).0;
        let specular = f * d * g1_i * self.mf.g1(wo, h) / (4.0 * cos_i);
        let t_o = self.transmittance(cos_o);
        let rho = self.diffuse_reflectance.eval(at.uv);
        let diffuse = internal_scattering(rho, self.internal_reflectance, self.nonlinear)
            * (FRAC_1_PI * self.inv_eta2 * cos_o * t_i * t_o);
        let value = self.specular_reflectance.eval(at.uv) * specular + diffuse;
        (value, pdf)
    }

    fn sample(&self, at: &SurfacePoint, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if !(wi.z > 0.0) {
            return None;
        }
        let p_spec = self.prob_specular(self.transmittance(wi.z));
        let wo = if u_lobe < p_spec {
            let m = if self.sample_visible {
                self.mf.sample_visible(wi, u)?
            } else {
                self.mf.sample_all(u)?
            };
            (2.0 * wi.dot(m) * m - wi).try_normalize()?
        } else {
            square_to_cosine_hemisphere(u)
        };
        // Mitsuba's weight: eval / pdf of the mixture, both at the rounded `wo` (so that
        // `pdf == self.pdf(wi, wo)` exactly). A reflection below the horizon ends the path.
        let (value, pdf) = self.eval_pdf(at, wi, wo);
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        let weight = value / pdf;
        weight.is_finite().then_some(BsdfSample {
            wo,
            weight,
            pdf,
            delta: false,
            eta: 1.0,
        })
    }
}
