//! Pajot et al.'s outlier delaying by density estimation: [`PajotRot`], [`PajotAdr`] and
//! [`PajotHybrid`] (docs/estimators.md §6).
//!
//! Source: A. Pajot, L. Barthe, M. Paulin, "Sample-Space Bright Spots Removal Using Density
//! Estimation", Graphics Interface 2011 (**[P]**). Each pixel keeps a one-dimensional density
//! estimate of its samples' log-luminance, built from Epanechnikov kernels ([P] eq. 3). A sample
//! whose log lies above the right-most *extended mode* (two or more samples whose kernels chain
//! together, [P] §3, §4.2) is *delayed*: it is left out of the pixel until the density grows to
//! reach it, and every delayed sample is re-tested whenever the acceptance bound `m` grows
//! ([P] Alg. 1). The first `learn` samples only build the initial density ([P] §4.1).
//!
//! - **ROT** ([P] §4.4, eq. 5; docs/estimators.md §6.2): every kernel has the rule-of-thumb half-width
//!   `h = (25 k)^(-1/5) σ` of the `k` log-luminances seen so far. Per-pixel state: the running
//!   moments, `m` and the delayed list.
//! - **ADR** ([P] §3.1 eq. 4, §4.2; docs/estimators.md §6.3): adaptive bandwidths (eq. 4) over an approximate
//!   distribution representation, in which an extended mode is kept as `(min, max, count)`
//!   ([`PajotMode`]). Per-pixel state: the modes, `m` and the delayed list.
//! - **Hybrid** ([P] §4.6; docs/estimators.md §6.4): both run side by side; once `T` successive updates of
//!   the bounds agree within `δ`, the pixel continues with ROT alone and the modes are freed.
//!
//! The estimate is the compensated mean of the accepted samples (black samples included).
//!
//! # Decisions
//!
//! From the spec (each is tested in this module or in `tests/pajot.rs`):
//! 1. **`≤` acceptance**: a non-black sample is accepted iff `ln S ≤ m` (Alg. 1 has `<`), so
//!    the sample defining `m` is itself accepted; accepted = zeros ∪ {`ln S ≤ m`} at all times.
//! 2. **Divisor**: the accepted count, not `n` (a renderer that does not splat a sample adds
//!    neither its value nor its weight); 0 when nothing is accepted. σ is the population σ.
//! 3. **Learning**: an estimate read while `n < learn` is computed as if learning ended now,
//!    leaving the state unchanged.
//! 4. **No extended mode**: `m = -inf`, every non-black sample is delayed (a value is trusted
//!    only once a similar one corroborates it): a one-sample pixel estimates 0.
//! 5. **Half-width**: `h` is read literally as the kernel's half-width; two samples overlap iff
//!    their logs are equal or closer than `h_a + h_b`. Silverman's unit-variance kernel would
//!    stretch the support by √5 and accept more.
//! 6. **ROT is incremental**: only the newcomer's overlaps with `m` and the delayed samples are
//!    examined; delayed samples are not re-chained among themselves when `h` grows.
//! 7. **ADR absorbs**: a merge replaces every mode meeting the span of the newcomer and the
//!    modes it overlaps (modes stay disjoint); the newcomer's bandwidth uses the point set that
//!    includes it.
//! 8. **Hybrid**: agreement is `|m_ROT − m_ADR| ≤ δ |m_ADR|` at each *event* (a sample, the one
//!    ending learning included, after which either bound changed); the bound never decreases at
//!    the switch (`m_h = max(m_h, m_ADR, m_ROT)` there, `max(m_h, m_ROT)` afterwards); while
//!    learning, ADR's bound is used.
//!
//! Ours, where the spec leaves a choice open:
//! 9. **Side by side means independent**: inside the hybrid, ROT and ADR evolve exactly as the
//!    standalone estimators on the same stream (ROT's overlap points are the samples above
//!    `m_ROT`, whatever `m_h` is). The hybrid's own acceptance depends on `m_h` only. Reason:
//!    the bounds the switch compares are then those of `pajot-rot` and `pajot-adr`, which makes
//!    the switch reproducible and testable against them.
//! 10. **Bounded delayed list** ([`PajotRot::with_max_delayed`] and the same on the others; not
//!     part of the spec-string grammar): when a new entry would make the list longer than `k`,
//!     the entry with the **largest** value is discarded for good. It is counted in `dropped`,
//!     never accepted even if `m` later passes it, and excluded from the estimate like a delayed
//!     sample; for ROT it also stops being an overlap point. Reason: `m` only grows, so the
//!     largest delayed sample is the last one that could ever be released; keeping the `k`
//!     smallest keeps the samples most likely to be accepted and ROT's most useful overlap
//!     points, and the kept content does not depend on arrival order. Dropping the oldest would
//!     discard a sample just below `m` as readily as a firefly. `k = 0` drops every delayed
//!     sample. In the hybrid the list also holds ROT's overlap points that `m_h` has already
//!     accepted; if such a point is the largest entry it is forgotten as an overlap point only
//!     (it stays in the estimate and is not counted in `dropped`).
//! 11. **Memory over speed in the delayed list**: it holds the linear values (8 bytes each),
//!     sorted ascending; logs are recomputed with `ln` (assumed monotone, as libm's is) when a
//!     sample is re-tested, which only happens when a sample lands above `m` or `m` grows. The
//!     hybrid keeps one list for its delayed samples and ROT's overlap points (everything above
//!     `min(m_ROT, m_h)`); a cap counts both. The list gives memory back (to twice its length)
//!     after a release leaves it under a quarter full.
//! 12. **Learning storage**: only non-black samples are stored (black ones are accepted on
//!     arrival), and the buffer is freed when learning ends.
//! 13. **Reads during learning**: extras, [`PajotRot::delayed`], bounds, bandwidth and modes
//!     are reported as if learning ended now, like the estimate (ROT's moments are also only
//!     fed at the end of learning, in arrival order, so `bandwidth` includes every stored
//!     sample).
//! 14. **After the switch** the hybrid reports `modes_single = modes_extended = 0` (the modes
//!     are freed) and `m_adr` as ADR's bound at the switch; `switch_index` is the 0-based index
//!     of the switching sample in the stream and appears once switched.
//! 15. **Black** means `S == 0.0` (`-0.0` included); inputs are validated at the boundary.
//! 16. **`learn = 0`**: the post-learning rules apply from the first sample; there is no
//!     learning-end event.
//! 17. **ADR without materialising points**: after learning, a newcomer outside every extended
//!     mode needs eq. 4 over all represented points (`n` of them). Instead of listing them, the
//!     points strictly inside an extended mode, which all see the same `w` neighbours on each
//!     side and nothing else, share one pilot value computed in closed form; the `w + 1` points
//!     at each end, singles and the newcomer are evaluated one by one, and same-mode neighbours
//!     are taken at the exact spacing `(hi - lo) / (c - 1)`. This differs from the spec's
//!     rounded point values by rounding only, so decisions agree except at ties within ~1e-15
//!     (checked against the materialised computation in the unit tests and against a literal
//!     reading of the spec in `tests/pajot.rs`). Reason: cost `O(modes)` instead of `O(n)` per
//!     such sample (on lognormal pixels of 1024 samples, 1.2 µs -> 0.14 µs per sample). The
//!     search was since made faster without changing a bit of its result: its first form is
//!     kept in `adr/reference.rs` and the unit tests compare whole estimators with it.
//!
//! # Properties
//!
//! Decisions depend on differences of logs only, and both bandwidths scale with the spread of
//! the logs, so ROT and ADR are invariant under `ln S -> a ln S + b` (`a > 0`): scaling every
//! sample by `c > 0` scales the estimate by `c` and changes no decision (up to rounding of `ln`,
//! and of `δ |m|` in the hybrid when `δ > 0`). Lognormal pixels with the same seed therefore
//! delay the same samples whatever their `μ` and `σ`. Order of arrival after learning matters
//! only through `m`: whatever the order, the delayed samples are exactly those above the final
//! `m` (with the list unbounded), and a sample at or below the bound at the end of learning is
//! never delayed. What moves `m` is order-dependent: ROT's `h` depends on how many samples have
//! arrived and on their spread when a bright one arrives, and delayed samples are not
//! re-chained (decision 6); ADR's bandwidths depend on the point set when the newcomer arrives.
//! For ROT, if no later sample exceeds the bound at the end of learning, the order changes
//! nothing (only samples above `m` move it). ADR has no such guarantee: a newcomer at or below
//! `m` can merge with a single mode above `m` and raise it, so there even the order of samples
//! below the bound can matter.
//!
//! # Cost
//!
//! ROT: one `ln` and one Welford update per non-black sample (the division `d / k` sits on the
//! update's dependency chain, so a sample costs about a division's latency plus an `ln`, several
//! times a compensated addition; the spec keeps this Welford per sample), and a binary search
//! over the delayed list (one `ln` per probe) when a sample lands above `m`. ADR: one `ln` and
//! a check of the last mode hit and of its neighbour on the sample's side (else a binary search
//! over the modes) when the sample falls inside an extended mode, as about 90% of samples do on
//! lognormal pixels; otherwise eq. 4 over the implicit point set (decision 17). That costs
//! `O(modes)`: `nn` is a sum over every run, added in order, and `g` a mean over every point, so
//! no search can skip them; but only the runs with a point within `nn` of another point
//! (typically 2-5 of 10-40) get closed forms and an `ln`, the others are checked with a few
//! comparisons (`adr::Query`). The scratch memory is per thread, not part of the per-pixel
//! state. The hybrid pays both until it switches, then ROT's.

mod adr;
mod ledger;
mod rot;
#[cfg(test)]
mod tests;

pub use adr::{PajotMode, adr_bandwidths};

use super::rgb::pajot_rgb;
use super::{Estimator, EstimatorSpec, Extra, Extras, Key, Method, RgbEstimator};
use crate::error::{Error, Result};
use adr::Adr;
use ledger::Ledger;
use rot::Rot;
use std::borrow::Cow;
use std::fmt;

/// `pajot-rot:learn=` (`learn` 50 by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PajotRotSpec {
    /// Learning-phase length.
    pub learn: usize,
}

impl Method for PajotRotSpec {
    const NAME: &'static str = "pajot-rot";
    const KEYS: &'static [Key<Self>] = &[Key::int("learn", |s| &mut s.learn)];
    const DEFAULT: Self = PajotRotSpec { learn: 50 };
    const CONSTANT_MEMORY: bool = false;

    fn build(&self) -> Result<Box<dyn Estimator>> {
        Ok(Box::new(PajotRot::new(self.learn)?))
    }

    fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
        Ok(pajot_rgb(PajotRot::new(self.learn)?, self.learn))
    }
}

/// `pajot-adr:learn=` (`learn` 50 by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PajotAdrSpec {
    /// Learning-phase length.
    pub learn: usize,
}

impl Method for PajotAdrSpec {
    const NAME: &'static str = "pajot-adr";
    const KEYS: &'static [Key<Self>] = &[Key::int("learn", |s| &mut s.learn)];
    const DEFAULT: Self = PajotAdrSpec { learn: 50 };
    const CONSTANT_MEMORY: bool = false;

    fn build(&self) -> Result<Box<dyn Estimator>> {
        Ok(Box::new(PajotAdr::new(self.learn)?))
    }

    fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
        Ok(pajot_rgb(PajotAdr::new(self.learn)?, self.learn))
    }
}

/// `pajot-hybrid:learn=,T=,delta=` (defaults 50, 2 and 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PajotHybridSpec {
    /// Learning-phase length.
    pub learn: usize,
    /// Successive agreeing updates before switching to ROT.
    pub t: usize,
    /// Relative agreement tolerance.
    pub delta: f64,
}

impl Method for PajotHybridSpec {
    const NAME: &'static str = "pajot-hybrid";
    const KEYS: &'static [Key<Self>] = &[
        Key::int("learn", |s| &mut s.learn),
        Key::int("T", |s| &mut s.t),
        Key::float("delta", |s| &mut s.delta),
    ];
    const DEFAULT: Self = PajotHybridSpec {
        learn: 50,
        t: 2,
        delta: 0.0,
    };
    const CONSTANT_MEMORY: bool = false;

    fn build(&self) -> Result<Box<dyn Estimator>> {
        Ok(Box::new(PajotHybrid::new(self.learn, self.t, self.delta)?))
    }

    fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
        let p = PajotHybrid::new(self.learn, self.t, self.delta)?;
        Ok(pajot_rgb(p, self.learn))
    }
}

/// Calls `emit(lo, hi, count)` for each run of consecutive values of the ascending `xs` in
/// which `linked(i)` holds between `xs[i]` and `xs[i + 1]`.
fn for_each_run(xs: &[f64], linked: impl Fn(usize) -> bool, mut emit: impl FnMut(f64, f64, u64)) {
    let mut start = 0;
    for i in 0..xs.len() {
        if i + 1 == xs.len() || !linked(i) {
            emit(xs[start], xs[i], (i + 1 - start) as u64);
            start = i + 1;
        }
    }
}

/// The learning phase's storage: non-black samples in arrival order.
fn store(buf: &mut Vec<f64>, learn: usize, s: f64) {
    if buf.capacity() == 0 {
        buf.reserve_exact(learn.min(1024));
    }
    buf.push(s);
}

/// Ends a learning phase: feeds the stored samples' logs to `rot` in arrival order (if given),
/// then returns the samples sorted, with their logs (`ln` is monotone, so the logs of the
/// sorted samples are the sorted logs).
fn sorted_with_logs(mut values: Vec<f64>, rot: Option<&mut Rot>) -> (Vec<f64>, Vec<f64>) {
    if let Some(rot) = rot {
        for &s in &values {
            rot.observe(s.ln());
        }
    }
    // Equal positive samples are equal bits, so an unstable sort gives the same list.
    values.sort_unstable_by(f64::total_cmp);
    let logs = values.iter().map(|s| s.ln()).collect();
    (values, logs)
}

/// The `learn` parameter as a sample count.
fn learn_count(learn: usize) -> u64 {
    u64::try_from(learn).unwrap_or(u64::MAX)
}

/// Pajot et al.'s outlier delaying (module docs), one type for the three methods: the learning
/// phase, the ledger of accepted and delayed samples and the estimate are shared, and the bound
/// strategy `B` ([`RotBound`], [`AdrBound`] or [`HybridBound`]) decides how the acceptance
/// bound `m` is learnt and moved. [`PajotRot`], [`PajotAdr`] and [`PajotHybrid`] name the three.
#[derive(Debug, Clone)]
pub struct Pajot<B> {
    learn: usize,
    n: u64,
    learning: Vec<f64>,
    bound: B,
    ledger: Ledger,
}

/// Pajot et al.'s outlier delaying with the rule-of-thumb bandwidth (docs/estimators.md §6.2),
/// `pajot-rot:learn=50`.
pub type PajotRot = Pajot<RotBound>;

/// Pajot et al.'s outlier delaying with adaptive bandwidths over the approximate distribution
/// representation (docs/estimators.md §6.3), `pajot-adr:learn=50`.
pub type PajotAdr = Pajot<AdrBound>;

/// ADR and ROT side by side, switching to ROT alone once their bounds agree `T` times in a row
/// within `δ` (docs/estimators.md §6.4), `pajot-hybrid:learn=50,T=2,delta=0`.
pub type PajotHybrid = Pajot<HybridBound>;

/// What a bound strategy asks of the ledger for one non-black sample after learning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// Settle the ledger at this `(bound, floor)` first (the bound or floor moved).
    settle: Option<(f64, f64)>,
    /// Place the sample against `(bound, floor)`; `None` accepts it without remembering it.
    place: Option<(f64, f64)>,
}

/// How a [`Pajot`] estimator learns and moves its acceptance bound. Implemented by the three
/// strategies of this module only.
pub trait BoundStrategy: Clone + fmt::Debug + Send + Sync + 'static {
    /// Whether the strategy sees every learning-phase log in arrival order (ROT's moments).
    const OBSERVES_LEARNING: bool;

    /// One learning-phase log, in arrival order (only when `OBSERVES_LEARNING`).
    fn observe(&mut self, l: f64);

    /// Ends learning on the sorted logs of the stored samples; `index` is the 0-based index of
    /// the sample ending it. Returns the `(bound, floor)` to place the stored samples against.
    fn learn_end(&mut self, logs: &[f64], index: u64) -> (f64, f64);

    /// Takes the non-black sample `index` with log `l` after learning (`kept`: the ledger's
    /// kept list) and says what the ledger does with it.
    fn step(&mut self, l: f64, index: u64, kept: &[f64]) -> Step;

    /// The acceptance bound `m` (log units, `-inf` before any extended mode).
    fn bound(&self) -> f64;

    /// The strategy's extras after the shared ones.
    fn extras(&self, x: &mut Extras);

    /// Heap bytes held.
    fn heap_bytes(&self) -> usize;

    /// Back to the state before any sample (keeping allocations where it can).
    fn reset(&mut self);

    /// Writes the display form up to and including the parameters (`Pajot-ROT(learn=50`).
    fn describe(&self, learn: usize, f: &mut fmt::Formatter<'_>) -> fmt::Result;

    /// The spec of an estimator learning for `learn` samples with this strategy.
    fn spec(&self, learn: usize) -> EstimatorSpec;
}

impl<B: BoundStrategy> Pajot<B> {
    fn with_bound(learn: usize, bound: B) -> Self {
        Pajot {
            learn,
            n: 0,
            learning: Vec::new(),
            bound,
            ledger: Ledger::new(usize::MAX),
        }
    }

    /// Bounds the delayed list (for the hybrid: the kept list of delayed samples and ROT's
    /// accepted overlap points) to `k` samples: when full, the largest entry is dropped for
    /// good (module doc, decision 10). Not part of the spec-string grammar. A builder: it
    /// resets the estimator, so call it before pushing samples.
    pub fn with_max_delayed(mut self, k: usize) -> Self {
        self.ledger = Ledger::new(k);
        self.reset();
        self
    }

    /// The bound on the delayed list, if any.
    pub fn max_delayed(&self) -> Option<usize> {
        Some(self.ledger.cap()).filter(|&k| k != usize::MAX)
    }

    /// The acceptance bound `m` (log units; `-inf` before any extended mode); the hybrid's
    /// `m_h`.
    pub fn bound(&self) -> f64 {
        self.settled().bound.bound()
    }

    /// Number of samples currently delayed.
    pub fn delayed(&self) -> u64 {
        self.settled().ledger.delayed() as u64
    }

    /// Number of delayed samples dropped because the list was full.
    pub fn dropped(&self) -> u64 {
        self.settled().ledger.dropped()
    }

    /// Number of accepted samples, black ones included (the estimate's divisor).
    pub fn accepted(&self) -> u64 {
        self.settled().ledger.accepted()
    }

    fn is_learning(&self) -> bool {
        self.n < learn_count(self.learn)
    }

    /// This estimator, or a copy whose learning phase has ended now.
    fn settled(&self) -> Cow<'_, Self> {
        if self.is_learning() {
            let mut copy = self.clone();
            copy.finish_learning();
            Cow::Owned(copy)
        } else {
            Cow::Borrowed(self)
        }
    }

    fn finish_learning(&mut self) {
        let values = std::mem::take(&mut self.learning);
        if B::OBSERVES_LEARNING {
            for &s in &values {
                self.bound.observe(s.ln());
            }
        }
        let (values, logs) = sorted_with_logs(values, None);
        let (bound, floor) = self.bound.learn_end(&logs, self.n.saturating_sub(1));
        for (&s, &l) in values.iter().zip(&logs) {
            self.ledger.place(s, l, bound, floor);
        }
    }

    #[inline(always)]
    fn push_one(&mut self, s: f64) {
        let index = self.n;
        self.n += 1;
        if self.n <= learn_count(self.learn) {
            if s == 0.0 {
                self.ledger.zero();
            } else {
                store(&mut self.learning, self.learn, s);
            }
            if self.n == learn_count(self.learn) {
                self.finish_learning();
            }
            return;
        }
        if s == 0.0 {
            self.ledger.zero();
            return;
        }
        let l = s.ln();
        let step = self.bound.step(l, index, self.ledger.kept());
        if let Some((bound, floor)) = step.settle {
            self.ledger.settle(bound, floor);
        }
        match step.place {
            None => self.ledger.accept(s),
            Some((bound, floor)) => self.ledger.place(s, l, bound, floor),
        }
    }
}

impl<B: BoundStrategy> fmt::Display for Pajot<B> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.bound.describe(self.learn, f)?;
        if self.ledger.cap() != usize::MAX {
            write!(f, ",max_delayed={}", self.ledger.cap())?;
        }
        write!(f, ")")
    }
}

impl<B: BoundStrategy> Estimator for Pajot<B> {
    fn push(&mut self, sample: f64) {
        self.push_one(sample);
    }

    fn push_slice(&mut self, samples: &[f64]) {
        for &s in samples {
            self.push_one(s);
        }
    }

    fn count(&self) -> u64 {
        self.n
    }

    fn estimate(&self) -> Result<f64> {
        if self.n == 0 {
            return Err(super::empty(self));
        }
        Ok(self.settled().ledger.mean())
    }

    fn extras(&self) -> Extras {
        let s = self.settled();
        let mut x: Extras = vec![
            ("delayed", Extra::Int(s.ledger.delayed() as u64)),
            ("m", Extra::Float(s.bound.bound())),
        ];
        if s.ledger.cap() != usize::MAX {
            x.push(("dropped", Extra::Int(s.ledger.dropped())));
        }
        s.bound.extras(&mut x);
        x
    }

    fn state_bytes(&self) -> usize {
        size_of::<Self>()
            + self.learning.capacity() * size_of::<f64>()
            + self.ledger.heap_bytes()
            + self.bound.heap_bytes()
    }

    fn spec(&self) -> EstimatorSpec {
        self.bound.spec(self.learn)
    }

    fn reset(&mut self) {
        self.n = 0;
        self.learning.clear();
        self.bound.reset();
        self.ledger.clear();
    }
}

/// ROT's bound: the rule-of-thumb bandwidth over the running moments of the logs.
#[derive(Debug, Clone)]
pub struct RotBound {
    rot: Rot,
}

impl PajotRot {
    /// A ROT estimator learning from the first `learn` samples (any value is valid; `0` skips
    /// learning). Returns `Result` like every estimator constructor.
    pub fn new(learn: usize) -> Result<Self> {
        Ok(Pajot::with_bound(learn, RotBound { rot: Rot::NEW }))
    }

    /// The current eq. 5 half-width `h` over every non-black log seen (0 for at most one).
    pub fn bandwidth(&self) -> f64 {
        self.settled().bound.rot.bandwidth()
    }
}

impl BoundStrategy for RotBound {
    const OBSERVES_LEARNING: bool = true;

    fn observe(&mut self, l: f64) {
        self.rot.observe(l);
    }

    fn learn_end(&mut self, logs: &[f64], _: u64) -> (f64, f64) {
        self.rot.learn_end(logs);
        (self.rot.m, self.rot.m)
    }

    #[inline(always)]
    fn step(&mut self, l: f64, _: u64, kept: &[f64]) -> Step {
        self.rot.observe(l);
        if l <= self.rot.m {
            return Step {
                settle: None,
                place: None,
            };
        }
        self.update(l, kept)
    }

    fn bound(&self) -> f64 {
        self.rot.m
    }

    fn extras(&self, _: &mut Extras) {}

    fn heap_bytes(&self) -> usize {
        0
    }

    fn reset(&mut self) {
        self.rot = Rot::NEW;
    }

    fn describe(&self, learn: usize, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Pajot-ROT(learn={learn}")
    }

    fn spec(&self, learn: usize) -> EstimatorSpec {
        PajotRotSpec { learn }.into()
    }
}

impl RotBound {
    /// A sample above `m`: ROT's overlap test against the kept samples.
    #[inline(never)]
    fn update(&mut self, l: f64, kept: &[f64]) -> Step {
        let moved = self.rot.update(l, kept);
        let m = self.rot.m;
        let settle = moved.then_some((m, m));
        Step {
            settle,
            place: Some((m, m)),
        }
    }
}

/// ADR's bound: the top of the last extended mode of the approximate distribution
/// representation.
#[derive(Debug, Clone)]
pub struct AdrBound {
    adr: Adr,
}

impl PajotAdr {
    /// An ADR estimator learning from the first `learn` samples (any value is valid).
    pub fn new(learn: usize) -> Result<Self> {
        Ok(Pajot::with_bound(learn, AdrBound { adr: Adr::NEW }))
    }

    /// The modes, ascending.
    pub fn modes(&self) -> Vec<PajotMode> {
        self.settled().bound.adr.public_modes()
    }
}

/// Empties an ADR representation, keeping its allocation.
fn clear_adr(adr: &mut Adr) {
    adr.modes.clear();
    adr.m = f64::NEG_INFINITY;
}

impl BoundStrategy for AdrBound {
    const OBSERVES_LEARNING: bool = false;

    fn observe(&mut self, _: f64) {}

    fn learn_end(&mut self, logs: &[f64], _: u64) -> (f64, f64) {
        self.adr.learn_end(logs);
        (self.adr.m, self.adr.m)
    }

    #[inline(always)]
    fn step(&mut self, l: f64, _: u64, _: &[f64]) -> Step {
        let settle = self.adr.update(l).then_some((self.adr.m, self.adr.m));
        let m = self.adr.m;
        Step {
            settle,
            place: if l <= m { None } else { Some((m, m)) },
        }
    }

    fn bound(&self) -> f64 {
        self.adr.m
    }

    fn extras(&self, x: &mut Extras) {
        let (single, extended) = self.adr.mode_counts();
        x.push(("modes_single", Extra::Int(single)));
        x.push(("modes_extended", Extra::Int(extended)));
    }

    fn heap_bytes(&self) -> usize {
        self.adr.heap_bytes()
    }

    fn reset(&mut self) {
        clear_adr(&mut self.adr);
    }

    fn describe(&self, learn: usize, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Pajot-ADR(learn={learn}")
    }

    fn spec(&self, learn: usize) -> EstimatorSpec {
        PajotAdrSpec { learn }.into()
    }
}

/// The hybrid's bound `m_h` over ROT and ADR side by side, and the switch to ROT alone.
#[derive(Debug, Clone)]
pub struct HybridBound {
    t: usize,
    delta: f64,
    rot: Rot,
    /// `None` once switched to ROT alone.
    adr: Option<Adr>,
    /// ADR's bound when it was dropped.
    adr_last: f64,
    m: f64,
    streak: usize,
    switch_index: Option<u64>,
}

impl PajotHybrid {
    /// A hybrid estimator: `learn` any integer, `t >= 1` agreeing events before the switch,
    /// `delta` finite and `>= 0`.
    pub fn new(learn: usize, t: usize, delta: f64) -> Result<Self> {
        if t < 1 {
            return Err(Error::param("T", t, "must be an integer >= 1"));
        }
        if !(delta >= 0.0 && delta.is_finite()) {
            return Err(Error::param("delta", delta, "must be finite and >= 0"));
        }
        let bound = HybridBound {
            t,
            delta,
            rot: Rot::NEW,
            adr: Some(Adr::NEW),
            adr_last: f64::NEG_INFINITY,
            m: f64::NEG_INFINITY,
            streak: 0,
            switch_index: None,
        };
        Ok(Pajot::with_bound(learn, bound))
    }

    /// ROT's bound `m_ROT` (the same as a standalone [`PajotRot`] on the same stream, without
    /// a cap on the list).
    pub fn rot_bound(&self) -> f64 {
        self.settled().bound.rot.m
    }

    /// ADR's bound `m_ADR` (the same as a standalone [`PajotAdr`] on the same stream until the
    /// switch; frozen at the switch).
    pub fn adr_bound(&self) -> f64 {
        self.settled().bound.adr_bound()
    }

    /// ADR's modes, ascending (empty after the switch).
    pub fn modes(&self) -> Vec<PajotMode> {
        self.settled()
            .bound
            .adr
            .as_ref()
            .map_or_else(Vec::new, Adr::public_modes)
    }

    /// The 0-based index of the sample at which the pixel switched to ROT alone, if it did.
    pub fn switch_index(&self) -> Option<u64> {
        self.settled().bound.switch_index
    }
}

impl HybridBound {
    fn adr_bound(&self) -> f64 {
        self.adr.as_ref().map_or(self.adr_last, |a| a.m)
    }

    /// Lower edge of the kept list: ROT needs the samples above `m_ROT`, the estimate the
    /// ones above `m_h`.
    fn floor(&self) -> f64 {
        self.rot.m.min(self.m)
    }

    /// Updates `m_h` after sample `index`; `changed` says whether `m_ROT` or `m_ADR` moved.
    fn after_sample(&mut self, index: u64, changed: bool) {
        let Some(adr) = &self.adr else {
            self.m = self.m.max(self.rot.m);
            return;
        };
        let (m_rot, m_adr) = (self.rot.m, adr.m);
        self.m = self.m.max(m_adr);
        if !changed {
            return;
        }
        let agree = m_rot.is_finite()
            && m_adr.is_finite()
            && (m_rot - m_adr).abs() <= self.delta * m_adr.abs();
        self.streak = if agree { self.streak + 1 } else { 0 };
        if self.streak == self.t {
            self.m = self.m.max(m_adr).max(m_rot);
            self.adr_last = m_adr;
            self.adr = None;
            self.switch_index = Some(index);
        }
    }

    fn update(&mut self, index: u64, l: f64, kept: &[f64]) -> Step {
        let (old_bound, old_floor) = (self.m, self.floor());
        let changed_rot = self.rot.update(l, kept);
        let changed_adr = self.adr.as_mut().is_some_and(|a| a.update(l));
        self.after_sample(index, changed_rot || changed_adr);
        let (bound, floor) = (self.m, self.floor());
        Step {
            settle: (bound != old_bound || floor != old_floor).then_some((bound, floor)),
            place: Some((bound, floor)),
        }
    }
}

impl BoundStrategy for HybridBound {
    const OBSERVES_LEARNING: bool = true;

    fn observe(&mut self, l: f64) {
        self.rot.observe(l);
    }

    fn learn_end(&mut self, logs: &[f64], index: u64) -> (f64, f64) {
        let changed_rot = self.rot.learn_end(logs);
        let changed_adr = self.adr.as_mut().is_some_and(|a| a.learn_end(logs));
        self.after_sample(index, changed_rot || changed_adr);
        (self.m, self.floor())
    }

    #[inline(always)]
    fn step(&mut self, l: f64, index: u64, kept: &[f64]) -> Step {
        self.rot.observe(l);
        if self.adr.is_none() && l <= self.rot.m {
            // Switched: ROT alone, and l <= m_ROT <= m_h, so nothing moves and l need not be
            // kept. (Between m_ROT and m_h, l is accepted but is one of ROT's overlap points.)
            return Step {
                settle: None,
                place: None,
            };
        }
        self.update(index, l, kept)
    }

    fn bound(&self) -> f64 {
        self.m
    }

    fn extras(&self, x: &mut Extras) {
        let (single, extended) = self.adr.as_ref().map_or((0, 0), Adr::mode_counts);
        x.push(("m_rot", Extra::Float(self.rot.m)));
        x.push(("m_adr", Extra::Float(self.adr_bound())));
        x.push(("modes_single", Extra::Int(single)));
        x.push(("modes_extended", Extra::Int(extended)));
        x.push(("switched", Extra::Bool(self.switch_index.is_some())));
        if let Some(i) = self.switch_index {
            x.push(("switch_index", Extra::Int(i)));
        }
    }

    fn heap_bytes(&self) -> usize {
        self.adr.as_ref().map_or(0, Adr::heap_bytes)
    }

    fn reset(&mut self) {
        self.rot = Rot::NEW;
        match &mut self.adr {
            Some(a) => clear_adr(a),
            None => self.adr = Some(Adr::NEW),
        }
        self.adr_last = f64::NEG_INFINITY;
        self.m = f64::NEG_INFINITY;
        self.streak = 0;
        self.switch_index = None;
    }

    fn describe(&self, learn: usize, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Pajot-hybrid(learn={learn},T={},delta={}",
            self.t, self.delta
        )
    }

    fn spec(&self, learn: usize) -> EstimatorSpec {
        PajotHybridSpec {
            learn,
            t: self.t,
            delta: self.delta,
        }
        .into()
    }
}
