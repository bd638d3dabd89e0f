//! Ray–shape intersection, the BVH and whole-shape sampling (`render::shapes`, `render::bvh`).
//!
//! Random scenes use fixed seeds, so every run checks the same rays. Monte Carlo checks state
//! their tolerance as a multiple of the estimate's standard error.

use fireflies::render::GeometryDesc;
use fireflies::render::bvh::Bvh;
use fireflies::render::scene::MeshDesc;
use fireflies::render::shapes::{Hit, Primitive, Ray, ShapeSampler, primitives};
use glam::{DVec3, Mat4, Quat, Vec2, Vec3};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::f64::consts::PI;

// ---------------------------------------------------------------------------------------------
// Helpers

fn rng(seed: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(0x6E0_0000 + seed)
}

fn uni(r: &mut Xoshiro256PlusPlus, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * r.random::<f32>()
}

fn rand_vec(r: &mut Xoshiro256PlusPlus, lo: f32, hi: f32) -> Vec3 {
    Vec3::new(uni(r, lo, hi), uni(r, lo, hi), uni(r, lo, hi))
}

fn rand_dir(r: &mut Xoshiro256PlusPlus) -> Vec3 {
    loop {
        let v = rand_vec(r, -1.0, 1.0);
        let l2 = v.length_squared();
        if l2 > 1e-4 && l2 <= 1.0 {
            return v / l2.sqrt();
        }
    }
}

fn rand_u(r: &mut Xoshiro256PlusPlus) -> Vec2 {
    Vec2::new(r.random::<f32>(), r.random::<f32>())
}

fn mesh(positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> GeometryDesc {
    GeometryDesc::Mesh(MeshDesc {
        positions,
        normals: None,
        uvs: None,
        indices,
    })
}

/// Mitsuba's rectangle: the square `[-1,1]²` at `z = 0` facing `+z`, mapped by `m`.
fn rectangle(m: Mat4) -> GeometryDesc {
    let p = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .map(|(x, y)| m.transform_point3(Vec3::new(x, y, 0.0)));
    mesh(p.to_vec(), vec![[0, 1, 2], [0, 2, 3]])
}

/// The cube `[lo, hi]` with outward (counter-clockwise) faces.
fn cube(lo: Vec3, hi: Vec3) -> GeometryDesc {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for axis in 0..3 {
        for side in [0, 1] {
            // Face with outward normal ±e_axis: corners in (u, v) of the two other axes.
            let (ua, va) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = positions.len() as u32;
            for (a, b) in [(0, 0), (1, 0), (1, 1), (0, 1)] {
                let mut p = [0.0f32; 3];
                p[axis] = if side == 1 { hi[axis] } else { lo[axis] };
                p[ua] = if a == 1 { hi[ua] } else { lo[ua] };
                p[va] = if b == 1 { hi[va] } else { lo[va] };
                positions.push(Vec3::from_array(p));
            }
            // (e_ua × e_va) = +e_axis: counter-clockwise for the +side face, reversed for −.
            if side == 1 {
                indices.push([base, base + 1, base + 2]);
                indices.push([base, base + 2, base + 3]);
            } else {
                indices.push([base, base + 2, base + 1]);
                indices.push([base, base + 3, base + 2]);
            }
        }
    }
    mesh(positions, indices)
}

fn brute(prims: &[Primitive], ray: &Ray, tmin: f32, tmax: f32) -> Option<Hit> {
    let mut best = None;
    let mut t = tmax;
    for p in prims {
        if let Some(h) = p.intersect(ray, tmin, t) {
            t = h.t;
            best = Some(h);
        }
    }
    best
}

#[track_caller]
fn assert_close(a: Vec3, b: Vec3, tol: f32) {
    assert!(
        (a - b).abs().max_element() <= tol,
        "{a:?} vs {b:?} (tol {tol:e})"
    );
}

#[track_caller]
fn assert_rel(a: f64, b: f64, tol: f64) {
    assert!(
        (a - b).abs() <= tol * b.abs(),
        "{a} vs {b}: relative error {:e} > {tol:e}",
        ((a - b) / b).abs()
    );
}

fn one(shape: u32, g: &GeometryDesc) -> Primitive {
    let mut v = primitives(shape, g);
    assert_eq!(v.len(), 1);
    v.pop().unwrap()
}

/// Solid angle of the triangle `(a, b, c)` seen from `x` (Van Oosterom & Strackee 1983).
fn triangle_solid_angle(x: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (a, b, c) = (a - x, b - x, c - x);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c)).abs();
    let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * num.atan2(den)
}

/// Solid angle of the front-facing triangles of a mesh from `x` (exact for a convex mesh).
fn visible_mesh_solid_angle(x: Vec3, g: &GeometryDesc) -> f64 {
    let GeometryDesc::Mesh(m) = g else { panic!() };
    let mut sum = 0.0;
    for t in &m.indices {
        let p = t.map(|i| m.positions[i as usize].as_dvec3());
        let n = (p[1] - p[0]).cross(p[2] - p[0]);
        if n.dot(x.as_dvec3() - p[0]) > 0.0 {
            sum += triangle_solid_angle(x.as_dvec3(), p[0], p[1], p[2]);
        }
    }
    sum
}

// ---------------------------------------------------------------------------------------------
// Single primitives

#[test]
fn triangle_hits_have_known_t_and_front_normal_from_both_sides() {
    let g = mesh(
        vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        vec![[0, 1, 2]], // counter-clockwise seen from +z
    );
    let tri = one(7, &g);
    let h = tri
        .intersect(
            &Ray::new(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z),
            0.0,
            f32::INFINITY,
        )
        .unwrap();
    assert_eq!(h.t, 2.0);
    assert_close(h.p, Vec3::new(0.25, 0.25, 0.0), 1e-7);
    assert_eq!(h.ng, Vec3::Z);
    assert_eq!(h.ns, Vec3::Z);
    assert_eq!(h.shape, 7);
    // From behind: same front normal.
    let h = tri
        .intersect(
            &Ray::new(Vec3::new(0.25, 0.25, -3.0), Vec3::Z),
            0.0,
            f32::INFINITY,
        )
        .unwrap();
    assert_eq!(h.t, 3.0);
    assert_eq!(h.ng, Vec3::Z);
    // Clockwise winding flips the front.
    let back = one(
        0,
        &mesh(vec![Vec3::ZERO, Vec3::Y, Vec3::X], vec![[0, 1, 2]]),
    );
    let h = back
        .intersect(
            &Ray::new(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z),
            0.0,
            f32::INFINITY,
        )
        .unwrap();
    assert_eq!(h.ng, -Vec3::Z);
    // Oblique ray.
    let d = Vec3::new(1.0, 1.0, -2.0).normalize();
    let o = Vec3::new(0.1, 0.1, 0.0) - d * 5.0;
    let h = tri.intersect(&Ray::new(o, d), 0.0, f32::INFINITY).unwrap();
    assert!((h.t - 5.0).abs() < 1e-5);
    assert_close(h.p, Vec3::new(0.1, 0.1, 0.0), 1e-6);
}

#[test]
fn triangle_misses_grazing_and_interval() {
    let tri = one(
        0,
        &mesh(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]),
    );
    let down = |x: f32, y: f32| Ray::new(Vec3::new(x, y, 1.0), -Vec3::Z);
    assert!(tri.intersect(&down(0.6, 0.6), 0.0, f32::INFINITY).is_none());
    assert!(
        tri.intersect(&down(-0.1, 0.5), 0.0, f32::INFINITY)
            .is_none()
    );
    // Pointing away.
    let up = Ray::new(Vec3::new(0.2, 0.2, 1.0), Vec3::Z);
    assert!(tri.intersect(&up, 0.0, f32::INFINITY).is_none());
    // In the triangle's plane: no hit, no NaN.
    for o in [Vec3::new(-1.0, 0.2, 0.0), Vec3::new(-1.0, 0.0, 0.0)] {
        assert!(
            tri.intersect(&Ray::new(o, Vec3::X), 0.0, f32::INFINITY)
                .is_none()
        );
    }
    // The interval is open at both ends.
    let r = down(0.2, 0.2);
    assert!(tri.intersect(&r, 0.0, 1.0).is_none());
    assert!(tri.intersect(&r, 1.0, 2.0).is_none());
    assert_eq!(tri.intersect(&r, 0.999, 1.001).unwrap().t, 1.0);
    // Edges and vertices count (watertight test, closed triangle).
    for (x, y) in [(0.5, 0.5), (0.0, 0.5), (0.5, 0.0), (0.0, 0.0), (1.0, 0.0)] {
        assert!(
            tri.intersect(&down(x, y), 0.0, f32::INFINITY).is_some(),
            "edge point ({x}, {y})"
        );
    }
}

#[test]
fn triangle_shading_normals_interpolate_and_stay_in_front_hemisphere() {
    let tilt = Vec3::new(0.6, 0.0, 0.8);
    let g = GeometryDesc::Mesh(MeshDesc {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        normals: Some(vec![Vec3::Z, tilt, Vec3::Z]),
        uvs: None,
        indices: vec![[0, 1, 2]],
    });
    let tri = one(0, &g);
    let h = tri
        .intersect(&Ray::new(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z), 0.0, 10.0)
        .unwrap();
    assert_eq!(h.ng, Vec3::Z);
    assert_close(h.ns, (Vec3::Z * 0.5 + tilt * 0.5).normalize(), 1e-6);
    // Vertex normals on the back side get flipped into ng's hemisphere.
    let g = GeometryDesc::Mesh(MeshDesc {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        normals: Some(vec![-Vec3::Z; 3]),
        uvs: None,
        indices: vec![[0, 1, 2]],
    });
    let h = one(0, &g)
        .intersect(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z), 0.0, 10.0)
        .unwrap();
    assert_eq!(h.ns, Vec3::Z);
}

#[test]
fn sphere_hits_from_outside_and_inside() {
    let c = Vec3::new(1.0, 2.0, 3.0);
    let s = one(
        3,
        &GeometryDesc::Sphere {
            center: c,
            radius: 2.0,
        },
    );
    let h = s
        .intersect(
            &Ray::new(Vec3::new(1.0, 2.0, -7.0), Vec3::Z),
            0.0,
            f32::INFINITY,
        )
        .unwrap();
    assert_eq!(h.t, 8.0);
    assert_close(h.p, Vec3::new(1.0, 2.0, 1.0), 1e-6);
    assert_close(h.ng, -Vec3::Z, 1e-7);
    assert_eq!(h.shape, 3);
    // The far side when the near root is excluded.
    let h = s
        .intersect(
            &Ray::new(Vec3::new(1.0, 2.0, -7.0), Vec3::Z),
            8.5,
            f32::INFINITY,
        )
        .unwrap();
    assert_eq!(h.t, 12.0);
    assert_close(h.ng, Vec3::Z, 1e-7);
    // From the centre and from off-centre inside: the outward normal (front = outside).
    let h = s
        .intersect(&Ray::new(c, Vec3::X), 0.0, f32::INFINITY)
        .unwrap();
    assert_eq!(h.t, 2.0);
    assert_close(h.ng, Vec3::X, 1e-7);
    let o = c + Vec3::new(0.0, 1.0, 0.0);
    let h = s
        .intersect(&Ray::new(o, -Vec3::Y), 0.0, f32::INFINITY)
        .unwrap();
    assert!((h.t - 3.0).abs() < 1e-6);
    assert_close(h.ng, -Vec3::Y, 1e-6);
    // Behind the ray, and a miss beside it.
    assert!(
        s.intersect(
            &Ray::new(Vec3::new(1.0, 2.0, 7.0), Vec3::Z),
            0.0,
            f32::INFINITY
        )
        .is_none()
    );
    assert!(
        s.intersect(
            &Ray::new(Vec3::new(3.01, 2.0, -7.0), Vec3::Z),
            0.0,
            f32::INFINITY
        )
        .is_none()
    );
    // Grazing: a tangent ray either touches at the tangent point or misses; never NaN.
    let h = s.intersect(
        &Ray::new(Vec3::new(3.0, 2.0, -7.0), Vec3::Z),
        0.0,
        f32::INFINITY,
    );
    if let Some(h) = h {
        assert!((h.t - 10.0).abs() < 1e-2, "{h:?}");
        assert!(h.p.is_finite() && h.ng.is_finite());
    }
    // Leaving from the surface outward with a small tmin: no self-hit.
    let p = c + Vec3::new(0.0, 0.0, 2.0);
    assert!(
        s.intersect(&Ray::new(p, Vec3::Z), 1e-4, f32::INFINITY)
            .is_none()
    );
    let h = s
        .intersect(&Ray::new(p, -Vec3::Z), 1e-4, f32::INFINITY)
        .unwrap();
    assert!((h.t - 4.0).abs() < 1e-5);
}

#[test]
fn sphere_far_away_keeps_precision() {
    let mut r = rng(1);
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        let c = rand_vec(&mut r, -10.0, 10.0);
        let radius = uni(&mut r, 0.01, 1.0);
        let s = one(0, &GeometryDesc::Sphere { center: c, radius });
        // Aim at a random point of the near hemisphere from 1e4 away.
        let dir_out = rand_dir(&mut r);
        let side = (rand_dir(&mut r) - dir_out * dir_out.dot(rand_dir(&mut r))).normalize();
        let side = (side - dir_out * dir_out.dot(side)).normalize();
        let target = c + side * radius * uni(&mut r, 0.0, 0.95);
        let o = target + dir_out * 1.0e4;
        let d = (target - o).normalize();
        let h = s.intersect(&Ray::new(o, d), 0.0, f32::INFINITY).unwrap();
        // On the surface (projected) and consistent with t.
        assert!(((h.p - c).length() - radius).abs() <= 1e-6 * (1.0 + c.length()));
        let along = (o + d * h.t - h.p).length();
        assert!(along < 4e-3, "t error {along}");
        // Exact distance in double precision.
        let (od, dd, cd) = (o.as_dvec3(), d.as_dvec3(), c.as_dvec3());
        let f = od - cd;
        let (a, b) = (dd.dot(dd), f.dot(dd));
        let disc = b * b - a * (f.dot(f) - (radius as f64).powi(2));
        let t_exact = (-b - disc.sqrt()) / a;
        // Within about an ulp of 1e4.
        assert!(
            (h.t as f64 - t_exact).abs() <= 1.2e-7 * t_exact,
            "t {} vs {t_exact}",
            h.t
        );
        // The point, to what f32 coordinates 1e4 from the sphere can hold (`o − c` alone
        // rounds by 5e-4 there).
        let p_exact = od + dd * t_exact;
        let err = (h.p.as_dvec3() - p_exact).length();
        assert!(
            err <= 1.5e-7 * t_exact,
            "point error {err} (radius {radius})"
        );
        worst = worst.max(err / t_exact);
    }
    eprintln!("worst point error relative to the distance: {worst:e}");
}

#[test]
fn disk_hits_in_object_space_with_inverse_transpose_normal() {
    // An ellipse of semi-axes 2 (x) and 3 (y) at z = 1, facing +z.
    let m = Mat4::from_translation(Vec3::Z) * Mat4::from_scale(Vec3::new(2.0, 3.0, 1.0));
    let d = one(5, &GeometryDesc::Disk { to_world: m });
    let down = |x: f32, y: f32| Ray::new(Vec3::new(x, y, 5.0), -Vec3::Z);
    let h = d.intersect(&down(1.9, 0.0), 0.0, f32::INFINITY).unwrap();
    assert_eq!(h.t, 4.0);
    assert_close(h.p, Vec3::new(1.9, 0.0, 1.0), 1e-6);
    assert_eq!(h.ng, Vec3::Z);
    assert_eq!(h.ns, Vec3::Z);
    assert_eq!(h.shape, 5);
    assert!(d.intersect(&down(0.0, 2.9), 0.0, f32::INFINITY).is_some());
    assert!(d.intersect(&down(1.9, 1.0), 0.0, f32::INFINITY).is_none()); // 0.9025 + 0.111 > 1
    assert!(d.intersect(&down(0.0, 3.1), 0.0, f32::INFINITY).is_none());
    // From below: same front normal.
    let h = d
        .intersect(
            &Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z),
            0.0,
            f32::INFINITY,
        )
        .unwrap();
    assert_eq!(h.t, 2.0);
    assert_eq!(h.ng, Vec3::Z);
    // Parallel to the disk: no hit, no NaN.
    assert!(
        d.intersect(
            &Ray::new(Vec3::new(-5.0, 0.0, 1.0), Vec3::X),
            0.0,
            f32::INFINITY
        )
        .is_none()
    );

    // A rotated, non-uniformly scaled disk: the normal is perpendicular to the disk's plane
    // and on the side of the image of +z.
    let rot = Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), 1.1);
    let m = Mat4::from_scale_rotation_translation(Vec3::new(2.0, 0.5, 3.0), rot, Vec3::ONE);
    let d = one(0, &GeometryDesc::Disk { to_world: m });
    let target = m.transform_point3(Vec3::new(0.3, -0.4, 0.0));
    let o = target + Vec3::new(0.3, 0.9, -0.2) * 3.0;
    let dir = (target - o).normalize();
    let h = d.intersect(&Ray::new(o, dir), 0.0, f32::INFINITY).unwrap();
    assert_close(h.p, target, 1e-5);
    let (a, b) = (m.transform_vector3(Vec3::X), m.transform_vector3(Vec3::Y));
    assert!(h.ng.dot(a).abs() < 1e-6 && h.ng.dot(b).abs() < 1e-6);
    assert!(h.ng.dot(m.transform_vector3(Vec3::Z)) > 0.0);
    assert!((h.ng.length() - 1.0).abs() < 1e-6);
}

/// A triangle reaching `s` from the origin in the plane `y = 0`, facing `+y`, containing the
/// origin.
fn ground(s: f32) -> GeometryDesc {
    mesh(
        vec![
            Vec3::new(-s, 0.0, s),
            Vec3::new(s, 0.0, s),
            Vec3::new(0.0, 0.0, -s),
        ],
        vec![[0, 1, 2]],
    )
}

/// Issue 10: a triangle with coordinates of 1e10 was dropped as degenerate (the squared length
/// of its cross product overflowed f32), so it was invisible. Up to the loader's coordinate
/// limit (1e18) a huge ground plane is now hit where the ray meets it, looking down, obliquely
/// and at a grazing angle (where the watertight test's `t`, a weighted sum of the vertices'
/// distances, errs by ulps of 1e10), and its area is sampled. Before the fix: no primitive.
#[test]
fn huge_triangles_are_hit_where_the_ray_meets_them() {
    let rays = [
        (Vec3::new(0.3, 2.0, -0.7), -Vec3::Y),
        (
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(-1.0, -2.0, 0.5).normalize(),
        ),
        (
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, -0.01, 1.0).normalize(),
        ),
        (
            Vec3::new(-3.0, 0.5, 2.0),
            Vec3::new(0.7, -0.05, -0.7).normalize(),
        ),
    ];
    for s in [1e5f32, 1e10, 1e15, 1e18] {
        let g = ground(s);
        let prims = primitives(3, &g);
        assert_eq!(prims.len(), 1, "s = {s:e}: the triangle was dropped");
        let bvh = Bvh::build(prims);
        for (o, d) in rays {
            let h = bvh
                .intersect(&Ray::new(o, d), 0.0, f32::INFINITY)
                .unwrap_or_else(|| panic!("s = {s:e}: ray from {o} along {d} misses"));
            let t_exact = -f64::from(o.y) / f64::from(d.y);
            assert_rel(f64::from(h.t), t_exact, 1e-6);
            let p_exact = o.as_dvec3() + d.as_dvec3() * t_exact;
            let err = (h.p.as_dvec3() - p_exact).abs().max_element();
            assert!(
                err <= 1e-6 * (1.0 + t_exact),
                "s = {s:e}: point {} off by {err}",
                h.p
            );
            assert_eq!((h.ng, h.ns, h.shape), (Vec3::Y, Vec3::Y, 3));
            // And from below, the same plane with its front normal.
            let below = Ray::new(o * Vec3::new(1.0, -1.0, 1.0), d * Vec3::new(1.0, -1.0, 1.0));
            let h = bvh
                .intersect(&below, 0.0, f32::INFINITY)
                .expect("hit from below");
            assert_rel(f64::from(h.t), t_exact, 1e-6);
            assert_eq!(h.ng, Vec3::Y);
        }
        let sampler = ShapeSampler::new(&g);
        assert_rel(f64::from(sampler.area()), 2.0 * f64::from(s).powi(2), 1e-6);
        let from = Vec3::new(0.0, 1.0, 0.0);
        let sample = sampler
            .sample_direction(from, Vec2::new(0.3, 0.6))
            .expect("a sample");
        assert_eq!((sample.p.y, sample.n), (0.0, Vec3::Y));
        assert!(sample.pdf.is_finite() && sample.pdf > 0.0, "{sample:?}");
    }
}

/// Triangles too small for the plain cross product (its squared length underflows below edges
/// of about 1e-10) are kept and hit as well.
#[test]
fn tiny_triangles_are_hit() {
    let s = 1e-12f32;
    let prims = primitives(0, &ground(s));
    assert_eq!(prims.len(), 1);
    let h = prims[0]
        .intersect(
            &Ray::new(Vec3::new(0.0, 1.0, 0.0), -Vec3::Y),
            0.0,
            f32::INFINITY,
        )
        .expect("hit");
    assert_eq!((h.t, h.ng), (1.0, Vec3::Y));
}

#[test]
fn degenerate_geometry_yields_nothing_and_samples_nothing() {
    let flat = mesh(
        vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::X * 2.0,
            Vec3::new(f32::NAN, 0.0, 0.0),
        ],
        vec![[0, 1, 2], [0, 1, 3], [0, 1, 9]],
    );
    let zero = GeometryDesc::Sphere {
        center: Vec3::ZERO,
        radius: 0.0,
    };
    let singular = GeometryDesc::Disk {
        to_world: Mat4::from_scale(Vec3::new(1.0, 0.0, 1.0)),
    };
    for g in [flat, zero, singular] {
        assert!(primitives(0, &g).is_empty(), "{g:?}");
        let s = ShapeSampler::new(&g);
        assert_eq!(s.area(), 0.0);
        assert!(s.sample_direction(Vec3::Z, Vec2::splat(0.5)).is_none());
        assert_eq!(s.pdf_direction(Vec3::Z, Vec3::ZERO, Vec3::Z), 0.0);
    }
}

// ---------------------------------------------------------------------------------------------
// BVH

fn random_scene(seed: u64, n_tris: usize, n_spheres: usize, n_disks: usize) -> Vec<Primitive> {
    let mut r = rng(seed);
    let mut prims = Vec::new();
    let mut shape = 0;
    // Triangle soup, in a few meshes so shape indices vary.
    for chunk in 0..4 {
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for _ in 0..n_tris / 4 {
            let c = rand_vec(&mut r, -5.0, 5.0);
            let s = uni(&mut r, 0.05, 1.5);
            let b = positions.len() as u32;
            for _ in 0..3 {
                positions.push(c + rand_vec(&mut r, -s, s));
            }
            indices.push([b, b + 1, b + 2]);
        }
        // Some axis-aligned quads on integer planes (flat boxes, shared edges).
        for k in 0..8 {
            let z = (k as f32) - 4.0 + chunk as f32 * 0.25;
            let b = positions.len() as u32;
            positions.extend([
                Vec3::new(-2.0, -2.0, z),
                Vec3::new(2.0, -2.0, z),
                Vec3::new(2.0, 2.0, z),
                Vec3::new(-2.0, 2.0, z),
            ]);
            indices.push([b, b + 1, b + 2]);
            indices.push([b, b + 2, b + 3]);
        }
        prims.extend(primitives(shape, &mesh(positions, indices)));
        shape += 1;
    }
    for _ in 0..n_spheres {
        let g = GeometryDesc::Sphere {
            center: rand_vec(&mut r, -5.0, 5.0),
            radius: uni(&mut r, 0.05, 1.0),
        };
        prims.extend(primitives(shape, &g));
        shape += 1;
    }
    for _ in 0..n_disks {
        let rot = Quat::from_axis_angle(rand_dir(&mut r), uni(&mut r, 0.0, 6.0));
        let scale = Vec3::new(uni(&mut r, 0.2, 1.5), uni(&mut r, 0.2, 1.5), 1.0);
        let mut m = Mat4::from_scale_rotation_translation(scale, rot, rand_vec(&mut r, -5.0, 5.0));
        if r.random::<f32>() < 0.5 {
            // Axis-aligned (flat bounding box).
            m = Mat4::from_translation(rand_vec(&mut r, -5.0, 5.0))
                * Mat4::from_scale(Vec3::new(scale.x, scale.y, 1.0));
        }
        prims.extend(primitives(shape, &GeometryDesc::Disk { to_world: m }));
        shape += 1;
    }
    prims
}

/// Rays of several kinds: random, axis-aligned with ±0 components and origins on the planes
/// of primitive bounds, and pointing at primitive vertices.
fn random_rays(seed: u64, n: usize, prims: &[Primitive]) -> Vec<(Ray, f32, f32)> {
    let mut r = rng(seed);
    let mut rays = Vec::with_capacity(n);
    for i in 0..n {
        let mut o = rand_vec(&mut r, -8.0, 8.0);
        let d = match i % 4 {
            0 | 1 => rand_dir(&mut r),
            2 => {
                // Axis-aligned, other components +0 or −0, origin on bounds planes.
                let axis = r.random_range(0..3usize);
                let mut d = [0.0f32; 3];
                for (k, c) in d.iter_mut().enumerate() {
                    *c = if k == axis {
                        if r.random::<bool>() { 1.0 } else { -1.0 }
                    } else if r.random::<bool>() {
                        0.0
                    } else {
                        -0.0
                    };
                }
                let p = &prims[r.random_range(0..prims.len())];
                let (lo, hi) = p.bounds();
                let mut oa = o.to_array();
                for k in 0..3 {
                    if k != axis && r.random::<f32>() < 0.7 {
                        oa[k] = if r.random::<bool>() { lo[k] } else { hi[k] };
                    }
                }
                o = Vec3::from_array(oa);
                Vec3::from_array(d)
            }
            _ => {
                // Toward a corner of some primitive's bounds or a triangle vertex.
                let p = &prims[r.random_range(0..prims.len())];
                let target = match p {
                    Primitive::Triangle { p, .. } => p[r.random_range(0..3usize)],
                    _ => {
                        let (lo, hi) = p.bounds();
                        lo.lerp(hi, r.random::<f32>())
                    }
                };
                match (target - o).try_normalize() {
                    Some(d) => d,
                    None => Vec3::X,
                }
            }
        };
        let tmin = if r.random::<f32>() < 0.3 {
            uni(&mut r, 0.0, 3.0)
        } else {
            0.0
        };
        let tmax = if r.random::<f32>() < 0.3 {
            uni(&mut r, tmin, 12.0)
        } else {
            f32::INFINITY
        };
        rays.push((Ray::new(o, d), tmin, tmax));
    }
    rays
}

fn check_against_brute_force(prims: Vec<Primitive>, rays: &[(Ray, f32, f32)]) -> usize {
    let bvh = Bvh::build(prims.clone());
    assert_eq!(bvh.len(), prims.len());
    let mut hits = 0;
    for (i, &(ray, tmin, tmax)) in rays.iter().enumerate() {
        let want = brute(&prims, &ray, tmin, tmax);
        let got = bvh.intersect(&ray, tmin, tmax);
        match (want, got) {
            (None, None) => {}
            (Some(w), Some(g)) => {
                hits += 1;
                assert!(
                    (w.t - g.t).abs() <= 1e-6 * w.t.abs().max(1.0),
                    "ray {i} {ray:?}: t {} vs brute {}",
                    g.t,
                    w.t
                );
                if w.t != g.t || w.shape == g.shape {
                    // Not a tie between primitives: same surface point.
                    assert_close(g.p, w.p, 1e-4 * w.t.max(1.0));
                }
                assert!(g.ng.is_finite() && g.ns.is_finite() && g.p.is_finite());
            }
            (w, g) => panic!("ray {i} {ray:?} [{tmin}, {tmax}]: bvh {g:?}, brute force {w:?}"),
        }
        assert_eq!(
            bvh.occluded(&ray, tmin, tmax),
            want.is_some(),
            "occluded, ray {i} {ray:?} [{tmin}, {tmax}]"
        );
    }
    hits
}

#[test]
fn bvh_agrees_with_brute_force_on_random_scenes() {
    for (seed, tris, spheres, disks) in [(1, 400, 20, 10), (2, 2000, 50, 30), (3, 40, 3, 3)] {
        let prims = random_scene(seed, tris, spheres, disks);
        let rays = random_rays(100 + seed, 6000, &prims);
        let hits = check_against_brute_force(prims, &rays);
        // The scenes are dense enough that a good share of rays hit something.
        assert!(hits > rays.len() / 5, "only {hits} hits");
    }
}

#[test]
fn bvh_agrees_with_brute_force_on_a_lattice_of_cubes_with_axis_rays() {
    // Unit cubes on an integer lattice: every box plane is an integer plane, and axis rays
    // from integer origins run along faces and edges.
    let mut prims = Vec::new();
    let mut shape = 0;
    for x in -2..2 {
        for y in -2..2 {
            for z in -2..2 {
                if (x + y + z) % 2 == 0 {
                    let lo = Vec3::new(x as f32, y as f32, z as f32);
                    prims.extend(primitives(shape, &cube(lo, lo + Vec3::ONE)));
                    shape += 1;
                }
            }
        }
    }
    let mut r = rng(9);
    let mut rays = Vec::new();
    for _ in 0..6000 {
        let mut o = [0.0f32; 3];
        for c in &mut o {
            *c = r.random_range(-4..=4) as f32 * 0.5;
        }
        let axis = r.random_range(0..3usize);
        let mut d = [0.0f32; 3];
        for (k, c) in d.iter_mut().enumerate() {
            *c = if k == axis {
                if r.random::<bool>() { 1.0 } else { -1.0 }
            } else if r.random::<bool>() {
                0.0
            } else {
                -0.0
            };
        }
        let d = if r.random::<f32>() < 0.2 {
            rand_dir(&mut r)
        } else {
            Vec3::from_array(d)
        };
        rays.push((Ray::new(Vec3::from_array(o), d), 0.0, f32::INFINITY));
    }
    let hits = check_against_brute_force(prims, &rays);
    assert!(hits > 1000);
}

#[test]
fn watertight_grid_never_leaks_through_edges_or_vertices() {
    // A 16×16 grid of quads at z = 0.5, each split into two triangles along a diagonal.
    let n = 16u32;
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            positions.push(Vec3::new(i as f32 * 0.25 - 2.0, j as f32 * 0.25 - 2.0, 0.5));
        }
    }
    let mut indices = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let v = j * (n + 1) + i;
            indices.push([v, v + 1, v + n + 2]);
            indices.push([v, v + n + 2, v + n + 1]);
        }
    }
    let prims = primitives(0, &mesh(positions, indices));
    let bvh = Bvh::build(prims);
    let mut r = rng(4);
    for k in 0..20000 {
        // Exactly representable targets on vertices, edges and diagonals.
        let (i, j) = (
            r.random_range(1..n * 2) as f32,
            r.random_range(1..n * 2) as f32,
        );
        let target = Vec3::new(i * 0.125 - 2.0, j * 0.125 - 2.0, 0.5);
        let o = target
            + Vec3::new(uni(&mut r, -1.0, 1.0), uni(&mut r, -1.0, 1.0), 1.0)
                * uni(&mut r, 0.5, 5.0);
        let o = if k % 2 == 0 { o } else { 2.0 * target - o }; // from below too
        let d = (target - o).normalize();
        let ray = Ray::new(o, d);
        let h = bvh.intersect(&ray, 0.0, f32::INFINITY);
        assert!(h.is_some(), "leak at {target:?} from {o:?}");
        assert!(bvh.occluded(&ray, 0.0, f32::INFINITY));
        assert_close(h.unwrap().p, target, 1e-5);
    }
}

#[test]
fn empty_and_single_primitive_bvh() {
    let empty = Bvh::build(Vec::new());
    assert!(empty.is_empty());
    assert_eq!(empty.len(), 0);
    assert!(empty.bounds().is_none());
    let ray = Ray::new(Vec3::ZERO, Vec3::Z);
    assert!(empty.intersect(&ray, 0.0, f32::INFINITY).is_none());
    assert!(!empty.occluded(&ray, 0.0, f32::INFINITY));

    let g = GeometryDesc::Sphere {
        center: Vec3::new(0.0, 0.0, 5.0),
        radius: 1.0,
    };
    let bvh = Bvh::build(primitives(2, &g));
    assert_eq!(bvh.len(), 1);
    assert!(!bvh.is_empty());
    let h = bvh.intersect(&ray, 0.0, f32::INFINITY).unwrap();
    assert_eq!((h.t, h.shape), (4.0, 2));
    assert!(bvh.occluded(&ray, 0.0, f32::INFINITY));
    assert!(!bvh.occluded(&ray, 0.0, 4.0));
    assert!(bvh.intersect(&ray, 0.0, 4.0).is_none());
    assert_eq!(bvh.intersect(&ray, 4.0, 10.0).unwrap().t, 6.0);
    assert!(
        bvh.intersect(&Ray::new(Vec3::ZERO, -Vec3::Z), 0.0, f32::INFINITY)
            .is_none()
    );
}

#[test]
fn bvh_handles_many_coincident_primitives() {
    // All box centres equal (nested triangles, tilted differently, plus exact duplicates and
    // spheres sharing the centre): no SAH split exists, yet leaves must stay small and the
    // answers right.
    let mut prims = Vec::new();
    for k in 0..300u32 {
        let s = 0.5 + (k / 2) as f32 * 0.01; // pairs of duplicates
        let z = if k % 4 < 2 { 0.1 * s } else { -0.1 * s };
        let g = mesh(
            vec![
                Vec3::new(-s, -s, -z),
                Vec3::new(s, -s, -z),
                Vec3::new(0.0, s, z),
            ],
            vec![[0, 1, 2]],
        );
        prims.extend(primitives(k, &g));
    }
    for k in 0..20 {
        let g = GeometryDesc::Sphere {
            center: Vec3::ZERO,
            radius: 0.1 + 0.2 * k as f32,
        };
        prims.extend(primitives(300 + k, &g));
    }
    let rays = random_rays(77, 3000, &prims);
    let hits = check_against_brute_force(prims, &rays);
    assert!(hits > 1000);
}

// ---------------------------------------------------------------------------------------------
// Shape sampling

/// Draws samples toward `g` from `from`, checks pdf consistency and that a ray toward each
/// sample lands on it when nothing of the shape is in front (unless the ray meets the surface
/// at a cosine below `grazing`, where an `f32` direction may slip past); returns (mean of
/// visible/pdf, its standard error, fraction visible).
fn sample_shape_grazing(
    g: &GeometryDesc,
    from: Vec3,
    n: usize,
    seed: u64,
    grazing: f32,
) -> (f64, f64, f64) {
    let sampler = ShapeSampler::new(g);
    let bvh = Bvh::build(primitives(0, g));
    let mut r = rng(seed);
    let (mut sum, mut sum2, mut visible) = (0.0f64, 0.0f64, 0usize);
    for _ in 0..n {
        let Some(s) = sampler.sample_direction(from, rand_u(&mut r)) else {
            continue;
        };
        assert!(s.pdf > 0.0 && s.pdf.is_finite());
        assert!((s.n.length() - 1.0).abs() < 1e-5);
        let back = sampler.pdf_direction(from, s.p, s.n);
        assert!(
            (back - s.pdf).abs() <= 1e-4 * s.pdf,
            "pdf_direction {back} vs sampled {}",
            s.pdf
        );
        let to = s.p - from;
        let dist = to.length();
        let d = to / dist;
        let cos = s.n.dot(-d).abs();
        let hit = bvh.intersect(&Ray::new(from, d), 0.0, dist * 1.01);
        let lands = hit.is_some_and(|h| (h.p - s.p).length() <= 1e-4 * dist.max(1.0));
        if lands {
            visible += 1;
            let w = 1.0 / s.pdf as f64;
            sum += w;
            sum2 += w * w;
        } else if let Some(h) = hit {
            // Something of the shape is in front: then it is strictly nearer.
            assert!(
                h.t < dist * (1.0 - 1e-4) || cos < grazing,
                "hit {h:?} for sample {s:?}"
            );
        } else {
            // Only grazing samples may slip past their own point.
            assert!(
                cos < grazing,
                "ray toward sample {s:?} from {from:?} missed"
            );
        }
    }
    let mean = sum / n as f64;
    let var = (sum2 / n as f64 - mean * mean).max(0.0);
    (mean, (var / n as f64).sqrt(), visible as f64 / n as f64)
}

fn sample_shape(g: &GeometryDesc, from: Vec3, n: usize, seed: u64) -> (f64, f64, f64) {
    sample_shape_grazing(g, from, n, seed, 1e-2)
}

#[test]
fn sphere_cone_sampling_covers_the_visible_solid_angle() {
    let c = Vec3::new(0.5, -1.0, 2.0);
    for (radius, dist) in [(1.0f32, 3.0f32), (0.5, 1.2), (2.0, 50.0), (0.01, 1.0e3)] {
        let g = GeometryDesc::Sphere { center: c, radius };
        let from = c + Vec3::new(0.3, -0.8, 0.52).normalize() * dist;
        // A ray toward a point of a tiny far sphere has a lateral error of about 1e-7 of the
        // distance: it may miss when grazing within that of the rim.
        let grazing = (1e-6 * dist / radius).sqrt().max(1e-2);
        let (mean, _, frac) = sample_shape_grazing(&g, from, 20000, 11, grazing);
        let sin2 = (radius as f64 / dist as f64).powi(2);
        let omc = sin2 / (1.0 + (1.0 - sin2).sqrt());
        let exact = 2.0 * PI * omc;
        // Every cone sample is visible (up to the grazing ones); 1/pdf is the cap's solid angle.
        let min_frac = 1.0 - 1e-3 - (grazing as f64).powi(2);
        assert!(frac > min_frac, "visible fraction {frac}");
        assert_rel(mean, exact * frac, 1e-4);
    }
}

#[test]
fn sphere_cone_sampling_is_uniform_in_the_cone() {
    let c = Vec3::ZERO;
    let g = GeometryDesc::Sphere {
        center: c,
        radius: 1.0,
    };
    let from = Vec3::new(0.0, 2.5, 0.0);
    let sampler = ShapeSampler::new(&g);
    let cos_max = (1.0f64 - 1.0 / 6.25).sqrt();
    let axis = (c - from).normalize();
    let n = 100_000;
    let mut r = rng(12);
    // Fraction of directions within sub-cones of the cone, against the uniform measure.
    for frac_solid in [0.1f64, 0.3, 0.7] {
        let cos1 = 1.0 - frac_solid * (1.0 - cos_max);
        let mut inside = 0usize;
        let mut quadrant = 0usize;
        for _ in 0..n {
            let s = sampler.sample_direction(from, rand_u(&mut r)).unwrap();
            let d = (s.p - from).normalize();
            assert!(s.n.dot(from - s.p) >= -1e-5, "sample on the far side");
            if (d.dot(axis) as f64) >= cos1 {
                inside += 1;
            }
            if d.x > 0.0 && d.z > 0.0 {
                quadrant += 1;
            }
        }
        let p = inside as f64 / n as f64;
        let se = (frac_solid * (1.0 - frac_solid) / n as f64).sqrt();
        assert!((p - frac_solid).abs() < 5.0 * se, "{p} vs {frac_solid}");
        let q = quadrant as f64 / n as f64;
        assert!(
            (q - 0.25).abs() < 5.0 * (0.1875 / n as f64).sqrt(),
            "azimuth {q}"
        );
    }
}

#[test]
fn sphere_area_sampling_from_inside_covers_four_pi() {
    let c = Vec3::new(1.0, 1.0, 1.0);
    let g = GeometryDesc::Sphere {
        center: c,
        radius: 2.0,
    };
    for from in [c, c + Vec3::new(0.5, -1.2, 0.7)] {
        let (mean, se, frac) = sample_shape(&g, from, 50000, 13);
        assert!(frac > 0.999);
        assert!((mean - 4.0 * PI).abs() < 5.0 * se + 1e-4, "{mean} ± {se}");
    }
}

#[test]
fn disk_sampling_matches_the_analytic_solid_angle() {
    // On-axis disk of radius R at height h: Ω = 2π (1 − h / sqrt(h² + R²)).
    let (radius, h) = (0.7f32, 1.5f32);
    let m =
        Mat4::from_translation(Vec3::new(0.2, 0.1, -0.3)) * Mat4::from_scale(Vec3::splat(radius));
    let g = GeometryDesc::Disk { to_world: m };
    let from = Vec3::new(0.2, 0.1, -0.3 + h);
    let (mean, se, frac) = sample_shape(&g, from, 100000, 14);
    let exact = 2.0 * PI * (1.0 - h as f64 / ((h * h + radius * radius) as f64).sqrt());
    assert!(frac > 0.999);
    assert!((mean - exact).abs() < 5.0 * se, "{mean} ± {se} vs {exact}");
    assert!(se < 0.02 * exact);
    // Seen from below (back side): same solid angle.
    let from = Vec3::new(0.2, 0.1, -0.3 - h);
    let (mean, se, _) = sample_shape(&g, from, 100000, 15);
    assert!((mean - exact).abs() < 5.0 * se, "{mean} ± {se} vs {exact}");
    // An ellipse seen off-axis: compare with the area-weighted density integral done by
    // quadrature over the disk.
    let rot = Quat::from_rotation_x(0.4) * Quat::from_rotation_z(0.3);
    let m = Mat4::from_scale_rotation_translation(Vec3::new(0.8, 0.3, 1.0), rot, Vec3::ZERO);
    let g = GeometryDesc::Disk { to_world: m };
    let from = Vec3::new(0.5, 0.4, 1.2);
    let (mean, se, _) = sample_shape(&g, from, 100000, 16);
    let nrm = {
        let a = m.transform_vector3(Vec3::X).as_dvec3();
        let b = m.transform_vector3(Vec3::Y).as_dvec3();
        a.cross(b)
    };
    let k = 400;
    let mut exact = 0.0;
    for i in 0..k {
        for j in 0..k {
            // Midpoint rule over [-1,1]² restricted to the unit disk.
            let x = -1.0 + (i as f64 + 0.5) * 2.0 / k as f64;
            let y = -1.0 + (j as f64 + 0.5) * 2.0 / k as f64;
            if x * x + y * y > 1.0 {
                continue;
            }
            let p = m.as_dmat4().transform_point3(DVec3::new(x, y, 0.0));
            let v = p - from.as_dvec3();
            let d2 = v.length_squared();
            exact += nrm.dot(v).abs() / (d2 * d2.sqrt()) * (4.0 / (k * k) as f64);
        }
    }
    assert!(
        (mean - exact).abs() < 5.0 * se + 2e-3 * exact,
        "{mean} ± {se} vs {exact}"
    );
}

#[test]
fn rectangle_sampling_matches_the_analytic_solid_angle() {
    let m = Mat4::from_scale_rotation_translation(
        Vec3::new(0.4, 0.25, 1.0),
        Quat::from_rotation_y(0.5),
        Vec3::new(0.3, 0.0, 0.1),
    );
    let g = rectangle(m);
    for from in [Vec3::new(0.0, 0.2, 2.0), Vec3::new(1.5, -0.3, -0.4)] {
        let (mean, se, frac) = sample_shape(&g, from, 100000, 17);
        let GeometryDesc::Mesh(mesh) = &g else {
            panic!()
        };
        let p: Vec<DVec3> = mesh.positions.iter().map(|v| v.as_dvec3()).collect();
        let x = from.as_dvec3();
        let exact =
            triangle_solid_angle(x, p[0], p[1], p[2]) + triangle_solid_angle(x, p[0], p[2], p[3]);
        assert!(frac > 0.999);
        assert!((mean - exact).abs() < 5.0 * se, "{mean} ± {se} vs {exact}");
        assert!(se < 0.02 * exact);
    }
}

#[test]
fn cube_sampling_counts_only_the_visible_faces() {
    let g = cube(Vec3::new(-0.5, -0.3, 0.0), Vec3::new(0.5, 0.3, 0.8));
    let sampler = ShapeSampler::new(&g);
    assert!((sampler.area() - 2.0 * (0.6 + 0.8 * 0.6 + 0.8)).abs() < 1e-5);
    for from in [
        Vec3::new(1.5, 1.1, 2.0),
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(-2.0, 0.1, 0.4),
    ] {
        let (mean, se, frac) = sample_shape(&g, from, 100000, 18);
        let exact = visible_mesh_solid_angle(from, &g);
        assert!(frac > 0.1 && frac < 0.9, "visible fraction {frac}");
        assert!(
            (mean - exact).abs() < 5.0 * se,
            "{mean} ± {se} vs {exact} from {from:?}"
        );
    }
}

#[test]
fn mesh_sampling_picks_triangles_by_area() {
    // Two triangles of areas 1 and 3 in the plane z = 0: the share of samples in each.
    let g = mesh(
        vec![
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(13.0, 0.0, 0.0),
            Vec3::new(10.0, 2.0, 0.0),
        ],
        vec![[0, 1, 2], [3, 4, 5]],
    );
    let s = ShapeSampler::new(&g);
    assert_eq!(s.area(), 4.0);
    let from = Vec3::new(5.0, 0.5, 3.0);
    let mut r = rng(19);
    let n = 100_000;
    let mut first = 0;
    for _ in 0..n {
        let x = s.sample_direction(from, rand_u(&mut r)).unwrap();
        assert_eq!(x.n, Vec3::Z);
        assert_eq!(x.p.z, 0.0);
        if x.p.x < 5.0 {
            first += 1;
            assert!(x.p.x >= 0.0 && x.p.y >= 0.0 && x.p.x / 2.0 + x.p.y <= 1.0 + 1e-6);
        }
    }
    let p = first as f64 / n as f64;
    assert!((p - 0.25).abs() < 5.0 * (0.1875 / n as f64).sqrt(), "{p}");
}

#[test]
fn sampling_is_robust_for_grazing_and_coincident_points() {
    let g = GeometryDesc::Disk {
        to_world: Mat4::IDENTITY,
    };
    let s = ShapeSampler::new(&g);
    assert!((s.area() - std::f32::consts::PI).abs() < 1e-6);
    // In the disk's plane: every direction is grazing.
    let mut r = rng(20);
    for _ in 0..1000 {
        assert!(
            s.sample_direction(Vec3::new(3.0, 0.0, 0.0), rand_u(&mut r))
                .is_none()
        );
    }
    assert_eq!(
        s.pdf_direction(Vec3::new(3.0, 0.0, 0.0), Vec3::X * 0.5, Vec3::Z),
        0.0
    );
    // Coincident with the sampled point.
    assert_eq!(s.pdf_direction(Vec3::ZERO, Vec3::ZERO, Vec3::Z), 0.0);
    let c = s.sample_direction(Vec3::ZERO, Vec2::splat(0.5));
    assert!(c.is_none(), "{c:?}");
    // On a sphere's surface, and at huge distance: finite or None, never NaN.
    let sphere = ShapeSampler::new(&GeometryDesc::Sphere {
        center: Vec3::ZERO,
        radius: 1.0,
    });
    for from in [
        Vec3::X,
        Vec3::X * 1.000_001,
        Vec3::new(0.0, 3.0e7, 0.0),
        Vec3::new(1e30, 0.0, 0.0),
    ] {
        for _ in 0..1000 {
            if let Some(x) = sphere.sample_direction(from, rand_u(&mut r)) {
                assert!(x.pdf.is_finite() && x.pdf > 0.0 && x.p.is_finite() && x.n.is_finite());
                assert!(((x.p.length() - 1.0).abs()) < 1e-5);
            }
        }
        let pdf = sphere.pdf_direction(from, Vec3::X, Vec3::X);
        assert!(pdf.is_finite() && pdf >= 0.0);
    }
    // Corner values of the random numbers.
    let m = ShapeSampler::new(&cube(Vec3::ZERO, Vec3::ONE));
    for u in [
        Vec2::ZERO,
        Vec2::new(0.999_999_94, 0.999_999_94),
        Vec2::new(0.0, 0.999_999_94),
    ] {
        let x = m.sample_direction(Vec3::splat(3.0), u).unwrap();
        assert!(x.p.cmpge(Vec3::ZERO).all() && x.p.cmple(Vec3::ONE).all());
    }
}
