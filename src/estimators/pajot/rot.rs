//! The rule-of-thumb bound ([P] §4.4, eq. 5; docs/estimators.md §6.2).

use super::for_each_run;
use crate::estimators::Welford;

/// ROT's state: the log-luminance moments and the bound `m`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Rot {
    /// Moments of every non-black log seen.
    pub(super) welford: Welford,
    /// The acceptance bound (log units), `-inf` until a mode exists.
    pub(super) m: f64,
}

impl Rot {
    pub(super) const NEW: Rot = Rot {
        welford: Welford::new(),
        m: f64::NEG_INFINITY,
    };

    /// Adds a non-black sample's log to the moments (every one counts, accepted or not).
    #[inline(always)]
    pub(super) fn observe(&mut self, l: f64) {
        self.welford.push(l);
    }

    /// Eq. 5: `h = (25 k)^(-1/5) σ` over the logs seen so far; 0 for `k <= 1`.
    pub(super) fn bandwidth(&self) -> f64 {
        let k = self.welford.count();
        if k <= 1 {
            0.0
        } else {
            (25.0 * k as f64).powf(-0.2) * self.welford.sigma()
        }
    }

    /// End of learning: modes of the ascending logs under the common bandwidth; `m` becomes the
    /// top of the last extended mode. Returns whether `m` changed.
    pub(super) fn learn_end(&mut self, logs: &[f64]) -> bool {
        let w = {
            let h = self.bandwidth();
            h + h
        };
        let mut top = f64::NEG_INFINITY;
        for_each_run(
            logs,
            |i| logs[i] == logs[i + 1] || (logs[i + 1] - logs[i]).abs() < w,
            |_, hi, count| {
                if count >= 2 {
                    top = hi;
                }
            },
        );
        let old = self.m;
        self.m = self.m.max(top);
        self.m != old
    }

    /// After learning, for a non-black `l` already observed: when `l > m`, tests it against
    /// `Q = {m} ∪ kept` and raises `m` to the largest of `l` and the overlapped points.
    /// `kept` must hold (at least) every ROT-delayed sample, ascending; kept samples at or below
    /// `m` may be present and change nothing (one that overlaps `l` lies between `m` and `l`,
    /// so `m` overlaps too, and it is below `l`). Returns whether `m` changed.
    pub(super) fn update(&mut self, l: f64, kept: &[f64]) -> bool {
        if l <= self.m {
            return false;
        }
        let w = {
            let h = self.bandwidth();
            h + h
        };
        let overlaps = |q: f64| q == l || (q - l).abs() < w;
        let mut hit = self.m.is_finite() && overlaps(self.m);
        let mut top = l;
        // The overlapping kept points are contiguous; the largest candidate is the last one
        // whose log is at most l or within 2h above it (a monotone predicate).
        let end = kept.partition_point(|&s| {
            let q = s.ln();
            q <= l || q - l < w
        });
        if let Some(&s) = end.checked_sub(1).and_then(|i| kept.get(i)) {
            let q = s.ln();
            if overlaps(q) {
                hit = true;
                top = top.max(q);
            }
        }
        if hit {
            self.m = top;
        }
        hit
    }
}
