//! Unit tests of the Pajot internals: the runs, the kept list, ROT's overlap search and ADR's
//! implicit point set, each against a literal computation.

use super::adr::reference::with_reference;
use super::adr::{Adr, PajotMode, adr_bandwidths};
use super::ledger::Ledger;
use super::rot::Rot;
use super::{PajotAdr, PajotHybrid, for_each_run, sorted_with_logs};
use crate::Estimator;
use proptest::prelude::*;

/// splitmix64: a deterministic stream for the randomised checks (no RNG crate in this module).
struct Mix(u64);

impl Mix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [a, b), rounded to 2 decimals like a hand-written fixture.
    fn uniform(&mut self, a: f64, b: f64) -> f64 {
        let u = (self.next() >> 11) as f64 / (1u64 << 53) as f64;
        ((a + (b - a) * u) * 100.0).round() / 100.0
    }

    fn pick<T: Copy>(&mut self, xs: &[T]) -> T {
        xs[(self.next() % xs.len() as u64) as usize]
    }
}

#[test]
fn runs_split_where_neighbours_do_not_link() {
    let xs = [1.0, 2.0, 3.0, 10.0, 11.0, 20.0];
    let mut runs = Vec::new();
    for_each_run(
        &xs,
        |i| xs[i + 1] - xs[i] < 1.5,
        |lo, hi, c| runs.push((lo, hi, c)),
    );
    assert_eq!(runs, vec![(1.0, 3.0, 3), (10.0, 11.0, 2), (20.0, 20.0, 1)]);
    let mut none = Vec::new();
    for_each_run(&[], |_| true, |lo, hi, c| none.push((lo, hi, c)));
    assert!(none.is_empty());
}

#[test]
fn ledger_keeps_sorted_and_releases_up_to_the_bound() {
    let mut l = Ledger::new(usize::MAX);
    for s in [50.0, 5.0, 500.0, 20.0] {
        l.place(s, s.ln(), 1.0, 1.0);
    }
    assert_eq!(l.kept(), &[5.0, 20.0, 50.0, 500.0]);
    assert_eq!((l.delayed(), l.accepted()), (4, 0));
    l.settle(30f64.ln(), 30f64.ln());
    assert_eq!(l.kept(), &[50.0, 500.0]);
    assert_eq!((l.delayed(), l.accepted(), l.mean()), (2, 2, 12.5));
    // Hybrid use: bound above floor keeps accepted overlap points in the prefix.
    let mut l = Ledger::new(usize::MAX);
    let (bound, floor) = (100f64.ln(), 10f64.ln());
    for s in [50.0, 5.0, 500.0, 20.0] {
        l.place(s, s.ln(), bound, floor);
    }
    assert_eq!(l.kept(), &[20.0, 50.0, 500.0], "5 is below the floor");
    assert_eq!((l.delayed(), l.accepted()), (1, 3));
    l.settle(bound, 60f64.ln());
    assert_eq!(l.kept(), &[500.0]);
    assert_eq!((l.delayed(), l.accepted()), (1, 3));
}

#[test]
fn ledger_cap_drops_largest_delayed_or_forgets_an_accepted_point() {
    let mut l = Ledger::new(2);
    for s in [50.0, 5.0, 500.0] {
        l.place(s, s.ln(), 1.0, 1.0);
    }
    assert_eq!(l.kept(), &[5.0, 50.0]);
    assert_eq!(l.dropped(), 1);
    // Every kept entry accepted (hybrid): the largest is forgotten, not dropped.
    let mut l = Ledger::new(1);
    l.place(20.0, 20f64.ln(), 100f64.ln(), 1.0);
    l.place(30.0, 30f64.ln(), 100f64.ln(), 1.0);
    assert_eq!(l.kept(), &[20.0]);
    assert_eq!((l.dropped(), l.accepted(), l.delayed()), (0, 2, 0));
}

#[test]
fn ledger_gives_memory_back_after_a_large_release() {
    let mut l = Ledger::new(usize::MAX);
    for i in 0..1000 {
        let s = 10.0 + i as f64;
        l.place(s, s.ln(), 0.0, 0.0);
    }
    let before = l.heap_bytes();
    l.settle(1005f64.ln(), 1005f64.ln());
    assert_eq!(l.delayed(), 4);
    assert!(
        l.heap_bytes() * 8 < before,
        "{} vs {before}",
        l.heap_bytes()
    );
}

/// ROT's binary search over the kept list equals a scan of every point.
#[test]
fn rot_update_matches_a_scan() {
    let mut rng = Mix(7);
    for _ in 0..20_000 {
        let mut rot = Rot::NEW;
        for _ in 0..(2 + rng.next() % 20) {
            rot.observe(rng.uniform(-3.0, 3.0));
        }
        let m = if rng.next() % 4 == 0 {
            f64::NEG_INFINITY
        } else {
            rng.uniform(-2.0, 2.0)
        };
        rot.m = m;
        let mut kept: Vec<f64> = (0..rng.next() % 8)
            .map(|_| rng.uniform(m.max(-2.0), 4.0).exp())
            .filter(|s| s.ln() > m)
            .collect();
        kept.sort_by(f64::total_cmp);
        let options = [rng.uniform(-3.0, 5.0), kept.first().map_or(0.0, |s| s.ln())];
        let l = rng.pick(&options);
        rot.observe(l);
        let w = 2.0 * rot.bandwidth();
        let hit = |q: f64| q == l || (q - l).abs() < w;
        let mut want = m;
        if l > m {
            let qs: Vec<f64> = kept
                .iter()
                .map(|s| s.ln())
                .chain(Some(m).filter(|m| m.is_finite()))
                .filter(|&q| hit(q))
                .collect();
            if !qs.is_empty() {
                want = qs.into_iter().fold(l, f64::max);
            }
        }
        let changed = rot.update(l, &kept);
        assert_eq!(rot.m, want, "l = {l}, m = {m}, kept = {kept:?}");
        assert_eq!(changed, want != m);
    }
}

#[test]
fn mode_points_follow_the_spec_formula() {
    let m = PajotMode {
        lo: 1.0,
        hi: 2.0,
        count: 5,
    };
    assert_eq!(
        m.points().collect::<Vec<_>>(),
        vec![1.0, 1.25, 1.5, 1.75, 2.0]
    );
    let single = PajotMode {
        lo: 3.0,
        hi: 3.0,
        count: 1,
    };
    assert_eq!(single.points().collect::<Vec<_>>(), vec![3.0]);
    assert!(!single.is_extended() && m.is_extended());
}

#[test]
fn adr_bandwidths_degenerate_sets_are_zero() {
    assert!(adr_bandwidths(&[]).is_empty());
    assert_eq!(adr_bandwidths(&[1.0]), vec![0.0]);
    assert_eq!(adr_bandwidths(&[2.0, 2.0, 2.0]), vec![0.0; 3], "nn = 0");
    // Two points: nn = their distance, p = 1 each, g = 1: h = nn.
    assert_eq!(adr_bandwidths(&[0.0, 3.0]), vec![3.0, 3.0]);
}

/// The eq. 4 pilot with an O(K^2) sum, to check the sliding window.
fn eq4_quadratic(xs: &[f64]) -> Vec<f64> {
    let k = xs.len();
    let nn = (0..k)
        .map(|i| {
            (0..k)
                .filter(|&j| j != i)
                .map(|j| (xs[i] - xs[j]).abs())
                .fold(f64::INFINITY, f64::min)
        })
        .sum::<f64>()
        / k as f64;
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

#[test]
fn adr_bandwidths_window_matches_quadratic_sum() {
    let mut rng = Mix(11);
    for _ in 0..2000 {
        let mut xs: Vec<f64> = (0..2 + rng.next() % 40)
            .map(|_| rng.uniform(-5.0, 5.0))
            .collect();
        xs.sort_by(f64::total_cmp);
        if xs.windows(2).all(|w| w[0] == w[1]) {
            continue;
        }
        for (a, b) in adr_bandwidths(&xs).iter().zip(eq4_quadratic(&xs)) {
            assert!((a - b).abs() <= 1e-12 * b.abs(), "{a} vs {b} for {xs:?}");
        }
    }
}

fn random_modes(rng: &mut Mix) -> Vec<PajotMode> {
    let n = 1 + rng.next() % 5;
    let mut edges: Vec<f64> = (0..2 * n).map(|_| rng.uniform(0.0, 8.0)).collect();
    edges.sort_by(f64::total_cmp);
    let mut modes = Vec::new();
    for pair in edges.chunks(2) {
        let c = rng.pick(&[1, 2, 3, 5, 10, 40, 300]);
        let hi = if c == 1 || rng.next() % 10 == 0 {
            pair[0]
        } else {
            pair[1]
        };
        if modes.last().is_some_and(|m: &PajotMode| m.hi >= pair[0]) {
            continue;
        }
        modes.push(PajotMode {
            lo: pair[0],
            hi,
            count: c,
        });
    }
    modes
}

/// ADR's implicit point set makes the same overlap decisions as the materialised one. Near
/// ties (|distance - (h_l + h_x)| within 1e-9) are skipped: the two differ by rounding there.
#[test]
fn adr_implicit_point_set_matches_materialised() {
    let mut rng = Mix(3);
    let (mut compared, mut merged) = (0, 0);
    for _ in 0..60_000 {
        let modes = random_modes(&mut rng);
        let options = [
            rng.uniform(-1.0, 9.0),
            modes[0].lo,
            modes[modes.len() - 1].hi,
        ];
        let l = rng.pick(&options);
        let i = modes.partition_point(|m| m.hi < l);
        if modes.get(i).is_some_and(|m| m.is_extended() && m.lo <= l) {
            continue;
        }
        let adr = Adr::with_modes(&modes, f64::NEG_INFINITY);
        // Skip near ties of the literal computation.
        let mut xs: Vec<f64> = modes
            .iter()
            .flat_map(|m| m.points().collect::<Vec<_>>())
            .collect();
        xs.push(l);
        xs.sort_by(f64::total_cmp);
        let h = adr_bandwidths(&xs);
        let me = xs.iter().position(|&x| x == l).unwrap();
        let tie = (0..xs.len())
            .filter(|&j| xs[j] != l)
            .any(|j| ((l - xs[j]).abs() - (h[me] + h[j])).abs() < 1e-9);
        let me_last = xs.iter().rposition(|&x| x == l).unwrap();
        if tie || me != me_last {
            continue;
        }
        let want = adr.overlapped_naive(l, i);
        assert_eq!(adr.overlapped(l, i), want, "l = {l}, modes = {modes:?}");
        compared += 1;
        merged += usize::from(want.is_some());
    }
    assert!(
        compared > 12_000 && merged > 3_000,
        "{compared} compared, {merged} merged"
    );
}

/// Spec decision 7's other half: a mode inside the merged span is absorbed even when the
/// newcomer does not overlap it. Here a wide two-point mode reaches the newcomer across a
/// dense mode whose narrow kernels it misses (found by search over hand-made mode sets).
#[test]
fn adr_merge_absorbs_a_mode_it_does_not_overlap() {
    let dense = PajotMode {
        lo: 1.47,
        hi: 1.49,
        count: 40,
    };
    let wide = PajotMode {
        lo: 2.16,
        hi: 7.61,
        count: 2,
    };
    let mut adr = Adr::with_modes(&[dense, wide], 7.61);
    let l = 0.32;
    assert_eq!(adr.overlapped_naive(l, 0), Some((0, 1)));
    // The newcomer overlaps only the wide mode's point 2.16:
    let mut xs: Vec<f64> = dense.points().chain(wide.points()).collect();
    xs.insert(0, l);
    let h = adr_bandwidths(&xs);
    assert!(
        xs[1..41]
            .iter()
            .zip(&h[1..41])
            .all(|(x, hx)| (x - l).abs() >= h[0] + hx)
    );
    assert!(xs[41] - l < h[0] + h[41]);
    assert!(!adr.update(l), "m unchanged");
    assert_eq!(
        adr.public_modes(),
        vec![PajotMode {
            lo: l,
            hi: 7.61,
            count: 43
        }]
    );
}

#[test]
fn adr_update_inside_an_extended_mode_only_counts() {
    let mut adr = Adr::with_modes(
        &[PajotMode {
            lo: 0.0,
            hi: 1.0,
            count: 3,
        }],
        1.0,
    );
    for l in [0.0, 0.5, 1.0] {
        assert!(!adr.update(l));
    }
    assert_eq!(adr.modes[0].count, 6);
    // Equal to a single: identical values overlap even with h = 0, forming an extended mode.
    let mut adr = Adr::with_modes(
        &[PajotMode {
            lo: 2.0,
            hi: 2.0,
            count: 1,
        }],
        f64::NEG_INFINITY,
    );
    assert!(adr.update(2.0));
    assert_eq!(adr.m, 2.0);
    assert_eq!(
        adr.public_modes(),
        vec![PajotMode {
            lo: 2.0,
            hi: 2.0,
            count: 2
        }]
    );
}

/// Heavy-tailed log-luminances with ties: a lognormal body, exact repeats, values one ulp apart,
/// a Pareto tail, and the extremes `ln 1e-300`, `ln 1e300`.
fn hard_log(rng: &mut Mix, repeats: &[f64]) -> f64 {
    let u = |rng: &mut Mix| ((rng.next() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    match rng.next() % 16 {
        0..=6 => {
            // Box-Muller normal
            let (a, b) = (u(rng), u(rng));
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        }
        7..=9 => rng.pick(repeats),
        10 => f64::from_bits(rng.pick(repeats).to_bits() + 1 + rng.next() % 3),
        11 | 12 => 3.0 - u(rng).ln() / 1.1,
        13 => 1e-300f64.ln(),
        14 => 1e300f64.ln(),
        _ => rng.uniform(-3.0, 3.0),
    }
}

/// ADR's fast overlap search equals the first implicit form bit for bit (no tie is skipped),
/// on random mode sets and on the modes of heavy-tailed streams.
#[test]
fn adr_overlapped_equals_reference() {
    let mut rng = Mix(5);
    let mut merged = 0;
    for _ in 0..60_000 {
        let modes = random_modes(&mut rng);
        let options = [
            rng.uniform(-1.0, 9.0),
            modes[0].lo,
            modes[modes.len() - 1].hi,
            rng.pick(&modes).hi,
            rng.pick(&modes).lo,
        ];
        let l = rng.pick(&options);
        let i = modes.partition_point(|m| m.hi < l);
        if modes.get(i).is_some_and(|m| m.is_extended() && m.lo <= l) {
            continue;
        }
        let adr = Adr::with_modes(&modes, f64::NEG_INFINITY);
        let want = adr.overlapped_ref(l, i);
        assert_eq!(adr.overlapped(l, i), want, "l = {l}, modes = {modes:?}");
        merged += usize::from(want.is_some());
    }
    assert!(merged > 8_000, "{merged} merged");
}

/// Whole streams: ADR through the fast search and through the reference end with the same
/// modes and bound after every sample, on heavy-tailed streams with ties and extremes.
#[test]
fn adr_updates_equal_reference_on_hard_streams() {
    let mut rng = Mix(17);
    let mut calls = 0u64;
    for round in 0..400 {
        let repeats: Vec<f64> = (0..4).map(|_| hard_log(&mut rng, &[0.0])).collect();
        let learn = rng.next() % 60;
        let n = 50 + rng.next() % 700;
        let mut logs: Vec<f64> = (0..n).map(|_| hard_log(&mut rng, &repeats)).collect();
        if round % 4 == 0 {
            // Scale like a far-off pixel: the same decisions up to rounding, new roundings.
            let (a, b) = (rng.uniform(0.01, 40.0), rng.uniform(-300.0, 300.0));
            logs.iter_mut().for_each(|l| *l = a * *l + b);
        }
        let (learning, rest) = logs.split_at(learn.min(n) as usize);
        let mut sorted = learning.to_vec();
        sorted.sort_by(f64::total_cmp);
        let (mut fast, mut slow) = (Adr::NEW, Adr::NEW);
        assert_eq!(fast.learn_end(&sorted), slow.learn_end(&sorted));
        for &l in rest {
            let before = fast.modes.len();
            assert_eq!(fast.update(l), slow.update_ref(l));
            assert_eq!(
                fast.public_modes(),
                slow.public_modes(),
                "round {round}, l = {l}"
            );
            assert_eq!(fast.m.to_bits(), slow.m.to_bits());
            calls += u64::from(fast.modes.len() != before);
        }
    }
    assert!(calls > 4_000, "{calls} searches changed the modes");
}

/// Heavy-tailed samples with ties: a lognormal body, a Pareto tail, black samples, repeated
/// values and their neighbours one ulp away, and the extremes 1e-300 and 1e300.
fn hard_samples(max_len: usize) -> impl Strategy<Value = Vec<f64>> {
    let tie = 2f64;
    prop::collection::vec(
        prop_oneof![
            8 => (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0)
                .prop_map(|(a, b, c)| (2.0 * (a + b + c) - 3.0).exp()),
            2 => (0.0f64..1.0).prop_map(|u| 1e3 * (1.0 - u).powf(-1.0 / 1.1)),
            2 => Just(0.0),
            2 => prop::sample::select(vec![0.5, tie, 7.25]),
            1 => prop::sample::select(vec![
                f64::from_bits(tie.to_bits() + 1),
                f64::from_bits(tie.to_bits() - 1),
            ]),
            1 => prop::sample::select(vec![1e-300, 1e300, f64::MIN_POSITIVE, 1.0]),
        ],
        0..max_len,
    )
}

/// Pushes `stream` into `fast` and, through the first implementation of ADR's update, into
/// `slow` (built alike); after every sample the two agree bit for bit on everything they
/// report.
fn check_same(mut fast: Box<dyn Estimator>, mut slow: Box<dyn Estimator>, stream: &[f64]) {
    let bits = |e: &dyn Estimator| e.estimate().ok().map(f64::to_bits);
    for (j, &s) in stream.iter().enumerate() {
        fast.push(s);
        with_reference(|| slow.push(s));
        assert_eq!(
            bits(&*fast),
            bits(&*slow),
            "{fast} estimate at {j}: {stream:?}"
        );
        assert_eq!(
            format!("{:?}", fast.extras()),
            format!("{:?}", slow.extras()),
            "{fast} extras at {j}: {stream:?}"
        );
        assert_eq!(fast.state_bytes(), slow.state_bytes(), "{fast} at {j}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// ADR and the hybrid with the faster search report exactly what they did with the first
    /// one, on heavy-tailed streams (ties, black samples, extremes), with and without a cap.
    #[test]
    fn estimators_equal_first_implementation(stream in hard_samples(700), learn in 0usize..60,
                                             t in 1usize..4, cap in 0usize..6) {
        let adr = || PajotAdr::new(learn).unwrap();
        check_same(Box::new(adr()), Box::new(adr()), &stream);
        check_same(
            Box::new(adr().with_max_delayed(cap)),
            Box::new(adr().with_max_delayed(cap)),
            &stream,
        );
        let hybrid = || PajotHybrid::new(learn, t, 0.0).unwrap();
        check_same(Box::new(hybrid()), Box::new(hybrid()), &stream);
        let hybrid = || PajotHybrid::new(learn, t, 0.05).unwrap().with_max_delayed(cap);
        check_same(Box::new(hybrid()), Box::new(hybrid()), &stream);
    }

    /// The learning phase's sorting: the logs of the sorted samples are the sorted logs.
    #[test]
    fn sorted_logs_equal_logs_sorted(stream in hard_samples(80)) {
        let values: Vec<f64> = stream.into_iter().filter(|&s| s > 0.0).collect();
        let mut logs: Vec<f64> = values.iter().map(|s| s.ln()).collect();
        logs.sort_by(f64::total_cmp);
        let (_, got) = sorted_with_logs(values, None);
        prop_assert_eq!(
            got.iter().map(|l| l.to_bits()).collect::<Vec<_>>(),
            logs.iter().map(|l| l.to_bits()).collect::<Vec<_>>()
        );
    }
}
