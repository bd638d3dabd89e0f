//! Up to four triangles of one BVH leaf, stored lane by lane, tested against a ray together
//! (glam's `Vec4`: one SSE2 operation per step on baseline x86-64).
//!
//! Why: the scalar test ran once per triangle behind an enum dispatch, and primitive tests were
//! a tenth of the living room's render time. The packet repeats, in every lane, the exact
//! operations of the scalar watertight test (same order, no fused multiply-add), so a lane's
//! edge functions, determinant and `t` are bit for bit the scalar ones. The rare lanes the
//! scalar test treats specially (an edge function exactly zero, an overflowing `t`, a hit whose
//! `t` must be refined from the plane) are not decided here: the caller then runs the scalar
//! test on the whole leaf, so the result never differs from it.

use super::{REFINE_SPAN, RawHit, RayPre};
use glam::{Vec3, Vec4};

/// The vertices of up to four triangles, lane `k` holding triangle `k`.
#[derive(Debug, Clone, Copy)]
pub struct TrianglePacket {
    /// `[x, y, z]` of the first, second and third vertex.
    v: [[Vec4; 3]; 3],
    /// Lanes holding a triangle (the first `count`).
    lanes: u32,
}

/// What a packet test found.
#[derive(Debug, Clone, Copy)]
pub enum PacketHit {
    /// No triangle is hit in `(tmin, tmax)`.
    Miss,
    /// The nearest hit (the first lane among equals) and its lane.
    Hit(usize, RawHit),
    /// A lane needs the scalar test's special handling: test the triangles one by one.
    Unsure,
}

impl TrianglePacket {
    /// A packet of one to four triangles.
    pub fn new(triangles: &[[Vec3; 3]]) -> TrianglePacket {
        assert!(
            (1..=4).contains(&triangles.len()),
            "a packet holds one to four triangles"
        );
        let mut v = [[Vec4::ZERO; 3]; 3];
        for (k, tri) in triangles.iter().enumerate() {
            for (vertex, p) in tri.iter().enumerate() {
                for axis in 0..3 {
                    v[vertex][axis][k] = p[axis];
                }
            }
        }
        TrianglePacket {
            v,
            lanes: (1u32 << triangles.len()) - 1,
        }
    }

    /// Number of triangles (one to four: a packet is never empty).
    pub fn count(&self) -> usize {
        self.lanes.count_ones() as usize
    }

    /// The watertight test of every lane; with `ANY`, a hit may be any lane's rather than the
    /// nearest.
    #[inline(always)]
    pub fn intersect<const ANY: bool>(&self, r: &RayPre, tmin: f32, tmax: f32) -> PacketHit {
        let (kx, ky, kz) = (r.kx, r.ky, r.kz);
        let o = r.o.to_array();
        let rel = |vertex: usize, axis: usize| self.v[vertex][axis] - Vec4::splat(o[axis]);
        let (sx, sy, sz) = (Vec4::splat(r.sx), Vec4::splat(r.sy), Vec4::splat(r.sz));
        let (az, bz, cz) = (rel(0, kz), rel(1, kz), rel(2, kz));
        let ax = rel(0, kx) - sx * az;
        let ay = rel(0, ky) - sy * az;
        let bx = rel(1, kx) - sx * bz;
        let by = rel(1, ky) - sy * bz;
        let cx = rel(2, kx) - sx * cz;
        let cy = rel(2, ky) - sy * cz;
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let zero = Vec4::ZERO;
        let on_edge = u.cmpeq(zero) | v.cmpeq(zero) | w.cmpeq(zero);
        let negative = u.cmplt(zero) | v.cmplt(zero) | w.cmplt(zero);
        let positive = u.cmpgt(zero) | v.cmpgt(zero) | w.cmpgt(zero);
        let det = u + v + w;
        let inside = !(negative & positive) & det.cmpne(zero);
        // Most packets end here: every lane outside its triangle's edges.
        if ((inside | on_edge).bitmask() & self.lanes) == 0 {
            return PacketHit::Miss;
        }
        let (saz, sbz, scz) = (sz * az, sz * bz, sz * cz);
        let big_t = u * saz + v * sbz + w * scz;
        let t = big_t / det;
        // False for ±∞ and NaN.
        let finite = big_t.abs().cmplt(Vec4::INFINITY);
        let reach = saz.abs().max(sbz.abs()).max(scz.abs());
        let far_off = reach.cmpgt(Vec4::splat(REFINE_SPAN) * t.abs());
        let doubt = Vec4::splat(8.0 * f32::EPSILON) * reach;
        let (lo, hi) = (Vec4::splat(tmin), Vec4::splat(tmax));
        let surely_out = (t + doubt).cmple(lo) | (t - doubt).cmpge(hi);
        let in_range = t.cmpgt(lo) & t.cmplt(hi);

        let lanes = self.lanes;
        let unsure = ((on_edge | (inside & (!finite | (far_off & !surely_out)))).bitmask()) & lanes;
        let hits = (inside & finite & !far_off & in_range).bitmask() & lanes;
        if ANY && hits != 0 {
            return PacketHit::Hit(hits.trailing_zeros() as usize, raw(hits, t, u, v, w));
        }
        if unsure != 0 {
            return PacketHit::Unsure;
        }
        if hits == 0 {
            return PacketHit::Miss;
        }
        // The nearest lane; among equal `t`, the first (as the scalar loop keeps it).
        let ts = t.to_array();
        let mut best = hits.trailing_zeros() as usize;
        let mut rest = hits & (hits - 1);
        while rest != 0 {
            let k = rest.trailing_zeros() as usize;
            if ts[k] < ts[best] {
                best = k;
            }
            rest &= rest - 1;
        }
        PacketHit::Hit(best, raw(1 << best, t, u, v, w))
    }
}

/// The [`RawHit`] of the first lane set in `mask`.
#[inline(always)]
fn raw(mask: u32, t: Vec4, u: Vec4, v: Vec4, w: Vec4) -> RawHit {
    let k = mask.trailing_zeros() as usize;
    RawHit {
        t: t[k],
        a: u[k],
        b: v[k],
        c: w[k],
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Ray, intersect_triangle};
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// What the BVH's scalar leaf loop finds: the nearest hit, the first among equal `t`.
    fn scalar(tris: &[[Vec3; 3]], r: &RayPre, tmin: f32, tmax: f32) -> Option<(usize, RawHit)> {
        let mut best = None;
        let mut t_best = tmax;
        for (k, p) in tris.iter().enumerate() {
            if let Some(h) = intersect_triangle(p, r, tmin, t_best) {
                t_best = h.t;
                best = Some((k, h));
            }
        }
        best
    }

    fn bits(h: &RawHit) -> [u32; 4] {
        [h.t, h.a, h.b, h.c].map(f32::to_bits)
    }

    /// Checks one packet against the scalar loop; returns whether the packet was unsure.
    fn check(tris: &[[Vec3; 3]], ray: &Ray, tmin: f32, tmax: f32) -> bool {
        let pre = RayPre::new(ray);
        let packet = TrianglePacket::new(tris);
        let want = scalar(tris, &pre, tmin, tmax);
        let case = || format!("{tris:?} {ray:?} ({tmin}, {tmax})");
        match packet.intersect::<false>(&pre, tmin, tmax) {
            PacketHit::Unsure => return true,
            PacketHit::Miss => assert!(want.is_none(), "packet missed {want:?}: {}", case()),
            PacketHit::Hit(lane, h) => {
                let (k, w) =
                    want.unwrap_or_else(|| panic!("packet hit, scalar did not: {}", case()));
                assert_eq!((lane, bits(&h)), (k, bits(&w)), "{}", case());
            }
        }
        match packet.intersect::<true>(&pre, tmin, tmax) {
            PacketHit::Unsure => {}
            PacketHit::Miss => assert!(want.is_none(), "any-hit missed: {}", case()),
            PacketHit::Hit(lane, h) => {
                let w = intersect_triangle(&tris[lane], &pre, tmin, tmax)
                    .unwrap_or_else(|| panic!("any-hit lane {lane} is no hit: {}", case()));
                assert_eq!(bits(&h), bits(&w), "{}", case());
            }
        }
        false
    }

    fn point(rng: &mut Xoshiro256PlusPlus, scale: f32) -> Vec3 {
        Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ) * scale
    }

    /// Random packets of 1-4 triangles (some sharing edges and vertices, some huge and met at
    /// grazing angles, some degenerate) against random rays: every sure answer is the scalar
    /// loop's, bit for bit, and the packet is unsure only rarely. A lane that compared the wrong
    /// `t`, kept the later of two equal hits, or skipped a lane fails here; deterministic.
    #[test]
    fn agrees_with_the_scalar_loop() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let (mut unsure, mut hits, cases) = ([0; 3], 0, 20_000);
        for case in 0..cases {
            let n = 1 + case % 4;
            let mut tris: Vec<[Vec3; 3]> = Vec::new();
            for k in 0..n {
                let tri = match (case / 4 + k) % 5 {
                    // A neighbour across the previous triangle's edge.
                    0 if k > 0 => {
                        let [a, b, _] = tris[k - 1];
                        [b, a, point(&mut rng, 1.0)]
                    }
                    // Huge, so rays meet it far from its vertices.
                    1 => [
                        point(&mut rng, 1e4),
                        point(&mut rng, 1e4),
                        point(&mut rng, 1e4),
                    ],
                    // Degenerate: a repeated vertex.
                    2 if case % 7 == 0 => {
                        let a = point(&mut rng, 1.0);
                        [a, a, point(&mut rng, 1.0)]
                    }
                    _ => [
                        point(&mut rng, 1.0),
                        point(&mut rng, 1.0),
                        point(&mut rng, 1.0),
                    ],
                };
                tris.push(tri);
            }
            // Aim at a vertex, at an edge midpoint or anywhere near the packet.
            let target = match case % 3 {
                0 => tris[0][0],
                1 => (tris[0][0] + tris[0][1]) * 0.5,
                _ => point(&mut rng, 0.5),
            };
            let o = point(&mut rng, 3.0);
            let d = (target - o).normalize();
            if !d.is_finite() {
                continue;
            }
            let ray = Ray { o, d };
            let tmax = if case % 5 == 0 { 2.0 } else { f32::INFINITY };
            unsure[case % 3] += usize::from(check(&tris, &ray, 0.0, tmax));
            hits += usize::from(scalar(&tris, &RayPre::new(&ray), 0.0, tmax).is_some());
        }
        assert!(hits > cases / 4, "too few hits to test anything: {hits}");
        // Rays aimed at a vertex or an edge often give an exact zero, and a huge triangle (one
        // in five here) hit far from its vertices has its `t` refined by the scalar test; rays
        // aimed elsewhere leave the packet unsure in 7% of cases with this seed (481 of 6667).
        // A packet that gave up on every hit would be unsure in every case with a hit.
        assert!(
            unsure[2] < cases / 3 / 10,
            "unsure (by aim: vertex, edge, other): {unsure:?}"
        );
    }

    /// A ray through the shared edge of two triangles: the scalar test decides it in double
    /// precision, so the packet must not decide it (or must agree).
    #[test]
    fn shared_edge_is_left_to_the_scalar_test() {
        let a = Vec3::new(0.0, 0.0, 0.0);
        let b = Vec3::new(1.0, 0.0, 0.0);
        let tris = [
            [a, b, Vec3::new(0.0, 1.0, 0.0)],
            [b, a, Vec3::new(0.0, -1.0, 0.0)],
        ];
        let ray = Ray {
            o: Vec3::new(0.5, 0.0, 1.0),
            d: Vec3::new(0.0, 0.0, -1.0),
        };
        assert!(check(&tris, &ray, 0.0, f32::INFINITY));
        let pre = RayPre::new(&ray);
        assert!(scalar(&tris, &pre, 0.0, f32::INFINITY).is_some());
    }
}
