//! A bounding volume hierarchy over [`Primitive`]s: a binned SAH binary build, collapsed into an
//! 8-wide tree whose nodes hold their children's boxes as structure-of-arrays, tested eight at
//! a time ([`super::slab`]: one AVX operation per step, two SSE2 ones where the build has no
//! AVX).
//!
//! Layout: the binary build reorders the primitives so that every leaf's (at most
//! [`MAX_LEAF`]) are contiguous; the collapse then opens, in each 8-wide node, the binary
//! child of largest area until eight children remain. A child reference is an interior node's
//! index or a leaf's primitive range ([`Child`]). Closest-hit traversal visits the children it
//! hits nearest first; occlusion rays stop at the first hit (see [`Bvh::occluded`] for their
//! order). A leaf of two to four triangles is also kept as a [`TrianglePacket`] and tested in
//! one go.
//!
//! Why eight: a node of eight costs about what a node of four did (the same steps on twice the
//! lanes), and a ray visits fewer nodes; README's "Speed" section has the measurements.

use super::prefetch::prefetch;
use super::shapes::packet::{PacketHit, TrianglePacket};
use super::shapes::{Hit, Primitive, RawHit, Ray, RayPre, TriangleAttrs};
use super::slab::{Lanes, SlabRay, WIDTH};
use arrayvec::ArrayVec;
use glam::Vec3;

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
/// 32 more binary levels follow; a node spans at least one of them and stacks at most
/// `WIDTH - 1` children.
const STACK: usize = (WIDTH - 1) * (MEDIAN_DEPTH + 40);

/// One node of the binary build: bounds, then for a leaf the first primitive and the count,
/// for an interior node the index of the second child and a count of 0.
#[derive(Debug, Clone, Copy)]
struct Node {
    bounds: [Vec3; 2],
    offset: u32,
    count: u32,
}

/// A child reference of a wide node: an interior node's index, or (top bit set) a leaf: with
/// the next bit set the index of its [`Packet`], else its first primitive shifted left by 3
/// and its count in the low 3 bits. [`Child::EMPTY`] fills unused slots (whose boxes are
/// empty, so no ray reaches them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Child(u32);

impl Child {
    const LEAF: u32 = 1 << 31;
    const PACKET: u32 = 1 << 30;
    const EMPTY: Child = Child(u32::MAX);

    fn leaf(first: usize, count: usize) -> Child {
        assert!(
            first < 1 << 27 && (1..=MAX_LEAF).contains(&count),
            "BVH: more than 2^27 primitives"
        );
        Child(Self::LEAF | (first as u32) << 3 | count as u32)
    }

    fn packet(index: usize) -> Child {
        assert!(index < 1 << 30, "BVH: more than 2^30 packets");
        Child(Self::LEAF | Self::PACKET | index as u32)
    }

    #[inline(always)]
    fn is_leaf(self) -> bool {
        self.0 & Self::LEAF != 0
    }

    /// A leaf's [`Packet`] index, if it has one.
    #[inline(always)]
    fn packet_index(self) -> Option<usize> {
        (self.0 & Self::PACKET != 0).then_some((self.0 & !(Self::LEAF | Self::PACKET)) as usize)
    }

    /// A leaf's primitive range (of a leaf without a packet).
    #[inline(always)]
    fn range(self) -> std::ops::Range<usize> {
        let first = ((self.0 & !Self::LEAF) >> 3) as usize;
        first..first + (self.0 & 7) as usize
    }
}

/// A wide node: the children's boxes as `[min x, min y, min z, max x, max y, max z]`, one
/// lane per child, then the children. Four cache lines, aligned as pairs (Intel's L2 fetches
/// a line's 128-byte buddy with it).
#[derive(Debug, Clone, Copy)]
#[repr(C, align(128))]
struct WideNode {
    planes: [Lanes; 6],
    child: [Child; WIDTH],
}

const _: () = assert!(std::mem::size_of::<WideNode>() == 256);

/// A leaf of two to four triangles: their vertices lane by lane, and where they are in the
/// primitive array (for the hit record, and for the scalar test when the packet is unsure).
#[derive(Debug, Clone, Copy)]
struct Packet {
    triangles: TrianglePacket,
    first: u32,
}

/// The acceleration structure: wide nodes (the root first) over a flat, reordered
/// primitive array.
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    nodes: Vec<WideNode>,
    packets: Vec<Packet>,
    /// Set when everything is one leaf (then `nodes` is empty).
    root_leaf: Option<Child>,
    bounds: Option<(Vec3, Vec3)>,
    prims: Vec<Primitive>,
    /// The triangles' normals and texture coordinates, in `prims` order (empty when no
    /// primitive has any). Why not in each triangle's own box: finishing a hit then waited for
    /// the primitive and, after it, for the box; here both addresses are known at the hit, and
    /// both are prefetched while the traversal goes on.
    attrs: Vec<TriangleAttrs>,
    /// Whether hits carry `dp_du`, `dp_dv` ([`Bvh::set_tangents`]).
    tangents: bool,
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
        let mut binary = Vec::with_capacity(2 * prims.len() / MAX_LEAF + 1);
        build_node(&mut binary, &mut items, 0, 0);
        let mut slots: Vec<Option<Primitive>> = prims.into_iter().map(Some).collect();
        let mut prims: Vec<Primitive> = items
            .iter()
            .map(|it| {
                slots[it.index as usize]
                    .take()
                    .expect("each primitive once")
            })
            .collect();
        let attrs = if prims.iter().any(|p| p.attrs().is_some()) {
            prims
                .iter_mut()
                .map(|p| p.take_attrs().unwrap_or_default())
                .collect()
        } else {
            Vec::new()
        };
        let root = &binary[0];
        let bounds = Some((root.bounds[0], root.bounds[1]));
        let mut nodes = Vec::with_capacity(binary.len() / 2 + 1);
        let mut root_leaf = if root.count > 0 {
            Some(Child::leaf(root.offset as usize, root.count as usize))
        } else {
            collapse(&binary, 0, &mut nodes);
            None
        };
        let mut packets = Vec::new();
        for child in nodes
            .iter_mut()
            .flat_map(|n| n.child.iter_mut())
            .chain(root_leaf.iter_mut())
        {
            if *child != Child::EMPTY && child.is_leaf() {
                *child = pack(*child, &prims, &mut packets);
            }
        }
        Bvh {
            nodes,
            packets,
            root_leaf,
            bounds,
            prims,
            attrs,
            tangents: true,
        }
    }

    /// Whether [`Bvh::intersect`]'s hits carry the tangents `dp_du`, `dp_dv` (they do unless
    /// turned off; left zero, they save their computation at every hit).
    pub fn set_tangents(&mut self, on: bool) {
        self.tangents = on;
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
        self.bounds
    }

    /// The closest hit with `t` in `(tmin, tmax)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, tmin: f32, tmax: f32) -> Option<Hit> {
        let mut best: Option<(usize, RawHit)> = None;
        self.traverse::<false, false>(ray, tmin, tmax, &mut best);
        best.map(|(i, h)| self.prims[i].finish(ray, &h, self.attrs.get(i), self.tangents))
    }

    /// Whether anything is hit with `t` in `(tmin, tmax)` (stops at the first hit).
    ///
    /// The answer does not depend on the order in which boxes are visited, only the work does.
    /// A ray without end (a shadow ray toward an environment map, or a sky) visits the farthest
    /// boxes first: indoors such a ray is mostly stopped by the room's walls, not by what lies
    /// near its origin. On the living room that visits 32% fewer nodes and 20% fewer leaves
    /// than lane order (8 spp at 160x90); nearest-first visits 6% more. A ray toward a point
    /// at a finite distance keeps lane order, the cheapest to pick (farthest-first visits 9%
    /// more leaves on the Cornell box, whose shadow rays end at its light).
    pub fn occluded(&self, ray: &Ray, tmin: f32, tmax: f32) -> bool {
        let mut best = None;
        if tmax.is_infinite() {
            self.traverse::<true, true>(ray, tmin, tmax, &mut best)
        } else {
            self.traverse::<true, false>(ray, tmin, tmax, &mut best)
        }
    }

    /// Tests a leaf's primitives; with `ANY` returns at the first hit, otherwise keeps the
    /// closest in `best` and lowers `t_best`. Returns whether anything was hit.
    #[inline(always)]
    fn leaf<const ANY: bool>(
        &self,
        leaf: Child,
        pre: &RayPre,
        tmin: f32,
        t_best: &mut f32,
        best: &mut Option<(usize, RawHit)>,
    ) -> bool {
        let range = match leaf.packet_index() {
            None => leaf.range(),
            Some(k) => {
                let packet = &self.packets[k];
                let first = packet.first as usize;
                match packet.triangles.intersect::<ANY>(pre, tmin, *t_best) {
                    PacketHit::Miss => return false,
                    PacketHit::Hit(lane, h) => {
                        *t_best = h.t;
                        *best = Some((first + lane, h));
                        if !ANY {
                            // The packet holds the vertices only: start loading what the hit
                            // will be finished from while the traversal goes on.
                            prefetch(&self.prims[first + lane]);
                            if let Some(a) = self.attrs.get(first + lane) {
                                prefetch(a);
                            }
                        }
                        return true;
                    }
                    PacketHit::Unsure => first..first + packet.triangles.count(),
                }
            }
        };
        let first = range.start;
        let mut any = false;
        for (i, p) in self.prims[range].iter().enumerate() {
            if let Some(h) = p.intersect_raw(pre, tmin, *t_best) {
                if ANY {
                    return true;
                }
                any = true;
                *t_best = h.t;
                *best = Some((first + i, h));
            }
        }
        any
    }

    /// Walks the tree; with `ANY` returns at the first hit, otherwise keeps the closest in
    /// `best`. Returns whether anything was hit. Boxes are visited nearest first, with
    /// `FARTHEST_FIRST` farthest first, and with `ANY` alone in lane order.
    #[inline(always)]
    fn traverse<const ANY: bool, const FARTHEST_FIRST: bool>(
        &self,
        ray: &Ray,
        tmin: f32,
        tmax: f32,
        best: &mut Option<(usize, RawHit)>,
    ) -> bool {
        if self.prims.is_empty() {
            return false;
        }
        let mut t_best = tmax;
        if let Some(leaf) = self.root_leaf {
            return self.leaf::<ANY>(leaf, &RayPre::new(ray), tmin, &mut t_best, best);
        }
        let slab = SlabRay::new(ray.o, ray.d);
        let pre = RayPre::new(ray);
        // ArrayVec: no zero-fill of the whole stack on every ray.
        let mut stack: ArrayVec<(Child, f32), STACK> = ArrayVec::new();
        let mut next = Child(0);
        loop {
            if next.is_leaf() {
                if self.leaf::<ANY>(next, &pre, tmin, &mut t_best, best) && ANY {
                    return true;
                }
            } else {
                let n = &self.nodes[next.0 as usize];
                let (t_near, mut mask) = slab.hit(&n.planes, tmin, t_best);
                if mask != 0 {
                    let t = t_near.to_array();
                    // Whether a box entered at `a` is visited before one entered at `b`.
                    let before = |a: f32, b: f32| if FARTHEST_FIRST { a > b } else { a < b };
                    if ANY && !FARTHEST_FIRST {
                        // Any order will do: descend into the first, stack the others.
                        next = n.child[mask.trailing_zeros() as usize];
                        mask &= mask - 1;
                        while mask != 0 {
                            let k = mask.trailing_zeros() as usize;
                            stack.push((n.child[k], t[k]));
                            mask &= mask - 1;
                        }
                        continue;
                    }
                    let k0 = mask.trailing_zeros() as usize;
                    let rest = mask & (mask - 1);
                    if rest == 0 {
                        // One child hit (the common case deep in the tree): nothing to order.
                        next = n.child[k0];
                        continue;
                    }
                    if rest & (rest - 1) == 0 {
                        // Two: on a tie the later lane first, as the sort below.
                        let k1 = rest.trailing_zeros() as usize;
                        let (first, second) = if before(t[k0], t[k1]) {
                            (k0, k1)
                        } else {
                            (k1, k0)
                        };
                        stack.push((n.child[second], t[second]));
                        next = n.child[first];
                        continue;
                    }
                    // Three or more: sort by entry distance so that the last is visited
                    // first, visit it and stack the others (among equal distances the later
                    // lane is visited first).
                    let mut hits: ArrayVec<(f32, Child), WIDTH> = ArrayVec::new();
                    while mask != 0 {
                        let k = mask.trailing_zeros() as usize;
                        let mut j = hits.len();
                        hits.push((t[k], n.child[k]));
                        while j > 0 && before(hits[j - 1].0, hits[j].0) {
                            hits.swap(j - 1, j);
                            j -= 1;
                        }
                        mask &= mask - 1;
                    }
                    let (_, first) = hits.pop().expect("a hit");
                    for &(t, c) in &hits {
                        stack.push((c, t));
                    }
                    next = first;
                    continue;
                }
            }
            // Pop the next box that may still hold something nearer.
            loop {
                let Some((c, t_enter)) = stack.pop() else {
                    return best.is_some();
                };
                if t_enter <= t_best {
                    next = c;
                    break;
                }
            }
        }
    }
}

/// `leaf` itself, or its packet (appended to `packets`) when it holds two or more triangles and
/// nothing else.
fn pack(leaf: Child, prims: &[Primitive], packets: &mut Vec<Packet>) -> Child {
    let range = leaf.range();
    let triangles: ArrayVec<[Vec3; 3], MAX_LEAF> = prims[range.clone()]
        .iter()
        .map_while(|p| match p {
            Primitive::Triangle { p, .. } => Some(*p),
            _ => None,
        })
        .collect();
    if triangles.len() < 2 || triangles.len() < range.len() {
        return leaf;
    }
    packets.push(Packet {
        triangles: TrianglePacket::new(&triangles),
        first: range.start as u32,
    });
    Child::packet(packets.len() - 1)
}

/// Appends the wide node of the binary interior node `b` (and, after it, its subtrees);
/// returns its index. Opens the binary child of largest area until `WIDTH` children remain.
fn collapse(binary: &[Node], b: usize, out: &mut Vec<WideNode>) -> u32 {
    let mut kids: ArrayVec<usize, WIDTH> = ArrayVec::new();
    kids.push(b + 1);
    kids.push(binary[b].offset as usize);
    while kids.len() < WIDTH {
        let area = |i: usize| {
            let n = &binary[i];
            Aabb {
                lo: n.bounds[0],
                hi: n.bounds[1],
            }
            .half_area()
        };
        let Some(k) = (0..kids.len())
            .filter(|&k| binary[kids[k]].count == 0)
            .max_by(|&x, &y| area(kids[x]).total_cmp(&area(kids[y])))
        else {
            break;
        };
        let i = kids[k];
        kids[k] = i + 1;
        kids.insert(k + 1, binary[i].offset as usize);
    }
    // Unused slots keep empty boxes (min +∞, max −∞), which no ray enters.
    let mut planes = [[f32::INFINITY; WIDTH]; 6];
    for max in &mut planes[3..] {
        *max = [f32::NEG_INFINITY; WIDTH];
    }
    let mut child = [Child::EMPTY; WIDTH];
    let me = out.len();
    out.push(WideNode {
        planes: planes.map(Lanes::new),
        child,
    });
    for (k, &i) in kids.iter().enumerate() {
        let n = &binary[i];
        for a in 0..3 {
            planes[a][k] = n.bounds[0][a];
            planes[a + 3][k] = n.bounds[1][a];
        }
        child[k] = if n.count > 0 {
            Child::leaf(n.offset as usize, n.count as usize)
        } else {
            Child(collapse(binary, i, out))
        };
    }
    out[me] = WideNode {
        planes: planes.map(Lanes::new),
        child,
    };
    me as u32
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
