//! Unidirectional path tracing with next-event estimation, multiple importance sampling
//! (power heuristic) and Russian roulette, following Mitsuba 3's `path` integrator so that the
//! expected value of every pixel is Mitsuba's for the same `max_depth` (Russian roulette and
//! the emitter choice only change variance).
//!
//! Mitsuba's conventions kept here: depth counts path segments, so `max_depth = 1` shows
//! emitters only and `2` adds direct light; next-event estimation runs only at BSDFs with a
//! smooth (non-delta) lobe; an emitter hit after a delta bounce, or seen directly, has MIS weight
//! 1; roulette runs after a bounce once the incremented `depth ≥ rr_depth`, survives with `min(max(β)·η², 0.95)`.

use super::bsdfs::SurfacePoint;
use super::sampler::SampleStream;
use super::sampling::{Frame, power_heuristic};
use super::scene::Rgb;
use super::shapes::{Hit, Ray};
use super::world::World;
use glam::Vec3;

/// Largest survival probability of Russian roulette (Mitsuba's).
const RR_MAX_SURVIVAL: f32 = 0.95;

/// Relative size of the offset that keeps a spawned ray off the surface it leaves.
const RAY_OFFSET: f32 = 1e-4;

/// A ray leaving `hit` in direction `d`, pushed off the surface to the side `d` goes to.
#[inline]
fn spawn(hit: &Hit, d: Vec3) -> Ray {
    let scale = RAY_OFFSET * (1.0 + hit.p.abs().max_element());
    let side = if hit.ng.dot(d) >= 0.0 { scale } else { -scale };
    Ray {
        o: hit.p + hit.ng * side,
        d,
    }
}

/// The shadow ray from `hit` towards the emitter point `dist` away along `wi` (or towards
/// infinity), and how far it may go: it starts off the surface and stops short of the emitter by
/// the same relative margin, so neither end can occlude it.
#[inline]
fn shadow_ray(hit: &Hit, wi: Vec3, dist: f32) -> (Ray, f32) {
    let ray = spawn(hit, wi);
    if !dist.is_finite() {
        return (ray, f32::INFINITY);
    }
    let target = hit.p + wi * dist;
    let to = target - ray.o;
    let len = to.length();
    let margin = RAY_OFFSET * (1.0 + target.abs().max_element());
    let ray = Ray {
        o: ray.o,
        d: to / len,
    };
    (ray, (len - margin).max(0.0))
}

/// What one camera sample saw at its *first non-specular hit*: the first surface along the
/// camera path whose BSDF has a smooth lobe (where next-event estimation runs), after following
/// every surface that has only delta lobes (mirror, smooth glass). These are the per-sample
/// feature values of NFOR (Bitterli et al., EGSR 2016); README "Buffers for denoising" says
/// what each holds, and [`Features::ESCAPED`] what a path without such a hit gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Features {
    /// World-space shading normal at the hit (the interpolated normal, as the BSDF sees it
    /// before any bump map; not flipped toward the ray).
    pub normal: Vec3,
    /// [`super::bsdfs::Bsdf::albedo`] at the hit, textures evaluated.
    pub albedo: Rgb,
    /// Length of the camera path up to the hit: the distance from the camera for a direct hit,
    /// and the unfolded distance through mirrors and glass otherwise (where the reflection
    /// appears to be).
    pub depth: f32,
    /// 1 if the next-event shadow ray at the hit reached the sampled emitter point, 0 if it was
    /// occluded or the emitter sample gave nothing (its back, a degenerate sample). Where the
    /// BSDF is zero toward the light the colour path casts no ray; the feature then casts it
    /// itself, so this is geometric visibility, except that an emitter behind the surface (on
    /// the other side of the geometric normal from the camera path) counts as occluded by the
    /// surface unless the BSDF transmits. 1 where no shadow ray is cast (`max_depth` ends the
    /// path at the hit). Its mean over a pixel's samples is the fraction of unoccluded shadow
    /// rays NFOR asks for.
    pub visibility: f32,
}

impl Features {
    /// A path that escaped, died on a delta surface or hit nothing smooth within `max_depth`:
    /// nothing to describe. Normal and albedo 0 and depth 0 set such pixels apart from any
    /// surface (NFOR only regresses within a window, so a constant is what it needs); visibility
    /// 1, as nothing was seen to occlude.
    pub const ESCAPED: Features = Features {
        normal: Vec3::ZERO,
        albedo: Rgb::ZERO,
        depth: 0.0,
        visibility: 1.0,
    };
}

/// A radiance sample as the estimators take it, or `None` for one they never see: NaN,
/// infinite or negative in a channel (callers count those). Checked on the three `f32` lanes
/// at once; widening to `f64` keeps finiteness and sign.
#[inline]
pub fn pushable(l: Rgb) -> Option<[f64; 3]> {
    (l.is_finite() && l.cmpge(Rgb::ZERO).all()).then(|| [l.x, l.y, l.z].map(f64::from))
}

/// The radiance of one camera sample of pixel `(x, y)`, drawn from `rng`.
#[inline]
pub fn radiance(world: &World, x: u32, y: u32, rng: &mut SampleStream) -> Rgb {
    trace::<false>(world, x, y, rng).0
}

/// The radiance of one camera sample and its [`Features`]. The same path as [`radiance`]: it
/// draws the same random numbers in the same order, so the radiance is bit-identical; the only
/// extra work is a shadow ray where the colour path skips it (a BSDF that is zero toward the
/// light) and the albedo lookup.
pub fn radiance_features(world: &World, x: u32, y: u32, rng: &mut SampleStream) -> (Rgb, Features) {
    trace::<true>(world, x, y, rng)
}

/// The path tracer; with `FEATURES` false every feature statement compiles away.
#[inline(always)]
fn trace<const FEATURES: bool>(
    world: &World,
    x: u32,
    y: u32,
    rng: &mut SampleStream,
) -> (Rgb, Features) {
    let cam = world.camera.ray(x, y, rng.next_2d());
    let (mut ray, mut tmin, mut tmax) = (cam.ray, cam.tmin, cam.tmax);
    let max_depth = world.integrator.max_depth.unwrap_or(u32::MAX);
    let rr_depth = world.integrator.rr_depth;
    let lights = &world.lights;

    let mut result = Rgb::ZERO;
    let mut beta = Rgb::ONE;
    let mut eta = 1.0f32;
    let mut depth = 0u32;
    // The previous vertex, for MIS of emitters hit by BSDF sampling.
    let mut prev_p = ray.o;
    let mut prev_pdf = 1.0f32;
    let mut prev_delta = true;
    // Features: what was found, the path length so far, and whether the found hit still waits
    // for its shadow ray.
    let mut features = Features::ESCAPED;
    let mut found = false;
    let mut travelled = 0.0f32;
    let mut last_vertex = ray.o;
    let mut awaiting_visibility = false;

    loop {
        // Tracing draws no numbers, so next-event estimation's three may be drawn before the
        // ray is traced, with the same stream: where an emitter prefetches, they are, so that
        // it can start loading the table entry its draw will read during the traversal.
        let drawn_ahead = (lights.prefetches() && depth + 1 < max_depth).then(|| {
            let u = (rng.next_1d(), rng.next_2d());
            lights.prefetch(u.0, u.1);
            u
        });
        let Some(hit) = world.bvh.intersect(&ray, tmin, tmax) else {
            if let Some((le, light_pdf)) = lights.environment(ray.d) {
                let w = if prev_delta {
                    1.0
                } else {
                    power_heuristic(prev_pdf, light_pdf)
                };
                result += beta * w * le;
            }
            break;
        };
        if FEATURES && !found {
            // From the previous vertex itself, not the offset origin of the spawned ray.
            travelled += (hit.p - last_vertex).length();
            last_vertex = hit.p;
            let bsdf = &*world.bsdfs[hit.shape as usize];
            if bsdf.has_smooth_lobe() {
                let at = SurfacePoint {
                    uv: hit.uv,
                    frame: Frame::new(hit.ns),
                    ng: hit.ng,
                    dp_du: hit.dp_du,
                    dp_dv: hit.dp_dv,
                };
                let wi = at.frame.to_local(-ray.d);
                features.normal = match bsdf.feature_normal(&at, wi) {
                    Some(n) => at.frame.to_world(n),
                    None => hit.ns,
                };
                features.albedo = bsdf.albedo(&at);
                features.depth = travelled;
                found = true;
                awaiting_visibility = true;
            }
        }
        if let Some(le) = lights.emitted(hit.shape, hit.ng, ray.d) {
            let w = if prev_delta {
                1.0
            } else {
                let pdf = lights.pdf_area_hit(hit.shape, prev_p, hit.p, hit.ng);
                power_heuristic(prev_pdf, pdf)
            };
            result += beta * w * le;
        }
        if depth + 1 >= max_depth {
            break;
        }

        let frame = Frame::new(hit.ns);
        let wi = frame.to_local(-ray.d);
        let bsdf = &*world.bsdfs[hit.shape as usize];
        let at = SurfacePoint {
            uv: hit.uv,
            frame,
            ng: hit.ng,
            dp_du: hit.dp_du,
            dp_dv: hit.dp_dv,
        };

        // Next-event estimation.
        let (u_choice, u_light) = drawn_ahead.unwrap_or_else(|| (rng.next_1d(), rng.next_2d()));
        if bsdf.has_smooth_lobe() {
            let mut visible = false;
            if let Some(ls) = lights.sample(hit.p, u_choice, u_light) {
                let wo = frame.to_local(ls.wi);
                let (f, bsdf_pdf) = bsdf.eval_pdf(&at, wi, wo);
                if f.max_element() > 0.0 {
                    let (shadow, dist) = shadow_ray(&hit, ls.wi, ls.dist);
                    if !world.bvh.occluded(&shadow, 0.0, dist) {
                        visible = true;
                        let (radiance, light_pdf) = lights.resolve(&ls);
                        let w = if ls.delta {
                            1.0
                        } else {
                            power_heuristic(light_pdf, bsdf_pdf)
                        };
                        result += beta * f * radiance * (w / light_pdf);
                    }
                } else if FEATURES && awaiting_visibility {
                    // The surface itself hides an emitter behind it unless light passes.
                    let behind = ls.wi.dot(hit.ng) * ray.d.dot(hit.ng) > 0.0;
                    if !behind || bsdf.transmits() {
                        let (shadow, dist) = shadow_ray(&hit, ls.wi, ls.dist);
                        visible = !world.bvh.occluded(&shadow, 0.0, dist);
                    }
                }
            }
            if FEATURES && awaiting_visibility {
                features.visibility = if visible { 1.0 } else { 0.0 };
                awaiting_visibility = false;
            }
        }

        // BSDF sampling.
        let u_lobe = rng.next_1d();
        let u_dir = rng.next_2d();
        let Some(bs) = bsdf.sample(&at, wi, u_lobe, u_dir) else {
            break;
        };
        let d = frame.to_world(bs.wo).normalize();
        beta *= bs.weight;
        eta *= bs.eta;
        prev_p = hit.p;
        prev_pdf = bs.pdf;
        prev_delta = bs.delta;
        ray = spawn(&hit, d);
        (tmin, tmax) = (0.0, f32::INFINITY);

        depth += 1;
        let beta_max = beta.max_element();
        if !(beta_max > 0.0) {
            break;
        }
        if depth >= rr_depth {
            let q = (beta_max * eta * eta).min(RR_MAX_SURVIVAL);
            if rng.next_1d() >= q {
                break;
            }
            beta /= q;
        }
    }
    (result, features)
}
