//! Helpers shared by the integration tests that reproduce the spec's worked examples.

/// The running example of docs/estimators.md §1.
pub const S: [f64; 7] = [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1];

/// Worked examples must match to this relative tolerance (docs/estimators.md §1, "Accuracy").
pub const REL: f64 = 1e-12;

/// Asserts `|actual - expected| <= tol * |expected|` (exact equality when `expected` is 0).
#[track_caller]
pub fn assert_rel(actual: f64, expected: f64, tol: f64) {
    let err = (actual - expected).abs();
    assert!(
        err <= tol * expected.abs(),
        "actual {actual:?} vs expected {expected:?}: relative error {:e} > {tol:e}",
        err / expected.abs()
    );
}
