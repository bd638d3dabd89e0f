//! RGB estimators for the film (`estimators::rgb`): grey pixels reproduce the scalar
//! estimators bit for bit, per-channel methods are three scalar estimators, Zirr and Pajot
//! classify by luminance and apply their weights or decisions to the colour, the 3×3 block and
//! Jung's image mode, the memory the module documents, and the edge cases.

use fireflies::estimators::{
    Estimator, EstimatorSpec, Extra, Jung, Neumaier, PajotAdr, PajotAdrSpec, PajotHybrid,
    PajotHybridSpec, PajotRot, PajotRotSpec, REC709, RgbEstimator, Zirr, ZirrRefSpec, ZirrSpec,
    build_rgb, luminance,
};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// The spec's running example.
const RUNNING: [f64; 7] = [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1];

/// Specs covering all twelve estimators, with the parameters that matter varied: fixed and
/// grown Zirr cascades, `u != 1`, `κ > 1` for the released code's colour term, reads during
/// and after Pajot's learning, an immediate hybrid switch.
const SPECS: [&str; 22] = [
    "mean",
    "clamp:c=10",
    "mon:M=1",
    "mon:M=5",
    "mon:M=21",
    "gini:M=5",
    "gmonb:M=5",
    "gmonb:M=21,threshold=0.5",
    "gmon:M=21",
    "jung:sigma_image=1",
    "jung:sigma_image=30,m_max=9",
    "zirr",
    "zirr:J=3",
    "zirr:b=4,kappa=2,u=0.25",
    "zirr-ref",
    "zirr-ref:kappa=4,J=4,u=2",
    "pajot-rot:learn=8",
    "pajot-rot",
    "pajot-adr:learn=0",
    "pajot-adr",
    "pajot-hybrid:learn=8",
    "pajot-hybrid:learn=20,T=1,delta=0.05",
];

/// Stream lengths at which estimates are compared (before, at and after Pajot's learning;
/// below and above M).
const CHECKPOINTS: [usize; 9] = [1, 2, 3, 7, 8, 20, 51, 300, 1500];

fn spec(s: &str) -> EstimatorSpec {
    s.parse().unwrap_or_else(|e| panic!("{s}: {e}"))
}

fn rgb(s: &str) -> Box<dyn RgbEstimator> {
    build_rgb(&spec(s)).unwrap_or_else(|e| panic!("{s}: {e}"))
}

fn scalar(s: &str) -> Box<dyn Estimator> {
    spec(s).build().unwrap_or_else(|e| panic!("{s}: {e}"))
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    a == b || (a - b).abs() <= rel * a.abs().max(b.abs())
}

#[track_caller]
fn assert_close(a: f64, b: f64, rel: f64, what: &str) {
    assert!(
        close(a, b, rel),
        "{what}: {a:?} vs {b:?} (relative error {:e})",
        (a - b).abs() / a.abs().max(b.abs())
    );
}

fn rng(seed: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(seed)
}

/// A heavy-tailed brightness: 10% black, otherwise Pareto with shape 1.2 and scale 0.3 (so
/// fireflies of 1e3 and more appear within a few thousand samples).
fn brightness(r: &mut Xoshiro256PlusPlus) -> f64 {
    if r.random_bool(0.1) {
        0.0
    } else {
        let u: f64 = r.random();
        0.3 * (1.0 - u).powf(-1.0 / 1.2)
    }
}

/// Heavy-tailed coloured samples: random colours, some pure primaries, some grey, some black.
fn coloured(seed: u64, n: usize) -> Vec<[f64; 3]> {
    let mut r = rng(seed);
    (0..n)
        .map(|_| {
            let s = brightness(&mut r);
            match r.random_range(0..10u32) {
                0 => [s, s, s],
                1 => [s, 0.0, 0.0],
                2 => [0.0, 0.0, s],
                _ => [
                    s * r.random::<f64>(),
                    s * r.random::<f64>(),
                    s * r.random::<f64>(),
                ],
            }
        })
        .collect()
}

/// Heavy-tailed grey values (zeros included).
fn grey(seed: u64, n: usize) -> Vec<f64> {
    let mut r = rng(seed);
    (0..n).map(|_| brightness(&mut r)).collect()
}

fn channel(xs: &[[f64; 3]], c: usize) -> Vec<f64> {
    xs.iter().map(|p| p[c]).collect()
}

fn lums(xs: &[[f64; 3]]) -> Vec<f64> {
    xs.iter().map(|&p| luminance(p)).collect()
}

/// Pushes `xs` in random block sizes (1 to 40).
fn push_blocks(e: &mut dyn RgbEstimator, xs: &[[f64; 3]], seed: u64) {
    let mut r = rng(seed);
    let mut rest = xs;
    while !rest.is_empty() {
        let k = r.random_range(1..=40usize).min(rest.len());
        e.push_slice(&rest[..k]);
        rest = &rest[k..];
    }
}

/// Feeds `xs` to `e` stopping at each checkpoint (and at the end), calling `check(n, e)`.
fn at_checkpoints(
    e: &mut dyn RgbEstimator,
    xs: &[[f64; 3]],
    mut check: impl FnMut(usize, &dyn RgbEstimator),
) {
    let mut done = 0;
    for &n in CHECKPOINTS
        .iter()
        .filter(|&&n| n < xs.len())
        .chain([&xs.len()])
    {
        push_blocks(e, &xs[done..n], n as u64);
        done = n;
        check(n, e);
    }
}

fn float(e: &dyn Estimator, key: &str) -> f64 {
    match e.extras().into_iter().find(|(k, _)| *k == key) {
        Some((_, Extra::Float(v))) => v,
        other => panic!("no Float extra {key}: {other:?}"),
    }
}

fn int(e: &dyn Estimator, key: &str) -> u64 {
    match e.extras().into_iter().find(|(k, _)| *k == key) {
        Some((_, Extra::Int(v))) => v,
        other => panic!("no Int extra {key}: {other:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Construction

#[test]
fn every_estimator_name_builds_and_prints_its_spec() {
    let with_keys = |name: &str| -> String {
        match name {
            "clamp" => "clamp:c=10".into(),
            "mon" | "gini" | "gmonb" | "gmon" => format!("{name}:M=21"),
            "jung" => "jung:sigma_image=1".into(),
            _ => name.into(),
        }
    };
    let mut names = 0;
    for name in EstimatorSpec::names() {
        let s = spec(&with_keys(name));
        let e = build_rgb(&s).unwrap();
        assert_eq!(e.spec(), s);
        assert_eq!(e.count(), 0);
        let shown = e.to_string();
        assert_eq!(shown, format!("{}[RGB]", s.build().unwrap()));
        assert!(e.estimate().is_err(), "{shown} estimated without samples");
        names += 1;
    }
    assert_eq!(names, 12);
    for s in SPECS {
        assert_eq!(rgb(s).spec(), spec(s));
    }
}

#[test]
fn invalid_parameters_are_the_scalar_errors() {
    for s in [
        "clamp:c=0",
        "mon:M=0",
        "gmonb:M=0",
        "jung:sigma_image=1,m_max=4",
        "zirr:b=1",
        "zirr-ref:J=1",
        "pajot-hybrid:T=0",
    ] {
        let want = spec(s).build().err().expect("invalid").to_string();
        let got = build_rgb(&spec(s)).err().expect("invalid").to_string();
        assert_eq!(got, want);
    }
}

#[test]
fn luminance_is_rec709_and_exact_on_grey() {
    assert_eq!(REC709, [0.2126, 0.7152, 0.0722]);
    assert_eq!(luminance([1.0, 0.0, 0.0]), 0.2126);
    assert_eq!(luminance([0.0, 1.0, 0.0]), 0.7152);
    assert_eq!(luminance([0.0, 0.0, 1.0]), 0.0722);
    assert_eq!(
        luminance([0.5, 2.0, 8.0]),
        0.2126 * 0.5 + 0.7152 * 2.0 + 0.0722 * 8.0
    );
    // The products alone miss some grey values by an ulp; luminance does not.
    let mut missed = 0;
    for s in grey(1, 10_000) {
        assert_eq!(luminance([s, s, s]), s);
        missed += usize::from(0.2126 * s + 0.7152 * s + 0.0722 * s != s);
    }
    assert!(missed > 0, "the grey rule is needed");
    // Subnormal colour can have luminance 0: such a sample is black (module docs).
    assert_eq!(luminance([5e-324, 0.0, 0.0]), 0.0);
}

// ---------------------------------------------------------------------------------------------
// Grey samples: every channel is the scalar estimator

#[test]
fn grey_samples_give_the_scalar_estimate_in_every_channel() {
    for (k, s) in SPECS.iter().enumerate() {
        let xs = grey(10 + k as u64, 1500);
        let px: Vec<[f64; 3]> = xs.iter().map(|&v| [v, v, v]).collect();
        let mut e = rgb(s);
        at_checkpoints(e.as_mut(), &px, |n, e| {
            let mut sc = scalar(s);
            sc.push_slice(&xs[..n]);
            let want = sc.estimate().unwrap();
            let got = e.estimate().unwrap();
            assert_eq!(got, [want; 3], "{s} at n = {n}");
        });
    }
}

#[test]
fn grey_running_example_matches_the_spec_values() {
    let px: Vec<[f64; 3]> = RUNNING.iter().map(|&v| [v, v, v]).collect();
    for (s, want) in [
        ("mean", 51.885714285714286),
        ("clamp:c=10", 3.314285714285714),
        ("mon:M=5", 2.8),
        ("gmon:M=5", 3.266666666666667),
        ("jung:sigma_image=40", 2.8),
        ("zirr:J=6", 5.191836734693878),
        ("zirr", 5.191836734693878),
        ("zirr-ref", 5.616560523284569),
        ("pajot-rot:learn=4", 2.2),
        ("pajot-adr:learn=4", 2.2),
        ("pajot-hybrid:learn=4", 2.2),
        ("pajot-rot", 2.2),
    ] {
        let mut e = rgb(s);
        e.push_slice(&px);
        for v in e.estimate().unwrap() {
            assert_close(v, want, 1e-12, s);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Per channel

#[test]
fn per_channel_estimators_are_three_scalar_estimators() {
    let per_channel = SPECS
        .iter()
        .filter(|s| !s.starts_with("zirr") && !s.starts_with("pajot"));
    for (k, s) in per_channel.enumerate() {
        let px = coloured(100 + k as u64, 1500);
        let mut e = rgb(s);
        at_checkpoints(e.as_mut(), &px, |n, e| {
            let got = e.estimate().unwrap();
            for (c, &g) in got.iter().enumerate() {
                let mut sc = scalar(s);
                sc.push_slice(&channel(&px[..n], c));
                assert_eq!(g, sc.estimate().unwrap(), "{s}, channel {c}, n = {n}");
            }
        });
    }
}

/// The RGB mean sums its three channels together in SIMD lanes; it must stay three scalar
/// means bit for bit where the sums are delicate: red and green overflowing `2^1023` in the
/// middle of a block (their block is redone and rescaled, blue keeps its own), tiny and huge
/// terms together, zeros, single samples, all-equal streams and blocks of every length around
/// the bank's 64-sample chunk. Fails on any lane mix-up, a dropped compensation or a wrong
/// undo.
#[test]
fn rgb_mean_is_three_scalar_means_on_hard_streams() {
    let mixed: Vec<[f64; 3]> = (0..300)
        .map(|i| {
            let f = i as f64;
            [
                if i % 7 == 0 {
                    1e306 * (1.0 + f)
                } else {
                    1e-300 * f
                },
                if i == 150 { f64::MAX } else { 0.1 * f },
                if i % 2 == 0 { 0.0 } else { 1e300 },
            ]
        })
        .collect();
    let equal = vec![[0.1, 1e-300, 1e300]; 129];
    let streams: [(&str, Vec<[f64; 3]>); 5] = [
        ("mixed", mixed),
        ("equal", equal),
        ("zeros", vec![[0.0; 3]; 65]),
        ("one", vec![[3.0, 5e-324, 1e308]]),
        ("coloured", coloured(7, 700)),
    ];
    for (name, xs) in &streams {
        for block in [1, 2, 3, 63, 64, 65, 1000] {
            let mut e = rgb("mean");
            let mut n = 0;
            for chunk in xs.chunks(block) {
                e.push_slice(chunk);
                n += chunk.len();
                let got = e.estimate().unwrap();
                for (c, g) in got.iter().enumerate() {
                    let mut sc = scalar("mean");
                    sc.push_slice(&channel(&xs[..n], c));
                    let want = sc.estimate().unwrap();
                    assert_eq!(
                        g.to_bits(),
                        want.to_bits(),
                        "{name}, blocks of {block}, channel {c}, n = {n}: {g:e} vs {want:e}"
                    );
                }
            }
        }
    }
}

#[test]
fn mon_is_three_scalar_mons() {
    let px = coloured(7, 999);
    let mut e = rgb("mon:M=21");
    e.push_slice(&px);
    for c in 0..3 {
        let mut m = fireflies::estimators::Mon::new(21).unwrap();
        m.push_slice(&channel(&px, c));
        assert_eq!(e.estimate().unwrap()[c], m.estimate().unwrap());
    }
}

#[test]
fn block_size_does_not_matter() {
    let px = coloured(3, 700);
    for s in SPECS {
        let mut whole = rgb(s);
        whole.push_slice(&px);
        let mut one = rgb(s);
        for p in &px {
            one.push_slice(std::slice::from_ref(p));
        }
        let mut blocks = rgb(s);
        push_blocks(blocks.as_mut(), &px, 99);
        let want = whole.estimate().unwrap();
        assert_eq!(one.estimate().unwrap(), want, "{s}");
        assert_eq!(blocks.estimate().unwrap(), want, "{s}");
        assert_eq!(whole.count(), 700);
    }
}

// ---------------------------------------------------------------------------------------------
// Luminance-classified methods

const BY_LUMINANCE: [&str; 10] = [
    "zirr",
    "zirr:J=3",
    "zirr:b=4,kappa=2,u=0.25",
    "zirr-ref",
    "zirr-ref:kappa=4,J=4,u=2",
    "pajot-rot:learn=8",
    "pajot-rot",
    "pajot-adr",
    "pajot-hybrid:learn=8",
    "pajot-hybrid:learn=20,T=1,delta=0.05",
];

#[test]
fn luminance_of_the_estimate_is_the_scalar_estimate_of_the_luminances() {
    for (k, s) in BY_LUMINANCE.iter().enumerate() {
        for seed in [200, 300, 400] {
            let px = coloured(seed + k as u64, 3000);
            let l = lums(&px);
            let mut e = rgb(s);
            at_checkpoints(e.as_mut(), &px, |n, e| {
                let mut sc = scalar(s);
                sc.push_slice(&l[..n]);
                let want = sc.estimate().unwrap();
                let got = luminance(e.estimate().unwrap());
                assert_close(got, want, 1e-9, &format!("{s}, seed {seed}, n = {n}"));
            });
        }
    }
}

#[test]
fn one_chromaticity_scales_the_scalar_estimate() {
    // Every sample has the colour k (luminance 1) times a brightness: the weights and the
    // decisions apply to all three channels alike, so the estimate is k times the scalar one.
    let k = [0.4, 1.1, 0.9];
    let k = k.map(|c| c / luminance(k));
    for s in BY_LUMINANCE {
        let l = grey(17, 2000);
        let px: Vec<[f64; 3]> = l.iter().map(|&v| k.map(|c| c * v)).collect();
        let mut e = rgb(s);
        at_checkpoints(e.as_mut(), &px, |n, e| {
            let mut sc = scalar(s);
            sc.push_slice(&lums(&px[..n]));
            let want = sc.estimate().unwrap();
            let got = e.estimate().unwrap();
            for c in 0..3 {
                assert_close(
                    got[c],
                    k[c] * want,
                    1e-9,
                    &format!("{s}, channel {c}, n = {n}"),
                );
            }
        });
    }
}

/// Pajot's accepted set is {black} ∪ {ln L ≤ m} for the scalar bound `m` (whatever the order
/// of acceptance): the RGB estimate is that set's mean.
fn accepted_mean(px: &[[f64; 3]], m: f64) -> [f64; 3] {
    let acc: Vec<&[f64; 3]> = px
        .iter()
        .filter(|&&p| {
            let l = luminance(p);
            l == 0.0 || l.ln() <= m
        })
        .collect();
    if acc.is_empty() {
        return [0.0; 3];
    }
    [0, 1, 2].map(|c| {
        let mut sum = Neumaier::new();
        acc.iter().for_each(|p| sum.add(p[c]));
        sum.value() / acc.len() as f64
    })
}

/// The scalar bound `m` of the Pajot estimator `s` after the luminances `l`.
fn pajot_bound(s: &str, l: &[f64]) -> f64 {
    match spec(s) {
        EstimatorSpec::PajotRot(PajotRotSpec { learn }) => {
            let mut p = PajotRot::new(learn).unwrap();
            p.push_slice(l);
            p.bound()
        }
        EstimatorSpec::PajotAdr(PajotAdrSpec { learn }) => {
            let mut p = PajotAdr::new(learn).unwrap();
            p.push_slice(l);
            p.bound()
        }
        EstimatorSpec::PajotHybrid(PajotHybridSpec { learn, t, delta }) => {
            let mut p = PajotHybrid::new(learn, t, delta).unwrap();
            p.push_slice(l);
            p.bound()
        }
        other => panic!("{other} is not a Pajot spec"),
    }
}

#[test]
fn pajot_estimate_is_the_mean_of_the_samples_whose_luminance_is_accepted() {
    let pajot = SPECS.iter().filter(|s| s.starts_with("pajot"));
    for (k, s) in pajot.enumerate() {
        let px = coloured(500 + k as u64, 3000);
        let l = lums(&px);
        let mut e = rgb(s);
        let mut delayed_somewhere = false;
        at_checkpoints(e.as_mut(), &px, |n, e| {
            let m = pajot_bound(s, &l[..n]);
            let want = accepted_mean(&px[..n], m);
            let got = e.estimate().unwrap();
            for c in 0..3 {
                assert_close(
                    got[c],
                    want[c],
                    1e-12,
                    &format!("{s}, channel {c}, n = {n}"),
                );
            }
            let mut sc = scalar(s);
            sc.push_slice(&l[..n]);
            delayed_somewhere |= int(sc.as_ref(), "delayed") > 0;
        });
        assert!(delayed_somewhere, "{s}: the stream should delay something");
    }
}

#[test]
fn a_coloured_firefly_is_excluded_from_all_three_channels() {
    let mut r = rng(42);
    // A quiet pixel, then one firefly whose energy is nearly all blue (the film's hardest
    // case for a luminance test: blue has the smallest weight).
    let mut px: Vec<[f64; 3]> = (0..200)
        .map(|_| {
            let s = 0.5 + r.random::<f64>();
            [s * 0.8, s, s * 1.2]
        })
        .collect();
    let firefly = [40.0, 10.0, 5e4];
    px.insert(120, firefly);
    for s in ["pajot-rot", "pajot-adr", "pajot-hybrid"] {
        let mut e = rgb(s);
        e.push_slice(&px);
        let got = e.estimate().unwrap();
        let mut sc = scalar(s);
        sc.push_slice(&lums(&px));
        let m = float(sc.as_ref(), "m");
        assert!(luminance(firefly).ln() > m, "{s}: the firefly is accepted");
        let want = accepted_mean(&px, m);
        for c in 0..3 {
            assert_close(got[c], want[c], 1e-12, &format!("{s}, channel {c}"));
            let quiet_max = px.iter().filter(|p| **p != firefly).map(|p| p[c]);
            assert!(
                got[c] <= quiet_max.fold(0.0, f64::max),
                "{s}, channel {c}: {got:?}"
            );
        }
        assert_eq!(int(sc.as_ref(), "delayed"), 1, "{s}");
        // A second, similar firefly corroborates the first: both are then accepted.
        e.push_slice(&[[41.0, 10.0, 5e4]]);
        let got = e.estimate().unwrap();
        assert!(got[2] > 400.0, "{s}: {got:?}");
    }
}

#[test]
fn zirr_reweights_a_coloured_firefly_in_all_channels() {
    // 99 samples of (1, 1, 1) and a lone blue firefly: the cascade rejects it (docs/estimators.md §5
    // consequence (i) with J = auto) and its colour goes with it.
    let mut px = vec![[1.0, 1.0, 1.0]; 99];
    px.push([0.0, 0.0, 4e4 / 0.0722]);
    let mut e = rgb("zirr");
    e.push_slice(&px);
    for v in e.estimate().unwrap() {
        assert_close(v, 0.99, 1e-12, "zirr");
    }
    let mut sc = scalar("zirr");
    sc.push_slice(&lums(&px));
    assert_close(sc.estimate().unwrap(), 0.99, 1e-12, "scalar zirr");
}

// ---------------------------------------------------------------------------------------------
// Zirr 3×3

fn zirr_rgb(s: &str, px: &[[f64; 3]]) -> Box<dyn RgbEstimator> {
    let mut e = rgb(s);
    e.push_slice(px);
    e
}

#[test]
fn zirr_block_estimate_is_the_scalar_block_estimate_in_luminance() {
    for s in [
        "zirr",
        "zirr:J=3",
        "zirr:b=4,kappa=2,u=0.25",
        "zirr-ref",
        "zirr-ref:kappa=4,J=4,u=2",
    ] {
        // Pixels of different lengths; one neighbour without samples; corners missing.
        let streams: Vec<Vec<[f64; 3]>> = (0..9)
            .map(|k| coloured(700 + k, if k == 2 { 0 } else { 50 + 37 * k as usize }))
            .collect();
        let pixels: Vec<Box<dyn RgbEstimator>> = streams.iter().map(|p| zirr_rgb(s, p)).collect();
        for present in [
            [true; 9],
            [false, true, true, false, true, true, false, true, true],
            [false, false, false, false, true, false, false, false, false],
            [true, false, false, false, true, false, false, false, true],
        ] {
            let block: [Option<&dyn RgbEstimator>; 9] =
                std::array::from_fn(|k| present[k].then(|| pixels[k].as_ref()));
            let got = luminance(pixels[4].block_estimate(&block).unwrap());
            let want = if s.starts_with("zirr-ref") {
                let lum: Vec<Zirr> = streams
                    .iter()
                    .map(|p| {
                        let mut z = Zirr::reference(zirr_params(s)).unwrap();
                        z.push_slice(&lums(p));
                        z
                    })
                    .collect();
                let b: [Option<&Zirr>; 9] = std::array::from_fn(|k| present[k].then(|| &lum[k]));
                Zirr::block_estimate(&b).unwrap().0
            } else {
                let lum: Vec<Zirr> = streams
                    .iter()
                    .map(|p| {
                        let mut z = Zirr::new(zirr_params(s)).unwrap();
                        z.push_slice(&lums(p));
                        z
                    })
                    .collect();
                let b: [Option<&Zirr>; 9] = std::array::from_fn(|k| present[k].then(|| &lum[k]));
                Zirr::block_estimate(&b).unwrap().0
            };
            assert_close(got, want, 1e-9, &format!("{s}, {present:?}"));
        }
    }
}

fn zirr_params(s: &str) -> fireflies::estimators::ZirrParams {
    match spec(s) {
        EstimatorSpec::Zirr(ZirrSpec(p)) | EstimatorSpec::ZirrRef(ZirrRefSpec(p)) => p,
        other => panic!("{other} is not a Zirr spec"),
    }
}

#[test]
fn zirr_block_reproduces_the_spec_example_on_grey() {
    // docs/estimators.md §5: centre the running example, eight neighbours of seven 1.0 samples.
    let centre: Vec<[f64; 3]> = RUNNING.iter().map(|&v| [v, v, v]).collect();
    for s in ["zirr", "zirr:J=6"] {
        let c = zirr_rgb(s, &centre);
        let ones = zirr_rgb(s, &[[1.0; 3]; 7]);
        let block: [Option<&dyn RgbEstimator>; 9] =
            std::array::from_fn(|k| Some(if k == 4 { c.as_ref() } else { ones.as_ref() }));
        for v in c.block_estimate(&block).unwrap() {
            assert_close(v, 1.8857142857142857, 1e-12, s);
        }
        // Without neighbours the block is the pixel alone.
        let alone: [Option<&dyn RgbEstimator>; 9] =
            std::array::from_fn(|k| (k == 4).then(|| c.as_ref()));
        assert_eq!(c.block_estimate(&alone).unwrap(), c.estimate().unwrap());
    }
}

#[test]
fn block_estimate_errors_name_the_pixel() {
    let z = zirr_rgb("zirr", &coloured(1, 20));
    let other = zirr_rgb("zirr:kappa=2", &coloured(2, 20));
    let mean = zirr_rgb("mean", &coloured(3, 20));
    let zref = zirr_rgb("zirr-ref", &coloured(4, 20));
    let empty = rgb("zirr");
    for (k, px, needle) in [
        (0, mean.as_ref(), "pixel 0"),
        (7, zref.as_ref(), "pixel 7"),
        (3, other.as_ref(), "pixel 3"),
    ] {
        let mut block: [Option<&dyn RgbEstimator>; 9] = [None; 9];
        block[4] = Some(z.as_ref());
        block[k] = Some(px);
        let e = z.block_estimate(&block).unwrap_err().to_string();
        assert!(e.contains(needle), "{e}");
    }
    let block: [Option<&dyn RgbEstimator>; 9] =
        std::array::from_fn(|k| Some(if k == 4 { empty.as_ref() } else { z.as_ref() }));
    assert!(empty.block_estimate(&block).is_err());
    // Every other estimator ignores the neighbours.
    let block: [Option<&dyn RgbEstimator>; 9] = std::array::from_fn(|_| Some(z.as_ref()));
    assert_eq!(
        mean.block_estimate(&block).unwrap(),
        mean.estimate().unwrap()
    );
}

// ---------------------------------------------------------------------------------------------
// Jung's image mode

#[test]
fn jung_image_sigma_is_set_per_channel() {
    let px = coloured(9, 800);
    let mut e = rgb("jung:sigma_image=1,m_max=17");
    e.push_slice(&px);
    let sigma = [0.05, 3.0, 1e6];
    e.set_image_sigma(sigma).unwrap();
    let got = e.estimate().unwrap();
    let mut ms = Vec::new();
    for c in 0..3 {
        let mut j = Jung::new(1.0, 17).unwrap();
        j.push_slice(&channel(&px, c));
        j.set_sigma_image(sigma[c]).unwrap();
        assert_eq!(got[c], j.estimate().unwrap(), "channel {c}");
        ms.push(j.chosen_m());
    }
    assert!(
        ms[0] > ms[2],
        "the sigmas should choose different M: {ms:?}"
    );
    // A bad sigma changes nothing, in any channel.
    for bad in [
        [1.0, -1.0, 1.0],
        [1.0, 1.0, f64::NAN],
        [f64::INFINITY, 1.0, 1.0],
    ] {
        let err = e.set_image_sigma(bad).unwrap_err().to_string();
        assert!(err.contains("sigma_image"), "{err}");
        assert_eq!(e.estimate().unwrap(), got);
    }
    // Zero (a black image so far) is allowed.
    e.set_image_sigma([0.0; 3]).unwrap();
    // Everything else ignores it.
    for s in ["mean", "mon:M=5", "zirr", "pajot-rot"] {
        let mut e = rgb(s);
        e.push_slice(&px);
        let before = e.estimate().unwrap();
        e.set_image_sigma([0.1, 0.2, 0.3]).unwrap();
        assert_eq!(e.estimate().unwrap(), before, "{s}");
    }
}

// ---------------------------------------------------------------------------------------------
// Memory

#[test]
fn per_channel_state_is_three_scalar_states_and_constant() {
    for s in SPECS
        .iter()
        .filter(|s| !s.starts_with("zirr") && !s.starts_with("pajot"))
    {
        let mut e = rgb(s);
        let fresh = e.state_bytes();
        if *s == "mean" {
            // Three sums and one count shared by the channels, not three counts.
            assert_eq!(
                fresh,
                3 * scalar(s).state_bytes() - 2 * size_of::<u64>(),
                "{s}"
            );
        } else {
            assert_eq!(fresh, 3 * scalar(s).state_bytes(), "{s}");
        }
        e.push_slice(&coloured(5, 2000));
        assert_eq!(e.state_bytes(), fresh, "{s}");
    }
}

#[test]
fn zirr_state_grows_by_an_rgb_buffer_beside_each_luminance_buffer() {
    let ladder = [0.5, 3.0, 20.0, 100.0, 1e3, 1e4, 1e5, 1e6];
    for s in ["zirr", "zirr:J=4", "zirr-ref"] {
        let mut e = rgb(s);
        let mut sc = scalar(s);
        let overhead = e.state_bytes() - sc.state_bytes();
        let mut buffers = 0;
        for &v in &ladder {
            let p = [v * 0.9, v, v * 1.3];
            e.push_slice(&[p]);
            sc.push(luminance(p));
            let j_used = int(sc.as_ref(), "J_used") as usize;
            let extra = e.state_bytes() - sc.state_bytes() - overhead;
            assert_eq!(extra % 48, 0, "{s}");
            let rgb_buffers = extra / 48;
            // Grown lazily up to the luminance cascade (the same length once a sample reached
            // it; J = auto grows both alike).
            assert!(rgb_buffers <= j_used && rgb_buffers >= buffers, "{s}");
            if s == "zirr" {
                assert_eq!(rgb_buffers, j_used, "{s}");
            }
            buffers = rgb_buffers;
        }
        assert!(buffers >= 4, "{s}: {buffers}");
    }
}

#[test]
fn pajot_state_keeps_only_the_samples_not_accepted() {
    for s in ["pajot-rot", "pajot-adr", "pajot-hybrid"] {
        let mut e = rgb(s);
        let mut sc = scalar(s);
        let overhead = e.state_bytes() - sc.state_bytes();
        // Learning: 50 similar samples are stored (32 bytes each beside the scalar's 8)...
        let quiet: Vec<[f64; 3]> = (0..49)
            .map(|i| {
                let v = 1.0 + 0.001 * (i % 3) as f64;
                [v, v * 0.5, v * 2.0]
            })
            .collect();
        e.push_slice(&quiet);
        sc.push_slice(&lums(&quiet));
        assert!(
            e.state_bytes() - sc.state_bytes() >= overhead + 49 * 32,
            "{s}"
        );
        // ... and released when learning ends: nothing is listed any more.
        e.push_slice(&[[1.0, 0.5, 2.0]]);
        sc.push(luminance([1.0, 0.5, 2.0]));
        assert_eq!(int(sc.as_ref(), "delayed"), 0, "{s}");
        assert_eq!(e.state_bytes() - sc.state_bytes(), overhead, "{s}");
        // Accepted samples are not stored, however many.
        let more: Vec<[f64; 3]> = quiet.iter().cycle().take(5000).copied().collect();
        e.push_slice(&more);
        sc.push_slice(&lums(&more));
        assert_eq!(e.state_bytes() - sc.state_bytes(), overhead, "{s}");
        // Delayed fireflies, decades apart, are listed: 32 bytes each (capacity may round up).
        let fireflies: Vec<[f64; 3]> = (0..6).map(|i| [0.0, 10f64.powi(3 + 3 * i), 0.0]).collect();
        e.push_slice(&fireflies);
        sc.push_slice(&lums(&fireflies));
        let delayed = int(sc.as_ref(), "delayed") as usize;
        assert!(delayed >= 1, "{s}");
        let listed = e.state_bytes() - sc.state_bytes() - overhead;
        assert!(
            listed >= 32 * delayed && listed <= 32 * 4 * delayed.max(4),
            "{s}: {listed}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Edge cases

#[test]
fn a_single_sample() {
    let p = [0.25, 3.0, 7.5];
    for s in SPECS {
        let mut e = rgb(s);
        e.push_slice(&[p]);
        assert_eq!(e.count(), 1);
        let got = e.estimate().unwrap();
        if s.starts_with("pajot") {
            // No extended mode: the lone sample is delayed (docs/estimators.md §6.1).
            assert_eq!(got, [0.0; 3], "{s}");
        } else if s.starts_with("gini") {
            assert_eq!(got, [0.0; 3], "{s}");
        } else if s.starts_with("zirr") {
            let mut sc = scalar(s);
            sc.push(luminance(p));
            assert_close(luminance(got), sc.estimate().unwrap(), 1e-12, s);
        } else if s.starts_with("clamp") {
            assert_eq!(got, [0.25, 3.0, 7.5], "{s}");
        } else {
            assert_eq!(got, p, "{s}");
        }
    }
}

#[test]
fn fewer_samples_than_sets() {
    // n < M: MoN is the median of the n samples of each channel.
    let px = [[1.0, 9.0, 0.0], [5.0, 2.0, 0.5], [3.0, 4.0, 0.25]];
    let mut e = rgb("mon:M=21");
    e.push_slice(&px);
    assert_eq!(e.estimate().unwrap(), [3.0, 4.0, 0.25]);
    let mut g = rgb("gmonb:M=21");
    g.push_slice(&px[..2]);
    assert_eq!(g.estimate().unwrap(), [3.0, 5.5, 0.25]);
}

#[test]
fn all_equal_samples_give_the_sample() {
    let p = [0.3, 0.5, 0.9];
    for s in SPECS {
        let mut e = rgb(s);
        e.push_slice(&vec![p; 300]);
        let got = e.estimate().unwrap();
        for c in 0..3 {
            let want = if s.starts_with("gini") { 0.0 } else { p[c] };
            assert_close(got[c], want, 1e-12, &format!("{s}, channel {c}"));
        }
    }
}

#[test]
fn zeros_give_zero_and_count() {
    for s in SPECS {
        let mut e = rgb(s);
        e.push_slice(&vec![[0.0, -0.0, 0.0]; 60]);
        assert_eq!(e.count(), 60);
        assert_eq!(e.estimate().unwrap().map(f64::abs), [0.0; 3], "{s}");
        // Black samples count in N (Zirr) and in the divisor (Pajot).
        e.push_slice(&[[0.3, 0.3, 0.3]; 60]);
        let got = e.estimate().unwrap();
        if !s.starts_with("gini") {
            assert!(got.iter().all(|&v| v <= 0.3 && v > 0.0), "{s}: {got:?}");
        }
    }
}

#[test]
fn subnormal_colour_with_zero_luminance_is_black() {
    let tiny = [5e-324, 0.0, 0.0];
    assert_eq!(luminance(tiny), 0.0);
    for s in BY_LUMINANCE {
        let mut e = rgb(s);
        e.push_slice(&[tiny, [1.0; 3], [1.0; 3], tiny]);
        assert_eq!(e.count(), 4);
        let got = e.estimate().unwrap();
        assert!(
            got.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{s}: {got:?}"
        );
        let mut sc = scalar(s);
        sc.push_slice(&[0.0, 1.0, 1.0, 0.0]);
        assert_close(got[1], sc.estimate().unwrap(), 1e-12, s);
    }
}
