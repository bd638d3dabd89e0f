//! The slab test of one BVH node's eight child boxes, eight lanes at once (`wide::f32x8`: one
//! AVX operation per step when the build targets AVX, as `.cargo/config.toml` asks for on
//! x86-64; two SSE2 operations otherwise).
//!
//! Each axis' near and far plane is picked by the sign bit of the direction, so a zero (or
//! negative zero) component gives an infinite slab of the right sign; `0·∞ = NaN` only arises
//! when the origin lies on a plane parallel to the ray, and such a lane is then treated as
//! unconstrained (the ray runs inside the closed slab). The far distance is enlarged by
//! `1 + 2γ₃` (Ize 2013) so that rounding cannot cull a box whose primitive the watertight
//! triangle test would hit.

use glam::Vec3;

/// Children per node.
pub const WIDTH: usize = 8;

/// One plane of a node: a coordinate per child.
pub type Lanes = wide::f32x8;

/// `1 + 2γ₃` with `γₙ = nε/(1 − nε)`, `ε` half an ulp of one.
const FAR_SCALE: f32 =
    1.0 + 2.0 * (3.0 * (f32::EPSILON * 0.5)) / (1.0 - 3.0 * (f32::EPSILON * 0.5));

/// A ray as the slab test wants it: origin and inverse direction splatted, and per axis the
/// plane indices (min x, y, z, then max x, y, z) of its near and far side.
#[derive(Debug, Clone, Copy)]
pub struct SlabRay {
    o: [Lanes; 3],
    inv: [Lanes; 3],
    near: [usize; 3],
    far: [usize; 3],
}

impl SlabRay {
    /// The ray from `o` along `d` (not necessarily normalised; components may be ±0).
    #[inline(always)]
    pub fn new(o: Vec3, d: Vec3) -> SlabRay {
        let inv = Vec3::ONE / d;
        let neg = |a: usize| usize::from(inv[a].is_sign_negative()) * 3;
        SlabRay {
            o: [0, 1, 2].map(|a| Lanes::splat(o[a])),
            inv: [0, 1, 2].map(|a| Lanes::splat(inv[a])),
            near: [0, 1, 2].map(|a| a + neg(a)),
            far: [0, 1, 2].map(|a| a + 3 - neg(a)),
        }
    }

    /// The eight entry distances, and a bit mask of the boxes the ray overlaps within
    /// `[tmin, tmax]`. A slot whose box is empty (min +∞, max −∞) is never entered. The
    /// distances stay in a register: most nodes are missed, and only a hit reads them.
    #[inline(always)]
    pub fn hit(&self, planes: &[Lanes; 6], tmin: f32, tmax: f32) -> (Lanes, u32) {
        let mut t_near = Lanes::splat(tmin);
        let mut t_far = Lanes::splat(f32::INFINITY);
        for a in 0..3 {
            let near = (planes[self.near[a]] - self.o[a]) * self.inv[a];
            let far = (planes[self.far[a]] - self.o[a]) * self.inv[a];
            t_near = max_or_keep(near, t_near);
            t_far = min_or_keep(far, t_far);
        }
        let t_far = (t_far * Lanes::splat(FAR_SCALE)).fast_min(Lanes::splat(tmax));
        (t_near, t_near.simd_le(t_far).to_bitmask())
    }
}

/// Per lane `x` where `x > keep`, else `keep` (also where `x` is NaN).
///
/// On x86-64 that is `maxps(x, keep)` (SSE or AVX), one instruction: it returns its second
/// operand when either is NaN, and for equal values. Elsewhere (NEON's max propagates NaN) a
/// compare and a select.
#[inline(always)]
fn max_or_keep(x: Lanes, keep: Lanes) -> Lanes {
    if cfg!(target_arch = "x86_64") {
        x.fast_max(keep)
    } else {
        x.simd_gt(keep).bitselect(x, keep)
    }
}

/// Per lane `x` where `x < keep`, else `keep` (also where `x` is NaN); see [`max_or_keep`].
#[inline(always)]
fn min_or_keep(x: Lanes, keep: Lanes) -> Lanes {
    if cfg!(target_arch = "x86_64") {
        x.fast_min(keep)
    } else {
        x.simd_lt(keep).bitselect(x, keep)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// The slab test of one box, one `f32` operation at a time, in the order the lanes use.
    fn scalar(o: Vec3, d: Vec3, lo: Vec3, hi: Vec3, tmin: f32, tmax: f32) -> (f32, bool) {
        let inv = Vec3::ONE / d;
        let (mut t_near, mut t_far) = (tmin, f32::INFINITY);
        for a in 0..3 {
            let (n, f) = if inv[a].is_sign_negative() {
                (hi[a], lo[a])
            } else {
                (lo[a], hi[a])
            };
            let (n, f) = ((n - o[a]) * inv[a], (f - o[a]) * inv[a]);
            // NaN compares false: it leaves the bound as it was.
            if n > t_near {
                t_near = n;
            }
            if f < t_far {
                t_far = f;
            }
        }
        let t_far = (t_far * FAR_SCALE).min(tmax);
        (t_near, t_near <= t_far)
    }

    /// A coordinate that is often exactly 0, ±1 or ±∞ (an empty slot's planes), else random.
    fn coordinate(rng: &mut Xoshiro256PlusPlus) -> f32 {
        match rng.random_range(0..8) {
            0 => 0.0,
            1 => 1.0,
            2 => -1.0,
            3 => f32::INFINITY,
            4 => f32::NEG_INFINITY,
            _ => rng.random_range(-4.0..4.0),
        }
    }

    /// Every lane of the eight-lane test gives the scalar test's entry distance bit for bit and
    /// its verdict, on random boxes and rays that include origins on a box plane with a zero
    /// direction component (a NaN lane), −0 components, empty slots and `tmax` below some
    /// entries. A NaN lane that constrained the ray, swapped `max` operands, a lane computed in
    /// another order or a mask bit in the wrong place fails here; deterministic.
    #[test]
    fn lanes_agree_with_the_scalar_test() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(11);
        let (mut hits, mut nan_lanes) = (0u32, 0u32);
        for case in 0..20_000 {
            let mut coords = [[0.0f32; WIDTH]; 6];
            for plane in &mut coords {
                for c in plane.iter_mut() {
                    *c = coordinate(&mut rng);
                }
            }
            // Origins on the integer planes above, directions often axis-aligned or −0.
            let o = Vec3::new(
                rng.random_range(-2..=2) as f32,
                rng.random_range(-2..=2) as f32,
                rng.random_range(-2..=2) as f32,
            );
            let d = Vec3::new(
                [0.0, -0.0, 1.0, -0.5, rng.random_range(-1.0..1.0)][case % 5],
                [1.0, 0.0, -0.0, 0.25, rng.random_range(-1.0..1.0)][(case / 5) % 5],
                rng.random_range(-1.0..1.0),
            );
            let (tmin, tmax) = (0.0, [f32::INFINITY, 1.5, 0.25][case % 3]);
            let (t, mask) = SlabRay::new(o, d).hit(&coords.map(Lanes::new), tmin, tmax);
            let t = t.to_array();
            for k in 0..WIDTH {
                let lo = Vec3::new(coords[0][k], coords[1][k], coords[2][k]);
                let hi = Vec3::new(coords[3][k], coords[4][k], coords[5][k]);
                let (want_t, want_hit) = scalar(o, d, lo, hi, tmin, tmax);
                assert_eq!(
                    (t[k].to_bits(), mask >> k & 1 == 1),
                    (want_t.to_bits(), want_hit),
                    "case {case} lane {k}: o {o}, d {d}, box {lo} {hi}, tmax {tmax}"
                );
                hits += u32::from(want_hit);
                nan_lanes +=
                    u32::from((0..3).any(|a| d[a] == 0.0 && (lo[a] == o[a] || hi[a] == o[a])));
            }
        }
        // Both verdicts and the NaN case must occur for the comparison to mean anything (with
        // this seed: 3611 lanes entered, 17 565 lanes with an origin on a plane parallel to the
        // ray, of 160 000).
        assert!(
            hits > 1_000 && nan_lanes > 1_000,
            "hits {hits}, NaN lanes {nan_lanes}"
        );
    }
}
