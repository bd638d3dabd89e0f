//! Hard numerical cases for the mean, clamp, MoN family and Jung (docs/estimators.md §1–§4): extreme
//! magnitudes, degenerate streams (all zeros, one sample, n < M, n not divisible by M), long
//! streams where compensated summation matters, a single enormous outlier, empty streams and
//! reset. Expected values are worked out by hand in the comments, not taken from the crate.

use fireflies::estimators::{
    Bank, Estimator, EstimatorSpec, Extra, GiniDiagnostic, Gmon, GmonB, Jung, Mean, Mon,
};

use crate::common;
use common::{REL, S, assert_rel};

fn run(spec: &str, xs: &[f64]) -> Box<dyn Estimator> {
    let mut e = spec
        .parse::<EstimatorSpec>()
        .and_then(|s| s.build())
        .unwrap_or_else(|err| panic!("{spec}: {err}"));
    e.push_slice(xs);
    e
}

fn est(spec: &str, xs: &[f64]) -> f64 {
    run(spec, xs)
        .estimate()
        .unwrap_or_else(|err| panic!("{spec}: {err}"))
}

fn extra(e: &dyn Estimator, key: &str) -> Option<Extra> {
    e.extras()
        .into_iter()
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v)
}

/// Every estimator in scope, with parameters that exercise their decisions.
const ALL: &[&str] = &[
    "mean",
    "clamp:c=10",
    "mon:M=1",
    "mon:M=4",
    "mon:M=21",
    "gini:M=4",
    "gini:M=21",
    "gmonb:M=4",
    "gmonb:M=21,threshold=0.9",
    "gmon:M=3",
    "gmon:M=21",
    "jung:sigma_image=40",
    "jung:sigma_image=0.5,m_max=5",
];

// Extreme magnitudes ----------------------------------------------------------------------------

#[test]
fn decimal_values_near_1e300() {
    // Pattern (1, 1, 1, 5) x 1e300, 250 times: n = 1000, n * max = 5e303 < 1e307 (docs/estimators.md §1).
    // M = 4 puts each position in its own set: theta = (1, 1, 1, 5)e300.
    // MoN = 1e300; mean = 2e300; s1 = 8, s2 = 1 + 2 + 3 + 20 = 26, G = 52/32 - 5/4 = 0.375;
    // G-MoN: k = 2, c = floor(0.75) = 0 -> mean of set means 2e300; G-MoN_b(0.25) -> MoN.
    let xs: Vec<f64> = [1e300, 1e300, 1e300, 5e300].repeat(250);
    assert_rel(est("mean", &xs), 2e300, REL);
    assert_rel(est("clamp:c=2e300", &xs), 1.25e300, REL);
    assert_rel(est("mon:M=4", &xs), 1e300, REL);
    assert_rel(est("gini:M=4", &xs), 0.375, REL);
    assert_rel(est("gmon:M=4", &xs), 2e300, REL);
    assert_rel(est("gmonb:M=4", &xs), 1e300, REL);
    assert_rel(est("gmonb:M=4,threshold=0.5", &xs), 2e300, REL);
    // M = 3 mixes the pattern: every set holds 1e300 and 5e300 in proportions 3:1 give or
    // take one sample, so all estimates stay finite and within [1e300, 5e300].
    for spec in ["mon:M=3", "gmon:M=3", "gmonb:M=3", "mon:M=21", "gmon:M=21"] {
        let e = est(spec, &xs);
        assert!((1e300..=5e300).contains(&e), "{spec} = {e:e}");
    }
}

#[test]
fn running_example_scaled_near_1e300_and_1e_minus_300() {
    // Scaling by a power of two is exact, so every estimate but Jung's must be exactly the
    // scaled spec value; against the spec's decimals, 1e-12 relative.
    // 2^995 = 3.3e299: max 1.2e302. 2^-997 = 7.5e-301: min non-zero 4.5e-301 (normal).
    for k in [995, -997] {
        let s = 2f64.powi(k);
        let xs: Vec<f64> = S.iter().map(|x| x * s).collect();
        let expected = [
            ("mean", 51.885714285714286),
            ("mon:M=5", 2.8),
            ("gmon:M=5", 3.266666666666667),
            ("gmonb:M=5", 2.8),
            ("gmonb:M=5,threshold=0.8", 51.885714285714286),
            ("mon:M=3", 3.15),
            ("gmon:M=3", 60.15),
            ("gmon:M=21", 2.6),
            ("mon:M=21", 2.2),
        ];
        for (spec, value) in expected {
            let e = est(spec, &xs);
            assert_eq!(
                e.to_bits(),
                (est(spec, &S) * s).to_bits(),
                "{spec} at 2^{k}"
            );
            assert_rel(e, value * s, REL);
        }
        assert_rel(
            est(&format!("clamp:c={:e}", 10.0 * s), &xs),
            3.314285714285714 * s,
            REL,
        );
        assert_rel(est("gini:M=5", &xs), 0.7632631010264719, REL);
        assert_rel(est("gini:M=3", &xs), 0.6380345432714516, REL);
        assert_rel(est("gini:M=21", &xs), 0.8346444304594085, REL);
    }
}

#[test]
fn jung_follows_the_spec_welford_literally_at_extreme_scales() {
    // docs/estimators.md §1: sigma = sqrt(m2/k), "+inf if m2 overflows"; docs/estimators.md §4: ratio = +inf gives M_max.
    // Near 1e300 every d*(x - mean) overflows, so sigma_pixel = +inf and M = m_max = 17
    // (MoN(17) of 7 samples = 2.2 * s), although the scaled ratio is the example's 3.04.
    let s = 2f64.powi(995);
    let xs: Vec<f64> = S.iter().map(|x| x * s).collect();
    let mut j = Jung::new(40.0 * s, 17).unwrap();
    j.push_slice(&xs);
    assert_eq!(extra(&j, "sigma_pixel"), Some(Extra::Float(f64::INFINITY)));
    assert_eq!(j.chosen_m(), 17);
    assert_rel(j.estimate().unwrap(), 2.2 * s, REL);
    // Near 1e-300 every product underflows to 0: sigma_pixel = 0 < sigma_image, M = 1, the mean.
    let s = 2f64.powi(-997);
    let xs: Vec<f64> = S.iter().map(|x| x * s).collect();
    let mut j = Jung::new(40.0 * s, 17).unwrap();
    j.push_slice(&xs);
    assert_eq!(extra(&j, "sigma_pixel"), Some(Extra::Float(0.0)));
    assert_eq!(j.chosen_m(), 1);
    assert_rel(j.estimate().unwrap(), 51.885714285714286 * s, REL);
    // At 2^-400 (1e-120) nothing under- or overflows and the example's M = 5 holds.
    let s = 2f64.powi(-400);
    let xs: Vec<f64> = S.iter().map(|x| x * s).collect();
    let mut j = Jung::new(40.0 * s, 17).unwrap();
    j.push_slice(&xs);
    assert_eq!(j.chosen_m(), 5);
    assert_rel(j.estimate().unwrap(), 2.8 * s, REL);
}

#[test]
fn long_stream_near_the_overflow_limit() {
    // The running example repeated 1428 times (n = 9996), scaled by 2^995: max 1.17e302,
    // n * max = 1.17e306 < 1e307. No sum may overflow; each estimate is 2^995 times the
    // unscaled one, bit for bit (Jung excluded, see above).
    let base: Vec<f64> = S.repeat(1428);
    let s = 2f64.powi(995);
    let xs: Vec<f64> = base.iter().map(|x| x * s).collect();
    for spec in [
        "mean",
        "mon:M=21",
        "gini:M=21",
        "gmonb:M=21",
        "gmon:M=21",
        "gmon:M=5",
        "mon:M=2",
    ] {
        let e = est(spec, &xs);
        assert!(e.is_finite(), "{spec} = {e}");
        let factor = if spec.starts_with("gini") { 1.0 } else { s };
        assert_eq!(e.to_bits(), (est(spec, &base) * factor).to_bits(), "{spec}");
    }
    assert_rel(est("mean", &xs), 51.885714285714286 * s, REL);
    // M = 7 gives every set 1428 copies of one sample value: theta = S sorted, as M = 21 on S.
    assert_rel(est("mon:M=7", &xs), 2.2 * s, REL);
    assert_rel(est("gmon:M=7", &xs), 2.6 * s, REL);
}

#[test]
fn decimal_values_near_1e_minus_300() {
    // The 1e300 case mirrored: same structure, same answers times 1e-600.
    let xs: Vec<f64> = [1e-300, 1e-300, 1e-300, 5e-300].repeat(250);
    assert_rel(est("mean", &xs), 2e-300, REL);
    assert_rel(est("clamp:c=2e-300", &xs), 1.25e-300, REL);
    assert_rel(est("mon:M=4", &xs), 1e-300, REL);
    assert_rel(est("gini:M=4", &xs), 0.375, REL);
    assert_rel(est("gmon:M=4", &xs), 2e-300, REL);
    assert_rel(est("gmonb:M=4", &xs), 1e-300, REL);
}

#[test]
fn subnormal_samples_are_summed_exactly() {
    // Sums of subnormals are exact, so the mean of eight copies of the smallest subnormal is
    // that subnormal, and nothing flushes to zero.
    let tiny = f64::from_bits(1); // 5e-324
    let xs = [tiny; 8];
    for spec in ["mean", "mon:M=1", "mon:M=3", "gmon:M=3", "gmonb:M=4"] {
        assert_eq!(est(spec, &xs), tiny, "{spec}");
    }
    assert_eq!(est("gini:M=4", &xs), 0.0);
    // Two unequal subnormals: (1, 3) ulps -> mean 2 ulps exactly.
    let xs = [tiny, f64::from_bits(3)];
    assert_eq!(est("mean", &xs), f64::from_bits(2));
    assert_eq!(est("mon:M=2", &xs), f64::from_bits(2));
}

// Degenerate streams ------------------------------------------------------------------------------

#[test]
fn all_zeros() {
    let mut xs = vec![0.0; 100];
    xs[17] = -0.0; // a valid zero too (docs/estimators.md §1)
    for &spec in ALL {
        let e = run(spec, &xs);
        assert_eq!(e.estimate().unwrap(), 0.0, "{spec}");
    }
    let g = run("gmonb:M=21", &xs);
    assert_eq!(extra(g.as_ref(), "gini"), Some(Extra::Float(0.0)));
    assert_eq!(extra(g.as_ref(), "used_mon"), Some(Extra::Bool(false)));
    let g = run("gmon:M=21", &xs);
    assert_eq!(extra(g.as_ref(), "trimmed"), Some(Extra::Int(0)));
    let mut j = Jung::new(1e-300, 17).unwrap();
    j.push_slice(&xs);
    assert_eq!(j.chosen_m(), 1, "sigma_pixel = 0 < any sigma_image");
}

#[test]
fn one_sample() {
    // K = 1: every estimate is the sample itself; Gini: s1 = s2 = x, G = 2 - 2 = 0.
    for x in [3.7f64, 0.0, 1e-300, 1e300, 350.0] {
        for &spec in ALL {
            let expected = if spec.starts_with("gini") {
                0.0
            } else if spec.starts_with("clamp") {
                x.min(10.0)
            } else {
                x
            };
            assert_eq!(est(spec, &[x]), expected, "{spec} on [{x:e}]");
        }
        let mut j = Jung::new(1e-300, 17).unwrap();
        j.push(x);
        assert_eq!(j.chosen_m(), 1, "one sample has sigma 0");
    }
}

#[test]
fn fewer_samples_than_sets_uses_k_equal_n() {
    // n = 4 < M = 21: K = 4, theta = (1, 2, 3, 10). MoN = (2 + 3)/2 = 2.5.
    // s1 = 16, s2 = 1 + 4 + 9 + 40 = 54, G = 108/64 - 5/4 = 0.4375 (with M = 21 in place of K it
    // would not be this). k = 2, c = floor(0.875) = 0: G-MoN = 16/4 = 4. G-MoN_b -> MoN.
    let xs = [3.0, 1.0, 10.0, 2.0];
    assert_rel(est("mon:M=21", &xs), 2.5, REL);
    assert_rel(est("gini:M=21", &xs), 0.4375, REL);
    assert_rel(est("gmon:M=21", &xs), 4.0, REL);
    assert_rel(est("gmonb:M=21", &xs), 2.5, REL);
    assert_rel(est("gmonb:M=21,threshold=0.5", &xs), 4.0, REL);

    // n = 3 < M = 5, odd K: theta = (1, 2, 9), MoN = 2; s1 = 12, s2 = 1 + 4 + 27 = 32,
    // G = 64/36 - 4/3 = 4/9; k = 1, c = 0: G-MoN = 4.
    let xs = [1.0, 9.0, 2.0];
    assert_rel(est("mon:M=5", &xs), 2.0, REL);
    assert_rel(est("gini:M=5", &xs), 4.0 / 9.0, REL);
    assert_rel(est("gmon:M=5", &xs), 4.0, REL);

    // n = 10 < M = 100, one bright sample: theta = nine 0s and 1000. s1 = 1000, s2 = 10000,
    // G = 20000/10000 - 11/10 = 0.9; k = 5, c = floor(4.5) = 4: G-MoN = mean of theta[4..6] = 0.
    let mut xs = [0.0; 10];
    xs[6] = 1000.0;
    assert_rel(est("gini:M=100", &xs), 0.9, REL);
    assert_eq!(est("gmon:M=100", &xs), 0.0);
    assert_eq!(est("mon:M=100", &xs), 0.0);
    assert_rel(est("mean", &xs), 100.0, REL);
    let g = run("gmon:M=100", &xs);
    assert_eq!(extra(g.as_ref(), "trimmed"), Some(Extra::Int(4)));

    // Jung: M = 17 chosen but n = 7, so K = 7 (docs/estimators.md §4): the example's 2.2.
    assert_rel(est("jung:sigma_image=0.5", &S), 2.2, REL);
}

#[test]
fn n_not_divisible_by_m() {
    // n = 10, M = 4: sets {0,0,8}, {0,0,4}, {0,0}, {0,0}: theta = (0, 0, 4/3, 8/3), so the mean
    // of set means (1) differs from the sample mean (1.2). MoN = 2/3.
    // s1 = 4, s2 = 3*(4/3) + 4*(8/3) = 44/3, G = (88/3)/16 - 5/4 = 7/12;
    // k = 2, c = floor(7/6) = 1: G-MoN = (0 + 4/3)/2 = 2/3.
    // G-MoN_b: G > 0.25 -> MoN; with t = 0.6 -> the sample mean 1.2 (not 1).
    let xs = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 8.0, 4.0];
    assert_rel(est("mean", &xs), 1.2, REL);
    assert_rel(est("mon:M=4", &xs), 2.0 / 3.0, REL);
    assert_rel(est("gini:M=4", &xs), 7.0 / 12.0, REL);
    assert_rel(est("gmon:M=4", &xs), 2.0 / 3.0, REL);
    assert_rel(est("gmonb:M=4", &xs), 2.0 / 3.0, REL);
    assert_rel(est("gmonb:M=4,threshold=0.6", &xs), 1.2, REL);
    // M = 3: sets {0,0,0,4}, {0,0,0}, {0,0,8}: theta = (0, 1, 8/3), MoN = 1,
    // G = 20/11 - 4/3 = 16/33, c = 0: G-MoN = (11/3)/3 = 11/9, not the sample mean 1.2.
    assert_rel(est("mon:M=3", &xs), 1.0, REL);
    assert_rel(est("gini:M=3", &xs), 16.0 / 33.0, REL);
    assert_rel(est("gmon:M=3", &xs), 11.0 / 9.0, REL);
    // Blocks that end mid-round give the same sets.
    let mut g = Gmon::new(4).unwrap();
    g.push_slice(&xs[..3]);
    g.push_slice(&xs[3..9]);
    g.push(xs[9]);
    assert_eq!(g.estimate().unwrap(), est("gmon:M=4", &xs));
}

// Compensated summation -----------------------------------------------------------------------------

#[test]
fn compensation_keeps_small_terms() {
    // 1e16 + 1 rounds back to 1e16 (ties to even), so a naive sum of (1e16, 1, 1) is 1e16;
    // the exact sum 1e16 + 2 is representable and Neumaier keeps it.
    let xs = [1e16, 1.0, 1.0];
    let naive: f64 = xs.iter().sum();
    assert_eq!(naive, 1e16, "the case must defeat a naive sum");
    assert_eq!(est("mean", &xs), (1e16 + 2.0) / 3.0);
    assert_eq!(est("mon:M=1", &xs), (1e16 + 2.0) / 3.0);
    assert_eq!(est("clamp:c=1e17", &xs), (1e16 + 2.0) / 3.0);
    // In sets: M = 2 puts (1e16, 1) and (1) apart; with (1e16, 1, 1, 1) set 0 is (1e16, 1).
    let xs = [1e16, 1.0, 1.0, 1.0, 1.0];
    // set 0 = {1e16, 1, 1} -> (1e16 + 2)/3, set 1 = {1, 1} -> 1; MoN(2) = their mean.
    assert_eq!(est("mon:M=2", &xs), ((1e16 + 2.0) / 3.0 + 1.0) / 2.0);
}

#[test]
fn hundred_million_equal_samples_have_an_exact_mean() {
    // 10^8 copies of 0.1, pushed as 1000 blocks of 10^5. The compensated sum is the double
    // nearest 10^8 * 0.1 = 1e7, so the mean is 0.1 exactly; a naive running sum drifts.
    const BLOCK: usize = 100_000;
    const BLOCKS: usize = 1_000;
    let block = vec![0.1; BLOCK];

    let mut naive = 0.0f64;
    for _ in 0..BLOCKS {
        for &x in &block {
            naive += x;
        }
    }
    let naive_mean = naive / (BLOCK * BLOCKS) as f64;
    assert_ne!(
        naive_mean, 0.1,
        "a naive sum must fail this case, else it proves nothing"
    );

    let mut mean = Mean::new();
    let mut bank =
        Bank::new(&["clamp:c=1".parse().unwrap(), "gmonb:M=5".parse().unwrap()]).unwrap();
    for _ in 0..BLOCKS {
        mean.push_slice(&block);
        bank.push_slice(&block).unwrap();
    }
    assert_eq!(mean.count(), 100_000_000);
    assert_eq!(mean.estimate().unwrap(), 0.1, "naive gave {naive_mean:?}");
    // Clamp at 1 is the mean here; G-MoN_b sees equal set means (Gini ~ 0) and takes the
    // overall compensated mean.
    assert_eq!(bank.count(), 100_000_000);
    assert_eq!(bank.estimates().unwrap(), vec![0.1, 0.1]);
    assert_eq!(
        extra(bank.estimators()[1].as_ref(), "used_mon"),
        Some(Extra::Bool(false))
    );
}

// A single enormous outlier ---------------------------------------------------------------------

#[test]
fn one_1e30_outlier_among_a_million_ones() {
    const N: usize = 1_000_000;
    let mut xs = vec![1.0; N];
    xs[123_457] = 1e30;
    let mean_expected = (1e6 - 1.0 + 1e30) / 1e6;

    let mut bank = Bank::new(
        &[
            "mean",
            "clamp:c=10",
            "mon:M=21",
            "gini:M=21",
            "gmon:M=21",
            "gmonb:M=21",
            "jung:sigma_image=1",
        ]
        .map(|s| s.parse().unwrap()),
    )
    .unwrap();
    for chunk in xs.chunks(65_536) {
        bank.push_slice(chunk).unwrap();
    }
    let e = bank.estimates().unwrap();
    assert_rel(e[0], mean_expected, REL);
    // Clamp: 999 999 ones and one 10.
    assert_rel(e[1], (999_999.0 + 10.0) / 1e6, REL);
    // 20 of the 21 sets hold only ones (their compensated means are exactly 1); the median and
    // the trimmed mean see only those.
    assert_eq!(e[2], 1.0, "MoN(21)");
    // theta = (1 x 20, B) with B ~ 2.1e25: G = 2 - 420/(420 + 21 B) - 22/21 = 20/21 to ~1e-24.
    assert_rel(e[3], 20.0 / 21.0, REL);
    assert_eq!(e[4], 1.0, "G-MoN(21)");
    let gmon = &bank.estimators()[4];
    assert_eq!(extra(gmon.as_ref(), "trimmed"), Some(Extra::Int(9))); // floor(20/21 * 10)
    // G-MoN_b switches to MoN.
    assert_eq!(e[5], 1.0, "G-MoN_b(21)");
    let gmonb = &bank.estimators()[5];
    assert_eq!(extra(gmonb.as_ref(), "used_mon"), Some(Extra::Bool(true)));
    // Jung: sigma_pixel ~ 1e27 >> 1: M = m_max = 17, MoN(17) = 1.
    assert_eq!(e[6], 1.0, "Jung");
    assert_eq!(
        extra(bank.estimators()[6].as_ref(), "M"),
        Some(Extra::Int(17))
    );
}

// Image mode of Jung (docs/estimators.md §4) -----------------------------------------------------------------------

#[test]
fn jung_with_a_black_image() {
    // sigma_image == 0: M = 1 when sigma_pixel == 0, else m_max.
    let mut j = Jung::new(1.0, 17).unwrap();
    j.push_slice(&S);
    j.set_sigma_image(0.0).unwrap();
    assert_eq!(j.chosen_m(), 17);
    assert_rel(j.estimate().unwrap(), 2.2, REL);
    let mut flat = Jung::new(1.0, 9).unwrap();
    flat.push_slice(&[2.5; 10]);
    flat.set_sigma_image(0.0).unwrap();
    assert_eq!(flat.chosen_m(), 1);
    assert_eq!(flat.estimate().unwrap(), 2.5);
    // The running sigma is read at estimate time.
    j.set_sigma_image(40.0).unwrap();
    assert_eq!(j.chosen_m(), 5);
    assert_rel(j.estimate().unwrap(), 2.8, REL);
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let err = j.set_sigma_image(bad).unwrap_err().to_string();
        assert!(err.contains("sigma_image"), "{err}");
    }
    assert_eq!(j.chosen_m(), 5, "a rejected sigma_image leaves the old one");
}

// Empty streams and reset ---------------------------------------------------------------------------

#[test]
fn empty_stream_is_an_error_mentioning_no_samples() {
    for &spec in ALL {
        let mut e = run(spec, &[]);
        assert_eq!(e.count(), 0);
        let err = e.estimate().unwrap_err().to_string();
        assert!(err.contains("no samples"), "{spec}: {err}");
        e.push_slice(&[]);
        assert!(e.estimate().is_err(), "{spec}: an empty block adds nothing");
    }
    let specs: Vec<EstimatorSpec> = ALL.iter().map(|s| s.parse().unwrap()).collect();
    let mut bank = Bank::new(&specs).unwrap();
    bank.push_slice(&[]).unwrap();
    let err = bank.estimates().unwrap_err().to_string();
    assert!(err.contains("no samples"), "{err}");
}

#[test]
fn reset_then_repush_gives_the_same_estimate() {
    let stream: Vec<f64> = S.iter().cycle().take(50).copied().collect();
    for &spec in ALL {
        let mut e = run(spec, &stream);
        let first = e.estimate().unwrap();
        let first_extras = e.extras();
        e.reset();
        assert_eq!(e.count(), 0, "{spec}");
        let err = e.estimate().unwrap_err().to_string();
        assert!(err.contains("no samples"), "{spec} after reset: {err}");
        // Different blocks this time.
        e.push_slice(&stream[..13]);
        for &x in &stream[13..] {
            e.push(x);
        }
        assert_eq!(e.estimate().unwrap().to_bits(), first.to_bits(), "{spec}");
        common::assert_same_extras(&e.extras(), &first_extras, spec);
    }
    let specs: Vec<EstimatorSpec> = ALL.iter().map(|s| s.parse().unwrap()).collect();
    let mut bank = Bank::new(&specs).unwrap();
    bank.push_slice(&stream).unwrap();
    let first = bank.estimates().unwrap();
    bank.push_slice(&[1e6; 9]).unwrap();
    bank.reset();
    assert_eq!(bank.count(), 0);
    assert!(bank.estimates().is_err());
    bank.push_slice(&stream).unwrap();
    assert_eq!(bank.estimates().unwrap(), first);
    // Indices in errors count from the reset.
    let err = bank.push_slice(&[1.0, f64::NAN]).unwrap_err().to_string();
    assert_eq!(err, "invalid sample at index 51: NaN");
}

#[test]
fn typed_constructors_agree_with_spec_strings() {
    // The same estimator reached two ways gives the same answer on a hard stream.
    let xs: Vec<f64> = (0..1001)
        .map(|i| {
            if i % 97 == 0 {
                1e12
            } else {
                (i % 13) as f64 * 0.37
            }
        })
        .collect();
    let pairs: Vec<(Box<dyn Estimator>, &str)> = vec![
        (Box::new(Mon::new(21).unwrap()), "mon:M=21"),
        (Box::new(Gmon::new(21).unwrap()), "gmon:M=21"),
        (Box::new(GmonB::new(21, 0.25).unwrap()), "gmonb:M=21"),
        (Box::new(GiniDiagnostic::new(21).unwrap()), "gini:M=21"),
        (Box::new(Jung::new(3.0, 17).unwrap()), "jung:sigma_image=3"),
    ];
    for (mut typed, spec) in pairs {
        typed.push_slice(&xs);
        assert_eq!(
            typed.estimate().unwrap().to_bits(),
            est(spec, &xs).to_bits(),
            "{spec}"
        );
    }
}

#[test]
fn gmonb_threshold_is_inclusive() {
    // n = 3, M = 2: sets {0, 0} and {4}: theta = (0, 4), s1 = 4, s2 = 8, G = 16/8 - 3/2 = 0.5
    // exactly. "G <= t" takes the mean 4/3 at t = 0.5; MoN would be (0 + 4)/2 = 2.
    let xs = [0.0, 4.0, 0.0];
    assert_eq!(est("gini:M=2", &xs), 0.5);
    assert_rel(est("gmonb:M=2,threshold=0.5", &xs), 4.0 / 3.0, REL);
    assert_rel(est("gmonb:M=2,threshold=0.4999999999999999", &xs), 2.0, REL);
}

#[test]
fn gini_of_equal_set_means_is_clamped_to_zero() {
    // theta = (0.7, 0.7): s1 = 1.4, s2 = 2.1, and in f64 (2*2.1)/(2*1.4) - 3/2 = -2.2e-16.
    // docs/estimators.md §3: G = max(G, 0), so the diagnostic reports exactly 0, never a negative value.
    let (s1, s2) = (0.7 + 0.7, 1.0 * 0.7 + 2.0 * 0.7);
    assert!(
        (2.0 * s2) / (2.0 * s1) - 1.5 < 0.0,
        "the case must round below zero"
    );
    for (m, xs) in [
        (2, vec![0.7, 0.7]),
        (2, vec![3.3, 3.3, 3.3, 3.3]),
        (6, vec![0.3; 6]),
    ] {
        let g = est(&format!("gini:M={m}"), &xs);
        assert_eq!(g.to_bits(), 0.0f64.to_bits(), "M = {m}: Gini = {g:e}");
        let e = run(&format!("gmonb:M={m}"), &xs);
        assert_eq!(extra(e.as_ref(), "gini"), Some(Extra::Float(0.0)));
    }
}

#[test]
fn state_size_does_not_grow_with_the_stream() {
    // Constant memory: the per-pixel state after 10^5 samples is what it was before the first.
    let xs: Vec<f64> = (0..100_000).map(|i| (i % 1000) as f64 * 0.01).collect();
    for &spec in ALL {
        let mut e = run(spec, &[]);
        let before = e.state_bytes();
        assert!(before > 0, "{spec}");
        e.push_slice(&xs);
        e.push(1e30);
        assert_eq!(e.state_bytes(), before, "{spec}");
    }
    // MoN keeps M sets of a compensated sum each (at least 16 bytes a set).
    let small = run("mon:M=3", &[]).state_bytes();
    let large = run("mon:M=1000", &[]).state_bytes();
    assert!(
        large >= small + 997 * 16,
        "MoN(3) {small} B, MoN(1000) {large} B"
    );
}
