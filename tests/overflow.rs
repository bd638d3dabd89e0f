//! Finite samples always have a finite estimate (issue 10, items 9 and 10).
//!
//! The mean of finite samples is at most the largest of them, yet `[1e308; 3]` used to sum to
//! `+inf` and every estimator that sums samples, set means or buffers reported `null`. Each
//! estimator, through its spec string, is fed streams whose sums overflow — equal samples at
//! `1e308` and `f64::MAX`, a mix of `1e308` and `1e-300`, fewer samples than sets, a single
//! sample — and must give a finite estimate, equal to the exact answer where it is known.
//!
//! Where no closed form is at hand, the oracle is the same estimator on the stream scaled
//! down by `2^-600` (with its scale parameters `c`, `u`, `σ_image` scaled alike), multiplied
//! back: multiplying by a power of two is exact, so an implementation that keeps its sums
//! finite must agree bit for bit. The scaled-down stream overflows nothing, so the oracle is
//! the code path the spec examples already pin.

use fireflies::estimators::zirr::MIN_UNIT;
use fireflies::estimators::{
    ClampSpec, Estimator, EstimatorSpec, Extra, JungSpec, ZirrParams, ZirrRefSpec, ZirrSpec,
    build_rgb,
};
use proptest::prelude::*;
use proptest::test_runner::Config;

#[allow(dead_code)] // REL: this file states its own tolerances
use crate::common;
use common::{S, assert_rel};

/// Every estimator name, at parameters that exercise the overflowing paths: an even number of
/// sets (median of two), `G-MoN_b` forced to either branch, a clamp that clamps nothing, fixed
/// and growing Zirr cascades, Pajot before and after learning.
const SPECS: &[&str] = &[
    "mean",
    "clamp:c=1.7976931348623157e308",
    "clamp:c=1e308",
    "mon:M=1",
    "mon:M=2",
    "mon:M=21",
    "mon:M=300",
    "gini:M=21",
    "gmonb:M=21",
    "gmonb:M=21,threshold=0",
    "gmonb:M=4,threshold=1",
    "gmon:M=4",
    "gmon:M=21",
    "jung:sigma_image=1",
    "jung:sigma_image=1e300,m_max=5",
    "zirr",
    "zirr:J=6",
    "zirr:b=2.5,kappa=0.25,kappa_min=0",
    "zirr-ref",
    "zirr-ref:kappa=4,u=0.5",
    "pajot-rot",
    "pajot-adr",
    "pajot-hybrid",
    "pajot-rot:learn=2",
    "pajot-adr:learn=0",
    "pajot-hybrid:learn=3,T=1",
];

/// The estimators whose estimate is a mean of samples, of clamped samples or of set means,
/// run per channel by the RGB film.
fn is_mean_like(spec: &str) -> bool {
    !(spec.starts_with("gini") || spec.starts_with("zirr") || spec.starts_with("pajot"))
}

/// The exact estimate of `spec` on a stream of `x` repeated, where the method fixes it: the
/// value itself for means (clamped for `clamp`). Means of `n` equal values are exact when the
/// rounded `n·x`, divided by `n`, rounds back to `x` (see
/// [`all_equal_streams_give_their_value`]). Gini's formula gives 0 up to its last rounding
/// (`2.2e-16` for three values with f64::MAX's mantissa, at any scale): see [`assert_even`].
fn exact_for_equal(spec: &str, x: f64) -> Option<f64> {
    match parse(spec) {
        EstimatorSpec::Clamp(ClampSpec { c }) => Some(x.min(c)),
        _ if is_mean_like(spec) => Some(x),
        _ => None,
    }
}

fn parse(spec: &str) -> EstimatorSpec {
    spec.parse()
        .unwrap_or_else(|e| panic!("spec '{spec}' should parse: {e}"))
}

fn build(spec: &EstimatorSpec) -> Box<dyn Estimator> {
    spec.build()
        .unwrap_or_else(|e| panic!("spec '{spec:?}' should build: {e}"))
}

/// The estimate of `spec` on `xs`, pushed in two uneven blocks (so both the block loops and
/// their undo paths run) and checked against pushing one by one.
fn estimate(spec: &EstimatorSpec, xs: &[f64]) -> f64 {
    let mut blocks = build(spec);
    let cut = xs.len() / 3;
    blocks.push_slice(&xs[..cut]);
    blocks.push_slice(&xs[cut..]);
    let mut one = build(spec);
    xs.iter().for_each(|&x| one.push(x));
    let (a, b) = (blocks.estimate().unwrap(), one.estimate().unwrap());
    assert_eq!(
        a.to_bits(),
        b.to_bits(),
        "{spec:?}: blocks {a:e} vs one by one {b:e}"
    );
    assert!(a.is_finite(), "{spec:?}: estimate {a}");
    a
}

/// `spec` with its scale parameters (`c`, `σ_image`, `u`) multiplied by `factor`.
fn rescaled(spec: &EstimatorSpec, factor: f64) -> EstimatorSpec {
    match *spec {
        EstimatorSpec::Clamp(ClampSpec { c }) => EstimatorSpec::Clamp(ClampSpec { c: c * factor }),
        EstimatorSpec::Jung(JungSpec { sigma_image, m_max }) => EstimatorSpec::Jung(JungSpec {
            sigma_image: sigma_image * factor,
            m_max,
        }),
        EstimatorSpec::Zirr(ZirrSpec(p)) => EstimatorSpec::Zirr(ZirrSpec(ZirrParams {
            u: p.u * factor,
            ..p
        })),
        EstimatorSpec::ZirrRef(ZirrRefSpec(p)) => EstimatorSpec::ZirrRef(ZirrRefSpec(ZirrParams {
            u: p.u * factor,
            ..p
        })),
        other => other,
    }
}

/// Whether the estimate is a ratio that does not scale with the samples.
fn is_scale_free(spec: &EstimatorSpec) -> bool {
    matches!(spec, EstimatorSpec::Gini(_))
}

/// The estimate on `xs` scaled by `2^k` (scale parameters too), scaled back by `2^-k`.
fn estimate_scaled(spec: &EstimatorSpec, xs: &[f64], k: i32) -> f64 {
    let (up, down) = (2f64.powi(k), 2f64.powi(-k));
    let ys: Vec<f64> = xs.iter().map(|x| x * up).collect();
    let e = estimate(&rescaled(spec, up), &ys);
    // Saturated as the estimators saturate: an estimate a rounding above f64::MAX·2^k stands
    // for a true value of at most f64::MAX.
    if is_scale_free(spec) {
        e
    } else {
        (e * down).min(f64::MAX)
    }
}

/// Asserts that `spec` on `xs` gives bit for bit its estimate on `xs·2^-600`, times `2^600`.
#[track_caller]
fn assert_matches_scaled_down(spec: &str, xs: &[f64]) -> f64 {
    let parsed = parse(spec);
    let e = estimate(&parsed, xs);
    let oracle = estimate_scaled(&parsed, xs, -600);
    assert_eq!(
        e.to_bits(),
        oracle.to_bits(),
        "{spec}: {e:e}, but {oracle:e} from the stream scaled down by 2^-600"
    );
    e
}

// ---------------------------------------------------------------------------------------------
// Streams whose sums overflow

#[test]
fn three_samples_of_1e308() {
    let xs = [1e308; 3];
    for spec in SPECS {
        let e = assert_matches_scaled_down(spec, &xs);
        if let Some(want) = exact_for_equal(spec, 1e308) {
            assert_eq!(e, want, "{spec}");
        } else if spec.starts_with("gini") {
            assert_even(spec, e);
        } else if spec.starts_with("zirr-ref") {
            // The released code clamps each sample at its top buffer's brightness.
            assert!(e <= 1e308, "{spec}: {e:e}");
        } else if spec.starts_with("zirr") {
            // Three equal samples count 3 > kappa_min and pass; the split between two buffers
            // and their sum round, so equality holds to a few ulps.
            assert_rel(e, 1e308, 1e-15);
        } else {
            // Pajot: three equal logs form an extended mode; all are accepted.
            assert_eq!(e, 1e308, "{spec}");
        }
    }
}

#[test]
fn a_thousand_samples_of_f64_max() {
    let xs = vec![f64::MAX; 1000];
    for spec in SPECS {
        let e = assert_matches_scaled_down(spec, &xs);
        if spec == &"gmon:M=21" {
            // G-MoN's spec'd plain sum of 21 equal set means rounds down, one ulp below
            // f64::MAX, as it does for this mantissa at any scale (21·x / 21 < x).
            assert_eq!(e, below(f64::MAX), "{spec}");
        } else if let Some(want) = exact_for_equal(spec, f64::MAX) {
            assert_eq!(e, want, "{spec}");
        } else if spec.starts_with("gini") {
            assert_even(spec, e);
        } else if spec.starts_with("zirr-ref") {
            assert!(e <= f64::MAX, "{spec}: {e:e}");
        } else if spec.starts_with("zirr") {
            // Zirr splits each sample between two buffers and sums them back: a few ulps.
            assert_rel(e, f64::MAX, 1e-15);
        } else {
            assert_eq!(e, f64::MAX, "{spec}");
        }
    }
}

/// Asserts that a Gini coefficient of equal set means is 0 up to the rounding of
/// `2·s2/(K·s1) − (K+1)/K`.
#[track_caller]
fn assert_even(spec: &str, g: f64) {
    assert!(
        (0.0..=4.0 * f64::EPSILON).contains(&g),
        "{spec}: Gini {g:e}"
    );
}

/// The largest f64 below the positive normal `x`.
fn below(x: f64) -> f64 {
    f64::from_bits(x.to_bits() - 1)
}

#[test]
fn all_equal_streams_give_their_value() {
    // n·x/n with a correctly rounded n·x gives x back for these n (and the set sizes they
    // make) at f64::MAX and at 1e308 ...
    for (x, ns) in [
        (f64::MAX, &[1usize, 2, 3, 4, 47, 48, 1000][..]),
        (1e308, &[1, 2, 3, 5, 17, 47, 333, 1000][..]),
    ] {
        for &n in ns {
            let xs = vec![x; n];
            for spec in SPECS {
                let e = assert_matches_scaled_down(spec, &xs);
                if spec.starts_with("gini") {
                    assert_even(spec, e);
                }
                let Some(want) = exact_for_equal(spec, x) else {
                    continue;
                };
                if spec.starts_with("gmon:") && x == f64::MAX && n > 4 {
                    // The plain sum of more than 4 set means, see a_thousand_samples_of_f64_max.
                    assert_rel(e, want, 1e-15);
                } else {
                    assert_eq!(e, want, "{spec} on [{x:e}; {n}]");
                }
            }
        }
    }
    // ... but not for every n: 5·x rounds so that 5·x/5 is one ulp below x = f64::MAX, exactly
    // as for the same mantissa at ordinary scale (1.9999999999999998 · 5 / 5). Still finite.
    let e = assert_matches_scaled_down("mean", &[f64::MAX; 5]);
    assert_eq!(e, below(f64::MAX));
}

#[test]
fn single_samples_at_f64_max() {
    for spec in SPECS {
        let e = assert_matches_scaled_down(spec, &[f64::MAX]);
        if let Some(want) = exact_for_equal(spec, f64::MAX) {
            assert_eq!(e, want, "{spec}");
        } else if spec.starts_with("gini") {
            assert_eq!(e, 0.0, "{spec}: one set");
        } else if spec.starts_with("pajot") || *spec == "zirr" {
            // docs/estimators.md §6.1: a value is trusted only once a similar one corroborates it. §5: a lone
            // sample counts 1 = kappa_min and is rejected.
            assert_eq!(e, 0.0, "{spec}");
        } else {
            // Fixed cascades let a lone sample above the top pass (docs/estimators.md §5, consequence (i));
            // kappa_min = 0 keeps it; zirr-ref weighs it down.
            assert!((0.0..=f64::MAX).contains(&e), "{spec}: {e:e}");
        }
    }
}

#[test]
fn fewer_samples_than_sets() {
    // n = 10 < M = 21 (and 10 is not a multiple of 21): K = 10 sets of one sample, an even
    // count, so the median averages two values near 1e308.
    let xs = [1e308; 10];
    for spec in SPECS {
        let e = assert_matches_scaled_down(spec, &xs);
        if let Some(want) = exact_for_equal(spec, 1e308) {
            assert_eq!(e, want, "{spec}");
        } else if spec.starts_with("gini") {
            assert_even(spec, e);
        }
    }
    // Distinct values, n = 50 not a multiple of 21 (sets of 3 and 2): the oracle is the same
    // stream scaled down. Jung is left out: docs/estimators.md §1's Welford σ overflows at this scale (see
    // `jung_keeps_the_spec_welford`).
    let xs: Vec<f64> = (0..50)
        .map(|i| f64::MAX * (1.0 - i as f64 / 64.0))
        .collect();
    let xs10 = &xs[..10];
    for spec in SPECS.iter().filter(|s| !s.starts_with("jung")) {
        assert_matches_scaled_down(spec, &xs);
        let e = assert_matches_scaled_down(spec, xs10);
        assert!(e <= f64::MAX, "{spec}");
    }
    // MoN(21) of 10 samples: the mean of the 5th and 6th smallest, whose sum overflows.
    let e = estimate(&parse("mon:M=21"), xs10);
    assert_eq!(e, xs10[5] / 2.0 + xs10[4] / 2.0);
    assert_rel(e, f64::MAX * (1.0 - 4.5 / 64.0), 1e-15);
}

#[test]
fn a_mix_of_1e308_and_1e_300() {
    // 1e308 at even indices, 1e-300 at odd ones: every set of M = 2, 21 or 17 (Jung's m_max,
    // chosen because sigma_pixel overflows) holds about half of each, the sets with M = 2 hold
    // one kind each, and Pajot finds two extended modes, the upper one at 1e308. Everything
    // comes to 1e308 / 2 up to a few roundings; the 1e-300 samples are far below one ulp.
    let xs: Vec<f64> = (0..1000)
        .map(|i| if i % 2 == 0 { 1e308 } else { 1e-300 })
        .collect();
    for spec in SPECS {
        let parsed = parse(spec);
        let e = estimate(&parsed, &xs);
        match spec {
            s if s.starts_with("gini") => assert!((0.0..0.05).contains(&e), "{s}: {e}"),
            s if s.starts_with("zirr-ref") => assert!((0.0..1e308).contains(&e), "{s}: {e:e}"),
            _ => assert_rel(e, 1e308 / 2.0, 1e-15),
        }
        // The extras are finite too (Zirr's B and discarded energy, Jung's M, Gini).
        let mut est = build(&parsed);
        est.push_slice(&xs);
        for (key, extra) in est.extras() {
            let values = match extra {
                Extra::Float(v) => vec![v],
                Extra::Floats(v) => v,
                _ => continue,
            };
            if matches!(key, "B" | "discarded" | "gini" | "w") {
                assert!(
                    values.iter().all(|v| v.is_finite()),
                    "{spec}: {key} {values:?}"
                );
            }
        }
    }
}

#[test]
fn jung_keeps_the_spec_welford() {
    // docs/estimators.md §1 defines sigma as +inf once m2 overflows, and tests/hard_cases.rs pins that Jung
    // follows it: M = m_max. The estimate, MoN(m_max), is finite all the same: here each of
    // the 17 sets holds two samples of f64::MAX and two zeros, whose sum overflowed.
    let xs: Vec<f64> = (0..68)
        .map(|i| if i % 2 == 0 { f64::MAX } else { 0.0 })
        .collect();
    let mut j = parse("jung:sigma_image=1e300").build().unwrap();
    j.push_slice(&xs);
    let extra = |key: &str| j.extras().into_iter().find(|(k, _)| *k == key).unwrap().1;
    assert_eq!(extra("M"), Extra::Int(17));
    assert_eq!(extra("sigma_pixel"), Extra::Float(f64::INFINITY));
    assert_eq!(j.estimate().unwrap(), f64::MAX / 2.0);
}

#[test]
fn the_issue_reproduction_through_the_command_line() {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let mut args = vec!["eval".to_string()];
    for spec in SPECS {
        args.extend(["-e".to_string(), spec.to_string()]);
    }
    let mut child = Command::new(env!("CARGO_BIN_EXE_fireflies"))
        .args(&args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(b"1e308 1e308 1e308")
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), SPECS.len());
    for line in &lines {
        let e = line["estimate"].as_f64();
        assert!(e.is_some_and(f64::is_finite), "{line}");
    }
    assert_eq!(lines[0]["estimate"].as_f64(), Some(1e308));
}

// ---------------------------------------------------------------------------------------------
// RGB

#[test]
fn rgb_estimators_stay_finite() {
    // Grey samples at f64::MAX, then colours whose red and green channels alternate between
    // 1e308 and 1e-300 while blue stays at 1e308.
    let grey = vec![[f64::MAX; 3]; 100];
    let colour: Vec<[f64; 3]> = (0..100)
        .map(|i| {
            let v = if i % 2 == 0 { 1e308 } else { 1e-300 };
            [v, v * 0.5, 1e308]
        })
        .collect();
    for spec in SPECS {
        let parsed = parse(spec);
        let scalar = |xs: &[f64]| {
            let mut e = build(&parsed);
            e.push_slice(xs);
            e.estimate().unwrap()
        };
        let mut e = build_rgb(&parsed).unwrap();
        e.push_slice(&grey[..30]);
        e.push_slice(&grey[30..]);
        // A grey stream gives the scalar estimate in every channel (rgb.rs, "Luminance").
        let want = scalar(&[f64::MAX; 100]);
        assert_eq!(e.estimate().unwrap(), [want; 3], "{spec}");

        let mut e = build_rgb(&parsed).unwrap();
        e.push_slice(&colour);
        let est = e.estimate().unwrap();
        assert!(est.iter().all(|v| v.is_finite()), "{spec}: {est:?}");
        if is_mean_like(spec) || spec.starts_with("gini") {
            // Per channel: each channel's estimate is the scalar one on that channel.
            for (c, &v) in est.iter().enumerate() {
                let channel: Vec<f64> = colour.iter().map(|p| p[c]).collect();
                assert_eq!(v, scalar(&channel), "{spec}, channel {c}");
            }
        }
        if !(spec.starts_with("gini") || spec.starts_with("zirr-ref")) {
            // Every method keeps both kinds of sample here (Zirr weighs both clusters of
            // luminance 1, Pajot finds two extended modes): the channel means.
            assert_rel(est[0], 1e308 / 2.0, 1e-15);
            assert_rel(est[2], 1e308, 1e-15);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Zirr's unit

#[test]
fn zirr_rejects_a_unit_whose_reciprocal_overflows() {
    for name in ["zirr", "zirr-ref"] {
        let spec = parse(&format!("{name}:u=5e-324"));
        let err = spec.build().map(|_| ()).unwrap_err().to_string();
        assert!(err.contains("u = 5e-324"), "{err}");
        assert!(
            err.contains("[5.56268464626801e-309, 1.7976931348623157e308]"),
            "{err}"
        );
        assert!(build_rgb(&spec).is_err());
        // 2^-1024 = 1/f64::MAX rounded: its reciprocal is 2^1024 = +inf.
        let two_to_minus_1024 = f64::from_bits(1 << 50);
        assert_eq!(two_to_minus_1024, 1.0 / f64::MAX);
        let err = parse(&format!("{name}:u={two_to_minus_1024:e}"))
            .build()
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(err.contains("u = 5.562684646268003e-309"), "{err}");
        // The smallest accepted unit, and any larger one, builds.
        assert_eq!(MIN_UNIT, 5.56268464626801e-309);
        assert!((1.0 / MIN_UNIT).is_finite());
        for u in [MIN_UNIT, 1e-300, 1.0, 1e300] {
            let spec = parse(&format!("{name}:u={u:e}"));
            let mut e = build(&spec);
            e.push_slice(&S);
            assert!(e.estimate().unwrap().is_finite(), "{name} u = {u:e}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Scaling by a power of two

/// Cases per property: enough to reach the rescaling regime often, small enough that the file
/// runs in a second or two in release.
const CASES: u32 = 256;

fn config() -> Config {
    Config {
        cases: CASES,
        ..Config::default()
    }
}

/// One sample: zeros, ties, and values `m·2^e` with `m` in `[1, 2)`, `e` in `-30..=30`, so that
/// any scaling by `2^k`, `k` in `SCALES`, keeps every sample and every rounding error of their
/// sums a normal number (no bits lost below `2^-1022`).
fn sample() -> impl Strategy<Value = f64> {
    prop_oneof![
        2 => Just(0.0),
        6 => (1.0f64..2.0, -30i32..=30).prop_map(|(m, e)| m * 2f64.powi(e)),
        2 => prop::sample::select(vec![0.1, 0.5, 1.0, 2.2, 3.0, 7.0]),
    ]
}

fn samples() -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(sample(), 1..150)
}

/// Scalings: down to `2^-900`, and up to `2^990`, where the samples reach `2^1021` and their
/// sums overflow (so the rescaled paths run).
fn scale() -> impl Strategy<Value = i32> {
    prop_oneof![-900i32..=990, 960i32..=990]
}

/// The estimators for which scaling the samples (and `c`, `u`) by `2^k` scales the estimate
/// by exactly `2^k` (Gini: leaves it unchanged). Not Jung: docs/estimators.md §1's Welford squares the
/// deviations, which overflow (sigma = +inf, M = m_max) or underflow (sigma = 0, M = 1) at
/// extreme scales, so its M, and the estimate, can change. Not Pajot: its decisions compare
/// rounded logarithms (`ln(2^k x) = k ln 2 + ln x` only up to rounding).
const EQUIVARIANT: &[&str] = &[
    "mean",
    "clamp:c=3",
    "mon:M=1",
    "mon:M=2",
    "mon:M=5",
    "mon:M=21",
    "mon:M=300",
    "gini:M=5",
    "gmonb:M=5",
    "gmonb:M=21,threshold=0.1",
    "gmon:M=4",
    "gmon:M=21",
    "zirr",
    "zirr:J=6",
    "zirr:b=2.5,kappa=0.25,kappa_min=0",
    "zirr-ref",
    "zirr-ref:kappa=4,u=0.5",
];

proptest! {
    #![proptest_config(config())]

    /// Scaling the stream by 2^k scales the estimate by exactly 2^k, including where the sums
    /// overflow f64 and are rescaled.
    #[test]
    fn scaling_by_a_power_of_two_is_exact(xs in samples(), k in scale()) {
        for spec in EQUIVARIANT {
            let parsed = parse(spec);
            let e = estimate(&parsed, &xs);
            let scaled = estimate_scaled(&parsed, &xs, k);
            prop_assert_eq!(scaled.to_bits(), e.to_bits(), "{} with k = {}: {:e} vs {:e}",
                spec, k, scaled, e);
        }
    }

    /// Every estimator gives a finite estimate for finite samples of any magnitude, most often
    /// near the top of the range, where a few samples overflow a plain sum.
    #[test]
    fn finite_samples_give_finite_estimates(
        xs in samples(),
        k in prop_oneof![-900i32..=992, 985i32..=992],
    ) {
        let c = 2f64.powi(k);
        let ys: Vec<f64> = xs.iter().map(|x| x * c).collect();
        for spec in SPECS {
            // estimate() asserts finiteness and agreement of block and single pushes.
            estimate(&parse(spec), &ys);
        }
    }
}
