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

/// Asserts that two estimators' extras agree: bit for bit, except Jung's `sigma_pixel`, which
/// the block form of docs/estimators.md §1 lets differ by `1e-12` relative with how the stream
/// was cut into blocks (Jung's `M`, compared exactly, may not).
#[track_caller]
pub fn assert_same_extras(
    a: &[(&'static str, fireflies::estimators::Extra)],
    b: &[(&'static str, fireflies::estimators::Extra)],
    context: &str,
) {
    use fireflies::estimators::Extra;
    let keys = |e: &[(&'static str, Extra)]| e.iter().map(|(k, _)| *k).collect::<Vec<_>>();
    assert_eq!(keys(a), keys(b), "{context}");
    for ((key, x), (_, y)) in a.iter().zip(b) {
        match (*key, x, y) {
            ("sigma_pixel", Extra::Float(x), Extra::Float(y)) if x.is_finite() => {
                assert!(
                    (x - y).abs() <= REL * x.abs(),
                    "{context}: sigma_pixel {x} vs {y}"
                )
            }
            _ => assert_eq!(x, y, "{context}: {key}"),
        }
    }
}
