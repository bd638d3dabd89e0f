//! A bounding volume hierarchy over [`Primitive`]s: binned SAH build, flattened depth-first
//! nodes of 32 bytes, iterative near-child-first traversal.
//!
//! Layout: an interior node's first child directly follows it and it stores the index of the
//! second; a leaf stores the range of its (at most [`MAX_LEAF`]) primitives, which the build
//! reorders so that every leaf's primitives are contiguous.
//!
//! The slab test picks each axis' near and far plane by the sign bit of the direction, so a
//! zero (or negative zero) component gives an infinite slab of the right sign; `0·∞ = NaN`
//! only arises when the origin lies on a plane parallel to the ray, and such a lane is then
//! treated as unconstrained (the ray runs inside the closed slab). The far distance is enlarged
//! by `1 + 2γ₃` (Ize 2013) so rounding cannot cull a box whose primitive the watertight
//! triangle test would hit.

use super::shapes::{Hit, Primitive, RawHit, Ray, RayPre};
use arrayvec::ArrayVec;
use glam::{BVec3A, Vec3, Vec3A};

/// Largest number of primitives in a leaf.
pub const MAX_LEAF: usize = 4;

/// Number of SAH bins per axis.
const BINS: usize = 16;

/// Cost of visiting an interior node relative to one primitive test.
const TRAVERSAL_COST: f32 = 1.0;

/// Depth from which splits are object medians (bounds the depth, hence the stack, whatever
/// the input).
const MEDIAN_DEPTH: usize = 64;

/// Traversal stack size: the median splits below [`MEDIAN_DEPTH`] halve the count, so at most
/// 32 more levels follow.
const STACK: usize = MEDIAN_DEPTH + 40;

/// `1 + 2γ₃` with `γₙ = nε/(1 − nε)`, `ε` half an ulp of one.
const FAR_SCALE: f32 =
    1.0 + 2.0 * (3.0 * (f32::EPSILON * 0.5)) / (1.0 - 3.0 * (f32::EPSILON * 0.5));

/// One node: bounds, then for a leaf the first primitive and the count, for an interior node
/// the index of the second child and a count of 0.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(32))]
struct Node {
    bounds: [Vec3; 2],
    offset: u32,
    count: u32,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);

/// The acceleration structure: flattened nodes over a flat, reordered primitive array.
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    prims: Vec<Primitive>,
}

/// A primitive's box and centroid during the build.
#[derive(Debug, Clone, Copy)]
struct Item {
    lo: Vec3,
    hi: Vec3,
    c: Vec3,
    index: u32,
}

/// Box accumulator.
#[derive(Debug, Clone, Copy)]
struct Aabb {
    lo: Vec3,
    hi: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        lo: Vec3::splat(f32::INFINITY),
        hi: Vec3::splat(f32::NEG_INFINITY),
    };

    #[inline]
    fn grow(&mut self, lo: Vec3, hi: Vec3) {
        self.lo = self.lo.min(lo);
        self.hi = self.hi.max(hi);
    }

    #[inline]
    fn union(self, o: Aabb) -> Aabb {
        Aabb {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }

    /// Half the surface area (0 for an empty box).
    #[inline]
    fn half_area(&self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// Per-ray traversal data.
struct Trav {
    pre: RayPre,
    o: Vec3A,
    inv: Vec3A,
    /// Lanes whose direction is negative (sign bit, so −0 counts): near plane is the max.
    neg: BVec3A,
}

impl Trav {
    #[inline]
    fn new(ray: &Ray) -> Trav {
        let inv = Vec3A::ONE / Vec3A::from(ray.d);
        Trav {
            pre: RayPre::new(ray),
            o: ray.o.into(),
            inv,
            neg: BVec3A::new(
                inv.x.is_sign_negative(),
                inv.y.is_sign_negative(),
                inv.z.is_sign_negative(),
            ),
        }
    }

    /// Entry distance of the node's box if the ray overlaps it within `[tmin, tmax]`.
    #[inline(always)]
    fn hit_box(&self, n: &Node, tmin: f32, tmax: f32) -> Option<f32> {
        let t0 = (Vec3A::from(n.bounds[0]) - self.o) * self.inv;
        let t1 = (Vec3A::from(n.bounds[1]) - self.o) * self.inv;
        let near = Vec3A::select(self.neg, t1, t0);
        let far = Vec3A::select(self.neg, t0, t1);
        // A NaN lane (0·∞: the origin on a plane parallel to the ray) constrains nothing.
        let near = Vec3A::select(near.cmpeq(near), near, Vec3A::NEG_INFINITY);
        let far = Vec3A::select(far.cmpeq(far), far, Vec3A::INFINITY);
        let t_near = fmax(near.max_element(), tmin);
        let t_far = fmin(far.min_element() * FAR_SCALE, tmax);
        (t_near <= t_far).then_some(t_near)
    }
}

/// Plain `max` (a single instruction; its operands are never NaN here).
#[inline(always)]
fn fmax(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// Plain `min` (a single instruction; its operands are never NaN here).
#[inline(always)]
fn fmin(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

impl Bvh {
    /// Builds the hierarchy (binned SAH, leaves of at most [`MAX_LEAF`] primitives).
    pub fn build(prims: Vec<Primitive>) -> Bvh {
        if prims.is_empty() {
            return Bvh::default();
        }
        let mut items: Vec<Item> = prims
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let (lo, hi) = p.bounds();
                Item {
                    lo,
                    hi,
                    c: (lo + hi) * 0.5,
                    index: i as u32,
                }
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * prims.len() / MAX_LEAF + 1);
        build_node(&mut nodes, &mut items, 0, 0);
        let mut slots: Vec<Option<Primitive>> = prims.into_iter().map(Some).collect();
        let prims = items
            .iter()
            .map(|it| {
                slots[it.index as usize]
                    .take()
                    .expect("each primitive once")
            })
            .collect();
        Bvh { nodes, prims }
    }

    /// Number of primitives.
    pub fn len(&self) -> usize {
        self.prims.len()
    }

    /// Whether there are no primitives.
    pub fn is_empty(&self) -> bool {
        self.prims.is_empty()
    }

    /// Bounds `(min, max)` of everything, or `None` when empty.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        self.nodes.first().map(|n| (n.bounds[0], n.bounds[1]))
    }

    /// The primitives, in the build's order.
    pub fn primitives(&self) -> &[Primitive] {
        &self.prims
    }

    /// The closest hit with `t` in `(tmin, tmax)`.
    pub fn intersect(&self, ray: &Ray, tmin: f32, tmax: f32) -> Option<Hit> {
        let mut best: Option<(usize, RawHit)> = None;
        self.traverse::<false>(ray, tmin, tmax, &mut best);
        best.map(|(i, h)| self.prims[i].finish(ray, &h))
    }

    /// Whether anything is hit with `t` in `(tmin, tmax)` (stops at the first hit).
    pub fn occluded(&self, ray: &Ray, tmin: f32, tmax: f32) -> bool {
        let mut best = None;
        self.traverse::<true>(ray, tmin, tmax, &mut best)
    }

    /// Walks the tree; with `ANY` returns at the first hit, otherwise keeps the closest in
    /// `best`. Returns whether anything was hit.
    #[inline(always)]
    fn traverse<const ANY: bool>(
        &self,
        ray: &Ray,
        tmin: f32,
        tmax: f32,
        best: &mut Option<(usize, RawHit)>,
    ) -> bool {
        let Some(root) = self.nodes.first() else {
            return false;
        };
        let tr = Trav::new(ray);
        let mut t_best = tmax;
        if tr.hit_box(root, tmin, t_best).is_none() {
            return false;
        }
        // ArrayVec: no zero-fill of the whole stack on every ray (that memset was 3% of a
        // render's instructions).
        let mut stack: ArrayVec<(u32, f32), STACK> = ArrayVec::new();
        let mut node = 0usize;
        loop {
            let n = &self.nodes[node];
            if n.count > 0 {
                let first = n.offset as usize;
                for (i, p) in self.prims[first..first + n.count as usize]
                    .iter()
                    .enumerate()
                {
                    if let Some(h) = p.intersect_raw(&tr.pre, tmin, t_best) {
                        if ANY {
                            return true;
                        }
                        t_best = h.t;
                        *best = Some((first + i, h));
                    }
                }
            } else {
                let (l, r) = (node + 1, n.offset as usize);
                let hl = tr.hit_box(&self.nodes[l], tmin, t_best);
                let hr = tr.hit_box(&self.nodes[r], tmin, t_best);
                match (hl, hr) {
                    (Some(tl), Some(tr_)) => {
                        let (near, far, tfar) = if tl <= tr_ { (l, r, tr_) } else { (r, l, tl) };
                        stack.push((far as u32, tfar));
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = r;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop the next box that may still hold something nearer.
            loop {
                let Some((nd, t_enter)) = stack.pop() else {
                    return best.is_some();
                };
                if t_enter <= t_best {
                    node = nd as usize;
                    break;
                }
            }
        }
    }
}

/// Builds the subtree over `items` (whose first element is primitive number `first` in the
/// final order) and returns its node index.
fn build_node(nodes: &mut Vec<Node>, items: &mut [Item], first: usize, depth: usize) -> usize {
    let me = nodes.len();
    let mut bounds = Aabb::EMPTY;
    let mut cb = Aabb::EMPTY;
    for it in items.iter() {
        bounds.grow(it.lo, it.hi);
        cb.grow(it.c, it.c);
    }
    nodes.push(Node {
        bounds: [bounds.lo, bounds.hi],
        offset: first as u32,
        count: items.len() as u32,
    });
    let n = items.len();
    if n == 1 {
        return me;
    }

    let split = if depth >= MEDIAN_DEPTH {
        None
    } else {
        best_split(items, &bounds, &cb)
    };
    let mid = match split {
        Some((axis, bin, cost)) => {
            if n <= MAX_LEAF && cost >= n as f32 {
                return me;
            }
            let (lo, scale) = bin_params(&cb, axis);
            let mid = partition(items, |it| bin_of(it.c[axis], lo, scale) <= bin);
            if mid == 0 || mid == n {
                median(items, &cb)
            } else {
                mid
            }
        }
        None => {
            if n <= MAX_LEAF {
                return me;
            }
            median(items, &cb)
        }
    };

    let (left, right) = items.split_at_mut(mid);
    let l = build_node(nodes, left, first, depth + 1);
    debug_assert_eq!(l, me + 1);
    let r = build_node(nodes, right, first + mid, depth + 1);
    nodes[me].offset = r as u32;
    nodes[me].count = 0;
    me
}

/// Bin origin and scale along `axis` of the centroid bounds.
#[inline]
fn bin_params(cb: &Aabb, axis: usize) -> (f32, f32) {
    let lo = cb.lo[axis];
    let extent = cb.hi[axis] - lo;
    (lo, BINS as f32 * (1.0 - 1e-6) / extent)
}

#[inline]
fn bin_of(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// The cheapest binned SAH split over the three axes: `(axis, last bin of the left side,
/// cost relative to one primitive test)`. `None` when the centroids do not spread.
fn best_split(items: &[Item], bounds: &Aabb, cb: &Aabb) -> Option<(usize, usize, f32)> {
    let parent = bounds.half_area();
    let mut best: Option<(usize, usize, f32)> = None;
    for axis in 0..3 {
        let extent = cb.hi[axis] - cb.lo[axis];
        if !(extent > 0.0) || !extent.is_finite() {
            continue;
        }
        let (lo, scale) = bin_params(cb, axis);
        let mut bins = [(Aabb::EMPTY, 0u32); BINS];
        for it in items {
            let b = &mut bins[bin_of(it.c[axis], lo, scale)];
            b.0.grow(it.lo, it.hi);
            b.1 += 1;
        }
        // Right-to-left sweep: area × count of everything right of each plane.
        let mut right_cost = [0.0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0u32;
        for i in (1..BINS).rev() {
            acc = acc.union(bins[i].0);
            cnt += bins[i].1;
            right_cost[i - 1] = acc.half_area() * cnt as f32;
        }
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0u32;
        for (i, &rc) in right_cost.iter().enumerate().take(BINS - 1) {
            acc = acc.union(bins[i].0);
            cnt += bins[i].1;
            if cnt == 0 || cnt as usize == items.len() {
                continue;
            }
            let cost = if parent > 0.0 {
                TRAVERSAL_COST + (acc.half_area() * cnt as f32 + rc) / parent
            } else {
                TRAVERSAL_COST + items.len() as f32 * 0.5
            };
            if best.is_none_or(|b| cost < b.2) {
                best = Some((axis, i, cost));
            }
        }
    }
    best
}

/// Splits at the median centroid along the widest centroid axis.
fn median(items: &mut [Item], cb: &Aabb) -> usize {
    let axis = (cb.hi - cb.lo).max_position();
    let mid = items.len() / 2;
    items.select_nth_unstable_by(mid, |a, b| a.c[axis].total_cmp(&b.c[axis]));
    mid
}

/// In-place partition; returns the number of items satisfying `pred` (now in front).
fn partition(items: &mut [Item], pred: impl Fn(&Item) -> bool) -> usize {
    let mut i = 0;
    let mut j = items.len();
    while i < j {
        if pred(&items[i]) {
            i += 1;
        } else {
            j -= 1;
            items.swap(i, j);
        }
    }
    i
}
