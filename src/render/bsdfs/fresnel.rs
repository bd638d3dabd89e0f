//! Fresnel reflectance of smooth interfaces, as Mitsuba 3.9.1 computes it
//! (`include/mitsuba/render/fresnel.h`).
//!
//! Every BSDF that reflects off an interface (`dielectric`, `thindielectric`, `plastic`,
//! `conductor` and their rough versions, per microfacet) weights by one of these, so any
//! difference from Mitsuba would show up as a bias in every such image. All three are
//! unpolarised (the average of the s and p intensities), as in Mitsuba's non-polarised variants.
//!
//! # Conventions
//!
//! * `cos_theta_i` is the cosine between the incident direction and the interface normal; for
//!   dielectrics its sign says on which side the direction lies (`≥ 0`: outside, where the normal
//!   points).
//! * `eta` is the relative index `η_inside / η_outside` (Mitsuba's `int_ior / ext_ior`).
//! * Conductors take the complex index `η + i k` per colour channel, with Mitsuba's sign
//!   convention (`k ≥ 0` absorbs).

use glam::Vec3;

/// Unpolarised Fresnel reflectance of a smooth dielectric interface (Mitsuba's `fresnel`).
///
/// `cos_theta_i` is `wi·n` (its sign says which side `wi` is on: `≥ 0` is outside) and `eta` is
/// `int_ior / ext_ior`, with Mitsuba's
/// precedence at the corners (index-matched beats grazing; `−0` is outside). Returns
/// `(F, cos_theta_t, eta_it, eta_ti)`:
/// * `F` — reflectance (1 under total internal reflection and at grazing incidence, 0 for an
///   index-matched interface — even at grazing incidence);
/// * `cos_theta_t` — signed cosine of the refracted direction (opposite sign to `cos_theta_i`,
///   0 under total internal reflection);
/// * `eta_it` — relative index `η_t/η_i` seen from `wi`'s side (`eta` outside, `1/eta` inside);
/// * `eta_ti` — its reciprocal, also the factor scaling the tangential part of the refracted
///   direction.
pub fn fresnel_dielectric(cos_theta_i: f32, eta: f32) -> (f32, f32, f32, f32) {
    let outside = cos_theta_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    let cos_i = cos_theta_i.abs().min(1.0);
    // Snell: sin θt = η_ti sin θi; a negative cos²θt is total internal reflection, where
    // cos θt = 0 makes the amplitudes below ±1 (F = 1).
    let cos_t_sqr = 1.0 - (1.0 - cos_i * cos_i) * (eta_ti * eta_ti);
    let cos_t = cos_t_sqr.max(0.0).sqrt();
    let f = if eta == 1.0 {
        // Index-matched: no interface, even at grazing incidence.
        0.0
    } else if cos_i == 0.0 {
        1.0
    } else {
        // Amplitude coefficients for s and p polarisation, both relative to the incident side.
        let a_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
        let a_p = (cos_t - eta_it * cos_i) / (cos_t + eta_it * cos_i);
        0.5 * (a_s * a_s + a_p * a_p)
    };
    // The sign opposite to cos θi's sign bit, as Mitsuba's `mulsign_neg` (cos θi = −0 gives +).
    let cos_t_signed = if cos_theta_i.is_sign_negative() {
        cos_t
    } else {
        -cos_t
    };
    (f, cos_t_signed, eta_it, eta_ti)
}

/// Unpolarised Fresnel reflectance of a conductor with complex relative index `eta + i k`, per
/// colour channel (Mitsuba's `fresnel_conductor`).
///
/// Light arrives from the dielectric side: Mitsuba assumes `cos_theta_i ≥ 0`, and we use
/// `|cos_theta_i|` so that a direction rounded just below the facet gets the grazing value
/// instead of a reflectance above one. Mitsuba's `material="none"` (`eta = 0`, `k = 1`) gives
/// exactly 1 at every angle.
pub fn fresnel_conductor(cos_theta_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    Vec3::new(
        fresnel_conductor_channel(cos_theta_i, eta.x, k.x),
        fresnel_conductor_channel(cos_theta_i, eta.y, k.y),
        fresnel_conductor_channel(cos_theta_i, eta.z, k.z),
    )
}

/// One channel of [`fresnel_conductor`]: the closed form for an absorbing medium in which the
/// transmitted wave's complex cosine is written through `a² + b² = |η̃² − sin²θi|` and
/// `a = Re √(η̃² − sin²θi)` (the form in Moeller, "Optics", 1988, that Mitsuba uses).
fn fresnel_conductor_channel(cos_theta_i: f32, eta: f32, k: f32) -> f32 {
    let c = cos_theta_i.abs();
    let c2 = c * c;
    let s2 = 1.0 - c2;
    let s4 = s2 * s2;
    // Re(η̃²) − sin²θi, and the modulus |η̃² − sin²θi| = a² + b².
    let re = eta * eta - k * k - s2;
    let a2_plus_b2 = (re * re + 4.0 * eta * eta * k * k).max(0.0).sqrt();
    let a = (0.5 * (a2_plus_b2 + re)).max(0.0).sqrt();
    // s polarisation.
    let t1 = a2_plus_b2 + c2;
    let t2 = 2.0 * c * a;
    let r_s = (t1 - t2) / (t1 + t2);
    // p polarisation, expressed relative to r_s.
    let t3 = a2_plus_b2 * c2 + s4;
    let t4 = t2 * s2;
    let r_p = r_s * (t3 - t4) / (t3 + t4);
    0.5 * (r_s + r_p)
}

/// Diffuse Fresnel reflectance `F_dr(η)`: the fraction of uniformly diffuse (cosine-weighted)
/// light reflected by a smooth interface of relative index `eta`, seen from the side where the
/// relative index is `eta` (Mitsuba's `fresnel_diffuse_reflectance`).
///
/// Mitsuba does not integrate: it uses two published polynomial fits, Egan & Hilgeman (1973)
/// for `eta < 1` and d'Eon & Irving (2011, "A quantized-diffusion model for rendering
/// translucent materials") for `eta ≥ 1`. We use the same fits with the same coefficients, so
/// `plastic`'s internal-reflection factor `1 / (1 − F_dr(1/η))` matches Mitsuba's (the fits are
/// accurate to about 0.1% for `η ∈ [1, 2]`, but matching Mitsuba matters more than the truth).
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let inv_eta = 1.0 / eta;
    if eta < 1.0 {
        // Egan & Hilgeman: −1.4399 η² + 0.7099 η + 0.6681 + 0.0636 / η.
        0.0636_f32.mul_add(inv_eta, eta.mul_add(eta.mul_add(-1.4399, 0.7099), 0.6681))
    } else {
        // d'Eon & Irving: a polynomial of degree 5 in 1/η, evaluated by Horner's rule.
        const C: [f32; 6] = [0.919317, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881];
        C.iter().rev().fold(0.0, |acc, &c| acc.mul_add(inv_eta, c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Rows of a numeric CSV fixture under `tests/data/fresnel/` (header skipped).
    fn fixture(name: &str) -> Vec<Vec<f32>> {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/fresnel")
            .join(name);
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        text.lines()
            .skip(1)
            .map(|line| {
                line.split(',')
                    .map(|x| x.parse::<f64>().expect("number") as f32)
                    .collect()
            })
            .collect()
    }

    /// Relative tolerance `rel`, plus 1e-9 absolute for reflectances near 0 (index-matched
    /// interfaces), where f32 cancellation leaves only a few correct digits.
    fn close(a: f32, b: f32, rel: f32) -> bool {
        (a - b).abs() <= rel * a.abs().max(b.abs()) + 1e-9
    }

    /// Against `mi.fresnel` on both sides of the interface, with TIR, grazing and index-matched
    /// cases (`tests/data/fresnel/make_fixture.py`). The tolerance
    /// (1e-4 relative on F, 1e-6 absolute on cos θt) covers f32 cancellation in `1 − cos²θt`
    /// for nearly index-matched interfaces at grazing angles, where Mitsuba's fused
    /// multiply-adds round differently; a wrong side convention or swapped `eta_it` misses by
    /// far more.
    #[test]
    fn dielectric_matches_mitsuba() {
        let rows = fixture("dielectric.csv");
        assert_eq!(rows.len(), 140);
        for r in rows {
            let (f, ct, eit, eti) = fresnel_dielectric(r[0], r[1]);
            let ok = close(f, r[2], 1e-4)
                && (ct - r[3]).abs() <= 1e-6
                && close(eit, r[4], 1e-6)
                && close(eti, r[5], 1e-6);
            assert!(
                ok,
                "cos {} eta {}: ours {:?}, Mitsuba {:?}",
                r[0],
                r[1],
                (f, ct, eit, eti),
                &r[2..]
            );
        }
    }

    /// Against `mi.fresnel_conductor`, including `none` (eta 0, k 1), which must be exactly 1.
    #[test]
    fn conductor_matches_mitsuba() {
        let rows = fixture("conductor.csv");
        assert_eq!(rows.len(), 70);
        for r in rows {
            let f = fresnel_conductor(r[0], Vec3::splat(r[1]), Vec3::splat(r[2]));
            assert!(
                close(f.x, r[3], 2e-5),
                "cos {} eta {} k {}: ours {}, Mitsuba {}",
                r[0],
                r[1],
                r[2],
                f.x,
                r[3]
            );
            assert_eq!(f.x, f.z);
            if r[1] == 0.0 && r[2] == 1.0 {
                assert_eq!(f, Vec3::ONE, "the none material must reflect everything");
            }
        }
        // Channels are independent.
        let f = fresnel_conductor(0.5, Vec3::new(0.2, 1.5, 0.0), Vec3::new(3.0, 0.0, 1.0));
        assert_eq!(f.y, fresnel_conductor_channel(0.5, 1.5, 0.0));
        assert_eq!(f.z, 1.0);
    }

    /// A conductor with `k = 0` is a dielectric seen from outside.
    #[test]
    fn conductor_without_absorption_is_dielectric() {
        for c in [1.0, 0.8, 0.5, 0.2, 0.05] {
            let fc = fresnel_conductor_channel(c, 1.5, 0.0);
            let (fd, ..) = fresnel_dielectric(c, 1.5);
            assert!(close(fc, fd, 1e-5), "cos {c}: {fc} vs {fd}");
        }
    }

    /// Against `mi.fresnel_diffuse_reflectance` on both branches of the fit.
    #[test]
    fn diffuse_reflectance_matches_mitsuba() {
        let rows = fixture("diffuse.csv");
        assert_eq!(rows.len(), 16);
        for r in rows {
            let f = fresnel_diffuse_reflectance(r[0]);
            assert!(
                close(f, r[1], 1e-5),
                "eta {}: ours {f}, Mitsuba {}",
                r[0],
                r[1]
            );
        }
    }

    /// The fit is close to the true hemispherical average `2 ∫ F(μ) μ dμ` (so a wrong
    /// coefficient would show), to the accuracy its authors state (under 1% for η ≤ 2).
    #[test]
    fn diffuse_reflectance_is_the_cosine_weighted_average() {
        for eta in [1.2_f32, 1.5, 1.9, 1.0 / 1.5, 1.0 / 1.2] {
            let n = 20_000;
            let integral: f64 = (0..n)
                .map(|i| {
                    let mu = (i as f64 + 0.5) / n as f64;
                    2.0 * fresnel_dielectric(mu as f32, eta).0 as f64 * mu / n as f64
                })
                .sum();
            let fit = fresnel_diffuse_reflectance(eta) as f64;
            assert!(
                (fit - integral).abs() <= 0.01 * integral,
                "eta {eta}: fit {fit}, integral {integral}"
            );
        }
    }
}
