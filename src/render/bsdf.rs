//! Surface scattering: the BSDFs of the supported Mitsuba 3 subset, with sampling routines whose
//! estimators have the same expectation as Mitsuba's.
//!
//! # Why these models, and why Mitsuba's exact formulas
//!
//! The renderer is a reference for comparing pixel estimators on heavy-tailed samples; its images
//! must agree with Mitsuba 3 renders of the same scene in expectation. So every choice that
//! changes the expected value (the GGX shadowing term, the Fresnel factor, the radiance scaling
//! across refractive interfaces, one-sidedness) follows Mitsuba, and only choices that leave the
//! expectation alone (the warp used for visible normals, how degenerate inputs are rejected) are
//! our own.
//!
//! # Conventions (Mitsuba's)
//!
//! * Every direction is a unit vector in the **local shading frame**: `z` is the front normal.
//! * `wi` points from the surface toward the previous path vertex (toward the camera side);
//!   `wo` toward the next vertex.
//! * [`Bsdf::eval`] returns `f(wi, wo) · |cos θo|` — the cosine foreshortening is included, as in
//!   Mitsuba's `BSDF::eval`.
//! * [`Bsdf::sample`] returns the weight `eval / pdf` for smooth lobes, so a path tracer
//!   multiplies its throughput by `weight` without touching `pdf`.
//! * Delta lobes (mirror, smooth glass) evaluate to 0 and have pdf 0 under [`Bsdf::eval`] /
//!   [`Bsdf::pdf`]: no finite direction can hit them.
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
//! # Models
//!
//! * `diffuse` — Lambertian, one-sided, cosine-weighted sampling.
//! * `conductor` (`material="none"`) — perfect mirror, one-sided, Fresnel factor 1 times the tint.
//!   (Mitsuba's `none` material is the complex index `0 + 1i`, whose conductor Fresnel
//!   reflectance is exactly 1 at every angle.)
//! * `roughconductor` (`material="none"`) — the GGX (Trowbridge–Reitz) microfacet model of
//!   Walter et al. 2007, "Microfacet models for refraction through rough surfaces", with Smith's
//!   *separable* shadowing–masking `G = G1(wi)·G1(wo)` (Mitsuba's choice; Heitz 2014,
//!   "Understanding the masking-shadowing function in microfacet-based BRDFs", discusses the
//!   alternatives). Sampling draws microfacet normals from the distribution of normals *visible*
//!   from `wi`, `D_wi(m) = G1(wi)·max(0, wi·m)·D(m)/cos θi` (Heitz 2014 and Heitz & d'Eon 2014),
//!   with the exact hemisphere-projection construction of Heitz 2018, "Sampling the GGX
//!   distribution of visible normals" (JCGT 7(4)). Mitsuba uses an older slope-space routine for
//!   the same density; the two produce identically distributed normals, so expectations agree.
//!   The reflected direction's density is `D_wi(m) / (4 |wo·m|)` and the sample weight
//!   simplifies to `F · G1(wo)`. Like Mitsuba, `alpha` is clamped below at `1e-4`, and `D(m)` is
//!   set to 0 where `D(m)·cos θm ≤ 1e-20`.
//! * `dielectric` — smooth interface, exact unpolarised Fresnel, reflection chosen with
//!   probability `F`, transmission weight scaled by `(1/η_it)²` (radiance transport: radiance is
//!   compressed into the smaller solid angle of the denser medium), as in Mitsuba's radiance mode.
//! * `twosided` — the nested one-sided BSDF mirrored onto the back side by flipping `z`.

use super::sampling::{self, square_to_disk};
use super::scene::{BsdfDesc, Rgb};
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// Smallest GGX roughness used (Mitsuba clamps `alpha` to the same bound).
pub const MIN_ALPHA: f32 = 1e-4;

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
    /// Whether `wo` came from a delta (specular) lobe.
    pub delta: bool,
    /// Relative index of refraction `η_t / η_i` crossed by a transmission; 1 for reflection.
    pub eta: f32,
}

/// A BSDF ready for rendering (parameters resolved from a [`BsdfDesc`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Bsdf {
    /// Lambertian reflection, front side only.
    Diffuse {
        /// Albedo.
        reflectance: Rgb,
    },
    /// Perfect mirror, front side only.
    Conductor {
        /// Tint.
        specular_reflectance: Rgb,
    },
    /// GGX microfacet mirror, front side only.
    RoughConductor {
        /// GGX roughness (already clamped to at least [`MIN_ALPHA`]).
        alpha: f32,
        /// Tint.
        specular_reflectance: Rgb,
    },
    /// Smooth dielectric interface, both sides.
    Dielectric {
        /// `int_ior / ext_ior`.
        eta: f32,
        /// Reflection tint.
        specular_reflectance: Rgb,
        /// Transmission tint.
        specular_transmittance: Rgb,
    },
    /// The nested BSDF seen from the front on both sides.
    TwoSided(Box<Bsdf>),
}

/// `v` with its `z` negated (mirror through the tangent plane).
#[inline]
fn flip_z(v: Vec3) -> Vec3 {
    Vec3::new(v.x, v.y, -v.z)
}

/// Mirror reflection of `wi` about the normal `+z`.
#[inline]
fn reflect_z(wi: Vec3) -> Vec3 {
    Vec3::new(-wi.x, -wi.y, wi.z)
}

/// Unpolarised Fresnel reflectance of a smooth dielectric interface (Mitsuba's `fresnel`).
///
/// `cos_theta_i` is `wi.z` (its sign says which side `wi` is on: `≥ 0` is outside) and `eta` is
/// `int_ior / ext_ior`. Returns `(F, cos_theta_t, eta_it, eta_ti)`:
/// * `F` — reflectance (1 under total internal reflection, 0 for an index-matched interface);
/// * `cos_theta_t` — signed cosine of the refracted direction (opposite sign to `cos_theta_i`,
///   0 under total internal reflection);
/// * `eta_it` — relative index `η_t/η_i` seen from `wi`'s side (`eta` outside, `1/eta` inside);
/// * `eta_ti` — its reciprocal.
pub fn fresnel_dielectric(cos_theta_i: f32, eta: f32) -> (f32, f32, f32, f32) {
    let outside = cos_theta_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    let cos_i = cos_theta_i.abs().min(1.0);
    // Snell: sin θt = η_ti sin θi.
    let cos_t_sqr = 1.0 - (1.0 - cos_i * cos_i) * (eta_ti * eta_ti);
    if cos_t_sqr <= 0.0 {
        // Total internal reflection.
        return (1.0, 0.0, eta_it, eta_ti);
    }
    let cos_t = cos_t_sqr.sqrt();
    let f = if eta == 1.0 {
        0.0
    } else if cos_i == 0.0 {
        1.0
    } else {
        // Amplitude coefficients for s and p polarisation, both relative to the incident side.
        let a_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
        let a_p = (cos_t - eta_it * cos_i) / (cos_t + eta_it * cos_i);
        0.5 * (a_s * a_s + a_p * a_p)
    };
    let cos_t_signed = if outside { -cos_t } else { cos_t };
    (f, cos_t_signed, eta_it, eta_ti)
}

/// The isotropic GGX distribution with Smith shadowing, as Mitsuba evaluates it.
#[derive(Debug, Clone, Copy)]
struct Ggx {
    alpha: f32,
}

impl Ggx {
    /// Microfacet normal density `D(m)` per unit solid angle of `m`, normalised so that the
    /// projected facet area is one: `∫ D(m) cos θm dm = 1`.
    #[inline]
    fn d(self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let t = (m.x * m.x + m.y * m.y) / a2 + m.z * m.z;
        let d = 1.0 / (PI * a2 * t * t);
        // Mitsuba drops vanishing densities to keep later stages well-conditioned.
        if d * m.z > 1e-20 && d.is_finite() {
            d
        } else {
            0.0
        }
    }

    /// `G1(v) / cos θv` for `v.z > 0`: Smith's GGX masking divided by the cosine, in a form that
    /// stays finite as `v.z → 0` (the plain `2/(1+√(1+α² tan²θ))` overflows there).
    #[inline]
    fn g1_over_cos(self, v: Vec3) -> f32 {
        let a2 = self.alpha * self.alpha;
        2.0 / (v.z + (v.z * v.z + a2 * (v.x * v.x + v.y * v.y)).sqrt())
    }

    /// Smith's masking `G1(v, m)`: 0 if `v` sees the back of the facet `m` or lies below the
    /// horizon of the macro-surface (only `v.z > 0` is used here).
    #[inline]
    fn g1(self, v: Vec3, m: Vec3) -> f32 {
        if v.z <= 0.0 || v.dot(m) <= 0.0 {
            return 0.0;
        }
        (v.z * self.g1_over_cos(v)).min(1.0)
    }

    /// Draws a microfacet normal from the visible-normal distribution `D_wi` (requires
    /// `wi.z > 0`), following Heitz 2018: in the configuration stretched to `alpha = 1` the
    /// visible normals are those of a hemisphere, whose projection onto the plane orthogonal to
    /// the (stretched) view is a unit disk — half of it behind the hemisphere's rim foreshortened
    /// by `cos θ`. A uniform disk point is squeezed into that shape, lifted onto the hemisphere,
    /// and the normal unstretched.
    fn sample_visible(self, wi: Vec3, u: Vec2) -> Option<Vec3> {
        let a = self.alpha;
        // Stretch the view so the distribution becomes the alpha = 1 one.
        let vh = Vec3::new(a * wi.x, a * wi.y, wi.z).try_normalize()?;
        // Basis of the plane orthogonal to vh.
        let len_sq = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len_sq > 0.0 {
            Vec3::new(-vh.y, vh.x, 0.0) / len_sq.sqrt()
        } else {
            Vec3::X
        };
        let t2 = vh.cross(t1);
        // Uniform point on the unit disk (concentric map: keeps strata compact), then compress
        // its t2 half behind the rim to the projected area of the visible half-ellipse.
        let p = square_to_disk(u);
        let s = 0.5 * (1.0 + vh.z);
        let p1 = p.x;
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p.y;
        // Lift onto the hemisphere around vh.
        let lift = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        let nh = p1 * t1 + p2 * t2 + lift * vh;
        // Unstretch (normals transform with the inverse transpose).
        let m = Vec3::new(a * nh.x, a * nh.y, nh.z.max(0.0)).try_normalize()?;
        (m.z > 0.0).then_some(m)
    }
}

impl Bsdf {
    /// Builds the renderable BSDF from its description.
    ///
    /// Mitsuba refuses to nest a BSDF with transmission (`dielectric`) inside `twosided`; should
    /// a description do so anyway, the dielectric — two-sided by nature — is used unwrapped.
    /// Nested `twosided` wrappers collapse into one (flipping to the front is idempotent).
    pub fn from_desc(d: &BsdfDesc) -> Bsdf {
        match d {
            BsdfDesc::Diffuse { reflectance } => Bsdf::Diffuse {
                reflectance: *reflectance,
            },
            BsdfDesc::Conductor {
                specular_reflectance,
            } => Bsdf::Conductor {
                specular_reflectance: *specular_reflectance,
            },
            BsdfDesc::RoughConductor {
                alpha,
                specular_reflectance,
            } => Bsdf::RoughConductor {
                // `max` also maps a NaN alpha to the bound.
                alpha: alpha.max(MIN_ALPHA),
                specular_reflectance: *specular_reflectance,
            },
            BsdfDesc::Dielectric {
                int_ior,
                ext_ior,
                specular_reflectance,
                specular_transmittance,
            } => Bsdf::Dielectric {
                eta: int_ior / ext_ior,
                specular_reflectance: *specular_reflectance,
                specular_transmittance: *specular_transmittance,
            },
            BsdfDesc::TwoSided(inner) => match Bsdf::from_desc(inner) {
                b @ (Bsdf::Dielectric { .. } | Bsdf::TwoSided(_)) => b,
                b => Bsdf::TwoSided(Box::new(b)),
            },
        }
    }

    /// True if the BSDF has a non-delta lobe, i.e. [`Bsdf::eval`] can be non-zero; only then is
    /// next-event estimation worth doing.
    pub fn has_smooth_lobe(&self) -> bool {
        match self {
            Bsdf::Diffuse { .. } | Bsdf::RoughConductor { .. } => true,
            Bsdf::Conductor { .. } | Bsdf::Dielectric { .. } => false,
            Bsdf::TwoSided(inner) => inner.has_smooth_lobe(),
        }
    }

    /// `f(wi, wo) · |cos θo|`; 0 for delta lobes and for directions a one-sided BSDF ignores.
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Rgb {
        self.eval_pdf(wi, wo).0
    }

    /// Solid-angle density with which [`Bsdf::sample`] produces `wo`; 0 for delta lobes.
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        self.eval_pdf(wi, wo).1
    }

    /// [`Bsdf::eval`] and [`Bsdf::pdf`] together, sharing one microfacet evaluation.
    pub fn eval_pdf(&self, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        const NONE: (Rgb, f32) = (Rgb::ZERO, 0.0);
        match self {
            Bsdf::Diffuse { reflectance } => {
                if wi.z <= 0.0 || wo.z <= 0.0 {
                    return NONE;
                }
                (*reflectance * (wo.z * FRAC_1_PI), wo.z * FRAC_1_PI)
            }
            Bsdf::RoughConductor {
                alpha,
                specular_reflectance,
            } => {
                if wi.z <= 0.0 || wo.z <= 0.0 {
                    return NONE;
                }
                let ggx = Ggx { alpha: *alpha };
                // Both directions are above the horizon, so wi + wo has z > 0 and the half
                // vector is well defined; it also faces both (wi·m = wo·m > 0).
                let Some(m) = (wi + wo).try_normalize() else {
                    return NONE;
                };
                let d = ggx.d(m);
                if d == 0.0 {
                    return NONE;
                }
                // pdf = D_wi(m) / (4 wo·m) = G1(wi) (wi·m) D / (cos θi · 4 wo·m), with wi·m = wo·m.
                let pdf = d * ggx.g1_over_cos(wi) * 0.25;
                // eval = F D G1(wi) G1(wo) / (4 cos θi) = pdf · F · G1(wo).
                let value = *specular_reflectance * (pdf * ggx.g1(wo, m));
                if pdf.is_finite() && pdf > 0.0 {
                    (value, pdf)
                } else {
                    NONE
                }
            }
            Bsdf::Conductor { .. } | Bsdf::Dielectric { .. } => NONE,
            Bsdf::TwoSided(inner) => {
                if wi.z < 0.0 {
                    inner.eval_pdf(flip_z(wi), flip_z(wo))
                } else {
                    inner.eval_pdf(wi, wo)
                }
            }
        }
    }

    /// Samples an outgoing direction. `u_lobe` (in `[0, 1)`) chooses between lobes (only the
    /// dielectric uses it), `u` (in `[0, 1)²`) the direction within the lobe. `None` means the
    /// path ends here (the back of a one-sided BSDF, or a sample below the horizon).
    pub fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        match self {
            Bsdf::Diffuse { reflectance } => {
                if wi.z <= 0.0 {
                    return None;
                }
                let wo = sampling::square_to_cosine_hemisphere(u);
                let pdf = sampling::cosine_hemisphere_pdf(wo);
                (pdf > 0.0).then_some(BsdfSample {
                    wo,
                    weight: *reflectance,
                    pdf,
                    delta: false,
                    eta: 1.0,
                })
            }
            Bsdf::Conductor {
                specular_reflectance,
            } => {
                if wi.z <= 0.0 {
                    return None;
                }
                Some(BsdfSample {
                    wo: reflect_z(wi),
                    weight: *specular_reflectance,
                    pdf: f32::INFINITY,
                    delta: true,
                    eta: 1.0,
                })
            }
            Bsdf::RoughConductor { alpha, .. } => {
                if wi.z <= 0.0 {
                    return None;
                }
                let ggx = Ggx { alpha: *alpha };
                let m = ggx.sample_visible(wi, u)?;
                let cos_im = wi.dot(m);
                if cos_im <= 0.0 {
                    return None;
                }
                let wo = (2.0 * cos_im * m - wi).try_normalize()?;
                if wo.z <= 0.0 {
                    // Reflected below the macro-surface: the lost energy of the separable model.
                    return None;
                }
                // Density D_wi(m) / (4 wo·m) and weight F·G1(wo), evaluated at the half vector of
                // the rounded `wo` rather than at `m`: identical in exact arithmetic, and this way
                // `pdf == self.pdf(wi, wo)` and `weight == eval / pdf` hold to the last bit
                // (near grazing `wi` the half vector is ill-conditioned, and a narrow lobe turns
                // its rounding into a visible density mismatch).
                let (value, pdf) = self.eval_pdf(wi, wo);
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
            Bsdf::Dielectric {
                eta,
                specular_reflectance,
                specular_transmittance,
            } => {
                let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.z, *eta);
                if u_lobe < f {
                    // Reflection chosen with probability F: weight F·tint / F.
                    Some(BsdfSample {
                        wo: reflect_z(wi),
                        weight: *specular_reflectance,
                        pdf: f32::INFINITY,
                        delta: true,
                        eta: 1.0,
                    })
                } else {
                    // Transmission chosen with probability 1 − F; radiance scales by η_ti².
                    let wo = Vec3::new(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
                    Some(BsdfSample {
                        wo: wo.try_normalize().unwrap_or(wo),
                        weight: *specular_transmittance * (eta_ti * eta_ti),
                        pdf: f32::INFINITY,
                        delta: true,
                        eta: eta_it,
                    })
                }
            }
            Bsdf::TwoSided(inner) => {
                if wi.z < 0.0 {
                    let mut s = inner.sample(flip_z(wi), u_lobe, u)?;
                    s.wo = flip_z(s.wo);
                    Some(s)
                } else {
                    inner.sample(wi, u_lobe, u)
                }
            }
        }
    }
}
