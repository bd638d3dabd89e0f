//! Compensated summation and running moments shared by the estimators.
//!
//! # Overflow
//!
//! The mean of finite samples is finite, but their sum need not be: three samples of `1e308`
//! sum to `+inf`. The sums here therefore keep their running value below [`SUM_LIMIT`]
//! (`2^1023`): a sum that would reach it is rescaled once by `2^-SUM_SHIFT` (`2^-128`), and so
//! is every later term. Scaling by a power of two is exact, so the rescaled sum performs the
//! same roundings as the plain one would with an unlimited exponent range, and a mean read
//! from it is bit-identical to the plain mean whenever that one is finite. One step suffices
//! for ever: `n < 2^64` terms of at most `f64::MAX < 2^1024` sum to less than `2^1088`, which
//! scaled is below `2^960`. The price is that, inside a sum that has reached `2^1023`, terms
//! below `2^-946` (about `1e-285`) lose their low bits — far below one rounding of that sum.
//!
//! The common case costs nothing per term where it matters: the estimators' block loops add
//! with the plain [`Neumaier::add`] and check afterwards that the running sums stayed below
//! the limit (sums of non-negative terms never decrease, so a final value below the limit
//! proves that no partial sum reached it), undoing the block from a copy in the rare case one
//! did; a MoN block shorter than one round, which adds one term to each sum it touches,
//! checks each `s + x` before instead. Single pushes check each addition, with one
//! comparison.

use wide::f64x4;

/// Plain running sums are kept below this magnitude, `2^1023`; see the module docs.
const SUM_LIMIT: f64 = f64::from_bits(0x7FE0_0000_0000_0000);

/// A stream of non-negative terms whose plain total ([`plain_total`] of every block, summed)
/// stays below this, `2^1020`, cannot take any compensated sum of some of its terms to
/// [`SUM_LIMIT`]: a running sum exceeds the exact sum of its terms by a factor of at most
/// `1 + nε`, and so does the exact total the plain one, which leaves a factor of 8 to spare for
/// any `n < 2^50`. Block loops below it need neither an undo copy nor a check.
pub(crate) const SAFE_TOTAL: f64 = f64::from_bits(0x7FB0_0000_0000_0000);

/// Plain sum of a block of non-negative finite terms ([`lane_sum`], which vectorises; its
/// order differs from a sequential sum, which does not matter for a bound): within a factor
/// `1 ± nε` of the exact sum, or `+inf` if it overflows.
#[inline]
pub(crate) fn plain_total(terms: &[f64]) -> f64 {
    lane_sum(terms, |x| x)
}

/// A rescaled sum holds its terms times `2^-SUM_SHIFT`.
const SUM_SHIFT: i32 = 128;

/// `2^-SUM_SHIFT`.
const SUM_DOWN: f64 = f64::from_bits(((1023 - SUM_SHIFT) as u64) << 52);

/// `2^SUM_SHIFT`.
const SUM_UP: f64 = f64::from_bits(((1023 + SUM_SHIFT) as u64) << 52);

/// Neumaier's compensated sum (docs/estimators.md §1): exact to about one rounding for long streams of
/// samples that differ in magnitude by many decades, where a naive sum loses the small ones.
///
/// A bare `Neumaier` overflows like any float sum; the estimators wrap theirs in a sum that
/// rescales itself by a power of two before its running value reaches `2^1023`, so their
/// means stay finite.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Neumaier {
    sum: f64,
    compensation: f64,
}

impl Neumaier {
    /// An empty sum.
    pub const fn new() -> Self {
        Neumaier {
            sum: 0.0,
            compensation: 0.0,
        }
    }

    /// Adds `x`, carrying the low-order bits lost by the naive sum into the compensation.
    #[inline(always)]
    pub fn add(&mut self, x: f64) {
        let t = self.sum + x;
        self.step(t, x);
    }

    /// [`Neumaier::add`] of `x ≥ 0` (or `-0`) to a sum of such terms: the same result, since
    /// then both magnitudes are the values themselves, without taking them.
    #[inline(always)]
    pub(crate) fn add_nonneg(&mut self, x: f64) {
        debug_assert!(x >= 0.0 && self.sum >= 0.0);
        let t = self.sum + x;
        self.settle(t, x, self.sum >= x);
    }

    /// The update of [`Neumaier::add`] once `t = s + x` is known.
    #[inline(always)]
    fn step(&mut self, t: f64, x: f64) {
        self.settle(t, x, self.sum.abs() >= x.abs());
    }

    /// Carries what `t = s + x` lost into the compensation, `sum_larger` saying which of `s`
    /// and `x` is larger in magnitude, and makes `t` the running sum.
    #[inline(always)]
    fn settle(&mut self, t: f64, x: f64, sum_larger: bool) {
        if sum_larger {
            self.compensation += (self.sum - t) + x;
        } else {
            self.compensation += (x - t) + self.sum;
        }
        self.sum = t;
    }

    /// Adds `x` as [`Neumaier::add`] does, unless the running sum would reach [`SUM_LIMIT`]
    /// in magnitude (or `x` is not finite): then it changes nothing and returns `false`.
    #[inline(always)]
    pub(crate) fn try_add(&mut self, x: f64) -> bool {
        let t = self.sum + x;
        if !(t.abs() < SUM_LIMIT) {
            return false;
        }
        self.step(t, x);
        true
    }

    /// Whether [`Neumaier::add`]`(x)` would keep the running sum below [`SUM_LIMIT`] in
    /// magnitude (the test of [`Neumaier::try_add`], without the addition).
    #[inline(always)]
    pub(crate) fn fits_with(&self, x: f64) -> bool {
        (self.sum + x).abs() < SUM_LIMIT
    }

    /// Whether the running sum is below [`SUM_LIMIT`] in magnitude (false once it overflowed).
    /// After adding non-negative terms with [`Neumaier::add`], this proves that no partial sum
    /// reached the limit, since such sums never decrease.
    #[inline(always)]
    pub(crate) fn below_limit(&self) -> bool {
        self.sum.abs() < SUM_LIMIT
    }

    /// The compensated total `s + c`.
    #[inline]
    pub fn value(&self) -> f64 {
        self.sum + self.compensation
    }

    /// Adds another compensated sum (for merging partial sums).
    pub fn merge(&mut self, other: &Neumaier) {
        self.add(other.sum);
        self.add(other.compensation);
    }

    /// Adds `x` to a sum that is rescaled (`*scaled`) or must become so because `x` would
    /// carry it to [`SUM_LIMIT`]. Off the common path.
    #[cold]
    #[inline(never)]
    fn add_scaled(&mut self, scaled: &mut bool, x: f64) {
        if !*scaled {
            // Exact: both parts are far above the subnormal range, or negligible beside it.
            self.sum *= SUM_DOWN;
            self.compensation *= SUM_DOWN;
            *scaled = true;
        }
        self.add(x * SUM_DOWN);
    }

    /// `value / count`, undoing the rescaling (saturated at `f64::MAX`: the true mean of
    /// finite terms is at most the largest of them, so `f64::MAX` is the nearest value to it
    /// when the rounded quotient lands just above).
    #[inline]
    fn mean_of(&self, scaled: bool, count: f64) -> f64 {
        let m = self.value() / count;
        if scaled {
            (m * SUM_UP).min(f64::MAX)
        } else {
            m
        }
    }
}

/// A [`Neumaier`] sum that cannot overflow: it rescales itself by `2^-128` when its running
/// value would reach `2^1023` (see the module docs). Until then it is bit-identical to a
/// bare [`Neumaier`] sum.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct ScaledSum {
    acc: Neumaier,
    /// The accumulator holds the terms times `2^-SUM_SHIFT`.
    scaled: bool,
}

impl ScaledSum {
    /// An empty sum.
    pub(crate) const fn new() -> Self {
        ScaledSum {
            acc: Neumaier::new(),
            scaled: false,
        }
    }

    /// Adds one finite term of any sign; one comparison beyond the plain addition.
    #[inline(always)]
    pub(crate) fn add(&mut self, x: f64) {
        if self.scaled || !self.acc.try_add(x) {
            self.acc.add_scaled(&mut self.scaled, x);
        }
    }

    /// Adds finite, **non-negative** terms in order; same result as [`ScaledSum::add`] on each.
    /// The loop is the plain compensated sum; the limit is checked once at the end (the sum
    /// never decreases), and only if it was passed is the block redone term by term.
    #[inline(always)]
    pub(crate) fn add_all(&mut self, terms: impl Iterator<Item = f64> + Clone) {
        if !self.scaled {
            // The undo copy is taken field by field (black_box keeps the compiler from merging
            // the two loads): one 16-byte load of a pair that the previous block stored as two
            // 8-byte halves would stall on store forwarding, a cost short blocks notice.
            let sum = std::hint::black_box(self.acc.sum);
            let compensation = std::hint::black_box(self.acc.compensation);
            for x in terms.clone() {
                self.acc.add(x);
            }
            if self.acc.below_limit() {
                return;
            }
            self.acc = Neumaier { sum, compensation };
        }
        self.add_each(terms);
    }

    /// [`ScaledSum::add`] on each term: `add_all`'s fallback, kept out of line so that the
    /// common path stays a small function.
    #[cold]
    #[inline(never)]
    fn add_each(&mut self, terms: impl Iterator<Item = f64>) {
        for x in terms {
            self.add(x);
        }
    }

    /// The sum divided by `count` (`count > 0`): finite, and bit-identical to
    /// `Neumaier::value() / count` whenever that is finite.
    #[inline]
    pub(crate) fn mean(&self, count: u64) -> f64 {
        self.acc.mean_of(self.scaled, count as f64)
    }
}

/// [`ScaledSum::add_all`] of channel `c` of every sample to `sums[c]`, for the three channels
/// of an RGB stream (finite, non-negative terms): bit for bit the three calls, with the three
/// running sums and compensations held in the lanes of one `f64x4`, so that a sample costs one
/// vector step instead of three scalar ones and the branch on which term is larger becomes a
/// blend (that branch is taken at random on noisy samples). As in `add_all`, the limit is
/// checked at the end of the block, and a channel that passed it is redone term by term.
pub(crate) fn add_all_rgb(sums: &mut [ScaledSum; 3], samples: &[[f64; 3]]) {
    if sums.iter().any(|s| s.scaled) {
        for (c, s) in sums.iter_mut().enumerate() {
            s.add_all(samples.iter().map(|p| p[c]));
        }
        return;
    }
    let lanes = |f: fn(&Neumaier) -> f64| {
        f64x4::new([f(&sums[0].acc), f(&sums[1].acc), f(&sums[2].acc), 0.0])
    };
    let (start_sum, start_compensation) = (lanes(|a| a.sum), lanes(|a| a.compensation));
    let (mut sum, mut compensation) = (start_sum, start_compensation);
    for p in samples {
        let x = f64x4::new([p[0], p[1], p[2], 0.0]);
        // Neumaier::add, lane by lane.
        let t = sum + x;
        let sum_larger = sum.abs().simd_ge(x.abs());
        compensation += sum_larger.bitselect((sum - t) + x, (x - t) + sum);
        sum = t;
    }
    let (sum, compensation) = (sum.to_array(), compensation.to_array());
    let (start_sum, start_compensation) = (start_sum.to_array(), start_compensation.to_array());
    for (c, s) in sums.iter_mut().enumerate() {
        s.acc = Neumaier {
            sum: sum[c],
            compensation: compensation[c],
        };
        if !s.acc.below_limit() {
            s.acc = Neumaier {
                sum: start_sum[c],
                compensation: start_compensation[c],
            };
            s.add_each(samples.iter().map(|p| p[c]));
        }
    }
}

/// Compensated sums held side by side (the sets of a partition, a cascade's buffers), each
/// rescaled on its own when it would overflow, as a [`ScaledSum`]: a sum of huge samples is
/// rescaled while its neighbours, which may hold tiny ones, keep full precision. The flags
/// are allocated only once a sum is rescaled, so the common state is 16 bytes a sum.
#[derive(Debug, Clone, Default)]
pub(crate) struct ScaledSums {
    sums: Vec<Neumaier>,
    /// Empty while no sum is rescaled; else one flag per sum.
    scaled: Vec<bool>,
}

impl ScaledSums {
    /// `len` empty sums.
    pub(crate) fn new(len: usize) -> Self {
        ScaledSums {
            sums: vec![Neumaier::new(); len],
            scaled: Vec::new(),
        }
    }

    /// Number of sums.
    #[inline]
    pub(crate) fn len(&self) -> usize {
        self.sums.len()
    }

    /// Whether any sum has been rescaled (then the unchecked block paths must not be used).
    #[inline]
    pub(crate) fn any_scaled(&self) -> bool {
        !self.scaled.is_empty()
    }

    /// The accumulators themselves, for block loops that add with the plain
    /// [`Neumaier::add`]. Only valid while [`ScaledSums::any_scaled`] is false, and the caller
    /// must then check [`Neumaier::below_limit`] on every sum it touched (and undo the block
    /// if one fails).
    #[inline]
    pub(crate) fn plain_mut(&mut self) -> &mut [Neumaier] {
        debug_assert!(!self.any_scaled());
        &mut self.sums
    }

    /// Sum `i` as a plain accumulator (see [`ScaledSums::plain_mut`]).
    #[inline]
    pub(crate) fn plain(&self, i: usize) -> Option<Neumaier> {
        self.sums.get(i).copied()
    }

    /// Adds one finite term of any sign to sum `i`; one comparison beyond the plain addition.
    #[inline(always)]
    pub(crate) fn add(&mut self, i: usize, x: f64) {
        if !(self.scaled.is_empty() && self.sums[i].try_add(x)) {
            self.add_slow(i, x);
        }
    }

    /// [`ScaledSums::add`] once some sum is rescaled or this one must be.
    #[cold]
    #[inline(never)]
    fn add_slow(&mut self, i: usize, x: f64) {
        if self.scaled.is_empty() {
            self.scaled = vec![false; self.sums.len()];
        }
        if self.scaled[i] || !self.sums[i].try_add(x) {
            self.sums[i].add_scaled(&mut self.scaled[i], x);
        }
    }

    /// Sum `i` divided by `count` (`count > 0`), as [`ScaledSum::mean`].
    #[inline]
    pub(crate) fn mean(&self, i: usize, count: f64) -> f64 {
        let scaled = self.scaled.get(i).copied().unwrap_or(false);
        self.sums[i].mean_of(scaled, count)
    }

    /// Becomes a copy of `other`, reusing this allocation where it is large enough.
    pub(crate) fn copy_from(&mut self, other: &ScaledSums) {
        self.sums.clone_from(&other.sums);
        self.scaled.clone_from(&other.scaled);
    }

    /// Grows to `len` empty sums (allocating exactly what is needed).
    pub(crate) fn grow(&mut self, len: usize) {
        if self.sums.len() < len {
            self.sums.reserve_exact(len - self.sums.len());
            self.sums.resize(len, Neumaier::new());
            if self.any_scaled() {
                self.scaled.resize(len, false);
            }
        }
    }

    /// Drops the sums from `len` on (keeping the allocation).
    pub(crate) fn truncate(&mut self, len: usize) {
        self.sums.truncate(len);
        self.scaled.truncate(len);
    }

    /// Empties every sum and keeps the first `len` (keeping the allocation of the sums).
    pub(crate) fn reset(&mut self, len: usize) {
        self.sums.truncate(len);
        self.sums.fill(Neumaier::new());
        self.scaled = Vec::new();
    }

    /// Heap bytes held.
    pub(crate) fn heap_bytes(&self) -> usize {
        self.sums.capacity() * std::mem::size_of::<Neumaier>()
            + self.scaled.capacity() * std::mem::size_of::<bool>()
    }
}

/// Welford's running mean and population variance (docs/estimators.md §1), mergeable with Chan et al.'s rule.
///
/// Unlike the sums above, it is **not** rescaled: docs/estimators.md §1 defines `sigma` as `+inf` once `m2`
/// overflows (observations spread over more than about `1e154`), and Jung's choice of `M`
/// follows that literally (`tests/hard_cases.rs` pins it); `M = m_max` then, and the estimate
/// stays finite.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Welford {
    count: u64,
    mean: f64,
    m2: f64,
}

impl Welford {
    /// No observations.
    pub const fn new() -> Self {
        Welford {
            count: 0,
            mean: 0.0,
            m2: 0.0,
        }
    }

    /// Adds one observation in the spec's exact operation order.
    #[inline(always)]
    pub fn push(&mut self, x: f64) {
        self.count += 1;
        let d = x - self.mean;
        self.mean += d / self.count as f64;
        self.m2 += d * (x - self.mean);
    }

    /// Number of observations.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Running mean (0 with no observation).
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Population standard deviation `sqrt(m2 / k)`: 0 with no observation, `+inf` once `m2`
    /// has overflowed.
    pub fn sigma(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            (self.m2 / self.count as f64).sqrt()
        }
    }

    /// Adds a block of observations without a division per observation on a dependency
    /// chain: per chunk of at most [`SPREAD_CHUNK`] observations, its mean and sum of squared
    /// deviations by two passes, merged with Chan et al.'s rule (docs/estimators.md §1, the
    /// block form). `sigma` then agrees with the per-observation update to about `1e-14`
    /// relative, not bit for bit. A chunk whose sum or squared deviations overflow (samples
    /// spread over more than about `1e154`) goes through [`Welford::push`] instead, so
    /// `sigma` becomes `+inf` exactly where the per-observation definition says.
    pub fn push_block(&mut self, xs: &[f64]) {
        for chunk in xs.chunks(SPREAD_CHUNK) {
            match Welford::of_chunk(chunk) {
                Some(block) => self.merge(&block),
                None => chunk.iter().for_each(|&x| self.push(x)),
            }
        }
    }

    /// The two-pass moments of one chunk, taken about its first observation `k` so that a
    /// chunk of equal values has exactly mean `k` and `m2 = 0`, as the per-observation update
    /// gives; `None` when a pass overflows.
    fn of_chunk(xs: &[f64]) -> Option<Welford> {
        let (k, n) = (xs[0], xs.len() as f64);
        let shift = lane_sum(xs, |x| x - k) / n;
        let m2 = lane_sum(xs, |x| (x - k - shift) * (x - k - shift));
        let mean = k + shift;
        (mean.is_finite() && m2.is_finite()).then_some(Welford {
            count: xs.len() as u64,
            mean,
            m2,
        })
    }

    /// Combines two accumulators as if all observations had gone through one.
    pub fn merge(&mut self, other: &Welford) {
        if other.count == 0 {
            return;
        }
        if self.count == 0 {
            *self = *other;
            return;
        }
        let (na, nb) = (self.count as f64, other.count as f64);
        let n = na + nb;
        let d = other.mean - self.mean;
        // Products in the formula's order, unless one overflows where the result need not
        // (means near 1e154 and up): then with the count ratios formed first, which stays
        // finite wherever the per-observation update does.
        let step = d * nb / n;
        self.mean += if step.is_finite() { step } else { d * (nb / n) };
        let spread = d * d * na * nb / n;
        self.m2 += other.m2
            + if spread.is_finite() {
                spread
            } else {
                d * (d * (na * nb / n))
            };
        self.count += other.count;
    }
}

/// Observations per chunk of [`Welford::push_block`]: a plain sum of `n` terms errs by at most
/// about `n` roundings, so 256 keeps each chunk's moments within `3e-14` relative while the
/// merge's division is paid once per 256 observations.
pub const SPREAD_CHUNK: usize = 256;

/// `sum f(x)` over four interleaved lanes, so the adds are independent chains the compiler
/// can put in vector registers; the order is fixed, so the result does not depend on the CPU.
#[inline(always)]
fn lane_sum(xs: &[f64], f: impl Fn(f64) -> f64) -> f64 {
    let mut lanes = [0.0f64; 4];
    let mut quads = xs.chunks_exact(4);
    for q in &mut quads {
        for (lane, &x) in lanes.iter_mut().zip(q) {
            *lane += f(x);
        }
    }
    let mut sum = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
    for &x in quads.remainder() {
        sum += f(x);
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_are_the_powers_of_two_they_name() {
        assert_eq!(SUM_LIMIT, 2f64.powi(1023));
        assert_eq!(SAFE_TOTAL, 2f64.powi(1020));
        assert_eq!(SUM_DOWN, 2f64.powi(-128));
        assert_eq!(SUM_UP, 2f64.powi(128));
    }

    #[test]
    fn neumaier_keeps_small_terms_a_naive_sum_drops() {
        let mut s = Neumaier::new();
        s.add(1e100);
        s.add(1.0);
        s.add(-1e100);
        assert_eq!(s.value(), 1.0);
    }

    #[test]
    fn scaled_sum_is_plain_until_the_limit_and_finite_beyond() {
        let xs = [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1];
        let mut plain = Neumaier::new();
        let (mut one, mut block) = (ScaledSum::new(), ScaledSum::new());
        xs.iter().for_each(|&x| {
            plain.add(x);
            one.add(x);
        });
        block.add_all(xs.iter().copied());
        let want = plain.value() / 7.0;
        assert_eq!(one.mean(7).to_bits(), want.to_bits());
        assert_eq!(block.mean(7).to_bits(), want.to_bits());

        let (mut one, mut block) = (ScaledSum::new(), ScaledSum::new());
        [1e308; 3].iter().for_each(|&x| one.add(x));
        block.add_all([1e308; 3].into_iter());
        assert_eq!(one.mean(3), 1e308);
        assert_eq!(block.mean(3), 1e308);
        assert_eq!(one, block);
    }

    #[test]
    fn scaled_sums_rescale_one_sum_and_keep_the_others() {
        let mut s = ScaledSums::new(2);
        for _ in 0..4 {
            s.add(0, f64::MAX);
            s.add(1, 1e-300);
        }
        assert!(s.any_scaled());
        assert_eq!(s.mean(0, 4.0), f64::MAX);
        assert_eq!(s.mean(1, 4.0), 1e-300);
        s.grow(3);
        s.add(2, 3.0);
        assert_eq!(s.mean(2, 1.0), 3.0);
        s.reset(1);
        assert!(!s.any_scaled());
        assert_eq!((s.len(), s.mean(0, 1.0)), (1, 0.0));
    }

    #[test]
    fn welford_sigma_of_running_example() {
        let mut w = Welford::new();
        for x in [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1] {
            w.push(x);
        }
        assert!((w.sigma() - 121.71536384499028).abs() < 1e-12 * 121.7);
    }

    #[test]
    fn welford_blocks_agree_with_the_per_observation_update() {
        // 10007 values spread over 12 decades (a deterministic power law), pushed in blocks
        // that do not divide the chunk: sigma within 1e-13 relative of the literal update (the
        // contract allows 1e-12), count and mean alike. A chunk merged twice or dropped moves
        // sigma by far more than that.
        let xs: Vec<f64> = (0..10_007u64)
            .map(|i| {
                let u = ((i * 2_654_435_761) % 1_000_003) as f64 / 1_000_003.0;
                (1.0 - u).powf(-1.0 / 0.25) * 1e-6
            })
            .collect();
        let mut literal = Welford::new();
        xs.iter().for_each(|&x| literal.push(x));
        for block in [1, 3, 255, 256, 257, 4096, 10_007] {
            let mut w = Welford::new();
            xs.chunks(block).for_each(|b| w.push_block(b));
            assert_eq!(w.count(), literal.count());
            let rel = |a: f64, b: f64| ((a - b) / b).abs();
            assert!(rel(w.mean(), literal.mean()) < 1e-13, "block {block}");
            assert!(rel(w.sigma(), literal.sigma()) < 1e-13, "block {block}");
        }
    }

    #[test]
    fn welford_blocks_overflow_and_underflow_as_the_literal_update_does() {
        // Squared deviations near 1e300 overflow: sigma = +inf as the literal update gives.
        let big = [1e300, 0.0, 3e300, 5e299];
        let mut w = Welford::new();
        w.push_block(&big);
        assert_eq!(w.sigma(), f64::INFINITY);
        assert!(w.mean().is_finite());
        // Equal values: exactly sigma 0 and the value itself, at any scale, like the literal
        // update (Jung's M = 1 on a flat pixel depends on it).
        for x in [2.4e127, 0.1, 3e-300] {
            let mut w = Welford::new();
            w.push_block(&[x; 1000]);
            assert_eq!((w.mean(), w.sigma()), (x, 0.0));
        }
        // Near 1e-300 every square underflows to 0.
        let tiny = [1e-300, 2e-300, 0.0];
        let mut w = Welford::new();
        w.push_block(&tiny);
        assert_eq!(w.sigma(), 0.0);
        // A sum that overflows (mean of f64::MAX and 0) takes the per-observation path.
        let mut w = Welford::new();
        w.push_block(&[f64::MAX, f64::MAX, 0.0]);
        let mut literal = Welford::new();
        [f64::MAX, f64::MAX, 0.0]
            .iter()
            .for_each(|&x| literal.push(x));
        assert_eq!(w, literal);
    }

    #[test]
    fn welford_merge_matches_single_pass() {
        let xs = [3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0];
        let mut all = Welford::new();
        xs.iter().for_each(|&x| all.push(x));
        let (mut a, mut b) = (Welford::new(), Welford::new());
        xs[..3].iter().for_each(|&x| a.push(x));
        xs[3..].iter().for_each(|&x| b.push(x));
        a.merge(&b);
        assert_eq!(a.count(), all.count());
        assert!((a.mean() - all.mean()).abs() < 1e-14);
        assert!((a.sigma() - all.sigma()).abs() < 1e-14);
    }

    #[test]
    fn welford_merge_stays_finite_where_the_per_observation_update_does() {
        // The case proptest found (tests/overflow.proptest-regressions): x near 1.1e154, then
        // two zeros merged as a block. `d * d * 1 * 2` is 2.3e308 and overflowed, so Jung saw
        // sigma = inf and took M = m_max; the literal update's m2 is (2/3)·x², finite.
        let x = 863728196.9766042 * 2f64.powi(482);
        let mut literal = Welford::new();
        [x, 0.0, 0.0].iter().for_each(|&v| literal.push(v));
        let mut merged = Welford::new();
        merged.push_block(&[x]);
        merged.push_block(&[0.0, 0.0]);
        assert!(literal.sigma().is_finite());
        assert!(
            (merged.sigma() / literal.sigma() - 1.0).abs() < 1e-15,
            "{:e} vs {:e}",
            merged.sigma(),
            literal.sigma()
        );
        assert_eq!(merged.mean(), literal.mean());
        // The mean's step `d * 2` overflows for two observations of f64::MAX after a zero.
        let mut merged = Welford::new();
        merged.push_block(&[0.0]);
        merged.push_block(&[f64::MAX, f64::MAX]);
        let mut literal = Welford::new();
        [0.0, f64::MAX, f64::MAX]
            .iter()
            .for_each(|&v| literal.push(v));
        assert!(merged.mean().is_finite());
        assert!((merged.mean() / literal.mean() - 1.0).abs() < 1e-15);
    }
}
