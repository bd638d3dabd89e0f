//! Numerical helpers shared by the generators: the normal CDF in a form that stays accurate in
//! the far lower tail, uniform variates built straight from the generator's bits, and a small
//! Gauss-Legendre rule for the one moment formula that cancels catastrophically in closed form.

use std::sync::OnceLock;

use statrs::function::erf::erfc;

/// ln(sqrt(2 pi)), the log normalising constant of the standard normal density.
const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;

/// Below this argument `ln_norm_cdf` switches from `erfc` (which underflows near -37) to the
/// continued fraction of the Mills ratio, which converges fast out here.
const MILLS_CF_BELOW: f64 = -10.0;

/// Terms of the Mills-ratio continued fraction; at |x| >= 10 sixty terms reach full precision
/// (checked against the erfc form in the unit tests).
const MILLS_CF_TERMS: u32 = 60;

/// 2^-53: spacing of the 53-bit uniforms.
const TWO_POW_M53: f64 = 1.0 / 9_007_199_254_740_992.0;

/// A uniform variate on [0, 1) with 53 random bits. One `next_u64`, no rejection: this is the
/// variate mixtures compare against their cumulative weights and inverse transforms invert.
#[inline(always)]
pub(crate) fn unit_f64<R: rand::Rng + ?Sized>(rng: &mut R) -> f64 {
    (rng.next_u64() >> 11) as f64 * TWO_POW_M53
}

/// Standard normal CDF, relative accuracy kept in the lower tail (statrs' `erfc` is relative).
pub(crate) fn norm_cdf(x: f64) -> f64 {
    0.5 * erfc(-x * std::f64::consts::FRAC_1_SQRT_2)
}

/// Standard normal survival function, computed directly rather than as `1 - cdf`.
pub(crate) fn norm_sf(x: f64) -> f64 {
    0.5 * erfc(x * std::f64::consts::FRAC_1_SQRT_2)
}

/// Mills ratio `(1 - Phi(y)) / phi(y)` for large positive `y`, by its continued fraction
/// `1 / (y + 1 / (y + 2 / (y + 3 / ...)))` evaluated from the tail.
fn mills_cf(y: f64) -> f64 {
    let mut f = y;
    for k in (1..=MILLS_CF_TERMS).rev() {
        f = y + f64::from(k) / f;
    }
    1.0 / f
}

/// `ln Phi(x)` for every `x`: needed because the truncated lognormal moments are ratios of
/// normal CDFs that may each underflow while their ratio is perfectly ordinary.
pub(crate) fn ln_norm_cdf(x: f64) -> f64 {
    if x.is_nan() {
        f64::NAN
    } else if x > 0.0 {
        (-norm_sf(x)).ln_1p()
    } else if x > MILLS_CF_BELOW {
        norm_cdf(x).ln()
    } else {
        -0.5 * x * x - LN_SQRT_2PI + mills_cf(-x).ln()
    }
}

/// Number of Gauss-Legendre nodes per panel.
const GL_NODES: usize = 10;

/// Nodes and weights of the `GL_NODES`-point Gauss-Legendre rule on [-1, 1], found once by
/// Newton's method on the Legendre polynomial (no tables to transcribe).
fn gauss_legendre() -> &'static [(f64, f64); GL_NODES] {
    static RULE: OnceLock<[(f64, f64); GL_NODES]> = OnceLock::new();
    RULE.get_or_init(|| {
        let n = GL_NODES;
        let mut rule = [(0.0, 0.0); GL_NODES];
        for (i, slot) in rule.iter_mut().enumerate() {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                // Legendre recurrence: p_k = ((2k - 1) x p_{k-1} - (k - 1) p_{k-2}) / k.
                let (mut p_prev, mut p) = (1.0, x);
                for k in 2..=n {
                    let kf = k as f64;
                    let p_next = ((2.0 * kf - 1.0) * x * p - (kf - 1.0) * p_prev) / kf;
                    p_prev = p;
                    p = p_next;
                }
                dp = n as f64 * (x * p - p_prev) / (x * x - 1.0);
                let step = p / dp;
                x -= step;
                if step.abs() < 1e-16 {
                    break;
                }
            }
            *slot = (x, 2.0 / ((1.0 - x * x) * dp * dp));
        }
        rule
    })
}

/// Composite Gauss-Legendre integral of `f` over [a, b] with `panels` equal panels.
pub(crate) fn integrate(f: impl Fn(f64) -> f64, a: f64, b: f64, panels: usize) -> f64 {
    let rule = gauss_legendre();
    let h = (b - a) / panels as f64;
    let mut total = 0.0;
    for j in 0..panels {
        let mid = a + (j as f64 + 0.5) * h;
        let mut s = 0.0;
        for &(x, w) in rule {
            s += w * f(mid + 0.5 * h * x);
        }
        total += 0.5 * h * s;
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        // A 10-point rule is exact up to degree 19.
        let got = integrate(|x| x.powi(19) + 3.0 * x.powi(18) - x, -1.0, 1.0, 1);
        assert!((got - 6.0 / 19.0).abs() < 1e-14, "{got}");
        let got = integrate(|x| (-x).exp(), 0.0, 5.0, 4);
        assert!((got + (-5.0f64).exp_m1()).abs() < 1e-15, "{got}");
    }

    #[test]
    fn mills_continued_fraction_matches_erfc_form() {
        for y in [10.0f64, 12.0, 20.0, 30.0] {
            let direct = norm_sf(y) / ((-0.5 * y * y).exp() / (2.0 * std::f64::consts::PI).sqrt());
            let rel = (mills_cf(y) - direct).abs() / direct;
            assert!(rel < 1e-13, "y={y} cf={} erfc={direct}", mills_cf(y));
        }
        // Both branches of ln_norm_cdf agree where they meet.
        let below = ln_norm_cdf(MILLS_CF_BELOW - 1e-12);
        let above = ln_norm_cdf(MILLS_CF_BELOW + 1e-12);
        assert!(
            (below - above).abs() < 1e-10 * above.abs(),
            "{below} {above}"
        );
    }

    #[test]
    fn ln_norm_cdf_far_tail_and_limits() {
        // ln Phi(-40) = -800 - ln 40 - ln sqrt(2 pi) + ln(1 - 1/y^2 + 3/y^4 - 15/y^6 + ...) with
        // y^2 = 1600, well past the point where erfc underflows.
        let x = -40.0f64;
        let y2: f64 = 1600.0;
        let series = 1.0 - 1.0 / y2 + 3.0 / (y2 * y2) - 15.0 / (y2 * y2 * y2);
        let expected = -800.0 - 40f64.ln() - LN_SQRT_2PI + series.ln();
        assert!((ln_norm_cdf(x) - expected).abs() < 1e-9);
        assert_eq!(ln_norm_cdf(f64::NEG_INFINITY), f64::NEG_INFINITY);
        assert_eq!(ln_norm_cdf(f64::INFINITY), 0.0);
        assert!(ln_norm_cdf(f64::NAN).is_nan());
        assert!((norm_cdf(0.0) - 0.5).abs() < 1e-16);
    }
}
