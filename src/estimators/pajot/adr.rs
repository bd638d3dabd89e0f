//! Adaptive bandwidths and the approximate distribution representation ([P] §3.1 eq. 4, §4.2;
//! spec §6.3).

use super::for_each_run;

/// One mode of ADR's approximate distribution representation, in log-luminance units.
///
/// A single mode has `count == 1` and `lo == hi`; an extended mode (`count >= 2`) stands for
/// `count` evenly spaced points from `lo` to `hi` (see [`PajotMode::points`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PajotMode {
    /// Smallest log-luminance of the mode.
    pub lo: f64,
    /// Largest log-luminance of the mode.
    pub hi: f64,
    /// Number of samples the mode represents.
    pub count: u64,
}

impl PajotMode {
    /// Whether the mode holds at least two samples.
    pub fn is_extended(&self) -> bool {
        self.count >= 2
    }

    /// The points the mode stands for when bandwidths are computed (spec §6.3):
    /// `lo + ((hi - lo) k) / (count - 1)` for `k = 0..count-2`, then `hi`; a single mode is `lo`.
    pub fn points(&self) -> impl Iterator<Item = f64> + '_ {
        let c = self.count;
        let span = self.hi - self.lo;
        let denom = c.saturating_sub(1) as f64;
        (0..c.saturating_sub(1))
            .map(move |k| self.lo + (span * k as f64) / denom)
            .chain(std::iter::once(self.hi).filter(move |_| c >= 1))
    }
}

/// Eq. 4 bandwidths of an ascending point set (spec §6.3): all 0 when there are fewer than two
/// points or the mean nearest-neighbour distance `nn` is 0; otherwise `h_i = nn sqrt(g / p_i)`
/// with the Epanechnikov pilot `p_i` (bandwidth `nn`) and `g` the geometric mean of the `p_i`.
///
/// The input must be sorted ascending (it is not checked; an unsorted input gives wrong `nn`).
pub fn adr_bandwidths(points: &[f64]) -> Vec<f64> {
    let mut p = Vec::new();
    match pilot(points, &mut p) {
        None => vec![0.0; points.len()],
        Some(Pilot { nn, g }) => p.iter().map(|&pi| nn * (g / pi).sqrt()).collect(),
    }
}

/// `nn` and `g` of eq. 4; `h_i = nn sqrt(g / p_i)`.
#[derive(Debug, Clone, Copy)]
struct Pilot {
    nn: f64,
    g: f64,
}

/// Fills `p` with the pilot densities of the ascending `xs`; `None` when every bandwidth is 0.
///
/// The Epanechnikov pilot has compact support, so each `p_i` sums only the points within `nn`
/// of `x_i` (a sliding window). `ln g` is the mean of `ln p_i`, accumulated as logs of partial
/// products (every `p_i >= 1`, its own term) to call `ln` rarely.
fn pilot(xs: &[f64], p: &mut Vec<f64>) -> Option<Pilot> {
    let k = xs.len();
    p.clear();
    if k < 2 {
        return None;
    }
    let mut nn_sum = 0.0;
    for i in 0..k {
        let left = if i > 0 { (xs[i] - xs[i - 1]).abs() } else { f64::INFINITY };
        let right = if i + 1 < k { (xs[i + 1] - xs[i]).abs() } else { f64::INFINITY };
        nn_sum += left.min(right);
    }
    let nn = nn_sum / k as f64;
    if !(nn > 0.0 && nn.is_finite()) {
        return None;
    }
    p.reserve(k);
    let (mut lo, mut hi) = (0, 0);
    let mut ln_sum = 0.0;
    let mut product = 1.0;
    for (i, &x) in xs.iter().enumerate() {
        while x - xs[lo] >= nn {
            lo += 1;
        }
        hi = hi.max(i + 1);
        while hi < k && xs[hi] - x < nn {
            hi += 1;
        }
        let mut pi = 0.0;
        for &y in &xs[lo..hi] {
            let r = (x - y) / nn;
            pi += (1.0 - r * r).max(0.0);
        }
        p.push(pi);
        product *= pi;
        if product > 1e200 {
            ln_sum += product.ln();
            product = 1.0;
        }
    }
    ln_sum += product.ln();
    let g = (ln_sum / k as f64).exp();
    Some(Pilot { nn, g })
}

/// ADR's state: the ordered, disjoint modes and the bound `m` (the top of the last extended
/// mode).
#[derive(Debug, Clone)]
pub(super) struct Adr {
    pub(super) modes: Vec<PajotMode>,
    /// The acceptance bound (log units), `-inf` until an extended mode exists.
    pub(super) m: f64,
}

impl Adr {
    pub(super) const NEW: Adr = Adr {
        modes: Vec::new(),
        m: f64::NEG_INFINITY,
    };

    /// Heap bytes held by the modes.
    pub(super) fn heap_bytes(&self) -> usize {
        self.modes.capacity() * size_of::<PajotMode>()
    }

    /// Numbers of single and extended modes.
    pub(super) fn mode_counts(&self) -> (u64, u64) {
        let ext = self.modes.iter().filter(|m| m.is_extended()).count() as u64;
        (self.modes.len() as u64 - ext, ext)
    }

    /// End of learning: eq. 4 bandwidths on the exact ascending logs, modes by chaining
    /// overlapping neighbours. Returns whether `m` changed.
    pub(super) fn learn_end(&mut self, logs: &[f64]) -> bool {
        let h = adr_bandwidths(logs);
        self.modes.clear();
        self.modes.reserve_exact(logs.len().min(16));
        let modes = &mut self.modes;
        for_each_run(
            logs,
            |i| logs[i] == logs[i + 1] || (logs[i + 1] - logs[i]).abs() < h[i] + h[i + 1],
            |lo, hi, count| modes.push(PajotMode { lo, hi, count }),
        );
        let top = self
            .modes
            .iter()
            .rev()
            .find(|m| m.is_extended())
            .map_or(f64::NEG_INFINITY, |m| m.hi);
        let old = self.m;
        self.m = self.m.max(top);
        self.m != old
    }

    /// After learning, adds a non-black `l` to the representation (spec §6.3). Returns whether
    /// `m` changed.
    pub(super) fn update(&mut self, l: f64) -> bool {
        let i = self.modes.partition_point(|md| md.hi < l);
        if let Some(md) = self.modes.get_mut(i) {
            if md.is_extended() && md.lo <= l {
                md.count += 1;
                return false;
            }
        }
        let Some((a, b)) = self.overlapped(l, i) else {
            self.modes.insert(i, PajotMode { lo: l, hi: l, count: 1 });
            return false;
        };
        // Span l and the overlapped modes, then absorb every mode meeting the span.
        let (mut a, mut b) = (a, b);
        let mut lo = l.min(self.modes[a].lo);
        let mut hi = l.max(self.modes[b].hi);
        while a > 0 && self.modes[a - 1].hi >= lo {
            a -= 1;
            lo = lo.min(self.modes[a].lo);
        }
        while b + 1 < self.modes.len() && self.modes[b + 1].lo <= hi {
            b += 1;
            hi = hi.max(self.modes[b].hi);
        }
        let count = self.modes[a..=b].iter().map(|m| m.count).sum::<u64>() + 1;
        self.modes.splice(a..=b, [PajotMode { lo, hi, count }]);
        let old = self.m;
        self.m = self.m.max(hi);
        self.m != old
    }

    /// The range of modes (first, last) having a point that `l` overlaps under the eq. 4
    /// bandwidths of all modes' points plus `l`; `None` if no point overlaps. `i` is the index of
    /// the first mode whose top is `>= l` (`l` goes between modes `i - 1` and `i`).
    fn overlapped(&self, l: f64, i: usize) -> Option<(usize, usize)> {
        let total: u64 = self.modes.iter().map(|m| m.count).sum();
        let mut xs = Vec::with_capacity(usize::try_from(total).unwrap_or(0).saturating_add(1));
        for md in &self.modes[..i] {
            xs.extend(md.points());
        }
        let pos = xs.len();
        xs.push(l);
        for md in &self.modes[i..] {
            xs.extend(md.points());
        }
        let mut p = Vec::new();
        let pilot = pilot(&xs, &mut p);
        let h = |j: usize| pilot.map_or(0.0, |Pilot { nn, g }| nn * (g / p[j]).sqrt());
        let h_l = h(pos);
        let h_max = pilot.map_or(0.0, |Pilot { nn, g }| {
            let p_min = p.iter().copied().fold(f64::INFINITY, f64::min);
            nn * (g / p_min).sqrt()
        });
        let reach = h_l + h_max;
        let hits = |j: usize| xs[j] == l || (l - xs[j]).abs() < h_l + h(j);

        // Scan left of l, tracking which mode each point belongs to.
        let mut first = None;
        if i > 0 {
            let mut mode = i - 1;
            let mut start = pos - self.modes[mode].count as usize;
            for j in (0..pos).rev() {
                if xs[j] != l && !(l - xs[j] < reach) {
                    break;
                }
                while j < start {
                    mode -= 1;
                    start -= self.modes[mode].count as usize;
                }
                if hits(j) {
                    first = Some(mode);
                }
            }
        }
        let mut last = None;
        if i < self.modes.len() {
            let mut mode = i;
            let mut end = pos + 1 + self.modes[mode].count as usize;
            for j in pos + 1..xs.len() {
                if xs[j] != l && !(xs[j] - l < reach) {
                    break;
                }
                while j >= end {
                    mode += 1;
                    end += self.modes[mode].count as usize;
                }
                if hits(j) {
                    last = Some(mode);
                }
            }
        }
        match (first, last) {
            (None, None) => None,
            (Some(a), None) => Some((a, i - 1)),
            (None, Some(b)) => Some((i, b)),
            (Some(a), Some(b)) => Some((a, b)),
        }
    }
}
