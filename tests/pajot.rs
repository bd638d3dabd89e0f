//! Pajot et al.'s outlier delaying (docs/estimators.md §6): the worked example, every decision of the module
//! doc, properties checked against a literal (slow) re-reading of the spec, hard inputs, and the
//! delayed fractions and state sizes on the presets.
//!
//! Run the statistical part with `cargo test --release --test suite -- pajot:: --nocapture` to see the
//! measured figures.

use fireflies::dist::Preset;
use fireflies::estimators::{
    Extra, Extras, PajotAdr, PajotHybrid, PajotMode, PajotRot, adr_bandwidths,
};
use fireflies::{Estimator, EstimatorSpec};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// The spec's running example.
const RUNNING: [f64; 7] = [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1];

/// The spec prints intermediate values to 4-5 significant digits.
const PRINTED: f64 = 5e-5;

fn close(a: f64, b: f64, rel: f64) -> bool {
    a == b || (a - b).abs() <= rel * a.abs().max(b.abs())
}

fn extra<'a>(x: &'a Extras, name: &str) -> Option<&'a Extra> {
    x.iter().find(|(n, _)| *n == name).map(|(_, v)| v)
}

fn int(x: &Extras, name: &str) -> u64 {
    match extra(x, name) {
        Some(Extra::Int(v)) => *v,
        other => panic!("extra {name}: {other:?}"),
    }
}

fn ln(x: f64) -> f64 {
    x.ln()
}

// ---------------------------------------------------------------------------------------------
// §6.5 worked example (learn = 4)
// ---------------------------------------------------------------------------------------------

#[test]
fn example_rot() {
    let mut e = PajotRot::new(4).unwrap();
    for &s in &RUNNING[..4] {
        e.push(s);
    }
    // Learning end: σ = 0.54512 over the three non-black logs, h = 0.22987.
    let h = e.bandwidth();
    assert!((h - 0.22987).abs() < PRINTED, "h = {h}");
    assert!((h / 75f64.powf(-0.2) - 0.54512).abs() < PRINTED, "sigma");
    // Gaps 0.9163 >= 2h and 0.3830 < 2h: one mode {1.5, 2.2}.
    assert!(ln(1.5) - ln(0.6) >= 2.0 * h && ln(2.2) - ln(1.5) < 2.0 * h);
    assert_eq!(e.bound(), ln(2.2));
    assert_eq!(e.delayed(), 0);
    assert_eq!(e.accepted(), 4);

    e.push(4.8);
    assert!((e.bandwidth() - 0.29792).abs() < PRINTED);
    assert!(ln(4.8) - ln(2.2) >= 2.0 * e.bandwidth());
    assert_eq!((e.bound(), e.delayed()), (ln(2.2), 1));

    e.push(350.0);
    assert!((e.bandwidth() - 0.84570).abs() < PRINTED);
    assert_eq!((e.bound(), e.delayed()), (ln(2.2), 2));

    e.push(4.1);
    assert!((e.bandwidth() - 0.74493).abs() < PRINTED);
    assert_eq!(e.bound(), ln(4.8), "4.1 overlaps m and 4.8");
    assert_eq!(e.delayed(), 1);
    assert!(close(e.estimate().unwrap(), 2.2, 1e-12));
    let x = e.extras();
    assert_eq!(int(&x, "delayed"), 1);
    assert_eq!(extra(&x, "m"), Some(&Extra::Float(ln(4.8))));
}

#[test]
fn example_adr() {
    let mut e = PajotAdr::new(4).unwrap();
    for &s in &RUNNING[..4] {
        e.push(s);
    }
    let h = adr_bandwidths(&[ln(0.6), ln(1.5), ln(2.2)]);
    for (h, want) in h.iter().zip([0.6467, 0.5222, 0.5222]) {
        assert!((h - want).abs() < PRINTED, "{h} vs {want}");
    }
    let mode = PajotMode {
        lo: ln(0.6),
        hi: ln(2.2),
        count: 3,
    };
    assert_eq!(e.modes(), vec![mode]);
    assert_eq!(e.bound(), ln(2.2));

    // 4.8: the mode's evenly spaced points plus the newcomer, eq. 4 bandwidths.
    let mut points: Vec<f64> = mode.points().collect();
    points.push(ln(4.8));
    for (p, want) in points.iter().zip([-0.5108, 0.1388, 0.7885, 1.5686]) {
        assert!((p - want).abs() < PRINTED, "{p} vs {want}");
    }
    let h = adr_bandwidths(&points);
    assert!(
        (h[3] - 0.7128).abs() < PRINTED && (h[2] - 0.6816).abs() < PRINTED,
        "{h:?}"
    );
    assert!(ln(4.8) - ln(2.2) < h[2] + h[3]);
    e.push(4.8);
    let wide = PajotMode {
        lo: ln(0.6),
        hi: ln(4.8),
        count: 4,
    };
    assert_eq!(e.modes(), vec![wide]);
    assert_eq!((e.bound(), e.delayed()), (ln(4.8), 0), "accepted at once");

    e.push(350.0);
    let far = PajotMode {
        lo: ln(350.0),
        hi: ln(350.0),
        count: 1,
    };
    assert_eq!(e.modes(), vec![wide, far]);
    assert_eq!(e.delayed(), 1);

    e.push(4.1);
    assert_eq!(e.modes(), vec![PajotMode { count: 5, ..wide }, far]);
    assert_eq!(e.delayed(), 1);
    assert!(close(e.estimate().unwrap(), 2.2, 1e-12));
    let x = e.extras();
    assert_eq!((int(&x, "modes_single"), int(&x, "modes_extended")), (1, 1));
}

#[test]
fn example_hybrid() {
    let mut e = PajotHybrid::new(4, 2, 0.0).unwrap();
    let mut bounds = Vec::new();
    for &s in &RUNNING {
        e.push(s);
        bounds.push((e.rot_bound(), e.adr_bound(), e.bound()));
    }
    // Events: learning end (equal), 4.8 (unequal), 4.1 (equal): streak 1, no switch.
    assert_eq!(bounds[3], (ln(2.2), ln(2.2), ln(2.2)));
    assert_eq!(bounds[4], (ln(2.2), ln(4.8), ln(4.8)));
    assert_eq!(bounds[5], (ln(2.2), ln(4.8), ln(4.8)));
    assert_eq!(bounds[6], (ln(4.8), ln(4.8), ln(4.8)));
    assert_eq!(e.switch_index(), None);
    assert_eq!(e.delayed(), 1);
    assert!(close(e.estimate().unwrap(), 2.2, 1e-12));
    let x = e.extras();
    assert_eq!(extra(&x, "switched"), Some(&Extra::Bool(false)));
    assert_eq!(extra(&x, "switch_index"), None);

    let mut e = PajotHybrid::new(4, 1, 0.0).unwrap();
    for &s in &RUNNING {
        e.push(s);
    }
    assert_eq!(e.switch_index(), Some(3));
    assert!(close(e.estimate().unwrap(), 2.2, 1e-12));
    assert_eq!(e.delayed(), 1);
    let x = e.extras();
    assert_eq!(extra(&x, "switched"), Some(&Extra::Bool(true)));
    assert_eq!(int(&x, "switch_index"), 3);
    assert_eq!(
        (int(&x, "modes_single"), int(&x, "modes_extended")),
        (0, 0),
        "modes freed at the switch"
    );
}

#[test]
fn example_while_learning() {
    // learn = 50: still learning after 7 samples; computed as if learning ended now.
    for spec in [
        "pajot-rot:learn=50",
        "pajot-adr:learn=50",
        "pajot-hybrid:learn=50,T=2,delta=0",
        "pajot-rot",
        "pajot-hybrid:delta=0,T=2",
    ] {
        let spec: EstimatorSpec = spec.parse().unwrap();
        let mut e = spec.build().unwrap();
        e.push_slice(&RUNNING);
        let got = e.estimate().unwrap();
        assert!(close(got, 2.2, 1e-12), "{spec}: {got}");
        assert_eq!(int(&e.extras(), "delayed"), 1, "{spec}");
        assert_eq!(e.spec(), spec);
    }
}

#[test]
fn spec_strings_build_the_estimators() {
    for (s, name) in [
        ("pajot-rot:learn=4", "Pajot-ROT(learn=4)"),
        ("pajot-adr:learn=4", "Pajot-ADR(learn=4)"),
        (
            "pajot-hybrid:learn=4,T=1,delta=0.5",
            "Pajot-hybrid(learn=4,T=1,delta=0.5)",
        ),
    ] {
        let spec: EstimatorSpec = s.parse().unwrap();
        let mut e = spec.build().unwrap();
        assert_eq!(e.to_string(), name);
        assert_eq!(e.spec().to_string(), s);
        e.push_slice(&RUNNING);
        assert!(close(e.estimate().unwrap(), 2.2, 1e-12), "{s}");
        assert!(
            e.spec().build().unwrap().estimate().is_err(),
            "rebuilt empty"
        );
    }
    let bad = |s: &str| {
        s.parse::<EstimatorSpec>()
            .unwrap()
            .build()
            .err()
            .unwrap()
            .to_string()
    };
    assert!(bad("pajot-hybrid:T=0").contains("T = 0"));
    assert!(bad("pajot-hybrid:delta=-1").contains("delta = -1"));
    assert!(bad("pajot-hybrid:delta=inf").contains("delta = inf"));
    assert!(bad("pajot-hybrid:delta=NaN").contains("delta = NaN"));
}

// ---------------------------------------------------------------------------------------------
// Decisions (module doc, numbered as there)
// ---------------------------------------------------------------------------------------------

/// Decision 1: `≤`. A newcomer exactly at `m` is accepted, and so is the sample defining `m`.
#[test]
fn decision_1_accept_at_the_bound() {
    for mut e in all(2) {
        e.push_slice(&[3.0, 3.0, 3.0]);
        assert_eq!(int(&e.extras(), "delayed"), 0, "{e}");
        assert_eq!(e.estimate().unwrap(), 3.0, "{e}");
    }
    let mut e = PajotRot::new(4).unwrap();
    e.push_slice(&RUNNING[..4]);
    assert_eq!(e.bound(), ln(2.2));
    e.push(2.2);
    assert_eq!(e.delayed(), 0);
}

/// Decision 2: the divisor is the accepted count (black samples included), not n.
#[test]
fn decision_2_divisor_is_accepted_count() {
    for mut e in all(4) {
        e.push_slice(&RUNNING);
        let x = e.extras();
        assert_eq!(int(&x, "delayed"), 1);
        // 6 accepted: 13.2 / 6, not 13.2 / 7.
        assert!(close(e.estimate().unwrap(), 13.2 / 6.0, 1e-12), "{e}");
    }
}

/// Decision 3: reads during learning are as if learning ended now, and change nothing.
#[test]
fn decision_3_reads_during_learning_leave_state_unchanged() {
    let stream: Vec<f64> = (0..80)
        .map(|i| 1.0 + ((i * 37) % 11) as f64 * 0.1)
        .collect();
    for (mut read, mut quiet) in all(50).into_iter().zip(all(50)) {
        for &s in &stream {
            read.push(s);
            let _ = read.estimate().unwrap();
            let _ = read.extras();
            let _ = read.state_bytes();
            quiet.push(s);
        }
        assert_eq!(
            read.estimate().unwrap(),
            quiet.estimate().unwrap(),
            "{read}"
        );
        assert_eq!(read.extras(), quiet.extras(), "{read}");
        assert_eq!(read.state_bytes(), quiet.state_bytes(), "{read}");
    }
    // As if learning ended now: the same as a learner of exactly n samples.
    let mut early = PajotAdr::new(50).unwrap();
    let mut exact = PajotAdr::new(7).unwrap();
    early.push_slice(&RUNNING);
    exact.push_slice(&RUNNING);
    assert_eq!(early.modes(), exact.modes());
    assert_eq!(early.extras(), exact.extras());
}

/// Decision 4: without an extended mode every non-black sample is delayed.
#[test]
fn decision_4_no_extended_mode_delays_everything() {
    for learn in [0, 1, 50] {
        for mut e in all(learn) {
            e.push(5.0);
            assert_eq!(e.estimate().unwrap(), 0.0, "{e}: one sample estimates 0");
            assert_eq!(int(&e.extras(), "delayed"), 1);
            e.push(0.0);
            assert_eq!(e.estimate().unwrap(), 0.0, "{e}");
            assert_eq!(int(&e.extras(), "delayed"), 1);
            assert_eq!(
                extra(&e.extras(), "m"),
                Some(&Extra::Float(f64::NEG_INFINITY))
            );
        }
    }
}

/// Decision 5: h is the half-width. Two distinct samples under ROT with k = 2 never overlap:
/// `2h = 2 (50)^(-1/5) |Δ|/2 ≈ 0.457 |Δ| < |Δ|`, whereas Silverman's √5-wider support would
/// reach (`≈ 1.02 |Δ|`).
#[test]
fn decision_5_half_width_reading() {
    let mut e = PajotRot::new(2).unwrap();
    e.push_slice(&[1.0, 2.0]);
    let (h, gap) = (e.bandwidth(), ln(2.0));
    assert!(2.0 * h < gap && 2.0 * 5f64.sqrt() * h > gap, "h = {h}");
    assert_eq!(e.bound(), f64::NEG_INFINITY);
    assert_eq!(e.delayed(), 2);
}

/// Decision 6: ROT examines only the newcomer's overlaps. Two delayed samples that the grown h
/// would chain to `m` stay delayed until a newcomer overlaps them.
#[test]
fn decision_6_rot_does_not_rechain_delayed_samples() {
    let mut e = PajotRot::new(4).unwrap();
    e.push_slice(&[1.0; 4]);
    assert_eq!(e.bound(), 0.0);
    e.push(1f64.exp()); // h = 0.152: 1.0 from m, delayed.
    e.push(1.5f64.exp()); // h = 0.223: 0.5 from the delayed 1.0, delayed.
    assert_eq!(e.delayed(), 2);
    e.push(10f64.exp()); // sigma grows: h = 1.21, 2h > 1.5, yet nothing is re-tested.
    assert!(2.0 * e.bandwidth() > 1.5);
    assert_eq!((e.bound(), e.delayed()), (0.0, 3));
    e.push(0.5f64.exp()); // overlaps m, 1.0 and 1.5: m = 1.5, both released.
    assert_eq!((e.bound(), e.delayed()), (1.5, 1));
}

/// Decision 7: a merge replaces the newcomer and the modes it overlaps by one extended mode
/// spanning them (here one mode on each side). The case where a mode inside the span is not
/// itself overlapped is a unit test of the module (it needs hand-made modes).
#[test]
fn decision_7_adr_merges_keep_modes_disjoint() {
    let mut e = PajotAdr::new(4).unwrap();
    e.push_slice(&[1.0, 2.0, 30.0, 90.0]);
    assert_eq!(e.modes().len(), 2);
    assert_eq!(e.bound(), ln(90.0));
    e.push(7.0);
    let merged = PajotMode {
        lo: 0.0,
        hi: ln(90.0),
        count: 5,
    };
    assert_eq!(e.modes(), vec![merged]);
}

/// Decision 8: the switch test is relative (`|m_ROT - m_ADR| <= δ |m_ADR|`), and `m_h` never
/// decreases, at the switch or elsewhere.
#[test]
fn decision_8_relative_agreement_and_monotone_bound() {
    // Example bounds after 4.8: m_ROT = ln 2.2 = 0.788, m_ADR = ln 4.8 = 1.569; relative gap
    // 0.497. With δ = 0.5 every event agrees: T = 2 switches at 4.8 (index 4).
    let mut e = PajotHybrid::new(4, 2, 0.5).unwrap();
    e.push_slice(&RUNNING);
    assert_eq!(e.switch_index(), Some(4));
    let mut e = PajotHybrid::new(4, 2, 0.49).unwrap();
    e.push_slice(&RUNNING);
    assert_eq!(e.switch_index(), None);
    // While learning the hybrid uses ADR's bound.
    let mut e = PajotHybrid::new(50, 2, 0.0).unwrap();
    e.push_slice(&[0.6, 1.5]);
    assert_eq!(e.bound(), e.adr_bound());
    assert_eq!(e.rot_bound(), f64::NEG_INFINITY);
    assert_eq!(e.bound(), ln(1.5));
}

/// Decision 9: inside the hybrid, ROT and ADR evolve as the standalone estimators.
#[test]
fn decision_9_components_match_standalone() {
    let stream = preset_stream(Preset::Firefly, 3, 2000);
    let mut h = PajotHybrid::new(20, 1_000_000, 0.0).unwrap();
    let mut r = PajotRot::new(20).unwrap();
    let mut a = PajotAdr::new(20).unwrap();
    for &s in &stream {
        h.push(s);
        r.push(s);
        a.push(s);
        assert_eq!(h.rot_bound(), r.bound());
        assert_eq!(h.adr_bound(), a.bound());
        assert_eq!(h.bound(), a.bound(), "never switches: m_h = m_ADR");
    }
}

/// Decision 10: the bounded list drops its largest entry, for good.
#[test]
fn decision_10_bounded_list_drops_the_largest() {
    // 100 black-free ones: m = 0 and h stays small, so these bright values never overlap.
    let ones = [1.0; 100];
    let bright = [1e3, 1e9, 1e5, 1e7, 1e2];
    let mut e = PajotRot::new(100).unwrap().with_max_delayed(3);
    assert_eq!(e.max_delayed(), Some(3));
    e.push_slice(&ones);
    e.push_slice(&bright);
    // Kept: the 3 smallest (1e2, 1e3, 1e5); 1e9 dropped when 1e7 came, then 1e7 when 1e2 came.
    assert_eq!((e.delayed(), e.dropped()), (3, 2));
    assert_eq!(e.accepted() + e.delayed() + e.dropped(), e.count());
    assert_eq!(e.to_string(), "Pajot-ROT(learn=100,max_delayed=3)");
    assert_eq!(int(&e.extras(), "dropped"), 2);
    // A copy of 1e9 arrives: unbounded, it would meet the first 1e9 (identical values
    // overlap) and release everything; here the first is gone, the newcomer is alone and the
    // largest, so it is dropped too.
    e.push(1e9);
    assert_eq!((e.delayed(), e.dropped(), e.bound()), (3, 3, 0.0));
    let mut u = PajotRot::new(100).unwrap();
    u.push_slice(&ones);
    u.push_slice(&bright);
    u.push(1e9);
    assert_eq!((u.delayed(), u.bound()), (0, ln(1e9)));
    assert_eq!(
        extra(&u.extras(), "dropped"),
        None,
        "reported only when bounded"
    );

    // A dropped sample is never accepted, even once m passes it. learn = 2: m = 0; 1e6 is
    // delayed, then dropped for 1e3; tiny accepted samples widen h until e^14.3 * 1 overlaps
    // 1e3 (ln 6.9) and sets m = 14.3 > ln 1e6 = 13.8.
    let mut stream = vec![1.0, 1.0, 1e6, 1e3];
    stream.extend([1e-8; 6]);
    let (a, b) = (1e6 * 0.5f64.exp(), 1e6 * 0.6f64.exp());
    stream.extend([a, b]);
    let mut e = PajotRot::new(2).unwrap().with_max_delayed(1);
    e.push_slice(&stream[..4]);
    assert_eq!((e.delayed(), e.dropped()), (1, 1));
    e.push_slice(&stream[4..]);
    assert_eq!(e.bound(), b.ln());
    assert!(e.bound() > ln(1e6));
    assert_eq!((e.delayed(), e.dropped()), (0, 1));
    let want = (2.0 + 1e3 + 6e-8 + a + b) / 11.0; // 12 samples, the dropped 1e6 left out
    assert!(close(e.estimate().unwrap(), want, 1e-12));

    // k = 0: every delayed sample is dropped at once.
    let mut e = PajotHybrid::new(4, 2, 0.0).unwrap().with_max_delayed(0);
    e.push_slice(&RUNNING);
    // 4.8 is accepted at once by ADR's bound; only 350 is delayed, hence dropped.
    assert_eq!((e.delayed(), e.dropped()), (0, 1));
    assert!(close(e.estimate().unwrap(), 2.2, 1e-12));
    assert_eq!(
        e.to_string(),
        "Pajot-hybrid(learn=4,T=2,delta=0,max_delayed=0)"
    );
}

/// Decision 10, in bulk: the cap holds, counts are conserved, and a cap never binding changes
/// nothing.
#[test]
fn decision_10_cap_invariants() {
    for preset in [Preset::Caustic, Preset::Firefly, Preset::Glossy] {
        let stream = preset_stream(preset, 11, 3000);
        for k in [0, 1, 4, 1_000_000] {
            let capped: Vec<Box<dyn Estimator>> = vec![
                Box::new(PajotRot::new(10).unwrap().with_max_delayed(k)),
                Box::new(PajotAdr::new(10).unwrap().with_max_delayed(k)),
                Box::new(PajotHybrid::new(10, 2, 0.0).unwrap().with_max_delayed(k)),
            ];
            for (mut c, mut u) in capped.into_iter().zip(all(10)) {
                for &s in &stream {
                    c.push(s);
                    u.push(s);
                    let x = c.extras();
                    assert!(int(&x, "delayed") <= k as u64);
                }
                if k == 1_000_000 {
                    assert_eq!(c.estimate().unwrap(), u.estimate().unwrap(), "{c}");
                    assert_eq!(int(&c.extras(), "dropped"), 0);
                }
            }
        }
    }
}

/// Decisions 12 and 14: learning storage and ADR's modes are freed when no longer needed.
#[test]
fn decisions_12_14_memory_is_released() {
    let stream = preset_stream(Preset::Diffuse, 5, 1200);
    let mut e = PajotRot::new(1000).unwrap();
    e.push_slice(&stream[..999]);
    let learning = e.state_bytes();
    e.push_slice(&stream[999..]);
    assert!(
        e.state_bytes() + 900 * 8 < learning,
        "{} vs {learning}",
        e.state_bytes()
    );

    let mut e = PajotHybrid::new(50, 1, 1e9).unwrap();
    let mut never = PajotHybrid::new(50, usize::MAX, 0.0).unwrap();
    let mut a = PajotAdr::new(50).unwrap();
    e.push_slice(&stream[..49]);
    a.push_slice(&stream[..49]);
    e.push(stream[49]); // learning end: an event, agreement within δ: switch.
    a.push(stream[49]);
    assert_eq!(e.switch_index(), Some(49));
    assert!(e.modes().is_empty());
    assert_eq!(extra(&e.extras(), "m_adr"), Some(&Extra::Float(a.bound())));
    e.push_slice(&stream[50..]);
    never.push_slice(&stream);
    assert!(!never.modes().is_empty());
    assert!(
        e.state_bytes() < never.state_bytes(),
        "no modes held after the switch"
    );
}

/// Decision 15: `-0.0` is black.
#[test]
fn decision_15_negative_zero_is_black() {
    for mut e in all(2) {
        e.push_slice(&[-0.0, 2.0, 2.0, -0.0]);
        assert_eq!(e.estimate().unwrap(), 1.0, "{e}");
        assert_eq!(int(&e.extras(), "delayed"), 0);
    }
}

/// Decision 16: `learn = 0` starts with the post-learning rules; there is no learning event.
#[test]
fn decision_16_learn_zero() {
    for mut e in all(0) {
        e.push(2.0);
        assert_eq!(int(&e.extras(), "delayed"), 1, "{e}");
        e.push(2.0);
        assert_eq!(
            int(&e.extras(), "delayed"),
            0,
            "{e}: identical values overlap"
        );
        assert_eq!(e.estimate().unwrap(), 2.0);
    }
    // The running example from sample 0: every step checked against the literal reading.
    for kind in [Kind::Rot, Kind::Adr, Kind::Hybrid { t: 1, delta: 0.0 }] {
        check_against_reference(kind, 0, &RUNNING, None);
    }
}

// ---------------------------------------------------------------------------------------------
// Properties
// ---------------------------------------------------------------------------------------------

fn all(learn: usize) -> Vec<Box<dyn Estimator>> {
    vec![
        Box::new(PajotRot::new(learn).unwrap()),
        Box::new(PajotAdr::new(learn).unwrap()),
        Box::new(PajotHybrid::new(learn, 2, 0.0).unwrap()),
    ]
}

fn preset_stream(preset: Preset, seed: u64, n: usize) -> Vec<f64> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut out = vec![0.0; n];
    preset.dist().fill(&mut rng, &mut out);
    out
}

/// Samples with black ones, repeats (so modes form) and bright outliers.
fn samples(max_len: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(
        prop_oneof![
            4 => 0.2f64..5.0,
            1 => Just(0.0),
            1 => Just(2.0),
            1 => Just(3.0),
            1 => 50.0f64..5e4,
        ],
        0..max_len,
    )
}

/// The accepted set is always {black} ∪ {ln S <= m}: the estimate is that set's mean.
fn mean_at_or_below(stream: &[f64], m: f64) -> f64 {
    let acc: Vec<f64> = stream
        .iter()
        .copied()
        .filter(|&s| s == 0.0 || s.ln() <= m)
        .collect();
    if acc.is_empty() {
        0.0
    } else {
        acc.iter().sum::<f64>() / acc.len() as f64
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Every estimator agrees with a literal, slow re-reading of the spec, step by step.
    #[test]
    fn matches_literal_reading(stream in samples(60), learn in 0usize..8, t in 1usize..4,
                               delta in prop_oneof![Just(0.0), 0.0f64..0.5]) {
        check_against_reference(Kind::Rot, learn, &stream, None);
        check_against_reference(Kind::Adr, learn, &stream, None);
        check_against_reference(Kind::Hybrid { t, delta }, learn, &stream, None);
    }

    /// With a bounded list, the reference with the same drop rule agrees too. (The hybrid's
    /// list also holds ROT's accepted overlap points, decision 10; its cap is checked by
    /// invariants in `decision_10_cap_invariants`.)
    #[test]
    fn matches_literal_reading_bounded(stream in samples(60), learn in 0usize..6,
                                       cap in 0usize..4) {
        check_against_reference(Kind::Rot, learn, &stream, Some(cap));
        check_against_reference(Kind::Adr, learn, &stream, Some(cap));
    }

    /// No sample above the last extended mode: nothing is delayed. The learning set's largest
    /// value comes twice, so the last mode is extended and tops at it; no later sample is
    /// larger.
    #[test]
    fn nothing_above_last_extended_mode_nothing_delayed(
        mut learning in prop::collection::vec(
            prop_oneof![3 => 0.1f64..100.0, 1 => Just(0.0)],
            1..30,
        ),
        later in prop::collection::vec(0.0f64..1.0, 0..100),
    ) {
        let top = learning.iter().copied().fold(0.0, f64::max);
        prop_assume!(top > 0.0);
        learning.push(top);
        let later: Vec<f64> = later.iter().map(|u| u * top).collect();
        for mut e in all(learning.len()) {
            e.push_slice(&learning);
            let x = e.extras();
            prop_assert_eq!(extra(&x, "m"), Some(&Extra::Float(top.ln())));
            e.push_slice(&later);
            prop_assert_eq!(int(&e.extras(), "delayed"), 0, "{}", e);
        }
    }

    /// A stream of identical values is fully accepted from the second sample on.
    #[test]
    fn identical_values_fully_accepted(v in 1e-300f64..1e300, n in 2usize..200,
                                       learn in 0usize..60) {
        for mut e in all(learn) {
            e.push_slice(&vec![v; n]);
            prop_assert_eq!(int(&e.extras(), "delayed"), 0);
            prop_assert!(close(e.estimate().unwrap(), v, 1e-12));
        }
    }

    /// Scaling every sample by c > 0 scales the estimate by c and changes no decision.
    #[test]
    fn scale_invariant(stream in samples(80), learn in 0usize..10,
                       c in prop_oneof![1e-3f64..1e3, Just(1024.0)]) {
        let scaled: Vec<f64> = stream.iter().map(|s| s * c).collect();
        for (mut a, mut b) in all(learn).into_iter().zip(all(learn)) {
            a.push_slice(&stream);
            b.push_slice(&scaled);
            if stream.is_empty() {
                continue;
            }
            prop_assert_eq!(int(&a.extras(), "delayed"), int(&b.extras(), "delayed"), "{}", a);
            let (ea, eb) = (a.estimate().unwrap(), b.estimate().unwrap());
            prop_assert!(close(ea * c, eb, 1e-9), "{}: {} * {} vs {}", a, ea, c, eb);
        }
    }

    /// Estimates lie in [0, max S]; accepted + delayed = n.
    #[test]
    fn estimate_in_range_and_counts_conserved(stream in samples(120), learn in 0usize..60) {
        prop_assume!(!stream.is_empty());
        let max = stream.iter().copied().fold(0.0, f64::max);
        for mut e in all(learn) {
            e.push_slice(&stream);
            let est = e.estimate().unwrap();
            prop_assert!((0.0..=max * (1.0 + 1e-12)).contains(&est), "{}: {}", e, est);
        }
        let mut r = PajotRot::new(learn).unwrap();
        let mut a = PajotAdr::new(learn).unwrap();
        let mut h = PajotHybrid::new(learn, 2, 0.0).unwrap();
        r.push_slice(&stream);
        a.push_slice(&stream);
        h.push_slice(&stream);
        let n = stream.len() as u64;
        prop_assert_eq!(r.accepted() + r.delayed(), n);
        prop_assert_eq!(a.accepted() + a.delayed(), n);
        prop_assert_eq!(h.accepted() + h.delayed(), n);
    }

    /// Order of arrival after learning: whatever the order, accepted = {black} ∪ {ln S <= m}
    /// for the final m, and m ends at or above the bound at the end of learning (so a sample
    /// at or below that bound is never delayed); for ROT, when no later sample exceeds that
    /// bound the outcome does not depend on the order at all. What m itself ends at may depend
    /// on the order (module doc, Properties).
    #[test]
    fn order_after_learning(learning in samples(20), rest in samples(60), seed in any::<u64>(),
                            below in any::<bool>()) {
        prop_assume!(!learning.is_empty());
        let mut rest = rest;
        let mut probe = PajotRot::new(learning.len()).unwrap();
        probe.push_slice(&learning);
        let m_learn_rot = probe.bound();
        if below {
            // Keep only later samples that cannot move any bound.
            rest.retain(|&s| s == 0.0 || s.ln() <= m_learn_rot);
        }
        let mut shuffled = rest.clone();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        use rand::seq::SliceRandom;
        shuffled.shuffle(&mut rng);
        let learn = learning.len();
        let full = |tail: &[f64]| [learning.as_slice(), tail].concat();
        let (a_stream, b_stream) = (full(&rest), full(&shuffled));

        let mut outcomes = Vec::new();
        for stream in [&a_stream, &b_stream] {
            let mut r = PajotRot::new(learn).unwrap();
            let mut a = PajotAdr::new(learn).unwrap();
            let mut h = PajotHybrid::new(learn, 2, 0.0).unwrap();
            r.push_slice(&stream[..learn]);
            a.push_slice(&stream[..learn]);
            h.push_slice(&stream[..learn]);
            let learned = [r.bound(), a.bound(), h.bound()];
            r.push_slice(&stream[learn..]);
            a.push_slice(&stream[learn..]);
            h.push_slice(&stream[learn..]);
            let fin = [r.bound(), a.bound(), h.bound()];
            let est = [r.estimate().unwrap(), a.estimate().unwrap(), h.estimate().unwrap()];
            for i in 0..3 {
                prop_assert!(fin[i] >= learned[i]);
                prop_assert!(close(est[i], mean_at_or_below(stream, fin[i]), 1e-12));
            }
            outcomes.push((fin, [r.delayed(), a.delayed(), h.delayed()], est));
        }
        if below {
            // ROT: no later sample exceeds m_ROT, so m_ROT never moves and the order changes
            // nothing. ADR (hence the hybrid) has no such guarantee: a newcomer at or below m
            // can merge with a single above m and raise m (module doc, Properties).
            prop_assert_eq!(outcomes[0].0[0], outcomes[1].0[0]);
            prop_assert_eq!(outcomes[0].1[0], outcomes[1].1[0]);
            prop_assert!(close(outcomes[0].2[0], outcomes[1].2[0], 1e-12));
        }
    }

    /// Constructors never panic; the estimators survive any later use.
    #[test]
    fn constructors_never_panic(learn in any::<usize>(), t in any::<usize>(), delta in any::<f64>(),
                                cap in any::<usize>()) {
        let _ = PajotRot::new(learn).map(|e| e.with_max_delayed(cap));
        let _ = PajotAdr::new(learn).map(|e| e.with_max_delayed(cap));
        if let Ok(mut e) = PajotHybrid::new(learn, t, delta) {
            prop_assert!(t >= 1 && delta >= 0.0 && delta.is_finite());
            e = e.with_max_delayed(cap);
            e.push_slice(&RUNNING);
            prop_assert!(e.estimate().is_ok());
        } else {
            prop_assert!(t == 0 || !(delta >= 0.0 && delta.is_finite()));
        }
        for special in [0usize, 1, usize::MAX] {
            let mut e = PajotRot::new(special).unwrap();
            e.push_slice(&RUNNING);
            prop_assert!(e.estimate().is_ok());
        }
    }
}

/// The glossy caustic of [P] fig. 9: rare bright samples from one small region of path space.
/// The first is delayed; once a similar one arrives they form an extended mode and both count.
#[test]
fn glossy_caustic_cluster_is_accepted_once_corroborated() {
    let body = preset_stream(Preset::Diffuse, 9, 400);
    let bright = [140.0, 141.0, 139.5];
    for mut e in all(50) {
        e.push_slice(&body[..200]);
        e.push(bright[0]);
        assert!(
            int(&e.extras(), "delayed") >= 1,
            "{e}: first bright delayed"
        );
        e.push_slice(&body[200..300]);
        e.push(bright[1]);
        let x = e.extras();
        assert_eq!(int(&x, "delayed"), 0, "{e}: the pair is a mode now");
        assert_eq!(extra(&x, "m"), Some(&Extra::Float(ln(141.0))), "{e}");
        e.push_slice(&body[300..]);
        e.push(bright[2]);
        assert_eq!(int(&e.extras(), "delayed"), 0, "{e}");
        let mut all_samples = body.clone();
        all_samples.extend(bright);
        let mean = all_samples.iter().sum::<f64>() / all_samples.len() as f64;
        assert!(close(e.estimate().unwrap(), mean, 1e-12), "{e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Hard inputs
// ---------------------------------------------------------------------------------------------

#[test]
fn hard_inputs() {
    for learn in [0, 3, 50] {
        for v in [1e-300, 1e300, f64::MIN_POSITIVE, 5e-324, f64::MAX / 1e3] {
            for mut e in all(learn) {
                e.push_slice(&[v; 100]);
                assert!(close(e.estimate().unwrap(), v, 1e-12), "{e}: {v}");
                assert_eq!(int(&e.extras(), "delayed"), 0);
            }
        }
        // Extremes together: finite, in range, counts conserved.
        let mixed: Vec<f64> = (0..200)
            .map(|i| [1e-300, 1e300, 0.0, 1.0][i % 4] * (1.0 + (i as f64) * 1e-3))
            .collect();
        let max = mixed.iter().copied().fold(0.0, f64::max);
        for mut e in all(learn) {
            e.push_slice(&mixed);
            let est = e.estimate().unwrap();
            assert!(est.is_finite() && (0.0..=max).contains(&est), "{e}: {est}");
        }
        // All black.
        for mut e in all(learn) {
            assert!(e.estimate().is_err(), "{e}: n = 0 is an error");
            e.push_slice(&[0.0; 10]);
            assert_eq!(e.estimate().unwrap(), 0.0);
            let x = e.extras();
            assert_eq!(int(&x, "delayed"), 0);
            assert_eq!(extra(&x, "m"), Some(&Extra::Float(f64::NEG_INFINITY)));
        }
    }
    // n < learn and reset.
    for mut e in all(1000) {
        e.push_slice(&RUNNING);
        assert!(close(e.estimate().unwrap(), 2.2, 1e-12));
        e.reset();
        assert!(e.estimate().is_err());
        assert_eq!(e.count(), 0);
        e.push_slice(&RUNNING);
        assert!(close(e.estimate().unwrap(), 2.2, 1e-12));
    }
    // Push and push_slice agree.
    let stream = preset_stream(Preset::Caustic, 2, 5000);
    for (mut a, mut b) in all(50).into_iter().zip(all(50)) {
        a.push_slice(&stream);
        for &s in &stream {
            b.push(s);
        }
        assert_eq!(a.estimate().unwrap(), b.estimate().unwrap());
        assert_eq!(a.extras(), b.extras());
    }
}

// ---------------------------------------------------------------------------------------------
// Statistics on the presets
// ---------------------------------------------------------------------------------------------

/// Pixels (independent streams) per measured configuration.
const PIXELS: u64 = 400;

struct Measured {
    /// Mean over pixels of (delayed at the end) / spp.
    delayed_fraction: f64,
    /// Standard error of that mean (over pixels).
    se: f64,
    /// Mean over pixels of the peak state size (bytes), read after every sample.
    mean_bytes: f64,
    /// Largest peak state size over pixels.
    max_bytes: usize,
    /// Mean and largest state size at the end of the stream.
    end_bytes: (f64, usize),
    /// Pixels whose hybrid switched to ROT.
    switched: u64,
}

fn measure(preset: Preset, spp: usize, pixels: u64, make: fn() -> Box<dyn Estimator>) -> Measured {
    let (mut sum, mut sum2, mut bytes, mut max_bytes, mut switched) = (0.0, 0.0, 0.0, 0, 0);
    let (mut end_sum, mut end_max) = (0.0, 0);
    for pixel in 0..pixels {
        // The stream is a pure function of (preset, pixel, spp).
        let stream = preset_stream(preset, 0x5eed_0000 + pixel, spp);
        let mut e = make();
        let mut peak = 0;
        for &s in &stream {
            e.push(s);
            peak = peak.max(e.state_bytes());
        }
        let x = e.extras();
        let f = int(&x, "delayed") as f64 / spp as f64;
        sum += f;
        sum2 += f * f;
        bytes += peak as f64;
        max_bytes = max_bytes.max(peak);
        end_sum += e.state_bytes() as f64;
        end_max = end_max.max(e.state_bytes());
        if extra(&x, "switched") == Some(&Extra::Bool(true)) {
            switched += 1;
        }
    }
    let k = pixels as f64;
    let mean = sum / k;
    Measured {
        delayed_fraction: mean,
        se: ((sum2 / k - mean * mean).max(0.0) / (k - 1.0)).sqrt(),
        mean_bytes: bytes / k,
        max_bytes,
        end_bytes: (end_sum / k, end_max),
        switched,
    }
}

/// A named estimator constructor.
type Method = (&'static str, fn() -> Box<dyn Estimator>);

const METHODS: [Method; 3] = [
    ("rot", || Box::new(PajotRot::new(50).unwrap())),
    ("adr", || Box::new(PajotAdr::new(50).unwrap())),
    ("hybrid", || Box::new(PajotHybrid::new(50, 2, 0.0).unwrap())),
];

/// Delayed fractions (%) measured when this test was written: (preset, spp, [rot, adr, hybrid]).
const PINNED: [(Preset, usize, [f64; 3]); 6] = [
    (Preset::Caustic, 64, [0.516, 1.293, 1.277]),
    (Preset::Caustic, 256, [0.141, 0.489, 0.376]),
    (Preset::Caustic, 1024, [0.063, 0.235, 0.159]),
    (Preset::Firefly, 64, [0.516, 2.027, 2.027]),
    (Preset::Firefly, 256, [0.136, 0.738, 0.576]),
    (Preset::Firefly, 1024, [0.045, 0.343, 0.257]),
];

/// Relative tolerance on a pinned fraction: about 4-8 standard errors at 400 pixels. The seeds
/// are fixed, so the figures only move if the estimators change or the generators draw a
/// different stream; a new stream moves them by about one standard error (2-8%), a change of
/// behaviour by more than this bound fails.
const PINNED_TOLERANCE: f64 = 0.25;

/// The fraction of samples still delayed at the end of a pixel (learn = 50), on the `caustic`
/// and `firefly` presets, against [P] Table 4's 0.5-1.4%.
///
/// What the comparison means: Table 4 counts delayed samples in rendered scenes; our presets
/// are synthetic pixels with a unimodal lognormal body plus rare bright atoms or a thin Pareto
/// tail. On them the number of delayed samples per pixel stays of order one (the few extreme
/// samples that nothing corroborates: ~0.3-0.6 for ROT, ~1-3 for ADR), so the *fraction* falls
/// roughly like 1/spp: the paper's band is met at 64 spp (ROT 0.5%, ADR and hybrid 1.3-2.0%)
/// and our fractions are 2-20x below it at 1024 spp. The test asserts (a) at 64 spp every
/// method lies within a factor 2 of the paper's band, [0.25%, 2.8%], and (b) every figure lies
/// within `PINNED_TOLERANCE` of the pinned table. Run with `--nocapture` to see the table.
#[test]
fn delayed_fraction_on_caustic_and_firefly() {
    println!("preset    spp   method  delayed%  (se)    delayed/pixel  switched");
    for (preset, spp, pinned) in PINNED {
        for ((name, make), want) in METHODS.into_iter().zip(pinned) {
            let m = measure(preset, spp, PIXELS, make);
            let got = 100.0 * m.delayed_fraction;
            println!(
                "{:<9} {:>5} {:<7} {:>7.3}  ({:.3})  {:>13.2}  {:>8}",
                preset.name(),
                spp,
                name,
                got,
                100.0 * m.se,
                m.delayed_fraction * spp as f64,
                m.switched
            );
            assert!(
                (got - want).abs() <= PINNED_TOLERANCE * want,
                "{} {spp} spp {name}: {got:.3}% vs pinned {want}%",
                preset.name()
            );
            if spp == 64 {
                assert!(
                    (0.25..=2.8).contains(&got),
                    "{} {name}: {got:.3}% more than a factor 2 from 0.5-1.4%",
                    preset.name()
                );
            }
        }
    }
}

/// Per-pixel state size (peak over the stream, read after every sample, so the learning
/// buffer of 50 samples, 400 bytes, counts) on every preset at 1024 spp, and at the end of the
/// stream: mean and max over 100 pixels. ROT holds its moments, bound and delayed list; ADR
/// also its modes; the hybrid both until it switches. The bounds are loose regression bounds on
/// the printed figures (`--nocapture`).
#[test]
fn state_size_per_preset() {
    println!("preset             method   peak: mean    max   end: mean    max");
    for preset in Preset::ALL {
        for (name, make) in METHODS {
            let m = measure(preset, 1024, 100, make);
            println!(
                "{:<18} {:<7} {:>12.0} {:>6} {:>11.0} {:>6}",
                preset.name(),
                name,
                m.mean_bytes,
                m.max_bytes,
                m.end_bytes.0,
                m.end_bytes.1
            );
            let bound = if name == "rot" { 1024 } else { 16 * 1024 };
            assert!(
                m.max_bytes <= bound,
                "{} {name}: {} bytes",
                preset.name(),
                m.max_bytes
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// A literal, slow re-reading of docs/estimators.md §6, used as an oracle
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy)]
enum Kind {
    Rot,
    Adr,
    Hybrid { t: usize, delta: f64 },
}

/// Population σ by two passes (independent of the implementation's Welford).
fn sigma(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return 0.0;
    }
    let mean = xs.iter().sum::<f64>() / xs.len() as f64;
    (xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / xs.len() as f64).sqrt()
}

fn rot_h(logs: &[f64]) -> f64 {
    let k = logs.len();
    if k <= 1 {
        0.0
    } else {
        (25.0 * k as f64).powf(-0.2) * sigma(logs)
    }
}

/// Eq. 4 with an O(K^2) pilot over the ascending points.
fn eq4(xs: &[f64]) -> Vec<f64> {
    let k = xs.len();
    if k < 2 {
        return vec![0.0; k];
    }
    let nn = (0..k)
        .map(|i| {
            (0..k)
                .filter(|&j| j != i)
                .map(|j| (xs[i] - xs[j]).abs())
                .fold(f64::INFINITY, f64::min)
        })
        .sum::<f64>()
        / k as f64;
    if nn == 0.0 {
        return vec![0.0; k];
    }
    let p: Vec<f64> = xs
        .iter()
        .map(|&x| {
            xs.iter()
                .map(|&y| (1.0 - ((x - y) / nn).powi(2)).max(0.0))
                .sum()
        })
        .collect();
    let g = (p.iter().map(|p| p.ln()).sum::<f64>() / k as f64).exp();
    p.iter().map(|p| nn * (g / p).sqrt()).collect()
}

fn overlap(a: f64, ha: f64, b: f64, hb: f64) -> bool {
    a == b || (a - b).abs() < ha + hb
}

/// Ascending runs of linked neighbours as (lo, hi, count).
fn chain(xs: &[f64], h: &[f64]) -> Vec<(f64, f64, u64)> {
    let mut out: Vec<(f64, f64, u64)> = Vec::new();
    for i in 0..xs.len() {
        match out.last_mut() {
            Some(last) if overlap(xs[i - 1], h[i - 1], xs[i], h[i]) => {
                last.1 = xs[i];
                last.2 += 1;
            }
            _ => out.push((xs[i], xs[i], 1)),
        }
    }
    out
}

fn last_extended_top(modes: &[(f64, f64, u64)]) -> f64 {
    modes
        .iter()
        .rev()
        .find(|m| m.2 >= 2)
        .map_or(f64::NEG_INFINITY, |m| m.1)
}

struct RefRot {
    logs: Vec<f64>,
    m: f64,
    /// ROT's own delayed logs (its overlap points).
    delayed: Vec<f64>,
}

impl RefRot {
    fn learn_end(&mut self, stored: &[f64], cap: Option<usize>) {
        let mut ls: Vec<f64> = stored
            .iter()
            .filter(|&&s| s > 0.0)
            .map(|s| s.ln())
            .collect();
        self.logs.extend(&ls);
        ls.sort_by(f64::total_cmp);
        let h = rot_h(&self.logs);
        self.m = last_extended_top(&chain(&ls, &vec![h; ls.len()]));
        self.delayed = ls.into_iter().filter(|&l| l > self.m).collect();
        self.delayed.truncate(cap.unwrap_or(usize::MAX));
    }

    fn push(&mut self, l: f64, cap: Option<usize>) {
        self.logs.push(l);
        if l <= self.m {
            return;
        }
        let h = rot_h(&self.logs);
        let q: Vec<f64> = self
            .delayed
            .iter()
            .copied()
            .chain(Some(self.m).filter(|m| m.is_finite()))
            .filter(|&q| overlap(q, h, l, h))
            .collect();
        if !q.is_empty() {
            self.m = q.iter().copied().fold(l, f64::max);
            self.delayed.retain(|&d| d > self.m);
        }
        if l > self.m {
            self.delayed.push(l);
            if let Some(cap) = cap {
                if self.delayed.len() > cap {
                    let max = self
                        .delayed
                        .iter()
                        .copied()
                        .fold(f64::NEG_INFINITY, f64::max);
                    let i = self.delayed.iter().position(|&d| d == max).unwrap();
                    self.delayed.remove(i);
                }
            }
        }
    }
}

struct RefAdr {
    modes: Vec<(f64, f64, u64)>,
    m: f64,
}

impl RefAdr {
    fn learn_end(&mut self, stored: &[f64]) {
        let mut ls: Vec<f64> = stored
            .iter()
            .filter(|&&s| s > 0.0)
            .map(|s| s.ln())
            .collect();
        ls.sort_by(f64::total_cmp);
        self.modes = chain(&ls, &eq4(&ls));
        self.m = last_extended_top(&self.modes);
    }

    fn push(&mut self, l: f64) {
        if let Some(md) = self
            .modes
            .iter_mut()
            .find(|m| m.2 >= 2 && m.0 <= l && l <= m.1)
        {
            md.2 += 1;
            return;
        }
        // Points tagged with their mode (usize::MAX for the newcomer), sorted.
        let mut pts: Vec<(f64, usize)> = vec![(l, usize::MAX)];
        for (i, &(lo, hi, c)) in self.modes.iter().enumerate() {
            let mode = PajotMode { lo, hi, count: c };
            pts.extend(mode.points().map(|p| (p, i)));
        }
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let xs: Vec<f64> = pts.iter().map(|p| p.0).collect();
        let h = eq4(&xs);
        let me = pts.iter().position(|p| p.1 == usize::MAX).unwrap();
        let hit: Vec<usize> = (0..xs.len())
            .filter(|&j| j != me && overlap(l, h[me], xs[j], h[j]))
            .map(|j| pts[j].1)
            .collect();
        if hit.is_empty() {
            self.modes.push((l, l, 1));
            self.modes.sort_by(|a, b| a.0.total_cmp(&b.0));
            return;
        }
        let (mut lo, mut hi) = (l, l);
        for &i in &hit {
            lo = lo.min(self.modes[i].0);
            hi = hi.max(self.modes[i].1);
        }
        let mut count = 1;
        loop {
            let before = self.modes.len();
            self.modes.retain(|m| {
                if m.0 <= hi && m.1 >= lo {
                    lo = lo.min(m.0);
                    hi = hi.max(m.1);
                    count += m.2;
                    false
                } else {
                    true
                }
            });
            if self.modes.len() == before {
                break;
            }
        }
        self.modes.push((lo, hi, count));
        self.modes.sort_by(|a, b| a.0.total_cmp(&b.0));
        self.m = self.m.max(hi);
    }
}

/// The hybrid's switching state in the reference.
struct RefSwitch {
    m_h: f64,
    streak: usize,
    switched: bool,
}

impl RefSwitch {
    fn after_sample(&mut self, kind: Kind, rot: &RefRot, adr: &RefAdr, changed: bool) {
        let Kind::Hybrid { t, delta } = kind else {
            return;
        };
        if self.switched {
            self.m_h = self.m_h.max(rot.m);
            return;
        }
        self.m_h = self.m_h.max(adr.m);
        if changed {
            let agree = rot.m.is_finite()
                && adr.m.is_finite()
                && (rot.m - adr.m).abs() <= delta * adr.m.abs();
            self.streak = if agree { self.streak + 1 } else { 0 };
            if self.streak == t {
                self.m_h = self.m_h.max(adr.m).max(rot.m);
                self.switched = true;
            }
        }
    }
}

/// The spec's estimator, literally: after every sample, the accepted set is recomputed from
/// scratch as {black} ∪ {ln S <= m} minus the dropped samples, and compared with what the
/// estimator reports (bound, delayed count, estimate, mode counts, switch).
fn check_against_reference(kind: Kind, learn: usize, stream: &[f64], cap: Option<usize>) {
    let mut est: Box<dyn Estimator> = match (kind, cap) {
        (Kind::Rot, None) => Box::new(PajotRot::new(learn).unwrap()),
        (Kind::Adr, None) => Box::new(PajotAdr::new(learn).unwrap()),
        (Kind::Rot, Some(k)) => Box::new(PajotRot::new(learn).unwrap().with_max_delayed(k)),
        (Kind::Adr, Some(k)) => Box::new(PajotAdr::new(learn).unwrap().with_max_delayed(k)),
        (Kind::Hybrid { t, delta }, None) => Box::new(PajotHybrid::new(learn, t, delta).unwrap()),
        (Kind::Hybrid { .. }, Some(_)) => unreachable!("see matches_literal_reading_bounded"),
    };
    let mut rot = RefRot {
        logs: vec![],
        m: f64::NEG_INFINITY,
        delayed: vec![],
    };
    let mut adr = RefAdr {
        modes: vec![],
        m: f64::NEG_INFINITY,
    };
    let mut sw = RefSwitch {
        m_h: f64::NEG_INFINITY,
        streak: 0,
        switched: false,
    };
    let mut dropped: Vec<usize> = Vec::new();
    let mut stored: Vec<f64> = Vec::new();
    for (i, &s) in stream.iter().enumerate() {
        let (r0, a0) = (rot.m, adr.m);
        if i < learn {
            stored.push(s);
            if i + 1 == learn {
                rot.learn_end(&stored, if matches!(kind, Kind::Rot) { cap } else { None });
                adr.learn_end(&stored);
                sw.after_sample(kind, &rot, &adr, rot.m != r0 || adr.m != a0);
            }
        } else if s > 0.0 {
            let l = s.ln();
            rot.push(l, if matches!(kind, Kind::Rot) { cap } else { None });
            if !sw.switched {
                adr.push(l);
            }
            sw.after_sample(kind, &rot, &adr, rot.m != r0 || adr.m != a0);
        }
        est.push(s);
        let n = i + 1;
        if n < learn {
            continue; // reads during learning (as if it ended now) are checked elsewhere
        }
        let m = match kind {
            Kind::Rot => rot.m,
            Kind::Adr => adr.m,
            Kind::Hybrid { .. } => sw.m_h,
        };
        // The cap: keep the `k` smallest delayed samples, dropping the largest for good
        // whenever one too many is delayed.
        if let Some(k) = cap {
            let mut delayed: Vec<usize> = (0..n)
                .filter(|j| !dropped.contains(j))
                .filter(|&j| stream[j] > 0.0 && stream[j].ln() > m)
                .collect();
            while delayed.len() > k {
                let worst = *delayed
                    .iter()
                    .max_by(|&&a, &&b| stream[a].total_cmp(&stream[b]))
                    .unwrap();
                dropped.push(worst);
                delayed.retain(|&j| j != worst);
            }
        }
        let accepted: Vec<f64> = (0..n)
            .filter(|j| !dropped.contains(j))
            .map(|j| stream[j])
            .filter(|&x| x == 0.0 || x.ln() <= m)
            .collect();
        let want = if accepted.is_empty() {
            0.0
        } else {
            accepted.iter().sum::<f64>() / accepted.len() as f64
        };
        let x = est.extras();
        assert_eq!(
            extra(&x, "m"),
            Some(&Extra::Float(m)),
            "{est} at {i}: m; {stream:?}"
        );
        let delayed = n - accepted.len() - dropped.len();
        assert_eq!(
            int(&x, "delayed"),
            delayed as u64,
            "{est} at {i}: delayed; {stream:?}"
        );
        if cap.is_some() {
            assert_eq!(
                int(&x, "dropped"),
                dropped.len() as u64,
                "{est} at {i}: {stream:?}"
            );
        }
        assert!(
            close(est.estimate().unwrap(), want, 1e-12),
            "{est} at {i}: estimate; {stream:?}"
        );
        if matches!(kind, Kind::Adr | Kind::Hybrid { .. }) && !sw.switched {
            let want_modes =
                adr.modes.iter().fold(
                    (0, 0),
                    |(s, e), m| {
                        if m.2 >= 2 { (s, e + 1) } else { (s + 1, e) }
                    },
                );
            let got = (int(&x, "modes_single"), int(&x, "modes_extended"));
            assert_eq!(got, want_modes, "{est} at {i}: modes; {stream:?}");
        }
        if let Kind::Hybrid { .. } = kind {
            let want = Some(&Extra::Bool(sw.switched));
            assert_eq!(extra(&x, "switched"), want, "{est} at {i}");
            assert_eq!(
                extra(&x, "m_rot"),
                Some(&Extra::Float(rot.m)),
                "{est} at {i}"
            );
        }
    }
}
