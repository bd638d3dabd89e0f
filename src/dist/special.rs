//! Numerical helpers shared by the generators: a full-precision normal CDF that stays
//! accurate in the far lower tail, uniform variates built straight from the generator's bits,
//! and a small Gauss-Legendre rule for the one moment formula that cancels in closed form.
//!
//! The normal CDF is computed here rather than through statrs 0.19.1, whose `erfc` carries a
//! relative error of ~1e-10 (its interval constants were transcribed to 10 digits; see
//! statrs-dev/statrs pull request 412). The unit tests check it against high-precision
//! reference values to 1e-14 and against statrs to its own 1e-9.

use std::sync::OnceLock;

/// ln(sqrt(2 pi)), the log normalising constant of the standard normal density.
const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;

/// 1 / sqrt(2 pi).
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// Below this |x| the CDF comes from its power series, above it from the Mills ratio.
const SERIES_BELOW: f64 = 1.5;

/// 2^-53: spacing of the 53-bit uniforms.
const TWO_POW_M53: f64 = 1.0 / 9_007_199_254_740_992.0;

/// A uniform variate on [0, 1) with 53 random bits. One `next_u64`, no rejection: this is the
/// variate mixtures compare against their cumulative weights and inverse transforms invert.
#[inline(always)]
pub(crate) fn unit_f64<R: rand::Rng + ?Sized>(rng: &mut R) -> f64 {
    (rng.next_u64() >> 11) as f64 * TWO_POW_M53
}

/// `-x^2 / 2` as an unevaluated sum `hi + lo`: the rounding of `x * x` would otherwise cost
/// ~x^2 ulps once exponentiated (hundreds of ulps in the far tail).
fn half_square(x: f64) -> (f64, f64) {
    let h = x * x;
    if !h.is_finite() {
        return (-0.5 * h, 0.0);
    }
    let l = x.mul_add(x, -h);
    (-0.5 * h, -0.5 * l)
}

/// Standard normal density.
fn norm_pdf(x: f64) -> f64 {
    let (hi, lo) = half_square(x);
    hi.exp() * (1.0 + lo) * FRAC_1_SQRT_2PI
}

/// Mills ratio `(1 - Phi(y)) / phi(y)` for `y >= SERIES_BELOW`, by its continued fraction
/// `1 / (y + 1 / (y + 2 / (y + 3 / ...)))` evaluated from the tail. The term counts reach full
/// precision (the fraction converges faster the larger `y` is).
fn mills(y: f64) -> f64 {
    let terms = if y >= 5.0 {
        50
    } else if y >= 2.5 {
        120
    } else {
        280
    };
    let mut f = y;
    for k in (1..=terms).rev() {
        f = y + f64::from(k) / f;
    }
    1.0 / f
}

/// `(Phi(x) - 1/2) / phi(x) = sum x^(2k+1) / (1 * 3 * ... * (2k+1))`: all terms share the sign
/// of `x`, so nothing cancels.
fn centre_series(x: f64) -> f64 {
    let x2 = x * x;
    let (mut term, mut sum) = (x, x);
    let mut k = 1.0;
    while term.abs() > 1e-17 * sum.abs() {
        k += 2.0;
        term *= x2 / k;
        sum += term;
    }
    sum
}

/// Standard normal survival function `1 - Phi(x)`, computed directly with relative accuracy
/// ~1e-15 wherever it does not underflow.
pub(crate) fn norm_sf(x: f64) -> f64 {
    if x.is_nan() {
        f64::NAN
    } else if x >= SERIES_BELOW {
        norm_pdf(x) * mills(x)
    } else if x <= -SERIES_BELOW {
        1.0 - norm_pdf(x) * mills(-x)
    } else {
        0.5 - norm_pdf(x) * centre_series(x)
    }
}

/// The standard normal quantile `Phi^-1(p) = -sqrt(2) erfc^-1(2p)`, accurate far into the lower
/// tail (statrs' inverse complementary error function).
pub(crate) fn norm_inv_cdf(p: f64) -> f64 {
    -std::f64::consts::SQRT_2 * statrs::function::erf::erfc_inv(2.0 * p)
}

/// Standard normal CDF, relative accuracy ~1e-15 in the lower tail.
pub(crate) fn norm_cdf(x: f64) -> f64 {
    norm_sf(-x)
}

/// `ln Phi(x)` for every `x`: the truncated lognormal moments are ratios of normal CDFs that
/// may each underflow while their ratio is perfectly ordinary.
pub(crate) fn ln_norm_cdf(x: f64) -> f64 {
    if x.is_nan() {
        f64::NAN
    } else if x >= 0.0 {
        (-norm_sf(x)).ln_1p()
    } else if x > -SERIES_BELOW {
        norm_cdf(x).ln()
    } else {
        let (hi, lo) = half_square(x);
        hi + lo - LN_SQRT_2PI + mills(-x).ln()
    }
}

/// Number of Gauss-Legendre nodes per panel.
const GL_NODES: usize = 10;

/// Nodes and weights of the `n`-point Gauss-Legendre rule on [-1, 1], found by Newton's method
/// on the Legendre polynomial from Tricomi's initial guesses (no tables to transcribe).
pub(crate) fn gauss_legendre_rule(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
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
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// The `GL_NODES`-point rule, found once.
fn gauss_legendre() -> &'static [(f64, f64)] {
    static RULE: OnceLock<Vec<(f64, f64)>> = OnceLock::new();
    RULE.get_or_init(|| gauss_legendre_rule(GL_NODES))
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

    /// Reference values of Phi(x) from 30-digit arithmetic (mpmath `ncdf`).
    const PHI_REFERENCE: [(f64, f64); 10] = [
        (-0.3, 0.382_088_577_811_047_4),
        (0.5, 0.691_462_461_274_013_1),
        (-1.0, 0.158_655_253_931_457_05),
        (-1.4999, 0.066_820_153_999_833_6),
        (-1.5, 0.066_807_201_268_858_07),
        (-2.0, 0.022_750_131_948_179_21),
        (-3.0, 0.001_349_898_031_630_094_5),
        (-5.0, 2.866_515_718_791_939e-7),
        (-10.0, 7.619_853_024_160_526e-24),
        (-20.0, 2.753_624_118_606_233_7e-89),
    ];

    #[test]
    fn normal_cdf_matches_high_precision_reference() {
        for (x, phi) in PHI_REFERENCE {
            let rel = (norm_cdf(x) - phi).abs() / phi;
            assert!(rel < 1e-14, "x={x}: {} vs {phi} (rel {rel:e})", norm_cdf(x));
            let rel = (ln_norm_cdf(x) - phi.ln()).abs() / phi.ln().abs();
            assert!(rel < 1e-14, "ln Phi({x})");
        }
        let rel = (norm_sf(6.0) - 9.865_876_450_376_98e-10).abs() / 9.865_876_450_376_98e-10;
        assert!(rel < 1e-14);
        // statrs agrees to its own ~1e-10 accuracy.
        for x in [-30.0, -8.0, -2.2, -0.7, 0.0, 0.9, 1.7, 4.0] {
            let oracle = 0.5 * statrs::function::erf::erfc(-x / std::f64::consts::SQRT_2);
            assert!((norm_cdf(x) - oracle).abs() <= 1e-9 * oracle, "x={x}");
        }
    }

    #[test]
    fn ln_norm_cdf_far_tail_and_limits() {
        // Far past the point where Phi underflows (30-digit references).
        assert!((ln_norm_cdf(-40.0) + 804.608_442_013_753_8).abs() < 1e-12);
        assert!((ln_norm_cdf(-100.0) + 5_005.524_208_694_205).abs() < 1e-11);
        assert_eq!(ln_norm_cdf(f64::NEG_INFINITY), f64::NEG_INFINITY);
        assert_eq!(ln_norm_cdf(f64::INFINITY), 0.0);
        assert!(ln_norm_cdf(f64::NAN).is_nan());
        assert!((norm_cdf(0.0) - 0.5).abs() < 1e-16);
    }
}
