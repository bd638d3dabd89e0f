//! Tests of `roughdielectric` and `thindielectric` (`src/render/bsdfs/`): values, densities and
//! samples against Mitsuba 3.9.1 (fixtures made by `tests/data/dielectrics/make_fixture.py`),
//! the rough sampler against its density (chi-square), the mean sample weight against the
//! integral of `eval` (both sides of the interface), the thin slab's lobe probabilities and
//! weights, and the loader.
//!
//! All randomness comes from fixed seeds, so every run is the same run; the significance levels
//! below describe how often a *correct* implementation would fail for a random choice of seeds.

use fireflies::Error;
use fireflies::render::bsdfs::fresnel::fresnel_dielectric;
use fireflies::render::bsdfs::microfacet::{Distribution, Microfacet};
use fireflies::render::bsdfs::roughdielectric::RoughDielectric;
use fireflies::render::bsdfs::thindielectric::ThinDielectric;
use fireflies::render::bsdfs::{Bsdf, SurfacePoint};
use fireflies::render::mitsuba::load_str;
use fireflies::render::scene::Rgb;
use fireflies::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::f64::consts::PI;
use std::path::Path;

static AT: std::sync::LazyLock<SurfacePoint> = std::sync::LazyLock::new(SurfacePoint::default);

/// The fixture's tints (see `make_fixture.py`).
const REFLECT_TINT: Rgb = Rgb::new(0.9, 0.5, 0.2);
const TRANSMIT_TINT: Rgb = Rgb::new(0.3, 0.6, 0.8);

/// Mitsuba's default indices (`bk7`, `air`).
const BK7: f32 = 1.5046;
const AIR: f32 = 1.000277;

fn rng(seed: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(seed)
}

fn u2(r: &mut Xoshiro256PlusPlus) -> Vec2 {
    Vec2::new(r.random::<f32>(), r.random::<f32>())
}

/// Unit direction at polar angle `theta_deg` from `+z` (below the surface if `inside`), at an
/// azimuth deliberately off the axes.
fn incident(theta_deg: f32, inside: bool) -> Vec3 {
    let t = theta_deg.to_radians();
    let z = if inside { -t.cos() } else { t.cos() };
    Vec3::new(t.sin() * 0.7f32.cos(), t.sin() * 0.7f32.sin(), z)
}

fn rough(dist: Distribution, alpha: f32, int_ior: f32, ext_ior: f32) -> RoughDielectric {
    RoughDielectric::new(Microfacet::isotropic(dist, alpha), int_ior, ext_ior)
}

fn tinted(mut b: RoughDielectric) -> RoughDielectric {
    b.specular_reflectance = Spectrum::Constant(REFLECT_TINT);
    b.specular_transmittance = Spectrum::Constant(TRANSMIT_TINT);
    b
}

/// The configurations of `make_fixture.py`, by name.
fn fixture_config(name: &str) -> RoughDielectric {
    use Distribution::{Beckmann, Ggx};
    match name {
        "beckmann_default" => rough(Beckmann, 0.1, BK7, AIR),
        "beckmann_0.3_1.5" => tinted(rough(Beckmann, 0.3, 1.5, 1.0)),
        "beckmann_0.05_2.4" => rough(Beckmann, 0.05, 2.4, 1.0),
        "ggx_0.1_1.5" => rough(Ggx, 0.1, 1.5, 1.0),
        "ggx_0.3_1.33" => tinted(rough(Ggx, 0.3, 1.33, 1.0)),
        "ggx_0.5_inverted" => rough(Ggx, 0.5, 1.0, 1.5),
        other => panic!("unknown fixture configuration {other}"),
    }
}

/// Rows of a CSV fixture under `tests/data/dielectrics/` (header skipped), split on commas.
fn fixture(name: &str) -> Vec<Vec<String>> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/dielectrics")
        .join(name);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    text.lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

fn num(s: &str) -> f32 {
    s.parse::<f64>().expect("number") as f32
}

fn v3(r: &[String], i: usize) -> Vec3 {
    Vec3::new(num(&r[i]), num(&r[i + 1]), num(&r[i + 2]))
}

/// `|a − b| ≤ abs + rel · max(|a|, |b|)`.
fn close(a: f32, b: f32, rel: f32, abs: f32) -> bool {
    (a - b).abs() <= abs + rel * a.abs().max(b.abs())
}

// ---------------------------------------------------------------------------------------------
// (1) Against Mitsuba
// ---------------------------------------------------------------------------------------------

/// `eval` and `pdf` equal Mitsuba's at 824 pairs: six configurations (both distributions, Mitsuba's
/// defaults, relative index 2.4 and below 1, tinted), `wi` outside and inside from normal to
/// 89.5°, `wo` random, near the specular reflection and refraction, and 1° off the horizon on
/// both sides. Tolerance: 2e-4 relative, the f32 rounding of differently ordered operations
/// amplified by the half vector (whose relative error grows like `1/|wi + η wo|`), plus 1e-30
/// absolute for the values Mitsuba cuts off at `D cos θm ≤ 1e-20`.
#[test]
fn eval_and_pdf_match_mitsuba() {
    let rows = fixture("rough_eval.csv");
    assert_eq!(rows.len(), 824);
    let (mut nonzero_r, mut nonzero_t, mut inside) = (0, 0, 0);
    let mut worst = 0.0f32;
    for r in &rows {
        let b = fixture_config(&r[0]);
        let (wi, wo) = (v3(r, 1), v3(r, 4));
        let (value, pdf) = b.eval_pdf(&AT, wi, wo);
        let (want, want_pdf) = (v3(r, 7), num(&r[10]));
        let ctx = format!(
            "{} wi={wi} wo={wo}: ours {value} / {pdf}, Mitsuba {want} / {want_pdf}",
            r[0]
        );
        for c in 0..3 {
            assert!(close(value[c], want[c], 2e-4, 1e-30), "value: {ctx}");
        }
        assert!(close(pdf, want_pdf, 2e-4, 1e-30), "pdf: {ctx}");
        if want_pdf > 1e-20 {
            worst = worst.max((pdf / want_pdf - 1.0).abs());
            if wi.z * wo.z > 0.0 {
                nonzero_r += 1;
            } else {
                nonzero_t += 1;
            }
            inside += usize::from(wi.z < 0.0);
        }
    }
    eprintln!(
        "worst pdf deviation {worst:e}; {nonzero_r} reflection, {nonzero_t} transmission, {inside} from inside"
    );
    // The fixture exercises every branch with non-trivial values.
    assert!(nonzero_r >= 50 && nonzero_t >= 100 && inside >= 50);
}

/// `sample` against Mitsuba's for the same random numbers. GGX: our visible-normal warp is
/// Mitsuba's, so the same `(u_lobe, u)` must give the same direction, weight, pdf and `eta`
/// (tolerances: f32 rounding, 1e-4 on directions, 5e-4 relative on weights and densities, which
/// near grazing depend on the rounding of the sampled normal). Beckmann: Mitsuba inverts the
/// visible-slope CDF with three Newton steps, we invert it to convergence, so directions agree
/// only to Mitsuba's residual; we check the lobe, `eta` and that the direction is close.
#[test]
fn sample_matches_mitsuba() {
    let rows = fixture("rough_sample.csv");
    assert_eq!(rows.len(), 360);
    let (mut ggx_checked, mut beckmann_checked) = (0, 0);
    for r in &rows {
        let b = fixture_config(&r[0]);
        let wi = v3(r, 1);
        let (ul, u) = (num(&r[4]), Vec2::new(num(&r[5]), num(&r[6])));
        let (want_wo, want_w, want_pdf, want_eta) = (v3(r, 7), v3(r, 10), num(&r[13]), num(&r[14]));
        let ours = b.sample(&AT, wi, ul, u);
        let ctx = format!(
            "{} wi={wi} u=({ul}, {u}): ours {ours:?}, Mitsuba wo={want_wo} w={want_w} pdf={want_pdf} eta={want_eta}",
            r[0]
        );
        if want_w.max_element() == 0.0 {
            // Mitsuba's sample is invalid (wo below the horizon of its lobe, or the grazing
            // tail of the sampler); ours must not return a weighted one.
            assert!(ours.is_none_or(|s| s.weight.max_element() == 0.0), "{ctx}");
            continue;
        }
        let Some(s) = ours else {
            panic!("no sample where Mitsuba has one: {ctx}");
        };
        assert!(!s.delta, "{ctx}");
        if b.microfacet.distribution() == Distribution::Ggx {
            assert!((s.wo - want_wo).abs().max_element() <= 1e-4, "wo: {ctx}");
            for c in 0..3 {
                assert!(close(s.weight[c], want_w[c], 5e-4, 0.0), "weight: {ctx}");
            }
            assert!(close(s.pdf, want_pdf, 5e-4, 0.0), "pdf: {ctx}");
            assert!(close(s.eta, want_eta, 1e-6, 0.0), "eta: {ctx}");
            ggx_checked += 1;
        } else {
            assert_eq!(s.eta == 1.0, want_eta == 1.0, "lobe: {ctx}");
            assert!(s.wo.dot(want_wo) > 0.999, "wo: {ctx}");
            beckmann_checked += 1;
        }
        // Our weight is exactly eval / pdf at the returned direction.
        let (value, pdf) = b.eval_pdf(&AT, wi, s.wo);
        assert_eq!(pdf, s.pdf, "{ctx}");
        assert_eq!(value / pdf, s.weight, "{ctx}");
    }
    assert!(
        ggx_checked >= 150 && beckmann_checked >= 150,
        "{ggx_checked} {beckmann_checked}"
    );
}

// ---------------------------------------------------------------------------------------------
// Quadrature over the sphere on a grid adapted to the lobe (as in tests/render_bsdf.rs)
// ---------------------------------------------------------------------------------------------

/// Polar bands and azimuthal sectors of the grid.
const THETA_BINS: usize = 20;
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

/// Cells `[θ_k, θ_k+1] × [φ_j, φ_j+1]` whose interior edges are marginal quantiles of pilot
/// samples, with the horizon always an edge (the densities jump there).
struct Grid {
    theta: Vec<f64>,
    phi: Vec<f64>,
}

fn spherical(w: Vec3) -> (f64, f64) {
    let theta = f64::from(w.z).clamp(-1.0, 1.0).acos();
    let phi = f64::from(w.y).atan2(f64::from(w.x)).rem_euclid(2.0 * PI);
    (theta, phi)
}

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

type Sampler<'a> = &'a dyn Fn(f32, Vec2) -> Option<Vec3>;

impl Grid {
    fn for_sampler(sample: Sampler, seed: u64) -> Grid {
        let mut r = rng(seed);
        let pilot: Vec<Vec3> = (0..PILOT_SAMPLES)
            .filter_map(|_| {
                let ul = r.random::<f32>();
                sample(ul, u2(&mut r))
            })
            .collect();
        assert!(pilot.len() >= 1000, "too few pilot samples");
        let (mut th, mut ph): (Vec<f64>, Vec<f64>) = pilot.iter().map(|&w| spherical(w)).unzip();
        Grid {
            theta: edges(&mut th, THETA_BINS, &[0.0, PI / 2.0, PI]),
            phi: edges(&mut ph, PHI_BINS, &[0.0, 2.0 * PI]),
        }
    }

    fn cells(&self) -> usize {
        (self.theta.len() - 1) * (self.phi.len() - 1)
    }

    fn cell_of(&self, w: Vec3) -> usize {
        let (t, p) = spherical(w);
        let find = |e: &[f64], x: f64| e.partition_point(|&b| b <= x).clamp(1, e.len() - 1) - 1;
        find(&self.theta, t) * (self.phi.len() - 1) + find(&self.phi, p)
    }

    /// `∫ f dω` over every cell by adaptive Gauss–Legendre cubature.
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

/// Relative accuracy asked of each cell's integral, and the absolute mass below which a
/// rectangle is not refined.
const QUAD_REL_TOL: f64 = 1e-5;
const QUAD_ABS_TOL: f64 = 1e-10;
const QUAD_MAX_DEPTH: u32 = 10;

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
// (2) Chi-square goodness of fit of the rough sampler
// ---------------------------------------------------------------------------------------------

/// Samples per chi-square test.
const CHI2_SAMPLES: usize = 1_000_000;
/// Cells expecting fewer samples are pooled.
const MIN_EXPECTED: f64 = 5.0;

/// The chi-square cases that must pass: `(distribution, alpha, θi in degrees, inside)`, all at
/// `int_ior = 1.5`, `ext_ior = 1` (critical angle 41.8° inside). Outside: normal, oblique and
/// near-grazing; inside: below and beyond the critical angle (where only facets tilted towards
/// `wi` transmit).
const CHI2_CASES: [(Distribution, f32, f32, bool); 12] = [
    (Distribution::Ggx, 0.1, 0.0, false),
    (Distribution::Ggx, 0.1, 45.0, false),
    (Distribution::Ggx, 0.1, 80.0, false),
    (Distribution::Ggx, 0.1, 30.0, true),
    (Distribution::Ggx, 0.1, 60.0, true),
    (Distribution::Ggx, 0.4, 0.0, false),
    (Distribution::Ggx, 0.4, 45.0, false),
    (Distribution::Ggx, 0.4, 80.0, false),
    (Distribution::Ggx, 0.4, 30.0, true),
    (Distribution::Ggx, 0.4, 60.0, true),
    (Distribution::Beckmann, 0.3, 45.0, false),
    (Distribution::Beckmann, 0.3, 30.0, true),
];

/// Family-wise significance: a *correct* sampler fails at least one of the 12 chi-square tests
/// of this file with probability 1% (for a random choice of seeds); each runs at the Šidák level
/// `1 − 0.99^(1/12) ≈ 8.4e-4`.
///
/// Power (normal approximation to the non-central chi-square, ~800 cells, critical value near
/// 930): a defect is caught with 90% probability once `N Σ (p − q)²/q` exceeds about 190, i.e.
/// with `N = 10⁶` a chi-square distance of ~1.9e-4 — a density error of about ±1.4% spread over
/// the whole sphere, or ±4.4% confined to a tenth of the mass. The must-fail case below (the
/// density of a 5% larger roughness) must be rejected.
const CHI2_FAMILY_ALPHA: f64 = 0.01;

fn chi2_level() -> f64 {
    1.0 - (1.0 - CHI2_FAMILY_ALPHA).powf(1.0 / CHI2_CASES.len() as f64)
}

/// Pearson's chi-square p-value of `sample` against the solid-angle density `pdf`; rejected
/// samples form their own bin, expecting the mass the density leaves outside the sphere.
fn chi2_p_value(sample: Sampler, pdf: &dyn Fn(Vec3) -> f64, seed: u64) -> f64 {
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
        kept.push((pool_o, pool_e));
    }
    assert!(kept.len() >= 2, "degenerate grid");
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
    let dof = (kept.len() - 1) as f64;
    let p = ChiSquared::new(dof).expect("dof > 0").sf(statistic);
    eprintln!(
        "chi2 = {statistic:.1}, dof = {dof}, p = {p:.3e}, rejected {} of {n}",
        observed[grid.cells()]
    );
    p
}

/// For Beckmann the reported pdf is Mitsuba's, with the fitted `G1(wi)`; the sampler draws from
/// the exact visible-normal density, which is the reported one times `G1_exact(wi) / G1_fit(wi)`
/// (a constant for a given `wi`; 1 for GGX). See the module docs of `roughdielectric`.
fn true_density_factor(mf: &Microfacet, wi: Vec3) -> f64 {
    let up = if wi.z < 0.0 { -wi } else { wi };
    let z = Vec3::Z;
    f64::from(mf.g1_exact(up, z)) / f64::from(mf.g1(up, z))
}

fn chi2_case(k: usize) {
    let (dist, alpha, deg, inside) = CHI2_CASES[k];
    let b = rough(dist, alpha, 1.5, 1.0);
    let wi = incident(deg, inside);
    let c = true_density_factor(&b.microfacet, wi);
    let p = chi2_p_value(
        &|ul, u| b.sample(&AT, wi, ul, u).map(|s| s.wo),
        &|wo| c * f64::from(b.pdf(&AT, wi, wo)),
        7000 + 10 * k as u64,
    );
    assert!(
        p >= chi2_level(),
        "{dist:?} α={alpha} θi={deg}° inside={inside}: chi-square rejects the sampler (p = {p:e})"
    );
}

#[test]
fn chi2_ggx_alpha_0_1() {
    for k in 0..5 {
        chi2_case(k);
    }
}

#[test]
fn chi2_ggx_alpha_0_4() {
    for k in 5..10 {
        chi2_case(k);
    }
}

#[test]
fn chi2_beckmann_with_the_true_density() {
    for k in 10..12 {
        chi2_case(k);
    }
}

/// The test has power: a density for a 5% larger roughness (`α = 0.42` instead of 0.4, which
/// moves little mass between the lobes and the rejected bin) is rejected.
#[test]
fn chi2_detects_a_slightly_wrong_density() {
    let b = rough(Distribution::Ggx, 0.4, 1.5, 1.0);
    let wrong = rough(Distribution::Ggx, 0.42, 1.5, 1.0);
    let wi = incident(45.0, false);
    let p = chi2_p_value(
        &|ul, u| b.sample(&AT, wi, ul, u).map(|s| s.wo),
        &|wo| f64::from(wrong.pdf(&AT, wi, wo)),
        7500,
    );
    assert!(
        p < chi2_level(),
        "a 5% roughness error went unnoticed (p = {p:e})"
    );
}

// ---------------------------------------------------------------------------------------------
// (3) Mean sample weight against the integral of eval, from both sides
// ---------------------------------------------------------------------------------------------

/// Samples per weight-mean check.
const MEAN_SAMPLES: usize = 400_000;

/// `E[weight] = ∫ eval dωo` (times the Beckmann factor of [`true_density_factor`], which
/// Mitsuba's estimator carries too), checked per configuration and side; and with the radiance
/// scaling undone (`weight · η²` for transmitted samples, i.e. `weight · sample.eta²`), the
/// albedo of the interface is at most 1 (plus 1e-4 for the overshoot of Mitsuba's Beckmann
/// `G1` fit) and, for the smooth-ish `α = 0.1`, above 0.9 (the
/// separable masking loses only a few percent).
///
/// Statistics: weights are bounded (by `max(η², 1/η²)`), so the sample mean is normal to good
/// approximation; each check allows 5 standard errors (false failure 5.7e-7 per check, below
/// 2e-5 for the 32 checks) plus 3e-4 relative for the cubature (asked to 1e-5 per cell). With
/// standard errors around 3e-4 this catches a bias of about 0.3% of the albedo — e.g. a
/// transmission weight missing `η²` (a factor 2.25) or a lobe chosen with the wrong probability.
#[test]
fn mean_weight_matches_the_integral_of_eval() {
    let cases = [
        (Distribution::Ggx, 0.1, 1.5, 1.0),
        (Distribution::Ggx, 0.5, 1.33, 1.0),
        (Distribution::Beckmann, 0.3, 1.5, 1.0),
        (Distribution::Beckmann, 0.1, 1.0, 1.5),
    ];
    let mut seed = 9000;
    for (dist, alpha, int_ior, ext_ior) in cases {
        let b = rough(dist, alpha, int_ior, ext_ior);
        for (deg, inside) in [(0.0, false), (60.0, false), (30.0, true), (70.0, true)] {
            seed += 2;
            let wi = incident(deg, inside);
            let ctx = format!(
                "{dist:?} α={alpha} η={} θi={deg}° inside={inside}",
                int_ior / ext_ior
            );
            let mut r = rng(seed);
            let (mut sum, mut sum2, mut albedo, mut albedo2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for _ in 0..MEAN_SAMPLES {
                let ul = r.random::<f32>();
                if let Some(s) = b.sample(&AT, wi, ul, u2(&mut r)) {
                    assert!(
                        s.weight.x == s.weight.y && s.weight.y == s.weight.z,
                        "{ctx}"
                    );
                    let w = f64::from(s.weight.x);
                    let a = w * f64::from(s.eta * s.eta);
                    sum += w;
                    sum2 += w * w;
                    albedo += a;
                    albedo2 += a * a;
                }
            }
            let n = MEAN_SAMPLES as f64;
            let (mean, mean_a) = (sum / n, albedo / n);
            let se = ((sum2 / n - mean * mean).max(0.0) / n).sqrt();
            let se_a = ((albedo2 / n - mean_a * mean_a).max(0.0) / n).sqrt();
            let grid = Grid::for_sampler(&|ul, u| b.sample(&AT, wi, ul, u).map(|s| s.wo), seed + 1);
            let integral: f64 = grid
                .integrate(&|wo| f64::from(b.eval(&AT, wi, wo).x))
                .iter()
                .sum();
            let expected = integral * true_density_factor(&b.microfacet, wi);
            eprintln!(
                "{ctx}: mean weight {mean:.5} ± {se:.1e}, ∫eval·c {expected:.5}, albedo {mean_a:.4}"
            );
            assert!(
                (mean - expected).abs() <= 5.0 * se + 3e-4 * expected,
                "{ctx}: mean weight {mean} ± {se}, integral {expected}"
            );
            // Mitsuba's Beckmann G1 fit overshoots 1 by up to 6.1e-5 (near a = 1.59).
            assert!(
                mean_a <= 1.0 + 1e-4 + 5.0 * se_a,
                "{ctx}: albedo {mean_a} ± {se_a}"
            );
            if alpha <= 0.1 {
                assert!(mean_a >= 0.9, "{ctx}: albedo {mean_a}");
            }
        }
    }
}

/// Radiance scaling and `eta`: a transmitted sample carries `η_it` (`η` from outside, `1/η` from
/// inside) and a weight of `G1(wo, m) / η_it²`; a reflected one carries 1 and `G1(wo, m) ≤ 1`.
#[test]
fn transmission_reports_eta_and_scales_radiance() {
    let b = rough(Distribution::Ggx, 0.05, 1.5, 1.0);
    for inside in [false, true] {
        let wi = incident(20.0, inside);
        let want_eta = if inside { 1.0 / 1.5 } else { 1.5 };
        let mut r = rng(31 + u64::from(inside));
        let (mut seen_r, mut seen_t) = (0, 0);
        for _ in 0..2000 {
            let ul = r.random::<f32>();
            let Some(s) = b.sample(&AT, wi, ul, u2(&mut r)) else {
                continue;
            };
            if s.wo.z * wi.z > 0.0 {
                assert_eq!(s.eta, 1.0);
                assert!(s.weight.x <= 1.0 + 1e-6);
                seen_r += 1;
            } else {
                assert!(close(s.eta, want_eta, 1e-6, 0.0), "{s:?}");
                // weight = G1(wo) / η² with G1 ≤ 1, and G1 close to 1 for α = 0.05.
                let g1_times = s.weight.x * s.eta * s.eta;
                assert!(g1_times <= 1.0 + 1e-5 && g1_times > 0.9, "{s:?}");
                seen_t += 1;
            }
        }
        assert!(seen_r > 10 && seen_t > 1000, "{seen_r} {seen_t}");
    }
}

/// Degenerate inputs give nothing rather than NaN: grazing `wi`, NaN, wo = ±wi at index match.
#[test]
fn degenerate_inputs() {
    let b = rough(Distribution::Beckmann, 0.2, 1.5, 1.0);
    let grazing = Vec3::new(1.0, 0.0, 0.0);
    assert_eq!(b.eval_pdf(&AT, grazing, Vec3::Z), (Rgb::ZERO, 0.0));
    assert!(b.sample(&AT, grazing, 0.5, Vec2::splat(0.5)).is_none());
    let nan = Vec3::splat(f32::NAN);
    assert_eq!(b.eval_pdf(&AT, nan, Vec3::Z), (Rgb::ZERO, 0.0));
    assert!(b.sample(&AT, nan, 0.5, Vec2::splat(0.5)).is_none());
    let wi = incident(30.0, false);
    assert_eq!(b.eval_pdf(&AT, wi, Vec3::new(0.0, 0.0, 0.0)).1, 0.0);
    let mut r = rng(5);
    for _ in 0..10_000 {
        let wi = {
            let z = 1.0 - 2.0 * r.random::<f32>();
            let s = (1.0 - z * z).max(0.0).sqrt();
            let phi = std::f32::consts::TAU * r.random::<f32>();
            Vec3::new(s * phi.cos(), s * phi.sin(), z)
        };
        let ul = r.random::<f32>();
        if let Some(s) = b.sample(&AT, wi, ul, u2(&mut r)) {
            assert!(
                s.weight.is_finite() && s.pdf.is_finite() && s.pdf > 0.0,
                "{s:?}"
            );
            assert!((s.wo.length() - 1.0).abs() < 1e-5);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// (4) thindielectric
// ---------------------------------------------------------------------------------------------

/// Mitsuba's lobe choice, directions, weights and lobe probabilities at 160 points (four index
/// pairs including Mitsuba's defaults and one below 1, tinted and untinted, both sides, normal to
/// 89.5°): our reflectance `R` equals Mitsuba's `pdf` of the reflected sample, and `1 − R` that
/// of the transmitted one, to f32 rounding.
#[test]
fn thin_matches_mitsuba() {
    let rows = fixture("thin_sample.csv");
    assert_eq!(rows.len(), 160);
    for r in &rows {
        let mut b = ThinDielectric::new(num(&r[0]), num(&r[1]));
        if r[2] == "1" {
            b.specular_reflectance = Spectrum::Constant(REFLECT_TINT);
            b.specular_transmittance = Spectrum::Constant(TRANSMIT_TINT);
        }
        let wi = v3(r, 3);
        let ul = num(&r[6]);
        let (want_wo, want_w, want_pdf, want_eta) = (v3(r, 7), v3(r, 10), num(&r[13]), num(&r[14]));
        let s = b.sample(&AT, wi, ul, Vec2::splat(0.5)).expect("a sample");
        let ctx = format!("{r:?}: ours {s:?}");
        assert_eq!(s.wo, want_wo, "{ctx}");
        assert_eq!(s.weight, want_w, "{ctx}");
        assert_eq!(s.eta, want_eta, "{ctx}");
        assert!(s.delta && s.pdf == f32::INFINITY, "{ctx}");
        let reflected = s.wo.z * wi.z > 0.0;
        let prob = if reflected {
            b.reflectance(wi)
        } else {
            1.0 - b.reflectance(wi)
        };
        assert!(
            close(prob, want_pdf, 1e-6, 1e-7),
            "{ctx}: probability {prob}"
        );
        assert_eq!(b.eval_pdf(&AT, wi, want_wo), (Rgb::ZERO, 0.0));
    }
}

/// `R = F + (1−F)² F / (1 − F²)` (the series of internal bounces), the reflection probability is
/// `R` (stratified `u_lobe`: the fraction is exact to 1/N), the weights are the tints (so the
/// expected weight is `R·tint_r + (1−R)·tint_t`), transmission goes straight through, and the
/// same holds from the back.
#[test]
fn thin_reflects_with_probability_r() {
    let mut b = ThinDielectric::new(1.5, 1.0);
    b.specular_reflectance = Spectrum::Constant(REFLECT_TINT);
    b.specular_transmittance = Spectrum::Constant(TRANSMIT_TINT);
    for (deg, inside) in [(0.0, false), (50.0, false), (85.0, true), (30.0, true)] {
        let wi = incident(deg, inside);
        let f = f64::from(fresnel_dielectric(wi.z.abs(), 1.5).0);
        let series = f + (1.0 - f) * (1.0 - f) * f / (1.0 - f * f);
        let r = b.reflectance(wi);
        assert!(
            (f64::from(r) - series).abs() <= 1e-6,
            "θ={deg}: {r} vs {series}"
        );
        let n = 100_000;
        let mut reflected = 0;
        for k in 0..n {
            let ul = (k as f32 + 0.5) / n as f32;
            let s = b.sample(&AT, wi, ul, Vec2::ZERO).expect("a sample");
            assert_eq!(s.eta, 1.0);
            if s.wo.z * wi.z > 0.0 {
                assert_eq!(s.wo, Vec3::new(-wi.x, -wi.y, wi.z));
                assert_eq!(s.weight, REFLECT_TINT);
                reflected += 1;
            } else {
                assert_eq!(s.wo, -wi);
                assert_eq!(s.weight, TRANSMIT_TINT);
            }
        }
        let frac = reflected as f64 / n as f64;
        assert!(
            (frac - f64::from(r)).abs() <= 2.0 / n as f64,
            "θ={deg}: {frac} vs {r}"
        );
    }
    // Index-matched: no reflection at all; grazing: all of it.
    let matched = ThinDielectric::new(1.2, 1.2);
    assert_eq!(matched.reflectance(incident(60.0, false)), 0.0);
    assert_eq!(b.reflectance(Vec3::X), 1.0);
    assert!(b.transmits() && !b.has_smooth_lobe());
}

// ---------------------------------------------------------------------------------------------
// (5) Loader
// ---------------------------------------------------------------------------------------------

const FILE: &str = "test.xml";

fn scene(body: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <film type="hdrfilm"><rfilter type="box"/></film>
    </sensor>
{body}
</scene>
"#
    )
}

fn load(xml: &str) -> Result<fireflies::render::scene::SceneDesc, Error> {
    load_str(xml, Path::new("."), FILE)
}

fn debug_eq(a: &dyn std::fmt::Debug, b: &dyn std::fmt::Debug) -> bool {
    format!("{a:?}") == format!("{b:?}")
}

#[test]
fn loads_both_plugins_with_mitsuba_defaults() {
    let xml = scene(
        r#"    <shape type="disk"><bsdf type="roughdielectric"/></shape>
    <shape type="disk">
        <bsdf type="roughdielectric">
            <string name="distribution" value="GGX"/>
            <float name="alpha" value="0.25"/>
            <string name="int_ior" value="water"/>
            <float name="ext_ior" value="1.1"/>
            <boolean name="sample_visible" value="true"/>
            <rgb name="specular_reflectance" value="0.9, 0.5, 0.2"/>
            <rgb name="specular_transmittance" value="0.3, 0.6, 0.8"/>
        </bsdf>
    </shape>
    <shape type="disk"><bsdf type="thindielectric"/></shape>
    <shape type="disk">
        <bsdf type="thindielectric">
            <float name="int_ior" value="3"/>
            <string name="ext_ior" value="vacuum"/>
            <float name="specular_transmittance" value="0.5"/>
        </bsdf>
    </shape>"#,
    );
    let s = load(&xml).expect("loads");
    assert!(debug_eq(
        &s.shapes[0].bsdf,
        &rough(Distribution::Beckmann, 0.1, BK7, AIR)
    ));
    let want = tinted(rough(Distribution::Ggx, 0.25, 1.333, 1.1));
    assert!(debug_eq(&s.shapes[1].bsdf, &want), "{:?}", s.shapes[1].bsdf);
    assert!(debug_eq(&s.shapes[2].bsdf, &ThinDielectric::new(BK7, AIR)));
    let mut thin = ThinDielectric::new(3.0, 1.0);
    thin.specular_transmittance = Spectrum::grey(0.5);
    assert!(debug_eq(&s.shapes[3].bsdf, &thin), "{:?}", s.shapes[3].bsdf);
    for shape in &s.shapes {
        assert!(shape.bsdf.transmits());
    }
}

/// Loads `body`, expects an `Error::Scene` on the line of `needle`, about element `element`
/// (which names the parameter), whose message contains each of `fragments`.
fn expect_error(body: &str, needle: &str, element: &str, fragments: &[&str]) {
    let xml = scene(body);
    let err = load(&xml).expect_err("must not load");
    let text = err.to_string();
    let line = xml[..xml.find(needle).expect("needle")]
        .matches('\n')
        .count() as u32
        + 1;
    match &err {
        Error::Scene {
            line: got_line,
            element: got_element,
            message,
            ..
        } => {
            assert_eq!(*got_line, line, "{text}");
            assert_eq!(got_element, element, "{text}");
            for f in fragments {
                assert!(message.contains(f), "{f:?} not in {text}");
            }
        }
        other => panic!("expected Error::Scene, got {other:?}"),
    }
}

#[test]
fn loader_errors_name_the_parameter() {
    for (value, fragment) in [("0", "alpha = 0"), ("-0.1", "alpha = -0.1")] {
        expect_error(
            &format!(
                r#"<shape type="disk"><bsdf type="roughdielectric">
        <float name="alpha" value="{value}"/>
    </bsdf></shape>"#
            ),
            "<float name=\"alpha\"",
            "float name=\"alpha\"",
            &[fragment, "> 0"],
        );
    }
    expect_error(
        r#"<shape type="disk"><bsdf type="roughdielectric">
        <string name="distribution" value="phong"/>
    </bsdf></shape>"#,
        "<string name=\"distribution\"",
        "string name=\"distribution\"",
        &["\"phong\"", "beckmann", "ggx"],
    );
    expect_error(
        r#"<shape type="disk"><bsdf type="roughdielectric">
        <float name="alpha_u" value="0.1"/>
        <float name="alpha_v" value="0.2"/>
    </bsdf></shape>"#,
        "<float name=\"alpha_u\"",
        "float name=\"alpha_u\"",
        &["alpha_u", "anisotropic"],
    );
    expect_error(
        r#"<shape type="disk"><bsdf type="roughdielectric">
        <boolean name="sample_visible" value="false"/>
    </bsdf></shape>"#,
        "<boolean name=\"sample_visible\"",
        "boolean name=\"sample_visible\"",
        &["sample_visible"],
    );
    expect_error(
        r#"<shape type="disk"><bsdf type="roughdielectric">
        <float name="int_ior" value="1.2"/>
        <float name="ext_ior" value="1.2"/>
    </bsdf></shape>"#,
        "<float name=\"int_ior\"",
        "float name=\"int_ior\"",
        &["must differ"],
    );
    expect_error(
        r#"<shape type="disk"><bsdf type="thindielectric">
        <string name="int_ior" value="glass"/>
    </bsdf></shape>"#,
        "<string name=\"int_ior\"",
        "string name=\"int_ior\"",
        &["\"glass\"", "bk7"],
    );
    expect_error(
        r#"<shape type="disk"><bsdf type="thindielectric">
        <float name="alpha" value="0.1"/>
    </bsdf></shape>"#,
        "<float name=\"alpha\"",
        "float name=\"alpha\"",
        &["alpha"],
    );
}
