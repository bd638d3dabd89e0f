//! The exponential the samplers draw through (`scale * e^Y` for Pareto laws, `e^(mu + sigma Z)`
//! for lognormals): the C library's `exp` took 40-54% of the NumPy-comparable task, as a call
//! that can be neither inlined nor vectorised, and its last bit differs between C libraries.
//!
//! [`exp`] is table-driven: `x = (k/N) ln 2 + r` with `N = 128` and `|r| <= ln2 / 256`, so
//! `e^x = 2^(k div N) * 2^((k mod N)/N) * e^r`. The 128 values `2^(i/N)` are stored correctly
//! rounded together with what their rounding left out (`exp_table.rs`, written by
//! `exp_table.py` in decimal arithmetic), `ln2/N` is split so that `k ln2/N` is exact, and `e^r`
//! is a degree-5 Taylor polynomial (truncation below 6e-19 relative). The tests measure it
//! against 2560 references computed in decimal arithmetic (`exp_cases.txt`, written by
//! `exp_table.py --cases`): at most 0.5045 ulp, where glibc's `exp` reaches 0.5.
//!
//! The result is the same on every IEEE-754 machine: only additions and multiplications in a
//! fixed order (Rust never fuses them into FMAs on its own) and integer operations on bits.

mod table {
    include!("exp_table.rs");
}

use crate::simd::vectorized;
use table::{EXP2_TABLE, LN2_OVER_N_HI, LN2_OVER_N_LO, N_OVER_LN2, TABLE_BITS};

/// Adding then subtracting `1.5 * 2^52` rounds to the nearest integer (ties to even) and leaves
/// that integer in the low bits, without a library call (baseline x86-64 has no `roundsd`).
const SHIFT: f64 = 6755399441055744.0;
/// Below this magnitude every step stays in the normal range and the result is normal.
const FAST_LIMIT: f64 = 708.0;

/// `e^x`, within about half an ulp (see the tests), with `exp(NaN) = NaN`, `exp(-inf) = 0`,
/// `exp(inf) = inf`, overflow to `inf` above `ln(f64::MAX)` and gradual underflow to 0 below
/// about -708.4.
#[inline(always)]
pub fn exp(x: f64) -> f64 {
    if x.abs() < FAST_LIMIT {
        scaled(x, 0)
    } else {
        exp_edge(x)
    }
}

/// Elements per pass of [`exp_affine_in_place`]: arguments are kept until the pass ends, so
/// that the rare ones outside the fast range can be redone.
const PASS: usize = 64;

/// `xs[i] = c * e^(a xs[i] + b)`, the same values as `c * exp(a * xs[i] + b)` one by one, in a
/// loop without branches that the compiler can vectorise: each pass computes every element on
/// the fast path and then redoes the rare arguments outside it.
pub fn exp_affine_in_place(xs: &mut [f64], a: f64, b: f64, c: f64) {
    vectorized(AffinePass { xs, a, b, c })
}

/// [`exp_affine_in_place`]'s arguments, as a job compiled once per instruction set.
struct AffinePass<'a> {
    xs: &'a mut [f64],
    a: f64,
    b: f64,
    c: f64,
}

impl pulp::WithSimd for AffinePass<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        affine_pass(self.xs, self.a, self.b, self.c)
    }
}

/// Three loops per block, so that the two without table lookups vectorise on their own.
#[inline(always)]
fn affine_pass(xs: &mut [f64], a: f64, b: f64, c: f64) {
    // Declared once: zeroing them for every block cost a sixth of the pass.
    let (mut args, mut ks, mut rs) = ([0.0; PASS], [0i64; PASS], [0.0; PASS]);
    let (mut scales, mut tails) = ([0.0; PASS], [0.0; PASS]);
    for block in xs.chunks_mut(PASS) {
        let mut outside = false;
        for (((x, arg), k), r) in block.iter().zip(&mut args).zip(&mut ks).zip(&mut rs) {
            *arg = a * *x + b;
            outside |= !(arg.abs() < FAST_LIMIT);
            (*k, *r) = reduce(*arg);
        }
        for ((k, scale), tail) in ks.iter().zip(&mut scales).zip(&mut tails) {
            (*scale, *tail) = lookup(*k, 0);
        }
        for (((x, scale), tail), r) in block.iter_mut().zip(&scales).zip(&tails).zip(&rs) {
            *x = c * combine(*scale, *tail, *r);
        }
        if outside {
            for (x, &arg) in block.iter_mut().zip(&args) {
                if !(arg.abs() < FAST_LIMIT) {
                    *x = c * exp_edge(arg);
                }
            }
        }
    }
}

/// `e^x * 2^-bias`, for `|x| < 746` and a bias that keeps `2^(x/ln2 - bias)` normal.
#[inline(always)]
fn scaled(x: f64, bias: i64) -> f64 {
    let (k, r) = reduce(x);
    let (scale, tail) = lookup(k, bias);
    combine(scale, tail, r)
}

/// `x = k ln2/N + r` with `k` the nearest integer to `x N/ln2`, `|r| <= ln2/(2N)`.
#[inline(always)]
fn reduce(x: f64) -> (i64, f64) {
    let shifted = x * N_OVER_LN2 + SHIFT;
    let k = shifted.to_bits().wrapping_sub(SHIFT.to_bits()) as i64;
    let kd = shifted - SHIFT;
    (k, (x - kd * LN2_OVER_N_HI) - kd * LN2_OVER_N_LO)
}

/// `2^(k/N - bias)` as a double and the relative error of its table entry.
#[inline(always)]
fn lookup(k: i64, bias: i64) -> (f64, f64) {
    let i = 2 * (k & ((1 << TABLE_BITS) - 1)) as usize;
    let exponent = (k >> TABLE_BITS) - bias;
    let scale = f64::from_bits(EXP2_TABLE[i].wrapping_add((exponent as u64) << 52));
    (scale, f64::from_bits(EXP2_TABLE[i + 1]))
}

/// `scale * e^r`, with `e^r - 1` as a degree-5 polynomial plus the table entry's error.
#[inline(always)]
fn combine(scale: f64, tail: f64, r: f64) -> f64 {
    let r2 = r * r;
    let poly = tail + (r + r2 * ((0.5 + r * (1.0 / 6.0)) + r2 * (1.0 / 24.0 + r * (1.0 / 120.0))));
    scale + scale * poly
}

/// `|x| >= 708` or NaN: the power of two is applied in two steps, so that the scale stays
/// normal and only the last multiplication overflows or underflows (once, as it should).
#[cold]
#[inline(never)]
fn exp_edge(x: f64) -> f64 {
    if x.is_nan() {
        x
    } else if x > 710.0 {
        f64::INFINITY
    } else if x < -746.0 {
        0.0
    } else if x > 0.0 {
        scaled(x, 1) * 2.0
    } else {
        scaled(x, -1022) * f64::from_bits(1 << 52) // 2^-1022
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between two finite doubles of the same sign.
    fn ulps(a: f64, b: f64) -> u64 {
        a.to_bits().abs_diff(b.to_bits())
    }

    /// `(y - exact) / ulp(exact)` for `exact = hi + lo` in the normal range.
    fn error_in_ulps(y: f64, hi: f64, lo: f64) -> f64 {
        let ulp = f64::from_bits(hi.to_bits() & (0x7ff << 52)) * f64::EPSILON;
        ((y - hi) - lo) / ulp
    }

    fn cases() -> impl Iterator<Item = (f64, f64, f64)> {
        include_str!("exp_cases.txt")
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| {
                let mut it = l
                    .split(' ')
                    .map(|h| f64::from_bits(u64::from_str_radix(h, 16).unwrap()));
                let mut next = || it.next().unwrap();
                (next(), next(), next())
            })
    }

    /// The worst error over 2560 arguments with decimal-arithmetic references, 512 of them where
    /// the reduced argument is largest (measured: 0.5045 ulp). Without the table's tails the
    /// worst was 0.985 ulp, so the bound catches their loss, and any larger defect.
    #[test]
    fn within_about_half_an_ulp_of_the_exact_value() {
        let worst = cases()
            .map(|(x, hi, lo)| error_in_ulps(exp(x), hi, lo).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.52, "worst error {worst} ulp");
    }

    /// Where the steps change (the edge path, gradual underflow, overflow) and across the whole
    /// domain, against the C library's `exp`, which is itself within about half an ulp: a
    /// misplaced power of two or a wrong branch is off by far more than one ulp.
    #[test]
    fn within_one_ulp_of_the_library_everywhere() {
        let ranges = [
            (-746.0, 710.0),
            (-746.0, -707.0),
            (707.0, 709.8),
            (-1e-3, 1e-3),
        ];
        for (lo, hi) in ranges {
            for j in 0..=100_000 {
                let x = lo + (hi - lo) * (j as f64 / 100_000.0);
                let (got, want) = (exp(x), x.exp());
                assert!(
                    got == want || (want.is_finite() && ulps(got, want) <= 1),
                    "exp({x:e}) = {got:e}, library {want:e}"
                );
            }
        }
    }

    /// The vectorised pass gives the bits of the one-by-one function, on the detected vector
    /// units and on baseline ones, including when a pass holds arguments outside the fast range
    /// (NaN, infinities, overflow, underflow) or ends short.
    #[test]
    fn in_place_pass_equals_one_by_one() {
        let specials = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            709.5,
            -745.0,
            -0.0,
            1e-300,
        ];
        let mut xs: Vec<f64> = (0..1000).map(|j| (j as f64 - 500.0) * 1.6).collect();
        for (j, s) in specials.iter().enumerate() {
            xs[j * 131] = *s;
        }
        let (a, b, c) = (0.75, -0.5, 3.0);
        let want: Vec<u64> = xs.iter().map(|&x| (c * exp(a * x + b)).to_bits()).collect();
        for len in [0, 1, 63, 64, 65, 1000] {
            let mut got = xs[..len].to_vec();
            exp_affine_in_place(&mut got, a, b, c);
            let got: Vec<u64> = got.iter().map(|x| x.to_bits()).collect();
            assert_eq!(got, want[..len], "length {len}");
        }
        // The baseline instructions give the same bits as the detected vector units.
        crate::simd::force_scalar(true);
        let mut scalar = xs.clone();
        exp_affine_in_place(&mut scalar, a, b, c);
        crate::simd::force_scalar(false);
        let scalar: Vec<u64> = scalar.iter().map(|x| x.to_bits()).collect();
        assert_eq!(scalar, want);
    }

    #[test]
    fn special_values() {
        assert!(exp(f64::NAN).is_nan());
        assert_eq!(exp(f64::INFINITY), f64::INFINITY);
        assert_eq!(exp(f64::NEG_INFINITY), 0.0);
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-0.0), 1.0);
        assert_eq!(exp(709.79), f64::INFINITY);
        assert_eq!(exp(-745.2), 0.0);
        assert_eq!(exp(-745.1), f64::from_bits(1));
        assert!(exp(709.78).is_finite());
    }
}
