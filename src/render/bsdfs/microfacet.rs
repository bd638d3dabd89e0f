//! Microfacet normal distributions (Beckmann and GGX), their Smith shadowing–masking and the
//! sampling routines shared by Mitsuba 3.9.1's rough BSDFs (`roughconductor`,
//! `roughdielectric`, `roughplastic`), following `include/mitsuba/render/microfacet.h`.
//!
//! # What must equal Mitsuba, and what need not
//!
//! The renderer must agree with Mitsuba **in expectation**. So every quantity that enters a
//! BSDF value — `D(m)`, Smith's `G1` and the separable `G = G1(wi) G1(wo)` — is Mitsuba's formula
//! to the letter, including its approximations: Mitsuba's Beckmann `G1` is a rational fit
//! (Walter et al. 2007, eq. 27; under 0.35% relative error), not the exact Smith function.
//! Sampling only has to produce *some* exact density that we can evaluate, so the warps are our
//! own where that is simpler or more exact.
//!
//! # Models
//!
//! Walter, Marschner, Li & Torrance 2007, "Microfacet models for refraction through rough
//! surfaces": with `t = (m_x/α_u)² + (m_y/α_v)²` over `cos²θ_m`,
//!
//! * Beckmann: `D(m) = exp(−t) / (π α_u α_v cos⁴θ_m)`;
//! * GGX (Trowbridge–Reitz): `D(m) = 1 / (π α_u α_v ((m_x/α_u)² + (m_y/α_v)² + m_z²)²)`.
//!
//! Both satisfy `∫ D(m) cos θ_m dm = 1`. Roughness is anisotropic (`α_u` along the tangent `x`,
//! `α_v` along `y`) and clamped below at [`MIN_ALPHA`], as in Mitsuba; `D` is set to 0 where
//! `D(m) cos θ_m ≤ 1e-20`, as in Mitsuba.
//!
//! Smith's masking is `G1(v, m) = 1 / (1 + Λ(a))` with `a = 1 / (α_v(φ) tan θ_v)`, zero when `v`
//! sees the back of `m` (`(v·m) v_z ≤ 0`) and one at normal incidence. GGX's is exact; for
//! Beckmann Mitsuba uses the fit (see [`Microfacet::g1`]) and we also provide the exact
//! [`Microfacet::g1_exact`] because the *sampler's* density needs it.
//!
//! # Sampling visible normals
//!
//! [`Microfacet::sample_visible`] draws `m` from `D_wi(m) = G1(wi, m) max(0, wi·m) D(m) / cos θ_i`
//! (Heitz & d'Eon 2014, "Importance sampling microfacet-based BSDFs using the distribution of
//! visible normals"), Mitsuba's default (`sample_visible = true`). Both distributions are
//! stretch-invariant, so `wi` is stretched to the `α = 1` configuration, sampled there and the
//! result unstretched.
//!
//! * GGX: Heitz 2018, "Sampling the GGX distribution of visible normals" (JCGT 7(4)): the visible
//!   `α = 1` normals are those of a hemisphere; a uniform disk point is compressed onto the
//!   projection of its visible part and lifted. This is the construction Mitsuba 3.9.1 uses too
//!   (in slope form), and with the same disk map and tangent orientation it gives the same
//!   normal for the same `u`.
//! * Beckmann: in the slope space of the `α = 1` configuration, with `wi` in the `xz` plane at
//!   angle `θ`, the visible slopes have density `∝ e^{−x²−y²} (cot θ − x)` for `x < cot θ`
//!   (Heitz & d'Eon 2014, §4). `y` is independent and Gaussian (`erf⁻¹(2u₂ − 1)`); `x` has the
//!   closed-form CDF `∝ (√π/2) erfc(−x) + (tan θ / 2) e^{−x²}`, which we invert to convergence
//!   (safeguarded Newton in `f64`). Mitsuba inverts the same CDF with three Newton steps from a
//!   fitted start (Jakob 2014, "An improved visible normal sampling routine for the Beckmann
//!   distribution"), so its normals differ from ours by its residual, far below what an image
//!   can resolve; ours is exact, so [`Microfacet::pdf_visible`] (with the exact `G1`) is the true
//!   density of what we sample. The slope range is truncated to `|x|, |y| ≤ 8` and `2u₂ − 1`
//!   clamped to `±(1 − 10⁻¹⁵)`: a probability mass below `10⁻¹⁵` (Mitsuba clamps `u` to
//!   `[10⁻⁶, 1 − 10⁻⁶]`, leaving out about `4·10⁻⁶`).
//!
//! # Which pdf to use
//!
//! * [`Microfacet::pdf_visible`]: the exact density of [`Microfacet::sample_visible`] (uses
//!   [`Microfacet::g1_exact`]). For GGX it equals Mitsuba's `pdf`.
//! * [`Microfacet::pdf_visible_mitsuba`]: Mitsuba's `MicrofacetDistribution::pdf`, which uses the
//!   Beckmann `G1` fit and therefore integrates to `1 ± 0.35%` for Beckmann.
//!
//! Mitsuba's `roughconductor` reports `pdf_visible_mitsuba / (4 wo·m)` as the sample's pdf and
//! `F · G1(wo, m)` (fit) as its weight, which is `eval / pdf` only if the fit were exact. So its
//! BSDF-sampled estimates carry a factor `G1*(wi) / G1(wi)` (within 0.35% of 1) relative to its
//! `eval`, and its MIS sum inherits it. To reproduce Mitsuba's Beckmann expectation exactly,
//! sample with [`Microfacet::sample_visible`] and use Mitsuba's weight and pdf formulas; to be
//! exact instead, weight by `eval / pdf` with [`Microfacet::pdf_visible`]. For GGX both agree.
//!
//! `sample_all` / `pdf_all` sample `D(m) cos θ_m` (Mitsuba's `sample_visible = false`), with
//! Mitsuba's closed forms (exact for both distributions, anisotropic included).

use crate::render::sampling::square_to_disk;
use glam::{Vec2, Vec3};
use statrs::function::erf::{erf_inv, erfc};
use std::f32::consts::PI;

/// Smallest roughness used (Mitsuba clamps `alpha_u` and `alpha_v` to the same bound).
pub const MIN_ALPHA: f32 = 1e-4;

/// Mitsuba's default roughness of its rough BSDFs.
pub const DEFAULT_ALPHA: f32 = 0.1;

/// Slopes of the `α = 1` Beckmann sampler are confined to `[−SLOPE_MAX, SLOPE_MAX]`: the
/// Gaussian mass beyond is `erfc(8)/2 ≈ 10⁻²⁹`.
const SLOPE_MAX: f64 = 8.0;

/// Which microfacet normal distribution (Mitsuba's `distribution` parameter).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Distribution {
    /// Trowbridge–Reitz / GGX: long tails.
    Ggx,
    /// Beckmann: Gaussian slopes; Mitsuba's default for the rough BSDFs.
    Beckmann,
}

impl Distribution {
    /// Parses Mitsuba's `distribution` string (`"beckmann"` or `"ggx"`, case-insensitive as in
    /// Mitsuba); `None` for anything else.
    pub fn from_name(name: &str) -> Option<Distribution> {
        match name.to_lowercase().as_str() {
            "ggx" => Some(Distribution::Ggx),
            "beckmann" => Some(Distribution::Beckmann),
            _ => None,
        }
    }

    /// The name Mitsuba uses.
    pub fn name(self) -> &'static str {
        match self {
            Distribution::Ggx => "ggx",
            Distribution::Beckmann => "beckmann",
        }
    }
}

/// A microfacet distribution with (possibly anisotropic) roughness, in the local shading frame
/// (`z` is the macro-surface normal, `x` the tangent along which `alpha_u` applies).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Microfacet {
    distribution: Distribution,
    alpha_u: f32,
    alpha_v: f32,
}

impl Microfacet {
    /// Roughness `alpha_u` along `x` and `alpha_v` along `y`, each clamped below at
    /// [`MIN_ALPHA`] (a NaN becomes the bound too), as Mitsuba does.
    pub fn new(distribution: Distribution, alpha_u: f32, alpha_v: f32) -> Microfacet {
        Microfacet {
            distribution,
            alpha_u: alpha_u.max(MIN_ALPHA),
            alpha_v: alpha_v.max(MIN_ALPHA),
        }
    }

    /// The isotropic distribution of roughness `alpha`.
    pub fn isotropic(distribution: Distribution, alpha: f32) -> Microfacet {
        Microfacet::new(distribution, alpha, alpha)
    }

    /// The distribution type.
    pub fn distribution(&self) -> Distribution {
        self.distribution
    }

    /// Roughness along the tangent (after clamping).
    pub fn alpha_u(&self) -> f32 {
        self.alpha_u
    }

    /// Roughness along the bitangent (after clamping).
    pub fn alpha_v(&self) -> f32 {
        self.alpha_v
    }

    /// Whether `alpha_u == alpha_v` (Mitsuba's `is_isotropic`, which selects its isotropic
    /// azimuth formula in [`Microfacet::sample_all`]).
    pub fn is_isotropic(&self) -> bool {
        self.alpha_u == self.alpha_v
    }

    /// Microfacet normal density `D(m)` per unit solid angle (Mitsuba's `eval`); 0 for `m` at or
    /// below the horizon and wherever `D(m) cos θm ≤ 1e-20`.
    pub fn d(&self, m: Vec3) -> f32 {
        let (au, av) = (self.alpha_u, self.alpha_v);
        let cos2 = m.z * m.z;
        let xu = m.x / au;
        let yv = m.y / av;
        let value = match self.distribution {
            Distribution::Beckmann => {
                (-(xu * xu + yv * yv) / cos2).exp() / (PI * au * av * (cos2 * cos2))
            }
            Distribution::Ggx => {
                let t = xu * xu + yv * yv + cos2;
                1.0 / (PI * au * av * (t * t))
            }
        };
        // Mitsuba's guard; also maps a NaN (m on the horizon) to 0.
        if value * m.z > 1e-20 { value } else { 0.0 }
    }

    /// `tan²θ_v · α(φ_v)²`, the squared inverse of the Smith variable `a`, or `None` at normal
    /// incidence (where `G1 = 1`).
    #[inline]
    fn tan2_alpha2(&self, v: Vec3) -> Option<f32> {
        let xu = self.alpha_u * v.x;
        let yv = self.alpha_v * v.y;
        let xy = xu * xu + yv * yv;
        (xy != 0.0).then(|| xy / (v.z * v.z))
    }

    /// Smith's masking `G1(v, m)` exactly as Mitsuba 3.9.1 computes it (`smith_g1`): 0 if `v`
    /// sees the back of `m` (`(v·m) v_z ≤ 0`), 1 at normal incidence, otherwise with
    /// `a = 1/(α tan θ_v)`:
    /// * GGX: `2 / (1 + √(1 + 1/a²))` (exact);
    /// * Beckmann: the rational fit `(3.535 a + 2.181 a²) / (1 + 2.276 a + 2.577 a²)` for
    ///   `a < 1.6`, else 1 (Walter et al. 2007, eq. 27; relative error under 0.35%).
    ///
    /// `v` may lie below the horizon (paired with a facet it sees from below), as
    /// `roughdielectric` needs for transmission.
    pub fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        let Some(t2) = self.tan2_alpha2(v) else {
            return 1.0;
        };
        match self.distribution {
            Distribution::Beckmann => {
                let a = 1.0 / t2.sqrt();
                if a >= 1.6 {
                    1.0
                } else {
                    let a2 = a * a;
                    (3.535 * a + 2.181 * a2) / (1.0 + 2.276 * a + 2.577 * a2)
                }
            }
            Distribution::Ggx => 2.0 / (1.0 + (1.0 + t2).sqrt()),
        }
    }

    /// The exact Smith masking `1 / (1 + Λ)`, same conventions as [`Microfacet::g1`]. Equal to
    /// it for GGX; for Beckmann `Λ(a) = (erf(a) − 1)/2 + e^{−a²} / (2a√π)` (evaluated in `f64`
    /// through `erfc` to keep the tail accurate). This is the normalisation of the visible-normal
    /// density that [`Microfacet::sample_visible`] draws from.
    pub fn g1_exact(&self, v: Vec3, m: Vec3) -> f32 {
        match self.distribution {
            Distribution::Ggx => self.g1(v, m),
            Distribution::Beckmann => {
                if v.dot(m) * v.z <= 0.0 {
                    return 0.0;
                }
                let Some(t2) = self.tan2_alpha2(v) else {
                    return 1.0;
                };
                let a = 1.0 / f64::from(t2).sqrt();
                if a == 0.0 {
                    return 0.0;
                }
                let lambda =
                    -0.5 * erfc(a) + (-a * a).exp() / (2.0 * a * std::f64::consts::PI.sqrt());
                (1.0 / (1.0 + lambda)) as f32
            }
        }
    }

    /// Smith's separable shadowing–masking `G1(wi, m) · G1(wo, m)` with Mitsuba's `G1`
    /// (Mitsuba's `G`).
    pub fn g(&self, wi: Vec3, wo: Vec3, m: Vec3) -> f32 {
        self.g1(wi, m) * self.g1(wo, m)
    }

    /// Draws a microfacet normal from the distribution of normals visible from `wi`
    /// (`wi.z > 0` required; `None` otherwise or if the sample degenerates). The density is
    /// [`Microfacet::pdf_visible`]; the construction is described in the module documentation.
    pub fn sample_visible(&self, wi: Vec3, u: Vec2) -> Option<Vec3> {
        if wi.z.is_nan() || wi.z <= 0.0 {
            return None;
        }
        let (au, av) = (self.alpha_u, self.alpha_v);
        // Stretch to the α = 1 configuration.
        let vh = Vec3::new(au * wi.x, av * wi.y, wi.z).try_normalize()?;
        // Azimuth of the stretched view; any azimuth is exact at normal incidence, and Mitsuba
        // takes φ = 0 there.
        let (sin_phi, cos_phi) = match Vec2::new(vh.x, vh.y).try_normalize() {
            Some(d) => (d.y, d.x),
            None => (0.0, 1.0),
        };
        let m = match self.distribution {
            Distribution::Ggx => {
                // Tangent frame of the plane orthogonal to vh, oriented as Mitsuba's (so the
                // same u gives the same normal): t1 ⟂ the plane of incidence.
                let t1 = Vec3::new(sin_phi, -cos_phi, 0.0);
                let t2 = t1.cross(vh);
                // Uniform disk point; the half behind the rim (along t2) is squeezed onto the
                // projection of the visible half-ellipse, of relative height cos θ.
                let p = square_to_disk(u);
                let s = 0.5 * (1.0 + vh.z);
                let p2 = (1.0 - s) * (1.0 - p.x * p.x).max(0.0).sqrt() + s * p.y;
                let lift = (1.0 - p.x * p.x - p2 * p2).max(0.0).sqrt();
                let nh = p.x * t1 + p2 * t2 + lift * vh;
                // Unstretch (normals transform with the inverse transpose).
                Vec3::new(au * nh.x, av * nh.y, nh.z.max(0.0)).try_normalize()?
            }
            Distribution::Beckmann => {
                let (x, y) = beckmann_visible_slope_11(f64::from(vh.z), u);
                // Rotate back to the azimuth of vh and unstretch the slopes.
                let (sp, cp) = (f64::from(sin_phi), f64::from(cos_phi));
                let sx = (cp * x - sp * y) * f64::from(au);
                let sy = (sp * x + cp * y) * f64::from(av);
                let n = (sx * sx + sy * sy + 1.0).sqrt();
                Vec3::new((-sx / n) as f32, (-sy / n) as f32, (1.0 / n) as f32)
            }
        };
        (m.z > 0.0 && m.is_finite()).then_some(m)
    }

    /// Exact density of [`Microfacet::sample_visible`] per unit solid angle of `m`:
    /// `D(m) G1*(wi, m) max(0, wi·m) / cos θ_i` with the exact `G1*` ([`Microfacet::g1_exact`]).
    /// 0 for `wi.z ≤ 0` (callers flip `wi` to the upper side first, as Mitsuba's BSDFs do).
    pub fn pdf_visible(&self, wi: Vec3, m: Vec3) -> f32 {
        if wi.z.is_nan() || wi.z <= 0.0 {
            return 0.0;
        }
        let d = self.d(m);
        if d == 0.0 {
            return 0.0;
        }
        d * self.g1_exact(wi, m) * wi.dot(m).max(0.0) / wi.z
    }

    /// Mitsuba's `MicrofacetDistribution::pdf` with `sample_visible = true`:
    /// `D(m) G1(wi, m) |wi·m| / cos θ_i` with Mitsuba's `G1` ([`Microfacet::g1`]). Equal to
    /// [`Microfacet::pdf_visible`] for GGX; for Beckmann it differs from the true sampling
    /// density by Mitsuba's `G1` fit (under 0.35%). 0 for `wi.z ≤ 0`.
    pub fn pdf_visible_mitsuba(&self, wi: Vec3, m: Vec3) -> f32 {
        if wi.z.is_nan() || wi.z <= 0.0 {
            return 0.0;
        }
        let d = self.d(m);
        if d == 0.0 {
            return 0.0;
        }
        d * self.g1(wi, m) * wi.dot(m).abs() / wi.z
    }

    /// Draws `m` with density `D(m) cos θ_m` ([`Microfacet::pdf_all`]), Mitsuba's sampler for
    /// `sample_visible = false`: azimuth first (uniform if isotropic, else
    /// `tan φ = (α_v/α_u) tan 2πu₂`), then the elevation by inverting the radial CDF for the
    /// roughness `α(φ)` along that azimuth. `None` if `m` lands on the horizon (`u₁ = 1`).
    pub fn sample_all(&self, u: Vec2) -> Option<Vec3> {
        let (au, av) = (self.alpha_u, self.alpha_v);
        let (sin_phi, cos_phi, alpha2) = if self.is_isotropic() {
            let (s, c) = (2.0 * PI * u.y).sin_cos();
            (s, c, au * au)
        } else {
            let tmp = (av / au) * (2.0 * PI * u.y).tan();
            // The quadrant of 2πu₂ decides the sign: cos φ > 0 on the first and last quarters.
            let cos_phi = (1.0 / (tmp * tmp + 1.0).sqrt()).copysign((u.y - 0.5).abs() - 0.25);
            let sin_phi = cos_phi * tmp;
            let a2 = 1.0 / ((cos_phi / au).powi(2) + (sin_phi / av).powi(2));
            (sin_phi, cos_phi, a2)
        };
        let cos_theta = match self.distribution {
            Distribution::Beckmann => 1.0 / (1.0 - alpha2 * (1.0 - u.x).ln()).sqrt(),
            Distribution::Ggx => {
                let tan2 = alpha2 * u.x / (1.0 - u.x);
                1.0 / (1.0 + tan2).sqrt()
            }
        };
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let m = Vec3::new(cos_phi * sin_theta, sin_phi * sin_theta, cos_theta);
        (m.z > 0.0 && m.is_finite()).then_some(m)
    }

    /// Density of [`Microfacet::sample_all`]: `D(m) cos θ_m` (Mitsuba's `pdf` with
    /// `sample_visible = false`).
    pub fn pdf_all(&self, m: Vec3) -> f32 {
        self.d(m) * m.z
    }
}

/// Visible slope `(x, y)` of the `α = 1` Beckmann surface seen at `cos θ = cos_theta > 0` from
/// azimuth 0: density `∝ e^{−x²−y²} max(0, cot θ − x)`.
///
/// Multiplying the `x` marginal by `tan θ`, its CDF is (up to the constant)
/// `h(x) = (√π/2) erfc(−x) + (tan θ/2) e^{−x²}` on `x ≤ cot θ`, increasing with
/// `h'(x) = e^{−x²} (1 − x tan θ)`. We solve `h(x) = h(lo) + u₁ (h(hi) − h(lo))` on
/// `[lo, hi] = [−8, min(cot θ, 8)]` by Newton's method, falling back to bisection whenever a
/// step would leave the bracket, until the step is below `10⁻¹²`.
fn beckmann_visible_slope_11(cos_theta: f64, u: Vec2) -> (f64, f64) {
    let half_sqrt_pi = 0.5 * std::f64::consts::PI.sqrt();
    let cos = cos_theta.min(1.0);
    let tan = (1.0 - cos * cos).max(0.0).sqrt() / cos;
    let h = |x: f64| half_sqrt_pi * erfc(-x) + 0.5 * tan * (-x * x).exp();
    let dh = |x: f64| (-x * x).exp() * (1.0 - x * tan);

    let (mut lo, mut hi) = (
        -SLOPE_MAX,
        if tan > 0.0 {
            (1.0 / tan).min(SLOPE_MAX)
        } else {
            SLOPE_MAX
        },
    );
    let (h_lo, h_hi) = (h(lo), h(hi));
    let target = h_lo + f64::from(u.x) * (h_hi - h_lo);
    // Start from the normal-incidence answer (exact when tan θ = 0).
    let mut x =
        erf_inv((2.0 * f64::from(u.x) - 1.0).clamp(-1.0 + 1e-15, 1.0 - 1e-15)).clamp(lo, hi);
    for _ in 0..200 {
        let f = h(x) - target;
        if f > 0.0 {
            hi = x;
        } else {
            lo = x;
        }
        let slope = dh(x);
        let newton = x - f / slope;
        let next = if newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        let step = (next - x).abs();
        x = next;
        if step <= 1e-12 * (1.0 + x.abs()) || hi - lo <= 1e-12 * (1.0 + x.abs()) {
            break;
        }
    }
    let y = erf_inv((2.0 * f64::from(u.y) - 1.0).clamp(-1.0 + 1e-15, 1.0 - 1e-15));
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    use std::path::Path;

    const DISTS: [Distribution; 2] = [Distribution::Beckmann, Distribution::Ggx];

    /// `(name, columns)` rows of `tests/data/microfacet/microfacet.csv`.
    fn fixture() -> Vec<(String, Vec<f32>)> {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/microfacet/microfacet.csv");
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        text.lines()
            .skip(1)
            .map(|line| {
                let mut it = line.split(',');
                let name = it.next().expect("name").to_owned();
                let vals = it
                    .map(|x| x.parse::<f64>().expect("number") as f32)
                    .collect();
                (name, vals)
            })
            .collect()
    }

    fn close(a: f32, b: f32, rel: f32, abs: f32) -> bool {
        (a.is_nan() && b.is_nan()) || (a - b).abs() <= abs + rel * a.abs().max(b.abs())
    }

    fn v3(r: &[f32], i: usize) -> Vec3 {
        Vec3::new(r[i], r[i + 1], r[i + 2])
    }

    /// `D`, `G1`, `G`, both pdfs and `sample_all` equal Mitsuba 3.9.1's at 432 points (both
    /// distributions, isotropic and anisotropic, `alpha = 1e-5` to check the clamp, normal to
    /// grazing `wi`, `wi` below the horizon for `G1`); GGX's `sample_visible` returns Mitsuba's
    /// normal for the same `u`. Tolerances are f32 rounding of differently ordered operations
    /// (1e-4 relative; sampled normals 2e-4 absolute).
    #[test]
    fn matches_mitsuba_fixture() {
        let rows = fixture();
        assert_eq!(rows.len(), 432);
        let mut beckmann_max_dev = 0.0_f32;
        for (name, r) in &rows {
            let dist = Distribution::from_name(name).expect("distribution");
            let mf = Microfacet::new(dist, r[0], r[1]);
            let (wi, m, wo) = (v3(r, 2), v3(r, 5), v3(r, 8));
            let u = Vec2::new(r[11], r[12]);
            let ctx = format!("{name} a=({}, {}) wi={wi} m={m} wo={wo} u={u}", r[0], r[1]);
            assert!(
                close(mf.d(m), r[13], 1e-4, 0.0),
                "D: {} vs {} at {ctx}",
                mf.d(m),
                r[13]
            );
            assert!(
                close(mf.g1(wi, m), r[14], 1e-5, 1e-7),
                "G1(wi): {} vs {} at {ctx}",
                mf.g1(wi, m),
                r[14]
            );
            assert!(close(mf.g1(wo, m), r[15], 1e-5, 1e-7), "G1(wo) at {ctx}");
            assert!(close(mf.g(wi, wo, m), r[16], 1e-5, 1e-7), "G at {ctx}");
            if wi.z <= 0.0 {
                continue;
            }
            let pdf = mf.pdf_visible_mitsuba(wi, m);
            assert!(
                close(pdf, r[17], 1e-4, 0.0),
                "pdf_visible_mitsuba: {pdf} vs {} at {ctx}",
                r[17]
            );
            assert!(close(mf.pdf_all(m), r[18], 1e-4, 0.0), "pdf_all at {ctx}");
            let sa = mf.sample_all(u).expect("sample_all");
            assert!(
                (sa - v3(r, 22)).abs().max_element() <= 2e-4,
                "sample_all {sa} vs {} at {ctx}",
                v3(r, 22)
            );
            let sv = mf.sample_visible(wi, u).expect("visible sample");
            // Mitsuba takes the azimuth of the stretched view as 0 when its sin²θ is at most
            // 4·2⁻²⁴ (`Frame3f::sincos_phi`); we use the true azimuth down to sin θ = 0 (exact
            // either way at normal incidence, ours also just off it), so such rows sample
            // differently rotated lobes and are not compared.
            let stretched = Vec3::new(mf.alpha_u() * wi.x, mf.alpha_v() * wi.y, wi.z).normalize();
            let same_frame = wi.x == 0.0 && wi.y == 0.0
                || stretched.x * stretched.x + stretched.y * stretched.y > 4.0 * f32::EPSILON / 2.0;
            if !same_frame {
                continue;
            }
            if dist == Distribution::Ggx {
                assert!(
                    close(mf.pdf_visible(wi, m), r[17], 1e-4, 0.0),
                    "GGX pdf_visible at {ctx}"
                );
                assert!(
                    (sv - v3(r, 19)).abs().max_element() <= 2e-4,
                    "sample_visible {sv} vs {} at {ctx}",
                    v3(r, 19)
                );
            } else {
                beckmann_max_dev = beckmann_max_dev.max((sv - v3(r, 19)).abs().max_element());
            }
        }
        // Mitsuba's three Newton steps land close to the exact inverse (measured: 6e-6 at
        // most): an error in our Beckmann sampler (rotation, stretch, CDF) would show.
        eprintln!("largest deviation of Beckmann normals from Mitsuba's: {beckmann_max_dev}");
        assert!(
            beckmann_max_dev <= 1e-4,
            "Beckmann normals differ from Mitsuba's by {beckmann_max_dev}"
        );
    }

    #[test]
    fn roughness_is_clamped_like_mitsuba() {
        let mf = Microfacet::new(Distribution::Ggx, 0.0, f32::NAN);
        assert_eq!((mf.alpha_u(), mf.alpha_v()), (MIN_ALPHA, MIN_ALPHA));
        assert!(mf.is_isotropic());
        assert_eq!(Distribution::from_name("GGX"), Some(Distribution::Ggx));
        assert_eq!(Distribution::from_name("phong"), None);
    }

    /// Composite Gauss–Legendre integration of `f` over the upper hemisphere, in
    /// `(w, φ)` with `tan θ = α w / (1 − w)`: the change of variable concentrates nodes on the
    /// lobe (width `α`) and maps the infinite slope range onto `[0, 1)`.
    fn integrate_hemisphere(
        f: &dyn Fn(Vec3) -> f64,
        alpha: f64,
        w_panels: usize,
        phi_panels: usize,
    ) -> f64 {
        integrate_region(
            f,
            alpha,
            (0.0, 1.0),
            (0.0, 2.0 * std::f64::consts::PI),
            w_panels,
            phi_panels,
        )
    }

    /// Gauss–Legendre nodes and weights on `[−1, 1]`, order 6.
    const GL6: [(f64, f64); 6] = [
        (-0.932_469_514_203_152, 0.171_324_492_379_170),
        (-0.661_209_386_466_265, 0.360_761_573_048_139),
        (-0.238_619_186_083_197, 0.467_913_934_572_691),
        (0.238_619_186_083_197, 0.467_913_934_572_691),
        (0.661_209_386_466_265, 0.360_761_573_048_139),
        (0.932_469_514_203_152, 0.171_324_492_379_170),
    ];

    /// The direction at `(w, φ)` and the Jacobian `dω / (dw dφ)`.
    fn direction(w: f64, phi: f64, alpha: f64) -> (Vec3, f64) {
        let t = alpha * w / (1.0 - w);
        let theta = t.atan();
        let dtheta_dw = alpha / ((1.0 - w) * (1.0 - w) * (1.0 + t * t));
        let (s, c) = theta.sin_cos();
        let dir = Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32);
        (dir, s * dtheta_dw)
    }

    fn integrate_region(
        f: &dyn Fn(Vec3) -> f64,
        alpha: f64,
        (w0, w1): (f64, f64),
        (p0, p1): (f64, f64),
        w_panels: usize,
        phi_panels: usize,
    ) -> f64 {
        let (hw, hp) = ((w1 - w0) / w_panels as f64, (p1 - p0) / phi_panels as f64);
        let mut total = 0.0;
        for i in 0..w_panels {
            for &(xw, ww) in &GL6 {
                let w = w0 + hw * (i as f64 + 0.5 + 0.5 * xw);
                let mut ring = 0.0;
                for j in 0..phi_panels {
                    for &(xp, wp) in &GL6 {
                        let phi = p0 + hp * (j as f64 + 0.5 + 0.5 * xp);
                        let (dir, jac) = direction(w, phi, alpha);
                        ring += wp * f(dir) * jac;
                    }
                }
                total += ww * ring;
            }
        }
        total * 0.25 * hw * hp
    }

    const ROUGHNESS: [(f32, f32); 5] = [
        (0.05, 0.05),
        (0.3, 0.3),
        (1.0, 1.0),
        (0.15, 0.6),
        (0.8, 0.2),
    ];

    /// `∫ D(m) cos θm dm = 1` (the normalisation every microfacet BSDF relies on), to 1e-4.
    #[test]
    fn d_is_normalised() {
        for dist in DISTS {
            for (au, av) in ROUGHNESS {
                let mf = Microfacet::new(dist, au, av);
                let alpha = f64::from(au.min(av));
                let total =
                    integrate_hemisphere(&|m| f64::from(mf.d(m)) * f64::from(m.z), alpha, 80, 32);
                assert!((total - 1.0).abs() < 1e-4, "{dist:?} ({au}, {av}): {total}");
                let all = integrate_hemisphere(&|m| f64::from(mf.pdf_all(m)), alpha, 80, 32);
                assert!(
                    (all - 1.0).abs() < 1e-4,
                    "{dist:?} ({au}, {av}) pdf_all: {all}"
                );
            }
        }
    }

    fn wis() -> [Vec3; 4] {
        let dir = |t: f32, p: f32| {
            let (t, p) = (t.to_radians(), p.to_radians());
            Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
        };
        [Vec3::Z, dir(40.0, 30.0), dir(75.0, 200.0), dir(88.0, 110.0)]
    }

    /// The visible-normal pdf integrates to 1 (with the exact `G1`) to 1e-4; Mitsuba's version
    /// with the Beckmann fit is within its stated 0.35% (and exactly ours for GGX).
    #[test]
    fn pdf_visible_is_normalised() {
        for dist in DISTS {
            for (au, av) in ROUGHNESS {
                let mf = Microfacet::new(dist, au, av);
                let alpha = f64::from(au.min(av));
                for wi in wis() {
                    let total =
                        integrate_hemisphere(&|m| f64::from(mf.pdf_visible(wi, m)), alpha, 80, 48);
                    assert!(
                        (total - 1.0).abs() < 1e-4,
                        "{dist:?} ({au}, {av}) wi {wi}: {total}"
                    );
                    let mts = integrate_hemisphere(
                        &|m| f64::from(mf.pdf_visible_mitsuba(wi, m)),
                        alpha,
                        80,
                        48,
                    );
                    assert!(
                        (mts - 1.0).abs() < 3.5e-3,
                        "{dist:?} ({au}, {av}) wi {wi}: Mitsuba's {mts}"
                    );
                }
            }
        }
    }

    /// Mitsuba's Beckmann `G1` fit is within 0.35% of the exact Smith function everywhere
    /// (the bound its comment states), and the GGX one is exact.
    #[test]
    fn beckmann_g1_fit_is_close_to_exact() {
        let mf = Microfacet::isotropic(Distribution::Beckmann, 1.0);
        let mut worst = 0.0_f32;
        for i in 1..2000 {
            let theta = (i as f32 / 2000.0) * PI / 2.0;
            let v = Vec3::new(theta.sin(), 0.0, theta.cos());
            let (fit, exact) = (mf.g1(v, Vec3::Z), mf.g1_exact(v, Vec3::Z));
            worst = worst.max((fit / exact - 1.0).abs());
        }
        assert!(
            worst < 3.5e-3 && worst > 1e-3,
            "worst relative error {worst}"
        );
        let ggx = Microfacet::isotropic(Distribution::Ggx, 0.4);
        let v = Vec3::new(0.6, 0.0, 0.8);
        assert_eq!(ggx.g1(v, Vec3::Z), ggx.g1_exact(v, Vec3::Z));
    }

    /// Pearson's chi-square statistic and p-value of `n` samples of `sample` against the density
    /// `pdf`, on a `12 × 16` grid in `(w, φ)` (see [`integrate_hemisphere`]) with cells of
    /// expected count below 5 pooled, and samples that fail (`None`) in their own cell with the
    /// mass the density leaves outside the hemisphere.
    fn chi2(
        sample: &dyn Fn(Vec2) -> Option<Vec3>,
        pdf: &dyn Fn(Vec3) -> f64,
        alpha: f64,
        n: usize,
        seed: u64,
    ) -> (f64, usize, f64) {
        const NW: usize = 12;
        const NP: usize = 16;
        let two_pi = 2.0 * std::f64::consts::PI;
        let mut observed = vec![0.0; NW * NP + 1];
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        for _ in 0..n {
            let u = Vec2::new(rng.random::<f32>(), rng.random::<f32>());
            match sample(u) {
                Some(m) => {
                    let t = f64::from(m.x).hypot(f64::from(m.y)) / f64::from(m.z) / alpha;
                    let w = t / (1.0 + t);
                    let phi = f64::from(m.y).atan2(f64::from(m.x)).rem_euclid(two_pi);
                    let iw = ((w * NW as f64) as usize).min(NW - 1);
                    let ip = ((phi / two_pi * NP as f64) as usize).min(NP - 1);
                    observed[iw * NP + ip] += 1.0;
                }
                None => observed[NW * NP] += 1.0,
            }
        }
        let mut expected = Vec::with_capacity(NW * NP + 1);
        for iw in 0..NW {
            for ip in 0..NP {
                let w = (iw as f64 / NW as f64, (iw + 1) as f64 / NW as f64);
                let p = (
                    ip as f64 * two_pi / NP as f64,
                    (ip + 1) as f64 * two_pi / NP as f64,
                );
                expected.push(n as f64 * integrate_region(pdf, alpha, w, p, 4, 2));
            }
        }
        let inside: f64 = expected.iter().sum();
        expected.push((n as f64 - inside).max(0.0));
        let (mut stat, mut cells, mut pool_o, mut pool_e) = (0.0, 0, 0.0, 0.0);
        for (o, e) in observed.iter().zip(&expected) {
            if *e < 5.0 {
                pool_o += o;
                pool_e += e;
            } else {
                stat += (o - e) * (o - e) / e;
                cells += 1;
            }
        }
        if pool_e > 0.0 {
            stat += (pool_o - pool_e) * (pool_o - pool_e) / pool_e.max(1.0);
            cells += 1;
        }
        let dof = cells - 1;
        let p = ChiSquared::new(dof as f64).expect("dof > 0").sf(stat);
        (stat, dof, p)
    }

    /// Significance level of each chi-square test below. Of the 30 tests (24 of
    /// `sample_visible`: 2 distributions × 3 roughnesses × 4 incident directions; 6 of
    /// `sample_all`), a correct sampler fails any for a random seed with probability at most
    /// 30 × 1e-6 = 3e-5 (union bound); the seeds are fixed, so the outcome is reproducible.
    const LEVEL: f64 = 1e-6;
    const N: usize = 200_000;

    /// The visible-normal sampler draws from `pdf_visible`. Power: a density `(1 + ε)` times too
    /// high on a region of probability `w` (compensated elsewhere) gives the statistic a
    /// non-centrality `N ε² w / (1 − w)`; with `N = 200 000`, `ε = 5%`, `w = 20%` that is 125,
    /// rejected at level 1e-6 with probability 0.72–0.95 (190–100 degrees of freedom), and
    /// `ε = 6.5%` (200) with probability above 0.99. The must-fail test below checks the
    /// teeth directly.
    #[test]
    fn sample_visible_has_density_pdf_visible() {
        let mut seed = 1;
        for dist in DISTS {
            for (au, av) in [(0.1, 0.1), (0.5, 0.5), (0.15, 0.6)] {
                let mf = Microfacet::new(dist, au, av);
                for wi in wis() {
                    seed += 1;
                    let (stat, dof, p) = chi2(
                        &|u| mf.sample_visible(wi, u),
                        &|m| f64::from(mf.pdf_visible(wi, m)),
                        f64::from(au.min(av)),
                        N,
                        seed,
                    );
                    assert!(
                        p >= LEVEL,
                        "{dist:?} ({au}, {av}) wi {wi}: chi2 {stat:.1} on {dof} dof, p = {p:.2e}"
                    );
                }
            }
        }
    }

    /// The chi-square test has teeth: a sampler for roughness 0.1 is rejected against the pdf
    /// of roughness 0.105, and Beckmann samples against the GGX pdf.
    #[test]
    fn chi2_rejects_a_wrong_density() {
        let wi = wis()[1];
        for dist in DISTS {
            let sampler = Microfacet::isotropic(dist, 0.1);
            let wrong = Microfacet::isotropic(dist, 0.105);
            let (stat, dof, p) = chi2(
                &|u| sampler.sample_visible(wi, u),
                &|m| f64::from(wrong.pdf_visible(wi, m)),
                0.1,
                N,
                7,
            );
            assert!(
                p < LEVEL,
                "{dist:?}: 5% roughness error not detected: chi2 {stat:.1} on {dof} dof"
            );
        }
        let b = Microfacet::isotropic(Distribution::Beckmann, 0.3);
        let g = Microfacet::isotropic(Distribution::Ggx, 0.3);
        let (_, _, p) = chi2(
            &|u| b.sample_visible(wi, u),
            &|m| f64::from(g.pdf_visible(wi, m)),
            0.3,
            N,
            8,
        );
        assert!(p < LEVEL);
    }

    /// `sample_all` draws from `pdf_all` (same test and level as above, 6 more tests:
    /// anisotropic included, which exercises Mitsuba's azimuth formula).
    #[test]
    fn sample_all_has_density_pdf_all() {
        let mut seed = 100;
        for dist in DISTS {
            for (au, av) in [(0.1, 0.1), (0.5, 0.5), (0.15, 0.6)] {
                seed += 1;
                let mf = Microfacet::new(dist, au, av);
                let (stat, dof, p) = chi2(
                    &|u| mf.sample_all(u),
                    &|m| f64::from(mf.pdf_all(m)),
                    f64::from(au.min(av)),
                    N,
                    seed,
                );
                assert!(
                    p >= LEVEL,
                    "{dist:?} ({au}, {av}): chi2 {stat:.1} on {dof} dof, p = {p:.2e}"
                );
            }
        }
    }

    /// Samples are unit vectors above the horizon that `wi` can see, for extreme inputs too.
    #[test]
    fn visible_samples_are_visible() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        for dist in DISTS {
            for (au, av) in [(1e-4, 1e-4), (0.02, 2.0), (3.0, 3.0)] {
                let mf = Microfacet::new(dist, au, av);
                for wi in wis()
                    .into_iter()
                    .chain([Vec3::new(1.0, 0.0, 1e-6).normalize()])
                {
                    for k in 0..2000 {
                        let u = match k {
                            0 => Vec2::ZERO,
                            1 => Vec2::splat(1.0 - f32::EPSILON / 2.0),
                            _ => Vec2::new(rng.random::<f32>(), rng.random::<f32>()),
                        };
                        if let Some(m) = mf.sample_visible(wi, u) {
                            assert!((m.length() - 1.0).abs() < 1e-5 && m.z > 0.0, "{m}");
                            assert!(
                                wi.dot(m) > -1e-4,
                                "{dist:?} ({au}, {av}) wi {wi} u {u}: m {m} faces away"
                            );
                        }
                    }
                }
                assert!(
                    mf.sample_visible(Vec3::new(0.0, 0.6, -0.8), Vec2::splat(0.5))
                        .is_none()
                );
            }
        }
    }
}
