//! Adaptive bandwidths and the approximate distribution representation ([P] §3.1 eq. 4, §4.2;
//! docs/estimators.md §6.3).

use super::for_each_run;

#[cfg(test)]
mod reference;

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

    /// The points the mode stands for when bandwidths are computed (docs/estimators.md §6.3):
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

/// Eq. 4 bandwidths of an ascending point set (docs/estimators.md §6.3): all 0 when there are fewer than two
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
        let left = if i > 0 {
            (xs[i] - xs[i - 1]).abs()
        } else {
            f64::INFINITY
        };
        let right = if i + 1 < k {
            (xs[i + 1] - xs[i]).abs()
        } else {
            f64::INFINITY
        };
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
    /// Index of the mode the last sample fell in (a guess: checked before use).
    pub(super) hint: usize,
}

impl Adr {
    pub(super) const NEW: Adr = Adr {
        modes: Vec::new(),
        m: f64::NEG_INFINITY,
        hint: 0,
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

    /// After learning, adds a non-black `l` to the representation (docs/estimators.md §6.3). Returns whether
    /// `m` changed.
    pub(super) fn update(&mut self, l: f64) -> bool {
        self.update_with(l, Adr::overlapped)
    }

    /// [`Adr::update`] with the overlap search given (the unit tests pass the reference).
    #[inline(always)]
    fn update_with(
        &mut self,
        l: f64,
        overlapped: impl Fn(&Adr, f64, usize) -> Option<(usize, usize)>,
    ) -> bool {
        // Most samples fall in the mode the previous one fell in: try it before searching.
        if let Some(md) = self.modes.get_mut(self.hint) {
            if md.is_extended() && md.lo <= l && l <= md.hi {
                md.count += 1;
                return false;
            }
        }
        let i = self.modes.partition_point(|md| md.hi < l);
        if let Some(md) = self.modes.get_mut(i) {
            if md.is_extended() && md.lo <= l {
                md.count += 1;
                self.hint = i;
                return false;
            }
        }
        let Some((a, b)) = overlapped(self, l, i) else {
            self.modes.insert(
                i,
                PajotMode {
                    lo: l,
                    hi: l,
                    count: 1,
                },
            );
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
    ///
    /// The point set is never materialised (module doc, decision 17): see [`Query`].
    pub(super) fn overlapped(&self, l: f64, i: usize) -> Option<(usize, usize)> {
        let q = Query {
            modes: &self.modes,
            l,
            i,
        };
        let Some((nn, g)) = q.pilot() else {
            // Every bandwidth is 0: only a point equal to l overlaps it, and the only point
            // that can equal l is a single mode just after it.
            return self.modes.get(i).filter(|m| m.lo == l).map(|_| (i, i));
        };
        let h = |s: usize, seg: &Seg, k: u64| nn * (g / q.p_at(s, seg, k, nn)).sqrt();
        let h_l = h(i, &q.seg(i, nn), 0);
        // Every p >= 1 (its own term), so no h exceeds nn sqrt(g).
        let reach = h_l + nn * g.sqrt();
        let hits = |x: f64, s: usize, seg: &Seg, k: u64| x == l || (l - x).abs() < h_l + h(s, seg, k);

        let mut first = None;
        'left: for s in (0..i).rev() {
            let seg = q.seg(s, nn);
            for k in seg.nearest_first(true) {
                let x = seg.at(k);
                if x != l && !(l - x < reach) {
                    break 'left;
                }
                if hits(x, s, &seg, k) {
                    first = Some(s);
                }
            }
        }
        let mut last = None;
        'right: for s in i + 1..q.runs() {
            let seg = q.seg(s, nn);
            for k in seg.nearest_first(false) {
                let x = seg.at(k);
                if x != l && !(x - l < reach) {
                    break 'right;
                }
                if hits(x, s, &seg, k) {
                    last = Some(s - 1);
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

/// One run of ADR's point set: a mode's evenly spaced points, or the newcomer alone.
#[derive(Debug, Clone, Copy)]
pub(super) struct Seg {
    lo: f64,
    hi: f64,
    c: u64,
    /// Spacing `(hi - lo) / (c - 1)` (0 for a single).
    d: f64,
    /// How many same-run neighbours on each side lie closer than `nn` (`j d < nn`).
    w: u64,
}

impl Seg {
    fn new(lo: f64, hi: f64, c: u64) -> Seg {
        let d = if c >= 2 {
            (hi - lo) / (c - 1) as f64
        } else {
            0.0
        };
        Seg { lo, hi, c, d, w: 0 }
    }

    /// This run with its `w` for the mean nearest-neighbour distance `nn`.
    pub(super) fn with_w(mut self, nn: f64) -> Seg {
        self.w = if self.c < 2 {
            0
        } else if self.is_point() || nn / self.d > (self.c - 1) as f64 {
            self.c - 1
        } else {
            // The largest integer j with j d < nn.
            ((nn / self.d).ceil() - 1.0).max(0.0) as u64
        };
        self
    }

    /// The points of the run to test for overlap, nearest to the newcomer first (`from_top`:
    /// the run lies below it). The interior points all share one bandwidth, so only the
    /// nearest of them is listed: if it misses, the farther ones miss too.
    pub(super) fn nearest_first(&self, from_top: bool) -> Nearest {
        let (c, w) = (self.c, self.w);
        // Ascending: the bottom points, the one interior point listed, the top points.
        let (bottom, mid, top) = if self.is_point() {
            (0..1, 0..0, c..c)
        } else if self.has_interior() {
            let m = if from_top { c - 2 - w } else { w + 1 };
            (0..w + 1, m..m + 1, c - 1 - w..c)
        } else {
            (0..c, 0..0, c..c)
        };
        Nearest {
            ranges: if from_top {
                [top, mid, bottom]
            } else {
                [bottom, mid, top]
            },
            from_top,
            at: 0,
        }
    }

    /// Point `k` (docs/estimators.md §6.3's formula; the last one is `hi`).
    #[inline]
    fn at(&self, k: u64) -> f64 {
        if k + 1 >= self.c {
            self.hi
        } else {
            self.lo + ((self.hi - self.lo) * k as f64) / (self.c - 1) as f64
        }
    }

    /// Whether every point coincides (a single, or `lo == hi`).
    fn is_point(&self) -> bool {
        !(self.d > 0.0)
    }

    /// Whether the points strictly between the first `w + 1` and the last `w + 1` exist; they
    /// all see exactly `w` same-run neighbours on each side and nothing else.
    fn has_interior(&self) -> bool {
        !self.is_point() && self.c > 2 * self.w + 2
    }
}

/// Point indices of a run, nearest to the newcomer first ([`Seg::nearest_first`]): three
/// ranges in turn, each walked downwards when the run lies below the newcomer.
pub(super) struct Nearest {
    ranges: [std::ops::Range<u64>; 3],
    from_top: bool,
    at: usize,
}

impl Iterator for Nearest {
    type Item = u64;

    fn next(&mut self) -> Option<u64> {
        while let Some(r) = self.ranges.get_mut(self.at) {
            let k = if self.from_top {
                r.next_back()
            } else {
                r.next()
            };
            if k.is_some() {
                return k;
            }
            self.at += 1;
        }
        None
    }
}

/// `Σ_{j=1..w} (1 - (j r)^2)`: the Epanechnikov pilot terms of `w` evenly spaced neighbours at
/// spacing `r` (in units of `nn`).
pub(super) fn kernel_sum(w: u64, r: f64) -> f64 {
    let w = w as f64;
    w - r * r * w * (w + 1.0) * (2.0 * w + 1.0) / 6.0
}

/// ADR's point set for one newcomer: the modes with `l` inserted as a single run at index `i`,
/// read in place (run `t` is mode `t` below `i` and mode `t - 1` above it).
///
/// An extended mode stands for `c` evenly spaced points; all but the `w + 1` at each end see
/// exactly `w` neighbours on each side within `nn` and none outside the mode, so they share one
/// pilot value `1 + 2 Σ_{j<=w} (1 - (j d / nn)^2)`. Those are counted in closed form; the end
/// points, and points whose window reaches another run, are evaluated one by one. Same-mode
/// neighbours are taken at the exact spacing `d`, which differs from the rounded point values
/// by a rounding error; a neighbour at the window's edge contributes ~0 either way.
///
/// Cost per newcomer: `O(modes + Σ min(c, w))` floating-point operations and one `ln` per
/// extended mode, without allocating. An end point whose run lies at least `nn` from both
/// neighbouring runs has no term from them, so its pilot value is the in-mode part alone; the
/// checks that prove this use the run's extreme points, so the values are those of a walk
/// over the neighbours (the unit tests compare with such a walk bit for bit).
#[derive(Clone, Copy)]
struct Query<'a> {
    modes: &'a [PajotMode],
    l: f64,
    i: usize,
}

impl Query<'_> {
    /// Number of runs (modes plus the newcomer).
    fn runs(&self) -> usize {
        self.modes.len() + 1
    }

    /// `(lo, hi, count)` of run `t`.
    #[inline(always)]
    fn run(&self, t: usize) -> (f64, f64, u64) {
        use std::cmp::Ordering::*;
        match t.cmp(&self.i) {
            Less => {
                let m = &self.modes[t];
                (m.lo, m.hi, m.count)
            }
            Equal => (self.l, self.l, 1),
            Greater => {
                let m = &self.modes[t - 1];
                (m.lo, m.hi, m.count)
            }
        }
    }

    /// Run `t` with its `w` for the mean nearest-neighbour distance `nn`.
    #[inline]
    fn seg(&self, t: usize, nn: f64) -> Seg {
        let (lo, hi, c) = self.run(t);
        Seg::new(lo, hi, c).with_w(nn)
    }

    /// Number of points, as the sum of the counts in `f64` plus one.
    fn points(&self) -> f64 {
        let mut total: u64 = 0;
        for m in self.modes {
            total = total.saturating_add(m.count);
        }
        if total < 1 << 52 {
            // Every partial sum of the f64 counts is an exact integer: the same value.
            total as f64 + 1.0
        } else {
            self.modes.iter().map(|m| m.count as f64).sum::<f64>() + 1.0
        }
    }

    /// `nn` and `g` of eq. 4, or `None` when every bandwidth is 0.
    fn pilot(&self) -> Option<(f64, f64)> {
        let k = self.points();
        if k < 2.0 {
            return None;
        }
        // Mean distance to the nearest other point, summed run by run in order.
        let n = self.runs();
        let mut nn_sum = 0.0;
        let mut prev = f64::INFINITY;
        let mut cur = self.run(0);
        for t in 0..n {
            let next_run = (t + 1 < n).then(|| self.run(t + 1));
            let (lo, hi, c) = cur;
            let next = next_run.map_or(f64::INFINITY, |r| r.0 - hi);
            if c == 1 {
                nn_sum += prev.min(next);
            } else {
                let seg = Seg::new(lo, hi, c);
                nn_sum += prev.min(seg.at(1) - lo);
                nn_sum += next.min(hi - seg.at(c - 2));
                nn_sum += (c - 2) as f64 * seg.d;
            }
            prev = next;
            if let Some(r) = next_run {
                cur = r;
            }
        }
        let nn = nn_sum / k;
        if !(nn > 0.0 && nn.is_finite()) {
            return None;
        }
        // ln g = mean of ln p, as logs of partial products (every p >= 1).
        let mut ln_sum = 0.0;
        let mut product = 1.0;
        let mut take = |p: f64, ln_sum: &mut f64| {
            product *= p;
            if product > 1e200 {
                *ln_sum += product.ln();
                product = 1.0;
            }
        };
        let mut prev_hi = f64::NAN;
        for s in 0..n {
            let seg = self.seg(s, nn);
            let next_lo = if s + 1 < n {
                self.run(s + 1).0
            } else {
                f64::NAN
            };
            if seg.c == 1 {
                // p = 1 unless a neighbour lies within nn (x = lo = hi); a factor 1 changes
                // nothing.
                if s > 0 && seg.lo - prev_hi < nn || s + 1 < n && next_lo - seg.lo < nn {
                    take(self.p_at(s, &seg, 0, nn), &mut ln_sum);
                }
            } else if seg.is_point() {
                ln_sum += seg.c as f64 * self.p_at(s, &seg, 0, nn).ln();
            } else {
                let alone = (s == 0 || !(seg.lo - prev_hi < nn))
                    && (s + 1 == n
                        || !(next_lo - seg.hi < nn) && !(next_lo - seg.at(seg.c - 2) < nn));
                let (c, w) = (seg.c, seg.w);
                let r = seg.d / nn;
                let p = |k: u64| {
                    if alone {
                        1.0 + (kernel_sum(k.min(w), r) + kernel_sum((c - 1 - k).min(w), r))
                    } else {
                        self.p_at(s, &seg, k, nn)
                    }
                };
                if seg.has_interior() {
                    for k in (0..=w).chain(c - 1 - w..c) {
                        take(p(k), &mut ln_sum);
                    }
                    let interior = (c - 2 * w - 2) as f64;
                    ln_sum += interior * (1.0 + 2.0 * kernel_sum(w, r)).ln();
                } else {
                    for k in 0..c {
                        take(p(k), &mut ln_sum);
                    }
                }
            }
            prev_hi = seg.hi;
        }
        ln_sum += product.ln();
        Some((nn, (ln_sum / k).exp()))
    }

    /// The pilot `p` at point `k` of run `s` (`seg`, with its `w`): itself, its own run's
    /// neighbours within `nn`, and other runs' points within `nn`.
    fn p_at(&self, s: usize, seg: &Seg, k: u64, nn: f64) -> f64 {
        let x = seg.at(k);
        let mut p = 1.0;
        if seg.c >= 2 {
            if seg.is_point() {
                p += (seg.c - 1) as f64;
            } else {
                let r = seg.d / nn;
                p += kernel_sum(k.min(seg.w), r) + kernel_sum((seg.c - 1 - k).min(seg.w), r);
            }
        }
        for t in (0..s).rev() {
            let (sum, done) = self.from_run(t, x, nn, true);
            p += sum;
            if done {
                break;
            }
        }
        for t in s + 1..self.runs() {
            let (sum, done) = self.from_run(t, x, nn, false);
            p += sum;
            if done {
                break;
            }
        }
        p
    }

    /// Pilot terms at `x` from the points of run `t` lying below (`below`) or above it;
    /// `done` when runs further away cannot contribute.
    fn from_run(&self, t: usize, x: f64, nn: f64, below: bool) -> (f64, bool) {
        let (lo, hi, c) = self.run(t);
        // Distances from x to the run's near and far ends.
        let (near, far) = if below { (x - hi, x - lo) } else { (lo - x, hi - x) };
        if !(near < nn) {
            return (0.0, true);
        }
        let seg = Seg::new(lo, hi, c);
        if far < nn {
            // The whole run is inside the window: Σ_j (1 - ((near + j d) / nn)^2) in closed
            // form, j = 0..c-1.
            let c = seg.c as f64;
            let (sj, sj2) = (c * (c - 1.0) / 2.0, (c - 1.0) * c * (2.0 * c - 1.0) / 6.0);
            let sq = c * near * near + 2.0 * near * seg.d * sj + seg.d * seg.d * sj2;
            return (c - sq / (nn * nn), false);
        }
        // Part of the run: walk from the near end until the window's edge.
        let mut sum = 0.0;
        for j in 0..seg.c {
            let y = if below {
                seg.at(seg.c - 1 - j)
            } else {
                seg.at(j)
            };
            let r = (x - y) / nn;
            if !(r.abs() < 1.0) {
                break;
            }
            sum += 1.0 - r * r;
        }
        (sum, true)
    }
}
