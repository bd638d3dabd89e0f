//! Every worked example of `docs/estimators.md` §1–§4 reproduced to 1e-12 relative, through
//! every way a sample stream can reach an estimator (one by one, uneven blocks, a Bank), plus
//! the spec-string grammar of §1a for these estimators.
//!
//! The expected values are the spec's own numbers, typed in from the document; none is
//! computed by the crate under test.

use fireflies::Error;
use fireflies::estimators::{
    Bank, Clamp, ClampSpec, Estimator, EstimatorSpec, Extra, GiniDiagnostic, GiniSpec, Gmon, GmonB,
    GmonBSpec, GmonSpec, Jung, JungSpec, Mean, MeanSpec, Mon, MonSpec,
};

use crate::common;
use common::{REL, S, assert_rel};

fn parse(spec: &str) -> EstimatorSpec {
    spec.parse()
        .unwrap_or_else(|e| panic!("spec '{spec}' should parse: {e}"))
}

fn build(spec: &str) -> Box<dyn Estimator> {
    parse(spec)
        .build()
        .unwrap_or_else(|e| panic!("spec '{spec}' should build: {e}"))
}

/// Block splittings of the 7-sample example: sizes sum to 7, uneven, with empty blocks and
/// blocks that cross the M = 3 and M = 5 round boundaries.
const SPLITS: &[&[usize]] = &[
    &[7],
    &[1, 6],
    &[6, 1],
    &[3, 0, 4],
    &[2, 2, 2, 1],
    &[4, 3],
    &[1, 1, 1, 1, 1, 1, 1],
    &[0, 5, 0, 2, 0],
];

/// Feeds `samples` to `spec` one by one, in every split of [`SPLITS`] through `push_slice`,
/// and through a Bank (in blocks and sample by sample); checks all routes agree bit for bit
/// and returns the estimate.
fn estimate_all_routes(spec: &str, samples: &[f64]) -> f64 {
    let mut one = build(spec);
    for &s in samples {
        one.push(s);
    }
    assert_eq!(one.count(), samples.len() as u64, "{spec}: count");
    let reference = one.estimate().unwrap();

    for split in SPLITS
        .iter()
        .filter(|s| s.iter().sum::<usize>() == samples.len())
    {
        let mut blocks = build(spec);
        let mut bank = Bank::new(&[parse(spec)]).unwrap();
        let mut at = 0;
        for &len in *split {
            blocks.push_slice(&samples[at..at + len]);
            bank.push_slice(&samples[at..at + len]).unwrap();
            at += len;
        }
        assert_eq!(
            blocks.estimate().unwrap().to_bits(),
            reference.to_bits(),
            "{spec}: push_slice in blocks {split:?} differs from push"
        );
        assert_eq!(bank.count(), samples.len() as u64);
        assert_eq!(
            bank.estimates().unwrap()[0].to_bits(),
            reference.to_bits(),
            "{spec}: Bank in blocks {split:?} differs from push"
        );
    }

    let mut bank = Bank::new(&[parse(spec)]).unwrap();
    for &s in samples {
        bank.push(s).unwrap();
    }
    assert_eq!(
        bank.estimates().unwrap()[0].to_bits(),
        reference.to_bits(),
        "{spec}: Bank::push differs from push"
    );
    reference
}

fn extra_f64(e: &dyn Estimator, key: &str) -> f64 {
    match e.extras().into_iter().find(|(k, _)| *k == key) {
        Some((_, Extra::Float(x))) => x,
        other => panic!("{e}: extra '{key}' missing or not a float: {other:?}"),
    }
}

fn extra_int(e: &dyn Estimator, key: &str) -> u64 {
    match e.extras().into_iter().find(|(k, _)| *k == key) {
        Some((_, Extra::Int(x))) => x,
        other => panic!("{e}: extra '{key}' missing or not an integer: {other:?}"),
    }
}

// §2 ------------------------------------------------------------------------------------------

#[test]
fn mean_of_running_example() {
    assert_rel(estimate_all_routes("mean", &S), 51.885714285714286, REL);
    assert_rel(estimate_all_routes("mean", &S), 363.2 / 7.0, REL);
}

#[test]
fn clamp_at_10_of_running_example() {
    assert_rel(
        estimate_all_routes("clamp:c=10", &S),
        3.314285714285714,
        REL,
    );
    assert_rel(estimate_all_routes("clamp:c=10", &S), 23.2 / 7.0, REL);
}

// §3 ------------------------------------------------------------------------------------------

/// One row of the §3 table: M, MoN, G, c, G-MoN, G-MoN_b(0.25).
struct Row {
    m: usize,
    mon: f64,
    gini: f64,
    trimmed: u64,
    gmon: f64,
    gmonb: f64,
}

const ROWS: [Row; 3] = [
    Row {
        m: 3,
        mon: 3.15,
        gini: 0.6380345432714516,
        trimmed: 0,
        gmon: 60.15,
        gmonb: 3.15,
    },
    Row {
        m: 5,
        mon: 2.8,
        gini: 0.7632631010264719,
        trimmed: 1,
        gmon: 3.266666666666667,
        gmonb: 2.8,
    },
    Row {
        m: 21,
        mon: 2.2,
        gini: 0.8346444304594085,
        trimmed: 2,
        gmon: 2.6,
        gmonb: 2.2,
    },
];

#[test]
fn median_of_means_table_rows() {
    for r in &ROWS {
        let m = r.m;
        assert_rel(estimate_all_routes(&format!("mon:M={m}"), &S), r.mon, REL);
        assert_rel(estimate_all_routes(&format!("gini:M={m}"), &S), r.gini, REL);
        assert_rel(estimate_all_routes(&format!("gmon:M={m}"), &S), r.gmon, REL);
        assert_rel(
            estimate_all_routes(&format!("gmonb:M={m}"), &S),
            r.gmonb,
            REL,
        );
        assert_rel(
            estimate_all_routes(&format!("gmonb:M={m},threshold=0.25"), &S),
            r.gmonb,
            REL,
        );
    }
}

#[test]
fn gmon_reports_gini_and_trimming_of_table_rows() {
    for r in &ROWS {
        let mut g = Gmon::new(r.m).unwrap();
        g.push_slice(&S);
        assert_rel(extra_f64(&g, "gini"), r.gini, REL);
        assert_eq!(extra_int(&g, "trimmed"), r.trimmed, "M = {}", r.m);
    }
}

#[test]
fn m5_worked_example_in_detail() {
    // G = 1817/925.5 - 1.2, the spec's closed form.
    assert_rel(
        estimate_all_routes("gini:M=5", &S),
        1817.0 / 925.5 - 1.2,
        REL,
    );
    assert_rel(estimate_all_routes("mon:M=5", &S), 2.8, REL);
    assert_rel(
        estimate_all_routes("gmon:M=5", &S),
        (2.2 + 2.8 + 4.8) / 3.0,
        REL,
    );
    assert_rel(estimate_all_routes("gmonb:M=5", &S), 2.8, REL);
    // Threshold 0.8 > G: the overall sample mean (not the mean of set means, 36.98).
    assert_rel(
        estimate_all_routes("gmonb:M=5,threshold=0.8", &S),
        51.885714285714286,
        REL,
    );
}

#[test]
fn gmonb_reports_its_decision() {
    let mut low = GmonB::new(5, 0.25).unwrap();
    let mut high = GmonB::new(5, 0.8).unwrap();
    low.push_slice(&S);
    high.push_slice(&S);
    for (e, used_mon) in [(&low, true), (&high, false)] {
        assert_rel(extra_f64(e, "gini"), 0.7632631010264719, REL);
        let flag = e.extras().into_iter().find(|(k, _)| *k == "used_mon");
        assert_eq!(flag, Some(("used_mon", Extra::Bool(used_mon))), "{e}");
    }
}

#[test]
fn m3_gmon_is_the_mean_of_set_means() {
    // docs/estimators.md §3 note: with M = 3, c = 0 for every G < 1, so G-MoN(3) is the mean of the three
    // set means (2.3 + 3.15 + 175)/3, not the sample mean.
    let g = estimate_all_routes("gmon:M=3", &S);
    assert_rel(g, (2.3 + 3.15 + 175.0) / 3.0, REL);
    assert!((g - 51.885714285714286).abs() > 1.0);
}

// §4 ------------------------------------------------------------------------------------------

#[test]
fn jung_worked_examples() {
    // (sigma_image, chosen M, estimate)
    let cases = [
        (40.0, 5, 2.8),
        (200.0, 1, 51.885714285714286),
        (0.5, 17, 2.2),
    ];
    for (sigma_image, m, expected) in cases {
        let spec = format!("jung:sigma_image={sigma_image}");
        assert_rel(estimate_all_routes(&spec, &S), expected, REL);
        let mut j = Jung::new(sigma_image, 17).unwrap();
        j.push_slice(&S);
        assert_eq!(j.chosen_m(), m, "sigma_image = {sigma_image}");
        assert_eq!(extra_int(&j, "M"), m as u64, "sigma_image = {sigma_image}");
        assert_rel(extra_f64(&j, "sigma_pixel"), 121.71536384499028, REL);
    }
}

#[test]
fn jung_m_max_caps_the_choice() {
    // ratio 243 would give M = 17; m_max = 5 caps it: MoN(5) = 2.8.
    assert_rel(
        estimate_all_routes("jung:sigma_image=0.5,m_max=5", &S),
        2.8,
        REL,
    );
    let mut j = Jung::new(0.5, 5).unwrap();
    j.push_slice(&S);
    assert_eq!(j.chosen_m(), 5);
}

// §1 ------------------------------------------------------------------------------------------

#[test]
fn invalid_sample_error_names_index_and_value() {
    // The spec's own message: `invalid sample at index 2: NaN`.
    let mut bank = Bank::new(&[parse("mean")]).unwrap();
    let err = bank.push_slice(&[0.6, 1.5, f64::NAN]).unwrap_err();
    assert_eq!(err.to_string(), "invalid sample at index 2: NaN");
    assert!(matches!(err, Error::InvalidSample { index: 2, value } if value.is_nan()));
    // The index counts from the start of the stream, not of the block.
    bank.push_slice(&[0.6, 1.5]).unwrap();
    let err = bank.push_slice(&[2.0, -1.0]).unwrap_err();
    assert_eq!(err.to_string(), "invalid sample at index 3: -1");
}

#[test]
fn negative_zero_is_a_valid_zero() {
    let mut with_neg = Bank::new(&[parse("mean"), parse("gmon:M=5")]).unwrap();
    with_neg
        .push_slice(&[0.6, 1.5, -0.0, 2.2, 4.8, 350.0, 4.1])
        .unwrap();
    let est = with_neg.estimates().unwrap();
    assert_rel(est[0], 51.885714285714286, REL);
    assert_rel(est[1], 3.266666666666667, REL);
}

#[test]
fn empty_stream_is_an_error() {
    for spec in [
        "mean",
        "clamp:c=10",
        "mon:M=5",
        "gini:M=5",
        "gmonb:M=5",
        "gmon:M=5",
    ] {
        let e = build(spec).estimate().unwrap_err();
        assert!(e.to_string().contains("no samples"), "{spec}: {e}");
    }
    let e = build("jung:sigma_image=40").estimate().unwrap_err();
    assert!(e.to_string().contains("no samples"), "{e}");
}

// §1a: spec strings ---------------------------------------------------------------------------

const CANONICAL: &[&str] = &[
    "mean",
    "clamp:c=10",
    "mon:M=5",
    "gini:M=5",
    "gmonb:M=5,threshold=0.25",
    "gmonb:M=21,threshold=0.25",
    "gmonb:M=5,threshold=0.8",
    "gmon:M=21",
    "jung:sigma_image=40,m_max=17",
    "jung:sigma_image=0.5,m_max=5",
];

#[test]
fn printed_spec_parses_back_to_an_equal_estimator() {
    for &s in CANONICAL {
        let mut e = build(s);
        e.push_slice(&S);
        let printed = e.spec().to_string();
        assert_eq!(printed, s, "canonical form");
        let mut again = parse(&printed).build().unwrap();
        assert_eq!(
            again.to_string(),
            e.to_string(),
            "{s}: Display after round trip"
        );
        assert_eq!(again.count(), 0, "{s}: a rebuilt estimator starts empty");
        again.push_slice(&S);
        assert_eq!(
            again.estimate().unwrap().to_bits(),
            e.estimate().unwrap().to_bits(),
            "{s}: estimate after round trip"
        );
        assert_eq!(again.spec(), e.spec());
    }
}

#[test]
fn omitted_keys_take_defaults_and_keys_come_in_any_order() {
    assert_eq!(parse("gmonb:M=21").to_string(), "gmonb:M=21,threshold=0.25");
    assert_eq!(
        parse("gmonb:threshold=0.8,M=5"),
        parse("gmonb:M=5,threshold=0.8")
    );
    assert_eq!(
        parse("jung:sigma_image=0.5").to_string(),
        "jung:sigma_image=0.5,m_max=17"
    );
    assert_eq!(
        parse("jung:m_max=5,sigma_image=0.5").to_string(),
        "jung:sigma_image=0.5,m_max=5"
    );
    assert_eq!(parse("clamp:c=1e1"), parse("clamp:c=10"));
}

#[test]
fn spec_variants_carry_the_parameters() {
    assert_eq!(parse("mean"), EstimatorSpec::Mean(MeanSpec));
    assert_eq!(
        parse("clamp:c=10"),
        EstimatorSpec::Clamp(ClampSpec { c: 10.0 })
    );
    assert_eq!(parse("mon:M=21"), EstimatorSpec::Mon(MonSpec { m: 21 }));
    assert_eq!(parse("gini:M=21"), EstimatorSpec::Gini(GiniSpec { m: 21 }));
    assert_eq!(parse("gmon:M=21"), EstimatorSpec::Gmon(GmonSpec { m: 21 }));
    assert_eq!(
        parse("gmonb:M=21"),
        EstimatorSpec::GmonB(GmonBSpec {
            m: 21,
            threshold: 0.25
        })
    );
    assert_eq!(
        parse("jung:sigma_image=0.5"),
        EstimatorSpec::Jung(JungSpec {
            sigma_image: 0.5,
            m_max: 17
        })
    );
}

#[test]
fn display_is_compact() {
    assert_eq!(Mon::new(5).unwrap().to_string(), "MoN(M=5)");
    assert_eq!(Gmon::new(21).unwrap().to_string(), "G-MoN(M=21)");
    assert_eq!(build("gmon:M=21").to_string(), "G-MoN(M=21)");
    assert_eq!(build("mon:M=5").to_string(), "MoN(M=5)");
    // The others are not fixed by the spec; they must at least name their parameters.
    assert_eq!(Mean::new().to_string(), "Mean");
    let shown = [
        (Clamp::new(10.0).unwrap().to_string(), vec!["10"]),
        (GiniDiagnostic::new(5).unwrap().to_string(), vec!["M=5"]),
        (
            GmonB::new(21, 0.25).unwrap().to_string(),
            vec!["M=21", "0.25"],
        ),
        (Jung::new(0.5, 17).unwrap().to_string(), vec!["0.5", "17"]),
    ];
    for (text, parts) in shown {
        for p in parts {
            assert!(text.contains(p), "'{text}' should contain '{p}'");
        }
        assert!(
            !text.contains(':'),
            "'{text}' looks like a spec string, not a name"
        );
    }
}

#[test]
fn unknown_names_and_keys_list_the_valid_ones() {
    let e = "median:M=5"
        .parse::<EstimatorSpec>()
        .unwrap_err()
        .to_string();
    for name in ["mean", "clamp", "mon", "gini", "gmonb", "gmon", "jung"] {
        assert!(e.contains(name), "'{e}' should list '{name}'");
    }
    let e = "gmonb:M=5,t=0.3"
        .parse::<EstimatorSpec>()
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("'t'") && e.contains("M") && e.contains("threshold"),
        "{e}"
    );
    let e = "jung:sigma=1"
        .parse::<EstimatorSpec>()
        .unwrap_err()
        .to_string();
    assert!(e.contains("sigma_image") && e.contains("m_max"), "{e}");
}

#[test]
fn malformed_specs_are_errors() {
    for bad in [
        "mon",        // M is required
        "gmon:M=5.0", // integer literal only
        "mon:M=-1",   // not a non-negative integer
        "mon:M=+5",   // a sign is not part of an integer literal (strict reading of §1a)
        "jung:sigma_image=1,m_max=17.0",
        "gmonb:M=5,M=5", // a key given twice
        "gmonb:M=5,threshold=0.2,threshold=0.3",
        "clamp", // c is required
        "clamp:c=ten",
        "jung:m_max=17", // sigma_image is required
        "mon:M",
        "",
    ] {
        assert!(
            bad.parse::<EstimatorSpec>().is_err(),
            "'{bad}' should not parse"
        );
    }
}

#[test]
fn invalid_parameters_are_errors_naming_the_value() {
    for (spec, needle) in [
        ("clamp:c=0", "0"),
        ("clamp:c=-1", "-1"),
        ("clamp:c=inf", "inf"),
        ("clamp:c=NaN", "NaN"),
        ("mon:M=0", "M"),
        ("gini:M=0", "M"),
        ("gmon:M=0", "M"),
        ("gmonb:M=0", "M"),
        ("jung:sigma_image=0", "sigma_image"),
        ("jung:sigma_image=-2", "-2"),
        ("jung:sigma_image=inf", "inf"),
        ("jung:sigma_image=1,m_max=16", "16"),
        ("jung:sigma_image=1,m_max=0", "m_max"),
    ] {
        let spec = parse(spec);
        let err = match spec.build() {
            Ok(e) => panic!("{spec} should not build, got {e}"),
            Err(err) => err.to_string(),
        };
        assert!(
            err.contains(needle),
            "{spec}: '{err}' should contain '{needle}'"
        );
    }
}
