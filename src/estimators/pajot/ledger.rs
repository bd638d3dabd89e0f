//! Acceptance bookkeeping shared by the three Pajot estimators: the running sum of accepted
//! samples and the sorted list of samples the method still has to remember.

use crate::estimators::numeric::ScaledSum;

/// The accepted sum and the kept list.
///
/// `kept` holds non-black samples (linear values, ascending) whose log lies above a *floor*;
/// the prefix `kept[..summed]` has already been accepted (its log is at most the acceptance
/// *bound*), the rest is delayed. The standalone estimators use `floor = bound = m`, so `kept` is
/// exactly the delayed list; the hybrid uses `floor = min(m_ROT, m_h)` so that one list serves
/// both as its own delayed list and as ROT's overlap points.
///
/// Entries are stored as linear values (8 bytes each) and compared through `ln`, which is
/// monotone, so ascending values are ascending logs.
#[derive(Debug, Clone)]
pub(super) struct Ledger {
    /// Compensated sum of the accepted samples, rescaled before it would overflow (so the mean
    /// of accepted samples near `f64::MAX` stays finite).
    sum: ScaledSum,
    /// Number of accepted samples, black ones included.
    accepted: u64,
    kept: Vec<f64>,
    summed: usize,
    cap: usize,
    dropped: u64,
}

impl Ledger {
    /// An empty ledger keeping at most `cap` entries (`usize::MAX`: unbounded).
    pub(super) fn new(cap: usize) -> Self {
        Ledger {
            sum: ScaledSum::new(),
            accepted: 0,
            kept: Vec::new(),
            summed: 0,
            cap,
            dropped: 0,
        }
    }

    /// Forgets every sample, keeping the cap and the list's allocation.
    pub(super) fn clear(&mut self) {
        self.sum = ScaledSum::new();
        self.accepted = 0;
        self.kept.clear();
        self.summed = 0;
        self.dropped = 0;
    }

    /// The cap on the kept list (`usize::MAX` when unbounded).
    pub(super) fn cap(&self) -> usize {
        self.cap
    }

    /// Accepts a black sample (it adds nothing to the sum but counts in the divisor).
    #[inline]
    pub(super) fn zero(&mut self) {
        self.accepted += 1;
    }

    /// Accepts a sample that need not be remembered.
    #[inline]
    pub(super) fn accept(&mut self, s: f64) {
        self.sum.add(s);
        self.accepted += 1;
    }

    /// The kept samples, ascending.
    pub(super) fn kept(&self) -> &[f64] {
        &self.kept
    }

    /// Number of delayed samples (kept and not accepted).
    pub(super) fn delayed(&self) -> usize {
        self.kept.len() - self.summed
    }

    /// Delayed samples discarded because the list was full.
    pub(super) fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Number of accepted samples, black ones included.
    pub(super) fn accepted(&self) -> u64 {
        self.accepted
    }

    /// Mean of the accepted samples; 0 when none is accepted.
    pub(super) fn mean(&self) -> f64 {
        if self.accepted == 0 {
            0.0
        } else {
            self.sum.mean(self.accepted)
        }
    }

    /// Heap bytes held (the list's capacity).
    pub(super) fn heap_bytes(&self) -> usize {
        self.kept.capacity() * size_of::<f64>()
    }

    /// After the bound or the floor grew: accepts every kept sample whose log is `<= bound`,
    /// then forgets the accepted ones whose log is `<= floor` (`floor <= bound`).
    pub(super) fn settle(&mut self, bound: f64, floor: f64) {
        while let Some(&s) = self.kept.get(self.summed) {
            if !(s.ln() <= bound) {
                break;
            }
            self.sum.add(s);
            self.accepted += 1;
            self.summed += 1;
        }
        let gone = self.kept[..self.summed].partition_point(|s| s.ln() <= floor);
        if gone > 0 {
            self.kept.drain(..gone);
            self.summed -= gone;
            // A released list can be far shorter than its peak: give the memory back.
            if self.kept.capacity() > 16 && self.kept.len() * 4 < self.kept.capacity() {
                self.kept.shrink_to(self.kept.len() * 2);
            }
        }
    }

    /// Classifies a non-black sample `s` with log `l` against `bound`, remembering it when its
    /// log exceeds `floor`. Call [`Ledger::settle`] first if the bound or floor moved.
    pub(super) fn place(&mut self, s: f64, l: f64, bound: f64, floor: f64) {
        if l <= bound {
            self.sum.add(s);
            self.accepted += 1;
            if l > floor {
                let at = self.kept[..self.summed].partition_point(|&x| x <= s);
                self.kept.insert(at, s);
                self.summed += 1;
                self.enforce_cap();
            }
        } else {
            let at = self.summed + self.kept[self.summed..].partition_point(|&x| x <= s);
            self.kept.insert(at, s);
            self.enforce_cap();
        }
    }

    /// When the list is over its cap, forgets its largest entry: the delayed sample least
    /// likely ever to be accepted (the bound must pass every smaller one first).
    fn enforce_cap(&mut self) {
        if self.kept.len() > self.cap {
            self.kept.pop();
            if self.summed > self.kept.len() {
                // Everything kept was accepted: the forgotten entry stays in the estimate and
                // only stops being one of ROT's overlap points (hybrid only).
                self.summed = self.kept.len();
            } else {
                self.dropped += 1;
            }
        }
    }
}
