//! Zirr et al.'s cascade reweighting of firefly samples (docs/estimators.md §5 and §5a).
//!
//! Source: T. Zirr, J. Hanika, C. Dachsbacher, "Re-Weighting Firefly Samples for Improved
//! Finite-Sample Monte Carlo Estimates", Computer Graphics Forum 37(6), 2018 (\[Z\]).
//!
//! # The method
//!
//! Each sample is splatted into a cascade of `J` buffers whose reference brightnesses grow
//! geometrically, `c_j = u·b^j` (\[Z\] §4.2, eqs. 15–16: a sample between two reference
//! brightnesses is split between the two buffers so that each part counts exactly one sample
//! there). Buffer `j` holds `B_j = A_j / N`; the buffers sum to the plain mean. From the
//! buffers the method estimates, per buffer, how many samples it saw (`n_j`, eq. 19, from the
//! three neighbouring buffers, eqs. 17–18) and composes the buffers from dark to bright, giving
//! each buffer a weight `w_j ∈ [0, 1]` that shrinks when its energy is carried by too few samples
//! to be trusted relative to the brightness composed so far (eqs. 12–13, §4.3). Buffers whose
//! rejection count `ρ_j` (the count itself, or its mean over a 3×3 pixel neighbourhood, §5.3.1)
//! is at most `κ_min` are dropped as lone fireflies.
//!
//! Two variants:
//!
//! * [`Zirr`] — the paper's method, `zirr` (docs/estimators.md §5).
//! * [`Zirr`] — the authors' released code (public repository `tszirr/ic.js`, folder `rw/`),
//!   `zirr-ref` (docs/estimators.md §5a): the top buffer clamps the energy it receives at its reference
//!   brightness (the excess is reported as the extra `discarded`), the weight averages a count
//!   term and a colour term, and the neighbourhood is always divided by 9 with clamp-to-edge.
//!
//! # Decisions (docs/estimators.md §5, §5a)
//!
//! * **Unit rule.** Wherever \[Z\] writes `b^j` this module uses `c_j = u·p_j`, with
//!   `p_0 = 1, p_j = p_{j−1}·b` (repeated multiplication, never `powi`). Scaling the samples and
//!   `u` together scales the estimate.
//! * **Cascade size.** `J = auto` (the `zirr` default) grows the pixel's cascade on demand so
//!   that a sample with `p_j ≤ s < p_{j+1}` always has buffers `0..=j+1` (\[Z\] eq. 14, and the
//!   "more buffers" remedy of §5.1); `J_used = 1 + the largest j+1 needed` (at least 1). A fixed
//!   `J` keeps the literal cascade: a sample above `c_{J−1}` goes wholly to the top buffer, where
//!   it counts more than one sample and so escapes the lone-firefly test (docs/estimators.md §5, consequence
//!   (i)); such samples are counted in the extra `over_range`.
//! * **At-most test.** `x ≼ κ_min` means `x ≤ κ_min + 1e-9·max(1, κ_min)`, because a lone firefly
//!   counts exactly 1 (the default `κ_min`) in real arithmetic and the decision must not depend
//!   on rounding.
//!   Where `n_j ≼ κ_min` the count bound `r_c` is `+inf`. One parameter `kappa_min` serves both
//!   the count bound and the rejection test.
//! * **Operation order.** The splat computes `s = S/u`, `ib = 1/b`,
//!   `a = (p_j/s − ib)/(1 − ib)`, `x = a·S` exactly in the spec's order, so that every discrete
//!   decision agrees bit for bit with an independent implementation of the spec. The only
//!   addition is `a = max(a, 0)`: when `p_{j+1} = p_j·b` is rounded up, a sample just below it
//!   can give `a` slightly below 0, which would put a tiny negative value into a buffer (and
//!   could make a later weight negative). It never acts when `b` is a power of two.
//! * **Memory.** The thresholds `c_j` are not cached: they are the same for every pixel with
//!   the same parameters, so caching them per pixel would double the per-pixel state. The splat
//!   recomputes `p_j` by the same repeated multiplication (one multiply per level above the
//!   sample's own, so a few per sample), bit-identical to a cached table. The state of one pixel
//!   is about a hundred bytes plus 16 bytes per buffer ([`Estimator::state_bytes`] reports it:
//!   struct plus buffer capacity). An auto cascade starts with one buffer and grows exactly as
//!   far as needed; [`Estimator::reset`] keeps its allocation.
//! * **Cost.** `push_slice` keeps `A_0` and `A_1` in registers for the whole block and skips the
//!   division `S/u` when `u = 1`. A sample below `u` costs one compensated addition, as the mean;
//!   one at or above `u` pays the two divisions of the spec's formula for `a` and two additions.
//!   On the development machine: about 1.5× the mean's time per sample when most samples are
//!   below `u`, about 5× when every sample is at or above `u` (Pareto with scale `u`).
//! * **Extras.** `J_used`, `over_range`, then per buffer `B`, `n`, `rho`, `w` (and `discarded`
//!   for `zirr-ref`). Before any sample the per-buffer lists are zeros.
//! * **Cascade limit.** A finite sample never needs more than `J_max = j* + 2` buffers, where
//!   `j*` is the largest `j` with `p_j` finite and `p_j ≤ f64::MAX/u` (about
//!   `log_b(f64::MAX/u) + 2`). Parameters whose maximum cascade exceeds [`MAX_BUFFERS`] (4096)
//!   buffers are rejected: with `J = auto` the error names `b` (use a larger `b` or `u`, or a
//!   fixed `J`), with a fixed `J > 4096` it names `J`.
//! * **Overflow of `S/u`.** With `u < 1`, a sample above `u·f64::MAX` makes `s = +inf`. With a
//!   fixed `J` it goes to the top buffer as any over-range sample. With `J = auto` it goes wholly
//!   to buffer `J_max − 1`, whose reference brightness is `+inf`; it counts 0 there and is always
//!   rejected. It is counted in `over_range`, which is otherwise 0 for `J = auto`. A unit whose
//!   reciprocal overflows (`u <` [`MIN_UNIT`] `≈ 5.56e-309`) is rejected by the constructors:
//!   there every sample above `u·f64::MAX < 1` would overflow `s` and be dropped, so
//!   `zirr:u=5e-324` would estimate 0 for any ordinary stream.
//! * **Overflow of sums.** Each buffer `A_j` (and `zirr-ref`'s discarded energy) is rescaled by
//!   `2^-128` on its own before its sum would reach `2^1023` (see `numeric`), so `B_j` is finite
//!   for any finite samples and bit-identical to the plain sum's whenever that one is finite.
//!   Where the spec's operation order would overflow an intermediate of the weights (`E·N` or
//!   `κ·c_j` in `zirr-ref`'s colour term), the same quantity is computed in an order that does
//!   not; and the composed `E`, at most the mean in real arithmetic, is saturated at
//!   `f64::MAX` against rounding. None of this changes a result that was finite.
//! * **`zirr-ref` limits.** `J = auto`, `J < 2` and `kappa_min ≠ 1` are errors (the released code
//!   has a fixed cascade and no separate threshold), and so is a `J` whose top reference
//!   brightness `c_{J−1}` overflows `f64`, because the top buffer adds `c_{J−1}` per sample.
//!   A weight that comes out NaN (only possible when `max(E, 0.05u)·N` and `κ·c_j` both overflow)
//!   counts as 0.
//!
//! # Neighbourhood (3×3)
//!
//! [`Zirr::block_estimate`] and [`Zirr::block_estimate`] take the nine pixels of a 3×3 block
//! in row-major order (index 4 is the centre; `None` is a pixel outside the image). The centre
//! must be present and have samples, and every present pixel must have the centre's parameters
//! (otherwise an error names the offending index). Only the rejection count `ρ_j` uses the
//! neighbours; buffers, counts, `N` and the weights' other terms are the centre's.
//!
//! * `zirr` (\[Z\] §5.3.1, docs/estimators.md §5): `ρ_j` = the mean of `n_j` over the present pixels that have
//!   samples (the centre included), summed in row-major order. A pixel whose cascade is shorter
//!   (`J = auto`) has empty buffers beyond it, so its `n_j` there is computed with those buffers
//!   as zeros — exactly as if its cascade had grown as far as the centre's. (Its `n_j` one
//!   buffer past its top is therefore `N·B_top/c_top`, not 0; this keeps the estimate
//!   independent of how far any cascade grew, as docs/estimators.md §5 requires.)
//! * `zirr-ref` (docs/estimators.md §5a): `ρ_j` = (sum of nine counts, row-major)/9. A missing pixel at offset
//!   `(dx, dy)` takes the counts of `(dx*, dy*)`, where `dx* = dx` if column `dx` has any present
//!   pixel and 0 otherwise (rows likewise), or of the centre if `(dx*, dy*)` is missing too
//!   (this is clamp-to-edge at image borders). A present pixel without samples counts 0.
//!
//! # Colour
//!
//! A colour film runs the cascade on each sample's luminance and splats the sample's RGB with
//! the same fractions: [`Zirr::push_split`] / [`Zirr::push_split`] push one luminance like
//! [`Estimator::push`] and return where it went ([`Splat`]); [`Zirr::weights`] and
//! [`Zirr::block_weights`] (and the same on [`Zirr`]) return the `w_j` the estimate applies
//! to the buffers, so the film's estimate is `Σ_j w_j·B_j(RGB)`. They change nothing in the
//! scalar method: a `push_split` makes the same additions as `push`, and the weights are those
//! the estimate composes with.

use super::numeric::{ScaledSum, ScaledSums};
use super::rgb::zirr_rgb;
use super::spec::fmt_f64;
use super::{
    CascadeSize, Estimator, EstimatorSpec, Extra, Extras, Key, Method, Neumaier, RgbEstimator,
};
use crate::error::Num;
use crate::error::{Error, Result};
use arrayvec::ArrayVec;
use std::fmt;

/// Parameters shared by `zirr` and `zirr-ref` (docs/estimators.md §5, §5a).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZirrParams {
    /// Cascade base `b > 1`.
    pub b: f64,
    /// Number of buffers.
    pub j: CascadeSize,
    /// Robustness `kappa > 0`.
    pub kappa: f64,
    /// Lone-firefly count threshold `kappa_min >= 0`.
    pub kappa_min: f64,
    /// Luminance unit `u > 0`: buffer j's reference brightness is `u * b^j`.
    pub u: f64,
}

impl ZirrParams {
    /// The paper method's defaults: `b = 8, J = auto, kappa = 1, kappa_min = 1, u = 1`.
    pub const PAPER: ZirrParams = ZirrParams {
        b: 8.0,
        j: CascadeSize::Auto,
        kappa: 1.0,
        kappa_min: 1.0,
        u: 1.0,
    };
    /// The released code's defaults: as [`ZirrParams::PAPER`] but `J = 6`.
    pub const REFERENCE: ZirrParams = ZirrParams {
        j: CascadeSize::Fixed(6),
        ..ZirrParams::PAPER
    };
}

/// A Zirr variant's spec type and its [`Method`] declaration: the keys `b, J, kappa,
/// kappa_min, u` (all optional), with the variant's defaults and whether `J = auto` parses.
macro_rules! zirr_spec {
    ($(#[$doc:meta])* $spec:ident, $name:literal, $defaults:expr, auto: $auto:literal, $build:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct $spec(pub ZirrParams);

        impl Method for $spec {
            const NAME: &'static str = $name;
            const KEYS: &'static [Key<Self>] = &[
                Key::float("b", |s| &mut s.0.b),
                Key::cascade("J", $auto, |s| &mut s.0.j),
                Key::float("kappa", |s| &mut s.0.kappa),
                Key::float("kappa_min", |s| &mut s.0.kappa_min),
                Key::float("u", |s| &mut s.0.u),
            ];
            const DEFAULT: Self = $spec($defaults);

            fn build(&self) -> Result<Box<dyn Estimator>> {
                Ok(Box::new($build(self.0)?))
            }

            fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
                Ok(zirr_rgb($build(self.0)?))
            }
        }
    };
}

zirr_spec!(
    /// `zirr:b=,J=,kappa=,kappa_min=,u=`, defaults [`ZirrParams::PAPER`] (`J = auto` allowed).
    ZirrSpec,
    "zirr",
    ZirrParams::PAPER,
    auto: true,
    Zirr::new
);
zirr_spec!(
    /// `zirr-ref:b=,J=,kappa=,kappa_min=,u=`, defaults [`ZirrParams::REFERENCE`] (`J` an
    /// integer).
    ZirrRefSpec,
    "zirr-ref",
    ZirrParams::REFERENCE,
    auto: false,
    Zirr::reference
);

/// The largest cascade (number of buffers) a parameter set may need; larger ones are rejected.
pub const MAX_BUFFERS: usize = 4096;

/// The smallest unit `u` whose reciprocal is finite (the subnormal just above `2^-1024`).
/// The splat computes `s = S/u` (docs/estimators.md §5), which overflows for samples above `u·f64::MAX`;
/// below this unit that bound is under 1, so ordinary samples would all land in the infinite
/// top buffer and be rejected (`zirr:u=5e-324` estimated 0 for a stream whose mean is 51.9).
/// Computing in sample units instead would change the spec's operation order, and with it
/// discrete decisions for ordinary units, so such units are rejected instead.
pub const MIN_UNIT: f64 = f64::from_bits(0x0004_0000_0000_0001);

/// Blocks at least this long run the unchecked loop (see [`Cascade::push_block`]); shorter
/// ones, single pushes above all, would spend more on the undo copy than they save.
const UNCHECKED_MIN: usize = 16;

/// Most buffers the unchecked loop's undo copy holds (16 bytes each, on the stack); longer
/// cascades take the checked additions.
const UNCHECKED_BUFFERS: usize = 256;

/// Relative tolerance of the at-most test `x ≼ κ_min` (docs/estimators.md §5).
const AT_MOST_TOLERANCE: f64 = 1e-9;

/// Floor of the running brightness in the released code's colour term, in units of `u`.
const REF_BRIGHTNESS_FLOOR: f64 = 0.05;

/// Which of the two variants a [`Zirr`] estimator is: the weighting that composes the buffers,
/// what the top buffer keeps, and how a 3×3 block averages the rejection counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flavor {
    /// \[Z\] eqs. 12–13 with the at-most rejection test (docs/estimators.md §5).
    Paper,
    /// The released shader's averaged count and colour terms (docs/estimators.md §5a).
    Reference,
}

/// Where one sample pushed through [`Zirr::push_split`] or [`Zirr::push_split`] went: the
/// hook that lets a colour film splat an RGB sample with the fractions of its luminance.
///
/// For a sample `S` (the luminance) and any other quantity `X` carried with it (one colour
/// channel), the buffers receive:
///
/// * [`Splat::Whole`]: `X` into buffer `j` (below `u`, a black sample, or over the top of a
///   fixed `zirr` cascade);
/// * [`Splat::Split`]: `a·X` into buffer `j` and `X − a·X` into buffer `j + 1` (\[Z\] eqs. 15–16,
///   the same operations the luminance itself went through);
/// * [`Splat::Clamped`]: `v·(X/S)` into buffer `j`, the top buffer of `zirr-ref`, which keeps
///   only `v = c_{J−1}` of the sample's `S` (docs/estimators.md §5a); the fraction `c_{J−1}/S` of `X` is kept
///   and the rest discarded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Splat {
    /// The whole sample went into buffer `j`.
    Whole {
        /// Buffer index.
        j: usize,
    },
    /// `a·S` went into buffer `j`, `S − a·S` into buffer `j + 1`.
    Split {
        /// Lower buffer index.
        j: usize,
        /// The lower buffer's fraction, in `[0, 1]`.
        a: f64,
    },
    /// Only `v < S` (or `v = S`) went into the top buffer `j`; the rest was discarded.
    Clamped {
        /// Buffer index (`J − 1`).
        j: usize,
        /// The energy kept, `c_{J−1}`.
        v: f64,
    },
}

/// The streaming state shared by both variants: `N`, the buffers `A_j` and the parameters.
#[derive(Debug, Clone)]
struct Cascade {
    /// Parameters as given (for `spec()`).
    params: ZirrParams,
    /// `ib = 1/b`, computed once exactly as the spec writes it.
    ib: f64,
    /// Most buffers this cascade may hold: `J` when fixed, `J_max` (see the module docs) for
    /// `J = auto`. The top index `limit − 1` takes every sample at or above `p_{limit−1}`.
    limit: usize,
    /// `N`: all samples, zeros included.
    n: u64,
    /// Samples with `s > p_{limit−1}`.
    over_range: u64,
    /// Neumaier accumulators `A_j`; always at least one; `limit` of them when `J` is fixed.
    /// Each is rescaled on its own before it would overflow, so `B_j` is finite for any finite
    /// samples (and bit-identical to the plain sum's whenever that is finite).
    a: ScaledSums,
}

/// Checks the parameters both variants share and returns the cascade limit.
fn check_common(p: &ZirrParams) -> Result<usize> {
    let ZirrParams {
        b,
        j,
        kappa,
        kappa_min,
        u,
    } = *p;
    if !(b > 1.0 && b.is_finite()) {
        return Err(Error::param("b", fmt_f64(b), "must be finite and > 1"));
    }
    if let CascadeSize::Fixed(j) = j {
        if j < 1 {
            return Err(Error::param("J", j, "must be at least 1 (or auto)"));
        }
        if j > MAX_BUFFERS {
            return Err(Error::param(
                "J",
                j,
                format!("at most {MAX_BUFFERS} buffers are allowed"),
            ));
        }
    }
    if !(kappa > 0.0 && kappa.is_finite()) {
        return Err(Error::param(
            "kappa",
            fmt_f64(kappa),
            "must be finite and > 0",
        ));
    }
    if !(kappa_min >= 0.0 && kappa_min.is_finite()) {
        return Err(Error::param(
            "kappa_min",
            fmt_f64(kappa_min),
            "must be finite and >= 0",
        ));
    }
    if !(u > 0.0 && u.is_finite()) {
        return Err(Error::param("u", fmt_f64(u), "must be finite and > 0"));
    }
    if !(u >= MIN_UNIT) {
        return Err(Error::param(
            "u",
            Num(u),
            format!(
                "must be in [{}, {}]: 1/u must be finite, else s = S/u overflows for every \
                 sample above u*f64::MAX = {} and the cascade rejects them all",
                Num(MIN_UNIT),
                Num(f64::MAX),
                Num(u * f64::MAX),
            ),
        ));
    }
    match j {
        CascadeSize::Fixed(j) => Ok(j),
        CascadeSize::Auto => auto_limit(b, u).ok_or_else(|| {
            Error::param(
                "b",
                fmt_f64(b),
                format!(
                    "with J = auto and u = {}, the cascade may need more than {MAX_BUFFERS} \
                     buffers (about log_b(f64::MAX/u) + 2); use a larger b or u, or a fixed J",
                    fmt_f64(u)
                ),
            )
        }),
    }
}

/// `J_max = j* + 2`, `j*` the largest `j` with `p_j` finite and `p_j ≤ f64::MAX/u`; `None` when
/// that exceeds [`MAX_BUFFERS`]. Requires a valid `b` and `u`.
fn auto_limit(b: f64, u: f64) -> Option<usize> {
    let lim = f64::MAX / u;
    let (mut j, mut p) = (0usize, 1.0f64);
    loop {
        let next = p * b;
        if !(next.is_finite() && next <= lim) {
            return Some(j + 2);
        }
        p = next;
        j += 1;
        if j + 2 > MAX_BUFFERS {
            return None;
        }
    }
}

/// Largest `j` in `0..=last` with `p_j ≤ s` (powers by repeated multiplication), and `p_j`;
/// `(0, 1)` when there is none (`s < 1` or NaN).
#[inline(always)]
fn locate(b: f64, last: usize, s: f64) -> (usize, f64) {
    let (mut j, mut p) = (0usize, 1.0f64);
    while j < last {
        let next = p * b;
        if next <= s {
            (p, j) = (next, j + 1);
        } else {
            break;
        }
    }
    (j, p)
}

/// Makes sure buffers `0..len` exist (only ever grows with `J = auto`).
#[inline(always)]
fn grow(buf: &mut ScaledSums, len: usize) {
    if buf.len() < len {
        grow_to(buf, len);
    }
}

#[cold]
#[inline(never)]
fn grow_to(buf: &mut ScaledSums, len: usize) {
    buf.grow(len);
}

/// Adds `v` to buffer `j`: with the checked addition when `CHECKED`, else with the plain one,
/// to the register copies of `A_0` and `A_1` or to the buffer itself.
#[inline(always)]
fn add_to<const CHECKED: bool>(
    buf: &mut ScaledSums,
    a0: &mut Neumaier,
    a1: &mut Neumaier,
    j: usize,
    v: f64,
) {
    match j {
        _ if CHECKED => buf.add(j, v),
        0 => a0.add(v),
        1 => a1.add(v),
        _ => buf.plain_mut()[j].add(v),
    }
}

/// `e + x`, saturated at `f64::MAX`. The composed estimate is at most `Σ_j B_j`, the mean of
/// finite samples, so it is at most `f64::MAX` in real arithmetic; only the rounding of a sum
/// of buffers near it can pass it, and `f64::MAX` is then the nearest value. A no-op otherwise.
#[inline(always)]
fn saturating_add(e: f64, x: f64) -> f64 {
    (e + x).min(f64::MAX)
}

impl Cascade {
    fn new(params: ZirrParams, limit: usize) -> Self {
        let len = match params.j {
            CascadeSize::Fixed(j) => j,
            CascadeSize::Auto => 1,
        };
        Cascade {
            params,
            ib: 1.0 / params.b,
            limit,
            n: 0,
            over_range: 0,
            a: ScaledSums::new(len),
        }
    }

    /// Pushes a block of samples (docs/estimators.md §5 "Splat", \[Z\] eqs. 15–16). A sample at or above the
    /// top buffer's reference brightness adds itself to the top buffer, or, with `discarded`
    /// (`zirr-ref`), adds `c_{limit−1}` there and the rest to `discarded`.
    ///
    /// Hot loop: `A_0` and `A_1`, which take nearly every sample, live in registers for the
    /// whole block (each accumulator still sees the same additions in the same order, so the
    /// result is bit-identical to pushing one sample at a time), and `s = S/u` is not divided
    /// when `u = 1` (`S/1 = S` exactly). Its additions are unchecked: the buffers are checked
    /// once after the block (they only grow, so one below the overflow limit never passed it),
    /// and in the rare case one did, the block is undone from a copy and pushed again with
    /// checked additions, which rescale that buffer. Short blocks (single pushes) and cascades
    /// with a rescaled buffer take the checked additions directly.
    #[inline(always)]
    fn push_block(&mut self, samples: &[f64], mut discarded: Option<&mut ScaledSum>) {
        if samples.len() >= UNCHECKED_MIN && !self.a.any_scaled() {
            let mut before = ArrayVec::<Neumaier, UNCHECKED_BUFFERS>::new();
            if before.try_extend_from_slice(self.a.plain_mut()).is_ok() {
                let (n, over_range) = (self.n, self.over_range);
                let kept = discarded.as_deref().copied();
                self.push_with::<false>(samples, discarded.as_deref_mut());
                let plain = self.a.plain_mut();
                if plain.iter().fold(true, |ok, acc| ok & acc.below_limit()) {
                    return;
                }
                self.a.truncate(before.len());
                self.a.plain_mut().copy_from_slice(&before);
                (self.n, self.over_range) = (n, over_range);
                if let (Some(d), Some(k)) = (discarded.as_deref_mut(), kept) {
                    *d = k;
                }
            }
        }
        self.push_with::<true>(samples, discarded);
    }

    #[inline(always)]
    fn push_with<const CHECKED: bool>(
        &mut self,
        samples: &[f64],
        discarded: Option<&mut ScaledSum>,
    ) {
        if self.params.u == 1.0 {
            self.push_block_with::<true, CHECKED>(samples, discarded);
        } else {
            self.push_block_with::<false, CHECKED>(samples, discarded);
        }
    }

    #[inline(always)]
    fn push_block_with<const UNIT: bool, const CHECKED: bool>(
        &mut self,
        samples: &[f64],
        mut discarded: Option<&mut ScaledSum>,
    ) {
        let (b, u, ib, limit) = (self.params.b, self.params.u, self.ib, self.limit);
        let mut over_range = self.over_range;
        let buf = &mut self.a;
        let (mut a0, mut a1) = if CHECKED {
            (Neumaier::new(), Neumaier::new())
        } else {
            (
                buf.plain(0).unwrap_or_default(),
                buf.plain(1).unwrap_or_default(),
            )
        };
        let mut rest_of = samples.iter();
        'block: loop {
            // Runs of samples below u only touch A_0: keep that loop tight.
            let (x, s) = loop {
                let Some(&x) = rest_of.next() else {
                    break 'block;
                };
                let s = if UNIT { x } else { x / u };
                if s < 1.0 {
                    add_to::<CHECKED>(buf, &mut a0, &mut a1, 0, x);
                } else {
                    break (x, s);
                }
            };
            let (j, p) = locate(b, limit - 1, s);
            if j + 1 == limit {
                // p = +inf only when s = S/u overflowed (see the module docs).
                if s > p || p == f64::INFINITY {
                    over_range += 1;
                }
                grow(buf, limit);
                let v = match discarded.as_deref_mut() {
                    Some(d) => {
                        let c = u * p;
                        d.add(x - c);
                        c
                    }
                    None => x,
                };
                add_to::<CHECKED>(buf, &mut a0, &mut a1, j, v);
                continue;
            }
            let a = ((p / s - ib) / (1.0 - ib)).max(0.0);
            let part = a * x;
            let rest = x - part;
            grow(buf, j + 2);
            match j {
                0 => {
                    add_to::<CHECKED>(buf, &mut a0, &mut a1, 0, part);
                    add_to::<CHECKED>(buf, &mut a0, &mut a1, 1, rest);
                }
                1 => {
                    add_to::<CHECKED>(buf, &mut a0, &mut a1, 1, part);
                    add_to::<CHECKED>(buf, &mut a0, &mut a1, 2, rest);
                }
                _ => {
                    add_to::<CHECKED>(buf, &mut a0, &mut a1, j, part);
                    add_to::<CHECKED>(buf, &mut a0, &mut a1, j + 1, rest);
                }
            }
        }
        if !CHECKED {
            let plain = buf.plain_mut();
            plain[0] = a0;
            if let Some(slot) = plain.get_mut(1) {
                *slot = a1;
            }
        }
        self.over_range = over_range;
        self.n += samples.len() as u64;
    }

    /// Pushes one sample exactly as [`Cascade::push_block`] would (the same additions to the
    /// same accumulators, so the buffers stay bit-identical to a block push) and tells where it
    /// went. `clamp_top` selects `zirr-ref`'s top buffer, which keeps `c_{J−1}` of the sample
    /// (the caller accounts for the discarded part).
    fn push_one(&mut self, x: f64, clamp_top: bool) -> Splat {
        let (b, u, ib, limit) = (self.params.b, self.params.u, self.ib, self.limit);
        // x/1 = x exactly, so this is push_block's s with or without the u = 1 shortcut.
        let s = x / u;
        self.n += 1;
        if s < 1.0 {
            self.a.add(0, x);
            return Splat::Whole { j: 0 };
        }
        let (j, p) = locate(b, limit - 1, s);
        if j + 1 == limit {
            if s > p || p == f64::INFINITY {
                self.over_range += 1;
            }
            grow(&mut self.a, limit);
            if clamp_top {
                let v = u * p;
                self.a.add(j, v);
                return Splat::Clamped { j, v };
            }
            self.a.add(j, x);
            return Splat::Whole { j };
        }
        let a = ((p / s - ib) / (1.0 - ib)).max(0.0);
        let part = a * x;
        let rest = x - part;
        grow(&mut self.a, j + 2);
        self.a.add(j, part);
        self.a.add(j + 1, rest);
        Splat::Split { j, a }
    }

    /// The weights `w_j`, one per buffer, that [`Cascade::compose`] gives with the rejection
    /// counts `rho` (the pixel's own counts when `None`). Requires `N > 0`.
    fn weights(&self, flavor: Flavor, rho: Option<&[f64]>) -> Vec<f64> {
        let mut w = Vec::with_capacity(self.a.len());
        self.compose(
            flavor,
            |j, nj| rho.map_or(nj, |r| r[j]),
            |_, _, _, wj| w.push(wj),
        );
        w
    }

    /// Calls `f(j, B_j, n_j, c_j)` for `j` in `0..len` (docs/estimators.md §5 "Buffers", "Counts", eq. 19),
    /// with `n_j = N·(B_{j−1}/c_{j−1} + B_j/c_j + B_{j+1}/c_{j+1})` summed left to right and
    /// terms past the cascade limit omitted. Buffers not grown yet (`J = auto`) are zeros.
    /// Requires `N > 0` and `len ≤ limit`.
    #[inline]
    fn for_each_row(&self, len: usize, mut f: impl FnMut(usize, f64, f64, f64)) {
        let nf = self.n as f64;
        let (b, u) = (self.params.b, self.params.u);
        let buffer = |j: usize| {
            if j < self.a.len() {
                self.a.mean(j, nf)
            } else {
                0.0
            }
        };
        let mut p = 1.0f64;
        let mut c = u * p;
        let mut bj = buffer(0);
        let mut q = bj / c;
        let mut q_prev = 0.0f64;
        for j in 0..len {
            let p_next = p * b;
            let c_next = u * p_next;
            let b_next = buffer(j + 1);
            let q_next = b_next / c_next;
            let mut sum = if j > 0 { q_prev + q } else { q };
            if j + 1 < self.limit {
                sum += q_next;
            }
            f(j, bj, nf * sum, c);
            q_prev = q;
            (p, c, bj, q) = (p_next, c_next, b_next, q_next);
        }
    }

    /// The counts `n_j`, `j` in `0..len` (all 0 without samples).
    fn counts(&self, len: usize) -> Vec<f64> {
        let mut out = vec![0.0; len];
        if self.n > 0 {
            self.for_each_row(len, |j, _, n, _| out[j] = n);
        }
        out
    }

    /// Composes the buffers (docs/estimators.md §5 "Compose" or §5a "Weight") with rejection counts
    /// `rho(j, n_j)`, calling `record(B_j, n_j, ρ_j, w_j)` per buffer; returns the estimate.
    /// Requires `N > 0`.
    #[inline]
    fn compose(
        &self,
        flavor: Flavor,
        rho: impl Fn(usize, f64) -> f64,
        mut record: impl FnMut(f64, f64, f64, f64),
    ) -> f64 {
        let ZirrParams {
            b,
            kappa,
            kappa_min,
            u,
            ..
        } = self.params;
        let nf = self.n as f64;
        let mut e = 0.0f64;
        match flavor {
            Flavor::Paper => {
                let bound = kappa_min + AT_MOST_TOLERANCE * kappa_min.max(1.0);
                self.for_each_row(self.a.len(), |j, bj, nj, cj| {
                    let r_c = if nj <= bound {
                        f64::INFINITY
                    } else {
                        nf / (nj - kappa_min)
                    };
                    let r_v = if e == 0.0 { f64::INFINITY } else { cj / e };
                    let r = r_c.min(r_v);
                    let mut w = if r == f64::INFINITY {
                        0.0
                    } else {
                        (nf / (kappa * r)).min(1.0)
                    };
                    let rho_j = rho(j, nj);
                    if rho_j <= bound {
                        w = 0.0;
                    }
                    e = saturating_add(e, w * bj);
                    record(bj, nj, rho_j, w);
                });
            }
            Flavor::Reference => {
                let a = (1.0 / kappa).min(1.0);
                let colour = (0.4 + 0.6 * b) * (1.0 - a) + a;
                let floor = REF_BRIGHTNESS_FLOOR * u;
                self.for_each_row(self.a.len(), |j, bj, nj, cj| {
                    let rho_j = rho(j, nj);
                    let r_loc = nj / kappa;
                    let r_glob = rho_j / kappa;
                    let mut rel = r_glob - 1.0 / kappa;
                    if rel >= 0.0 {
                        rel = r_loc - 1.0 / kappa;
                    }
                    let mut col = e.max(floor) * nf / (kappa * cj) * colour;
                    if !(col.is_finite() && (kappa * cj).is_finite()) {
                        // The spec's order overflowed (E·N or κ·c_j above f64::MAX): the same
                        // quantity in an order that does not (+inf only if it truly is).
                        col = e.max(floor) / cj * (nf / kappa) * colour;
                    }
                    // Not f64::clamp, which keeps NaN: a NaN weight counts as 0.
                    let half = (rel + col) / 2.0;
                    let w = if half >= 0.0 { half.min(1.0) } else { 0.0 };
                    e = saturating_add(e, w * bj);
                    record(bj, nj, rho_j, w);
                });
            }
        }
        e
    }

    /// The estimate and its extras (`J_used`, `over_range`, `B`, `n`, `rho`, `w`), with the
    /// rejection counts `rho` (one per buffer) or the pixel's own counts when `None`.
    fn report(&self, flavor: Flavor, rho: Option<&[f64]>) -> (f64, Extras) {
        let len = self.a.len();
        let (mut bs, mut ns, mut rhos, mut ws) = (
            Vec::with_capacity(len),
            Vec::with_capacity(len),
            Vec::with_capacity(len),
            Vec::with_capacity(len),
        );
        let estimate = if self.n == 0 {
            for v in [&mut bs, &mut ns, &mut rhos, &mut ws] {
                v.resize(len, 0.0);
            }
            f64::NAN
        } else {
            self.compose(
                flavor,
                |j, nj| rho.map_or(nj, |r| r[j]),
                |bj, nj, rj, wj| {
                    bs.push(bj);
                    ns.push(nj);
                    rhos.push(rj);
                    ws.push(wj);
                },
            )
        };
        let extras = vec![
            ("J_used", Extra::Int(len as u64)),
            ("over_range", Extra::Int(self.over_range)),
            ("B", Extra::Floats(bs)),
            ("counts", Extra::Floats(ns)),
            ("rho", Extra::Floats(rhos)),
            ("w", Extra::Floats(ws)),
        ];
        (estimate, extras)
    }

    fn state_bytes(&self) -> usize {
        self.a.heap_bytes()
    }

    fn reset(&mut self) {
        let keep = match self.params.j {
            CascadeSize::Auto => 1,
            CascadeSize::Fixed(_) => self.a.len(),
        };
        self.a.reset(keep);
        self.n = 0;
        self.over_range = 0;
    }

    fn write_params(&self, f: &mut fmt::Formatter<'_>, with_kappa_min: bool) -> fmt::Result {
        let p = &self.params;
        write!(f, "b={},J=", fmt_f64(p.b))?;
        match p.j {
            CascadeSize::Auto => write!(f, "auto")?,
            CascadeSize::Fixed(j) => write!(f, "{j}")?,
        }
        write!(f, ",kappa={}", fmt_f64(p.kappa))?;
        if with_kappa_min && p.kappa_min != 1.0 {
            write!(f, ",kappa_min={}", fmt_f64(p.kappa_min))?;
        }
        if p.u != 1.0 {
            write!(f, ",u={}", fmt_f64(p.u))?;
        }
        Ok(())
    }
}

/// Checks a 3×3 block (centre present with samples, equal flavours and parameters) and returns
/// the centre.
fn check_block<'a>(block: &[Option<&'a Zirr>; 9]) -> Result<&'a Zirr> {
    fn cascade(z: &Zirr) -> &Cascade {
        &z.c
    }
    let Some(centre) = block[4] else {
        return Err(Error::param(
            "block index",
            4,
            "the centre of a 3x3 block must be a pixel inside the image",
        ));
    };
    if cascade(centre).n == 0 {
        return Err(Error::EmptyStream(format!(
            "{centre} at the centre of a 3x3 block"
        )));
    }
    for (i, px) in block.iter().enumerate() {
        let Some(px) = px else { continue };
        if px.flavor() != centre.flavor() {
            return Err(Error::param(
                "block index",
                i,
                format!(
                    "pixel {i} is {px} but the centre is {centre}; all pixels of a block \
                     must be the same variant (zirr or zirr-ref)"
                ),
            ));
        }
        if cascade(px).params != cascade(centre).params {
            return Err(Error::param(
                "block index",
                i,
                format!(
                    "pixel {i} is {px} but the centre is {centre}; all pixels of a block \
                     must share b, J, kappa, kappa_min and u"
                ),
            ));
        }
    }
    Ok(centre)
}

/// Zirr et al.'s cascade reweighting, in either variant ([`Flavor`]): as in the paper
/// (docs/estimators.md §5, spec string `zirr`, [`Zirr::new`]) or as in the authors' released
/// code (docs/estimators.md §5a, spec string `zirr-ref`, [`Zirr::reference`]).
///
/// Extras, in order: `J_used`, `over_range`, `B`, `n`, `rho`, `w` (see the module docs); the
/// released-code variant adds `discarded`: the energy above `c_{J−1}` dropped at the top buffer,
/// `Σ (S − c_{J−1}) / N` over the samples with `S/u ≥ p_{J−1}` — a per-sample mean like `B`, so
/// `Σ B_j + discarded` is the plain mean.
#[derive(Debug, Clone)]
pub struct Zirr {
    c: Cascade,
    /// The released code's discarded energy, rescaled before it overflows like the buffers;
    /// `None` in the paper's variant (its presence is the flavour, so the paper's per-pixel
    /// state grows by one sum's size only).
    discarded: Option<ScaledSum>,
}

impl Zirr {
    /// The paper's variant. Checked constructor: `b > 1`, `kappa > 0`, `kappa_min ≥ 0`,
    /// `u > 0`, all finite; `J = auto` or a fixed `J` in `1..=4096`; with `J = auto` the
    /// cascade limit `log_b(f64::MAX/u) + 2` must be at most [`MAX_BUFFERS`]. Never panics.
    pub fn new(p: ZirrParams) -> Result<Self> {
        Self::with_flavor(Flavor::Paper, p)
    }

    /// The released code's variant. Checked constructor: as [`Zirr::new`], and moreover `J`
    /// fixed and at least 2, `kappa_min = 1`, and `u·b^(J−1)` finite. Never panics.
    pub fn reference(p: ZirrParams) -> Result<Self> {
        Self::with_flavor(Flavor::Reference, p)
    }

    /// Either variant, checking its parameters as [`Zirr::new`] or [`Zirr::reference`] do.
    pub fn with_flavor(flavor: Flavor, p: ZirrParams) -> Result<Self> {
        if flavor == Flavor::Reference {
            check_reference(&p)?;
        }
        let limit = check_common(&p)?;
        if flavor == Flavor::Reference {
            check_reference_top(&p)?;
        }
        Ok(Zirr {
            c: Cascade::new(p, limit),
            discarded: (flavor == Flavor::Reference).then(ScaledSum::new),
        })
    }

    /// The parameters.
    pub fn params(&self) -> ZirrParams {
        self.c.params
    }

    /// The variant.
    pub fn flavor(&self) -> Flavor {
        match self.discarded {
            None => Flavor::Paper,
            Some(_) => Flavor::Reference,
        }
    }

    /// The estimate of the centre pixel of a 3×3 block (row-major, index 4 the centre, `None`
    /// outside the image), with the rejection counts `ρ_j` averaged over the block (\[Z\]
    /// §5.3.1; see the module docs), and the centre's extras with that `rho`. The paper's
    /// variant averages over the present pixels that have samples; the released code's, as its
    /// shader, sums nine counts over 9, with clamp-to-edge substitution for missing pixels and 0
    /// for present pixels without samples (docs/estimators.md §5a). Errors when the centre is
    /// missing or empty, or when a pixel's variant or parameters differ from the centre's
    /// (naming its index).
    pub fn block_estimate(block: &[Option<&Self>; 9]) -> Result<(f64, Extras)> {
        let (centre, rho) = Self::block_rho(block)?;
        let (estimate, mut extras) = centre.c.report(centre.flavor(), Some(&rho));
        centre.push_discarded(&mut extras);
        Ok((estimate, extras))
    }

    /// Pushes one sample (the same as [`Estimator::push`]) and tells which buffers received
    /// which fractions of it: the hook for a colour film that splats each RGB sample with the
    /// fractions of its luminance (see [`Splat`]). In the released code's variant a sample at
    /// or over the top buffer's reference brightness comes back as [`Splat::Clamped`].
    pub fn push_split(&mut self, sample: f64) -> Splat {
        let splat = self.c.push_one(sample, self.discarded.is_some());
        if let (Splat::Clamped { v, .. }, Some(d)) = (splat, &mut self.discarded) {
            d.add(sample - v);
        }
        splat
    }

    /// The weights `w_j` of the estimate, one per buffer of the cascade (`J_used` of them): the
    /// estimate is `Σ_j w_j·B_j`, summed in ascending `j`. Errors without samples.
    pub fn weights(&self) -> Result<Vec<f64>> {
        if self.c.n == 0 {
            return Err(super::empty(self));
        }
        Ok(self.c.weights(self.flavor(), None))
    }

    /// The weights `w_j` of [`Zirr::block_estimate`]'s estimate for the centre of the block,
    /// one per buffer of the centre's cascade. Errors as [`Zirr::block_estimate`].
    pub fn block_weights(block: &[Option<&Self>; 9]) -> Result<Vec<f64>> {
        let (centre, rho) = Self::block_rho(block)?;
        Ok(centre.c.weights(centre.flavor(), Some(&rho)))
    }

    /// The checked centre of a block and its rejection counts `ρ_j`.
    fn block_rho<'a>(block: &[Option<&'a Self>; 9]) -> Result<(&'a Self, Vec<f64>)> {
        let centre = check_block(block)?;
        let len = centre.c.a.len();
        let rho = match centre.flavor() {
            Flavor::Paper => paper_rho(block, len),
            Flavor::Reference => reference_rho(block, len),
        };
        Ok((centre, rho))
    }

    /// Appends `discarded` to the extras in the released code's variant.
    fn push_discarded(&self, extras: &mut Extras) {
        if let Some(d) = &self.discarded {
            let mean = if self.c.n == 0 { 0.0 } else { d.mean(self.c.n) };
            extras.push(("discarded", Extra::Float(mean)));
        }
    }
}

/// zirr-ref's own rules on J, checked before the common ones so its messages never suggest
/// `auto`.
fn check_reference(p: &ZirrParams) -> Result<()> {
    let CascadeSize::Fixed(j) = p.j else {
        return Err(Error::param(
            "J",
            "auto",
            "zirr-ref needs a fixed integer J (the released code's cascade is fixed)",
        ));
    };
    if j < 2 {
        return Err(Error::param(
            "J",
            j,
            format!("zirr-ref needs an integer J in 2..={MAX_BUFFERS}"),
        ));
    }
    Ok(())
}

/// zirr-ref's rules after the common ones: `kappa_min = 1` and a finite top reference
/// brightness `u·b^(J−1)`.
fn check_reference_top(p: &ZirrParams) -> Result<()> {
    if p.kappa_min != 1.0 {
        return Err(Error::param(
            "kappa_min",
            fmt_f64(p.kappa_min),
            "must be 1 for zirr-ref (the released code has no separate threshold)",
        ));
    }
    let CascadeSize::Fixed(j) = p.j else {
        return Ok(());
    };
    let mut top = 1.0f64;
    for _ in 1..j {
        top *= p.b;
    }
    if !(p.u * top).is_finite() {
        return Err(Error::param(
            "J",
            j,
            format!(
                "the top buffer's reference brightness u*b^(J-1) overflows f64 with b = {} \
                 and u = {}",
                fmt_f64(p.b),
                fmt_f64(p.u)
            ),
        ));
    }
    Ok(())
}

/// The paper's `ρ_j`: the counts averaged over the present pixels that have samples.
fn paper_rho(block: &[Option<&Zirr>; 9], len: usize) -> Vec<f64> {
    let mut sum = vec![0.0f64; len];
    let mut pixels = 0usize;
    for px in block.iter().flatten() {
        if px.c.n == 0 {
            continue;
        }
        pixels += 1;
        px.c.for_each_row(len, |j, _, n, _| sum[j] += n);
    }
    sum.iter().map(|s| s / pixels as f64).collect()
}

/// The released shader's `ρ_j`: nine counts over 9, missing pixels replaced clamp-to-edge.
fn reference_rho(block: &[Option<&Zirr>; 9], len: usize) -> Vec<f64> {
    let present = block.map(|px| px.is_some());
    let column = |dx: usize| present[dx] || present[3 + dx] || present[6 + dx];
    let row = |dy: usize| present[3 * dy] || present[3 * dy + 1] || present[3 * dy + 2];
    let counts: [Option<Vec<f64>>; 9] = block.map(|px| px.map(|z| z.c.counts(len)));
    let mut sum = vec![0.0f64; len];
    for k in 0..9 {
        let source = if present[k] {
            k
        } else {
            let (dx, dy) = (k % 3, k / 3);
            let dx = if column(dx) { dx } else { 1 };
            let dy = if row(dy) { dy } else { 1 };
            let s = 3 * dy + dx;
            if present[s] { s } else { 4 }
        };
        if let Some(n) = &counts[source] {
            for (acc, v) in sum.iter_mut().zip(n) {
                *acc += v;
            }
        }
    }
    sum.iter().map(|s| s / 9.0).collect()
}

impl fmt::Display for Zirr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.flavor() {
            Flavor::Paper => write!(f, "Zirr(")?,
            Flavor::Reference => write!(f, "Zirr-ref(")?,
        }
        self.c.write_params(f, self.flavor() == Flavor::Paper)?;
        write!(f, ")")
    }
}

impl Estimator for Zirr {
    #[inline]
    fn push(&mut self, sample: f64) {
        self.push_slice(std::slice::from_ref(&sample));
    }

    fn push_slice(&mut self, samples: &[f64]) {
        match &mut self.discarded {
            None => self.c.push_block(samples, None),
            Some(d) => self.c.push_block(samples, Some(d)),
        }
    }

    fn count(&self) -> u64 {
        self.c.n
    }

    fn estimate(&self) -> Result<f64> {
        if self.c.n == 0 {
            return Err(super::empty(self));
        }
        Ok(self.c.compose(self.flavor(), |_, n| n, |_, _, _, _| {}))
    }

    fn extras(&self) -> Extras {
        let mut extras = self.c.report(self.flavor(), None).1;
        self.push_discarded(&mut extras);
        extras
    }

    fn state_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.c.state_bytes()
    }

    fn spec(&self) -> EstimatorSpec {
        match self.flavor() {
            Flavor::Paper => ZirrSpec(self.c.params).into(),
            Flavor::Reference => ZirrRefSpec(self.c.params).into(),
        }
    }

    fn reset(&mut self) {
        self.c.reset();
        if let Some(d) = &mut self.discarded {
            *d = ScaledSum::new();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RUNNING: [f64; 7] = [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1];

    fn fixed(j: usize) -> ZirrParams {
        ZirrParams {
            j: CascadeSize::Fixed(j),
            ..ZirrParams::PAPER
        }
    }

    fn floats(extras: &Extras, key: &str) -> Vec<f64> {
        match extras.iter().find(|(k, _)| *k == key) {
            Some((_, Extra::Floats(v))) => v.clone(),
            other => panic!("no Floats extra {key}: {other:?}"),
        }
    }

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * a.abs().max(b.abs()) || a == b
    }

    #[test]
    fn locate_finds_the_largest_power_below() {
        assert_eq!(locate(8.0, 5, 1.0), (0, 1.0));
        assert_eq!(locate(8.0, 5, 7.999), (0, 1.0));
        assert_eq!(locate(8.0, 5, 8.0), (1, 8.0));
        assert_eq!(locate(8.0, 5, 350.0), (2, 64.0));
        assert_eq!(locate(8.0, 5, 1e9), (5, 32768.0));
        assert_eq!(locate(8.0, 5, f64::INFINITY), (5, 32768.0));
        assert_eq!(locate(8.0, 0, 1e9), (0, 1.0));
    }

    #[test]
    fn auto_limit_counts_finite_powers() {
        // 8^341 ≈ 4.0e307 is the largest finite power of 8 below f64::MAX.
        assert_eq!(auto_limit(8.0, 1.0), Some(343));
        assert_eq!(auto_limit(2.0, 1.0), Some(1025));
        // u = f64::MAX: only p_0 = 1 fits, so buffers 0 and 1.
        assert_eq!(auto_limit(8.0, f64::MAX), Some(2));
        assert_eq!(auto_limit(1.01, 1.0), None);
    }

    #[test]
    fn running_example_buffers_counts_and_estimate() {
        let mut z = Zirr::new(fixed(6)).unwrap();
        z.push_slice(&RUNNING);
        let e = z.extras();
        let a: Vec<f64> = floats(&e, "B").iter().map(|b| b * 7.0).collect();
        let want_a = [3.371429, 9.828571, 23.142857, 326.857143, 0.0, 0.0];
        for (x, w) in a.iter().zip(want_a) {
            assert!((x - w).abs() < 1e-6, "{a:?}");
        }
        let n = floats(&e, "counts");
        let want_n = [4.6, 4.961607, 2.228571, 1.0, 0.638393, 0.0];
        for (x, w) in n.iter().zip(want_n) {
            assert!((x - w).abs() < 1e-6, "{n:?}");
        }
        assert!(close(z.estimate().unwrap(), 5.191836734693878, 1e-12));
    }

    #[test]
    fn reference_example() {
        let mut z = Zirr::reference(ZirrParams::REFERENCE).unwrap();
        z.push_slice(&RUNNING);
        assert!(close(z.estimate().unwrap(), 5.616560523284569, 1e-12));
    }

    #[test]
    fn push_and_push_slice_agree_bit_for_bit() {
        let xs = [0.3, 9.0, 1e6, 0.0, 2.5, 64.0, 1e-3, 7e4];
        for p in [ZirrParams::PAPER, fixed(3), fixed(1)] {
            let (mut a, mut b) = (Zirr::new(p).unwrap(), Zirr::new(p).unwrap());
            a.push_slice(&xs);
            xs.iter().for_each(|&x| b.push(x));
            assert_eq!(a.extras(), b.extras());
        }
    }

    #[test]
    fn push_split_is_push_and_weights_are_the_composed_ones() {
        // Below u, split, exact powers, over the top of fixed cascades, and u != 1.
        let xs = [0.3, 9.0, 1e6, 0.0, 2.5, 64.0, 1e-3, 7e4, 8.0, 32768.0, 4e5];
        let u_half = ZirrParams { u: 0.5, ..fixed(4) };
        for p in [ZirrParams::PAPER, fixed(3), fixed(1), u_half] {
            let (mut a, mut b) = (Zirr::new(p).unwrap(), Zirr::new(p).unwrap());
            a.push_slice(&xs);
            for &x in &xs {
                match b.push_split(x) {
                    Splat::Whole { .. } | Splat::Split { .. } => {}
                    Splat::Clamped { .. } => panic!("zirr never clamps"),
                }
            }
            assert_eq!(a.extras(), b.extras());
            assert_eq!(b.weights().unwrap(), floats(&a.extras(), "w"));
            let block = [None, None, None, None, Some(&a), None, None, Some(&b), None];
            assert_eq!(
                Zirr::block_weights(&block).unwrap(),
                floats(&Zirr::block_estimate(&block).unwrap().1, "w")
            );
        }
        for p in [
            ZirrParams::REFERENCE,
            ZirrParams {
                u: 0.5,
                ..ZirrParams::REFERENCE
            },
        ] {
            let (mut a, mut b) = (Zirr::reference(p).unwrap(), Zirr::reference(p).unwrap());
            a.push_slice(&xs);
            let mut clamped = 0;
            for &x in &xs {
                if let Splat::Clamped { v, .. } = b.push_split(x) {
                    assert!(v <= x);
                    clamped += 1;
                }
            }
            assert!(clamped > 0);
            assert_eq!(a.extras(), b.extras());
            assert_eq!(b.weights().unwrap(), floats(&b.extras(), "w"));
            let block = [Some(&b), None, None, None, Some(&a), None, None, None, None];
            assert_eq!(
                Zirr::block_weights(&block).unwrap(),
                floats(&Zirr::block_estimate(&block).unwrap().1, "w")
            );
        }
        assert!(Zirr::new(ZirrParams::PAPER).unwrap().weights().is_err());
    }

    #[test]
    fn reset_forgets_samples_and_keeps_params() {
        let mut z = Zirr::new(ZirrParams::PAPER).unwrap();
        z.push_slice(&RUNNING);
        z.reset();
        assert_eq!(z.count(), 0);
        assert!(z.estimate().is_err());
        z.push_slice(&RUNNING);
        let mut fresh = Zirr::new(ZirrParams::PAPER).unwrap();
        fresh.push_slice(&RUNNING);
        assert_eq!(z.extras(), fresh.extras());
    }
}
