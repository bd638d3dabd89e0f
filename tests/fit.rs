//! `fireflies fit`: generators fitted to pixel streams. Known parameters are recovered from
//! streams drawn with the crate's own generators (fixed seeds); hand-made cases pin the Hill
//! estimator, the threshold rule, the atoms and the mean-constrained lognormal exactly; the
//! fitted mean equals the stream's on many heavy-tailed streams and on real pixels rendered
//! by `fireflies render` (tests/data/fit/); the command line is driven as a user drives it.

use fireflies::dist::fit::{
    Detail, Role, TAIL_MIN_K, choose_tail, find_atoms, fit, hill, mean_constrained, tail_ks,
};
use fireflies::dist::{Dist, DistSpec, Preset};
use fireflies::harness::Experiment;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn draw(d: &Dist, seed: u64, n: usize) -> Vec<f64> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut v = vec![0.0; n];
    d.fill(&mut rng, &mut v);
    v
}

fn law(json: &str) -> Dist {
    serde_json::from_str::<DistSpec>(json)
        .unwrap()
        .build()
        .unwrap()
}

fn roles(f: &fireflies::dist::fit::Fit) -> Vec<Role> {
    f.components.iter().map(|c| c.role).collect()
}

#[track_caller]
fn assert_within(what: &str, actual: f64, expected: f64, tol: f64) {
    assert!(
        (actual - expected).abs() <= tol,
        "{what}: {actual} vs {expected} (tolerance {tol})"
    );
}

#[track_caller]
fn assert_mean_exact(f: &fireflies::dist::fit::Fit) {
    let rel = (f.mean() - f.stream_mean).abs() / f.stream_mean;
    assert!(
        rel <= 1e-9,
        "fitted mean {} vs stream mean {}: relative error {rel:e}",
        f.mean(),
        f.stream_mean
    );
}

// ---------------------------------------------------------------------------------------------
// Hand-made cases with exact answers
// ---------------------------------------------------------------------------------------------

#[test]
fn hill_on_a_hand_made_tail_and_its_errors() {
    // ln(e^3 / 1) + ln(e^2 / 1) + ln(e / 1) = 6 over k = 3: a = 1/2, se = a / sqrt(3).
    let desc = [3f64.exp(), 2f64.exp(), 1f64.exp(), 1.0, 0.5];
    let h = hill(&desc, 3).unwrap();
    assert_eq!((h.k, h.threshold), (3, 1.0));
    assert!((h.shape - 0.5).abs() < 1e-15);
    assert!((h.se - 0.5 / 3f64.sqrt()).abs() < 1e-15);
    // With k = 4 the threshold is 0.5: each of the four logs gains ln 2, sum = 6 + 4 ln 2.
    let h4 = hill(&desc, 4).unwrap();
    assert!((h4.shape - 4.0 / (6.0 + 4.0 * 2f64.ln())).abs() < 1e-15);
    for k in [0, 5, 9] {
        let e = hill(&desc, k).unwrap_err().to_string();
        assert!(e.contains('k') && e.contains(&k.to_string()), "{e}");
    }
    // A tie across the threshold leaves no tail strictly above it.
    let e = hill(&[4.0, 2.0, 2.0, 1.0], 2).unwrap_err().to_string();
    assert!(e.contains("strictly above"), "{e}");
}

#[test]
fn hill_recovers_the_shape_of_exact_pareto_samples() {
    // 10^5 draws of pareto(scale 2, shape 1.5): Hill on all but the smallest sample estimates
    // the shape with standard error a / sqrt(k) = 0.0047. Passing within 4 SE fails by chance
    // with probability 6e-5 (normal approximation, accurate at this k); it catches a shape off by
    // 2% (0.03), e.g. an off-by-one in k or the wrong threshold.
    let d = law(r#"{"kind":"pareto","scale":2.0,"shape":1.5}"#);
    let mut xs = draw(&d, 11, 100_000);
    xs.sort_by(|a, b| b.total_cmp(a));
    let h = hill(&xs, xs.len() - 1).unwrap();
    assert!(
        (h.shape - 1.5).abs() < 4.0 * h.se,
        "Hill {} ± {}",
        h.shape,
        h.se
    );
    assert!((h.se - 1.5 / (99_999f64).sqrt()).abs() < 1e-4);
}

/// A body of 200 values log-evenly spaced from 0.1 up to exactly 1, and above it the 100 exact
/// Pareto quantiles of scale 1 and shape 2 at the midpoints `(i - 1/2) / 100`.
fn constructed_stream() -> Vec<f64> {
    let mut xs: Vec<f64> = (0..200)
        .map(|i| 10f64.powf(-1.0 + i as f64 / 199.0))
        .collect();
    xs.extend((1..=100).map(|i| (1.0 - (i as f64 - 0.5) / 100.0).powf(-0.5)));
    xs
}

#[test]
fn threshold_rule_finds_the_start_of_a_constructed_pareto_tail() {
    // At k = 100 the threshold is the body's top value 1, the true scale, and the tail is the
    // exact quantiles: Hill's shape is within 2% of 2 and the KS distance near its floor
    // 1 / (2k). A larger k takes in body values that are no Pareto; a smaller one leaves fewer
    // points whose distance cannot be as small. The rule must pick exactly k = 100.
    let mut desc = constructed_stream();
    desc.sort_by(|a, b| b.total_cmp(a));
    let choice = choose_tail(&desc).unwrap();
    assert_eq!(choice.hill.k, 100, "{choice:?}");
    assert_eq!(choice.hill.threshold, 1.0);
    assert!((choice.hill.shape - 2.0).abs() < 0.04, "{choice:?}");
    assert!(choice.ks < 0.02, "{choice:?}");
    // The rule's KS at k = 100 is the distance tail_ks reports for that fit.
    assert_eq!(choice.ks, tail_ks(&desc, &choice.hill));
    // Neighbours are worse.
    for k in [90, 99, 101, 120] {
        let h = hill(&desc, k).unwrap();
        assert!(tail_ks(&desc, &h) > choice.ks, "k = {k}");
    }
    // The whole fit keeps the tail: a lognormal cannot have this power law.
    let f = fit(&constructed_stream()).unwrap();
    assert!(f.tail.unwrap().fitted.is_some());
    assert_mean_exact(&f);
}

#[test]
fn atoms_exact_repeats_and_near_clusters() {
    let n = 1000;
    // 30 samples at 5 exactly; 20 within 1e-4 relative of 2 (a near cluster, 2% of the stream);
    // 2 at 7 (too few); the rest distinct values spread over [10, 20).
    let mut xs = vec![5.0; 30];
    xs.extend((0..20).map(|i| 2.0 * (1.0 + 4e-6 * i as f64)));
    xs.extend([7.0, 7.0]);
    xs.extend((0..n - 52).map(|i| 10.0 + 10.0 * i as f64 / (n - 52) as f64));
    xs.sort_by(f64::total_cmp);
    let (atoms, rest) = find_atoms(&xs, n);
    assert_eq!(atoms.len(), 2, "{atoms:?}");
    let near = atoms[0];
    assert_eq!((near.count, near.low, near.value), (20, 2.0, 2.0));
    assert!((near.high - 2.0 * (1.0 + 76e-6)).abs() < 1e-12);
    let mean = 2.0 * (1.0 + 4e-6 * 9.5);
    assert!((near.mean - mean).abs() < 1e-15);
    assert_eq!(
        (atoms[1].value, atoms[1].count, atoms[1].mean),
        (5.0, 30, 5.0)
    );
    assert_eq!(rest.len(), n - 50);
    assert!(rest.contains(&7.0));
    // Exact repeats need 1e-4 of the stream: 3 equal values in 100 000 samples are not enough.
    let mut big: Vec<f64> = (0..100_000).map(|i| 1.0 + i as f64).collect();
    big.extend([0.5; 9]);
    big.sort_by(f64::total_cmp);
    let (atoms, _) = find_atoms(&big, big.len());
    assert!(atoms.is_empty(), "{atoms:?}");
    big.push(0.5);
    big.sort_by(f64::total_cmp);
    let (atoms, _) = find_atoms(&big, big.len());
    assert_eq!(atoms.len(), 0, "10 of 100 010 is below 1e-4");
    big.extend([0.5; 2]);
    big.sort_by(f64::total_cmp);
    let (atoms, _) = find_atoms(&big, big.len());
    assert_eq!((atoms.len(), atoms[0].count), (1, 12));
}

#[test]
fn mean_constrained_lognormal_is_the_constrained_maximum() {
    // When the mean is the fit's own, nothing moves.
    let (mu, sigma) = mean_constrained(0.3, 0.7, (0.3f64 + 0.245).exp());
    assert!((mu - 0.3).abs() < 1e-14 && (sigma - 0.7).abs() < 1e-14);
    // Otherwise its mean is the target and no other sigma (mu then fixed by the mean) scores
    // higher: per sample, -ln(sigma) - (s^2 + (mu - mu_mle)^2) / (2 sigma^2).
    let (mu_mle, s, target) = (-2.0, 1.5, 0.05);
    let (mu, sigma) = mean_constrained(mu_mle, s, target);
    assert!(((mu + 0.5 * sigma * sigma).exp() - target).abs() < 1e-15);
    let ll = |sg: f64| {
        let m = target.ln() - 0.5 * sg * sg;
        -sg.ln() - (s * s + (m - mu_mle) * (m - mu_mle)) / (2.0 * sg * sg)
    };
    for f in [0.9, 0.99, 0.999, 1.001, 1.01, 1.1] {
        assert!(ll(sigma) > ll(sigma * f), "factor {f}");
    }
}

// ---------------------------------------------------------------------------------------------
// Recovering known generators
// ---------------------------------------------------------------------------------------------
//
// Tolerances are five standard errors of the maximum-likelihood estimates (a two-sided normal
// tail of 6e-7 each, under 1e-5 for every check of this file together); the defects they
// catch are stated per test.

#[test]
fn recovers_a_lognormal() {
    // lognormal(0.5, 0.8), 4096 samples: SE(mu) = 0.8 / 64 = 0.0125, SE(sigma) = 0.0088. Catches
    // a location or spread off by 0.07 or 0.05 (a wrong log, variance divisor, or a spurious
    // tail or extra part, which would also fail the structure check). The mean-constrained
    // parameters move with the sample mean (relative SE 1.5%): checked to 0.06. Over 200 seeds
    // none gave a tail or a second part (so below 1.5% per seed, by the rule of three).
    let xs = draw(
        &law(r#"{"kind":"lognormal","mu":0.5,"sigma":0.8}"#),
        1,
        4096,
    );
    let f = fit(&xs).unwrap();
    assert_eq!(roles(&f), [Role::Body], "{:?}", f.components);
    assert!(f.tail.unwrap().fitted.is_none());
    let b = f.bodies()[0];
    assert_within("mu_mle", b.mu_mle, 0.5, 5.0 * 0.0125);
    assert_within("sigma_mle", b.sigma_mle, 0.8, 5.0 * 0.0088);
    assert_within("mu", b.mu, 0.5, 0.06);
    assert_within("sigma", b.sigma, 0.8, 0.06);
    assert_eq!(
        f.spec(),
        DistSpec::LogNormal {
            mu: b.mu,
            sigma: b.sigma
        }
    );
    assert_mean_exact(&f);
    assert!(f.ks_log < 0.03, "KS {}", f.ks_log);
}

#[test]
fn recovers_zeros_and_a_lognormal() {
    // 30% zeros: the fraction has SE sqrt(0.21 / 4096) = 0.0072; the body lognormal(-1, 1) of
    // ~2870 samples SE 0.019 (mu) and 0.013 (sigma). Catches a zero mass off by 0.036 (zeros
    // counted in the body) or parameters off by 0.1 / 0.07. Over 200 seeds the structure was
    // always zero mass + one lognormal.
    let d = law(r#"{"kind":"mixture","components":[
            {"weight":0.3,"dist":{"kind":"point-mass","value":0.0}},
            {"weight":0.7,"dist":{"kind":"lognormal","mu":-1.0,"sigma":1.0}}]}"#);
    let f = fit(&draw(&d, 2, 4096)).unwrap();
    assert_eq!(roles(&f), [Role::Zero, Role::Body], "{:?}", f.components);
    assert_within(
        "zero mass",
        f.components[0].count / 4096.0,
        0.3,
        5.0 * 0.0072,
    );
    let b = f.bodies()[0];
    assert_within("mu_mle", b.mu_mle, -1.0, 5.0 * 0.019);
    assert_within("sigma_mle", b.sigma_mle, 1.0, 5.0 * 0.013);
    assert_mean_exact(&f);
}

#[test]
fn recovers_point_masses() {
    // 20% zeros, 10% exactly 5, 70% lognormal(0, 0.5): weights SE 0.0063 and 0.0047, body
    // (~2870 samples) SE 0.0093 (mu) and 0.0066 (sigma). The atom is 5 exactly. Over 200 seeds
    // the structure was always zero mass + atom + one lognormal.
    let d = law(r#"{"kind":"mixture","components":[
            {"weight":0.2,"dist":{"kind":"point-mass","value":0.0}},
            {"weight":0.1,"dist":{"kind":"point-mass","value":5.0}},
            {"weight":0.7,"dist":{"kind":"lognormal","mu":0.0,"sigma":0.5}}]}"#);
    let f = fit(&draw(&d, 3, 4096)).unwrap();
    assert_eq!(
        roles(&f),
        [Role::Zero, Role::Atom, Role::Body],
        "{:?}",
        f.components
    );
    assert_eq!(f.components[1].law, DistSpec::PointMass { value: 5.0 });
    assert_within(
        "zero mass",
        f.components[0].count / 4096.0,
        0.2,
        5.0 * 0.0063,
    );
    assert_within(
        "atom mass",
        f.components[1].count / 4096.0,
        0.1,
        5.0 * 0.0047,
    );
    let b = f.bodies()[0];
    assert_within("mu_mle", b.mu_mle, 0.0, 5.0 * 0.0093);
    assert_within("sigma_mle", b.sigma_mle, 0.5, 5.0 * 0.0066);
    assert_mean_exact(&f);
    assert!(f.ks_log < 0.03, "KS {}", f.ks_log);
}

#[test]
fn recovers_a_lognormal_body_and_a_pareto_tail() {
    // 95% lognormal(0, 0.5) and 5% pareto(e^2, 1.5), 20 000 samples: ~1000 tail samples. The
    // lognormal has mass 3e-5 above e^2, so the rule should find the tail near e^2 (it may
    // start higher: the Pareto's bottom end is thin, and what lies below the threshold joins
    // the body as extra parts) and Hill's shape within 5 of its standard errors (~0.05) of 1.5.
    // The body's main part is the lognormal (SE 0.0036 for mu, 0.0026 for sigma). Over 200 seeds
    // the tail was always kept, Hill within 3.4 SE and ln u within 0.84 of 2; over 60 of them
    // the main part within 2.4 SE, its weight within 0.006 of 0.95, k between 342 and 1098.
    // Catches a missing tail, a threshold in the body (ln u off by more than 1), a shape off by
    // 0.25, a body spoilt by the tail.
    let d = law(r#"{"kind":"mixture","components":[
            {"weight":0.95,"dist":{"kind":"lognormal","mu":0.0,"sigma":0.5}},
            {"weight":0.05,"dist":{"kind":"pareto","scale":7.38905609893065,"shape":1.5}}]}"#);
    let f = fit(&draw(&d, 4, 20_000)).unwrap();
    let tail = f.tail.unwrap();
    let h = tail.choice.hill;
    let fitted = tail.fitted.expect("the tail is kept");
    assert!(
        (h.threshold.ln() - 2.0).abs() < 1.0,
        "threshold {}",
        h.threshold
    );
    assert!(
        (h.shape - 1.5).abs() < 5.0 * h.se,
        "Hill {} ± {}",
        h.shape,
        h.se
    );
    assert!(h.k > 150 && h.k < 2000, "k = {}", h.k);
    assert!(fitted.shape > 1.0 && fitted.upper > fitted.scale);
    let main = f
        .bodies()
        .into_iter()
        .max_by(|a, b| a.count.total_cmp(&b.count))
        .unwrap();
    assert_within("mu_mle", main.mu_mle, 0.0, 5.0 * 0.0036);
    assert_within("sigma_mle", main.sigma_mle, 0.5, 5.0 * 0.0026);
    assert_within("body weight", main.count / 20_000.0, 0.95, 0.03);
    assert_eq!(f.components.last().unwrap().role, Role::Tail);
    assert_mean_exact(&f);
}

#[test]
fn a_single_wild_sample_becomes_an_outlier_point_mass() {
    // A pareto(1, 3) tail of 300 samples (its largest expected near 300^(1/3) = 7) plus one
    // sample at 1e4, which that tail expects with probability 300 * 1e-12: it is set apart as
    // a point mass of weight 1/n, and the Pareto fit describes the rest.
    let d = law(r#"{"kind":"mixture","components":[
            {"weight":0.7,"dist":{"kind":"lognormal","mu":-1.0,"sigma":0.3}},
            {"weight":0.3,"dist":{"kind":"pareto","scale":1.0,"shape":3.0}}]}"#);
    let mut xs = draw(&d, 5, 1000);
    xs.push(1e4);
    let f = fit(&xs).unwrap();
    let last = f.components.last().unwrap();
    assert_eq!(last.role, Role::Outlier);
    assert_eq!(
        (last.count, &last.law),
        (1.0, &DistSpec::PointMass { value: 1e4 })
    );
    let Detail::Tail(t) = f.components[f.components.len() - 2].detail else {
        panic!("{:?}", f.components);
    };
    assert_eq!(t.outliers, 1);
    assert!(t.upper < 100.0, "{t:?}");
    assert_mean_exact(&f);
}

// ---------------------------------------------------------------------------------------------
// The mean guarantee
// ---------------------------------------------------------------------------------------------

#[test]
fn fitted_mean_equals_the_stream_mean_on_many_heavy_tailed_streams() {
    // Not statistical: the mean is matched by construction, so every stream must pass, at a
    // tolerance 10^8 times tighter than the 10% the issue asks for. The streams cover every
    // preset (spikes, zeros, infinite variance), bare Pareto tails with shape <= 1 (truncated)
    // and > 1, at lengths from 16 to 4096, 8 seeds each: 400 fits.
    let mut laws: Vec<(String, Dist)> = Preset::ALL
        .iter()
        .map(|p| (p.to_string(), p.dist()))
        .collect();
    for json in [
        r#"{"kind":"truncated-pareto","scale":1.0,"shape":0.6,"upper":1e6}"#,
        r#"{"kind":"pareto","scale":0.01,"shape":1.05}"#,
        r#"{"kind":"mixture","components":[
            {"weight":0.9,"dist":{"kind":"point-mass","value":0.0}},
            {"weight":0.1,"dist":{"kind":"pareto","scale":1.0,"shape":1.2}}]}"#,
    ] {
        laws.push((json.to_string(), law(json)));
    }
    let mut fits = 0;
    for (name, d) in &laws {
        for n in [16, 256, 1024, 4096] {
            for seed in 0..4 {
                let xs = draw(d, 100 + seed, n);
                if xs.iter().all(|&x| x == 0.0) {
                    continue;
                }
                let f = fit(&xs).unwrap_or_else(|e| panic!("{name} n={n} seed={seed}: {e}"));
                let rel = (f.mean() - f.stream_mean).abs() / f.stream_mean;
                assert!(
                    rel <= 1e-9 && f.mean().is_finite(),
                    "{name} n={n} seed={seed}: {} vs {}",
                    f.mean(),
                    f.stream_mean
                );
                // The spec round-trips to the same generator.
                assert_eq!(f.spec().build().unwrap(), f.dist);
                assert!(f.ks_log >= 0.0 && f.ks_log <= 1.0);
                fits += 1;
            }
        }
    }
    assert!(fits >= 150, "{fits}");
}

/// The real pixel streams rendered for these tests (see tests/data/fit/README.md).
fn real_streams() -> Vec<(String, Vec<f64>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fit");
    let mut out: Vec<(String, Vec<f64>)> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| {
            let p = e.unwrap().path();
            (p.extension()? == "txt").then(|| {
                let text = std::fs::read_to_string(&p).unwrap();
                let xs = fireflies::samples::read_all(&p.display().to_string(), text.as_bytes());
                (
                    p.file_name().unwrap().to_string_lossy().into_owned(),
                    xs.unwrap(),
                )
            })
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn real_pixels_fit_with_their_mean_and_a_small_ks_distance() {
    // KS bounds are the distances measured when the fit was written (0.162, 0.114, 0.013, 0.098;
    // see the README), rounded up by 0.02-0.03: a regression in the body or tail fit shows up
    // here first.
    let expected = [
        ("caustic_84_84.txt", 0.18),
        ("caustic_108_92.txt", 0.14),
        ("cbox_68_84.txt", 0.04),
        ("veach_mis_28_52.txt", 0.12),
    ];
    let streams = real_streams();
    assert_eq!(streams.len(), expected.len());
    for (name, ks_max) in expected {
        let xs = &streams.iter().find(|s| s.0 == name).unwrap().1;
        let f = fit(xs).unwrap();
        assert_mean_exact(&f);
        assert!(f.ks_log <= ks_max, "{name}: KS {}", f.ks_log);
        if name.starts_with("caustic") {
            // The caustic spike of radiance 874.01 is a point mass, as an atom or an outlier.
            let spike = f.components.iter().any(
                |c| matches!(c.law, DistSpec::PointMass { value } if (value - 874.0).abs() < 0.1),
            );
            assert!(spike, "{name}: {:?}", f.components);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Degenerate streams and errors
// ---------------------------------------------------------------------------------------------

#[test]
fn an_all_equal_stream_is_one_point_mass() {
    for n in [1, 2, 3, 100] {
        let f = fit(&vec![2.5; n]).unwrap();
        assert_eq!(f.spec(), DistSpec::PointMass { value: 2.5 }, "n = {n}");
        assert_eq!((f.mean(), f.ks_log), (2.5, 0.0));
        assert!(f.tail.is_none());
    }
}

#[test]
fn a_stream_of_zeros_is_the_point_mass_at_zero() {
    // A valid fit: mean 0 equals the stream's. It is flagged, because the harness measures
    // estimators relative to the mean, which is then undefined.
    let f = fit(&[0.0; 64]).unwrap();
    assert!(f.is_black());
    assert_eq!(f.spec(), DistSpec::PointMass { value: 0.0 });
    assert_eq!((f.mean(), f.stream_mean, f.ks_log), (0.0, 0.0, 0.0));
    assert_eq!(roles(&f), [Role::Zero]);
    assert!(!fit(&[0.0, 1.0]).unwrap().is_black());
}

#[test]
fn invalid_streams_are_errors_naming_the_sample() {
    assert!(fit(&[]).unwrap_err().to_string().contains("empty"));
    for (bad, text) in [(f64::NAN, "NaN"), (-1.0, "-1"), (f64::INFINITY, "inf")] {
        let e = fit(&[1.0, 2.0, bad]).unwrap_err().to_string();
        assert!(e.contains("index 2") && e.contains(text), "{e}");
    }
}

#[test]
fn short_streams_fit_without_a_tail_search() {
    // Fewer than TAIL_MIN_K + BODY_MIN_N continuous samples: no threshold to choose.
    let xs: Vec<f64> = (1..=TAIL_MIN_K).map(|i| i as f64).collect();
    let f = fit(&xs).unwrap();
    assert!(f.tail.is_none());
    assert_eq!(roles(&f), [Role::Body]);
    assert_mean_exact(&f);
}

// ---------------------------------------------------------------------------------------------
// The command line
// ---------------------------------------------------------------------------------------------

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fireflies"))
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fireflies-fit-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run_with_stdin(args: &[&str], input: &str) -> Output {
    use std::io::Write;
    let mut child = bin()
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    child.wait_with_output().unwrap()
}

#[test]
fn cli_prints_one_json_object_with_a_spec_an_experiment_runs() {
    let dir = scratch("json");
    let file = dir.join("pixel_3_4.txt");
    let text: String = constructed_stream()
        .iter()
        .map(|x| format!("{x:e}\n"))
        .chain(std::iter::once("0\n0\n".to_string()))
        .collect();
    std::fs::write(&file, text).unwrap();
    let qq = dir.join("tail.png");
    let out = bin()
        .args(["fit", file.to_str().unwrap(), "--qq", qq.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert_eq!(stdout.lines().count(), 1);
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
    assert_eq!(
        keys,
        [
            "n",
            "stream_mean",
            "mean",
            "mean_rel_error",
            "zero_fraction",
            "components",
            "tail",
            "ks_log",
            "spec",
            "toml"
        ]
    );
    assert_eq!(v["n"], 302);
    assert!((v["zero_fraction"].as_f64().unwrap() - 2.0 / 302.0).abs() < 1e-15);
    assert!(v["mean_rel_error"].as_f64().unwrap().abs() < 1e-9);
    let tail = &v["tail"];
    assert_eq!(
        (tail["k"].as_u64(), tail["threshold"].as_f64()),
        (Some(100), Some(1.0))
    );
    for key in ["hill", "hill_se", "ks", "kept", "loglik_gain", "mean_rule"] {
        assert!(!tail[key].is_null(), "{key}");
    }
    let c0 = &v["components"][0];
    assert_eq!(
        (c0["role"].as_str(), c0["kind"].as_str()),
        (Some("zero"), Some("point-mass"))
    );
    // The spec is a DistSpec, and the TOML snippet is an experiment's distribution entry.
    let spec: DistSpec = serde_json::from_value(v["spec"].clone()).unwrap();
    let built = spec.build().unwrap();
    assert!((built.mean() - v["mean"].as_f64().unwrap()).abs() < 1e-15);
    let experiment = format!(
        "seed = 1\ntrials = 8\ncheckpoints = [4]\nestimators = [\"mean\"]\n{}",
        v["toml"].as_str().unwrap()
    );
    let exp = Experiment::from_toml(&experiment, "fit.toml", "fit").unwrap();
    assert_eq!(exp.distributions[0].label, "pixel_3_4");
    assert_eq!(exp.distributions[0].dist, built);
    // The QQ plot is a PNG of the stated size.
    let png = std::fs::read(&qq).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let img = image::load_from_memory(&png).unwrap();
    assert_eq!((img.width(), img.height()), (720, 680));
}

#[test]
fn cli_reads_stdin_and_reports_input_errors_with_exit_2() {
    let out = run_with_stdin(&["fit"], "1 2 3\n4 5 6\n");
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["n"].as_u64(), v["stream_mean"].as_f64()),
        (Some(6), Some(3.5))
    );
    assert!(v["tail"].is_null());
    let same = run_with_stdin(&["fit", "-", "--label", "mine"], "1 2 3\n4 5 6\n");
    let w: serde_json::Value = serde_json::from_slice(&same.stdout).unwrap();
    assert_eq!(v["spec"], w["spec"]);
    assert!(w["toml"].as_str().unwrap().contains("label = \"mine\""));
    for (input, needle) in [
        ("1 2\nnan\n", "-:2: invalid sample at index 2: NaN"),
        ("1\n-3\n", "-:2: invalid sample at index 1: -3"),
        ("1 inf", "-:1: invalid sample at index 1: inf"),
        ("1 x2", "-:1: malformed number 'x2'"),
        ("", "empty stream"),
    ] {
        let out = run_with_stdin(&["fit"], input);
        assert_eq!(out.status.code(), Some(2), "{input:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{input:?}: {err}");
    }
    // Too few samples for a threshold: the QQ plot cannot be drawn, and says why.
    let out = run_with_stdin(&["fit", "--qq", "/tmp/never-written.png"], "1 2 3");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no tail threshold"));
    let out = bin()
        .args(["fit", "/nonexistent/pixel.txt"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/pixel.txt"));
}

#[test]
fn cli_fits_a_black_pixel_and_says_so() {
    let out = run_with_stdin(&["fit"], "0 0 0 0\n");
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["mean"].as_f64(), v["mean_rel_error"].as_f64()),
        (Some(0.0), Some(0.0))
    );
    assert!(v["warning"].as_str().unwrap().contains("undefined"));
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning"));
}
