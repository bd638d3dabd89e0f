//! The median-of-means family of Buisine et al., "Firefly removal in Monte Carlo rendering
//! with adaptive Median of meaNs", EGSR 2021 ([B]): MoN (eq. 2), the Gini coefficient of the
//! set means (eq. 4, App. A eq. 7), G-MoN_b (eq. 5) and G-MoN (eq. 6).
//!
//! Samples are dealt round-robin into M sets (sample `i` to set `i mod M`); each set keeps only
//! a compensated sum, since its count follows from n. Everything else happens at estimate time
//! on the `K = min(n, M)` non-empty set means. **Decision (docs/estimators.md §3):** wherever [B] writes M in
//! the median, Gini, `k` and `c`, K is used; the two differ only while `n < M`.

use super::numeric::{SAFE_TOTAL, ScaledSum, ScaledSums, plain_total};
use super::rgb::per_channel;
use super::{Estimator, EstimatorSpec, Extra, Extras, Key, Method, Neumaier, RgbEstimator, empty};
use crate::error::{Error, Result};
use arrayvec::ArrayVec;
use std::fmt;

/// Largest accepted M: a pixel's state is 16 bytes a set, so this caps it at 16 MiB.
pub const MAX_SETS: usize = 1 << 20;

/// Most sets whose undo copy (16 bytes a set, 4 KiB) [`Partition::push_slice`] keeps on the
/// stack; more sets are copied to the heap, once per block of at least one round.
const UNCHECKED_SETS: usize = 256;

/// Round-robin partition of a stream of non-negative samples into M sets, each a compensated
/// sum.
///
/// Each set's sum is rescaled on its own if it would overflow (see `numeric`), so set means
/// are finite for any finite samples and bit-identical to the plain ones when those are.
#[derive(Debug, Clone)]
pub struct Partition {
    sums: ScaledSums,
    cursor: usize,
    n: u64,
    /// Plain total of every sample so far (see [`SAFE_TOTAL`]): while it is below the bound,
    /// blocks take the plain loop with no undo copy and no check.
    seen: f64,
}

impl Partition {
    /// A partition into `m` sets; `m` must be in `1..=MAX_SETS`.
    pub fn new(m: usize) -> Result<Self> {
        if !(1..=MAX_SETS).contains(&m) {
            return Err(Error::param(
                "M",
                m,
                format!("must be an integer in 1..={MAX_SETS}"),
            ));
        }
        Ok(Partition {
            sums: ScaledSums::new(m),
            cursor: 0,
            n: 0,
            seen: 0.0,
        })
    }

    /// Number of sets M.
    pub fn sets(&self) -> usize {
        self.sums.len()
    }

    /// Samples pushed so far.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// Adds one sample to the next set in turn.
    #[inline(always)]
    pub fn push(&mut self, sample: f64) {
        self.seen += sample;
        self.sums.add(self.cursor, sample);
        self.cursor += 1;
        if self.cursor == self.sums.len() {
            self.cursor = 0;
        }
        self.n += 1;
    }

    /// Adds a block; same result as pushing one by one.
    ///
    /// While the plain total of the stream stays below [`SAFE_TOTAL`] (any stream of
    /// renderer or generator samples), no set can approach the limit and the block is the
    /// plain compensated loop. Beyond it the sums are checked once per block, not per sample:
    /// a block shorter than one round adds one sample to each set it touches, and is checked
    /// before it runs; a longer block runs first and checks each set once at the end (sums of
    /// non-negative samples never decrease, so a set below the limit at the end never passed
    /// it). In the rare case one did, the block is undone from a copy of the sets (on the
    /// stack up to 256 sets) and pushed sample by sample, which rescales that set.
    pub fn push_slice(&mut self, samples: &[f64]) {
        self.push_slice_totalled(samples, plain_total(samples));
    }

    /// [`Partition::push_slice`] given `total`, the [`plain_total`] of `samples`, for callers
    /// that feed one block to several partitions (Jung's) and sum it once.
    pub(crate) fn push_slice_totalled(&mut self, samples: &[f64], total: f64) {
        self.seen += total;
        let m = self.sums.len();
        if self.seen < SAFE_TOTAL {
            Self::push_unchecked(self.sums.plain_mut(), &mut self.cursor, samples);
            self.n += samples.len() as u64;
        } else if self.sums.any_scaled() {
            self.push_each(samples);
        } else if samples.len() < m {
            self.push_short(samples);
        } else if m <= UNCHECKED_SETS {
            let mut before = ArrayVec::<Neumaier, UNCHECKED_SETS>::new();
            match before.try_extend_from_slice(self.sums.plain_mut()) {
                Ok(()) => self.push_rounds(samples, &before),
                Err(_) => self.push_each(samples),
            }
        } else {
            let before = self.sums.plain_mut().to_vec();
            self.push_rounds(samples, &before);
        }
    }

    /// [`Partition::push_slice`] for a block shorter than one round: each set it touches gets
    /// exactly one sample, so checking every `s + x` first (a branch-free pass) proves the plain
    /// loop safe, for less than an undo copy would cost.
    fn push_short(&mut self, samples: &[f64]) {
        let (start, m) = (self.cursor, self.sums.len());
        let first = (m - start).min(samples.len());
        let sums = self.sums.plain_mut();
        let fits = |accs: &[Neumaier], xs: &[f64]| {
            accs.iter()
                .zip(xs)
                .fold(true, |ok, (acc, &x)| ok & acc.fits_with(x))
        };
        if fits(&sums[start..], &samples[..first]) & fits(sums, &samples[first..]) {
            Self::push_unchecked(sums, &mut self.cursor, samples);
            self.n += samples.len() as u64;
        } else {
            self.push_each(samples);
        }
    }

    /// [`Partition::push_slice`] for a block of at least one round, given a copy of every set
    /// to undo it from.
    fn push_rounds(&mut self, samples: &[f64], before: &[Neumaier]) {
        let cursor = self.cursor;
        let sums = self.sums.plain_mut();
        Self::push_unchecked(sums, &mut self.cursor, samples);
        if sums.iter().fold(true, |ok, acc| ok & acc.below_limit()) {
            self.n += samples.len() as u64;
            return;
        }
        sums.copy_from_slice(before);
        self.cursor = cursor;
        self.push_each(samples);
    }

    /// [`Partition::push`] on each sample: the fallback of the block paths, kept out of line
    /// so that they stay small functions.
    #[cold]
    #[inline(never)]
    fn push_each(&mut self, samples: &[f64]) {
        samples.iter().for_each(|&s| self.push(s));
    }

    /// The plain block loop over the sets' accumulators (no overflow check).
    #[inline(always)]
    fn push_unchecked(sums: &mut [Neumaier], cursor: &mut usize, samples: &[f64]) {
        let m = sums.len();
        let mut rest = samples;
        // Finish the current round, then whole rounds, so the inner loop has no wrap test.
        let head = (m - *cursor).min(rest.len());
        for (sum, &s) in sums[*cursor..*cursor + head].iter_mut().zip(rest) {
            sum.add_nonneg(s);
        }
        *cursor += head;
        if *cursor == m {
            *cursor = 0;
        }
        rest = &rest[head..];
        let mut rounds = rest.chunks_exact(m);
        for round in &mut rounds {
            for (sum, &s) in sums.iter_mut().zip(round) {
                sum.add_nonneg(s);
            }
        }
        let tail = rounds.remainder();
        for (sum, &s) in sums.iter_mut().zip(tail) {
            sum.add_nonneg(s);
        }
        if !tail.is_empty() {
            *cursor = tail.len();
        }
    }

    /// The `K = min(n, M)` non-empty set means, ascending, written into `out`.
    pub fn sorted_means(&self, out: &mut Vec<f64>) {
        let m = self.sums.len() as u64;
        let k = self.n.min(m) as usize;
        let (base, extra) = (self.n / m, (self.n % m) as usize);
        out.clear();
        out.extend((0..k).map(|i| {
            let count = base + u64::from(i < extra);
            self.sums.mean(i, count as f64)
        }));
        out.sort_unstable_by(f64::total_cmp);
    }

    /// Becomes a copy of `other` (a partition fed the same stream elsewhere, see
    /// [`crate::estimators::Bank`]), without allocating when the set counts match.
    pub fn copy_from(&mut self, other: &Partition) {
        self.sums.copy_from(&other.sums);
        self.cursor = other.cursor;
        self.n = other.n;
        self.seen = other.seen;
    }

    /// Forgets every sample.
    pub fn reset(&mut self) {
        self.sums.reset(self.sums.len());
        self.cursor = 0;
        self.n = 0;
        self.seen = 0.0;
    }

    /// Heap bytes held by the sets.
    pub fn heap_bytes(&self) -> usize {
        self.sums.heap_bytes()
    }
}

/// `2^-128`: the factor by which the estimate-time fallbacks below rescale set means whose
/// plain sums overflow (exact; means below `2^-946` lose bits, far below one rounding of a
/// sum of values that large).
const THETA_DOWN: f64 = f64::from_bits((1023 - 128) << 52);

/// `2^128`, undoing [`THETA_DOWN`].
const THETA_UP: f64 = f64::from_bits((1023 + 128) << 52);

/// Median of ascending values (mean of the two middle ones for an even count).
pub fn median_sorted(theta: &[f64]) -> f64 {
    let k = theta.len();
    if k % 2 == 1 {
        theta[k / 2]
    } else {
        let (a, b) = (theta[k / 2 - 1], theta[k / 2]);
        let m = (a + b) / 2.0;
        // a + b overflows only above 2^1023, where halving first is exact.
        if m.is_finite() { m } else { a / 2.0 + b / 2.0 }
    }
}

/// Gini coefficient of ascending non-negative values ([B] App. A eq. 7), in `[0, 1)`:
/// 0 when all are equal, near 1 when one value holds all the mass.
///
/// G does not change when every value is multiplied by a power of two, so when the plain sums
/// overflow they are recomputed on the values times `2^-128`: the result is then exactly what
/// the plain formula gives with an unlimited exponent range.
pub fn gini(theta: &[f64]) -> f64 {
    let k = theta.len();
    let sums = |scale: f64| {
        let (mut s1, mut s2) = (0.0, 0.0);
        for (j, &t) in theta.iter().enumerate() {
            let t = t * scale;
            s1 += t;
            s2 += (j + 1) as f64 * t;
        }
        (s1, s2)
    };
    let kf = k as f64;
    let g = |(s1, s2): (f64, f64)| {
        if s1 == 0.0 {
            return Some(0.0);
        }
        let (num, den) = (2.0 * s2, kf * s1);
        // None when a term overflowed (it would give NaN or a wrong 0).
        (num.is_finite() && den.is_finite()).then(|| (num / den - (kf + 1.0) / kf).max(0.0))
    };
    // With the values times 2^-128 (at most 2^896), s2 <= K^2 * 2^896 cannot overflow.
    g(sums(1.0)).or_else(|| g(sums(THETA_DOWN))).unwrap_or(0.0)
}

/// G-MoN's trimmed mean ([B] eq. 6): drop `c = floor(G * floor(K/2))` set means at each end.
/// Returns the estimate and `c`.
pub fn gini_trimmed_mean(theta: &[f64], g: f64) -> (f64, usize) {
    let k = theta.len();
    let half = (k / 2) as f64;
    let c = ((g * half).floor() as usize).min((k - 1) / 2);
    let kept = &theta[c..k - c];
    let sum: f64 = kept.iter().fold(0.0, |acc, &t| acc + t);
    let mean = if sum.is_finite() {
        sum / kept.len() as f64
    } else {
        // The same sum on the values times 2^-128 (exact scaling), scaled back; saturated at
        // f64::MAX, the nearest value to a mean of finite values that rounds above it.
        let sum: f64 = kept.iter().fold(0.0, |acc, &t| acc + t * THETA_DOWN);
        (sum / kept.len() as f64 * THETA_UP).min(f64::MAX)
    };
    (mean, c)
}

/// An estimator over one partition, its spec type `$spec` (spec string `$key:M=`, `M`
/// required) and the spec's [`Method`] declaration.
macro_rules! partition_estimator {
    ($(#[$doc:meta])* $name:ident, $spec:ident, $key:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone)]
        pub struct $name {
            part: Partition,
        }

        #[doc = concat!("`", $key, ":M=`: the number of sets (required).")]
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct $spec {
            /// Number of sets.
            pub m: usize,
        }

        impl Method for $spec {
            const NAME: &'static str = $key;
            const KEYS: &'static [Key<Self>] = &[Key::required(Key::int("M", |s| &mut s.m))];
            const DEFAULT: Self = $spec { m: 0 };

            fn build(&self) -> Result<Box<dyn Estimator>> {
                Ok(Box::new($name::new(self.m)?))
            }

            fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
                per_channel(|| $name::new(self.m))
            }
        }

        impl $name {
            /// An estimator over `m` sets; `m` must be in `1..=MAX_SETS`.
            pub fn new(m: usize) -> Result<Self> {
                Ok($name { part: Partition::new(m)? })
            }

            /// The spec this estimator was built from.
            fn spec_of(&self) -> EstimatorSpec {
                $spec { m: self.part.sets() }.into()
            }

            fn sorted_means(&self) -> Result<Vec<f64>> {
                if self.part.count() == 0 {
                    return Err(empty(self));
                }
                let mut theta = Vec::with_capacity(self.part.sets());
                self.part.sorted_means(&mut theta);
                Ok(theta)
            }
        }
    };
}

macro_rules! partition_common {
    () => {
        #[inline]
        fn push(&mut self, sample: f64) {
            self.part.push(sample);
        }

        fn push_slice(&mut self, samples: &[f64]) {
            self.part.push_slice(samples);
        }

        fn count(&self) -> u64 {
            self.part.count()
        }

        fn state_bytes(&self) -> usize {
            std::mem::size_of::<Self>() + self.part.heap_bytes()
        }

        fn reset(&mut self) {
            self.part.reset();
        }

        fn partitions(&self) -> &[Partition] {
            std::slice::from_ref(&self.part)
        }

        fn push_slice_sharing(&mut self, _samples: &[f64], partition: &Partition) {
            self.part.copy_from(partition);
        }
    };
}

partition_estimator!(
    /// Median of means ([B] eq. 2). With `M = 1` it is bit-identical to the mean.
    Mon,
    MonSpec,
    "mon"
);
partition_estimator!(
    /// The Gini coefficient of the MoN set means as an "estimate": a diagnostic of how
    /// unequal the sets are, the quantity G-MoN adapts to.
    GiniDiagnostic,
    GiniSpec,
    "gini"
);
partition_estimator!(
    /// G-MoN ([B] eq. 6): a trimmed mean of the set means whose trimming grows with Gini.
    Gmon,
    GmonSpec,
    "gmon"
);

impl fmt::Display for Mon {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "MoN(M={})", self.part.sets())
    }
}

impl Estimator for Mon {
    partition_common!();

    fn estimate(&self) -> Result<f64> {
        Ok(median_sorted(&self.sorted_means()?))
    }

    fn spec(&self) -> EstimatorSpec {
        self.spec_of()
    }
}

impl fmt::Display for GiniDiagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Gini(M={})", self.part.sets())
    }
}

impl Estimator for GiniDiagnostic {
    partition_common!();

    fn estimate(&self) -> Result<f64> {
        Ok(gini(&self.sorted_means()?))
    }

    fn spec(&self) -> EstimatorSpec {
        self.spec_of()
    }
}

impl fmt::Display for Gmon {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "G-MoN(M={})", self.part.sets())
    }
}

impl Estimator for Gmon {
    partition_common!();

    fn estimate(&self) -> Result<f64> {
        let theta = self.sorted_means()?;
        Ok(gini_trimmed_mean(&theta, gini(&theta)).0)
    }

    fn extras(&self) -> Extras {
        let Ok(theta) = self.sorted_means() else {
            return Vec::new();
        };
        let g = gini(&theta);
        let (_, c) = gini_trimmed_mean(&theta, g);
        vec![("gini", Extra::Float(g)), ("trimmed", Extra::Int(c as u64))]
    }

    fn spec(&self) -> EstimatorSpec {
        self.spec_of()
    }
}

/// `gmonb:M=,threshold=` (`M` required, `threshold` 0.25 by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GmonBSpec {
    /// Number of sets.
    pub m: usize,
    /// Gini threshold above which MoN replaces the mean.
    pub threshold: f64,
}

impl Method for GmonBSpec {
    const NAME: &'static str = "gmonb";
    const KEYS: &'static [Key<Self>] = &[
        Key::required(Key::int("M", |s| &mut s.m)),
        Key::float("threshold", |s| &mut s.threshold),
    ];
    const DEFAULT: Self = GmonBSpec {
        m: 0,
        threshold: 0.25,
    };

    fn build(&self) -> Result<Box<dyn Estimator>> {
        Ok(Box::new(GmonB::new(self.m, self.threshold)?))
    }

    fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
        per_channel(|| GmonB::new(self.m, self.threshold))
    }
}

/// G-MoN_b ([B] eq. 5): the plain mean while the set means are even (Gini at most the
/// threshold), MoN once they are not — unbiased on well-behaved pixels, robust on fireflies.
#[derive(Debug, Clone)]
pub struct GmonB {
    part: Partition,
    total: ScaledSum,
    threshold: f64,
}

impl GmonB {
    /// `m` sets and a Gini threshold, which must be finite and in `[0, 1]`.
    pub fn new(m: usize, threshold: f64) -> Result<Self> {
        if !(0.0..=1.0).contains(&threshold) {
            return Err(Error::param(
                "threshold",
                threshold,
                "must be in [0, 1] (a Gini coefficient)",
            ));
        }
        Ok(GmonB {
            part: Partition::new(m)?,
            total: ScaledSum::new(),
            threshold,
        })
    }

    fn decide(&self) -> Result<(f64, f64, bool)> {
        let n = self.part.count();
        if n == 0 {
            return Err(empty(self));
        }
        let mut theta = Vec::with_capacity(self.part.sets());
        self.part.sorted_means(&mut theta);
        let g = gini(&theta);
        if g <= self.threshold {
            Ok((self.total.mean(n), g, false))
        } else {
            Ok((median_sorted(&theta), g, true))
        }
    }
}

impl fmt::Display for GmonB {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "G-MoN_b(M={},t={})", self.part.sets(), self.threshold)
    }
}

impl Estimator for GmonB {
    #[inline]
    fn push(&mut self, sample: f64) {
        self.part.push(sample);
        self.total.add(sample);
    }

    fn push_slice(&mut self, samples: &[f64]) {
        self.part.push_slice(samples);
        self.total.add_all(samples.iter().copied());
    }

    fn partitions(&self) -> &[Partition] {
        std::slice::from_ref(&self.part)
    }

    fn push_slice_sharing(&mut self, samples: &[f64], partition: &Partition) {
        self.part.copy_from(partition);
        self.total.add_all(samples.iter().copied());
    }

    fn count(&self) -> u64 {
        self.part.count()
    }

    fn estimate(&self) -> Result<f64> {
        Ok(self.decide()?.0)
    }

    fn extras(&self) -> Extras {
        match self.decide() {
            Ok((_, g, used_mon)) => vec![
                ("gini", Extra::Float(g)),
                ("used_mon", Extra::Bool(used_mon)),
            ],
            Err(_) => Vec::new(),
        }
    }

    fn state_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.part.heap_bytes()
    }

    fn spec(&self) -> EstimatorSpec {
        GmonBSpec {
            m: self.part.sets(),
            threshold: self.threshold,
        }
        .into()
    }

    fn reset(&mut self) {
        self.part.reset();
        self.total = ScaledSum::new();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: [f64; 7] = [0.6, 1.5, 0.0, 2.2, 4.8, 350.0, 4.1];

    #[test]
    fn block_push_matches_single_push() {
        for m in [1, 2, 3, 5, 7, 21] {
            for split in 0..=S.len() {
                let mut a = Partition::new(m).unwrap();
                S.iter().for_each(|&s| a.push(s));
                let mut b = Partition::new(m).unwrap();
                b.push_slice(&S[..split]);
                b.push_slice(&S[split..]);
                let (mut ta, mut tb) = (Vec::new(), Vec::new());
                a.sorted_means(&mut ta);
                b.sorted_means(&mut tb);
                assert_eq!(ta, tb, "m={m} split={split}");
                assert_eq!(a.cursor, b.cursor);
            }
        }
    }

    #[test]
    fn blocks_across_the_safe_total_match_single_pushes() {
        // Small samples, then huge ones: the plain total passes SAFE_TOTAL (2^1020, about
        // 1.1e307) inside the stream and the sets pass SUM_LIMIT later, so blocks take the
        // unchecked loop, then the checked one, then the rescaling fallback. Any block that
        // took the unchecked loop past the bound would overflow a set to inf.
        let xs: Vec<f64> = (0..400u32)
            .map(|i| {
                if i < 100 {
                    f64::from(i)
                } else {
                    1e306 * f64::from(i % 7 + 1)
                }
            })
            .collect();
        for m in [1, 3, 21] {
            for len in [1, 5, 64] {
                let mut a = Partition::new(m).unwrap();
                xs.iter().for_each(|&s| a.push(s));
                let mut b = Partition::new(m).unwrap();
                xs.chunks(len).for_each(|c| b.push_slice(c));
                let (mut ta, mut tb) = (Vec::new(), Vec::new());
                a.sorted_means(&mut ta);
                b.sorted_means(&mut tb);
                assert!(tb.iter().all(|t| t.is_finite()), "m={m} len={len}");
                assert_eq!(ta, tb, "m={m} len={len}");
                assert!(
                    b.sums.any_scaled(),
                    "m={m}: the stream must reach the limit"
                );
            }
        }
    }

    #[test]
    fn sets_are_dealt_round_robin() {
        let mut p = Partition::new(5).unwrap();
        p.push_slice(&S);
        let mut theta = Vec::new();
        p.sorted_means(&mut theta);
        assert_eq!(theta, vec![0.0, 2.2, 2.8, 4.8, 175.3]);
    }

    #[test]
    fn m_out_of_range_is_named() {
        let e = Mon::new(0).unwrap_err().to_string();
        assert!(e.contains("M = 0"), "{e}");
        let e = GmonB::new(3, f64::NAN).unwrap_err().to_string();
        assert!(e.contains("threshold = NaN"), "{e}");
    }
}
