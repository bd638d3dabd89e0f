//! `render --nfor`: the half buffers, features and per-half estimators NFOR denoising reads
//! (src/render/nfor_buffers.rs), on small hand-made scenes with known answers.
//!
//! Exact checks recompute each sample's camera ray from the same random stream the film uses
//! (its first two numbers place the sample in the pixel), so expected features are exact up to
//! f32 rounding. The one statistical test states its false-failure probability where it is.

use fireflies::estimators::EstimatorSpec;
use fireflies::image::Image;
use fireflies::render::bsdfs::conductor::Conductor;
use fireflies::render::bsdfs::dielectric::Dielectric;
use fireflies::render::bsdfs::diffuse::Diffuse;
use fireflies::render::bsdfs::mask::Mask;
use fireflies::render::bsdfs::plastic::Plastic;
use fireflies::render::bsdfs::twosided::TwoSided;
use fireflies::render::bsdfs::{Bsdf, SurfacePoint};
use fireflies::render::film::{self, FilmConfig, FilmOutput};
use fireflies::render::integrator::radiance;
use fireflies::render::mitsuba::load_str;
use fireflies::render::nfor_buffers::{HalfBuffer, NforBuffers};
use fireflies::render::sampler::SampleStream;
use fireflies::render::textures::Spectrum;
use fireflies::render::textures::checkerboard::Checkerboard;
use fireflies::render::world::World;
use glam::{Mat3, Vec2, Vec3};
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn world(xml: &str) -> World {
    let scene = load_str(xml, Path::new("."), "test.xml").expect("scene loads");
    World::new(&scene)
}

/// A camera at `(0, 0, 5)` looking down `-z` at the origin, `size`² pixels, box filter.
fn sensor(fov: f32, size: u32) -> String {
    format!(
        r#"<sensor type="perspective">
            <float name="fov" value="{fov}"/>
            <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/><rfilter type="box"/></film>
            <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        </sensor>"#
    )
}

/// A diffuse floor with a roughplastic sphere, a glass sphere and a mirror sphere under an
/// environment and a point light: every kind of first hit (direct, through delta lobes, escape).
fn mixed(size: u32) -> World {
    world(&format!(
        r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="6"/></integrator>
            {}
            <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
            <emitter type="point"><rgb name="intensity" value="4"/><point name="position" value="1, 1, 2"/></emitter>
            <shape type="rectangle">
                <transform name="to_world"><scale value="1.5"/></transform>
                <bsdf type="diffuse">
                    <texture type="checkerboard" name="reflectance">
                        <rgb name="color0" value="0.2, 0.5, 0.7"/><rgb name="color1" value="0.8, 0.3, 0.1"/>
                    </texture>
                </bsdf>
            </shape>
            <shape type="sphere"><point name="center" value="0, 0, 0.5"/><float name="radius" value="0.5"/>
                <bsdf type="roughplastic"><string name="distribution" value="ggx"/><float name="alpha" value="0.2"/></bsdf></shape>
            <shape type="sphere"><point name="center" value="0.8, -0.6, 0.3"/><float name="radius" value="0.3"/>
                <bsdf type="dielectric"/></shape>
            <shape type="sphere"><point name="center" value="-0.8, 0.6, 0.3"/><float name="radius" value="0.3"/>
                <bsdf type="conductor"/></shape>
        </scene>"#,
        sensor(45.0, size)
    ))
}

fn config(estimators: &[&str], spp: u32, checkpoints: Vec<u32>) -> FilmConfig {
    FilmConfig {
        estimators: estimators
            .iter()
            .map(|s| s.parse::<EstimatorSpec>().unwrap())
            .collect(),
        spp,
        checkpoints,
        seed: 7,
        dump_pixels: vec![(0, 0)],
        memory: Default::default(),
    }
}

fn render(w: &World, cfg: &FilmConfig, nfor: bool, threads: usize) -> FilmOutput {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| film::render_with_nfor(w, cfg, nfor, |_| {}))
        .unwrap()
}

const ESTIMATORS: [&str; 4] = ["mean", "gmon:M=3", "zirr", "jung:sigma_image=1"];

/// The colour path draws the same numbers with and without `--nfor`: every estimator's image
/// (at a checkpoint and at the end), the dumped stream and the invalid count are bit-identical.
#[test]
fn colour_is_bit_identical_with_and_without_nfor() {
    let w = mixed(12);
    let cfg = config(&ESTIMATORS, 10, vec![5]);
    let plain = render(&w, &cfg, false, 2);
    let with = render(&w, &cfg, true, 2);
    assert!(plain.nfor.is_none() && with.nfor.is_some());
    assert_eq!(plain.images.len(), 8);
    for (a, b) in plain.images.iter().zip(&with.images) {
        assert_eq!((a.estimator, a.spp), (b.estimator, b.spp));
        assert_eq!(
            a.image, b.image,
            "estimator {} at {} spp",
            a.estimator, a.spp
        );
    }
    assert_eq!(plain.dumps, with.dumps);
    assert_eq!(plain.invalid_samples, with.invalid_samples);
    // Not vacuous: the image has light in it.
    assert!(plain.images[0].image.mean()[0] > 0.05);
}

/// Every buffer is a pure function of (seed, pixel, sample): 1 and 3 threads, with and without
/// checkpoints, give identical NFOR outputs (Jung's per-half image spread and Zirr's per-half
/// neighbourhoods included).
#[test]
fn thread_count_and_checkpoints_change_no_buffer() {
    let w = mixed(10);
    let a = render(&w, &config(&ESTIMATORS, 6, vec![]), true, 1);
    let b = render(&w, &config(&ESTIMATORS, 6, vec![3, 5]), true, 3);
    let (a, b) = (a.nfor.unwrap(), b.nfor.unwrap());
    assert_eq!(a, b);
    assert_eq!(a.estimators.len(), 4);
    assert_eq!(a.estimators[1].stem, "gmon_M=3");
    // The halves differ (independent samples), and each is non-trivial.
    assert_ne!(a.color.mean[0], a.color.mean[1]);
    assert_ne!(a.estimators[0].image[0], a.estimators[0].image[1]);
}

fn px(img: &Image, i: usize) -> [f64; 3] {
    img.pixels()[i].map(f64::from)
}

/// With an even spp the halves hold equal counts, so the mean of the two half means is the full
/// mean image, within f32 rounding; the `mean` estimator on each half equals that half's colour
/// mean likewise.
#[test]
fn half_means_average_to_the_full_mean() {
    let w = mixed(12);
    let out = render(&w, &config(&["mean"], 16, vec![]), true, 2);
    let full = &out.images[0].image;
    let nfor = out.nfor.unwrap();
    let mut largest = 0.0f64;
    for i in 0..full.pixels().len() {
        let (a, b, f) = (
            px(&nfor.color.mean[0], i),
            px(&nfor.color.mean[1], i),
            px(full, i),
        );
        for c in 0..3 {
            let tol = 2e-6 * f[c].abs().max(1e-3);
            assert!(
                ((a[c] + b[c]) / 2.0 - f[c]).abs() <= tol,
                "pixel {i}: {a:?} {b:?} {f:?}"
            );
            for h in 0..2 {
                let (m, e) = (
                    px(&nfor.color.mean[h], i)[c],
                    px(&nfor.estimators[0].image[h], i)[c],
                );
                assert!(
                    (m - e).abs() <= 2e-6 * m.abs().max(1e-3),
                    "pixel {i}: {m} {e}"
                );
            }
            largest = largest.max(f[c]);
        }
    }
    assert!(largest > 0.1);
}

/// Per-sample values of channel `c` of a feature, recomputed from the film's streams.
struct Truth {
    /// Per sample index: the camera ray's direction.
    dirs: Vec<Vec3>,
}

fn camera_dirs(w: &World, seed: u64, x: u32, y: u32, spp: u32) -> Truth {
    let index = u64::from(y * w.camera.width() + x);
    let dirs = (0..spp)
        .map(|s| {
            let mut rng = SampleStream::new(seed, index, u64::from(s));
            w.camera.ray(x, y, rng.next_2d()).ray.d
        })
        .collect();
    Truth { dirs }
}

/// Mean and variance of the mean of `values` over the samples of half `h` (two-pass, f64).
fn half_stats(values: &[f64], h: usize) -> (f64, f64) {
    let v: Vec<f64> = values.iter().copied().skip(h).step_by(2).collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let s2 = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, s2 / n)
}

fn assert_close(got: f64, want: f64, rel: f64, abs: f64, what: &str) {
    assert!(
        (got - want).abs() <= rel * want.abs() + abs,
        "{what}: got {got}, want {want}"
    );
}

/// Checks one grey (single-channel) buffer of pixel `i` against per-sample values.
fn check_grey(buf: &HalfBuffer, i: usize, values: &[f64], what: &str) {
    for h in 0..2 {
        let (mean, var) = half_stats(values, h);
        let (m, v) = (px(&buf.mean[h], i), px(&buf.var[h], i));
        assert!(m[0] == m[1] && m[1] == m[2], "{what}: grey");
        assert_close(m[0], mean, 1e-5, 1e-7, what);
        assert_close(v[0], var, 1e-3, 1e-10, what);
    }
}

/// A diffuse floor facing the camera 5 away, lit by a point light at `(0.5, 0, 0.3)` beside a
/// thin wall in the plane `x = 0` that the camera sees edge-on: every feature is known. Normal
/// `+z`; albedo the reflectance; depth `5 / |d.z|` for the sample's camera direction `d`;
/// visibility 1 where `x > 0` (the light's side) and 0 behind the wall.
#[test]
fn features_of_a_diffuse_floor_beside_a_shadowing_wall() {
    let w = world(&format!(
        r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="2"/></integrator>
            {}
            <emitter type="point"><rgb name="intensity" value="1"/><point name="position" value="0.5, 0, 0.3"/></emitter>
            <shape type="rectangle">
                <transform name="to_world"><scale value="3"/></transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.6"/></bsdf>
            </shape>
            <shape type="rectangle">
                <transform name="to_world"><scale x="0.6" y="10"/><rotate y="1" angle="90"/><translate z="0.5"/></transform>
                <bsdf type="twosided"><bsdf type="diffuse"/></bsdf>
            </shape>
        </scene>"#,
        sensor(30.0, 8)
    ));
    let spp = 8;
    let cfg = config(&["mean"], spp, vec![]);
    let nfor = render(&w, &cfg, true, 2).nfor.unwrap();
    let (mut lit, mut dark) = (0, 0);
    for y in 0..8u32 {
        for x in 0..8u32 {
            let i = (y * 8 + x) as usize;
            let truth = camera_dirs(&w, cfg.seed, x, y, spp);
            for h in 0..2 {
                assert_eq!(px(&nfor.normal.mean[h], i), [0.0, 0.0, 1.0]);
                assert_eq!(px(&nfor.normal.var[h], i), [0.0; 3]);
                let albedo = px(&nfor.albedo.mean[h], i);
                assert_eq!(albedo, [0.2f32, 0.4, 0.6].map(f64::from));
                assert_eq!(px(&nfor.albedo.var[h], i), [0.0; 3]);
            }
            let depth: Vec<f64> = truth
                .dirs
                .iter()
                .map(|d| 5.0 / f64::from(d.z.abs()))
                .collect();
            check_grey(
                &nfor.depth,
                i,
                &depth,
                &format!("depth of pixel ({x}, {y})"),
            );
            // Which side of the wall the pixel sees: where its centre ray meets the floor.
            let centre = w.camera.ray(x, y, Vec2::splat(0.5)).ray;
            let floor_x = centre.o.x - centre.d.x * centre.o.z / centre.d.z;
            let want = if floor_x > 0.0 { 1.0 } else { 0.0 };
            for h in 0..2 {
                assert_eq!(
                    px(&nfor.visibility.mean[h], i),
                    [want; 3],
                    "pixel ({x}, {y})"
                );
                assert_eq!(px(&nfor.visibility.var[h], i), [0.0; 3]);
                if want == 0.0 {
                    assert_eq!(px(&nfor.color.mean[h], i), [0.0; 3], "shadow is black");
                }
            }
            if want == 1.0 { lit += 1 } else { dark += 1 }
        }
    }
    assert_eq!((lit, dark), (32, 32));
}

/// A mirror at `z = 0` facing the camera (5 away) and a diffuse wall behind the camera at
/// `z = 8` facing the mirror, lit by a point light between them: the first non-specular hit is
/// the wall, so the features are the wall's: normal `-z`, its reflectance, depth the unfolded
/// path `(5 + 8) / |d.z|`, visibility 1.
#[test]
fn features_through_a_mirror_are_those_of_the_wall() {
    let w = world(&format!(
        r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="3"/></integrator>
            {}
            <emitter type="point"><rgb name="intensity" value="1"/><point name="position" value="0, 0, 7"/></emitter>
            <shape type="rectangle">
                <transform name="to_world"><scale value="3"/></transform>
                <bsdf type="conductor"/>
            </shape>
            <shape type="rectangle">
                <transform name="to_world"><scale value="20"/><rotate x="1" angle="180"/><translate z="8"/></transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.2, 0.1"/></bsdf>
            </shape>
        </scene>"#,
        sensor(20.0, 6)
    ));
    let spp = 6;
    let cfg = config(&["mean"], spp, vec![]);
    let nfor = render(&w, &cfg, true, 2).nfor.unwrap();
    for y in 0..6u32 {
        for x in 0..6u32 {
            let i = (y * 6 + x) as usize;
            for h in 0..2 {
                let n = px(&nfor.normal.mean[h], i);
                assert!(
                    n[0].abs() < 1e-6 && n[1].abs() < 1e-6 && n[2] == -1.0,
                    "{n:?}"
                );
                assert_eq!(
                    px(&nfor.albedo.mean[h], i),
                    [0.7f32, 0.2, 0.1].map(f64::from)
                );
                assert_eq!(px(&nfor.visibility.mean[h], i), [1.0; 3]);
                assert!(px(&nfor.color.mean[h], i)[0] > 0.0, "the lit wall is seen");
            }
            let truth = camera_dirs(&w, cfg.seed, x, y, spp);
            let depth: Vec<f64> = truth
                .dirs
                .iter()
                .map(|d| 13.0 / f64::from(d.z.abs()))
                .collect();
            check_grey(
                &nfor.depth,
                i,
                &depth,
                &format!("depth of pixel ({x}, {y})"),
            );
        }
    }
}

/// A path that leaves the scene: normal 0, albedo 0, depth 0, visibility 1 (documented in
/// `Features::ESCAPED`).
#[test]
fn escaped_paths_have_the_documented_features() {
    let w = world(&format!(
        r#"<scene version="3.0.0">
            {}
            <emitter type="constant"><rgb name="radiance" value="0.25"/></emitter>
        </scene>"#,
        sensor(30.0, 4)
    ));
    let nfor = render(&w, &config(&["mean"], 4, vec![]), true, 1)
        .nfor
        .unwrap();
    for i in 0..16 {
        for h in 0..2 {
            assert_eq!(px(&nfor.normal.mean[h], i), [0.0; 3]);
            assert_eq!(px(&nfor.albedo.mean[h], i), [0.0; 3]);
            assert_eq!(px(&nfor.depth.mean[h], i), [0.0; 3]);
            assert_eq!(px(&nfor.visibility.mean[h], i), [1.0; 3]);
            assert_eq!(px(&nfor.color.mean[h], i), [0.25; 3]);
        }
    }
}

/// The half variances agree with the full variance, exactly and statistically.
///
/// Exactly: with `N = 2n` samples split in halves of `n`, the full sample variance obeys
/// `(N − 1) s² = (n − 1)(s_a² + s_b²) + (n / 2)(m_a − m_b)²`; the test recomputes `s²` from the
/// film's streams and checks the identity on the written half means and variances (which are
/// `s_h² / n`) to 1e-4 relative.
///
/// Statistically: the halves are independent, so `z = (m_a − m_b) / sqrt(v_a + v_b)` has mean 0
/// and variance about 1 in every pixel (a t-like variable with ~62 degrees of freedom, so
/// `E z² ≈ 1.03`). Over the ≥ 600 pixels with spread, the mean of `z²` has a standard deviation
/// of about `sqrt(Var z² / N) ≤ 1.6 / sqrt(600) ≈ 0.065` (allowing for tails heavier than
/// Gaussian); the band [0.7, 1.4] is over 5 such deviations from 1.03 on either side, a
/// false-failure probability below 1e-6 under the central limit theorem. It fails if the
/// variance were of a sample rather than of the mean (z² ≈ 1/32), off by a factor of 2 either
/// way, or if the halves shared samples (z ≈ 0).
#[test]
fn half_variances_are_consistent_with_the_full_variance() {
    let w = mixed(32);
    let spp = 64;
    let cfg = config(&["mean"], spp, vec![]);
    let nfor = render(&w, &cfg, true, 2).nfor.unwrap();
    let n = f64::from(spp / 2);
    let (mut z2, mut count) = (0.0, 0usize);
    for y in 0..32u32 {
        for x in 0..32u32 {
            let i = (y * 32 + x) as usize;
            let index = u64::from(y * 32 + x);
            let samples: Vec<f64> = (0..spp)
                .map(|s| {
                    let mut rng = SampleStream::new(cfg.seed, index, u64::from(s));
                    f64::from(radiance(&w, x, y, &mut rng).x)
                })
                .collect();
            let total = samples.iter().sum::<f64>() / f64::from(spp);
            let s2 =
                samples.iter().map(|v| (v - total).powi(2)).sum::<f64>() / (f64::from(spp) - 1.0);
            let (ma, mb) = (px(&nfor.color.mean[0], i)[0], px(&nfor.color.mean[1], i)[0]);
            let (va, vb) = (px(&nfor.color.var[0], i)[0], px(&nfor.color.var[1], i)[0]);
            let pooled =
                ((n - 1.0) * n * (va + vb) + n / 2.0 * (ma - mb).powi(2)) / (f64::from(spp) - 1.0);
            assert_close(pooled, s2, 1e-4, 1e-9, &format!("pixel ({x}, {y})"));
            if va + vb > 1e-12 {
                z2 += (ma - mb).powi(2) / (va + vb);
                count += 1;
            }
        }
    }
    let mean_z2 = z2 / count as f64;
    assert!(count >= 500, "{count} pixels with spread");
    eprintln!("mean z² = {mean_z2} over {count} pixels");
    assert!(
        (0.7..=1.4).contains(&mean_z2),
        "mean z² = {mean_z2} over {count} pixels"
    );
}

/// What each plugin's albedo is (see `Bsdf::albedo`), textures evaluated.
#[test]
fn albedo_per_plugin() {
    let at = |u: f32, v: f32| SurfacePoint {
        uv: Vec2::new(u, v),
        ..Default::default()
    };
    let (c0, c1) = (Vec3::new(0.1, 0.2, 0.3), Vec3::new(0.9, 0.8, 0.7));
    let board = Arc::new(Checkerboard::new(c0, c1, Mat3::IDENTITY));
    let textured = Diffuse {
        reflectance: Spectrum::Texture(board.clone()),
    };
    assert_eq!(
        textured.albedo(&at(0.25, 0.25)),
        board.eval(Vec2::new(0.25, 0.25))
    );
    assert_eq!(
        textured.albedo(&at(0.75, 0.25)),
        board.eval(Vec2::new(0.75, 0.25))
    );
    assert_ne!(
        textured.albedo(&at(0.25, 0.25)),
        textured.albedo(&at(0.75, 0.25))
    );
    let plastic = Plastic::new(1.5, Spectrum::Constant(c0), None, false);
    assert_eq!(plastic.albedo(&at(0.0, 0.0)), c0);
    assert_eq!(Conductor::mirror(c1).albedo(&at(0.0, 0.0)), c1);
    let glass = Dielectric::new(1.5, 1.0).albedo(&at(0.0, 0.0));
    assert!((glass - Vec3::ONE).abs().max_element() < 1e-6, "{glass}");
    let mask = Mask {
        opacity: Spectrum::grey(0.25),
        nested: Arc::new(Diffuse::new(c1)),
    };
    assert!((mask.albedo(&at(0.0, 0.0)) - c1 * 0.25).abs().max_element() < 1e-7);
    assert_eq!(
        TwoSided(Arc::new(Diffuse::new(c0))).albedo(&at(0.0, 0.0)),
        c0
    );
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fireflies-nfor-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_fireflies"))
}

const SMALL: &str = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="WIDTH"/><integer name="height" value="6"/><rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
</scene>
"#;

/// Renders `SMALL` with `width` into `dir` with the given arguments.
fn run_render(dir: &Path, width: u32, args: &[&str]) -> std::process::Output {
    let scene = dir.join(format!("s{width}.xml"));
    std::fs::write(&scene, SMALL.replace("WIDTH", &width.to_string())).unwrap();
    bin()
        .arg("render")
        .arg(&scene)
        .args([
            "--out",
            dir.to_str().unwrap(),
            "--estimators",
            "mean,gmon:M=3",
        ])
        .args(args)
        .output()
        .unwrap()
}

fn read_err(dir: &Path) -> String {
    NforBuffers::read(dir).unwrap_err().to_string()
}

/// The command writes every documented file and `render.json`'s `nfor` object; the reader
/// loads them back equal to what the film made, and refuses a missing, resized, stale or
/// non-finite file or a mismatched `render.json`, naming it.
#[test]
fn render_command_writes_buffers_the_reader_checks() {
    let dir = scratch("cli");
    let out = run_render(&dir, 8, &["--spp", "5", "--nfor", "--seed", "3"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for buf in ["color", "normal", "albedo", "depth", "visibility"] {
        for f in ["a", "b", "a_var", "b_var"] {
            assert!(dir.join(format!("{buf}_{f}.exr")).is_file(), "{buf}_{f}");
        }
    }
    for f in [
        "mean_a",
        "mean_b",
        "gmon_M=3_a",
        "gmon_M=3_b",
        "mean",
        "gmon_M=3",
    ] {
        assert!(dir.join(format!("{f}.exr")).is_file(), "{f}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("render.json")).unwrap()).unwrap();
    let nfor = &report["nfor"];
    assert_eq!(nfor["format_version"], 1);
    assert_eq!(
        (
            nfor["spp"].as_u64(),
            nfor["spp_a"].as_u64(),
            nfor["spp_b"].as_u64()
        ),
        (Some(5), Some(3), Some(2))
    );
    assert_eq!(nfor["buffers"]["depth"]["b_var"], "depth_b_var.exr");
    assert_eq!(nfor["estimators"][1]["spec"], "gmon:M=3");
    assert!(nfor["extra_bytes_per_pixel"].as_u64().unwrap() > 0);

    let buffers = NforBuffers::read(&dir).expect("reads back");
    assert_eq!((buffers.spp, buffers.seed), (5, 3));
    assert_eq!(buffers.estimators.len(), 2);
    assert_eq!(buffers.color.mean[0].width(), 8);

    // A file from another render (other spp) left in place: its attributes give it away.
    let other = scratch("other");
    assert!(
        run_render(&other, 8, &["--spp", "6", "--nfor", "--seed", "3"])
            .status
            .success()
    );
    std::fs::copy(other.join("normal_b.exr"), dir.join("normal_b.exr")).unwrap();
    let e = read_err(&dir);
    assert!(
        e.contains("normal_b.exr") && e.contains("fireflies.nfor.spp"),
        "{e}"
    );
    // A file of the wrong size.
    let wide = scratch("wide");
    assert!(
        run_render(&wide, 9, &["--spp", "5", "--nfor", "--seed", "3"])
            .status
            .success()
    );
    std::fs::copy(wide.join("normal_b.exr"), dir.join("normal_b.exr")).unwrap();
    let e = read_err(&dir);
    assert!(e.contains("normal_b.exr") && e.contains("9x6"), "{e}");
    // A missing file.
    std::fs::remove_file(dir.join("normal_b.exr")).unwrap();
    let e = read_err(&dir);
    assert!(e.contains("normal_b.exr") && e.contains("missing"), "{e}");
    // Non-finite values, in an otherwise consistent file.
    let mut broken = buffers.clone();
    let mut pixels = broken.depth.mean[1].pixels().to_vec();
    pixels[7] = [f32::NAN; 3];
    broken.depth.mean[1] = Image::from_pixels(8, 6, pixels).unwrap();
    broken.write(&dir).unwrap();
    let e = read_err(&dir);
    assert!(e.contains("depth_b.exr") && e.contains("finite"), "{e}");
    buffers.write(&dir).unwrap();
    assert_eq!(NforBuffers::read(&dir).unwrap(), buffers);
    // render.json whose spp disagrees with the buffers'.
    let json = dir.join("render.json");
    let text = std::fs::read_to_string(&json).unwrap();
    std::fs::write(&json, text.replacen("\"spp\": 5", "\"spp\": 6", 1)).unwrap();
    let e = read_err(&dir);
    assert!(e.contains("render.json") && e.contains("spp"), "{e}");
    std::fs::write(&json, &text).unwrap();
    assert!(NforBuffers::read(&dir).is_ok());

    // A render without --nfor has nothing to read, and --nfor needs 4 spp.
    let plain = scratch("plain");
    assert!(run_render(&plain, 8, &["--spp", "4"]).status.success());
    let e = read_err(&plain);
    assert!(e.contains("render.json") && e.contains("--nfor"), "{e}");
    let out = run_render(&plain, 8, &["--spp", "3", "--nfor"]);
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("spp = 3") && e.contains("at least 4"), "{e}");
    for d in [dir, other, wide, plain] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// A floor seen from above, lit only by a point light below it: a BSDF that does not transmit
/// is zero toward the light, so the colour path casts no shadow ray; the feature casts its own
/// and counts the floor itself as the occluder (visibility 0). A rough dielectric floor
/// transmits, so the same light is visible through it (visibility 1).
#[test]
fn visibility_of_an_emitter_behind_the_surface() {
    let scene = |bsdf: &str| {
        world(&format!(
            r#"<scene version="3.0.0">
                <integrator type="path"><integer name="max_depth" value="2"/></integrator>
                {}
                <emitter type="point"><rgb name="intensity" value="1"/><point name="position" value="0, 0, -1"/></emitter>
                <shape type="rectangle"><transform name="to_world"><scale value="3"/></transform>{bsdf}</shape>
            </scene>"#,
            sensor(30.0, 4)
        ))
    };
    for (bsdf, want) in [
        (r#"<bsdf type="diffuse"/>"#, 0.0),
        (
            r#"<bsdf type="twosided"><bsdf type="diffuse"/></bsdf>"#,
            0.0,
        ),
        (
            r#"<bsdf type="roughdielectric"><float name="alpha" value="0.3"/></bsdf>"#,
            1.0,
        ),
    ] {
        let nfor = render(&scene(bsdf), &config(&["mean"], 4, vec![]), true, 1)
            .nfor
            .unwrap();
        for i in 0..16 {
            for h in 0..2 {
                assert_eq!(px(&nfor.visibility.mean[h], i), [want; 3], "{bsdf}");
                assert!(px(&nfor.depth.mean[h], i)[0] >= 5.0, "{bsdf}");
            }
        }
    }
}

/// The halves count against the memory limit: a film that fits without `--nfor` is refused
/// with it, and the message says why.
#[test]
fn nfor_counts_against_the_memory_limit() {
    let w = mixed(64);
    let mut cfg = config(&["mean"], 4, vec![]);
    // 64x64 pixels: the plain film needs well under 1 MB; the halves add 920 bytes a pixel
    // (3.8 MB).
    cfg.memory = fireflies::limits::MemoryLimit(2_000_000);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let check_only = |nfor: bool| {
        let mut tiny = cfg.clone();
        tiny.spp = 4;
        pool.install(|| film::render_with_nfor(&w, &tiny, nfor, |_| {}))
    };
    assert!(check_only(false).is_ok());
    let e = check_only(true).unwrap_err().to_string();
    assert!(e.contains("NFOR buffers") && e.contains("memory"), "{e}");
}
