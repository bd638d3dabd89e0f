//! The first implementation of [`Adr::update`], kept as the bit-for-bit oracle of the faster
//! one: its search (the last mode hit, else a binary search) and its overlap search (an
//! implicit point set in an allocated list of runs), verbatim; and the literal reading, which
//! materialises every point.

use super::{Adr, PajotMode, Pilot, pilot};
use std::cell::Cell;

thread_local! {
    static REFERENCE: Cell<bool> = const { Cell::new(false) };
}

/// Runs `f` with every [`Adr::update`] of this thread going through [`Adr::update_ref`].
pub(in crate::estimators::pajot) fn with_reference<T>(f: impl FnOnce() -> T) -> T {
    REFERENCE.set(true);
    let out = f();
    REFERENCE.set(false);
    out
}

/// Whether [`with_reference`] is in force.
pub(super) fn reference() -> bool {
    REFERENCE.get()
}

impl Adr {
    /// [`Adr::update`] as first implemented.
    pub(in crate::estimators::pajot) fn update_ref(&mut self, l: f64) -> bool {
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
        // The merge is shared: this oracle checks the searches.
        let overlap = self.overlapped_ref(l, i);
        self.merge(l, i, overlap)
    }

    /// [`Adr::overlapped`] by materialising every point: the literal reading, kept as the
    /// oracle of the unit tests.
    #[cfg(test)]
    pub(in crate::estimators::pajot) fn overlapped_naive(
        &self,
        l: f64,
        i: usize,
    ) -> Option<(usize, usize)> {
        let modes = &self.modes;
        let total: u64 = modes.iter().map(|m| m.count).sum();
        let mut xs = Vec::with_capacity(usize::try_from(total).unwrap_or(0).saturating_add(1));
        for md in &modes[..i] {
            xs.extend(md.points());
        }
        let pos = xs.len();
        xs.push(l);
        for md in &modes[i..] {
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
            let mut start = pos - modes[mode].count as usize;
            for j in (0..pos).rev() {
                if xs[j] != l && !(l - xs[j] < reach) {
                    break;
                }
                while j < start {
                    mode -= 1;
                    start -= modes[mode].count as usize;
                }
                if hits(j) {
                    first = Some(mode);
                }
            }
        }
        let mut last = None;
        if i < modes.len() {
            let mut mode = i;
            let mut end = pos + 1 + modes[mode].count as usize;
            for (j, &x) in xs.iter().enumerate().skip(pos + 1) {
                if x != l && !(x - l < reach) {
                    break;
                }
                while j >= end {
                    mode += 1;
                    end += modes[mode].count as usize;
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

    /// The range of modes (first, last) having a point that `l` overlaps under the eq. 4
    /// bandwidths of all modes' points plus `l`; `None` if no point overlaps. `i` is the index of
    /// the first mode whose top is `>= l` (`l` goes between modes `i - 1` and `i`).
    ///
    /// The implementation before the allocation-free [`Adr::overlapped`], kept verbatim as
    /// its bit-for-bit oracle.
    pub(in crate::estimators::pajot) fn overlapped_ref(
        &self,
        l: f64,
        i: usize,
    ) -> Option<(usize, usize)> {
        let modes = &self.modes;
        let mut set = PointSet::new(modes, l, i);
        let Some((nn, g)) = set.pilot() else {
            // Every bandwidth is 0: only a point equal to l overlaps it, and the only point
            // that can equal l is a single mode just after it.
            return modes.get(i).filter(|m| m.lo == l).map(|_| (i, i));
        };
        let h = |s: usize, k: u64| nn * (g / set.p_at(s, k, nn)).sqrt();
        let h_l = h(i, 0);
        // Every p >= 1 (its own term), so no h exceeds nn sqrt(g).
        let reach = h_l + nn * g.sqrt();
        let hits = |x: f64, s: usize, k: u64| x == l || (l - x).abs() < h_l + h(s, k);

        let mut first = None;
        'left: for s in (0..i).rev() {
            for k in set.order(s, true) {
                let x = set.segs[s].at(k);
                if x != l && !(l - x < reach) {
                    break 'left;
                }
                if hits(x, s, k) {
                    first = Some(s);
                }
            }
        }
        let mut last = None;
        'right: for s in i + 1..set.segs.len() {
            for k in set.order(s, false) {
                let x = set.segs[s].at(k);
                if x != l && !(x - l < reach) {
                    break 'right;
                }
                if hits(x, s, k) {
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

/// ADR's point set (every mode's points plus the newcomer) without materialising it.
///
/// An extended mode stands for `c` evenly spaced points; all but the `w + 1` at each end see
/// exactly `w` neighbours on each side within `nn` and none outside the mode, so they share one
/// pilot value `1 + 2 Σ_{j<=w} (1 - (j d / nn)^2)`. Those are counted in closed form; the end
/// points, and points whose window reaches another mode, are evaluated one by one. Same-mode
/// neighbours are taken at the exact spacing `d`, which differs from the rounded point values
/// by a rounding error; a neighbour at the window's edge contributes ~0 either way. Cost per
/// newcomer: `O(modes + Σ min(c, w))` instead of `O(n)` points.
struct PointSet {
    segs: Vec<Seg>,
    /// Number of points.
    k: f64,
}

impl PointSet {
    fn new(modes: &[PajotMode], l: f64, i: usize) -> PointSet {
        let mut segs = Vec::with_capacity(modes.len() + 1);
        segs.extend(modes[..i].iter().map(|m| Seg::new(m.lo, m.hi, m.count)));
        segs.push(Seg::new(l, l, 1));
        segs.extend(modes[i..].iter().map(|m| Seg::new(m.lo, m.hi, m.count)));
        let k = modes.iter().map(|m| m.count as f64).sum::<f64>() + 1.0;
        PointSet { segs, k }
    }

    /// `nn` and `g` of eq. 4, or `None` when every bandwidth is 0. Sets each run's `w`.
    fn pilot(&mut self) -> Option<(f64, f64)> {
        if self.k < 2.0 {
            return None;
        }
        // Mean distance to the nearest other point.
        let n = self.segs.len();
        let mut nn_sum = 0.0;
        for s in 0..n {
            let seg = self.segs[s];
            let prev = if s > 0 {
                seg.lo - self.segs[s - 1].hi
            } else {
                f64::INFINITY
            };
            let next = if s + 1 < n {
                self.segs[s + 1].lo - seg.hi
            } else {
                f64::INFINITY
            };
            if seg.c == 1 {
                nn_sum += prev.min(next);
            } else {
                nn_sum += prev.min(seg.at(1) - seg.lo);
                nn_sum += next.min(seg.hi - seg.at(seg.c - 2));
                nn_sum += (seg.c - 2) as f64 * seg.d;
            }
        }
        let nn = nn_sum / self.k;
        if !(nn > 0.0 && nn.is_finite()) {
            return None;
        }
        for seg in &mut self.segs {
            seg.w = if seg.c < 2 {
                0
            } else if seg.is_point() || nn / seg.d > (seg.c - 1) as f64 {
                seg.c - 1
            } else {
                // The largest integer j with j d < nn.
                ((nn / seg.d).ceil() - 1.0).max(0.0) as u64
            };
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
        for s in 0..n {
            let seg = self.segs[s];
            if seg.c >= 2 && seg.is_point() {
                ln_sum += seg.c as f64 * self.p_at(s, 0, nn).ln();
            } else if seg.has_interior() {
                for k in (0..=seg.w).chain(seg.c - 1 - seg.w..seg.c) {
                    take(self.p_at(s, k, nn), &mut ln_sum);
                }
                let interior = (seg.c - 2 * seg.w - 2) as f64;
                ln_sum += interior * (1.0 + 2.0 * kernel_sum(seg.w, seg.d / nn)).ln();
            } else {
                for k in 0..seg.c {
                    take(self.p_at(s, k, nn), &mut ln_sum);
                }
            }
        }
        ln_sum += product.ln();
        Some((nn, (ln_sum / self.k).exp()))
    }

    /// The pilot `p` at point `k` of run `s`: itself, its own run's neighbours within `nn`, and
    /// other runs' points within `nn`.
    fn p_at(&self, s: usize, k: u64, nn: f64) -> f64 {
        let seg = self.segs[s];
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
            let (sum, done) = Self::from_run(&self.segs[t], x, nn, true);
            p += sum;
            if done {
                break;
            }
        }
        for t in s + 1..self.segs.len() {
            let (sum, done) = Self::from_run(&self.segs[t], x, nn, false);
            p += sum;
            if done {
                break;
            }
        }
        p
    }

    /// Pilot terms at `x` from the points of another run lying below (`below`) or above it;
    /// `done` when runs further away cannot contribute.
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

    /// The points of run `s` to test for overlap, nearest to the newcomer first (`from_top`:
    /// the run lies below it). The interior points all share one bandwidth, so only the
    /// nearest of them is listed: if it misses, the farther ones miss too.
    fn order(&self, s: usize, from_top: bool) -> Vec<u64> {
        let seg = self.segs[s];
        let (c, w) = (seg.c, seg.w);
        let ks: Vec<u64> = if seg.is_point() {
            vec![0]
        } else if seg.has_interior() {
            (0..=w).chain([w + 1]).chain(c - 1 - w..c).collect()
        } else {
            (0..c).collect()
        };
        if from_top {
            // Mirror: nearest is the top; the interior's nearest is c - 2 - w.
            if seg.has_interior() {
                (c - 1 - w..c)
                    .rev()
                    .chain([c - 2 - w])
                    .chain((0..=w).rev())
                    .collect()
            } else {
                ks.into_iter().rev().collect()
            }
        } else {
            ks
        }
    }
}

/// One run of the point set (the first implementation's, verbatim).
#[derive(Debug, Clone, Copy)]
struct Seg {
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

    /// Point `k`.
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

    /// Whether the points strictly between the first `w + 1` and the last `w + 1` exist.
    fn has_interior(&self) -> bool {
        !self.is_point() && self.c > 2 * self.w + 2
    }
}

/// `Σ_{j=1..w} (1 - (j r)^2)`.
fn kernel_sum(w: u64, r: f64) -> f64 {
    let w = w as f64;
    w - r * r * w * (w + 1.0) * (2.0 * w + 1.0) / 6.0
}
