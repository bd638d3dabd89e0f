//! Adaptive bandwidths and the approximate distribution representation ([P] §3.1 eq. 4, §4.2;
//! docs/estimators.md §6.3).

use super::for_each_run;

#[cfg(test)]
pub(super) mod reference;

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

    /// ADR holding `modes` (ascending, disjoint) and the bound `m`.
    #[cfg(test)]
    pub(super) fn with_modes(modes: &[PajotMode], m: f64) -> Adr {
        Adr {
            modes: modes.to_vec(),
            m,
            hint: 0,
        }
    }

    /// The modes, ascending.
    pub(super) fn public_modes(&self) -> Vec<PajotMode> {
        self.modes.clone()
    }

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
        #[cfg(test)]
        if reference::reference() {
            return self.update_ref(l);
        }

        // Most samples fall in the mode the previous one fell in, or in its neighbour on their
        // side: try those before searching.
        let h = self.hint;
        if let Some(md) = self.modes.get(h) {
            let j = if l < md.lo {
                h.wrapping_sub(1)
            } else if l > md.hi {
                h + 1
            } else {
                h
            };
            if let Some(md) = self.modes.get_mut(j) {
                if md.is_extended() && md.lo <= l && l <= md.hi {
                    md.count += 1;
                    self.hint = j;
                    return false;
                }
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
        let overlap = self.overlapped(l, i);
        self.merge(l, i, overlap)
    }

    /// The last step of [`Adr::update`] once the search has placed `l` before mode `i` and
    /// found the modes `a..=b` it overlaps (if any): a new point mode, or one mode spanning `l`
    /// and every mode meeting that span. Returns whether `m` changed.
    fn merge(&mut self, l: f64, i: usize, overlap: Option<(usize, usize)>) -> bool {
        let Some((mut a, mut b)) = overlap else {
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
        query(&self.modes, l, i, |q| q.overlapped())
    }
}

/// Runs `f` on the query of `l` (index `i`) among `modes`.
fn query<T>(modes: &[PajotMode], l: f64, i: usize, f: impl FnOnce(&Query) -> T) -> T {
    SCRATCH.with_borrow_mut(|runs| {
        runs.clear();
        runs.push(Seg::BELOW);
        runs.extend(modes[..i].iter().map(|m| Seg::new(m.lo, m.hi, m.count)));
        runs.push(Seg::single(l));
        runs.extend(modes[i..].iter().map(|m| Seg::new(m.lo, m.hi, m.count)));
        runs.push(Seg::ABOVE);
        let mut total: u64 = 0;
        for m in modes {
            total = total.saturating_add(m.count);
        }
        let points = if total < 1 << 52 {
            // Every partial sum of the f64 counts is an exact integer: the same value.
            total as f64 + 1.0
        } else {
            modes.iter().map(|m| m.count as f64).sum::<f64>() + 1.0
        };
        f(&Query { runs, l, i, points })
    })
}

thread_local! {
    /// The runs of the current query: transient, not part of any pixel's state.
    static SCRATCH: std::cell::RefCell<Vec<Seg>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// One run of ADR's point set: a mode's evenly spaced points, or the newcomer alone.
#[derive(Debug, Clone, Copy)]
struct Seg {
    lo: f64,
    hi: f64,
    c: u64,
    /// Spacing `(hi - lo) / (c - 1)` (0 for a single).
    d: f64,
    /// How many same-run neighbours on each side lie closer than `nn` (`j d < nn`).
    w: u64,
    /// The spacing in units of `nn`, `d / nn` (set with `w`).
    r: f64,
    /// The next-to-last point, [`Seg::at`]`(c - 2)` (`lo` for a single). Every point but `hi`
    /// lies in `[lo, top]` (the formula is monotone in `k`), and `top` may exceed `hi` by
    /// rounding.
    top: f64,
}

impl Seg {
    /// A run below every point, ending a query's walks.
    const BELOW: Seg = Seg::sentinel(f64::NEG_INFINITY);

    /// A run above every point.
    const ABOVE: Seg = Seg::sentinel(f64::INFINITY);

    const fn sentinel(x: f64) -> Seg {
        Seg {
            lo: x,
            hi: x,
            c: 0,
            d: 0.0,
            w: 0,
            r: 0.0,
            top: x,
        }
    }

    fn new(lo: f64, hi: f64, c: u64) -> Seg {
        let d = if c >= 2 {
            (hi - lo) / to_f64(c - 1)
        } else {
            0.0
        };
        let mut seg = Seg {
            lo,
            hi,
            c,
            d,
            w: 0,
            r: 0.0,
            top: lo,
        };
        if c >= 2 {
            seg.top = seg.formula(c - 2);
        }
        seg
    }

    /// The newcomer `l`.
    fn single(l: f64) -> Seg {
        Seg {
            lo: l,
            hi: l,
            c: 1,
            d: 0.0,
            w: 0,
            r: 0.0,
            top: l,
        }
    }

    /// This run with its `w` for the mean nearest-neighbour distance `nn`.
    fn with_w(mut self, nn: f64) -> Seg {
        self.r = self.d / nn;
        self.w = if self.c < 2 {
            0
        } else if self.is_point() || nn / self.d > to_f64(self.c - 1) {
            self.c - 1
        } else {
            // The largest integer j with j d < nn.
            (ceil(nn / self.d) - 1.0).max(0.0) as u64
        };
        self
    }

    /// Point `k` (docs/estimators.md §6.3's formula; the last one is `hi`).
    #[inline]
    fn at(&self, k: u64) -> f64 {
        if k + 1 >= self.c {
            self.hi
        } else if k == 0 {
            // The formula's term is +0.
            self.lo + 0.0
        } else if k + 2 == self.c {
            self.top
        } else {
            self.formula(k)
        }
    }

    /// `lo + ((hi - lo) k) / (c - 1)` (`c >= 2`).
    fn formula(&self, k: u64) -> f64 {
        self.lo + ((self.hi - self.lo) * to_f64(k)) / to_f64(self.c - 1)
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

    /// The points of the run to test for overlap, nearest to the newcomer first (`from_top`:
    /// the run lies below it). The interior points all share one bandwidth, so only the
    /// nearest of them is listed: if it misses, the farther ones miss too.
    fn nearest_first(&self, from_top: bool) -> Nearest {
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
}

/// Point indices of a run, nearest to the newcomer first ([`Seg::nearest_first`]): three
/// ranges in turn, each walked downwards when the run lies below the newcomer.
struct Nearest {
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
fn kernel_sum(w: u64, r: f64) -> f64 {
    let w = to_f64(w);
    w - r * r * w * (w + 1.0) * (2.0 * w + 1.0) / 6.0
}

/// `a.min(b)` for operands that are never NaN nor `-0` (distances between logs), in one
/// instruction rather than `f64::min`'s several.
#[inline(always)]
fn min(a: f64, b: f64) -> f64 {
    if b < a { b } else { a }
}

/// `c as f64` (the signed conversion is one instruction on x86-64, the unsigned one several).
#[inline(always)]
fn to_f64(c: u64) -> f64 {
    match i64::try_from(c) {
        Ok(c) => c as f64,
        Err(_) => c as f64,
    }
}

/// `x.ceil()` without a library call (baseline x86-64 has no rounding instruction).
#[inline(always)]
fn ceil(x: f64) -> f64 {
    if x.abs() < (1u64 << 52) as f64 {
        // |x| < 2^52: the truncation is exact, and the ceiling is it or the next integer.
        let t = x as i64 as f64;
        if t < x { t + 1.0 } else { t }
    } else {
        x.ceil()
    }
}

/// ADR's point set for one newcomer: the modes' runs with `l` inserted as a single run at
/// index `i` (run `t` is mode `t` below `i` and mode `t - 1` above it).
///
/// An extended mode stands for `c` evenly spaced points; all but the `w + 1` at each end see
/// exactly `w` neighbours on each side within `nn` and none outside the mode, so they share one
/// pilot value `1 + 2 Σ_{j<=w} (1 - (j d / nn)^2)`. Those are counted in closed form; the end
/// points, and points whose window reaches another run, are evaluated one by one. Same-mode
/// neighbours are taken at the exact spacing `d`, which differs from the rounded point values
/// by a rounding error; a neighbour at the window's edge contributes ~0 either way.
///
/// Cost per newcomer, without allocating (the runs live in a per-thread scratch list): two
/// divisions per extended mode for its spacing and next-to-last point, `O(modes)` additions
/// and comparisons, and `O(w)` more with one `ln` per run whose points have a neighbour
/// within `nn`. A run lying at least `nn` from both neighbouring runs gets no term from them,
/// so a point's pilot value is its in-run part alone, and 1 when the run's spacing is at least
/// `nn` (`w = 0`): such points change neither the product nor the sum of logs, and are
/// skipped. The checks use the run's extreme points, so the values are those of a walk over
/// the neighbours: the unit tests compare with the first implementation, which walked, bit
/// for bit.
struct Query<'a> {
    /// The runs in order, between two sentinels: run `t` is `runs[t + 1]`, the newcomer is
    /// run `i`, and modes keep their index below it and shift by one above.
    runs: &'a [Seg],
    l: f64,
    i: usize,
    /// Number of points.
    points: f64,
}

impl Query<'_> {
    /// [`Adr::overlapped`].
    fn overlapped(&self) -> Option<(usize, usize)> {
        let (l, i) = (self.l, self.i);
        let Some((nn, g)) = self.pilot() else {
            // Every bandwidth is 0: only a point equal to l overlaps it, and the only point
            // that can equal l is a single mode just after it.
            return (self.runs[i + 2].lo == l).then_some((i, i));
        };
        let h = |s: usize, seg: &Seg, k: u64| nn * (g / self.p_at(s, seg, k, nn)).sqrt();
        let h_l = h(i, &Seg::single(l), 0);
        // Every p >= 1 (its own term), so no h exceeds nn sqrt(g).
        let reach = h_l + nn * g.sqrt();
        // A distance below h_l is below h_l + h_x whatever h_x >= 0 (rounding is monotone).
        let hits = |x: f64, s: usize, seg: &Seg, k: u64| {
            let dist = (l - x).abs();
            x == l || dist < h_l || dist < h_l + h(s, seg, k)
        };

        // Only the farthest mode with a hit matters on each side: once a point of a mode hits,
        // its other points need no test (those of the next mode are farther still).
        let mut first = None;
        'left: for s in (0..i).rev() {
            let seg = self.runs[s + 1].with_w(nn);
            for k in seg.nearest_first(true) {
                let x = seg.at(k);
                if x != l && !(l - x < reach) {
                    break 'left;
                }
                if hits(x, s, &seg, k) {
                    first = Some(s);
                    break;
                }
            }
        }
        let mut last = None;
        'right: for s in i + 1..self.runs.len() - 2 {
            let seg = self.runs[s + 1].with_w(nn);
            for k in seg.nearest_first(false) {
                let x = seg.at(k);
                if x != l && !(x - l < reach) {
                    break 'right;
                }
                if hits(x, s, &seg, k) {
                    last = Some(s - 1);
                    break;
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

    /// `nn` and `g` of eq. 4, or `None` when every bandwidth is 0.
    fn pilot(&self) -> Option<(f64, f64)> {
        let k = self.points;
        if k < 2.0 {
            return None;
        }
        // Mean distance to the nearest other point, summed run by run in order.
        let mut nn_sum = 0.0;
        for w in self.runs.windows(3) {
            let (below, r, above) = (&w[0], &w[1], &w[2]);
            let (prev, next) = (r.lo - below.hi, above.lo - r.hi);
            if r.c == 1 {
                nn_sum += min(prev, next);
            } else {
                nn_sum += min(prev, r.at(1) - r.lo);
                nn_sum += min(next, r.hi - r.top);
                nn_sum += to_f64(r.c - 2) * r.d;
            }
        }
        let nn = nn_sum / k;
        if !(nn > 0.0 && nn.is_finite()) {
            return None;
        }
        // ln g = mean of ln p, as logs of partial products (every p >= 1). A factor 1 changes
        // nothing, nor does adding ln 1 = 0 (ln_sum is never -0), so such points are skipped.
        let mut ln_sum = 0.0;
        let mut product = 1.0;
        let mut take = |p: f64, ln_sum: &mut f64| {
            if p != 1.0 {
                product *= p;
                if product > 1e200 {
                    *ln_sum += product.ln();
                    product = 1.0;
                }
            }
        };
        for (s, w) in self.runs.windows(3).enumerate() {
            let (below, r, above) = (&w[0], &w[1], &w[2]);
            // The least distance from the run's points, which lie in [lo, top] and at hi, to
            // another run's: no other run within nn when nn <= far.
            let far = min(min(r.lo - below.hi, above.lo - r.hi), above.lo - r.top);
            // Every p is then 1 for a single, and for an extended run with w = 0, which holds
            // exactly when nn / d rounds to at most 1, that is when nn <= d (d > 0): the
            // in-run part is 1 + (K(0) + K(0)) = 1, unless r^2 overflows (K(0) is then NaN,
            // as in the literal form).
            if nn <= far && (r.c == 1 || r.d > 0.0 && nn <= r.d && r.d <= nn * 1e150) {
                continue;
            }
            let seg = r.with_w(nn);
            let (c, w) = (seg.c, seg.w);
            if nn <= far && seg.has_interior() && w < 8 {
                // The common case, alone with a few neighbours on each side: the bottom points
                // k = 0..=w have p = 1 + (K(k) + K(w)), the top ones mirror them, and the
                // interior points share 1 + 2 K(w).
                let mut p = [0.0; 8];
                let kw = kernel_sum(w, seg.r);
                for (j, pj) in p[..=w as usize].iter_mut().enumerate() {
                    *pj = 1.0 + (kernel_sum(j as u64, seg.r) + kw);
                }
                for &pj in &p[..=w as usize] {
                    take(pj, &mut ln_sum);
                }
                for &pj in p[..=w as usize].iter().rev() {
                    take(pj, &mut ln_sum);
                }
                let p_int = 1.0 + 2.0 * kw;
                if p_int != 1.0 {
                    ln_sum += to_f64(c - 2 * w - 2) * p_int.ln();
                }
                continue;
            }
            self.add_logs(s, seg, nn <= far, nn, &mut take, &mut ln_sum);
        }
        ln_sum += product.ln();
        Some((nn, (ln_sum / k).exp()))
    }

    /// The terms of run `s` (`seg`, with its `w`) in the pilot's `ln g`, in order: `take` for
    /// the points evaluated one by one, then the interior's share. `alone`: no other run lies
    /// within `nn` of its points.
    #[inline(never)]
    fn add_logs(
        &self,
        s: usize,
        seg: Seg,
        alone: bool,
        nn: f64,
        take: &mut impl FnMut(f64, &mut f64),
        ln_sum: &mut f64,
    ) {
        let (c, w) = (seg.c, seg.w);
        if c == 1 {
            take(self.p_at(s, &seg, 0, nn), ln_sum);
            return;
        }
        if seg.is_point() {
            *ln_sum += to_f64(c) * self.p_at(s, &seg, 0, nn).ln();
            return;
        }
        let r = seg.r;
        if seg.has_interior() {
            let kw = kernel_sum(w, r);
            if alone {
                // Bottom points k = 0..=w: 1 + (K(k) + K(w)); the top ones mirror them.
                for j in 0..=w {
                    take(1.0 + (kernel_sum(j, r) + kw), ln_sum);
                }
                for j in (0..=w).rev() {
                    take(1.0 + (kw + kernel_sum(j, r)), ln_sum);
                }
            } else {
                for k in (0..=w).chain(c - 1 - w..c) {
                    take(self.p_at(s, &seg, k, nn), ln_sum);
                }
            }
            let p_int = 1.0 + 2.0 * kw;
            if p_int != 1.0 {
                *ln_sum += to_f64(c - 2 * w - 2) * p_int.ln();
            }
        } else {
            for k in 0..c {
                let p = if alone {
                    1.0 + (kernel_sum(k.min(w), r) + kernel_sum((c - 1 - k).min(w), r))
                } else {
                    self.p_at(s, &seg, k, nn)
                };
                take(p, ln_sum);
            }
        }
    }

    /// The pilot `p` at point `k` of run `s` (`seg`, with its `w`): itself, its own run's
    /// neighbours within `nn`, and other runs' points within `nn` (the sentinels end the
    /// walks).
    fn p_at(&self, s: usize, seg: &Seg, k: u64, nn: f64) -> f64 {
        let x = seg.at(k);
        let mut p = 1.0;
        if seg.c >= 2 {
            if seg.is_point() {
                p += to_f64(seg.c - 1);
            } else {
                let r = seg.r;
                p += kernel_sum(k.min(seg.w), r) + kernel_sum((seg.c - 1 - k).min(seg.w), r);
            }
        }
        for run in self.runs[..s + 1].iter().rev() {
            let (sum, done) = from_run(run, x, nn, true);
            p += sum;
            if done {
                break;
            }
        }
        for run in &self.runs[s + 2..] {
            let (sum, done) = from_run(run, x, nn, false);
            p += sum;
            if done {
                break;
            }
        }
        p
    }
}

/// Pilot terms at `x` from the points of another run lying below (`below`) or above it;
/// `done` when runs further away cannot contribute.
#[inline]
fn from_run(seg: &Seg, x: f64, nn: f64, below: bool) -> (f64, bool) {
    // Distances from x to the run's near and far ends.
    let (near, far) = if below {
        (x - seg.hi, x - seg.lo)
    } else {
        (seg.lo - x, seg.hi - x)
    };
    if !(near < nn) {
        return (0.0, true);
    }
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
