//! Property tests (proptest) of the mean, clamp, MoN family, Jung, the spec-string grammar and
//! the Bank: invariants the spec states or implies, checked on random streams of finite,
//! non-negative samples spanning 20 decades, with zeros, negative zeros, ties and outliers.
//!
//! Several properties compare with `oracle`, an independent transcription of docs/estimators.md §1–§4 written
//! for these tests (no code of the crate): since the spec fixes every operation order, the
//! crate must agree with it bit for bit.

use crate::common;
use fireflies::estimators::{
    Bank, Clamp, ClampSpec, Estimator, EstimatorSpec, Extra, GiniDiagnostic, GiniSpec, Gmon, GmonB,
    GmonBSpec, GmonSpec, Jung, JungSpec, Mean, MeanSpec, Mon, MonSpec,
};
use proptest::prelude::*;
use proptest::test_runner::Config;

/// Cases per property: enough to hit the corners of the sample strategy, small enough that
/// the whole file runs in a few seconds in release.
const CASES: u32 = 256;

fn config() -> Config {
    Config {
        cases: CASES,
        ..Config::default()
    }
}

/// An independent transcription of docs/estimators.md §1–§4, used as the oracle.
mod oracle {
    /// docs/estimators.md §1 Neumaier sum, in the spec's words.
    pub fn neumaier(xs: impl IntoIterator<Item = f64>) -> f64 {
        let (mut s, mut c) = (0.0f64, 0.0f64);
        for x in xs {
            let t = s + x;
            if s.abs() >= x.abs() {
                c += (s - t) + x;
            } else {
                c += (x - t) + s;
            }
            s = t;
        }
        s + c
    }

    pub fn mean(xs: &[f64]) -> f64 {
        neumaier(xs.iter().copied()) / xs.len() as f64
    }

    pub fn clamp(xs: &[f64], c: f64) -> f64 {
        neumaier(xs.iter().map(|&x| x.min(c))) / xs.len() as f64
    }

    /// The K = min(n, M) non-empty set means, ascending (docs/estimators.md §3 "Partition").
    pub fn theta(xs: &[f64], m: usize) -> Vec<f64> {
        let mut t: Vec<f64> = (0..m.min(xs.len()))
            .map(|set| {
                let members: Vec<f64> = xs.iter().copied().skip(set).step_by(m).collect();
                neumaier(members.iter().copied()) / members.len() as f64
            })
            .collect();
        t.sort_by(|a, b| a.partial_cmp(b).unwrap());
        t
    }

    pub fn mon(xs: &[f64], m: usize) -> f64 {
        let t = theta(xs, m);
        let k = t.len();
        if k % 2 == 1 {
            // theta_{(K+1)/2}, 1-based
            t[k / 2]
        } else {
            (t[k / 2 - 1] + t[k / 2]) / 2.0
        }
    }

    pub fn gini_of(t: &[f64]) -> f64 {
        let k = t.len();
        let mut s1 = 0.0;
        let mut s2 = 0.0;
        for (j, &x) in t.iter().enumerate() {
            s1 += x;
            s2 += ((j + 1) as f64) * x;
        }
        if s1 == 0.0 {
            return 0.0;
        }
        let g = (2.0 * s2) / (k as f64 * s1) - (k as f64 + 1.0) / k as f64;
        if g < 0.0 { 0.0 } else { g }
    }

    pub fn gini(xs: &[f64], m: usize) -> f64 {
        gini_of(&theta(xs, m))
    }

    /// (estimate, c)
    pub fn gmon(xs: &[f64], m: usize) -> (f64, usize) {
        let t = theta(xs, m);
        let k = t.len();
        let g = gini_of(&t);
        let half = k / 2;
        let c = ((g * half as f64).floor() as usize).min((k - 1) / 2);
        let mut sum = 0.0;
        for &x in &t[c..k - c] {
            sum += x;
        }
        (sum / (k - 2 * c) as f64, c)
    }

    pub fn gmonb(xs: &[f64], m: usize, threshold: f64) -> f64 {
        if gini(xs, m) <= threshold {
            mean(xs)
        } else {
            mon(xs, m)
        }
    }

    /// docs/estimators.md §1 Welford population sigma.
    pub fn sigma(xs: &[f64]) -> f64 {
        let (mut k, mut mean, mut m2) = (0.0f64, 0.0f64, 0.0f64);
        for &x in xs {
            k += 1.0;
            let d = x - mean;
            mean += d / k;
            m2 += d * (x - mean);
        }
        (m2 / k).sqrt()
    }

    /// docs/estimators.md §4: q is the largest integer with 2^q <= ratio, found by doubling (exact).
    pub fn jung_m(xs: &[f64], sigma_image: f64, m_max: usize) -> usize {
        let ratio = sigma(xs) / sigma_image;
        if ratio < 1.0 {
            return 1;
        }
        if ratio == f64::INFINITY {
            return m_max;
        }
        let mut q = 0usize;
        let mut p = 2.0f64;
        while p <= ratio {
            q += 1;
            p *= 2.0;
        }
        (2 * (q + 1) + 1).min(m_max)
    }
}

// Strategies ----------------------------------------------------------------------------------

/// One finite, non-negative sample: zeros (both signs), values from 1e-8 to 1e8, ties drawn
/// from a small pool, and rare outliers up to 1e12.
fn sample() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => Just(0.0),
        1 => Just(-0.0),
        8 => (0.0f64..1.0, -8i32..=8).prop_map(|(m, e)| m * 10f64.powi(e)),
        3 => prop::sample::select(vec![0.1, 0.5, 0.7, 1.0, 2.2, 3.0, 3.3, 7.0]),
        1 => (1.0f64..10.0, 9i32..=11).prop_map(|(m, e)| m * 10f64.powi(e)),
    ]
}

fn samples() -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(sample(), 1..200)
}

fn m_sets() -> impl Strategy<Value = usize> {
    prop_oneof![1usize..=8, 9usize..=40]
}

fn odd_m_max() -> impl Strategy<Value = usize> {
    (0usize..=10).prop_map(|i| 2 * i + 1)
}

/// Any f64 at all, weighted towards the special values.
fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => any::<f64>(),
        1 => prop::sample::select(vec![
            0.0, -0.0, 1.0, -1.0, 0.25, 1.5, f64::NAN, f64::INFINITY, f64::NEG_INFINITY,
            f64::MIN_POSITIVE, 5e-324, f64::MAX, f64::MIN, f64::EPSILON,
        ]),
        2 => -2.0f64..2.0,
    ]
}

/// A positive finite f64 of any magnitude, subnormals included (log-uniform, or any bit
/// pattern that is positive and finite).
fn positive_finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        (1.0f64..10.0, -330i32..=308).prop_map(|(m, e)| m * 10f64.powi(e)),
        any::<f64>(),
    ]
    .prop_filter("positive and finite", |x| *x > 0.0 && x.is_finite())
}

/// Any usize, weighted towards small values and the edges.
fn any_usize() -> impl Strategy<Value = usize> {
    prop_oneof![
        4 => 0usize..64,
        1 => any::<usize>(),
        1 => prop::sample::select(vec![0, 1, 2, 16, 17, 255, 256, 257, usize::MAX]),
    ]
}

/// Every estimator of this file's scope, as spec strings with parameters derived from `m`.
fn specs(m: usize, clamp_c: f64, sigma_image: f64, m_max: usize, t: f64) -> Vec<EstimatorSpec> {
    vec![
        EstimatorSpec::Mean(MeanSpec),
        EstimatorSpec::Clamp(ClampSpec { c: clamp_c }),
        EstimatorSpec::Mon(MonSpec { m }),
        EstimatorSpec::Gini(GiniSpec { m }),
        EstimatorSpec::GmonB(GmonBSpec { m, threshold: t }),
        EstimatorSpec::Gmon(GmonSpec { m }),
        EstimatorSpec::Jung(JungSpec { sigma_image, m_max }),
    ]
}

fn fed(spec: &EstimatorSpec, xs: &[f64]) -> Box<dyn Estimator> {
    let mut e = spec.build().expect("valid spec");
    for &x in xs {
        e.push(x);
    }
    e
}

fn est(spec: &EstimatorSpec, xs: &[f64]) -> f64 {
    fed(spec, xs).estimate().expect("non-empty stream")
}

fn extra(e: &dyn Estimator, key: &str) -> Option<Extra> {
    e.extras()
        .into_iter()
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v)
}

/// Cuts `xs` into blocks at the given fractions (empty blocks allowed).
fn blocks<'a>(xs: &'a [f64], cuts: &[prop::sample::Index]) -> Vec<&'a [f64]> {
    let mut at: Vec<usize> = cuts.iter().map(|c| c.index(xs.len() + 1)).collect();
    at.push(0);
    at.push(xs.len());
    at.sort_unstable();
    at.windows(2).map(|w| &xs[w[0]..w[1]]).collect()
}

fn min_max(xs: &[f64]) -> (f64, f64) {
    xs.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &x| {
        (lo.min(x), hi.max(x))
    })
}

// Constructors and spec strings never panic ----------------------------------------------------

proptest! {
    #![proptest_config(config())]

    #[test]
    fn constructors_never_panic(x in any_f64(), y in any_f64(), m in any_usize(), k in any_usize()) {
        // Each call must return Ok or Err; a panic fails the test.
        let _ = Clamp::new(x);
        let _ = Mon::new(m);
        let _ = GiniDiagnostic::new(m);
        let _ = Gmon::new(m);
        let _ = GmonB::new(m, x);
        let _ = Jung::new(x, k);
        let _ = Jung::new(y, m);
        let _ = Mean::new();
        // Accepted parameters are the documented domains.
        prop_assert_eq!(Clamp::new(x).is_ok(), x.is_finite() && x > 0.0, "clamp c = {}", x);
        prop_assert_eq!(
            Jung::new(x, 17).is_ok(),
            x.is_finite() && x > 0.0,
            "jung sigma_image = {}",
            x
        );
        if m == 0 {
            prop_assert!(Mon::new(m).is_err());
            prop_assert!(Gmon::new(m).is_err());
            prop_assert!(GmonB::new(m, 0.25).is_err());
            prop_assert!(GiniDiagnostic::new(m).is_err());
        }
        if k % 2 == 0 {
            prop_assert!(Jung::new(1.0, k).is_err(), "even m_max = {} accepted", k);
        }
    }

    #[test]
    fn spec_strings_from_arbitrary_values_never_panic(
        x in any_f64(), y in any_f64(), m in any_usize(), k in any_usize()
    ) {
        let texts = [
            format!("clamp:c={x}"),
            format!("clamp:c={x:e}"),
            format!("mon:M={m}"),
            format!("gini:M={m}"),
            format!("gmon:M={m}"),
            format!("gmonb:M={m}"),
            format!("gmonb:M={m},threshold={x}"),
            format!("gmonb:threshold={y},M={k}"),
            format!("jung:sigma_image={x},m_max={k}"),
            format!("jung:sigma_image={y:e},m_max={m}"),
            format!("jung:sigma_image={x}"),
            format!("mon:M={x}"),
            format!("jung:sigma_image={x},m_max={y}"),
        ];
        for t in &texts {
            let built = t.parse::<EstimatorSpec>().ok().and_then(|s| s.build().ok());
            if let Some(mut e) = built {
                e.push_slice(&[1.0, 0.0, 3.5]);
                prop_assert!(e.estimate().is_ok(), "{}", t);
            }
        }
        // Valid values must parse and build.
        if x.is_finite() && x > 0.0 {
            let spec: EstimatorSpec = format!("clamp:c={x}").parse().unwrap();
            prop_assert_eq!(spec, EstimatorSpec::Clamp(ClampSpec { c: x }));
            prop_assert!(spec.build().is_ok());
        }
    }

    #[test]
    fn arbitrary_text_never_panics_the_parser(text in ".{0,40}", tail in "[a-zA-Z_=,:.0-9 -]{0,30}") {
        for name in ["", "mean", "clamp", "mon", "gini", "gmonb", "gmon", "jung"] {
            for t in [format!("{name}{text}"), format!("{name}:{tail}")] {
                if let Ok(spec) = t.parse::<EstimatorSpec>() {
                    let _ = spec.build();
                    // Whatever parses prints to something that parses to the same spec.
                    let again: EstimatorSpec = spec.to_string().parse().unwrap();
                    prop_assert_eq!(again.to_string(), spec.to_string());
                }
            }
        }
    }

    #[test]
    fn printed_spec_round_trips_exactly(
        c in positive_finite(),
        m in m_sets(),
        t in 0.0f64..=1.0,
        m_max in odd_m_max(),
        xs in samples(),
    ) {
        for spec in specs(m, c, c, m_max, t) {
            let text = spec.to_string();
            let back: EstimatorSpec = text.parse().unwrap();
            prop_assert_eq!(back, spec, "{}", text);
            let a = fed(&spec, &xs);
            let b = fed(&a.spec(), &xs);
            prop_assert_eq!(a.spec(), spec);
            prop_assert_eq!(a.estimate().unwrap().to_bits(), b.estimate().unwrap().to_bits());
        }
    }
}

// The estimators agree with the spec ---------------------------------------------------------

proptest! {
    #![proptest_config(config())]

    #[test]
    fn every_estimator_matches_the_spec_transcription_bit_for_bit(
        xs in samples(),
        m in m_sets(),
        c in 1e-6f64..1e6,
        sigma_image in 1e-6f64..1e6,
        m_max in odd_m_max(),
        t in 0.0f64..1.0,
    ) {
        let got: Vec<f64> = specs(m, c, sigma_image, m_max, t).iter().map(|s| est(s, &xs)).collect();
        let jm = oracle::jung_m(&xs, sigma_image, m_max);
        let want = [
            oracle::mean(&xs),
            oracle::clamp(&xs, c),
            oracle::mon(&xs, m),
            oracle::gini(&xs, m),
            oracle::gmonb(&xs, m, t),
            oracle::gmon(&xs, m).0,
            oracle::mon(&xs, jm),
        ];
        let names = ["mean", "clamp", "mon", "gini", "gmonb", "gmon", "jung"];
        for ((g, w), name) in got.iter().zip(want).zip(names) {
            prop_assert_eq!(g.to_bits(), w.to_bits(), "{}: crate {:?}, spec {:?}", name, g, w);
        }
        let mut j = Jung::new(sigma_image, m_max).unwrap();
        j.push_slice(&xs);
        prop_assert_eq!(j.chosen_m(), jm);
        let mut g = Gmon::new(m).unwrap();
        g.push_slice(&xs);
        prop_assert_eq!(extra(&g, "trimmed"), Some(Extra::Int(oracle::gmon(&xs, m).1 as u64)));
    }

    #[test]
    fn jung_m_boundaries_are_exact_powers_of_two(q in 0i32..40, below in any::<bool>(), m_max in odd_m_max()) {
        // Two samples {0, 2x} have population sigma exactly x. With sigma_image = 1 the ratio is
        // x itself; just below 2^q the answer must be the previous q.
        let two_q = 2f64.powi(q);
        let x = if below { two_q * (1.0 - f64::EPSILON) } else { two_q };
        let mut j = Jung::new(1.0, m_max).unwrap();
        j.push_slice(&[0.0, 2.0 * x]);
        let expected_q = if below { q - 1 } else { q };
        let expected = if expected_q < 0 { 1 } else { (2 * (expected_q as usize + 1) + 1).min(m_max) };
        prop_assert_eq!(j.chosen_m(), expected, "sigma_pixel = {:?}", x);
    }

    #[test]
    fn mon_with_one_set_is_bit_identical_to_the_mean(xs in samples(), cuts in prop::collection::vec(any::<prop::sample::Index>(), 0..5)) {
        let mut mon = Mon::new(1).unwrap();
        let mut mean = Mean::new();
        for b in blocks(&xs, &cuts) {
            mon.push_slice(b);
        }
        for &x in &xs {
            mean.push(x);
        }
        prop_assert_eq!(mon.estimate().unwrap().to_bits(), mean.estimate().unwrap().to_bits());
        // And G-MoN(1), G-MoN_b(1) with any threshold, Jung with m_max = 1.
        for spec in ["gmon:M=1", "gmonb:M=1,threshold=0", "gmonb:M=1,threshold=1", "jung:sigma_image=1e-9,m_max=1"] {
            let e = est(&spec.parse().unwrap(), &xs);
            prop_assert_eq!(e.to_bits(), mean.estimate().unwrap().to_bits(), "{}", spec);
        }
    }

    #[test]
    fn gmon_with_gini_zero_is_the_mean_of_set_means(
        rounds in prop::collection::vec(sample(), 1..30),
        m in m_sets(),
    ) {
        // Every round deals the same value to all M sets, so all set means are equal: Gini 0.
        let xs: Vec<f64> = rounds.iter().flat_map(|&r| std::iter::repeat_n(r, m)).collect();
        let theta = oracle::theta(&xs, m);
        prop_assert!(theta.windows(2).all(|w| w[0] == w[1]), "set means differ: {:?}", theta);
        let mut gini = GiniDiagnostic::new(m).unwrap();
        let mut gmon = Gmon::new(m).unwrap();
        gini.push_slice(&xs);
        gmon.push_slice(&xs);
        let g = gini.estimate().unwrap();
        prop_assert!((0.0..=1e-13).contains(&g), "Gini of equal set means = {:?}", g);
        let mut sum = 0.0;
        for &t in &theta {
            sum += t;
        }
        let mean_of_means = sum / theta.len() as f64;
        prop_assert_eq!(gmon.estimate().unwrap().to_bits(), mean_of_means.to_bits());
        prop_assert_eq!(extra(&gmon, "trimmed"), Some(Extra::Int(0)));
        let v = theta[0];
        prop_assert!((gmon.estimate().unwrap() - v).abs() <= 1e-13 * v);
    }

    #[test]
    fn gmon_without_trimming_is_the_mean_of_set_means(xs in samples(), m in m_sets()) {
        // Whenever c = 0 (Gini below 1/floor(K/2), or K <= 3), G-MoN is the plain mean of the
        // K set means, which differs from the sample mean when set counts differ.
        let mut gmon = Gmon::new(m).unwrap();
        gmon.push_slice(&xs);
        let theta = oracle::theta(&xs, m);
        if extra(&gmon, "trimmed") == Some(Extra::Int(0)) {
            let sum = theta.iter().fold(0.0, |a, &t| a + t);
            prop_assert_eq!(gmon.estimate().unwrap().to_bits(), (sum / theta.len() as f64).to_bits());
        }
        if theta.len() <= 3 {
            prop_assert_eq!(extra(&gmon, "trimmed"), Some(Extra::Int(0)));
        }
    }

    #[test]
    fn mon_family_lies_within_sample_range(
        xs in samples(),
        m in m_sets(),
        sigma_image in 1e-6f64..1e6,
        m_max in odd_m_max(),
        t in 0.0f64..=1.0,
    ) {
        // In exact arithmetic every set mean, hence every median or trimmed mean of them, lies in
        // [min, max]. The division sum/count may round past max by an ulp or so (e.g. three
        // copies of 0.1), so allow 1e-15 relative: a real defect (a wrong set, a wrong median
        // index reaching outside) misses by far more.
        let (lo, hi) = min_max(&xs);
        let tol = 1e-15;
        for spec in [
            EstimatorSpec::Mon(MonSpec { m }),
            EstimatorSpec::Gmon(GmonSpec { m }),
            EstimatorSpec::GmonB(GmonBSpec { m, threshold: t }),
            EstimatorSpec::Jung(JungSpec { sigma_image, m_max }),
            EstimatorSpec::Mean(MeanSpec),
        ] {
            let e = est(&spec, &xs);
            prop_assert!(
                e >= lo * (1.0 - tol) && e <= hi * (1.0 + tol),
                "{} = {:?} outside [{:?}, {:?}]", spec, e, lo, hi
            );
        }
        let c = hi / 2.0 + 1e-9;
        let e = est(&EstimatorSpec::Clamp(ClampSpec { c }), &xs);
        prop_assert!(e >= lo.min(c) * (1.0 - tol) && e <= c * (1.0 + tol), "clamp {:?} = {:?}", c, e);
    }

    #[test]
    fn gini_lies_in_zero_one(xs in samples(), m in m_sets()) {
        let g = est(&EstimatorSpec::Gini(GiniSpec { m }), &xs);
        prop_assert!((0.0..1.0).contains(&g), "Gini = {:?}", g);
        // The bound 1 - 1/K is attained only with a single non-zero set mean.
        let k = m.min(xs.len()) as f64;
        prop_assert!(g <= 1.0 - 1.0 / k + 1e-12, "Gini = {:?} > 1 - 1/K", g);
    }
}

// Scaling -------------------------------------------------------------------------------------

proptest! {
    #![proptest_config(config())]

    #[test]
    fn scaling_by_a_power_of_two_scales_every_estimate_exactly(
        xs in samples(),
        k in -40i32..=40,
        m in m_sets(),
        c in 1e-6f64..1e6,
        sigma_image in 1e-6f64..1e6,
        m_max in odd_m_max(),
        t in 0.0f64..1.0,
    ) {
        // Multiplying by 2^k is exact for these magnitudes (no overflow, no subnormals), and every
        // operation of the spec commutes with it, including every discrete decision: the result
        // must be bit for bit 2^k times the original (Gini: unchanged).
        let s = 2f64.powi(k);
        let ys: Vec<f64> = xs.iter().map(|&x| x * s).collect();
        let plain = specs(m, c, sigma_image, m_max, t);
        let scaled = specs(m, c * s, sigma_image * s, m_max, t);
        for (a, b) in plain.iter().zip(&scaled) {
            let (ea, eb) = (fed(a, &xs), fed(b, &ys));
            let factor = if matches!(a, EstimatorSpec::Gini(_)) { 1.0 } else { s };
            prop_assert_eq!(
                (ea.estimate().unwrap() * factor).to_bits(),
                eb.estimate().unwrap().to_bits(),
                "{} vs {}", a, b
            );
        }
        let (mut ja, mut jb) = (Jung::new(sigma_image, m_max).unwrap(), Jung::new(sigma_image * s, m_max).unwrap());
        ja.push_slice(&xs);
        jb.push_slice(&ys);
        prop_assert_eq!(ja.chosen_m(), jb.chosen_m());
    }

    #[test]
    fn scaling_by_any_factor_scales_every_estimate(
        xs in samples(),
        s in prop_oneof![1e-3f64..1.0, 1.0f64..1e3],
        m in m_sets(),
        c in 1e-6f64..1e6,
        sigma_image in 1e-6f64..1e6,
        m_max in odd_m_max(),
        t in 0.0f64..1.0,
    ) {
        // With a general factor each scaled sample is rounded, so estimates agree to 1e-12
        // relative. A discrete decision (Gini trimming c, G-MoN_b's switch, Jung's M) is
        // scale-invariant in exact arithmetic but may flip when the unscaled quantity sits
        // within rounding of its boundary; a flip is accepted only with that explanation.
        const REL: f64 = 1e-12;
        const NEAR: f64 = 1e-9;
        let ys: Vec<f64> = xs.iter().map(|&x| x * s).collect();
        let close = |a: f64, b: f64| (a - b).abs() <= REL * a.abs().max(b.abs());

        let pairs = specs(m, c, sigma_image, m_max, t)
            .into_iter()
            .zip(specs(m, c * s, sigma_image * s, m_max, t));
        for (a, b) in pairs {
            let (ea, eb) = (fed(&a, &xs), fed(&b, &ys));
            let (va, vb) = (ea.estimate().unwrap(), eb.estimate().unwrap());
            match a {
                EstimatorSpec::Gini(_) => {
                    prop_assert!((va - vb).abs() <= REL, "Gini {:?} vs {:?}", va, vb);
                }
                EstimatorSpec::Gmon(_) => {
                    let (ta, tb) = (extra(ea.as_ref(), "trimmed"), extra(eb.as_ref(), "trimmed"));
                    if ta == tb {
                        prop_assert!(close(va * s, vb), "{}: {:?}*{} vs {:?}", a, va, s, vb);
                    } else {
                        let g = oracle::gini(&xs, m);
                        let gk = g * (m.min(xs.len()) / 2) as f64;
                        prop_assert!((gk - gk.round()).abs() < NEAR, "trimming flipped far from a boundary: G*k = {:?}", gk);
                    }
                }
                EstimatorSpec::GmonB(GmonBSpec { threshold, .. }) => {
                    let (fa, fb) = (extra(ea.as_ref(), "used_mon"), extra(eb.as_ref(), "used_mon"));
                    if fa == fb {
                        prop_assert!(close(va * s, vb), "{}: {:?}*{} vs {:?}", a, va, s, vb);
                    } else {
                        let g = oracle::gini(&xs, m);
                        prop_assert!((g - threshold).abs() < NEAR, "switch flipped with G = {:?}, t = {:?}", g, threshold);
                    }
                }
                EstimatorSpec::Jung(_) => {
                    let (ma, mb) = (extra(ea.as_ref(), "M"), extra(eb.as_ref(), "M"));
                    if ma == mb {
                        prop_assert!(close(va * s, vb), "{}: {:?}*{} vs {:?}", a, va, s, vb);
                    } else {
                        let ratio = oracle::sigma(&xs) / sigma_image;
                        let l = ratio.log2();
                        prop_assert!((l - l.round()).abs() < NEAR, "Jung's M flipped with ratio {:?}", ratio);
                    }
                }
                _ => prop_assert!(close(va * s, vb), "{}: {:?}*{} vs {:?}", a, va, s, vb),
            }
        }
    }
}

// Blocks, banks, validation ---------------------------------------------------------------------

proptest! {
    #![proptest_config(config())]

    #[test]
    fn push_slice_in_random_blocks_equals_push(
        xs in samples(),
        cuts in prop::collection::vec(any::<prop::sample::Index>(), 0..8),
        m in m_sets(),
        c in 1e-6f64..1e6,
        sigma_image in 1e-6f64..1e6,
        m_max in odd_m_max(),
        t in 0.0f64..1.0,
    ) {
        let parts = blocks(&xs, &cuts);
        for spec in specs(m, c, sigma_image, m_max, t) {
            let one = fed(&spec, &xs);
            let mut blk = spec.build().unwrap();
            for b in &parts {
                blk.push_slice(b);
            }
            prop_assert_eq!(blk.count(), one.count());
            prop_assert_eq!(blk.estimate().unwrap().to_bits(), one.estimate().unwrap().to_bits(), "{}", spec);
            common::assert_same_extras(&blk.extras(), &one.extras(), &spec.to_string());
            // Pushing more after a block boundary keeps them in step.
            blk.push_slice(&xs);
            let mut one = one;
            one.push_slice(&xs);
            prop_assert_eq!(blk.estimate().unwrap().to_bits(), one.estimate().unwrap().to_bits(), "{}", spec);
        }
    }

    #[test]
    fn bank_equals_standalone_estimators(
        xs in samples(),
        cuts in prop::collection::vec(any::<prop::sample::Index>(), 0..8),
        m in m_sets(),
        c in 1e-6f64..1e6,
        sigma_image in 1e-6f64..1e6,
        m_max in odd_m_max(),
        t in 0.0f64..1.0,
    ) {
        let all = specs(m, c, sigma_image, m_max, t);
        let mut bank = Bank::new(&all).unwrap();
        for b in blocks(&xs, &cuts) {
            bank.push_slice(b).unwrap();
        }
        prop_assert_eq!(bank.count(), xs.len() as u64);
        let got = bank.estimates().unwrap();
        prop_assert_eq!(got.len(), all.len());
        for (spec, g) in all.iter().zip(&got) {
            prop_assert_eq!(g.to_bits(), est(spec, &xs).to_bits(), "{}", spec);
        }
        for (e, spec) in bank.estimators().iter().zip(&all) {
            prop_assert_eq!(e.spec(), *spec);
            prop_assert_eq!(e.count(), xs.len() as u64);
        }
    }

    #[test]
    fn bank_rejects_a_bad_block_whole_and_names_the_sample(
        head in samples(),
        block in samples(),
        at in any::<prop::sample::Index>(),
        bad in prop::sample::select(vec![
            f64::NAN, -f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1.0, -5e-324, -1e300, -f64::MIN_POSITIVE,
        ]),
        later_bad in any::<bool>(),
        m in m_sets(),
        m_max in odd_m_max(),
    ) {
        let all = specs(m, 2.5, 0.75, m_max, 0.25);
        let mut bank = Bank::new(&all).unwrap();
        bank.push_slice(&head).unwrap();
        let before = bank.estimates().unwrap();
        let extras_before: Vec<_> = bank.estimators().iter().map(|e| e.extras()).collect();

        let pos = at.index(block.len() + 1);
        let mut poisoned = block.clone();
        poisoned.insert(pos, bad);
        if later_bad {
            // A second bad value after the first: the first is the one named.
            poisoned.push(-2.0);
        }
        let err = bank.push_slice(&poisoned).unwrap_err();
        let index = head.len() + pos;
        match &err {
            fireflies::Error::InvalidSample { index: i, value } => {
                prop_assert_eq!(*i, index as u64);
                prop_assert_eq!(value.to_bits(), bad.to_bits());
            }
            other => prop_assert!(false, "wrong error {:?}", other),
        }
        prop_assert!(err.to_string().starts_with(&format!("invalid sample at index {index}: ")), "{}", err);

        // Nothing was applied: counts, estimates and extras are as before, bit for bit.
        prop_assert_eq!(bank.count(), head.len() as u64);
        let after = bank.estimates().unwrap();
        prop_assert_eq!(
            after.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            before.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        for (e, x) in bank.estimators().iter().zip(&extras_before) {
            prop_assert_eq!(e.count(), head.len() as u64);
            prop_assert_eq!(&e.extras(), x);
        }

        // The stream goes on as if the bad block had never been offered.
        bank.push_slice(&block).unwrap();
        let whole: Vec<f64> = head.iter().chain(&block).copied().collect();
        for (spec, g) in all.iter().zip(bank.estimates().unwrap()) {
            prop_assert_eq!(g.to_bits(), est(spec, &whole).to_bits(), "{}", spec);
        }
    }

    #[test]
    fn bank_single_push_rejects_bad_samples(xs in samples(), bad in prop::sample::select(vec![f64::NAN, f64::INFINITY, -0.5])) {
        let mut bank = Bank::new(&[EstimatorSpec::Mean(MeanSpec), EstimatorSpec::Gmon(GmonSpec { m: 5 })]).unwrap();
        for &x in &xs {
            bank.push(x).unwrap();
        }
        let before = bank.estimates().unwrap();
        let err = bank.push(bad).unwrap_err();
        prop_assert!(matches!(err, fireflies::Error::InvalidSample { index, .. } if index == xs.len() as u64), "{:?}", err);
        prop_assert_eq!(bank.estimates().unwrap(), before);
    }

    #[test]
    fn reset_forgets_everything(
        xs in samples(),
        ys in samples(),
        m in m_sets(),
        m_max in odd_m_max(),
    ) {
        for spec in specs(m, 1.5, 0.3, m_max, 0.25) {
            let mut e = fed(&spec, &xs);
            e.reset();
            prop_assert_eq!(e.count(), 0);
            prop_assert!(e.estimate().is_err(), "{}: estimate after reset", spec);
            e.push_slice(&ys);
            prop_assert_eq!(e.estimate().unwrap().to_bits(), est(&spec, &ys).to_bits(), "{}", spec);
        }
    }
}
