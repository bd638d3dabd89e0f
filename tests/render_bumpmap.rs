//! The `bumpmap` BSDF and the `bitmap` texture's gradient against Mitsuba 3.9.1 (`scalar_rgb`),
//! the uv tangents of mesh hits against Mitsuba's, the bump's sampling against its own `eval`,
//! and its loader's errors. The fixture and the
//! script that made it are in `tests/data/bumpmap/`.
//!
//! Tolerances, and why:
//! * `eval_1_grad` on float texels: [`GRAD_TOL`] relative (of the larger of the value and 1).
//!   The texel blend is Mitsuba's arithmetic; only the last sums may round differently (fused
//!   or not): 253 of the 280 points agree to the bit, the worst differs by 1.8e-7. Getting
//!   Mitsuba's order of `to_uv` and resolution wrong changes the rotated textures' gradients by
//!   O(1) (e.g. -1.385 instead of -2.309).
//! * `eval` and `pdf` of a bumpmap over a diffuse: [`EVAL_TOL`], likewise. They go through a
//!   cross product, a normalisation and two frame changes in f32 on each side: the worst
//!   difference seen is 7.5e-8. Dropping the shadowing term changes 158 of the 300 cases,
//!   dropping the flip of invalid normals 35, by far more.
//! * Hit records (`uv`, `dp_du`, `dp_dv`, normals) on an OBJ mesh: 2e-5 of the vector's length;
//!   the transform is built from the XML's rotation axis, normalised by us and by Mitsuba.
//!
//! The comparisons with Mitsuba are deterministic; the sampling test uses a fixed seed and
//! states its false-failure probability.

use fireflies::Error;
use fireflies::image::read::TextureData;
use fireflies::render::bsdfs::bumpmap::BumpMap;
use fireflies::render::bsdfs::diffuse::Diffuse;
use fireflies::render::bsdfs::{Bsdf, SurfacePoint};
use fireflies::render::mitsuba::load_str;
use fireflies::render::sampling::Frame;
use fireflies::render::scene::{Rgb, SceneDesc};
use fireflies::render::shapes::{Ray, primitives};
use fireflies::render::textures::Texture;
use fireflies::render::textures::bitmap::{Bitmap, Filter, Wrap};
use fireflies::render::world::World;
use glam::{Mat3, Vec2, Vec3};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Allowed relative difference of gradients (see the module documentation).
const GRAD_TOL: f32 = 1e-6;
/// Allowed relative difference of `eval` and `pdf` (see the module documentation).
const EVAL_TOL: f32 = 1e-6;
/// The fixture's diffuse reflectance.
const REFLECTANCE: Rgb = Rgb::new(0.2, 0.5, 0.8);

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bumpmap")
}

fn rows(file: &str) -> Vec<HashMap<String, String>> {
    let mut reader = csv::Reader::from_path(data_dir().join(file)).unwrap();
    let headers = reader.headers().unwrap().clone();
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            headers
                .iter()
                .zip(r.iter())
                .map(|(h, v)| (h.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}

fn num(row: &HashMap<String, String>, key: &str) -> f32 {
    row[key].parse().unwrap()
}

fn vec3(row: &HashMap<String, String>, key: &str) -> Vec3 {
    Vec3::new(
        num(row, &format!("{key}x")),
        num(row, &format!("{key}y")),
        num(row, &format!("{key}z")),
    )
}

/// The fixture's textures, by id.
fn textures() -> HashMap<String, Bitmap> {
    rows("textures.csv")
        .into_iter()
        .map(|row| {
            let m = |k: &str| num(&row, k);
            let to_uv = Mat3::from_cols(
                Vec3::new(m("m00"), m("m10"), 0.0),
                Vec3::new(m("m01"), m("m11"), 0.0),
                Vec3::new(m("m02"), m("m12"), 1.0),
            );
            let filter = match row["filter"].as_str() {
                "bilinear" => Filter::Bilinear,
                _ => Filter::Nearest,
            };
            let wrap = match row["wrap"].as_str() {
                "repeat" => Wrap::Repeat,
                "mirror" => Wrap::Mirror,
                _ => Wrap::Clamp,
            };
            let image = TextureData {
                width: row["width"].parse().unwrap(),
                height: row["height"].parse().unwrap(),
                channels: row["channels"].parse().unwrap(),
                data: row["texels"]
                    .split(' ')
                    .map(|x| x.parse().unwrap())
                    .collect(),
                alpha_dropped: false,
            };
            let tex = Bitmap::from_data(row["id"].clone(), image, filter, wrap, to_uv);
            (row["id"].clone(), tex)
        })
        .collect()
}

fn close(ours: f32, theirs: f32, rel: f32) -> bool {
    (ours - theirs).abs() <= rel * ours.abs().max(theirs.abs()).max(1.0)
}

#[test]
fn bitmap_gradient_matches_mitsuba() {
    let textures = textures();
    let (mut nearest, mut nonzero) = (0, 0);
    let grads = rows("grad.csv");
    assert_eq!(grads.len(), 280);
    for row in &grads {
        let tex = &textures[&row["id"]];
        let uv = Vec2::new(num(row, "u"), num(row, "v"));
        let theirs = Vec2::new(num(row, "gu"), num(row, "gv"));
        let ours = Texture::eval_1_grad(tex, uv);
        assert!(
            close(ours.x, theirs.x, GRAD_TOL) && close(ours.y, theirs.y, GRAD_TOL),
            "texture {} at {uv}: ours {ours}, Mitsuba {theirs}",
            row["id"]
        );
        if row["id"] == "6" {
            assert_eq!(theirs, Vec2::ZERO, "nearest filtering");
            nearest += 1;
        } else if theirs != Vec2::ZERO {
            nonzero += 1;
        }
    }
    // The nearest-filtered texture has gradient zero; elsewhere only clamped lookups outside
    // the image do.
    assert_eq!(nearest, 40);
    assert!(nonzero > 200, "{nonzero}");
    assert!(textures.values().all(|t| t.has_eval_1_grad()));
}

#[test]
fn bumpmap_eval_and_pdf_match_mitsuba() {
    let textures = textures();
    let cases = rows("eval.csv");
    assert_eq!(cases.len(), 300);
    let (mut nonzero, mut decided_by_bump) = (0, 0);
    for (k, row) in cases.iter().enumerate() {
        let bump = BumpMap {
            flip_invalid_normals: row["flip"] == "1",
            use_shadowing_function: row["shadow"] == "1",
            ..BumpMap::new(
                Arc::new(textures[&row["id"]].clone()),
                num(row, "scale"),
                Arc::new(Diffuse::new(REFLECTANCE)),
            )
        };
        let at = SurfacePoint {
            uv: Vec2::new(num(row, "u"), num(row, "v")),
            frame: Frame::new(vec3(row, "ns")),
            ng: vec3(row, "n"),
            dp_du: vec3(row, "dpdu"),
            dp_dv: vec3(row, "dpdv"),
        };
        let (wi, wo) = (vec3(row, "wi"), vec3(row, "wo"));
        let (value, pdf) = bump.eval_pdf(&at, wi, wo);
        let theirs = Rgb::new(num(row, "r"), num(row, "g"), num(row, "b"));
        let their_pdf = num(row, "pdf");
        let ok =
            (0..3).all(|c| close(value[c], theirs[c], EVAL_TOL)) && close(pdf, their_pdf, EVAL_TOL);
        assert!(
            ok,
            "case {k}: ours {value} pdf {pdf}, Mitsuba {theirs} pdf {their_pdf}"
        );
        // The unbumped diffuse would scatter iff both are in front of the shading normal.
        let unbumped = wi.z > 0.0 && wo.z > 0.0;
        if their_pdf > 0.0 {
            nonzero += 1;
        }
        if unbumped != (their_pdf > 0.0) {
            decided_by_bump += 1;
        }
    }
    // The fixture exercises both outcomes, and the bump changes the outcome often.
    assert!(nonzero > 100 && nonzero < 250, "{nonzero}");
    assert!(decided_by_bump > 20, "{decided_by_bump}");
}

/// A height field with the same gradient everywhere.
#[derive(Debug)]
struct Slope(Vec2);

impl Texture for Slope {
    fn eval(&self, _uv: Vec2) -> Rgb {
        Rgb::ZERO
    }
    fn eval_1(&self, _uv: Vec2) -> f32 {
        0.0
    }
    fn mean(&self) -> f32 {
        0.0
    }
    fn eval_1_grad(&self, _uv: Vec2) -> Vec2 {
        self.0
    }
    fn has_eval_1_grad(&self) -> bool {
        true
    }
}

/// A hit with a tilted shading normal and a sheared parametrisation, bumped by 40–50 degrees.
fn tilted_point() -> (BumpMap, SurfacePoint) {
    let ng = Vec3::new(0.1, 0.2, 1.0).normalize();
    let ns = Vec3::new(-0.2, 0.25, 1.0).normalize();
    let bump = BumpMap::new(
        Arc::new(Slope(Vec2::new(0.7, -0.4))),
        1.3,
        Arc::new(Diffuse::new(REFLECTANCE)),
    );
    let at = SurfacePoint {
        uv: Vec2::new(0.3, 0.6),
        frame: Frame::new(ns),
        ng,
        dp_du: Vec3::new(1.2, 0.1, -0.14),
        dp_dv: Vec3::new(0.3, 0.9, -0.2),
    };
    (bump, at)
}

/// Midpoint rule over the sphere of `wo` in `(cos θ, φ)`: exact at the `z = 0` discontinuity
/// (a cell edge), second order elsewhere (the integrand is continuous, with kinks).
fn quadrature(f: &dyn Fn(Vec3) -> Rgb, nz: usize, nphi: usize) -> Rgb {
    let mut sum = Rgb::ZERO;
    let (dz, dphi) = (2.0 / nz as f64, 2.0 * std::f64::consts::PI / nphi as f64);
    for i in 0..nz {
        let z = -1.0 + (i as f64 + 0.5) * dz;
        let r = (1.0 - z * z).sqrt();
        for j in 0..nphi {
            let phi = (j as f64 + 0.5) * dphi;
            let wo = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
            sum += f(wo);
        }
    }
    sum * (dz * dphi) as f32
}

#[test]
fn without_shadowing_the_bump_only_cuts_the_lobe() {
    // A Lambertian lobe about the bumped normal, cut to the shading hemisphere, integrates to
    // R (1 + cos α) / 2 (the view factor of a tilted plane to a hemisphere): the quadrature of
    // eval must find it, which checks the tilt and the refusal of wo behind the shading normal.
    let (mut bump, at) = tilted_point();
    bump.use_shadowing_function = false;
    let wi = Vec3::new(0.3, -0.5, 0.8).normalize();
    let local = bump.local_frame(&at, wi);
    let tilt = local.n.z.acos().to_degrees();
    assert!((35.0..55.0).contains(&tilt), "tilt {tilt}");
    assert!(local.to_local(wi).z > 0.0);
    let integral = quadrature(&|wo| bump.eval(&at, wi, wo), 600, 1200);
    let closed = REFLECTANCE * (1.0 + local.n.z) / 2.0;
    for c in 0..3 {
        assert!(
            (integral[c] - closed[c]).abs() < 2e-4 * closed[c],
            "{integral} vs {closed}"
        );
    }
}

/// The Monte Carlo mean of `bump`'s sample weights at `at` for `wi` against the quadrature of
/// its eval, with per-sample checks that a sample's pdf and weight are eval_pdf's.
///
/// Each weight is bounded by R (a shadowed Lambertian lobe), so the mean has a standard error
/// of at most R·sqrt(E[w²] − E[w]²)/sqrt(n), estimated from the samples; 5 standard errors: a
/// correct sampler fails with probability 6e-7 (two-sided normal), and a defect that moves the
/// mean by more than about 0.3 % of R (a missing refusal moves it by (1 − cos α) / 2 ≈ 12 %, a
/// missing shadowing term on the weight by several percent) fails.
fn assert_sampling_matches_eval(bump: &BumpMap, at: &SurfacePoint, wi: Vec3, seed: u64) {
    let integral = quadrature(&|wo| bump.eval(at, wi, wo), 600, 1200);
    let n = 400_000;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut sum = [0.0f64; 3];
    let mut sum2 = [0.0f64; 3];
    for k in 0..n {
        let u_lobe: f32 = rng.random();
        let u = Vec2::new(rng.random(), rng.random());
        let Some(s) = bump.sample(at, wi, u_lobe, u) else {
            continue;
        };
        for c in 0..3 {
            sum[c] += f64::from(s.weight[c]);
            sum2[c] += f64::from(s.weight[c]).powi(2);
        }
        if k % 1000 == 0 {
            let (value, pdf) = bump.eval_pdf(at, wi, s.wo);
            assert!(close(s.pdf, pdf, 1e-4), "{} vs {pdf}", s.pdf);
            assert!((s.weight * s.pdf - value).abs().max_element() < 1e-4 * pdf);
        }
    }
    for c in 0..3 {
        let mean = sum[c] / n as f64;
        let se = ((sum2[c] / n as f64 - mean * mean).max(0.0) / n as f64).sqrt();
        let diff = (mean - f64::from(integral[c])).abs();
        assert!(
            diff < 5.0 * se,
            "channel {c}: MC {mean} vs quadrature {} (se {se})",
            integral[c]
        );
    }
}

#[test]
fn sampling_weights_average_to_the_integral_of_eval() {
    let (bump, at) = tilted_point();
    // wi in front of the bumped normal, and wi behind it (flipped by flip_invalid_normals).
    let front = Vec3::new(0.3, -0.5, 0.8).normalize();
    assert!(bump.local_frame(&at, front).to_local(front).z > 0.0);
    assert_sampling_matches_eval(&bump, &at, front, 0xb0b);
    let mut unflipped = bump.clone();
    unflipped.flip_invalid_normals = false;
    let n = unflipped.local_frame(&at, front).n;
    let grazing = Vec3::new(-n.x, -n.y, 0.3).normalize();
    assert!(unflipped.local_frame(&at, grazing).to_local(grazing).z < 0.0);
    assert!(bump.local_frame(&at, grazing).to_local(grazing).z > 0.0);
    assert_sampling_matches_eval(&bump, &at, grazing, 0xb0c);
}

#[test]
fn a_flat_height_changes_nothing() {
    let (mut bump, at) = tilted_point();
    bump.height = Arc::new(Slope(Vec2::ZERO));
    let diffuse = Diffuse::new(REFLECTANCE);
    let wi = Vec3::new(0.3, -0.5, 0.8).normalize();
    for wo in [Vec3::new(0.1, 0.2, 0.9), Vec3::new(-0.7, 0.1, 0.3), Vec3::Z] {
        let wo = wo.normalize();
        let (a, pa) = bump.eval_pdf(&at, wi, wo);
        let (b, pb) = diffuse.eval_pdf(&at, wi, wo);
        assert!((a - b).abs().max_element() < 1e-6 && (pa - pb).abs() < 1e-6);
    }
}

// ---------------------------------------------------------------------------------------------
// Hits
// ---------------------------------------------------------------------------------------------

#[test]
fn mesh_hits_have_mitsubas_uv_tangents() {
    // The fixture's HIT_TO_WORLD, with the rotation axis normalised in the file as Mitsuba's
    // Python call did (so the two transforms agree to rounding).
    let a = Vec3::new(1.0, 2.0, 0.5).normalize();
    let xml = format!(
        "<scene version=\"3.0.0\">\n<sensor type=\"perspective\"><float name=\"fov\" \
         value=\"45\"/><film type=\"hdrfilm\"><rfilter type=\"box\"/></film></sensor>\n\
         <shape type=\"obj\"><string name=\"filename\" value=\"quad.obj\"/>\
         <transform name=\"to_world\"><scale x=\"0.5\" y=\"2\" z=\"1\"/>\
         <rotate x=\"{}\" y=\"{}\" z=\"{}\" angle=\"50\"/>\
         <translate x=\"0.3\" y=\"-0.2\" z=\"1\"/></transform></shape>\n</scene>\n",
        a.x, a.y, a.z
    );
    let scene = load_str(&xml, &data_dir(), "hits.xml").expect("quad loads");
    let prims = primitives(0, &scene.shapes[0].geometry);
    assert_eq!(prims.len(), 2);
    let hits = rows("hits.csv");
    assert_eq!(hits.len(), 12);
    let (mut first, mut second) = (0, 0);
    for (k, row) in hits.iter().enumerate() {
        let ray = Ray::new(vec3(row, "o"), vec3(row, "d"));
        let hit = prims
            .iter()
            .filter_map(|p| p.intersect(&ray, 0.0, f32::INFINITY))
            .min_by(|a, b| a.t.total_cmp(&b.t))
            .unwrap_or_else(|| panic!("ray {k} misses"));
        let near = |ours: Vec3, key: &str| {
            let theirs = vec3(row, key);
            assert!(
                (ours - theirs).length() <= 2e-5 * theirs.length().max(1.0),
                "ray {k} {key}: ours {ours}, Mitsuba {theirs}"
            );
        };
        let uv = Vec2::new(num(row, "u"), num(row, "v"));
        assert!(
            (hit.uv - uv).length() < 1e-5,
            "ray {k}: uv {} vs {uv}",
            hit.uv
        );
        near(hit.dp_du, "dpdu");
        near(hit.dp_dv, "dpdv");
        near(hit.ng, "n");
        near(hit.ns, "ns");
        // The two triangles' maps have opposite orientations (dp_du × dp_dv along n, then not).
        if hit.dp_du.cross(hit.dp_dv).dot(hit.ng) > 0.0 {
            first += 1;
        } else {
            second += 1;
        }
    }
    assert!(first > 0 && second > 0, "{first} {second}");
}

// ---------------------------------------------------------------------------------------------
// Loader
// ---------------------------------------------------------------------------------------------

fn load(body: &str) -> Result<SceneDesc, Error> {
    let xml = format!(
        "<scene version=\"3.0.0\">\n<sensor type=\"perspective\"><float name=\"fov\" value=\"45\"/>\
         <film type=\"hdrfilm\"><rfilter type=\"box\"/></film></sensor>\n{body}\n</scene>\n"
    );
    load_str(&xml, &data_dir().join("../textures"), "test.xml")
}

const HEIGHT: &str =
    r#"<texture type="bitmap"><string name="filename" value="y_float.exr"/></texture>"#;

fn expect_error(body: &str, element: &str, fragment: &str) {
    let err = load(body).expect_err("must not load");
    match &err {
        Error::Scene {
            element: got,
            message,
            line,
            ..
        } => {
            assert_eq!(got, element, "{err}");
            assert_eq!(*line, 4, "{err}");
            assert!(message.contains(fragment), "{fragment:?} not in {err}");
        }
        other => panic!("expected Error::Scene, got {other:?}"),
    }
}

#[test]
fn bumpmap_loads_with_a_height_under_any_name_and_scale() {
    for texture in [
        HEIGHT,
        &HEIGHT.replace("<texture ", "<texture name=\"whatever\" "),
    ] {
        let scene = load(&format!(
            "<shape type=\"rectangle\">\n<bsdf type=\"bumpmap\">{texture}\
             <float name=\"scale\" value=\"0.3\"/><bsdf type=\"diffuse\"/></bsdf></shape>"
        ))
        .expect("bumpmap loads");
        let text = format!("{:?}", scene.shapes[0].bsdf);
        assert!(
            text.starts_with("BumpMap") && text.contains("scale: 0.3"),
            "{text}"
        );
    }
}

#[test]
fn bumpmap_errors_name_the_element() {
    // Each snippet puts the <bsdf type="bumpmap"> on line 4 of the file.
    let bumpmap = "bsdf type=\"bumpmap\"";
    let shape = |inner: &str| {
        format!("<shape type=\"rectangle\">\n<bsdf type=\"bumpmap\">{inner}</bsdf></shape>")
    };
    expect_error(&shape(HEIGHT), bumpmap, "bumpmap needs one nested <bsdf>");
    expect_error(
        &shape("<bsdf type=\"diffuse\"/>"),
        bumpmap,
        "bumpmap needs one nested <texture>",
    );
    expect_error(
        &shape(&format!(
            "{HEIGHT}<bsdf type=\"diffuse\"/><bsdf type=\"diffuse\"/>"
        )),
        "bsdf type=\"diffuse\"",
        "exactly one nested bsdf",
    );
    expect_error(
        &shape(&format!("{HEIGHT}{HEIGHT}<bsdf type=\"diffuse\"/>")),
        "texture type=\"bitmap\"",
        "exactly one nested texture",
    );
    // Mitsuba's checkerboard has no eval_1_grad: refused when read, not when rendered.
    expect_error(
        &shape("<texture type=\"checkerboard\"/><bsdf type=\"diffuse\"/>"),
        "texture type=\"checkerboard\"",
        "has no gradient",
    );
    expect_error(
        &shape(&format!(
            "{HEIGHT}<bsdf type=\"diffuse\"/><float name=\"scales\" value=\"2\"/>"
        )),
        "float name=\"scales\"",
        "did you mean \"scale\"",
    );
    // A bump map needs texture coordinates, which spheres do not have here.
    let err = load(&format!(
        "<shape type=\"sphere\">\n<bsdf type=\"bumpmap\">{HEIGHT}<bsdf type=\"diffuse\"/></bsdf></shape>"
    ))
    .expect_err("no uvs");
    assert!(err.to_string().contains("no texture coordinates"), "{err}");
}

/// NFOR's normal feature sees the bumps: a bump map reports its bumped normal (the frame its
/// `eval` shades with), a plain BSDF the shading normal (`None`), and a two-sided bump map seen
/// from the back the mirrored normal of the mirrored viewer. Before, every hit reported the
/// shading normal, so a denoiser guided by it could blur the relief away.
#[test]
fn bumped_normal_is_the_normal_feature() {
    use fireflies::render::bsdfs::twosided::TwoSided;
    let (bump, at) = tilted_point();
    let wi = Vec3::new(0.3, -0.2, 0.9).normalize();
    let n = bump
        .feature_normal(&at, wi)
        .expect("a bump map reports its normal");
    assert_eq!(n, bump.local_frame(&at, wi).n);
    assert!(
        n.z < 0.8,
        "bumped by 40-50 degrees, so well off the shading normal: {n}"
    );
    assert_eq!(Diffuse::new(REFLECTANCE).feature_normal(&at, wi), None);
    let two = TwoSided(Arc::new(bump.clone()));
    assert_eq!(two.feature_normal(&at, wi), Some(n));
    let back = Vec3::new(wi.x, wi.y, -wi.z);
    let mirrored = bump.local_frame(&at, wi).n;
    assert_eq!(
        two.feature_normal(&at, back),
        Some(Vec3::new(mirrored.x, mirrored.y, -mirrored.z))
    );
}

/// The integrator records the bump map's normal as NFOR's normal feature: a flat rectangle
/// facing the camera gives one normal at every pixel when plain, and normals tilted by the
/// height map's slope when bumped (the texture `y_float.exr` varies along v).
#[test]
fn bumped_plate_tilts_the_rendered_normal_feature() {
    use fireflies::render::integrator::radiance_features;
    use fireflies::render::sampler::SampleStream;
    use fireflies::render::world::World;
    let plate = |bsdf: &str| {
        let mut desc = load(&format!(
            "<shape type=\"rectangle\"><transform name=\"to_world\"><rotate y=\"1\" \
             angle=\"180\"/><translate z=\"5\"/></transform>{bsdf}</shape>\
             <emitter type=\"constant\"><rgb name=\"radiance\" value=\"1, 1, 1\"/></emitter>"
        ))
        .unwrap();
        desc.camera.width = 16;
        desc.camera.height = 16;
        let world = World::new(&desc);
        // The largest angle between the normal features of the centre 8x8 pixels (all on the plate).
        let normals: Vec<Vec3> = (4..12)
            .flat_map(|y| (4..12).map(move |x| (x, y)))
            .map(|(x, y)| {
                let mut rng = SampleStream::new(1, u64::from(y * 16 + x), 0);
                radiance_features(&world, x, y, &mut rng).1.normal
            })
            .collect();
        normals
            .iter()
            .flat_map(|a| normals.iter().map(move |b| a.angle_between(*b)))
            .fold(0.0f32, f32::max)
    };
    let flat = plate("<bsdf type=\"diffuse\"/>");
    let bumped = plate(&format!(
        "<bsdf type=\"bumpmap\">{HEIGHT}<float name=\"scale\" value=\"0.3\"/>\
         <bsdf type=\"diffuse\"/></bsdf>"
    ));
    assert!(flat < 1e-3, "a flat plate's normals differ by {flat} rad");
    assert!(
        bumped > 0.05,
        "a bumped plate's normals differ by only {bumped} rad"
    );
}

/// Hits skip the tangents in a scene no BSDF of which reads them, and carry them (Mitsuba's
/// `dp_du`, `dp_dv` of the rectangle: `2x`, `2y`) wherever a bump map sits, also inside
/// `twosided` or `mask`. A wrapper that did not pass the question on would bump with zero
/// tangents, i.e. not at all; caught here.
#[test]
fn hits_carry_tangents_where_a_bsdf_reads_them() {
    let bump = format!("<bsdf type=\"bumpmap\">{HEIGHT}<bsdf type=\"diffuse\"/></bsdf>");
    let opacity = "<float name=\"opacity\" value=\"0.5\"/>";
    for (bsdf, tangents) in [
        ("<bsdf type=\"diffuse\"/>".to_string(), false),
        (
            "<bsdf type=\"twosided\"><bsdf type=\"diffuse\"/></bsdf>".to_string(),
            false,
        ),
        (bump.clone(), true),
        (format!("<bsdf type=\"twosided\">{bump}</bsdf>"), true),
        (format!("<bsdf type=\"mask\">{opacity}{bump}</bsdf>"), true),
    ] {
        let scene = load(&format!("<shape type=\"rectangle\">{bsdf}</shape>")).expect("loads");
        let world = World::new(&scene);
        let ray = Ray::new(Vec3::new(0.2, 0.1, 2.0), Vec3::new(0.0, 0.0, -1.0));
        let hit = world.bvh.intersect(&ray, 0.0, f32::INFINITY).expect("hits");
        let want = if tangents {
            (Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0))
        } else {
            (Vec3::ZERO, Vec3::ZERO)
        };
        assert_eq!((hit.dp_du, hit.dp_dv), want, "{bsdf}");
    }
}
