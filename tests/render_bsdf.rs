//! Tests of the BSDFs in `src/render/bsdfs/`: sampling against densities (chi-square goodness of fit),
//! estimator consistency (`weight = eval / pdf`), normalisation, reciprocity, energy, the
//! dielectric's Fresnel/Snell behaviour, one- and two-sidedness, and robustness on degenerate
//! inputs.
//!
//! All randomness comes from fixed seeds, so every run is the same run; the significance levels
//! below describe how often a *correct* implementation would fail for a random choice of seeds.

use fireflies::render::bsdfs::conductor::Conductor;
use fireflies::render::bsdfs::dielectric::Dielectric;
use fireflies::render::bsdfs::diffuse::Diffuse;
use fireflies::render::bsdfs::fresnel::fresnel_dielectric;
use fireflies::render::bsdfs::microfacet::MIN_ALPHA;
use fireflies::render::bsdfs::roughconductor::RoughConductor;
use fireflies::render::bsdfs::twosided::TwoSided;
use fireflies::render::bsdfs::{self, BsdfSample, SurfacePoint};
use fireflies::render::scene::Rgb;
use fireflies::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::f64::consts::PI;
use std::sync::Arc;

// ---------------------------------------------------------------------------------------------
// Fixtures
// ---------------------------------------------------------------------------------------------

/// GGX roughnesses under test: from a near-mirror lobe to the roughest physically common value.
const ALPHAS: [f32; 4] = [0.05, 0.2, 0.5, 1.0];

/// Incidence angles (degrees from the normal): normal, oblique and grazing.
const INCIDENCES_DEG: [f32; 3] = [0.0, 45.0, 80.0];

/// Azimuth of the incident direction: deliberately off the axes.
const WI_AZIMUTH: f32 = 0.7;

fn rng(seed: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(seed)
}

fn u2(r: &mut Xoshiro256PlusPlus) -> Vec2 {
    Vec2::new(r.random::<f32>(), r.random::<f32>())
}

/// Unit direction at polar angle `theta_deg` from `+z` and azimuth [`WI_AZIMUTH`].
fn incident(theta_deg: f32) -> Vec3 {
    let t = theta_deg.to_radians();
    Vec3::new(
        t.sin() * WI_AZIMUTH.cos(),
        t.sin() * WI_AZIMUTH.sin(),
        t.cos(),
    )
}

/// Uniformly distributed unit vector.
fn uniform_dir(r: &mut Xoshiro256PlusPlus) -> Vec3 {
    let z = 1.0 - 2.0 * r.random::<f32>();
    let s = (1.0 - z * z).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * r.random::<f32>();
    Vec3::new(s * phi.cos(), s * phi.sin(), z)
}

fn flip(v: Vec3) -> Vec3 {
    Vec3::new(v.x, v.y, -v.z)
}

/// The BSDFs under test, described by their parameters (a test-side description, so that the
/// tests read as before the plugins got one file each).
#[derive(Debug, Clone)]
enum BsdfDesc {
    Diffuse {
        reflectance: Rgb,
    },
    RoughConductor {
        alpha: f32,
        specular_reflectance: Rgb,
    },
    Conductor {
        specular_reflectance: Rgb,
    },
    Dielectric {
        int_ior: f32,
        ext_ior: f32,
        specular_reflectance: Rgb,
        specular_transmittance: Rgb,
    },
    TwoSided(Box<BsdfDesc>),
}

/// A BSDF evaluated at a surface point without texture coordinates.
#[derive(Debug, Clone)]
struct Bsdf(Arc<dyn bsdfs::Bsdf>);

impl Bsdf {
    fn from_desc(d: &BsdfDesc) -> Bsdf {
        Bsdf(match d {
            BsdfDesc::Diffuse { reflectance } => Arc::new(Diffuse::new(*reflectance)),
            BsdfDesc::RoughConductor {
                alpha,
                specular_reflectance,
            } => Arc::new(RoughConductor::new(*alpha, *specular_reflectance)),
            BsdfDesc::Conductor {
                specular_reflectance,
            } => Arc::new(Conductor::mirror(*specular_reflectance)),
            BsdfDesc::Dielectric {
                int_ior,
                ext_ior,
                specular_reflectance,
                specular_transmittance,
            } => Arc::new(Dielectric {
                eta: int_ior / ext_ior,
                specular_reflectance: Spectrum::Constant(*specular_reflectance),
                specular_transmittance: Spectrum::Constant(*specular_transmittance),
            }),
            BsdfDesc::TwoSided(inner) => Arc::new(TwoSided(Bsdf::from_desc(inner).0)),
        })
    }

    fn has_smooth_lobe(&self) -> bool {
        self.0.has_smooth_lobe()
    }

    fn eval_pdf(&self, wi: Vec3, wo: Vec3) -> (Rgb, f32) {
        self.0.eval_pdf(&SurfacePoint::default(), wi, wo)
    }

    fn eval(&self, wi: Vec3, wo: Vec3) -> Rgb {
        self.eval_pdf(wi, wo).0
    }

    fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        self.eval_pdf(wi, wo).1
    }

    fn sample(&self, wi: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        self.0.sample(&SurfacePoint::default(), wi, u_lobe, u)
    }
}

fn diffuse(r: f32) -> Bsdf {
    Bsdf::from_desc(&BsdfDesc::Diffuse {
        reflectance: Rgb::splat(r),
    })
}

fn rough(alpha: f32) -> Bsdf {
    Bsdf::from_desc(&BsdfDesc::RoughConductor {
        alpha,
        specular_reflectance: Rgb::ONE,
    })
}

fn conductor() -> Bsdf {
    Bsdf::from_desc(&BsdfDesc::Conductor {
        specular_reflectance: Rgb::new(0.9, 0.8, 0.7),
    })
}

fn glass(int_ior: f32, ext_ior: f32) -> Bsdf {
    Bsdf::from_desc(&BsdfDesc::Dielectric {
        int_ior,
        ext_ior,
        specular_reflectance: Rgb::ONE,
        specular_transmittance: Rgb::ONE,
    })
}

fn twosided(inner: BsdfDesc) -> Bsdf {
    Bsdf::from_desc(&BsdfDesc::TwoSided(Box::new(inner)))
}

fn rel_close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + 1e-30
}

fn rgb_close(a: Rgb, b: Rgb, rel: f32) -> bool {
    (0..3).all(|i| rel_close(a[i], b[i], rel))
}

// ---------------------------------------------------------------------------------------------
// Quadrature over the sphere on a grid adapted to the lobe
// ---------------------------------------------------------------------------------------------

/// Polar bands of the chi-square grid.
const THETA_BINS: usize = 20;
/// Azimuthal sectors of the chi-square grid.
const PHI_BINS: usize = 40;
/// Pilot samples that place the grid edges (independent of the tested samples).
const PILOT_SAMPLES: usize = 100_000;

/// 5-point Gauss–Legendre nodes and weights on [−1, 1].
const GL5: [(f64, f64); 5] = [
    (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.0, 0.568_888_888_888_888_9),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.906_179_845_938_664, 0.236_926_885_056_189_1),
];

/// A partition of the sphere into cells `[θ_k, θ_k+1] × [φ_j, φ_j+1]` whose interior edges are
/// marginal quantiles of pilot samples, so that narrow lobes get fine cells where their mass is.
/// The horizon `θ = π/2` is always an edge: the densities under test are discontinuous there,
/// and Gauss–Legendre quadrature is only accurate on cells where the integrand is smooth.
struct Grid {
    theta: Vec<f64>,
    phi: Vec<f64>,
}

fn spherical(w: Vec3) -> (f64, f64) {
    let theta = (w.z as f64).clamp(-1.0, 1.0).acos();
    let phi = (w.y as f64).atan2(w.x as f64).rem_euclid(2.0 * PI);
    (theta, phi)
}

/// Interior quantile edges of `v` (sorted in place) merged with the fixed edges.
fn edges(v: &mut [f64], bins: usize, fixed: &[f64]) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    let mut e: Vec<f64> = fixed.to_vec();
    for k in 1..bins {
        e.push(v[k * v.len() / bins]);
    }
    e.sort_by(f64::total_cmp);
    e.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    e
}

impl Grid {
    fn adapted(pilot: &[Vec3]) -> Grid {
        assert!(
            pilot.len() >= 1000,
            "too few pilot samples: {}",
            pilot.len()
        );
        let (mut th, mut ph): (Vec<f64>, Vec<f64>) = pilot.iter().map(|&w| spherical(w)).unzip();
        Grid {
            theta: edges(&mut th, THETA_BINS, &[0.0, PI / 2.0, PI]),
            phi: edges(&mut ph, PHI_BINS, &[0.0, 2.0 * PI]),
        }
    }

    /// A grid adapted to the directions `sample` produces for pilot seed `seed`.
    fn for_sampler(sample: &dyn Fn(f32, Vec2) -> Option<Vec3>, seed: u64) -> Grid {
        let mut r = rng(seed);
        let pilot: Vec<Vec3> = (0..PILOT_SAMPLES)
            .filter_map(|_| {
                let ul = r.random::<f32>();
                sample(ul, u2(&mut r))
            })
            .collect();
        Grid::adapted(&pilot)
    }

    fn cells(&self) -> usize {
        (self.theta.len() - 1) * (self.phi.len() - 1)
    }

    fn cell_of(&self, w: Vec3) -> usize {
        let (t, p) = spherical(w);
        let find = |e: &[f64], x: f64| e.partition_point(|&b| b <= x).clamp(1, e.len() - 1) - 1;
        find(&self.theta, t) * (self.phi.len() - 1) + find(&self.phi, p)
    }

    /// `∫ f dω` over every cell (`dω = sin θ dθ dφ`), each by adaptive Gauss–Legendre cubature.
    fn integrate(&self, f: &dyn Fn(Vec3) -> f64) -> Vec<f64> {
        let integrand = |t: f64, p: f64| {
            let (st, ct) = t.sin_cos();
            let (sp, cp) = p.sin_cos();
            f(Vec3::new((st * cp) as f32, (st * sp) as f32, ct as f32)) * st
        };
        let mut out = Vec::with_capacity(self.cells());
        for band in self.theta.windows(2) {
            for sector in self.phi.windows(2) {
                out.push(adaptive_cubature(
                    &integrand,
                    [band[0], band[1], sector[0], sector[1]],
                    0,
                ));
            }
        }
        out
    }
}

/// 5×5 Gauss–Legendre cubature of `g(x, y)` over the rectangle `[x0, x1] × [y0, y1]`.
fn gl_rect(g: &dyn Fn(f64, f64) -> f64, [x0, x1, y0, y1]: [f64; 4]) -> f64 {
    let (hx, hy) = (0.5 * (x1 - x0), 0.5 * (y1 - y0));
    let (mx, my) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let mut sum = 0.0;
    for (xi, wx) in GL5 {
        for (yi, wy) in GL5 {
            sum += wx * wy * g(mx + hx * xi, my + hy * yi);
        }
    }
    sum * hx * hy
}

/// Relative accuracy asked of each cell's integral (well above the ~1e-7 noise of f32
/// evaluations, which would otherwise force refinement to the maximum depth).
const QUAD_REL_TOL: f64 = 1e-5;
/// Absolute accuracy (probability mass) below which a rectangle is not refined further.
const QUAD_ABS_TOL: f64 = 1e-10;
/// Deepest quadrant refinement (rectangles shrink by up to 2¹⁰ per side).
const QUAD_MAX_DEPTH: u32 = 10;

/// Integral of `g` over `rect`, refining into quadrants until one level and the next agree.
/// The lobes under test are smooth inside each cell (the horizon is a cell edge) but vary over
/// many orders of magnitude in the wide cells of their tails, where a fixed rule fails.
fn adaptive_cubature(g: &dyn Fn(f64, f64) -> f64, rect: [f64; 4], depth: u32) -> f64 {
    let [x0, x1, y0, y1] = rect;
    let (xm, ym) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let quads = [
        [x0, xm, y0, ym],
        [xm, x1, y0, ym],
        [x0, xm, ym, y1],
        [xm, x1, ym, y1],
    ];
    let coarse = gl_rect(g, rect);
    let fine: f64 = quads.iter().map(|&q| gl_rect(g, q)).sum();
    if depth >= QUAD_MAX_DEPTH
        || (coarse - fine).abs() <= (QUAD_REL_TOL * fine.abs()).max(QUAD_ABS_TOL)
    {
        return fine;
    }
    quads
        .iter()
        .map(|&q| adaptive_cubature(g, q, depth + 1))
        .sum()
}

// ---------------------------------------------------------------------------------------------
// Chi-square goodness of fit
// ---------------------------------------------------------------------------------------------

/// Samples per chi-square test.
const CHI2_SAMPLES: usize = 1_000_000;

/// Cells expecting fewer samples than this are pooled (the chi-square approximation of the
/// Pearson statistic needs expected counts of about 5 or more).
const MIN_EXPECTED: f64 = 5.0;

/// Number of chi-square tests that a correct implementation must pass: diffuse and every GGX
/// roughness at every incidence, plus the two back-side `twosided` cases.
const CHI2_FAMILY_SIZE: usize = INCIDENCES_DEG.len() * (1 + ALPHAS.len()) + 2;

/// Family-wise significance: the probability that a *correct* BSDF fails at least one of the
/// [`CHI2_FAMILY_SIZE`] chi-square tests of this file, for a random choice of seeds, is 1%.
/// Each test runs at the Šidák level `1 − (1 − 0.01)^(1/17) ≈ 5.9e-4`.
///
/// What that buys (normal approximation to the non-central chi-square, ~800 cells, so about
/// 800 degrees of freedom and a critical value near 930): a defect is caught with 90%
/// probability once the non-centrality `N · Σ (p_cell − q_cell)² / q_cell` exceeds about 190,
/// i.e. with `N = 10⁶` samples a chi-square distance of ~1.9e-4 between the sampled and the
/// claimed cell probabilities. That is a density error of about ±1.4% spread over the whole
/// lobe, or about ±4.4% confined to a tenth of its mass. The deliberately wrong densities below
/// (10% scale, 10% roughness shift) are far beyond that and must fail.
const CHI2_FAMILY_ALPHA: f64 = 0.01;

fn chi2_level() -> f64 {
    1.0 - (1.0 - CHI2_FAMILY_ALPHA).powf(1.0 / CHI2_FAMILY_SIZE as f64)
}

#[derive(Debug)]
#[allow(dead_code)] // `statistic` and `dof` are read through `Debug` in failure messages.
struct Chi2 {
    statistic: f64,
    dof: usize,
    p_value: f64,
    /// Samples `sample` rejected (`None`), and how many the density implies.
    rejected: (u64, f64),
}

/// Pearson's chi-square test of `sample` (given `u_lobe` and `u`) against the solid-angle
/// density `pdf`. The grid is placed with pilot samples from seed `seed + 1`; the counted samples
/// use `seed`. Rejected samples form their own bin, whose expected probability is the mass the
/// density leaves outside the sphere (`1 − ∫ pdf`).
fn chi2_gof(
    sample: &dyn Fn(f32, Vec2) -> Option<Vec3>,
    pdf: &dyn Fn(Vec3) -> f64,
    seed: u64,
) -> Chi2 {
    let grid = Grid::for_sampler(sample, seed.wrapping_add(1));
    let mut observed = vec![0u64; grid.cells() + 1];
    let mut r = rng(seed);
    for _ in 0..CHI2_SAMPLES {
        let ul = r.random::<f32>();
        match sample(ul, u2(&mut r)) {
            Some(w) => observed[grid.cell_of(w)] += 1,
            None => observed[grid.cells()] += 1,
        }
    }
    let n = CHI2_SAMPLES as f64;
    let mass = grid.integrate(pdf);
    let total: f64 = mass.iter().sum();
    let mut expected: Vec<f64> = mass.iter().map(|m| m * n).collect();
    expected.push(((1.0 - total) * n).max(0.0));
    let rejected = (observed[grid.cells()], expected[grid.cells()]);

    // Pool the sparse bins.
    let mut kept: Vec<(f64, f64)> = Vec::new();
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    for (&o, &e) in observed.iter().zip(&expected) {
        if e < MIN_EXPECTED {
            pool_o += o as f64;
            pool_e += e;
        } else {
            kept.push((o as f64, e));
        }
    }
    if pool_o > 0.0 || pool_e > 0.0 {
        if pool_e >= MIN_EXPECTED || kept.is_empty() {
            kept.push((pool_o, pool_e));
        } else {
            let i = (0..kept.len())
                .min_by(|&a, &b| kept[a].1.total_cmp(&kept[b].1))
                .unwrap();
            kept[i].0 += pool_o;
            kept[i].1 += pool_e;
        }
    }
    assert!(kept.len() >= 2, "grid degenerate: {} bins", kept.len());
    let statistic: f64 = kept
        .iter()
        .map(|&(o, e)| {
            if e > 0.0 {
                (o - e) * (o - e) / e
            } else if o > 0.0 {
                f64::INFINITY
            } else {
                0.0
            }
        })
        .sum();
    let dof = kept.len() - 1;
    let p_value = ChiSquared::new(dof as f64).unwrap().sf(statistic);
    Chi2 {
        statistic,
        dof,
        p_value,
        rejected,
    }
}

fn assert_chi2_passes(name: &str, c: &Chi2) {
    eprintln!("{name}: {c:?}");
    assert!(
        c.p_value >= chi2_level(),
        "{name}: chi-square rejects the sampler against its pdf: {c:?} (level {:.2e})",
        chi2_level()
    );
}

fn assert_chi2_fails(name: &str, c: &Chi2) {
    eprintln!("{name} (must fail): {c:?}");
    assert!(
        c.p_value < chi2_level(),
        "{name}: chi-square failed to detect a wrong pdf: {c:?}"
    );
}

/// Chi-square of `bsdf.sample(wi, ..)` against `bsdf.pdf(wi, ..)`.
fn chi2_bsdf(bsdf: &Bsdf, wi: Vec3, seed: u64) -> Chi2 {
    chi2_gof(
        &|ul, u| bsdf.sample(wi, ul, u).map(|s| s.wo),
        &|wo| bsdf.pdf(wi, wo) as f64,
        seed,
    )
}

#[test]
fn chi2_family_size_matches_the_tests() {
    // Diffuse: one per incidence; GGX: one per (alpha, incidence); two twosided back cases.
    assert_eq!(CHI2_FAMILY_SIZE, 17);
    assert!((chi2_level() - 5.9e-4).abs() < 0.05e-4);
}

#[test]
fn chi2_diffuse() {
    let b = diffuse(0.5);
    for (k, &deg) in INCIDENCES_DEG.iter().enumerate() {
        let c = chi2_bsdf(&b, incident(deg), 100 + 2 * k as u64);
        assert_chi2_passes(&format!("diffuse θi={deg}°"), &c);
        assert_eq!(c.rejected.0, 0);
    }
}

fn chi2_rough_all_incidences(ai: usize) {
    let alpha = ALPHAS[ai];
    let b = rough(alpha);
    for (k, &deg) in INCIDENCES_DEG.iter().enumerate() {
        let c = chi2_bsdf(&b, incident(deg), 1000 + 100 * ai as u64 + 2 * k as u64);
        assert_chi2_passes(&format!("roughconductor α={alpha} θi={deg}°"), &c);
    }
}

#[test]
fn chi2_roughconductor_alpha_0_05() {
    chi2_rough_all_incidences(0);
}

#[test]
fn chi2_roughconductor_alpha_0_2() {
    chi2_rough_all_incidences(1);
}

#[test]
fn chi2_roughconductor_alpha_0_5() {
    chi2_rough_all_incidences(2);
}

#[test]
fn chi2_roughconductor_alpha_1() {
    chi2_rough_all_incidences(3);
}

#[test]
fn chi2_twosided_from_the_back() {
    let wi = flip(incident(45.0));
    let d = twosided(BsdfDesc::Diffuse {
        reflectance: Rgb::splat(0.5),
    });
    assert_chi2_passes("twosided diffuse, back", &chi2_bsdf(&d, wi, 3000));
    let g = twosided(BsdfDesc::RoughConductor {
        alpha: 0.3,
        specular_reflectance: Rgb::ONE,
    });
    assert_chi2_passes(
        "twosided roughconductor α=0.3, back",
        &chi2_bsdf(&g, wi, 3002),
    );
}

/// The same test must reject densities that are wrong by amounts a real bug could produce.
#[test]
fn chi2_rejects_wrong_pdfs() {
    let wi = incident(45.0);
    // Diffuse density scaled by 1.1 (a normalisation bug).
    let d = diffuse(0.5);
    let c = chi2_gof(
        &|ul, u| d.sample(wi, ul, u).map(|s| s.wo),
        &|wo| 1.1 * d.pdf(wi, wo) as f64,
        200,
    );
    assert_chi2_fails("diffuse pdf × 1.1", &c);
    // GGX density with a 10% larger roughness than the sampler's.
    let (g, g_wrong) = (rough(0.2), rough(0.22));
    let c = chi2_gof(
        &|ul, u| g.sample(wi, ul, u).map(|s| s.wo),
        &|wo| g_wrong.pdf(wi, wo) as f64,
        202,
    );
    assert_chi2_fails("roughconductor α=0.2 sampled, α=0.22 pdf", &c);
    // GGX density of the right roughness but the wrong incidence (a frame bug): 40° for 45°.
    let c = chi2_gof(
        &|ul, u| g.sample(wi, ul, u).map(|s| s.wo),
        &|wo| g.pdf(incident(40.0), wo) as f64,
        204,
    );
    assert_chi2_fails("roughconductor, pdf at the wrong incidence", &c);
}

// ---------------------------------------------------------------------------------------------
// Estimator consistency, normalisation, reciprocity, energy
// ---------------------------------------------------------------------------------------------

fn smooth_bsdfs() -> Vec<(String, Bsdf)> {
    let mut v = vec![("diffuse".to_string(), diffuse(0.7))];
    for a in [0.01, 0.05, 0.2, 0.5, 1.0, 2.0] {
        v.push((format!("rough α={a}"), rough(a)));
    }
    v.push((
        "rough tinted".into(),
        Bsdf::from_desc(&BsdfDesc::RoughConductor {
            alpha: 0.3,
            specular_reflectance: Rgb::new(0.9, 0.5, 0.2),
        }),
    ));
    v.push((
        "twosided diffuse".into(),
        twosided(BsdfDesc::Diffuse {
            reflectance: Rgb::new(0.2, 0.4, 0.8),
        }),
    ));
    v.push((
        "twosided rough".into(),
        twosided(BsdfDesc::RoughConductor {
            alpha: 0.15,
            specular_reflectance: Rgb::ONE,
        }),
    ));
    v
}

#[test]
fn sample_weight_is_eval_over_pdf() {
    let mut r = rng(7);
    for (name, b) in smooth_bsdfs() {
        assert!(b.has_smooth_lobe(), "{name}");
        let mut hits = 0;
        for _ in 0..50_000 {
            let wi = uniform_dir(&mut r);
            let ul = r.random::<f32>();
            let Some(s) = b.sample(wi, ul, u2(&mut r)) else {
                continue;
            };
            hits += 1;
            assert!(!s.delta && s.eta == 1.0, "{name}: {s:?}");
            assert!(s.pdf.is_finite() && s.pdf > 0.0, "{name}: {s:?}");
            let (e, p) = b.eval_pdf(wi, s.wo);
            assert_eq!(e, b.eval(wi, s.wo), "{name}");
            assert_eq!(p, b.pdf(wi, s.wo), "{name}");
            assert!(
                p > 0.0,
                "{name}: sampled a direction of pdf 0: wi={wi} {s:?}"
            );
            assert!(
                rel_close(p, s.pdf, 1e-6),
                "{name}: pdf {p} vs sampled {s:?}"
            );
            assert!(
                rgb_close(e / p, s.weight, 1e-6),
                "{name}: eval/pdf {} vs weight, wi={wi} {s:?}",
                e / p
            );
        }
        assert!(hits > 10_000, "{name}: only {hits} samples");
    }
}

#[test]
fn diffuse_weight_is_reflectance() {
    let b = diffuse(0.3);
    let mut r = rng(8);
    for _ in 0..1000 {
        let s = b.sample(incident(30.0), 0.5, u2(&mut r)).unwrap();
        assert_eq!(s.weight, Rgb::splat(0.3));
        assert!((s.pdf - s.wo.z / std::f32::consts::PI).abs() < 1e-6);
    }
}

/// `∫ pdf dω` and `∫ eval dω` on a lobe-adapted grid.
fn integrals(b: &Bsdf, wi: Vec3, seed: u64) -> (f64, f64) {
    let grid = Grid::for_sampler(&|ul, u| b.sample(wi, ul, u).map(|s| s.wo), seed);
    let p: f64 = grid.integrate(&|wo| b.pdf(wi, wo) as f64).iter().sum();
    let e: f64 = grid.integrate(&|wo| b.eval(wi, wo).x as f64).iter().sum();
    (p, e)
}

/// Fraction of `sample` calls that succeed, and the mean weight (0 for failures): unbiased
/// estimates of `∫ pdf` and of the albedo.
fn mc_mass_and_albedo(b: &Bsdf, wi: Vec3, n: usize, seed: u64) -> (f64, f64) {
    let mut r = rng(seed);
    let (mut hits, mut sum) = (0usize, 0.0f64);
    for _ in 0..n {
        let ul = r.random::<f32>();
        if let Some(s) = b.sample(wi, ul, u2(&mut r)) {
            hits += 1;
            sum += s.weight.x as f64;
        }
    }
    (hits as f64 / n as f64, sum / n as f64)
}

#[test]
fn pdf_integrates_to_one_minus_lost_mass() {
    for deg in INCIDENCES_DEG {
        let wi = incident(deg);
        let (p, e) = integrals(&diffuse(1.0), wi, 40);
        assert!((p - 1.0).abs() < 1e-5, "diffuse θi={deg}: ∫pdf = {p}");
        assert!((e - 1.0).abs() < 1e-5, "diffuse θi={deg}: albedo {e}");
        for (k, alpha) in [0.01, 0.05, 0.2, 0.5, 1.0].into_iter().enumerate() {
            let b = rough(alpha);
            let (p, _) = integrals(&b, wi, 41 + k as u64);
            let n = 400_000;
            let (frac, _) = mc_mass_and_albedo(&b, wi, n, 50 + k as u64);
            let sigma = (frac * (1.0 - frac) / n as f64).sqrt();
            eprintln!("rough α={alpha} θi={deg}: ∫pdf = {p:.6}, accepted fraction {frac:.6}");
            assert!(p <= 1.0 + 1e-5, "α={alpha} θi={deg}: ∫pdf = {p} > 1");
            // The missing mass is exactly the probability that the reflection goes below the
            // horizon, i.e. that `sample` returns None.
            assert!(
                (p - frac).abs() < 5.0 * sigma + 1e-4,
                "α={alpha} θi={deg}: ∫pdf = {p} but {frac} of samples accepted"
            );
            if deg == 0.0 {
                // At normal incidence D_wi(m) = D(m) cos θm, under which tan²θm has the CDF
                // t / (α² + t); the mirror direction stays above the horizon iff θm < 45°.
                let a2 = (alpha as f64).powi(2);
                let want = 1.0 / (1.0 + a2);
                assert!(
                    (p - want).abs() < 1e-5,
                    "α={alpha}: ∫pdf = {p}, want {want}"
                );
            }
        }
    }
}

#[test]
fn eval_is_reciprocal() {
    let mut r = rng(9);
    for (name, b) in smooth_bsdfs() {
        for _ in 0..20_000 {
            let (wi, wo) = (uniform_dir(&mut r), uniform_dir(&mut r));
            let f_io = b.eval(wi, wo) / wo.z.abs();
            let f_oi = b.eval(wo, wi) / wi.z.abs();
            if wi.z.abs() < 1e-4 || wo.z.abs() < 1e-4 {
                continue;
            }
            assert!(
                rgb_close(f_io, f_oi, 2e-4),
                "{name}: f(wi,wo)={f_io} f(wo,wi)={f_oi} wi={wi} wo={wo}"
            );
        }
    }
}

#[test]
fn white_furnace() {
    // Diffuse of albedo 1 reflects everything, by quadrature and by sampling.
    for deg in INCIDENCES_DEG {
        let b = diffuse(1.0);
        let (_, e) = integrals(&b, incident(deg), 60);
        assert!((e - 1.0).abs() < 1e-5, "diffuse albedo {e}");
        let (_, mc) = mc_mass_and_albedo(&b, incident(deg), 10_000, 61);
        assert_eq!(mc, 1.0);
    }
    // GGX mirror: albedo ≤ 1, not increasing with roughness, → 1 as alpha → 0.
    for (k, deg) in INCIDENCES_DEG.into_iter().enumerate() {
        let wi = incident(deg);
        let mut prev = f64::INFINITY;
        for (j, alpha) in [1e-3, 0.01, 0.05, 0.2, 0.5, 1.0].into_iter().enumerate() {
            let b = rough(alpha);
            let (_, e) = integrals(&b, wi, 70 + 10 * k as u64 + j as u64);
            let n = 400_000;
            let (_, mc) = mc_mass_and_albedo(&b, wi, n, 100 + 10 * k as u64 + j as u64);
            eprintln!("rough α={alpha} θi={deg}: albedo quadrature {e:.6}, sampled {mc:.6}");
            assert!(e <= 1.0 + 1e-5, "α={alpha} θi={deg}: albedo {e} > 1");
            // Weights are G1(wo) ∈ [0, 1], so their standard deviation is at most 1/2.
            assert!(
                (e - mc).abs() < 5.0 * 0.5 / (n as f64).sqrt() + 1e-4,
                "α={alpha} θi={deg}: quadrature {e} vs sampled {mc}"
            );
            assert!(
                e <= prev + 1e-4,
                "albedo increased with roughness at α={alpha}"
            );
            prev = e;
            if alpha <= 0.01 {
                assert!(e > 0.99, "α={alpha} θi={deg}: albedo {e} should be ≈ 1");
            }
            if alpha <= 1e-3 {
                assert!(e > 0.999, "α={alpha} θi={deg}: albedo {e} should be ≈ 1");
            }
        }
    }
}

/// Walter et al. 2007's GGX formulas in f64, written with tangents (independently of the
/// implementation's algebra): `D = 1 / (π α² cos⁴θm (1 + tan²θm/α²)²)`,
/// `G1 = 2 / (1 + √(1 + α² tan²θ))`.
fn walter_ggx_eval(alpha: f64, wi: Vec3, wo: Vec3) -> f64 {
    let (wi, wo) = (wi.as_dvec3(), wo.as_dvec3());
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let m = (wi + wo).normalize();
    let tan2 = |v: glam::DVec3| (1.0 - v.z * v.z) / (v.z * v.z);
    let a2 = alpha * alpha;
    let d = 1.0 / (PI * a2 * m.z.powi(4) * (1.0 + tan2(m) / a2).powi(2));
    let g1 = |v: glam::DVec3| 2.0 / (1.0 + (1.0 + a2 * tan2(v)).sqrt());
    d * g1(wi) * g1(wo) / (4.0 * wi.z)
}

#[test]
fn roughconductor_matches_walter_formulas() {
    let mut r = rng(10);
    for alpha in [0.05f32, 0.2, 0.5, 1.0] {
        let b = rough(alpha);
        for _ in 0..20_000 {
            let (wi, wo) = (uniform_dir(&mut r), uniform_dir(&mut r));
            if wi.z.abs() < 1e-3 || wo.z.abs() < 1e-3 {
                continue;
            }
            let want = walter_ggx_eval(alpha as f64, wi, wo);
            let got = b.eval(wi, wo).x as f64;
            assert!(
                (got - want).abs() <= 1e-4 * want.abs().max(got.abs()) + 1e-12,
                "α={alpha} wi={wi} wo={wo}: {got} vs {want}"
            );
        }
    }
    // Tint multiplies (material "none": Fresnel factor 1).
    let t = Bsdf::from_desc(&BsdfDesc::RoughConductor {
        alpha: 0.3,
        specular_reflectance: Rgb::new(0.5, 0.25, 1.0),
    });
    let (wi, wo) = (incident(30.0), Vec3::new(-0.3, -0.2, 0.9).normalize());
    let base = rough(0.3).eval(wi, wo).x;
    assert!(rgb_close(
        t.eval(wi, wo),
        Rgb::new(0.5, 0.25, 1.0) * base,
        1e-6
    ));
}

// ---------------------------------------------------------------------------------------------
// Mirror and dielectric
// ---------------------------------------------------------------------------------------------

#[test]
fn conductor_is_a_one_sided_tinted_mirror() {
    let b = conductor();
    assert!(!b.has_smooth_lobe());
    let mut r = rng(11);
    for _ in 0..1000 {
        let wi = uniform_dir(&mut r);
        let wo = uniform_dir(&mut r);
        assert_eq!(b.eval(wi, wo), Rgb::ZERO);
        assert_eq!(b.pdf(wi, wo), 0.0);
        let s = b.sample(wi, r.random(), u2(&mut r));
        if wi.z <= 0.0 {
            assert!(s.is_none());
            continue;
        }
        let s = s.unwrap();
        assert_eq!(s.wo, Vec3::new(-wi.x, -wi.y, wi.z));
        assert_eq!(s.weight, Rgb::new(0.9, 0.8, 0.7));
        assert!(s.delta && s.pdf == f32::INFINITY && s.eta == 1.0);
    }
}

/// Fresnel reflectance from the textbook angle form (f64): `Rs = sin²(θi−θt)/sin²(θi+θt)`,
/// `Rp = tan²(θi−θt)/tan²(θi+θt)`, for light going from index `n1` into `n2`.
fn fresnel_reference(cos_i: f64, n1: f64, n2: f64) -> f64 {
    let ti = cos_i.abs().min(1.0).acos();
    let st = n1 / n2 * ti.sin();
    if st >= 1.0 {
        return 1.0;
    }
    let tt = st.asin();
    if ti == 0.0 {
        let r = (n1 - n2) / (n1 + n2);
        return r * r;
    }
    let rs = ((ti - tt).sin() / (ti + tt).sin()).powi(2);
    let rp = ((ti - tt).tan() / (ti + tt).tan()).powi(2);
    0.5 * (rs + rp)
}

#[test]
fn dielectric_fresnel() {
    for eta in [1.5f32, 1.5046 / 1.000277, 1.33, 2.4, 0.7] {
        // Normal incidence, both sides.
        let r0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
        assert!((fresnel_dielectric(1.0, eta).0 - r0).abs() < 1e-6);
        assert!((fresnel_dielectric(-1.0, eta).0 - r0).abs() < 1e-6);
        // Every angle from outside (n1 = 1, n2 = eta) and from inside (n1 = eta, n2 = 1).
        for k in 0..=200 {
            let c = k as f32 / 200.0;
            for (ci, n1, n2) in [(c, 1.0, eta), (-c, eta, 1.0)] {
                let (f, cos_t, _, _) = fresnel_dielectric(ci, eta);
                let want = fresnel_reference(ci as f64, n1 as f64, n2 as f64);
                assert!(
                    (f as f64 - want).abs() < 2e-5,
                    "eta={eta} cos={ci}: {f} vs {want}"
                );
                assert!(cos_t == 0.0 || cos_t.signum() == -ci.signum() || ci == 0.0);
            }
        }
    }
    // 1.5 at normal incidence is the familiar 4%.
    assert!((fresnel_dielectric(1.0, 1.5).0 - 0.04).abs() < 1e-6);
    // Index-matched interfaces do not reflect.
    assert_eq!(fresnel_dielectric(0.3, 1.0).0, 0.0);
}

#[test]
fn dielectric_is_delta_and_reports_ratio() {
    let b = glass(1.5, 1.0);
    assert!(!b.has_smooth_lobe());
    let mut r = rng(12);
    for _ in 0..1000 {
        let (wi, wo) = (uniform_dir(&mut r), uniform_dir(&mut r));
        assert_eq!(b.eval(wi, wo), Rgb::ZERO);
        assert_eq!(b.pdf(wi, wo), 0.0);
        let s = b.sample(wi, r.random(), u2(&mut r)).unwrap();
        assert!(s.delta && s.pdf == f32::INFINITY);
    }
    // eta is int_ior / ext_ior.
    assert_eq!(Dielectric::new(1.5046, 1.000277).eta, 1.5046 / 1.000277);
}

#[test]
fn dielectric_selection_frequency_matches_fresnel() {
    let eta = 1.5f32;
    let b = glass(eta, 1.0);
    let n = 200_000;
    let mut r = rng(13);
    for deg in [0.0f32, 30.0, 60.0, 75.0, 85.0] {
        // Inside, stay below the critical angle (41.8°) so both lobes occur.
        for wi in [incident(deg), flip(incident(deg * 0.45))] {
            let f = fresnel_dielectric(wi.z, eta).0 as f64;
            let mut refl = 0;
            for _ in 0..n {
                let s = b.sample(wi, r.random(), u2(&mut r)).unwrap();
                if s.wo.z * wi.z > 0.0 {
                    refl += 1;
                }
            }
            let freq = refl as f64 / n as f64;
            let sigma = (f * (1.0 - f) / n as f64).sqrt();
            assert!(
                (freq - f).abs() < 5.0 * sigma + 1e-6,
                "wi={wi}: reflected {freq}, Fresnel {f}"
            );
        }
    }
}

#[test]
fn dielectric_reflection_and_refraction_geometry() {
    let eta = 1.5f32;
    let tint_r = Rgb::new(0.9, 0.8, 0.7);
    let tint_t = Rgb::new(0.6, 0.5, 0.4);
    let b = Bsdf::from_desc(&BsdfDesc::Dielectric {
        int_ior: 1.5,
        ext_ior: 1.0,
        specular_reflectance: tint_r,
        specular_transmittance: tint_t,
    });
    let mut r = rng(14);
    for _ in 0..20_000 {
        let wi = uniform_dir(&mut r);
        let u_lobe: f32 = r.random();
        let s = b.sample(wi, u_lobe, u2(&mut r)).unwrap();
        assert!((s.wo.length() - 1.0).abs() < 1e-5);
        let (f, _, eta_it, _) = fresnel_dielectric(wi.z, eta);
        if u_lobe < f {
            assert_eq!(s.wo, Vec3::new(-wi.x, -wi.y, wi.z));
            assert_eq!(s.weight, tint_r);
            assert_eq!(s.eta, 1.0);
        } else {
            // Opposite side, opposite azimuth, Snell's law n_i sin θi = n_t sin θt.
            assert!(s.wo.z * wi.z < 0.0, "wi={wi} {s:?}");
            let sin_i = wi.truncate().length();
            let sin_t = s.wo.truncate().length();
            assert!(
                (sin_i - eta_it * sin_t).abs() < 1e-5,
                "Snell: wi={wi} {s:?}"
            );
            assert!(s.wo.truncate().dot(wi.truncate()) <= 0.0);
            assert!(s.wo.truncate().perp_dot(wi.truncate()).abs() < 1e-5);
            // eta_it is eta entering, 1/eta leaving; radiance scales by 1/eta_it².
            let want_eta = if wi.z >= 0.0 { eta } else { 1.0 / eta };
            assert_eq!(s.eta, want_eta);
            assert!(rgb_close(s.weight, tint_t / (want_eta * want_eta), 1e-6));
        }
    }
}

#[test]
fn dielectric_total_internal_reflection() {
    let eta = 1.5f32;
    let b = glass(eta, 1.0);
    let critical = (1.0 / eta).asin().to_degrees(); // ≈ 41.8°
    let mut r = rng(15);
    for deg in [critical + 0.1, 50.0, 70.0, 89.9] {
        let wi = flip(incident(deg));
        assert_eq!(fresnel_dielectric(wi.z, eta).0, 1.0);
        for _ in 0..1000 {
            let s = b.sample(wi, r.random(), u2(&mut r)).unwrap();
            assert_eq!(s.wo, Vec3::new(-wi.x, -wi.y, wi.z));
            assert_eq!((s.weight, s.eta), (Rgb::ONE, 1.0));
        }
        // The same angle from outside refracts as usual.
        assert!(fresnel_dielectric(-wi.z, eta).0 < 1.0);
    }
    // Just inside the critical angle both lobes occur.
    let wi = flip(incident(critical - 0.5));
    let f = fresnel_dielectric(wi.z, eta).0;
    assert!(f < 1.0 && f > 0.3, "near-critical F = {f}");
    assert!(b.sample(wi, 0.999_999, Vec2::ZERO).unwrap().wo.z > 0.0);
}

#[test]
fn dielectric_is_symmetric_across_the_interface() {
    let eta = 1.5046f32 / 1.000277;
    let b = glass(1.5046, 1.000277);
    // Refraction is reversible: going back along the refracted ray returns along the incident
    // one, with the same Fresnel reflectance (Stokes), and the radiance scalings cancel.
    for deg in [0.0f32, 10.0, 30.0, 50.0, 70.0, 85.0] {
        let wi = incident(deg);
        let t = b.sample(wi, 0.999_999, Vec2::ZERO).unwrap();
        assert!(t.wo.z < 0.0);
        // The reversed path arrives from inside along t.wo and must leave along wi.
        let back = b.sample(t.wo, 0.999_999, Vec2::ZERO).unwrap();
        assert!((back.wo - wi).length() < 1e-5, "deg={deg}: {back:?}");
        assert!(rel_close(back.eta * t.eta, 1.0, 1e-6));
        assert!(rgb_close(back.weight * t.weight, Rgb::ONE, 1e-5));
        let (f_out, f_in) = (
            fresnel_dielectric(wi.z, eta).0,
            fresnel_dielectric(t.wo.z, eta).0,
        );
        assert!(
            (f_out - f_in).abs() < 1e-5,
            "deg={deg}: F {f_out} vs {f_in}"
        );
    }
    // A glass of eta seen from inside behaves as a glass of 1/eta seen from outside.
    let inv = glass(1.000277, 1.5046);
    let mut r = rng(16);
    for _ in 0..2000 {
        let wi = uniform_dir(&mut r);
        let (ul, u) = (r.random::<f32>(), u2(&mut r));
        let a = b.sample(wi, ul, u).unwrap();
        let c = inv.sample(flip(wi), ul, u).unwrap();
        assert!((a.wo - flip(c.wo)).length() < 1e-5);
        assert!(rgb_close(a.weight, c.weight, 1e-5));
        assert!(rel_close(a.eta, c.eta, 1e-6));
    }
    // Index matched: the interface is invisible.
    let m = glass(1.3, 1.3);
    let wi = incident(60.0);
    let s = m.sample(wi, 0.0, Vec2::ZERO).unwrap();
    assert!((s.wo + wi).length() < 1e-6 && s.weight == Rgb::ONE && s.eta == 1.0);
}

// ---------------------------------------------------------------------------------------------
// Sidedness
// ---------------------------------------------------------------------------------------------

#[test]
fn one_sided_bsdfs_are_black_from_the_back() {
    let mut r = rng(17);
    for b in [diffuse(0.5), rough(0.3), rough(0.01), conductor()] {
        for _ in 0..5000 {
            let (a, c) = (uniform_dir(&mut r), uniform_dir(&mut r));
            let back = flip(Vec3::new(a.x, a.y, a.z.abs()));
            let front = Vec3::new(c.x, c.y, c.z.abs());
            assert!(b.sample(back, r.random(), u2(&mut r)).is_none(), "{b:?}");
            for (wi, wo) in [(back, front), (front, flip(front)), (back, back)] {
                assert_eq!(b.eval(wi, wo), Rgb::ZERO, "{b:?}");
                assert_eq!(b.pdf(wi, wo), 0.0, "{b:?}");
            }
        }
    }
}

#[test]
fn twosided_back_equals_front() {
    let inners = [
        BsdfDesc::Diffuse {
            reflectance: Rgb::new(0.2, 0.5, 0.9),
        },
        BsdfDesc::RoughConductor {
            alpha: 0.25,
            specular_reflectance: Rgb::new(1.0, 0.5, 0.25),
        },
        BsdfDesc::Conductor {
            specular_reflectance: Rgb::splat(0.8),
        },
    ];
    let mut r = rng(18);
    for inner in inners {
        let one = Bsdf::from_desc(&inner);
        let two = twosided(inner.clone());
        assert_eq!(one.has_smooth_lobe(), two.has_smooth_lobe());
        for _ in 0..5000 {
            let (wi, wo) = (uniform_dir(&mut r), uniform_dir(&mut r));
            let (ul, u) = (r.random::<f32>(), u2(&mut r));
            let (fi, fo) = if wi.z < 0.0 {
                (flip(wi), flip(wo))
            } else {
                (wi, wo)
            };
            assert_eq!(two.eval(wi, wo), one.eval(fi, fo));
            assert_eq!(two.pdf(wi, wo), one.pdf(fi, fo));
            let (s2, s1) = (two.sample(wi, ul, u), one.sample(fi, ul, u));
            assert_eq!(s2.is_some(), s1.is_some());
            if let (Some(s2), Some(s1)) = (s2, s1) {
                let wo1 = if wi.z < 0.0 { flip(s1.wo) } else { s1.wo };
                assert_eq!(s2, BsdfSample { wo: wo1, ..s1 });
                assert!(s2.wo.z * wi.z > 0.0, "twosided reflects to wi's side");
            }
        }
    }
    // Wrapping a dielectric or another twosided is refused by the loader, as in Mitsuba
    // (tests/render_loader.rs).
}

// ---------------------------------------------------------------------------------------------
// Robustness
// ---------------------------------------------------------------------------------------------

#[test]
fn alpha_is_clamped_like_mitsuba() {
    assert_eq!(
        RoughConductor::new(0.0, Rgb::ONE).distribution.alpha_u(),
        MIN_ALPHA
    );
    // A near-zero roughness behaves as a mirror in expectation.
    let b = rough(0.0);
    let wi = incident(40.0);
    let mut r = rng(19);
    for _ in 0..1000 {
        let s = b.sample(wi, 0.5, u2(&mut r)).unwrap();
        assert!((s.wo - Vec3::new(-wi.x, -wi.y, wi.z)).length() < 1e-2);
        assert!(s.weight.x > 0.99 && s.weight.x <= 1.0);
    }
}

/// Awkward unit vectors: poles, exact and near-grazing directions, subnormal components.
fn awkward_dirs() -> Vec<Vec3> {
    let mut v = vec![
        Vec3::Z,
        -Vec3::Z,
        Vec3::X,
        -Vec3::Y,
        Vec3::new(0.6, 0.8, 0.0),
    ];
    for z in [1e-38f32, 1e-30, 1e-20, 1e-12, 1e-7, 1e-4, 1e-2] {
        for sz in [z, -z] {
            let s = (1.0 - sz * sz).sqrt();
            v.push(Vec3::new(s * 0.8, s * 0.6, sz));
        }
    }
    for e in [1e-38f32, 1e-20, 1e-7, 1e-4] {
        let s = (1.0 - e * e).sqrt();
        v.push(Vec3::new(e, 0.0, s));
        v.push(Vec3::new(0.0, -e, -s));
    }
    v.push(incident(45.0));
    v.push(flip(incident(80.0)));
    v
}

fn all_bsdfs() -> Vec<Bsdf> {
    let mut v: Vec<Bsdf> = smooth_bsdfs().into_iter().map(|(_, b)| b).collect();
    v.extend([
        rough(0.0),
        rough(1e-3),
        rough(10.0),
        conductor(),
        glass(1.5, 1.0),
        glass(1.0, 1.5),
        glass(1.0, 1.0),
        twosided(BsdfDesc::Conductor {
            specular_reflectance: Rgb::ONE,
        }),
    ]);
    v
}

fn check_finite(b: &Bsdf, wi: Vec3, wo: Vec3, ul: f32, u: Vec2) {
    let (e, p) = b.eval_pdf(wi, wo);
    assert!(
        e.is_finite() && e.min_element() >= 0.0,
        "{b:?} eval({wi}, {wo}) = {e}"
    );
    assert!(p.is_finite() && p >= 0.0, "{b:?} pdf({wi}, {wo}) = {p}");
    if let Some(s) = b.sample(wi, ul, u) {
        let ctx = format!("{b:?} sample({wi}, {ul}, {u}) = {s:?}");
        assert!(
            s.wo.is_finite() && (s.wo.length() - 1.0).abs() < 1e-4,
            "{ctx}"
        );
        assert!(
            s.weight.is_finite() && s.weight.min_element() >= 0.0,
            "{ctx}"
        );
        assert!(s.eta.is_finite() && s.eta > 0.0, "{ctx}");
        if s.delta {
            assert_eq!(s.pdf, f32::INFINITY, "{ctx}");
        } else {
            assert!(s.pdf.is_finite() && s.pdf > 0.0, "{ctx}");
            let (e, p) = b.eval_pdf(wi, s.wo);
            assert!(p > 0.0 && p.is_finite(), "{ctx}: pdf(wi, wo) = {p}");
            assert!(e.is_finite(), "{ctx}: eval(wi, wo) = {e}");
        }
    }
}

#[test]
fn no_nan_or_inf_on_degenerate_inputs() {
    let one_minus = 1.0 - f32::EPSILON / 2.0; // the largest f32 below 1
    let us = [0.0, 1e-7, 0.5, one_minus];
    let dirs = awkward_dirs();
    for b in all_bsdfs() {
        for &wi in &dirs {
            for &wo in &dirs {
                check_finite(&b, wi, wo, 0.5, Vec2::splat(0.5));
            }
            for &ul in &us {
                for &ux in &us {
                    for &uy in &us {
                        check_finite(&b, wi, -wi, ul, Vec2::new(ux, uy));
                    }
                }
            }
        }
    }
    // And on random inputs.
    let mut r = rng(20);
    for b in all_bsdfs() {
        for _ in 0..20_000 {
            let (wi, wo) = (uniform_dir(&mut r), uniform_dir(&mut r));
            let ul = r.random::<f32>();
            check_finite(&b, wi, wo, ul, u2(&mut r));
        }
    }
}
