//! Tests of `plastic` and `roughplastic` (`src/render/bsdfs/plastic.rs`, `roughplastic.rs`):
//! values against Mitsuba 3.9.1, the sampler against its density (chi-square), the mean sample
//! weight against the albedo by quadrature, and the loader.
//!
//! All randomness comes from fixed seeds; the stated false-failure probabilities are over a
//! random choice of seeds.

use fireflies::render::bsdfs::microfacet::Distribution;
use fireflies::render::bsdfs::plastic::Plastic;
use fireflies::render::bsdfs::roughplastic::RoughPlastic;
use fireflies::render::bsdfs::{Bsdf, SurfacePoint, reflect_z};
use fireflies::render::mitsuba::load_str;
use fireflies::render::scene::Rgb;
use fireflies::render::textures::Spectrum;
use glam::{Vec2, Vec3};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::collections::HashMap;
use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;

static AT: std::sync::LazyLock<SurfacePoint> = std::sync::LazyLock::new(SurfacePoint::default);

fn rng(seed: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(seed)
}

fn u2(r: &mut Xoshiro256PlusPlus) -> Vec2 {
    Vec2::new(r.random::<f32>(), r.random::<f32>())
}

/// Unit direction at polar angle `theta_deg` and azimuth 0.7 (off the axes).
fn incident(theta_deg: f32) -> Vec3 {
    let t = theta_deg.to_radians();
    Vec3::new(t.sin() * 0.7_f32.cos(), t.sin() * 0.7_f32.sin(), t.cos())
}

fn rough(dist: Distribution, alpha: f32, nonlinear: bool) -> RoughPlastic {
    RoughPlastic::new(
        dist,
        alpha,
        1.5,
        Spectrum::Constant(Rgb::new(0.2, 0.45, 0.75)),
        None,
        nonlinear,
    )
}

// ---------------------------------------------------------------------------------------------
// (1) Values against Mitsuba
// ---------------------------------------------------------------------------------------------

/// One row of `tests/data/plastic/plastic.csv` (see `make_fixture.py` there).
struct Row {
    kind: String,
    /// The material's columns joined, to build each material once.
    key: String,
    plugin: String,
    distribution: String,
    alpha: f32,
    eta: f32,
    nonlinear: bool,
    specular: Option<f32>,
    diffuse: Rgb,
    sample_visible: bool,
    wi: Vec3,
    /// `wo` for `eval` rows; `(u_lobe, u1, u2)` for sample rows.
    a: Vec3,
    /// eval RGB, pdf, eval_pdf RGB, eval_pdf pdf; or weight RGB, pdf, wo.
    v: [f32; 8],
}

fn fixture() -> Vec<Row> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/plastic/plastic.csv");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    text.lines()
        .skip(1)
        .map(|line| {
            let c: Vec<&str> = line.split(',').collect();
            assert_eq!(c.len(), 26, "{line}");
            let f = |i: usize| c[i].parse::<f64>().expect("number") as f32;
            let specular = f(7);
            Row {
                kind: c[0].to_owned(),
                key: c[1..12].join(","),
                plugin: c[1].to_owned(),
                distribution: c[2].to_owned(),
                alpha: f(3),
                // Mitsuba divides in single precision, as we do.
                eta: f(4) / f(5),
                nonlinear: c[6] == "1",
                specular: (specular >= 0.0).then_some(specular),
                diffuse: Rgb::new(f(8), f(9), f(10)),
                sample_visible: c[11] == "1",
                wi: Vec3::new(f(12), f(13), f(14)),
                a: Vec3::new(f(15), f(16), f(17)),
                v: std::array::from_fn(|i| f(18 + i)),
            }
        })
        .collect()
}

fn build(r: &Row) -> Arc<dyn Bsdf> {
    let diffuse = Spectrum::Constant(r.diffuse);
    let specular = r.specular.map(Spectrum::grey);
    match r.plugin.as_str() {
        "plastic" => Arc::new(Plastic::new(r.eta, diffuse, specular, r.nonlinear)),
        "roughplastic" => Arc::new(
            RoughPlastic::new(
                Distribution::from_name(&r.distribution).expect("distribution"),
                r.alpha,
                r.eta,
                diffuse,
                specular,
                r.nonlinear,
            )
            .with_sample_visible(r.sample_visible),
        ),
        other => panic!("unknown plugin {other}"),
    }
}

/// `|a − b| ≤ abs + rel · max(|a|, |b|)`.
fn close(a: f32, b: f32, rel: f32, abs: f32) -> bool {
    (a - b).abs() <= abs + rel * a.abs().max(b.abs())
}

fn rgb_close(a: Rgb, b: Rgb, rel: f32, abs: f32) -> bool {
    (0..3).all(|i| close(a[i], b[i], rel, abs))
}

/// `eval` and `pdf` equal Mitsuba's at 12 materials × 44 direction pairs (both plugins, GGX and
/// Beckmann, α from 0.02 to 0.5, `nonlinear` on and off, η above and below 1, a
/// `specular_reflectance`, `sample_visible = false`; cosines from 1 down to 10⁻³, near and far
/// from the mirror direction, below the horizon), and `sample` gives Mitsuba's direction, pdf
/// and weight for the same random numbers (GGX and the cosine lobe use Mitsuba's warps; Beckmann
/// normals differ from Mitsuba's by its Newton residual, so there our value and pdf are compared
/// at Mitsuba's direction).
///
/// Tolerance: 1e-4 relative (f32 rounding of differently ordered operations, and for Beckmann the
/// transmittance tables built from normals within 1e-5 of Mitsuba's), plus 1e-9 absolute for
/// values that cancel to nearly 0 at grazing angles. A wrong table recipe (e.g. the
/// cosine-weighted mean instead of Mitsuba's plain mean, or 64 vs 63 intervals) shifts the
/// diffuse lobe by far more.
#[test]
fn matches_mitsuba_fixture() {
    let rows = fixture();
    assert_eq!(rows.len(), 12 * (44 + 27));
    let mut cache: HashMap<String, Arc<dyn Bsdf>> = HashMap::new();
    let (mut evals, mut samples, mut deltas) = (0, 0, 0);
    for r in &rows {
        let bsdf = cache
            .entry(r.key.clone())
            .or_insert_with(|| build(r))
            .clone();
        let ctx = format!("{} {} wi={} a={}", r.kind, r.key, r.wi, r.a);
        let m_value = Rgb::new(r.v[0], r.v[1], r.v[2]);
        let m_pdf = r.v[3];
        match r.kind.as_str() {
            "eval" => {
                evals += 1;
                // Mitsuba's own eval_pdf agrees with its eval and pdf.
                assert!(rgb_close(
                    m_value,
                    Rgb::new(r.v[4], r.v[5], r.v[6]),
                    1e-6,
                    0.0
                ));
                assert!(close(m_pdf, r.v[7], 1e-6, 0.0), "{ctx}");
                let (value, pdf) = bsdf.eval_pdf(&AT, r.wi, r.a);
                assert!(
                    rgb_close(value, m_value, 1e-4, 1e-9),
                    "eval {value} vs Mitsuba {m_value} at {ctx}"
                );
                assert!(
                    close(pdf, m_pdf, 1e-4, 1e-9),
                    "pdf {pdf} vs Mitsuba {m_pdf} at {ctx}"
                );
            }
            "sample" => {
                samples += 1;
                let m_wo = Vec3::new(r.v[4], r.v[5], r.v[6]);
                let s = bsdf.sample(&AT, r.wi, r.a.x, Vec2::new(r.a.y, r.a.z));
                if m_pdf == 0.0 {
                    // Mitsuba's sample was invalid (a reflection below the horizon).
                    assert!(m_value == Rgb::ZERO && s.is_none(), "{ctx}: {s:?}");
                    continue;
                }
                let s = s.unwrap_or_else(|| panic!("no sample at {ctx}"));
                assert!(!s.delta && s.eta == 1.0, "{ctx}");
                assert!(
                    (s.wo - m_wo).abs().max_element() <= 2e-4,
                    "wo {} vs Mitsuba {m_wo} at {ctx}",
                    s.wo
                );
                if r.distribution == "beckmann" {
                    let (value, pdf) = bsdf.eval_pdf(&AT, r.wi, m_wo);
                    assert!(close(pdf, m_pdf, 1e-4, 0.0), "pdf {pdf} at {ctx}");
                    assert!(
                        rgb_close(value / pdf, m_value, 1e-4, 1e-9),
                        "weight {} vs Mitsuba {m_value} at {ctx}",
                        value / pdf
                    );
                } else {
                    assert!(close(s.pdf, m_pdf, 1e-4, 0.0), "pdf {} at {ctx}", s.pdf);
                    assert!(
                        rgb_close(s.weight, m_value, 1e-4, 1e-9),
                        "weight {} vs Mitsuba {m_value} at {ctx}",
                        s.weight
                    );
                }
            }
            "sample_delta" => {
                deltas += 1;
                let s = bsdf
                    .sample(&AT, r.wi, r.a.x, Vec2::new(r.a.y, r.a.z))
                    .unwrap_or_else(|| panic!("no sample at {ctx}"));
                assert!(s.delta && s.pdf == f32::INFINITY, "{ctx}: {s:?}");
                assert_eq!(s.wo, reflect_z(r.wi), "{ctx}");
                // Mitsuba's weight already divides by the lobe probability (its pdf).
                assert!(
                    rgb_close(s.weight, m_value, 1e-4, 0.0),
                    "weight {} vs Mitsuba {m_value} at {ctx}",
                    s.weight
                );
            }
            other => panic!("unknown row kind {other}"),
        }
    }
    eprintln!("{evals} eval rows, {samples} smooth samples, {deltas} delta samples");
    assert!(samples > 100 && deltas > 10);
}

// ---------------------------------------------------------------------------------------------
// Quadrature over the sphere on a grid adapted to the lobe (as in tests/render_bsdf.rs)
// ---------------------------------------------------------------------------------------------

const THETA_BINS: usize = 20;
const PHI_BINS: usize = 40;
const PILOT_SAMPLES: usize = 100_000;

/// 5-point Gauss–Legendre nodes and weights on [−1, 1].
const GL5: [(f64, f64); 5] = [
    (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.0, 0.568_888_888_888_888_9),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.906_179_845_938_664, 0.236_926_885_056_189_1),
];

/// Cells `[θ_k, θ_k+1] × [φ_j, φ_j+1]` with marginal quantiles of pilot samples as interior
/// edges, and the horizon always an edge (the densities jump there).
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
        let (mut th, mut ph): (Vec<f64>, Vec<f64>) = (0..PILOT_SAMPLES)
            .filter_map(|_| {
                let ul = r.random::<f32>();
                sample(ul, u2(&mut r))
            })
            .map(spherical)
            .unzip();
        assert!(th.len() >= 1000, "too few pilot samples");
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

    /// `∫ f dω` over every cell, by adaptive Gauss–Legendre cubature.
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

/// Integral of `g` over `rect`, refining into quadrants until one level and the next agree to
/// 1e-5 relative (or 1e-10 absolute), at most 10 levels deep.
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
    if depth >= 10 || (coarse - fine).abs() <= (1e-5 * fine.abs()).max(1e-10) {
        return fine;
    }
    quads
        .iter()
        .map(|&q| adaptive_cubature(g, q, depth + 1))
        .sum()
}

// ---------------------------------------------------------------------------------------------
// (2) Chi-square: the sampler against its density
// ---------------------------------------------------------------------------------------------

const CHI2_SAMPLES: usize = 1_000_000;
const MIN_EXPECTED: f64 = 5.0;

/// Chi-square tests a correct implementation must pass in this file: GGX at 3 roughnesses × 3
/// incidences, Beckmann at 2 × 2.
const CHI2_FAMILY_SIZE: usize = 9 + 4;

/// Family-wise false-failure probability 1%: each test runs at the Šidák level
/// `1 − 0.99^(1/13) ≈ 7.7e-4`. With about 800 cells (critical value near 930) a defect is caught
/// with 90% probability once `N Σ (p − q)²/q` exceeds about 190, i.e. with `N = 10⁶` a density
/// error of about ±1.4% spread over the lobe (±4.4% on a tenth of its mass); the wrong density of
/// [`chi_square_detects_a_wrong_density`] (10% roughness shift) is far beyond that.
fn chi2_level() -> f64 {
    1.0 - 0.99_f64.powf(1.0 / CHI2_FAMILY_SIZE as f64)
}

/// Pearson's chi-square p-value of `sample` against the solid-angle density `pdf`; rejected
/// samples form their own bin, expected to hold the mass `1 − ∫ pdf`.
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
    // Pool the sparse bins into one.
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
    // A pool too small to stand alone (e.g. the few samples the sampler rejects where f32
    // rounding puts a cosine-weighted direction exactly on the horizon, mass ~1e-7) joins the
    // smallest kept bin, so that one such sample cannot dominate the statistic.
    if pool_o > 0.0 || pool_e > 0.0 {
        if pool_e >= MIN_EXPECTED || kept.is_empty() {
            kept.push((pool_o, pool_e));
        } else {
            let i = (0..kept.len())
                .min_by(|&a, &b| kept[a].1.total_cmp(&kept[b].1))
                .expect("non-empty");
            kept[i].0 += pool_o;
            kept[i].1 += pool_e;
        }
    }
    assert!(kept.len() >= 2, "grid degenerate");
    let statistic: f64 = kept.iter().map(|&(o, e)| (o - e) * (o - e) / e).sum();
    let dof = kept.len() - 1;
    let p = ChiSquared::new(dof as f64).expect("dof").sf(statistic);
    eprintln!(
        "chi2 {statistic:.1} dof {dof} p {p:.3e} (mass outside {:.2e})",
        1.0 - total
    );
    p
}

/// The true density of `RoughPlastic::sample`: the lobe mixture with the *exact* visible-normal
/// density (`pdf_visible`, exact Smith `G1`), which for GGX is the reported pdf itself.
fn true_density(b: &RoughPlastic, wi: Vec3, wo: Vec3) -> f64 {
    let reported = b.pdf(&AT, wi, wo);
    if b.microfacet().distribution() == Distribution::Ggx || reported == 0.0 {
        return f64::from(reported);
    }
    // Swap the specular part: p·pdf_mitsuba(h)/(4 wo·h) for p·pdf_visible(h)/(4 wo·h).
    let mf = b.microfacet();
    let h = (wi + wo).normalize();
    let p_spec = f64::from(b.specular_probability(wi));
    let spec = f64::from(mf.pdf_visible(wi, h)) / (4.0 * f64::from(wo.dot(h)));
    p_spec * spec + (1.0 - p_spec) * f64::from(wo.z) / PI
}

#[test]
fn ggx_sampler_matches_its_pdf() {
    let mut seed = 100;
    for alpha in [0.05, 0.3, 1.0] {
        let b = rough(Distribution::Ggx, alpha, false);
        for theta in [0.0, 45.0, 80.0] {
            let wi = incident(theta);
            eprint!("GGX alpha {alpha} theta {theta}: ");
            let sample = |ul: f32, u: Vec2| b.sample(&AT, wi, ul, u).map(|s| s.wo);
            let p = chi2_p_value(&sample, &|wo| f64::from(b.pdf(&AT, wi, wo)), seed);
            assert!(
                p >= chi2_level(),
                "GGX alpha {alpha} theta {theta}: p = {p:.3e}"
            );
            seed += 2;
        }
    }
}

/// Beckmann is tested against the density it truly samples (exact Smith `G1` in the
/// visible-normal density); the reported pdf (Mitsuba's, with the fitted `G1`) is within 0.35%
/// of it in the specular part, checked here directly.
#[test]
fn beckmann_sampler_matches_its_true_density() {
    let mut seed = 200;
    for alpha in [0.1, 0.3] {
        let b = rough(Distribution::Beckmann, alpha, true);
        for theta in [30.0, 80.0] {
            let wi = incident(theta);
            eprint!("Beckmann alpha {alpha} theta {theta}: ");
            let sample = |ul: f32, u: Vec2| b.sample(&AT, wi, ul, u).map(|s| s.wo);
            let p = chi2_p_value(&sample, &|wo| true_density(&b, wi, wo), seed);
            assert!(
                p >= chi2_level(),
                "Beckmann alpha {alpha} theta {theta}: p = {p:.3e}"
            );
            seed += 2;
            let mut r = rng(seed);
            for _ in 0..10_000 {
                let Some(s) = b.sample(&AT, wi, r.random(), u2(&mut r)) else {
                    continue;
                };
                let t = true_density(&b, wi, s.wo);
                assert!(
                    (f64::from(s.pdf) / t - 1.0).abs() <= 3.5e-3,
                    "reported {} vs true {t}",
                    s.pdf
                );
            }
        }
    }
}

/// The test has power: a density with a 10% larger roughness than sampled is rejected.
#[test]
fn chi_square_detects_a_wrong_density() {
    let b = rough(Distribution::Ggx, 0.2, false);
    let wrong = rough(Distribution::Ggx, 0.22, false);
    let wi = incident(45.0);
    let sample = |ul: f32, u: Vec2| b.sample(&AT, wi, ul, u).map(|s| s.wo);
    let p = chi2_p_value(&sample, &|wo| f64::from(wrong.pdf(&AT, wi, wo)), 300);
    assert!(p < chi2_level(), "a wrong density passed: p = {p:.3e}");
}

// ---------------------------------------------------------------------------------------------
// (3) Mean sample weight against the albedo
// ---------------------------------------------------------------------------------------------

/// `E[weight] = ∫ eval dωo` (the directional albedo, by quadrature on a lobe-adapted grid) for
/// both plugins, GGX at three roughnesses, three incidences. For Beckmann the sampler's true
/// density `q` differs from the reported `pdf` (Mitsuba's fitted `G1`), so its expectation is
/// `∫ eval · q / pdf dωo` — Mitsuba's own bias, within 0.35% of the albedo — and that is what is
/// checked; the albedo itself must be within 0.35%.
///
/// Each check is `|mean − expected| ≤ 5 SE + 2e-4 · expected` per channel (SE from the sample
/// variance of 200 000 weights; 2e-4 covers the quadrature's 1e-5 per cell over 800 cells).
/// A correct implementation fails one of the 3 channels × 23 cases with probability about
/// 69 × 5.7e-7 ≈ 4e-5 (normal tails); a 1% error in the weights is at least 7 SE for every case
/// here and is caught.
#[test]
fn mean_weight_is_the_albedo() {
    let n = 200_000;
    let mut seed = 400;
    let mut cases: Vec<(String, Arc<dyn Bsdf>, Option<RoughPlastic>)> = Vec::new();
    for alpha in [0.05, 0.3, 1.0] {
        let b = rough(Distribution::Ggx, alpha, alpha > 0.1);
        cases.push((format!("GGX {alpha}"), Arc::new(b.clone()), Some(b)));
    }
    for alpha in [0.1, 0.3] {
        let b = rough(Distribution::Beckmann, alpha, false);
        cases.push((format!("Beckmann {alpha}"), Arc::new(b.clone()), Some(b)));
    }
    let plastic = Plastic::new(
        1.5,
        Spectrum::Constant(Rgb::new(0.8, 0.25, 0.1)),
        Some(Spectrum::grey(0.7)),
        true,
    );
    cases.push(("plastic".into(), Arc::new(plastic.clone()), None));
    for (name, bsdf, rough) in &cases {
        for theta in [0.0, 60.0, 85.0] {
            let wi = incident(theta);
            let mut r = rng(seed);
            seed += 1;
            let (mut sum, mut sum2) = ([0.0_f64; 3], [0.0_f64; 3]);
            let mut delta_sum = [0.0_f64; 3];
            for _ in 0..n {
                let Some(s) = bsdf.sample(&AT, wi, r.random(), u2(&mut r)) else {
                    continue;
                };
                for c in 0..3 {
                    let w = f64::from(s.weight[c]);
                    sum[c] += w;
                    sum2[c] += w * w;
                    if s.delta {
                        delta_sum[c] += w;
                    }
                }
            }
            let grid = Grid::for_sampler(
                &|ul, u| bsdf.sample(&AT, wi, ul, u).map(|s| s.wo),
                seed + 1000,
            );
            for c in 0..3 {
                let albedo: f64 = grid
                    .integrate(&|wo| f64::from(bsdf.eval(&AT, wi, wo)[c]))
                    .iter()
                    .sum();
                let mut expected = albedo;
                if let Some(b) = rough
                    .as_ref()
                    .filter(|b| b.microfacet().distribution() == Distribution::Beckmann)
                {
                    expected = grid
                        .integrate(&|wo| {
                            let (v, pdf) = b.eval_pdf(&AT, wi, wo);
                            if pdf > 0.0 {
                                f64::from(v[c]) * true_density(b, wi, wo) / f64::from(pdf)
                            } else {
                                0.0
                            }
                        })
                        .iter()
                        .sum();
                    assert!((expected / albedo - 1.0).abs() < 3.5e-3, "{name}");
                }
                if rough.is_none() {
                    // plastic's mirror lobe: E[delta weights] = F(cos θi) · specular_reflectance.
                    let f = fireflies::render::bsdfs::fresnel::fresnel_dielectric(wi.z, 1.5).0;
                    expected += f64::from(f) * 0.7;
                    let mean_delta = delta_sum[c] / n as f64;
                    assert!(mean_delta > 0.0 || f == 0.0, "{name}: no mirror samples");
                }
                let mean = sum[c] / n as f64;
                let var = (sum2[c] / n as f64 - mean * mean).max(0.0);
                let se = (var / n as f64).sqrt();
                eprintln!(
                    "{name} theta {theta} ch {c}: mean {mean:.6} expected {expected:.6} \
                     (albedo {albedo:.6}) se {se:.2e}"
                );
                assert!(
                    (mean - expected).abs() <= 5.0 * se + 2e-4 * expected,
                    "{name} theta {theta} channel {c}: mean weight {mean} vs {expected} \
                     (se {se:.2e})"
                );
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// (4) Loader
// ---------------------------------------------------------------------------------------------

const SENSOR: &str = r#"<sensor type="perspective">
        <float name="fov" value="45"/>
        <film type="hdrfilm"><rfilter type="box"/></film>
    </sensor>"#;

fn scene(bsdfs: &[&str]) -> String {
    let shapes: String = bsdfs
        .iter()
        .map(|b| format!("    <shape type=\"rectangle\">{b}</shape>\n"))
        .collect();
    format!("<scene version=\"3.0.0\">\n    {SENSOR}\n{shapes}</scene>\n")
}

fn load_err(bsdf: &str) -> String {
    match load_str(&scene(&[bsdf]), Path::new("."), "test.xml") {
        Ok(_) => panic!("{bsdf} must not load"),
        Err(e) => e.to_string(),
    }
}

/// Both plugins load with Mitsuba's defaults and with every parameter; the loaded material is
/// the one the constructors build (same values); textured reflectances read `uv`.
#[test]
fn loader_reads_both_plugins() {
    let xml = scene(&[
        r#"<bsdf type="plastic"/>"#,
        r#"<bsdf type="roughplastic"/>"#,
        r#"<bsdf type="roughplastic">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.2"/>
            <string name="int_ior" value="bk7"/>
            <float name="ext_ior" value="1"/>
            <rgb name="diffuse_reflectance" value="0.2, 0.45, 0.75"/>
            <float name="specular_reflectance" value="0.8"/>
            <boolean name="nonlinear" value="true"/>
            <boolean name="sample_visible" value="true"/>
        </bsdf>"#,
        r#"<bsdf type="plastic">
            <texture type="checkerboard" name="diffuse_reflectance"/>
            <float name="int_ior" value="1.5"/>
            <boolean name="nonlinear" value="true"/>
        </bsdf>"#,
    ]);
    let scene = load_str(&xml, Path::new("."), "test.xml").expect("loads");
    let b: Vec<&Arc<dyn Bsdf>> = scene.shapes.iter().map(|s| &s.bsdf).collect();
    let wi = incident(40.0);
    let wo = Vec3::new(-0.3, 0.2, 0.5).normalize();
    let pairs: [(Arc<dyn Bsdf>, _); 3] = [
        (
            Arc::new(Plastic::new(
                1.49 / 1.000277,
                Spectrum::grey(0.5),
                None,
                false,
            )),
            b[0],
        ),
        (
            Arc::new(RoughPlastic::new(
                Distribution::Beckmann,
                0.1,
                1.49 / 1.000277,
                Spectrum::grey(0.5),
                None,
                false,
            )),
            b[1],
        ),
        (
            Arc::new(RoughPlastic::new(
                Distribution::Ggx,
                0.2,
                1.5046,
                Spectrum::Constant(Rgb::new(0.2, 0.45, 0.75)),
                Some(Spectrum::grey(0.8)),
                true,
            )),
            b[2],
        ),
    ];
    for (want, got) in pairs {
        assert_eq!(want.eval_pdf(&AT, wi, wo), got.eval_pdf(&AT, wi, wo));
        assert!(!got.uses_uv() && got.has_smooth_lobe());
    }
    assert!(b[3].uses_uv());
    let at = |u: f32, v: f32| SurfacePoint {
        uv: Vec2::new(u, v),
        ..SurfacePoint::default()
    };
    assert_ne!(
        b[3].eval(&at(0.25, 0.25), wi, wo),
        b[3].eval(&at(0.75, 0.25), wi, wo),
        "the checkerboard's two colours"
    );
}

#[test]
fn loader_errors_name_the_parameter() {
    for (bsdf, fragments) in [
        (
            r#"<bsdf type="roughplastic"><float name="alpha" value="0"/></bsdf>"#,
            &["alpha", "> 0"][..],
        ),
        (
            r#"<bsdf type="roughplastic"><float name="alpha" value="-0.1"/></bsdf>"#,
            &["alpha", "> 0"][..],
        ),
        (
            r#"<bsdf type="roughplastic"><string name="distribution" value="phong"/></bsdf>"#,
            &["distribution", "phong", "beckmann", "ggx"][..],
        ),
        (
            r#"<bsdf type="roughplastic"><float name="alpha_u" value="0.1"/></bsdf>"#,
            &["alpha_u", "anisotropic"][..],
        ),
        (
            r#"<bsdf type="roughplastic"><float name="alpha_v" value="0.1"/></bsdf>"#,
            &["alpha_v"][..],
        ),
        (
            r#"<bsdf type="roughplastic"><float name="int_ior" value="1.3"/><float name="ext_ior" value="1.3"/></bsdf>"#,
            &["int_ior", "ext_ior", "differ"][..],
        ),
        (
            r#"<bsdf type="plastic"><float name="alpha" value="0.1"/></bsdf>"#,
            &["alpha", "unknown parameter"][..],
        ),
        (
            r#"<bsdf type="plastic"><string name="int_ior" value="unobtainium"/></bsdf>"#,
            &["unobtainium", "index of refraction"][..],
        ),
        (
            r#"<bsdf type="roughplastic"><rgb name="diffuse_reflectanse" value="0.5"/></bsdf>"#,
            &[
                "diffuse_reflectanse",
                "did you mean \"diffuse_reflectance\"",
            ][..],
        ),
    ] {
        let text = load_err(bsdf);
        for f in fragments {
            assert!(text.contains(f), "{f:?} not in {text}");
        }
        assert!(text.starts_with("test.xml:"), "{text}");
    }
}

/// A black material (both reflectances 0) neither panics nor produces NaN: Mitsuba's lobe
/// weight would be 0/0 there.
#[test]
fn black_material_is_finite() {
    let black = RoughPlastic::new(
        Distribution::Ggx,
        0.2,
        1.5,
        Spectrum::grey(0.0),
        Some(Spectrum::grey(0.0)),
        false,
    );
    let p = Plastic::new(1.5, Spectrum::grey(0.0), Some(Spectrum::grey(0.0)), false);
    let wi = incident(30.0);
    let mut r = rng(7);
    for b in [&black as &dyn Bsdf, &p] {
        for _ in 0..1000 {
            if let Some(s) = b.sample(&AT, wi, r.random(), u2(&mut r)) {
                assert!(s.weight.is_finite() && !s.pdf.is_nan(), "{s:?}");
            }
        }
    }
}
