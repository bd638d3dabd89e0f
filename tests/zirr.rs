//! Zirr et al.'s cascade reweighting (docs/estimators.md §5 `zirr`, §5a `zirr-ref`): the spec's worked
//! examples reproduced to 1e-12, hand-computed 3×3 neighbourhoods, hard inputs, error messages,
//! a literal transcription of the spec as an independent oracle (bit-for-bit), and property
//! tests of the invariants.

use fireflies::estimators::{
    CascadeSize, Estimator, EstimatorSpec, Extra, Extras, Neumaier, Zirr, ZirrParams, ZirrSpec,
};
use proptest::prelude::*;

/// docs/estimators.md §1 running example.
const RUNNING: [f64; 7] = [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1];
/// docs/estimators.md §5 example estimate (b = 8, J = 6 or auto, κ = κ_min = u = 1).
const PAPER_ESTIMATE: f64 = 5.191836734693878;
/// docs/estimators.md §5a example estimate.
const REF_ESTIMATE: f64 = 5.616560523284569;
/// docs/estimators.md §5 3×3 example estimate, 13.2/7.
const BLOCK_ESTIMATE: f64 = 1.8857142857142857;

// Exact buffers of the running example (docs/estimators.md §5), in units of A_j = N·B_j:
// 0.6, 0 -> A_0; 1.5 -> 13/14 + 4/7; 2.2 -> 29/35 + 48/35; 4.8 -> 16/35 + 152/35;
// 4.1 -> 39/70 + 124/35; 350 -> 162/7 (buffer 2) + 2288/7 (buffer 3).
const A0: f64 = 236.0 / 70.0;
const A1: f64 = 344.0 / 35.0;
const A2: f64 = 162.0 / 7.0;
const A3: f64 = 2288.0 / 7.0;
// Counts n_j = A_{j−1}/c_{j−1} + A_j/c_j + A_{j+1}/c_{j+1}.
const N_RUNNING: [f64; 6] = [
    4.6,
    4.6 + 81.0 / 224.0,
    78.0 / 35.0,
    1.0,
    143.0 / 224.0,
    0.0,
];

fn params(j: CascadeSize) -> ZirrParams {
    ZirrParams {
        j,
        ..ZirrParams::PAPER
    }
}

fn fixed(j: usize) -> ZirrParams {
    params(CascadeSize::Fixed(j))
}

fn zirr(p: ZirrParams, xs: &[f64]) -> Zirr {
    let mut z = Zirr::new(p).expect("valid zirr params");
    z.push_slice(xs);
    z
}

fn zirr_ref(p: ZirrParams, xs: &[f64]) -> Zirr {
    let mut z = Zirr::reference(p).expect("valid zirr-ref params");
    z.push_slice(xs);
    z
}

fn floats(e: &Extras, key: &str) -> Vec<f64> {
    match e.iter().find(|(k, _)| *k == key) {
        Some((_, Extra::Floats(v))) => v.clone(),
        other => panic!("extra {key} is not Floats: {other:?}"),
    }
}

fn int(e: &Extras, key: &str) -> u64 {
    match e.iter().find(|(k, _)| *k == key) {
        Some((_, Extra::Int(v))) => *v,
        other => panic!("extra {key} is not Int: {other:?}"),
    }
}

fn float(e: &Extras, key: &str) -> f64 {
    match e.iter().find(|(k, _)| *k == key) {
        Some((_, Extra::Float(v))) => *v,
        other => panic!("extra {key} is not Float: {other:?}"),
    }
}

#[track_caller]
fn assert_rel(got: f64, want: f64, rel: f64) {
    let ok = got == want || (got - want).abs() <= rel * got.abs().max(want.abs());
    assert!(
        ok,
        "got {got:e}, want {want:e} (relative tolerance {rel:e})"
    );
}

#[track_caller]
fn assert_all_rel(got: &[f64], want: &[f64], rel: f64) {
    assert_eq!(got.len(), want.len(), "got {got:?}, want {want:?}");
    for (g, w) in got.iter().zip(want) {
        let ok = g == w || (g - w).abs() <= rel * g.abs().max(w.abs()).max(1e-300);
        assert!(ok, "got {got:?}, want {want:?}");
    }
}

fn err(p: ZirrParams) -> String {
    Zirr::new(p).expect_err("must be rejected").to_string()
}

fn err_ref(p: ZirrParams) -> String {
    Zirr::reference(p)
        .expect_err("must be rejected")
        .to_string()
}

// ---------------------------------------------------------------------------------------------
// docs/estimators.md §5 and §5a worked examples.

#[test]
fn spec_5_example_fixed_cascade() {
    let z = zirr(fixed(6), &RUNNING);
    let e = z.extras();
    let keys: Vec<&str> = e.iter().map(|(k, _)| *k).collect();
    assert_eq!(keys, ["J_used", "over_range", "B", "counts", "rho", "w"]);
    assert_eq!(int(&e, "J_used"), 6);
    assert_eq!(int(&e, "over_range"), 0);
    let b = floats(&e, "B");
    let want_b: Vec<f64> = [A0, A1, A2, A3, 0.0, 0.0].iter().map(|a| a / 7.0).collect();
    assert_all_rel(&b, &want_b, 1e-12);
    // The printed values of docs/estimators.md §5.
    let a: Vec<f64> = b.iter().map(|b| b * 7.0).collect();
    for (x, w) in a
        .iter()
        .zip([3.371429, 9.828571, 23.142857, 326.857143, 0.0, 0.0])
    {
        assert!((x - w).abs() < 5e-7, "A = {a:?}");
    }
    assert_all_rel(&floats(&e, "counts"), &N_RUNNING, 1e-12);
    assert_eq!(floats(&e, "rho"), floats(&e, "counts"));
    assert_eq!(floats(&e, "w"), [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]);
    assert_rel(z.estimate().unwrap(), PAPER_ESTIMATE, 1e-12);
    assert_rel(PAPER_ESTIMATE, (A0 + A1 + A2) / 7.0, 1e-15);
    // The invariant: the buffers sum to the mean 363.2/7.
    assert_rel(b.iter().sum::<f64>(), 363.2 / 7.0, 1e-12);
}

#[test]
fn spec_5_example_auto_cascade_has_four_buffers_and_same_numbers() {
    let fixed6 = zirr(fixed(6), &RUNNING).extras();
    let z = zirr(ZirrParams::PAPER, &RUNNING);
    let e = z.extras();
    assert_eq!(int(&e, "J_used"), 4);
    assert_eq!(int(&e, "over_range"), 0);
    for key in ["B", "counts", "rho", "w"] {
        assert_eq!(floats(&e, key), floats(&fixed6, key)[..4], "{key}");
    }
    assert_eq!(
        z.estimate().unwrap(),
        zirr(fixed(6), &RUNNING).estimate().unwrap()
    );
    assert_rel(z.estimate().unwrap(), PAPER_ESTIMATE, 1e-12);
}

#[test]
fn spec_5_splat_of_350_uses_buffer_2_with_a_0_066122() {
    let e = zirr(fixed(6), &[350.0]).extras();
    let b = floats(&e, "B");
    let a = 1296.0 / 19600.0;
    assert!((a - 0.066122_f64).abs() < 5e-7);
    assert_all_rel(
        &b,
        &[0.0, 0.0, a * 350.0, 350.0 - a * 350.0, 0.0, 0.0],
        1e-12,
    );
    // eqs. 17–18: a lone split sample adds exactly 1 to both counts it touches.
    let n = floats(&e, "counts");
    assert_rel(n[2], 1.0, 1e-15);
    assert_rel(n[3], 1.0, 1e-15);
}

/// Eight neighbours with seven samples of 1.0 each: `n = (7, 7, 0, …)`.
fn ones() -> Vec<f64> {
    vec![1.0; 7]
}

#[test]
fn spec_5_three_by_three_example() {
    for p in [fixed(6), ZirrParams::PAPER] {
        let centre = zirr(p, &RUNNING);
        let neighbour = zirr(p, &ones());
        assert_eq!(floats(&neighbour.extras(), "counts")[..2], [7.0, 7.0]);
        let mut block = [Some(&neighbour); 9];
        block[4] = Some(&centre);
        let (est, e) = Zirr::block_estimate(&block).unwrap();
        assert_rel(est, BLOCK_ESTIMATE, 1e-12);
        assert_rel(est, 13.2 / 7.0, 1e-12);
        let len = if p.j == CascadeSize::Auto { 4 } else { 6 };
        assert_eq!(int(&e, "J_used"), len as u64);
        let rho = floats(&e, "rho");
        let want = [
            (56.0 + N_RUNNING[0]) / 9.0,
            (56.0 + N_RUNNING[1]) / 9.0,
            N_RUNNING[2] / 9.0,
            N_RUNNING[3] / 9.0,
            N_RUNNING[4] / 9.0,
            0.0,
        ];
        assert_all_rel(&rho, &want[..len], 1e-12);
        // Printed values of docs/estimators.md §5.
        for (r, w) in rho.iter().zip([6.733, 6.774, 0.248, 0.111, 0.071, 0.0]) {
            assert!((r - w).abs() < 5e-4, "rho = {rho:?}");
        }
        assert_eq!(floats(&e, "w"), [1.0, 1.0, 0.0, 0.0, 0.0, 0.0][..len]);
        // The centre's own buffers and counts are reported unchanged.
        assert_eq!(floats(&e, "counts"), floats(&centre.extras(), "counts"));
        assert_eq!(floats(&e, "B"), floats(&centre.extras(), "B"));
    }
}

#[test]
fn spec_5a_example() {
    let z = zirr_ref(ZirrParams::REFERENCE, &RUNNING);
    let e = z.extras();
    let keys: Vec<&str> = e.iter().map(|(k, _)| *k).collect();
    assert_eq!(
        keys,
        [
            "J_used",
            "over_range",
            "B",
            "counts",
            "rho",
            "w",
            "discarded"
        ]
    );
    // Same buffers and counts as §5.
    let paper = zirr(fixed(6), &RUNNING).extras();
    assert_eq!(floats(&e, "B"), floats(&paper, "B"));
    assert_eq!(floats(&e, "counts"), floats(&paper, "counts"));
    assert_all_rel(
        &floats(&e, "w"),
        &[1.0, 1.0, 0.7174107142857143, 0.02910442741549745, 0.0, 0.0],
        1e-12,
    );
    assert_rel(z.estimate().unwrap(), REF_ESTIMATE, 1e-12);
    assert_eq!(float(&e, "discarded"), 0.0);
    // w_2 by hand: (n_2 − 1 + (13.2/7)·7/64)/2.
    assert_rel(floats(&e, "w")[2], (43.0 / 35.0 + 13.2 / 64.0) / 2.0, 1e-12);
}

#[test]
fn running_example_with_any_chunking_is_bit_identical() {
    let whole = zirr(ZirrParams::PAPER, &RUNNING);
    let mut one_by_one = Zirr::new(ZirrParams::PAPER).unwrap();
    RUNNING.iter().for_each(|&x| one_by_one.push(x));
    let mut chunks = Zirr::new(ZirrParams::PAPER).unwrap();
    RUNNING.chunks(3).for_each(|c| chunks.push_slice(c));
    assert_eq!(whole.extras(), one_by_one.extras());
    assert_eq!(whole.extras(), chunks.extras());
    let whole = zirr_ref(ZirrParams::REFERENCE, &RUNNING);
    let mut one_by_one = Zirr::reference(ZirrParams::REFERENCE).unwrap();
    RUNNING.iter().for_each(|&x| one_by_one.push(x));
    assert_eq!(whole.extras(), one_by_one.extras());
}

// ---------------------------------------------------------------------------------------------
// Consequence (i): a fixed cascade lets the largest fireflies through.

#[test]
fn consequence_i_fixed_cascade_passes_the_firefly_auto_rejects_it() {
    let mut xs = vec![1.0; 99];
    xs.push(4e4);
    let z6 = zirr(fixed(6), &xs);
    let e6 = z6.extras();
    assert_eq!(int(&e6, "over_range"), 1);
    let est6 = z6.estimate().unwrap();
    assert_eq!(format!("{est6:.2}"), "89.27");
    // By hand: the top buffer counts 4e4/32768 = 1.2207 > 1, so w_5 = n_5 − 1 = 0.220703125.
    assert_rel(est6, 0.99 + (4e4 / 32768.0 - 1.0) * 400.0, 1e-12);

    let auto = zirr(ZirrParams::PAPER, &xs);
    let e = auto.extras();
    assert_eq!(int(&e, "over_range"), 0);
    assert_eq!(int(&e, "J_used"), 7); // 8^5 ≤ 4e4 < 8^6: buffers 0..=6.
    assert_eq!(format!("{:.2}", auto.estimate().unwrap()), "0.99");
    assert_rel(auto.estimate().unwrap(), 0.99, 1e-12);

    // zirr-ref clamps the firefly at c_5 = 32768 and reports the rest as discarded.
    let r = zirr_ref(ZirrParams::REFERENCE, &xs);
    let er = r.extras();
    assert_eq!(int(&er, "over_range"), 1);
    assert_rel(float(&er, "discarded"), (4e4 - 32768.0) / 100.0, 1e-12);
    let sum: f64 = floats(&er, "B").iter().sum();
    assert_rel(sum + float(&er, "discarded"), (99.0 + 4e4) / 100.0, 1e-12);
}

// ---------------------------------------------------------------------------------------------
// Neighbourhoods.

#[test]
fn zirr_block_leaves_out_missing_and_empty_pixels() {
    let centre = zirr(fixed(6), &RUNNING);
    let neighbour = zirr(fixed(6), &ones());
    let empty = Zirr::new(fixed(6)).unwrap();
    // Only the centre has samples: the block estimate is the lone estimate.
    let mut block = [None; 9];
    block[4] = Some(&centre);
    block[0] = Some(&empty);
    let (est, e) = Zirr::block_estimate(&block).unwrap();
    assert_eq!(est, centre.estimate().unwrap());
    assert_eq!(e, centre.extras());
    // One neighbour with samples, one empty, the rest outside: ρ = (n_centre + n_P)/2.
    block[8] = Some(&neighbour);
    let (est, e) = Zirr::block_estimate(&block).unwrap();
    let want: Vec<f64> = N_RUNNING
        .iter()
        .zip([7.0, 7.0, 0.0, 0.0, 0.0, 0.0])
        .map(|(c, p)| (c + p) / 2.0)
        .collect();
    assert_all_rel(&floats(&e, "rho"), &want, 1e-12);
    // ρ_2 = 1.114 > 1 lets buffer 2 through as in the lone pixel; ρ_3 = 0.5 rejects buffer 3.
    assert_eq!(floats(&e, "w"), [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]);
    assert_rel(est, PAPER_ESTIMATE, 1e-12);
}

/// Seven samples of 2.0: buffers `A = (6, 8)`, counts `(7, 7, 1, 0, …)`.
fn twos() -> Vec<f64> {
    vec![2.0; 7]
}

#[test]
fn zirr_block_does_not_depend_on_how_far_a_neighbour_cascade_grew() {
    // Neighbours with seven 2.0 samples have J_used = 2 with `auto`, yet count
    // n_2 = N·B_1/c_1 = 8/8 = 1 one buffer past their top, exactly as with a fixed J = 6.
    let mut results = Vec::new();
    for p in [ZirrParams::PAPER, fixed(6), fixed(40)] {
        let centre = zirr(p, &RUNNING);
        let neighbour = zirr(p, &twos());
        let mut block = [Some(&neighbour); 9];
        block[4] = Some(&centre);
        let (est, e) = Zirr::block_estimate(&block).unwrap();
        let rho = floats(&e, "rho");
        assert_rel(rho[2], (N_RUNNING[2] + 8.0) / 9.0, 1e-12);
        assert_rel(rho[3], 1.0 / 9.0, 1e-12);
        results.push(est);
    }
    assert_rel(results[0], PAPER_ESTIMATE, 1e-12);
    assert_eq!(results[0], results[1]);
    assert_eq!(results[0], results[2]);
}

#[test]
fn zirr_ref_block_interior_matches_lone_pixel_when_neighbours_equal_centre() {
    let centre = zirr_ref(ZirrParams::REFERENCE, &RUNNING);
    let block = [Some(&centre); 9];
    let (est, _) = Zirr::block_estimate(&block).unwrap();
    assert_rel(est, REF_ESTIMATE, 1e-12);
    // A lone pixel of a 1×1 image: everything clamps to the centre.
    let mut block = [None; 9];
    block[4] = Some(&centre);
    let (est, e) = Zirr::block_estimate(&block).unwrap();
    assert_rel(est, REF_ESTIMATE, 1e-12);
    assert_all_rel(&floats(&e, "rho"), &N_RUNNING, 1e-12);
}

#[test]
fn zirr_ref_block_top_left_corner_clamps_to_edge() {
    let p = ZirrParams::REFERENCE;
    let centre = zirr_ref(p, &RUNNING);
    let right = zirr_ref(p, &ones()); // offset (1, 0)
    let below = Zirr::reference(p).unwrap(); // offset (0, 1): in the image, no samples
    let diagonal = zirr_ref(p, &twos()); // offset (1, 1)
    // Row −1 and column −1 are outside the image.
    let block = [
        None,
        None,
        None,
        None,
        Some(&centre),
        Some(&right),
        None,
        Some(&below),
        Some(&diagonal),
    ];
    let (est, e) = Zirr::block_estimate(&block).unwrap();
    // Clamp-to-edge: (−1,−1), (0,−1), (−1,0) take the centre; (1,−1) takes (1,0);
    // (−1,1) takes (0,1), which counts 0. Nine = 4·centre + 2·(7,7,0..) + (7,7,1,0..) + 0 + 0.
    let want = [
        (4.0 * N_RUNNING[0] + 14.0 + 7.0) / 9.0,
        (4.0 * N_RUNNING[1] + 14.0 + 7.0) / 9.0,
        (4.0 * N_RUNNING[2] + 1.0) / 9.0,
        4.0 / 9.0,
        4.0 * N_RUNNING[4] / 9.0,
        0.0,
    ];
    assert_all_rel(&floats(&e, "rho"), &want, 1e-12);
    for (r, w) in floats(&e, "rho")
        .iter()
        .zip([4.377778, 4.538492, 1.101587, 0.444444, 0.283730, 0.0])
    {
        assert!((r - w).abs() < 1e-6);
    }
    // j = 2: ρ_2 ≥ 1, so rel = n_2 − 1 and w_2 is the lone pixel's 0.7174107142857143.
    // j = 3: ρ_3 = 4/9 < 1, so rel = −5/9 and the colour term cannot lift it: w_3 = 0.
    let w2 = (43.0 / 35.0 + 13.2 / 64.0) / 2.0;
    assert_all_rel(&floats(&e, "w"), &[1.0, 1.0, w2, 0.0, 0.0, 0.0], 1e-12);
    let want_est = 13.2 / 7.0 + w2 * A2 / 7.0;
    assert_rel(est, want_est, 1e-12);
    assert_rel(est, 4.25756195335277, 1e-12);
}

#[test]
fn zirr_ref_block_right_edge_and_empty_pixel_counts_zero() {
    let p = ZirrParams::REFERENCE;
    let centre = zirr_ref(p, &RUNNING);
    let one = zirr_ref(p, &ones());
    let empty = Zirr::reference(p).unwrap();
    // Column +1 outside the image; the pixel above the centre is in the image but empty.
    let block = [
        Some(&one),
        Some(&empty),
        None,
        Some(&one),
        Some(&centre),
        None,
        Some(&one),
        Some(&one),
        None,
    ];
    let (est, e) = Zirr::block_estimate(&block).unwrap();
    // (1,−1) takes (0,−1) = empty (0); (1,0) takes the centre; (1,1) takes (0,1).
    // Nine = 5·(7,7,0..) + 2·centre + 2·0.
    let rho = floats(&e, "rho");
    assert_rel(rho[0], (35.0 + 2.0 * N_RUNNING[0]) / 9.0, 1e-12);
    assert_rel(rho[2], 2.0 * N_RUNNING[2] / 9.0, 1e-12);
    // ρ_2 = 0.495 < 1: rel = ρ_2 − 1 = −0.505 and col = 0.20625, so w_2 = 0.
    assert_eq!(floats(&e, "w"), [1.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
    assert_rel(est, 13.2 / 7.0, 1e-12);

    // The same block with the empty pixel outside instead: (0,−1) is then missing while its
    // row and column have present pixels, so it (and (1,−1), which maps onto it) takes the
    // centre. Nine = 5·(7,7,0..) + 4·centre.
    let mut holes = block;
    holes[1] = None;
    let (est, e) = Zirr::block_estimate(&holes).unwrap();
    let rho = floats(&e, "rho");
    assert_rel(rho[2], 4.0 * N_RUNNING[2] / 9.0, 1e-12);
    let w2 = (4.0 * N_RUNNING[2] / 9.0 - 1.0 + 13.2 / 64.0) / 2.0;
    assert_rel(floats(&e, "w")[2], w2, 1e-12);
    assert_rel(est, 13.2 / 7.0 + w2 * A2 / 7.0, 1e-12);
}

#[test]
fn block_errors_name_the_problem() {
    let p = fixed(6);
    let centre = zirr(p, &RUNNING);
    let empty = Zirr::new(p).unwrap();
    let other = zirr(fixed(5), &RUNNING);

    let mut block = [Some(&centre); 9];
    block[4] = None;
    let e = Zirr::block_estimate(&block).unwrap_err().to_string();
    assert!(e.contains("block index = 4") && e.contains("centre"), "{e}");

    block[4] = Some(&empty);
    let e = Zirr::block_estimate(&block).unwrap_err().to_string();
    assert!(e.contains("empty stream") && e.contains("centre"), "{e}");

    let mut block = [Some(&centre); 9];
    block[7] = Some(&other);
    let e = Zirr::block_estimate(&block).unwrap_err().to_string();
    assert!(
        e.contains("block index = 7") && e.contains("J=5") && e.contains("J=6"),
        "{e}"
    );

    let c = zirr_ref(ZirrParams::REFERENCE, &RUNNING);
    let k32 = zirr_ref(
        ZirrParams {
            kappa: 32.0,
            ..ZirrParams::REFERENCE
        },
        &RUNNING,
    );
    let mut block = [Some(&c); 9];
    block[2] = Some(&k32);
    let e = Zirr::block_estimate(&block).unwrap_err().to_string();
    assert!(
        e.contains("block index = 2") && e.contains("kappa=32"),
        "{e}"
    );
    let mut block = [None; 9];
    block[0] = Some(&c);
    let e = Zirr::block_estimate(&block).unwrap_err().to_string();
    assert!(e.contains("block index = 4"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// Constructors, errors, display, spec round-trip, state size.

#[test]
fn parameter_errors_name_parameter_and_value() {
    let base = ZirrParams::PAPER;
    let e = err(ZirrParams { b: 1.0, ..base });
    assert!(e.contains("b = 1") && e.contains("> 1"), "{e}");
    let e = err(ZirrParams {
        b: f64::NAN,
        ..base
    });
    assert!(e.contains("b = NaN"), "{e}");
    let e = err(ZirrParams {
        b: f64::INFINITY,
        ..base
    });
    assert!(e.contains("b = inf"), "{e}");
    let e = err(ZirrParams {
        kappa: f64::NAN,
        ..base
    });
    assert!(e.contains("kappa = NaN"), "{e}");
    let e = err(ZirrParams { kappa: 0.0, ..base });
    assert!(e.contains("kappa = 0"), "{e}");
    let e = err(ZirrParams {
        kappa_min: -1.0,
        ..base
    });
    assert!(e.contains("kappa_min = -1"), "{e}");
    let e = err(ZirrParams { u: 0.0, ..base });
    assert!(e.contains("u = 0"), "{e}");
    let e = err(ZirrParams {
        u: f64::INFINITY,
        ..base
    });
    assert!(e.contains("u = inf"), "{e}");
    let e = err(fixed(0));
    assert!(e.contains("J = 0"), "{e}");
    let e = err(fixed(4097));
    assert!(e.contains("J = 4097") && e.contains("4096"), "{e}");
    // A base this close to 1 would need more than 4096 buffers to cover f64 with J = auto.
    let e = err(ZirrParams { b: 1.01, ..base });
    assert!(e.contains("b = 1.01") && e.contains("4096"), "{e}");
    // ... but a fixed cascade of the same base is fine, and 4096 buffers are allowed.
    assert!(
        Zirr::new(ZirrParams {
            b: 1.01,
            ..fixed(6)
        })
        .is_ok()
    );
    assert!(Zirr::new(fixed(4096)).is_ok());
    assert!(Zirr::new(ZirrParams { b: 1.2, ..base }).is_ok());
    assert!(
        Zirr::new(ZirrParams {
            kappa_min: 0.0,
            ..base
        })
        .is_ok()
    );
    assert!(Zirr::new(fixed(1)).is_ok());

    let r = ZirrParams::REFERENCE;
    let e = err_ref(ZirrParams::PAPER);
    assert!(e.contains("J = auto"), "{e}");
    let e = err_ref(ZirrParams {
        j: CascadeSize::Fixed(1),
        ..r
    });
    assert!(e.contains("J = 1") && e.contains("2..=4096"), "{e}");
    let e = err_ref(ZirrParams {
        kappa_min: 2.0,
        ..r
    });
    assert!(e.contains("kappa_min = 2"), "{e}");
    let e = err_ref(ZirrParams {
        j: CascadeSize::Fixed(400),
        ..r
    });
    assert!(e.contains("J = 400") && e.contains("overflows"), "{e}");
    let e = err_ref(ZirrParams { kappa: -1.0, ..r });
    assert!(e.contains("kappa = -1"), "{e}");
    assert!(
        Zirr::reference(ZirrParams {
            j: CascadeSize::Fixed(2),
            ..r
        })
        .is_ok()
    );
}

#[test]
fn display_is_compact_and_spec_round_trips() {
    let z = Zirr::new(ZirrParams::PAPER).unwrap();
    assert_eq!(z.to_string(), "Zirr(b=8,J=auto,kappa=1)");
    let r = Zirr::reference(ZirrParams {
        kappa: 32.0,
        ..ZirrParams::REFERENCE
    })
    .unwrap();
    assert_eq!(r.to_string(), "Zirr-ref(b=8,J=6,kappa=32)");
    let odd = ZirrParams {
        b: 2.5,
        j: CascadeSize::Fixed(9),
        kappa: 0.25,
        kappa_min: 0.0,
        u: 1e-300,
    };
    assert_eq!(
        Zirr::new(odd).unwrap().to_string(),
        "Zirr(b=2.5,J=9,kappa=0.25,kappa_min=0,u=1e-300)"
    );
    for text in [
        "zirr",
        "zirr:J=6",
        "zirr:b=2.5,J=9,kappa=0.25,kappa_min=0,u=1e-300",
        "zirr-ref",
        "zirr-ref:kappa=32,u=0.5",
    ] {
        let spec: EstimatorSpec = text.parse().unwrap();
        let est = spec.build().unwrap();
        assert_eq!(est.spec(), spec, "{text}");
        let again = est.spec().build().unwrap();
        assert_eq!(again.to_string(), est.to_string());
        assert_eq!(again.spec(), spec);
    }
    let mut z = zirr(fixed(6), &RUNNING);
    assert_eq!(z.spec(), EstimatorSpec::Zirr(ZirrSpec(fixed(6))));
    assert_eq!(z.params(), fixed(6));
    z.reset();
    assert_eq!(z.count(), 0);
    let e = z.estimate().unwrap_err().to_string();
    assert!(e.contains("Zirr(b=8,J=6,kappa=1)"), "{e}");
}

#[test]
fn state_bytes_are_struct_plus_buffers() {
    let buffer = std::mem::size_of::<Neumaier>();
    let z = Zirr::new(fixed(6)).unwrap();
    assert_eq!(z.state_bytes(), std::mem::size_of::<Zirr>() + 6 * buffer);
    let mut z = Zirr::new(ZirrParams::PAPER).unwrap();
    assert_eq!(z.state_bytes(), std::mem::size_of::<Zirr>() + buffer);
    z.push_slice(&RUNNING);
    assert_eq!(z.state_bytes(), std::mem::size_of::<Zirr>() + 4 * buffer);
    // Per-pixel state stays small: 128 bytes of cascade plus the released variant's
    // discarded sum (one type serves both variants).
    assert!(std::mem::size_of::<Zirr>() <= 152);
    let r = Zirr::reference(ZirrParams::REFERENCE).unwrap();
    assert_eq!(r.state_bytes(), std::mem::size_of::<Zirr>() + 6 * buffer);
    // Reset keeps the allocation (and so the reported size) of an auto cascade.
    z.reset();
    assert_eq!(z.count(), 0);
    assert_eq!(z.extras()[0], ("J_used", Extra::Int(1)));
}

// ---------------------------------------------------------------------------------------------
// Hard inputs.

#[test]
fn all_zeros_estimate_zero() {
    let zeros = [0.0, -0.0, 0.0, 0.0];
    for est in [
        Box::new(zirr(ZirrParams::PAPER, &zeros)) as Box<dyn Estimator>,
        Box::new(zirr(fixed(6), &zeros)),
        Box::new(zirr_ref(ZirrParams::REFERENCE, &zeros)),
    ] {
        let e = est.estimate().unwrap();
        assert_eq!(e, 0.0, "{est}");
        assert!(e.is_sign_positive());
    }
    assert_eq!(int(&zirr(ZirrParams::PAPER, &zeros).extras(), "J_used"), 1);
}

#[test]
fn one_sample_pixels() {
    // N = 1: a lone sample below u counts S/u < 1 and is dropped (consequence (ii)); one above
    // counts exactly 1 in each buffer it touches and is dropped as a lone firefly.
    for x in [0.5, 1.0, 3.0, 350.0, 32767.0, 1e10] {
        assert_eq!(
            zirr(ZirrParams::PAPER, &[x]).estimate().unwrap(),
            0.0,
            "{x}"
        );
        if x < 32768.0 {
            assert_eq!(zirr(fixed(6), &[x]).estimate().unwrap(), 0.0, "{x}");
        }
    }
    // With kappa_min = 0 nothing is a lone firefly: S = 1 goes to buffer 0 and passes.
    let p = ZirrParams {
        kappa_min: 0.0,
        ..ZirrParams::PAPER
    };
    assert_eq!(zirr(p, &[1.0]).estimate().unwrap(), 1.0);
    // With a fixed cascade a sample above c_{J−1} counts > 1 and passes (consequence (i)).
    let z = zirr(fixed(3), &[1000.0]);
    assert_eq!(int(&z.extras(), "over_range"), 1);
    assert!(z.estimate().unwrap() > 0.0);
    // zirr-ref: a lone sample keeps a small weight from the colour term.
    let r = zirr_ref(ZirrParams::REFERENCE, &[3.0]);
    let e = r.estimate().unwrap();
    assert!((0.0..=3.0).contains(&e), "{e}");
}

#[test]
fn extreme_magnitudes() {
    // 1e300 needs buffers up to 8^332 ≤ 1e300 < 8^333: J_used = 334.
    let z = zirr(ZirrParams::PAPER, &[1e300, 1e300, 1e300]);
    let e = z.extras();
    assert_eq!(int(&e, "J_used"), 334);
    let est = z.estimate().unwrap();
    assert!(est.is_finite() && (0.0..=1e300).contains(&est), "{est}");
    // Three equal samples count 3 > 1 and pass in full.
    assert_rel(est, 1e300, 1e-12);
    let sum: f64 = floats(&e, "B").iter().sum();
    assert_rel(sum, 1e300, 1e-12);

    // 1e-300 with u = 1 is far below the floor u·κ_min/N: dropped (consequence (ii)).
    assert_eq!(
        zirr(ZirrParams::PAPER, &[1e-300; 5]).estimate().unwrap(),
        0.0
    );
    // With u at their scale they behave like samples of 1 with u = 1.
    let tiny = ZirrParams {
        u: 1e-300,
        ..ZirrParams::PAPER
    };
    let z = zirr(tiny, &[1e-300; 5]);
    assert_rel(z.estimate().unwrap(), 1e-300, 1e-12);
    // f64::MAX and sums near it do not panic.
    for p in [ZirrParams::PAPER, fixed(6), tiny] {
        let z = zirr(p, &[f64::MAX, 1.0, f64::MAX]);
        let _ = z.estimate();
        let _ = z.extras();
    }
    let r = zirr_ref(ZirrParams::REFERENCE, &[f64::MAX, 1e300, 1e-300]);
    assert!(r.estimate().unwrap().is_finite());
}

#[test]
fn overflowing_s_goes_to_an_infinite_top_buffer_and_is_rejected() {
    // u = 0.5: S = 1e308 gives s = S/u = +inf.
    let p = ZirrParams {
        u: 0.5,
        ..ZirrParams::PAPER
    };
    let z = zirr(p, &[1.0, 1.0, 1.0, 1e308]);
    let e = z.extras();
    assert_eq!(int(&e, "over_range"), 1);
    assert_rel(z.estimate().unwrap(), 0.75, 1e-12);
    let sum: f64 = floats(&e, "B").iter().sum();
    assert_rel(sum, (3.0 + 1e308) / 4.0, 1e-12);
}

#[test]
fn a_million_samples_with_one_huge_outlier() {
    // Deterministic values in [0, 2) (a Weyl sequence) and one 1e30 firefly.
    let mut xs: Vec<f64> = (0..1_000_000u64)
        .map(|i| 2.0 * ((i as f64 * 0.618_033_988_749_894_9) % 1.0))
        .collect();
    xs[123_456] = 1e30;
    let rest = {
        let mut s = Neumaier::new();
        xs.iter().filter(|&&x| x < 1e30).for_each(|&x| s.add(x));
        s.value()
    };
    let n = xs.len() as f64;

    let auto = zirr(ZirrParams::PAPER, &xs);
    let e = auto.extras();
    // 8^33 ≤ 1e30 < 8^34: buffers 0..=34.
    assert_eq!(int(&e, "J_used"), 35);
    assert_eq!(int(&e, "over_range"), 0);
    // The firefly is rejected; every other sample passes with weight 1.
    assert_rel(auto.estimate().unwrap(), rest / n, 1e-12);
    let sum: f64 = floats(&e, "B").iter().sum();
    assert_rel(sum, (rest + 1e30) / n, 1e-12);

    // A fixed J = 6 cascade lets it through.
    let z6 = zirr(fixed(6), &xs);
    assert_eq!(int(&z6.extras(), "over_range"), 1);
    assert!(z6.estimate().unwrap() > 1e23);

    // zirr-ref clamps it at c_5 = 32768 and reports the excess.
    let r = zirr_ref(ZirrParams::REFERENCE, &xs);
    let er = r.extras();
    assert_rel(float(&er, "discarded"), (1e30 - 32768.0) / n, 1e-12);
    let est = r.estimate().unwrap();
    assert!(est < 1.1 && est > 0.9, "{est}");
}

// ---------------------------------------------------------------------------------------------
// An independent oracle: the spec transcribed literally (cached power table, search by scan,
// counts by explicit bounds checks), compared bit for bit.

struct Literal {
    b: Vec<f64>,
    n: Vec<f64>,
    w: Vec<f64>,
    estimate: f64,
    discarded: f64,
}

fn literal(p: &ZirrParams, j_count: usize, reference: bool, samples: &[f64]) -> Literal {
    let (b, u) = (p.b, p.u);
    let mut pw = vec![1.0f64];
    for j in 1..j_count {
        pw.push(pw[j - 1] * b);
    }
    let c: Vec<f64> = pw.iter().map(|pj| u * pj).collect();
    let mut acc = vec![Neumaier::new(); j_count];
    let mut disc = Neumaier::new();
    for &x in samples {
        let s = x / u;
        if s < 1.0 || j_count == 1 {
            acc[0].add(x);
            continue;
        }
        let j = (0..j_count).filter(|&k| pw[k] <= s).max().unwrap();
        if j == j_count - 1 {
            if reference {
                acc[j].add(c[j]);
                disc.add(x - c[j]);
            } else {
                acc[j].add(x);
            }
        } else {
            let ib = 1.0 / b;
            let a = (pw[j] / s - ib) / (1.0 - ib);
            let part = a * x;
            acc[j].add(part);
            acc[j + 1].add(x - part);
        }
    }
    let nf = samples.len() as f64;
    let bufs: Vec<f64> = acc.iter().map(|a| a.value() / nf).collect();
    let mut counts = Vec::new();
    for j in 0..j_count {
        let mut terms = Vec::new();
        for k in [j.wrapping_sub(1), j, j + 1] {
            if k < j_count {
                terms.push(bufs[k] / c[k]);
            }
        }
        let mut sum = terms[0];
        for t in &terms[1..] {
            sum += t;
        }
        counts.push(nf * sum);
    }
    let mut e = 0.0f64;
    let mut ws = Vec::new();
    for j in 0..j_count {
        let w = if reference {
            let a = (1.0 / p.kappa).min(1.0);
            let r_loc = counts[j] / p.kappa;
            let r_glob = counts[j] / p.kappa;
            let mut rel = r_glob - 1.0 / p.kappa;
            if rel >= 0.0 {
                rel = r_loc - 1.0 / p.kappa;
            }
            let col = e.max(0.05 * u) * nf / (p.kappa * c[j]) * ((0.4 + 0.6 * b) * (1.0 - a) + a);
            ((rel + col) / 2.0).clamp(0.0, 1.0)
        } else {
            let at_most = |x: f64| x <= p.kappa_min + 1e-9 * p.kappa_min.max(1.0);
            let r_c = if at_most(counts[j]) {
                f64::INFINITY
            } else {
                nf / (counts[j] - p.kappa_min)
            };
            let r_v = if e == 0.0 { f64::INFINITY } else { c[j] / e };
            let r = r_c.min(r_v);
            let mut w = if r == f64::INFINITY {
                0.0
            } else {
                (nf / (p.kappa * r)).min(1.0)
            };
            if at_most(counts[j]) {
                w = 0.0;
            }
            w
        };
        e += w * bufs[j];
        ws.push(w);
    }
    Literal {
        b: bufs,
        n: counts,
        w: ws,
        estimate: e,
        discarded: disc.value() / nf,
    }
}

// ---------------------------------------------------------------------------------------------
// Property tests.

/// Samples shaped like path-tracing luminance: zeros, a body in [0, 2), a log-uniform tail.
fn sample() -> impl Strategy<Value = f64> {
    prop_oneof![
        1 => Just(0.0),
        4 => 0.0..2.0f64,
        3 => (-3.0..12.0f64).prop_map(|e| 10f64.powf(e)),
    ]
}

fn samples() -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(sample(), 1..60)
}

fn zirr_params() -> impl Strategy<Value = ZirrParams> {
    let b = prop_oneof![Just(8.0), Just(2.0), Just(3.0), 1.2..20.0f64];
    let j = prop_oneof![
        2 => Just(CascadeSize::Auto),
        3 => (1usize..12).prop_map(CascadeSize::Fixed),
    ];
    let kappa = prop_oneof![Just(1.0), Just(4.0), Just(32.0), 0.1..50.0f64];
    let kappa_min = prop_oneof![Just(1.0), Just(0.0), 0.0..3.0f64];
    let u = prop_oneof![Just(1.0), (-3.0..3.0f64).prop_map(|e| 10f64.powf(e))];
    (b, j, kappa, kappa_min, u).prop_map(|(b, j, kappa, kappa_min, u)| ZirrParams {
        b,
        j,
        kappa,
        kappa_min,
        u,
    })
}

fn ref_params() -> impl Strategy<Value = ZirrParams> {
    (zirr_params(), 2usize..12).prop_map(|(p, j)| ZirrParams {
        j: CascadeSize::Fixed(j),
        kappa_min: 1.0,
        ..p
    })
}

fn any_cascade() -> impl Strategy<Value = CascadeSize> {
    prop_oneof![
        Just(CascadeSize::Auto),
        (0usize..5000).prop_map(CascadeSize::Fixed),
    ]
}

fn neumaier_mean(xs: &[f64]) -> f64 {
    let mut s = Neumaier::new();
    xs.iter().for_each(|&x| s.add(x));
    s.value() / xs.len() as f64
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Constructors never panic on any f64, and what they accept can be fed extreme samples.
    #[test]
    fn constructors_never_panic(
        b in proptest::num::f64::ANY,
        j in any_cascade(),
        kappa in proptest::num::f64::ANY,
        kappa_min in proptest::num::f64::ANY,
        u in proptest::num::f64::ANY,
    ) {
        let p = ZirrParams { b, j, kappa, kappa_min, u };
        let xs = [0.0, 1e-300, 0.7, 1.0, 9.0, 1e30, 1e300, f64::MAX];
        if let Ok(mut z) = Zirr::new(p) {
            z.push_slice(&xs);
            let _ = (z.estimate(), z.extras(), z.state_bytes(), z.to_string());
        }
        if let Ok(mut z) = Zirr::reference(p) {
            z.push_slice(&xs);
            let _ = (z.estimate(), z.extras(), z.state_bytes(), z.to_string());
        }
    }

    /// The implementation equals the literal transcription of docs/estimators.md §5 bit for bit
    /// (an auto cascade equals a fixed one of J_used buffers).
    #[test]
    fn zirr_matches_the_literal_spec(p in zirr_params(), xs in samples()) {
        let z = zirr(p, &xs);
        let e = z.extras();
        let j = int(&e, "J_used") as usize;
        let lit = literal(&p, j, false, &xs);
        prop_assert_eq!(floats(&e, "B"), lit.b);
        prop_assert_eq!(floats(&e, "counts"), lit.n);
        prop_assert_eq!(floats(&e, "w"), lit.w);
        prop_assert_eq!(z.estimate().unwrap(), lit.estimate);
    }

    /// Same for zirr-ref (docs/estimators.md §5a).
    #[test]
    fn zirr_ref_matches_the_literal_spec(p in ref_params(), xs in samples()) {
        let CascadeSize::Fixed(j) = p.j else { unreachable!() };
        let z = zirr_ref(p, &xs);
        let e = z.extras();
        let lit = literal(&p, j, true, &xs);
        prop_assert_eq!(floats(&e, "B"), lit.b);
        prop_assert_eq!(floats(&e, "counts"), lit.n);
        prop_assert_eq!(floats(&e, "w"), lit.w);
        prop_assert_eq!(z.estimate().unwrap(), lit.estimate);
        prop_assert_eq!(float(&e, "discarded"), lit.discarded);
    }

    /// docs/estimators.md §5 invariant: Σ B_j is the mean; for zirr-ref Σ B_j + discarded is.
    #[test]
    fn buffers_sum_to_the_mean(p in zirr_params(), r in ref_params(), xs in samples()) {
        let mean = neumaier_mean(&xs);
        let e = zirr(p, &xs).extras();
        let sum: f64 = floats(&e, "B").iter().sum();
        prop_assert!((sum - mean).abs() <= 1e-12 * mean, "{} vs {}", sum, mean);
        let e = zirr_ref(r, &xs).extras();
        let sum = floats(&e, "B").iter().sum::<f64>() + float(&e, "discarded");
        prop_assert!((sum - mean).abs() <= 1e-12 * mean, "{} vs {}", sum, mean);
    }

    /// Estimates lie in [0, max sample] (up to the rounding of a sum of buffers) and every
    /// weight in [0, 1].
    #[test]
    fn estimate_and_weights_are_bounded(p in zirr_params(), r in ref_params(), xs in samples()) {
        let max = xs.iter().cloned().fold(0.0, f64::max);
        let z = zirr(p, &xs);
        let zr = zirr_ref(r, &xs);
        for (est, e) in [(z.estimate().unwrap(), z.extras()), (zr.estimate().unwrap(), zr.extras())] {
            prop_assert!(est >= 0.0 && est <= max * (1.0 + 1e-12), "{} not in [0, {}]", est, max);
            for w in floats(&e, "w") {
                prop_assert!((0.0..=1.0).contains(&w), "w = {}", w);
            }
        }
    }

    /// Scaling samples and u by a power of two scales the estimate exactly.
    #[test]
    fn scaling_by_a_power_of_two_is_exact(
        p in zirr_params(), r in ref_params(), xs in samples(), k in -30i32..30,
    ) {
        let c = 2f64.powi(k);
        let scaled: Vec<f64> = xs.iter().map(|x| x * c).collect();
        let z = zirr(p, &xs).estimate().unwrap();
        let zc = zirr(ZirrParams { u: p.u * c, ..p }, &scaled).estimate().unwrap();
        prop_assert_eq!(zc, z * c);
        let z = zirr_ref(r, &xs).estimate().unwrap();
        let zc = zirr_ref(ZirrParams { u: r.u * c, ..r }, &scaled).estimate().unwrap();
        prop_assert_eq!(zc, z * c);
    }

    /// Scaling by any c > 0 scales the estimate up to rounding.
    #[test]
    fn scaling_by_any_factor(
        p in zirr_params(), r in ref_params(), xs in samples(), lc in -6.0..6.0f64,
    ) {
        let c = 10f64.powf(lc);
        let scaled: Vec<f64> = xs.iter().map(|x| x * c).collect();
        let max = xs.iter().cloned().fold(0.0, f64::max);
        let z = zirr(p, &xs).estimate().unwrap();
        let zc = zirr(ZirrParams { u: p.u * c, ..p }, &scaled).estimate().unwrap();
        prop_assert!((zc - z * c).abs() <= 1e-9 * max * c, "{} vs {}", zc, z * c);
        let z = zirr_ref(r, &xs).estimate().unwrap();
        let zc = zirr_ref(ZirrParams { u: r.u * c, ..r }, &scaled).estimate().unwrap();
        prop_assert!((zc - z * c).abs() <= 1e-9 * max * c, "{} vs {}", zc, z * c);
    }

    /// Block estimates: bounded weights and estimates, and a block whose neighbours are all
    /// outside the image (zirr) or copies of the centre (zirr-ref) equals the lone pixel.
    #[test]
    fn block_estimates_are_bounded(
        p in zirr_params(),
        r in ref_params(),
        pixels in prop::collection::vec(prop::option::of(prop::collection::vec(sample(), 0..20)), 9),
        centre in samples(),
    ) {
        let max = centre.iter().cloned().fold(0.0, f64::max);
        let zs: Vec<Option<Zirr>> = pixels.iter().map(|o| o.as_ref().map(|xs| zirr(p, xs))).collect();
        let rs: Vec<Option<Zirr>> =
            pixels.iter().map(|o| o.as_ref().map(|xs| zirr_ref(r, xs))).collect();
        let zc = zirr(p, &centre);
        let rc = zirr_ref(r, &centre);
        let mut zb: [Option<&Zirr>; 9] = std::array::from_fn(|i| zs[i].as_ref());
        let mut rb: [Option<&Zirr>; 9] = std::array::from_fn(|i| rs[i].as_ref());
        zb[4] = Some(&zc);
        rb[4] = Some(&rc);
        for (est, e) in [Zirr::block_estimate(&zb).unwrap(), Zirr::block_estimate(&rb).unwrap()] {
            prop_assert!(est >= 0.0 && est <= max * (1.0 + 1e-12), "{} not in [0, {}]", est, max);
            for w in floats(&e, "w") {
                prop_assert!((0.0..=1.0).contains(&w), "w = {}", w);
            }
        }
        let mut lone = [None; 9];
        lone[4] = Some(&zc);
        prop_assert_eq!(Zirr::block_estimate(&lone).unwrap().0, zc.estimate().unwrap());
        let copies = [Some(&rc); 9];
        let (est, _) = Zirr::block_estimate(&copies).unwrap();
        let lone = rc.estimate().unwrap();
        prop_assert!((est - lone).abs() <= 1e-12 * max, "{} vs {}", est, lone);
    }
}
