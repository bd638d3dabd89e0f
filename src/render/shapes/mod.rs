//! Shapes: rays, the primitives the BVH holds, their intersection tests, and whole-shape
//! sampling for next-event estimation; one file per Mitsuba shape plugin reads its parameters
//! into a [`GeometryDesc`] ([`mesh`] builds the meshes, [`obj_file`] reads OBJ files).
//!
//! Orientation follows [`super::scene`]: a triangle's front is where
//! `(p1 − p0) × (p2 − p0)` points, a sphere's front is its outside and a disk's front is the image
//! of `+z`. [`Hit::ng`] is always the front normal, whichever side the ray came from; the
//! integrator decides which side it is on.
//!
//! Triangles use the watertight test of Woop, Benthin and Wald (JCGT 2013): the per-ray shear
//! is computed once ([`RayPre`]), edge functions that come out exactly zero are recomputed in
//! double precision, so a ray through a shared edge or vertex never slips between triangles.

pub mod cube;
pub mod disk;
pub mod mesh;
pub mod obj;
pub mod obj_file;
pub mod packet;
pub mod rectangle;
pub mod sphere;

use super::sampling::{self, Frame};
use super::scene::{GeometryDesc, MeshDesc};
use glam::{Mat4, Vec2, Vec3};
use std::f32::consts::PI;

/// A ray `o + t·d`; `d` has unit length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Origin.
    pub o: Vec3,
    /// Unit direction.
    pub d: Vec3,
}

impl Ray {
    /// A ray from `o` along the unit vector `d`.
    #[inline]
    pub fn new(o: Vec3, d: Vec3) -> Ray {
        Ray { o, d }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}

/// A ray–surface intersection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter (distance, `d` being unit).
    pub t: f32,
    /// The point on the surface.
    pub p: Vec3,
    /// Unit geometric normal of the shape's front (not flipped toward the ray).
    pub ng: Vec3,
    /// Unit shading normal: interpolated vertex normals where the mesh has them (flipped into
    /// `ng`'s hemisphere when needed), else `ng`.
    pub ns: Vec3,
    /// Index of the shape in the scene.
    pub shape: u32,
    /// Texture coordinates (interpolated on meshes that have them, else `(0, 0)`).
    pub uv: Vec2,
    /// World-space `∂p/∂u` as Mitsuba defines it: from the uv parametrisation on triangles
    /// with texture coordinates ([`uv_tangents`]), else a tangent of `ng`; zero when the hit
    /// was finished without tangents ([`Primitive::finish`]).
    pub dp_du: Vec3,
    /// World-space `∂p/∂v` (likewise).
    pub dp_dv: Vec3,
}

/// Per-ray data shared by every primitive test of one traversal: the origin, the direction
/// and the watertight triangle test's axis permutation and shear.
#[derive(Debug, Clone, Copy)]
pub struct RayPre {
    o: Vec3,
    d: Vec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl RayPre {
    /// Precomputes the shear of `ray` (its direction must not be zero).
    #[inline]
    pub fn new(ray: &Ray) -> RayPre {
        let a = ray.d.abs();
        let kz = if a.x > a.y {
            if a.x > a.z { 0 } else { 2 }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        let d = ray.d.to_array();
        // Keep the winding: swapping x and y when the dominant component is negative.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        RayPre {
            o: ray.o,
            d: ray.d,
            kx,
            ky,
            kz,
            sx: d[kx] / d[kz],
            sy: d[ky] / d[kz],
            sz: 1.0 / d[kz],
        }
    }
}

/// What a primitive test reports before the closest hit is known: the parameter and the data
/// [`Primitive::finish`] needs (unnormalised barycentrics for triangles, object-space `x, y`
/// for disks).
#[derive(Debug, Clone, Copy)]
pub struct RawHit {
    /// Ray parameter.
    pub t: f32,
    a: f32,
    b: f32,
    c: f32,
}

/// A disk's transforms, kept out of line so that [`Primitive`] stays small.
#[derive(Debug, Clone)]
pub struct DiskData {
    to_world: Mat4,
    to_object: Mat4,
    normal: Vec3,
}

/// What a triangle interpolates besides its position.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TriangleAttrs {
    /// Vertex shading normals.
    pub n: Option<[Vec3; 3]>,
    /// Vertex texture coordinates.
    pub uv: Option<[Vec2; 3]>,
}

/// One intersectable primitive; each carries the index of the shape it belongs to.
#[derive(Debug, Clone)]
pub enum Primitive {
    /// A world-space triangle, front counter-clockwise.
    Triangle {
        /// Vertices.
        p: [Vec3; 3],
        /// Vertex shading normals and texture coordinates, if the mesh has them (out of line,
        /// so that a flat untextured triangle stays small).
        attrs: Option<Box<TriangleAttrs>>,
        /// Shape index.
        shape: u32,
    },
    /// A sphere, front outside.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius.
        radius: f32,
        /// Shape index.
        shape: u32,
    },
    /// The unit disk at `z = 0` facing `+z`, mapped by an affine transform.
    Disk {
        /// Transforms and world normal.
        disk: Box<DiskData>,
        /// Shape index.
        shape: u32,
    },
}

/// The primitives of one shape. Degenerate parts (zero-area or non-finite triangles, spheres
/// without a positive radius, disks with a singular transform) are left out.
pub fn primitives(shape: u32, g: &GeometryDesc) -> Vec<Primitive> {
    match g {
        GeometryDesc::Mesh(m) => mesh_triangles(m)
            .map(|(idx, p)| {
                let n = m.normals.as_ref().and_then(|ns| {
                    let get = |i: u32| ns.get(i as usize).copied();
                    Some([get(idx[0])?, get(idx[1])?, get(idx[2])?])
                });
                let uv = m.uvs.as_ref().and_then(|uvs| {
                    let get = |i: u32| uvs.get(i as usize).copied();
                    Some([get(idx[0])?, get(idx[1])?, get(idx[2])?])
                });
                let attrs =
                    (n.is_some() || uv.is_some()).then(|| Box::new(TriangleAttrs { n, uv }));
                Primitive::Triangle { p, attrs, shape }
            })
            .collect(),
        &GeometryDesc::Sphere { center, radius } => {
            if radius > 0.0 && radius.is_finite() && center.is_finite() {
                vec![Primitive::Sphere {
                    center,
                    radius,
                    shape,
                }]
            } else {
                Vec::new()
            }
        }
        GeometryDesc::Disk { to_world } => match disk_data(to_world) {
            Some(d) => vec![Primitive::Disk {
                disk: Box::new(d),
                shape,
            }],
            None => Vec::new(),
        },
    }
}

/// The unit normal of the triangle `p` (along `(p1 − p0) × (p2 − p0)`), or `None` when it is
/// degenerate or not finite.
///
/// The edges are divided by their largest component first: the plain cross product's squared
/// length overflows f32 once edges pass about 1e9, and underflows below about 1e-10, and either
/// made a valid triangle count as degenerate (a 1e10 ground plane silently vanished).
pub fn triangle_normal(p: &[Vec3; 3]) -> Option<Vec3> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let scale = e1.abs().max_element().max(e2.abs().max_element());
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    (e1 / scale).cross(e2 / scale).try_normalize()
}

/// The mesh's valid triangles: indices in range, finite, of non-zero area.
fn mesh_triangles(m: &MeshDesc) -> impl Iterator<Item = ([u32; 3], [Vec3; 3])> + '_ {
    m.indices.iter().filter_map(|&idx| {
        let get = |i: u32| m.positions.get(i as usize).copied();
        let p = [get(idx[0])?, get(idx[1])?, get(idx[2])?];
        (p.iter().all(|v| v.is_finite()) && triangle_normal(&p).is_some()).then_some((idx, p))
    })
}

/// The disk's inverse and front normal, or `None` for a singular or non-finite transform.
fn disk_data(to_world: &Mat4) -> Option<DiskData> {
    if !to_world.is_finite() {
        return None;
    }
    // The unit disk only spans x and y: it is degenerate when their images are parallel.
    let a = to_world.x_axis.truncate();
    let b = to_world.y_axis.truncate();
    let cross = a.cross(b).length_squared();
    let det = to_world.determinant();
    if !(cross > 0.0) || det == 0.0 {
        return None;
    }
    let to_object = to_world.inverse();
    if !to_object.is_finite() {
        return None;
    }
    // Normal: inverse transpose applied to +z, i.e. the third row of the inverse.
    let normal =
        Vec3::new(to_object.x_axis.z, to_object.y_axis.z, to_object.z_axis.z).try_normalize()?;
    Some(DiskData {
        to_world: *to_world,
        to_object,
        normal,
    })
}

impl Primitive {
    /// The shape this primitive belongs to.
    #[inline]
    pub fn shape(&self) -> u32 {
        match *self {
            Primitive::Triangle { shape, .. }
            | Primitive::Sphere { shape, .. }
            | Primitive::Disk { shape, .. } => shape,
        }
    }

    /// Axis-aligned bounds `(min, max)`. Curved and transformed shapes get a small relative
    /// margin so that rounding in their tests never reaches outside the box.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        match self {
            Primitive::Triangle { p, .. } => (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2])),
            &Primitive::Sphere { center, radius, .. } => {
                let e = Vec3::splat(radius) + pad(center, radius);
                (center - e, center + e)
            }
            Primitive::Disk { disk, .. } => {
                let m = &disk.to_world;
                let c = m.w_axis.truncate();
                let (a, b) = (m.x_axis.truncate(), m.y_axis.truncate());
                // Extent of c + x·a + y·b over the unit disk, per axis: sqrt(a_i² + b_i²).
                let half = (a * a + b * b).sqrt();
                let e = half + pad(c, half.max_element());
                (c - e, c + e)
            }
        }
    }

    /// Closest intersection with `t` in `(tmin, tmax)`, with the full hit record.
    pub fn intersect(&self, ray: &Ray, tmin: f32, tmax: f32) -> Option<Hit> {
        let pre = RayPre::new(ray);
        self.intersect_raw(&pre, tmin, tmax)
            .map(|h| self.finish(ray, &h, self.attrs(), true))
    }

    /// A triangle's own attributes, if it still holds them (see [`Primitive::take_attrs`]).
    pub fn attrs(&self) -> Option<&TriangleAttrs> {
        match self {
            Primitive::Triangle { attrs, .. } => attrs.as_deref(),
            _ => None,
        }
    }

    /// Moves a triangle's attributes out, for a container that keeps them in an array of its
    /// own and passes them to [`Primitive::finish`].
    pub fn take_attrs(&mut self) -> Option<TriangleAttrs> {
        match self {
            Primitive::Triangle { attrs, .. } => attrs.take().map(|a| *a),
            _ => None,
        }
    }

    /// The intersection test proper: `t` in `(tmin, tmax)` and what [`Primitive::finish`] needs.
    #[inline]
    pub fn intersect_raw(&self, r: &RayPre, tmin: f32, tmax: f32) -> Option<RawHit> {
        match self {
            Primitive::Triangle { p, .. } => intersect_triangle(p, r, tmin, tmax),
            &Primitive::Sphere { center, radius, .. } => {
                intersect_sphere(center, radius, r.o, r.d, tmin, tmax)
            }
            Primitive::Disk { disk, .. } => intersect_disk(disk, r.o, r.d, tmin, tmax),
        }
    }

    /// The hit record of an intersection this primitive reported for `ray`; `attrs` are a
    /// triangle's attributes, wherever they are kept ([`Primitive::attrs`] if it holds them).
    /// Without `tangents`, `dp_du` and `dp_dv` are left zero.
    pub fn finish(
        &self,
        ray: &Ray,
        h: &RawHit,
        attrs: Option<&TriangleAttrs>,
        tangents: bool,
    ) -> Hit {
        match self {
            Primitive::Triangle { p, shape, .. } => {
                let det = h.a + h.b + h.c;
                let inv = 1.0 / det;
                let (b0, b1, b2) = (h.a * inv, h.b * inv, h.c * inv);
                let mut t = h.t;
                let mut pos = p[0] * b0 + p[1] * b1 + p[2] * b2;
                // Interpolation errs by a few ulps of the vertices, not of the hit: on a
                // triangle much larger than the distance of the hit from the origin (a 1e10
                // ground plane seen from near the origin) that is far off. Intersect its plane
                // in f64 there instead.
                let span = p[0].abs().max(p[1].abs()).max(p[2].abs()).max_element();
                if span > REFINE_SPAN * (1.0 + pos.abs().max_element()) {
                    if let Some((t64, pos64)) = plane_hit(p, ray) {
                        (t, pos) = (t64, pos64);
                    }
                }
                let ng = (p[1] - p[0])
                    .cross(p[2] - p[0])
                    .try_normalize()
                    .or_else(|| triangle_normal(p))
                    .unwrap_or(Vec3::Z);
                let normals = attrs.and_then(|a| a.n.as_ref());
                let uvs = attrs.and_then(|a| a.uv.as_ref());
                let uv = match uvs {
                    Some(uv) => uv[0] * b0 + uv[1] * b1 + uv[2] * b2,
                    None => Vec2::ZERO,
                };
                // Derived here, per hit, rather than stored per triangle: two more vectors for
                // each of a scene's 10^5 triangles would cost more memory than they save time.
                let (dp_du, dp_dv) = tangents_if(tangents, || {
                    uvs.and_then(|uv| uv_tangents(p, uv))
                        .unwrap_or_else(|| tangents_of(ng))
                });
                let ns = match normals {
                    Some(n) => match (n[0] * b0 + n[1] * b1 + n[2] * b2).try_normalize() {
                        Some(s) if s.dot(ng) < 0.0 => -s,
                        Some(s) => s,
                        None => ng,
                    },
                    None => ng,
                };
                Hit {
                    t,
                    p: pos,
                    ng,
                    ns,
                    shape: *shape,
                    uv,
                    dp_du,
                    dp_dv,
                }
            }
            &Primitive::Sphere {
                center,
                radius,
                shape,
            } => {
                // Refine from a point near the surface, where the quadratic is well conditioned
                // (far away, |o − c|² ≫ r² costs a few ulps of t).
                let near = ray.at(h.t) - center;
                let (t, q) = match nearest_root(near, ray.d, radius) {
                    Some(dt) => (h.t + dt, near + ray.d * dt),
                    None => (h.t, near),
                };
                // Project onto the surface: the normal is exact and the point on the sphere.
                let ng = q.try_normalize().unwrap_or(Vec3::Z);
                let (dp_du, dp_dv) = tangents_if(tangents, || tangents_of(ng));
                Hit {
                    t,
                    p: center + ng * radius,
                    ng,
                    ns: ng,
                    shape,
                    uv: Vec2::ZERO,
                    dp_du,
                    dp_dv,
                }
            }
            Primitive::Disk { disk, shape } => {
                let p = disk.to_world.transform_point3(Vec3::new(h.a, h.b, 0.0));
                let (dp_du, dp_dv) = tangents_if(tangents, || tangents_of(disk.normal));
                Hit {
                    t: h.t,
                    p,
                    ng: disk.normal,
                    ns: disk.normal,
                    shape: *shape,
                    uv: Vec2::ZERO,
                    dp_du,
                    dp_dv,
                }
            }
        }
    }
}

/// Mitsuba's `∂p/∂u` and `∂p/∂v` of the triangle `p` with texture coordinates `uv`: the
/// linear map from uv to position that sends the uv edges to the position edges, i.e. with
/// `Δuv₀ = uv₁ − uv₀`, `Δuv₁ = uv₂ − uv₀`, `Δp₀ = p₁ − p₀`, `Δp₁ = p₂ − p₀` and
/// `det = Δu₀Δv₁ − Δv₀Δu₁`:
/// `∂p/∂u = (Δv₁·Δp₀ − Δv₀·Δp₁) / det`, `∂p/∂v = (Δu₀·Δp₁ − Δu₁·Δp₀) / det`.
/// Swapping two vertices negates both numerators and `det`, so the mirrored winding of
/// [`mesh::transform_mesh`] leaves them unchanged. `None` when the uvs are collinear (Mitsuba
/// then keeps the tangents of the normal, as [`tangents_of`]) or the result is not finite.
pub fn uv_tangents(p: &[Vec3; 3], uv: &[Vec2; 3]) -> Option<(Vec3, Vec3)> {
    let (duv0, duv1) = (uv[1] - uv[0], uv[2] - uv[0]);
    let (dp0, dp1) = (p[1] - p[0], p[2] - p[0]);
    let det = duv0.x * duv1.y - duv0.y * duv1.x;
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let dp_du = (dp0 * duv1.y - dp1 * duv0.y) * inv;
    let dp_dv = (dp1 * duv0.x - dp0 * duv1.x) * inv;
    (dp_du.is_finite() && dp_dv.is_finite()).then_some((dp_du, dp_dv))
}

/// `tangents()` if they are wanted, else zero.
#[inline(always)]
fn tangents_if(wanted: bool, tangents: impl FnOnce() -> (Vec3, Vec3)) -> (Vec3, Vec3) {
    if wanted {
        tangents()
    } else {
        (Vec3::ZERO, Vec3::ZERO)
    }
}

/// The two tangents of the unit normal `n`'s coordinate system (Mitsuba's
/// `coordinate_system`, the same construction as [`Frame::new`]): its `dp_du`, `dp_dv` where a
/// shape has no texture coordinates.
#[inline]
fn tangents_of(n: Vec3) -> (Vec3, Vec3) {
    let f = Frame::new(n);
    (f.s, f.t)
}

/// How much larger than a triangle hit's own values (its `t`, its coordinates) the vertices'
/// may be before the hit is recomputed from the triangle's plane in f64. The watertight test's
/// `t` and the interpolated point are weighted sums of the vertices, so they err by ulps of the
/// vertices: on a huge triangle met near its middle (a 1e10 ground plane seen from near the
/// origin) by far more than the values themselves. Past this ratio the error would exceed
/// about 64 ulps (4e-6 relative; the spawn offset is 1e-4 relative). Almost every hit stays on
/// the f32 path: the Cornell box renders bit for bit as before; a ray that meets a wall at a
/// distance below 1/64 of the wall's extent takes the f64 path.
const REFINE_SPAN: f32 = 64.0;

/// The parameter at which the ray `o + t·d` meets the plane of triangle `p`, computed in f64
/// from the f32 inputs, or `None` if the ray is parallel to it.
fn plane_t(p: &[Vec3; 3], o: Vec3, d: Vec3) -> Option<f64> {
    let [a, b, c] = p.map(Vec3::as_dvec3);
    let n = (b - a).cross(c - a);
    let t = n.dot(a - o.as_dvec3()) / n.dot(d.as_dvec3());
    t.is_finite().then_some(t)
}

/// [`plane_t`] and the point there, rounded to f32.
fn plane_hit(p: &[Vec3; 3], ray: &Ray) -> Option<(f32, Vec3)> {
    let t = plane_t(p, ray.o, ray.d)?;
    Some((
        t as f32,
        (ray.o.as_dvec3() + ray.d.as_dvec3() * t).as_vec3(),
    ))
}

/// A bounds margin for shapes whose test is not the box's own arithmetic.
#[inline]
fn pad(center: Vec3, extent: f32) -> Vec3 {
    (center.abs() + Vec3::splat(extent)) * 4e-6
}

/// Watertight ray–triangle test (two-sided).
#[inline]
fn intersect_triangle(p: &[Vec3; 3], r: &RayPre, tmin: f32, tmax: f32) -> Option<RawHit> {
    let a = (p[0] - r.o).to_array();
    let b = (p[1] - r.o).to_array();
    let c = (p[2] - r.o).to_array();
    let (kx, ky, kz) = (r.kx, r.ky, r.kz);
    // Shear so that the ray runs along +z through the origin.
    let ax = a[kx] - r.sx * a[kz];
    let ay = a[ky] - r.sy * a[kz];
    let bx = b[kx] - r.sx * b[kz];
    let by = b[ky] - r.sy * b[kz];
    let cx = c[kx] - r.sx * c[kz];
    let cy = c[ky] - r.sy * c[kz];
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // On an edge in single precision: decide in double so neighbours agree.
        let (ax, ay, bx, by, cx, cy) = (
            ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
        );
        u = (cx * by - cy * bx) as f32;
        v = (ax * cy - ay * cx) as f32;
        w = (bx * ay - by * ax) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let big_t = u * (r.sz * a[kz]) + v * (r.sz * b[kz]) + w * (r.sz * c[kz]);
    let mut t = if big_t.is_finite() {
        big_t / det
    } else {
        // Products of three coordinates overflow past about 1e12: weigh by the normalised
        // barycentrics instead (all of one sign here, so each lies in [0, 1]).
        let inv = 1.0 / det;
        (u * inv) * (r.sz * a[kz]) + (v * inv) * (r.sz * b[kz]) + (w * inv) * (r.sz * c[kz])
    };
    // `t` weighs the vertices' distances along the ray: when they dwarf it (a huge triangle
    // met at a grazing angle), its rounding error does too, and the hit could even land behind
    // the ray. Recompute from the plane then; only hits inside the edges get here.
    let reach = (r.sz * a[kz])
        .abs()
        .max((r.sz * b[kz]).abs())
        .max((r.sz * c[kz]).abs());
    if reach > REFINE_SPAN * t.abs() {
        // Outside the interval beyond doubt, no need to refine: that is the common case, a
        // spawned ray's own triangle just behind its origin, at every bounce.
        let doubt = 8.0 * f32::EPSILON * reach;
        if t + doubt <= tmin || t - doubt >= tmax {
            return None;
        }
        t = plane_t(p, r.o, r.d)? as f32;
    }
    if t > tmin && t < tmax {
        Some(RawHit {
            t,
            a: u,
            b: v,
            c: w,
        })
    } else {
        None
    }
}

/// Ray–sphere test; the nearer root in `(tmin, tmax)`.
///
/// The discriminant is formed from the ray's perpendicular offset to the centre (small relative
/// error even far away), and the two roots as `q` and `c/q` (no cancellation).
#[inline]
fn intersect_sphere(
    center: Vec3,
    radius: f32,
    o: Vec3,
    d: Vec3,
    tmin: f32,
    tmax: f32,
) -> Option<RawHit> {
    let f = o - center;
    let a = d.length_squared();
    let fd = f.dot(d);
    let perp = f - d * (fd / a);
    let r2 = radius * radius;
    let disc = a * (r2 - perp.length_squared());
    if disc < 0.0 {
        return None;
    }
    let c = f.length_squared() - r2;
    let b = -fd;
    let q = b + disc.sqrt().copysign(b);
    if q == 0.0 {
        return None;
    }
    let (t0, t1) = {
        let (x, y) = (c / q, q / a);
        if x <= y { (x, y) } else { (y, x) }
    };
    let t = if t0 > tmin && t0 < tmax {
        t0
    } else if t1 > tmin && t1 < tmax {
        t1
    } else {
        return None;
    };
    Some(RawHit {
        t,
        a: 0.0,
        b: 0.0,
        c: 0.0,
    })
}

/// The root of smaller magnitude of `|f + t·d|² = r²` (`f` the origin relative to the
/// centre), or `None` without real roots.
#[inline]
fn nearest_root(f: Vec3, d: Vec3, radius: f32) -> Option<f32> {
    let a = d.length_squared();
    let fd = f.dot(d);
    let perp = f - d * (fd / a);
    let r2 = radius * radius;
    let disc = a * (r2 - perp.length_squared());
    if !(disc >= 0.0) {
        return None;
    }
    let b = -fd;
    let q = b + disc.sqrt().copysign(b);
    if q == 0.0 {
        return None;
    }
    let (x, y) = ((f.length_squared() - r2) / q, q / a);
    let t = if x.abs() <= y.abs() { x } else { y };
    t.is_finite().then_some(t)
}

/// Ray–disk test in object space (the ray parameter is the same in both spaces).
#[inline]
fn intersect_disk(disk: &DiskData, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Option<RawHit> {
    let oo = disk.to_object.transform_point3(o);
    let od = disk.to_object.transform_vector3(d);
    if od.z == 0.0 {
        return None;
    }
    let t = -oo.z / od.z;
    if !(t > tmin && t < tmax) {
        return None;
    }
    let x = oo.x + t * od.x;
    let y = oo.y + t * od.y;
    if !(x * x + y * y <= 1.0) {
        return None;
    }
    Some(RawHit {
        t,
        a: x,
        b: y,
        c: 0.0,
    })
}

/// A point sampled on a shape for next-event estimation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeSample {
    /// The point.
    pub p: Vec3,
    /// Unit front (geometric) normal there.
    pub n: Vec3,
    /// Density per unit solid angle at the reference point.
    pub pdf: f32,
}

/// Samples points on one whole shape (for next-event estimation toward an area emitter).
#[derive(Debug, Clone)]
pub struct ShapeSampler {
    kind: SamplerKind,
    area: f32,
}

#[derive(Debug, Clone)]
enum SamplerKind {
    /// Triangles chosen by area (`cdf` holds the running sums, the last one the total area).
    Mesh {
        tris: Vec<[Vec3; 3]>,
        normals: Vec<Vec3>,
        cdf: Vec<f32>,
    },
    Sphere {
        center: Vec3,
        radius: f32,
    },
    Disk {
        to_world: Mat4,
        normal: Vec3,
    },
    /// Nothing to sample (degenerate geometry).
    Empty,
}

/// The largest `f32` below one (keeps reused random numbers in `[0, 1)`).
const ONE_MINUS_EPS: f32 = 1.0 - f32::EPSILON / 2.0;

impl ShapeSampler {
    /// A sampler for the whole of `g`.
    pub fn new(g: &GeometryDesc) -> ShapeSampler {
        match g {
            GeometryDesc::Mesh(m) => {
                let mut tris = Vec::new();
                let mut normals = Vec::new();
                let mut cdf = Vec::new();
                let mut sum = 0.0f64;
                for (_, p) in mesh_triangles(m) {
                    let c = (p[1] - p[0]).cross(p[2] - p[0]);
                    let len = c.length();
                    let (len, n) = if len > 0.0 && len.is_finite() {
                        (f64::from(len), c / len)
                    } else {
                        // Too large or small for the f32 length: area in f64, scale-safe normal.
                        let c64 = (p[1] - p[0]).as_dvec3().cross((p[2] - p[0]).as_dvec3());
                        match triangle_normal(&p) {
                            Some(n) if c64.length() > 0.0 => (c64.length(), n),
                            _ => continue,
                        }
                    };
                    sum += 0.5 * len;
                    tris.push(p);
                    normals.push(n);
                    cdf.push(sum as f32);
                }
                let area = sum as f32;
                if tris.is_empty() || !(area > 0.0) || !area.is_finite() {
                    return ShapeSampler::empty();
                }
                ShapeSampler {
                    kind: SamplerKind::Mesh { tris, normals, cdf },
                    area,
                }
            }
            &GeometryDesc::Sphere { center, radius } => {
                let area = 4.0 * PI * radius * radius;
                if !(radius > 0.0) || !area.is_finite() || !center.is_finite() {
                    return ShapeSampler::empty();
                }
                ShapeSampler {
                    kind: SamplerKind::Sphere { center, radius },
                    area,
                }
            }
            GeometryDesc::Disk { to_world } => {
                let Some(d) = disk_data(to_world) else {
                    return ShapeSampler::empty();
                };
                let a = to_world.x_axis.truncate();
                let b = to_world.y_axis.truncate();
                let area = PI * a.cross(b).length();
                if !(area > 0.0) || !area.is_finite() {
                    return ShapeSampler::empty();
                }
                ShapeSampler {
                    kind: SamplerKind::Disk {
                        to_world: *to_world,
                        normal: d.normal,
                    },
                    area,
                }
            }
        }
    }

    fn empty() -> ShapeSampler {
        ShapeSampler {
            kind: SamplerKind::Empty,
            area: 0.0,
        }
    }

    /// Surface area of the shape.
    pub fn area(&self) -> f32 {
        self.area
    }

    /// Samples a point of the shape as seen from `from`: the point, its front normal and the
    /// solid-angle density at `from`. `None` when the density would be zero or not finite
    /// (grazing, degenerate, or `from` on the sampled point).
    pub fn sample_direction(&self, from: Vec3, u: Vec2) -> Option<ShapeSample> {
        let (p, n, pdf) = match &self.kind {
            SamplerKind::Mesh { tris, normals, cdf } => {
                let total = self.area;
                let target = u.x * total;
                let i = cdf.partition_point(|&c| c <= target).min(cdf.len() - 1);
                let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
                let w = cdf[i] - lo;
                let ux = if w > 0.0 {
                    ((target - lo) / w).clamp(0.0, ONE_MINUS_EPS)
                } else {
                    0.5
                };
                let b = sampling::square_to_triangle(Vec2::new(ux, u.y));
                let t = &tris[i];
                let p = t[0] + (t[1] - t[0]) * b.x + (t[2] - t[0]) * b.y;
                let n = normals[i];
                (p, n, area_to_solid_angle(1.0 / total, from, p, n))
            }
            &SamplerKind::Sphere { center, radius } => {
                let w = from - center;
                let dist2 = w.length_squared();
                let r2 = radius * radius;
                if dist2 > r2 {
                    // Uniform in the cone of directions that sees the sphere.
                    let dist = dist2.sqrt();
                    let sin2_max = r2 / dist2;
                    let sin_max = radius / dist;
                    let one_minus_cos_max = one_minus_cos_max(sin2_max);
                    let pdf = cone_pdf(one_minus_cos_max);
                    if pdf == 0.0 {
                        return None;
                    }
                    // 1 − cos θ uniform in [0, 1 − cos θmax].
                    let omc = u.y * one_minus_cos_max;
                    let cos_t = 1.0 - omc;
                    let sin_t = (omc * (2.0 - omc)).max(0.0).sqrt();
                    // The first hit along that direction, as an angle α at the centre between
                    // the axis toward `from` and the point: sin β = sin θ / sin θmax is the
                    // sine of the angle at the point, and α = β − θ.
                    let sin_b = (sin_t / sin_max).min(1.0);
                    let cos_b = (1.0 - sin_b * sin_b).max(0.0).sqrt();
                    let cos_a = sin_b * sin_t + cos_b * cos_t;
                    let sin_a = (sin_b * cos_t - cos_b * sin_t).max(0.0);
                    let axis = w / dist;
                    let frame = Frame::new(axis);
                    let (sin_p, cos_p) = (2.0 * PI * u.x).sin_cos();
                    let e = frame.s * cos_p + frame.t * sin_p;
                    let n = (axis * cos_a + e * sin_a).normalize();
                    (center + n * radius, n, pdf)
                } else {
                    // Inside: uniform on the whole surface.
                    let n = sampling::square_to_uniform_sphere(u);
                    let p = center + n * radius;
                    (p, n, area_to_solid_angle(1.0 / self.area, from, p, n))
                }
            }
            &SamplerKind::Disk { to_world, normal } => {
                let q = sampling::square_to_disk(u);
                let p = to_world.transform_point3(Vec3::new(q.x, q.y, 0.0));
                (
                    p,
                    normal,
                    area_to_solid_angle(1.0 / self.area, from, p, normal),
                )
            }
            SamplerKind::Empty => return None,
        };
        (pdf > 0.0 && pdf.is_finite()).then_some(ShapeSample { p, n, pdf })
    }

    /// The solid-angle density with which [`ShapeSampler::sample_direction`] produces the point
    /// `p` (front normal `n`) of this shape seen from `from`. For a sphere seen from outside,
    /// `p` is taken to be on the visible cap (as the first hit of any ray from `from` is).
    pub fn pdf_direction(&self, from: Vec3, p: Vec3, n: Vec3) -> f32 {
        let pdf = match &self.kind {
            SamplerKind::Mesh { .. } | SamplerKind::Disk { .. } => {
                area_to_solid_angle(1.0 / self.area, from, p, n)
            }
            &SamplerKind::Sphere { center, radius } => {
                let dist2 = (from - center).length_squared();
                let r2 = radius * radius;
                if dist2 > r2 {
                    cone_pdf(one_minus_cos_max(r2 / dist2))
                } else {
                    area_to_solid_angle(1.0 / self.area, from, p, n)
                }
            }
            SamplerKind::Empty => 0.0,
        };
        if pdf.is_finite() { pdf } else { 0.0 }
    }
}

/// `1 − cos θmax` from `sin² θmax`, without cancellation for small cones.
#[inline]
fn one_minus_cos_max(sin2_max: f32) -> f32 {
    let cos_max = (1.0 - sin2_max).max(0.0).sqrt();
    sin2_max / (1.0 + cos_max)
}

/// Density of a uniform cone of the given `1 − cos θmax` (0 when it is not finite).
#[inline]
fn cone_pdf(one_minus_cos_max: f32) -> f32 {
    let pdf = 1.0 / (2.0 * PI * one_minus_cos_max);
    if pdf.is_finite() { pdf } else { 0.0 }
}

/// Converts an area density at `p` (normal `n`) to a solid-angle density at `from`:
/// `pdf_area · dist² / |cos|`, 0 for grazing or coincident points.
#[inline]
fn area_to_solid_angle(pdf_area: f32, from: Vec3, p: Vec3, n: Vec3) -> f32 {
    let d = p - from;
    let dist2 = d.length_squared();
    if !(dist2 > 0.0) {
        return 0.0;
    }
    let cos = n.dot(d).abs() / dist2.sqrt();
    if !(cos > 0.0) {
        return 0.0;
    }
    let pdf = pdf_area * dist2 / cos;
    if pdf.is_finite() { pdf } else { 0.0 }
}
