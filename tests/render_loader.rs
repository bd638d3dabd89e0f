//! The Mitsuba 3 XML loader: the Cornell box, transforms, shapes, OBJ meshes and the errors that
//! name file, line and element.

use std::path::{Path, PathBuf};

use fireflies::Error;
use fireflies::render::bsdfs::conductor::Conductor;
use fireflies::render::bsdfs::dielectric::Dielectric;
use fireflies::render::bsdfs::diffuse::Diffuse;
use fireflies::render::bsdfs::roughconductor::RoughConductor;
use fireflies::render::bsdfs::twosided::TwoSided;
use fireflies::render::emitters::constant::Constant;
use fireflies::render::emitters::point::PointLight;
use fireflies::render::integrator::radiance;
use fireflies::render::mitsuba::{load_file, load_str};
use fireflies::render::sampler::SampleStream;
use fireflies::render::scene::{FovAxis, GeometryDesc, MeshDesc, SceneDesc};
use std::fmt::Debug;
use std::sync::Arc;

use fireflies::render::world::World;
use glam::{Mat4, Vec3};

const FILE: &str = "test.xml";

/// Plugins compare by their debug form (they are trait objects).
fn same(a: &impl Debug, b: &impl Debug) -> bool {
    format!("{a:?}") == format!("{b:?}")
}

/// A valid sensor, so that snippets only need the part under test.
const SENSOR: &str = r#"<sensor type="perspective">
        <float name="fov" value="45"/>
        <film type="hdrfilm"><rfilter type="box"/></film>
    </sensor>"#;

/// `body` inside a scene root, after a valid sensor.
fn scene(body: &str) -> String {
    format!("<scene version=\"3.0.0\">\n    {SENSOR}\n{body}\n</scene>\n")
}

fn load(xml: &str) -> Result<SceneDesc, Error> {
    load_str(xml, Path::new("."), FILE)
}

/// 1-based line of the first occurrence of `needle` in `xml`.
fn line_of(xml: &str, needle: &str) -> u32 {
    let at = xml
        .find(needle)
        .unwrap_or_else(|| panic!("{needle} not in xml"));
    xml[..at].matches('\n').count() as u32 + 1
}

/// Loads `xml`, expects an [`Error::Scene`] at the line of `line_needle` about `element`, whose
/// message contains each of `fragments`; returns the full message.
fn expect_error(xml: &str, line_needle: &str, element: &str, fragments: &[&str]) -> String {
    let err = load(xml).expect_err("the scene must not load");
    let text = err.to_string();
    let line = line_of(xml, line_needle);
    match &err {
        Error::Scene {
            file,
            line: got_line,
            element: got_element,
            message,
        } => {
            assert_eq!(file, FILE, "{text}");
            assert_eq!(*got_line, line, "{text}");
            assert_eq!(got_element, element, "{text}");
            for fragment in fragments {
                assert!(message.contains(fragment), "{fragment:?} not in {text}");
            }
        }
        other => panic!("expected Error::Scene, got {other:?}"),
    }
    assert!(
        text.starts_with(&format!("{FILE}:{line}: <{element}>: ")),
        "{text}"
    );
    text
}

fn mesh(scene: &SceneDesc, index: usize) -> &MeshDesc {
    match &scene.shapes[index].geometry {
        GeometryDesc::Mesh(mesh) => mesh,
        other => panic!("shape {index} is not a mesh: {other:?}"),
    }
}

/// Unit geometric normals of the triangles, from their winding.
fn face_normals(mesh: &MeshDesc) -> Vec<Vec3> {
    mesh.indices
        .iter()
        .map(|t| {
            let p = t.map(|i| mesh.positions[i as usize]);
            (p[1] - p[0]).cross(p[2] - p[0]).normalize()
        })
        .collect()
}

fn disk_to_world(scene: &SceneDesc) -> Mat4 {
    match scene.shapes[0].geometry {
        GeometryDesc::Disk { to_world } => to_world,
        ref other => panic!("not a disk: {other:?}"),
    }
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-5
}

#[test]
fn cornell_box_loads() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments/scenes/cbox.xml");
    let scene = load_file(&path).unwrap();

    assert_eq!(scene.shapes.len(), 8);
    assert_eq!(scene.integrator.max_depth, Some(8));
    assert_eq!(scene.integrator.rr_depth, 5);
    assert!(scene.emitters.is_empty());

    let camera = scene.camera.clone();
    assert_eq!((camera.width, camera.height), (128, 128));
    assert_eq!(camera.fov_deg, 39.3077);
    assert_eq!(camera.fov_axis, FovAxis::Smaller);
    assert_eq!(camera.spp, 64);
    assert_eq!((camera.near_clip, camera.far_clip), (0.01, 10000.0));
    assert!(close(
        camera.to_world.w_axis.truncate(),
        Vec3::new(0.0, 0.0, 3.9)
    ));
    // Local +z looks at the target, local +y is up, local +x (image left) is world -x.
    assert!(close(camera.to_world.z_axis.truncate(), -Vec3::Z));
    assert!(close(camera.to_world.y_axis.truncate(), Vec3::Y));
    assert!(close(camera.to_world.x_axis.truncate(), -Vec3::X));

    let light = &scene.shapes[0];
    assert_eq!(light.emission, Some(Vec3::new(18.387, 13.9873, 6.75357)));
    assert!(scene.shapes[1..].iter().all(|s| s.emission.is_none()));
    let light_mesh = mesh(&scene, 0);
    assert_eq!(light_mesh.indices.len(), 2);
    for n in face_normals(light_mesh) {
        assert!(close(n, -Vec3::Y), "light normal {n}");
    }
    // The light is 0.46 x 0.38 at height 0.99 around (0, 0.99, 0.01).
    let light_center =
        light_mesh.positions.iter().copied().sum::<Vec3>() / light_mesh.positions.len() as f32;
    assert!(close(light_center, Vec3::new(0.0, 0.99, 0.01)));
    assert!(close(
        light_mesh.positions[2] - light_mesh.positions[0],
        Vec3::new(0.46, 0.0, 0.38)
    ));

    // Floor, ceiling, back, green (x = +1) and red (x = -1) walls all face the inside.
    let inward = [Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::X, Vec3::X];
    for (k, want) in inward.iter().enumerate() {
        for n in face_normals(mesh(&scene, k + 1)) {
            assert!(close(n, *want), "wall {} normal {n}, want {want}", k + 1);
        }
    }
    assert!(same(
        &scene.shapes[5].bsdf,
        &Diffuse::new(Vec3::new(0.570068, 0.043014, 0.044371))
    ));

    // Both boxes: 12 triangles facing away from their centre.
    for k in [6, 7] {
        let cube = mesh(&scene, k);
        assert_eq!(cube.indices.len(), 12);
        assert_eq!(cube.normals, None);
        let center = cube.positions.iter().copied().sum::<Vec3>() / cube.positions.len() as f32;
        for (t, n) in cube.indices.iter().zip(face_normals(cube)) {
            let centroid = t.map(|i| cube.positions[i as usize]).iter().sum::<Vec3>() / 3.0;
            assert!(
                (centroid - center).dot(n) > 0.0,
                "box {k} has an inward face"
            );
        }
    }
    let small = mesh(&scene, 6);
    let center = small.positions.iter().copied().sum::<Vec3>() / small.positions.len() as f32;
    assert!(close(center, Vec3::new(0.335, -0.7, 0.38)));
}

#[test]
fn transforms_apply_in_order() {
    let disk = |ops: &str| {
        let xml = scene(&format!(
            r#"<shape type="disk"><transform name="to_world">{ops}</transform></shape>"#
        ));
        disk_to_world(&load(&xml).unwrap())
    };
    // Scale, then translate: the origin lands on the translation.
    let st = disk(r#"<scale value="2"/><translate x="1"/>"#);
    assert!(close(
        st.transform_point3(Vec3::ZERO),
        Vec3::new(1.0, 0.0, 0.0)
    ));
    assert!(close(
        st.transform_point3(Vec3::X),
        Vec3::new(3.0, 0.0, 0.0)
    ));
    // Translate, then scale: the translation is scaled too.
    let ts = disk(r#"<translate value="1 0 0"/><scale value="2"/>"#);
    assert!(close(
        ts.transform_point3(Vec3::ZERO),
        Vec3::new(2.0, 0.0, 0.0)
    ));
    assert_ne!(st, ts);

    // Right-handed rotation: +x turns into +y about +z.
    let rot = disk(r#"<rotate z="1" angle="90"/>"#);
    assert!(close(rot.transform_vector3(Vec3::X), Vec3::Y));

    // Per-axis scale defaults to 1; a row-major matrix reads as written.
    let scale = disk(r#"<scale y="3"/>"#);
    assert!(close(
        scale.transform_vector3(Vec3::ONE),
        Vec3::new(1.0, 3.0, 1.0)
    ));
    let matrix = disk(r#"<matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/>"#);
    assert!(close(
        matrix.transform_point3(Vec3::ZERO),
        Vec3::new(5.0, 6.0, 7.0)
    ));
}

#[test]
fn mirrored_rectangle_keeps_front_along_transformed_normal() {
    let xml = scene(
        r#"<shape type="rectangle"><transform name="to_world"><scale z="-1"/><translate z="2"/></transform></shape>"#,
    );
    let scene = load(&xml).unwrap();
    // The inverse transpose of diag(1, 1, -1) maps +z to -z; the winding must follow.
    for n in face_normals(mesh(&scene, 0)) {
        assert!(close(n, -Vec3::Z), "normal {n}");
    }
}

#[test]
fn sphere_center_and_radius_come_from_to_world() {
    let xml = scene(
        r#"<shape type="sphere">
        <point name="center" x="1" y="0" z="0"/>
        <float name="radius" value="0.5"/>
        <transform name="to_world">
            <scale value="2"/>
            <rotate z="1" angle="90"/>
            <translate x="0" y="1" z="0"/>
        </transform>
    </shape>"#,
    );
    let scene = load(&xml).unwrap();
    match scene.shapes[0].geometry {
        GeometryDesc::Sphere { center, radius } => {
            assert!(close(center, Vec3::new(0.0, 3.0, 0.0)), "center {center}");
            assert!((radius - 1.0).abs() < 1e-6, "radius {radius}");
        }
        ref other => panic!("not a sphere: {other:?}"),
    }
    assert!(same(&scene.shapes[0].bsdf, &Diffuse::new(Vec3::splat(0.5))));

    let xml = self::scene(
        r#"<shape type="sphere">
        <transform name="to_world"><scale x="1" y="2" z="1"/></transform>
    </shape>"#,
    );
    expect_error(
        &xml,
        "<transform",
        "transform name=\"to_world\"",
        &["non-uniform"],
    );
}

#[test]
fn bsdfs_defaults_refs_and_emitters() {
    let xml = r#"<scene version="3.5.2">
    <default name="spp" value="16"/>
    <default name="glass" value="water"/>
    <sensor type="perspective">
        <float name="fov" value="30"/>
        <string name="fov_axis" value="y"/>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="32"/>
            <string name="pixel_format" value="rgb"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <integrator type="path"><integer name="max_depth" value="-1"/></integrator>
    <bsdf type="roughconductor" id="metal">
        <string name="distribution" value="ggx"/>
        <float name="alpha" value="0.3"/>
        <rgb name="specular_reflectance" value="0.9 0.8 0.7"/>
    </bsdf>
    <shape type="disk"><ref id="metal"/></shape>
    <shape type="disk"><ref name="bsdf" id="metal"/></shape>
    <shape type="disk"><bsdf type="dielectric"><string name="int_ior" value="$glass"/></bsdf></shape>
    <shape type="disk"><bsdf type="twosided"><bsdf type="conductor"/></bsdf></shape>
    <shape type="disk"><bsdf type="diffuse"><float name="reflectance" value="0.25"/></bsdf></shape>
    <emitter type="point">
        <rgb name="intensity" value="5"/>
        <point name="position" value="1, 2, 3"/>
    </emitter>
    <emitter type="point">
        <float name="intensity" value="1"/>
        <transform name="to_world"><translate x="4"/></transform>
    </emitter>
    <emitter type="constant"><rgb name="radiance" value="0.1, 0.2, 0.3"/></emitter>
</scene>"#;
    let scene = load(xml).unwrap();
    assert_eq!(scene.camera.spp, 16);
    assert_eq!((scene.camera.width, scene.camera.height), (32, 576));
    assert_eq!(scene.camera.fov_axis, FovAxis::Y);
    assert_eq!(scene.camera.to_world, Mat4::IDENTITY);
    assert_eq!(scene.integrator.max_depth, None);
    let metal = RoughConductor::new(0.3, Vec3::new(0.9, 0.8, 0.7));
    assert!(same(&scene.shapes[0].bsdf, &metal));
    assert!(same(&scene.shapes[1].bsdf, &metal));
    assert!(same(
        &scene.shapes[2].bsdf,
        &Dielectric::new(1.3330, 1.000277)
    ));
    let mirror = Conductor::mirror(Vec3::ONE);
    assert!(same(&scene.shapes[3].bsdf, &TwoSided(Arc::new(mirror))));
    assert!(same(
        &scene.shapes[4].bsdf,
        &Diffuse::new(Vec3::splat(0.25))
    ));
    let lights = [
        format!(
            "{:?}",
            PointLight {
                position: Vec3::new(1.0, 2.0, 3.0),
                intensity: Vec3::splat(5.0)
            }
        ),
        format!(
            "{:?}",
            PointLight {
                position: Vec3::new(4.0, 0.0, 0.0),
                intensity: Vec3::splat(1.0)
            }
        ),
        format!(
            "{:?}",
            Constant {
                radiance: Vec3::new(0.1, 0.2, 0.3)
            }
        ),
    ];
    let loaded: Vec<String> = scene.emitters.iter().map(|e| format!("{e:?}")).collect();
    assert_eq!(loaded, lights);
}

#[test]
fn error_misspelt_parameter() {
    let xml = scene(
        r#"<shape type="cube">
        <bsdf type="diffuse">
            <rgb name="reflectanse" value="0.5"/>
        </bsdf>
    </shape>"#,
    );
    let text = expect_error(
        &xml,
        "<rgb name=\"reflectanse\"",
        "rgb name=\"reflectanse\"",
        &[
            "reflectanse",
            "bsdf type=\"diffuse\"",
            "did you mean \"reflectance\"",
        ],
    );
    assert!(
        text.contains(&format!("(line {})", line_of(&xml, "<bsdf"))),
        "{text}"
    );
}

#[test]
fn error_unknown_shape_type() {
    let xml = scene(r#"<shape type="torus"/>"#);
    expect_error(
        &xml,
        "<shape",
        "shape type=\"torus\"",
        &["\"torus\"", "rectangle"],
    );
}

#[test]
fn error_unknown_bsdf_type() {
    let xml = scene(r#"<shape type="cube"><bsdf type="hair"/></shape>"#);
    expect_error(
        &xml,
        "<shape",
        "bsdf type=\"hair\"",
        &["\"hair\"", "diffuse"],
    );
}

#[test]
fn error_unparsable_float() {
    let xml = scene(
        r#"<shape type="cube">
        <bsdf type="roughconductor">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.1x"/>
        </bsdf>
    </shape>"#,
    );
    expect_error(
        &xml,
        "<float name=\"alpha\"",
        "float name=\"alpha\"",
        &["\"0.1x\""],
    );
}

#[test]
fn error_missing_rfilter() {
    let xml = r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <film type="hdrfilm">
            <integer name="width" value="64"/>
        </film>
    </sensor>
</scene>"#;
    expect_error(
        xml,
        "<film",
        "film type=\"hdrfilm\"",
        &["rfilter", "gaussian"],
    );
}

#[test]
fn error_roughconductor_with_an_unknown_distribution() {
    let xml = scene(
        r#"<shape type="cube">
        <bsdf type="roughconductor"><string name="distribution" value="phong"/></bsdf>
    </shape>"#,
    );
    expect_error(
        &xml,
        "<string",
        "string name=\"distribution\"",
        &["\"phong\"", "beckmann or ggx"],
    );
}

#[test]
fn error_undefined_default() {
    let xml = scene(
        r#"<shape type="sphere">
        <float name="radius" value="$undefined"/>
    </shape>"#,
    );
    expect_error(
        &xml,
        "<float name=\"radius\"",
        "float name=\"radius\"",
        &["$undefined"],
    );
}

#[test]
fn error_unknown_ref_id() {
    let xml = scene(
        r#"<bsdf type="diffuse" id="white"/>
    <shape type="cube"><ref id="whit"/></shape>"#,
    );
    expect_error(&xml, "<ref", "ref id=\"whit\"", &["\"whit\"", "white"]);
}

#[test]
fn error_two_sensors() {
    let xml = format!("<scene version=\"3.0.0\">\n    {SENSOR}\n    {SENSOR}\n</scene>");
    let second = xml.rfind("<sensor").unwrap();
    let err = load(&xml).unwrap_err();
    let line = xml[..second].matches('\n').count() + 1;
    let text = err.to_string();
    assert!(
        text.starts_with(&format!("{FILE}:{line}: <sensor type=\"perspective\">: ")),
        "{text}"
    );
    assert!(text.contains("line 2"), "{text}");
}

#[test]
fn error_parameter_given_twice() {
    let xml = scene(
        r#"<shape type="cube">
        <bsdf type="diffuse">
            <rgb name="reflectance" value="0.5"/>
            <rgb name="reflectance" value="0.7"/>
        </bsdf>
    </shape>"#,
    );
    let second = xml.rfind("<rgb").unwrap();
    let err = load(&xml).unwrap_err().to_string();
    let line = xml[..second].matches('\n').count() + 1;
    assert!(
        err.starts_with(&format!("{FILE}:{line}: <rgb name=\"reflectance\">: ")),
        "{err}"
    );
    assert!(err.contains("twice"), "{err}");
    assert!(err.contains(&format!("line {}", line - 1)), "{err}");
}

#[test]
fn error_missing_obj_file() {
    let xml = scene(
        r#"<shape type="obj">
        <string name="filename" value="no_such_mesh.obj"/>
    </shape>"#,
    );
    expect_error(
        &xml,
        "<string",
        "string name=\"filename\"",
        &["no_such_mesh.obj"],
    );
}

#[test]
fn error_unsupported_features_are_named() {
    // max_depth = 0, flip_normals, a missing version, an unknown tag and a wrong value kind.
    let xml =
        scene(r#"<integrator type="path"><integer name="max_depth" value="0"/></integrator>"#);
    expect_error(
        &xml,
        "<integer",
        "integer name=\"max_depth\"",
        &["max_depth = 0"],
    );
    let xml = scene(r#"<shape type="cube"><boolean name="flip_normals" value="true"/></shape>"#);
    expect_error(
        &xml,
        "<boolean",
        "boolean name=\"flip_normals\"",
        &["flip_normals"],
    );
    let xml = scene(r#"<shape type="cube"><texture type="bitmap"/></shape>"#);
    expect_error(
        &xml,
        "<texture",
        "texture type=\"bitmap\"",
        &["not allowed inside <shape"],
    );
    let xml = scene(r#"<shape type="sphere"><integer name="radius" value="2"/></shape>"#);
    expect_error(
        &xml,
        "<integer",
        "integer name=\"radius\"",
        &["<float>", "<integer>"],
    );
    let xml = "<scene version=\"1.0.0\">\n</scene>";
    expect_error(xml, "<scene", "scene", &["1.0.0"]);
    let xml = scene(r#"<emitter type="area"><rgb name="radiance" value="1"/></emitter>"#);
    expect_error(
        &xml,
        "<emitter",
        "emitter type=\"area\"",
        &["inside a <shape>"],
    );
    let xml = "<scene version=\"3.0.0\">\n</scene>";
    expect_error(xml, "<scene", "scene", &["sensor"]);
}

/// A fresh folder under the system temp dir.
fn temp_dir(tag: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    let dir = std::env::temp_dir().join(format!(
        "fireflies_render_loader_{tag}_{}_{nanos}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn obj_mesh_loads_with_its_normals() {
    let dir = temp_dir("obj");
    // A unit quad in the z = 0 plane facing +z, with vertex normals tilted differently.
    let obj = "\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vn 0 0 1
vn 0 0.6 0.8
vn 0 0 1
vn 0.6 0 0.8
f 1//1 2//2 3//3 4//4
";
    std::fs::write(dir.join("quad.obj"), obj).unwrap();
    std::fs::write(dir.join("bare.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let xml = scene(
        r#"<shape type="obj">
        <string name="filename" value="quad.obj"/>
        <transform name="to_world"><rotate x="1" angle="90"/><translate z="5"/></transform>
    </shape>
    <shape type="obj">
        <string name="filename" value="quad.obj"/>
        <boolean name="face_normals" value="true"/>
    </shape>
    <shape type="obj"><string name="filename" value="bare.obj"/></shape>"#,
    );
    std::fs::write(dir.join("scene.xml"), &xml).unwrap();
    let scene = load_file(&dir.join("scene.xml")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();

    let quad = mesh(&scene, 0);
    assert_eq!(quad.positions.len(), 4);
    assert_eq!(quad.indices.len(), 2);
    // Rotating +z by 90 degrees about +x gives -y; (0, 0.6, 0.8) goes to (0, -0.8, 0.6).
    let normals = quad.normals.as_ref().expect("the file has normals");
    assert!(close(normals[0], -Vec3::Y), "{normals:?}");
    assert!(close(normals[1], Vec3::new(0.0, -0.8, 0.6)), "{normals:?}");
    assert!(
        close(quad.positions[2], Vec3::new(1.0, 0.0, 6.0)),
        "{:?}",
        quad.positions
    );
    for n in face_normals(quad) {
        assert!(close(n, -Vec3::Y), "winding normal {n}");
    }

    assert_eq!(mesh(&scene, 1).normals, None);
    assert_eq!(mesh(&scene, 1).indices.len(), 2);
    // Without normals in the file, Mitsuba computes vertex normals.
    assert_eq!(mesh(&scene, 2).normals, Some(vec![Vec3::Z; 3]));
}

#[test]
fn obj_without_triangles_is_an_error() {
    let dir = temp_dir("empty");
    std::fs::write(dir.join("points.obj"), "v 0 0 0\nv 1 0 0\n").unwrap();
    let xml = scene(r#"<shape type="obj"><string name="filename" value="points.obj"/></shape>"#);
    let err = load_str(&xml, &dir, FILE).unwrap_err().to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(err.contains("no triangles"), "{err}");
    assert!(err.contains("points.obj"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// Issue 10: large scenes, huge coordinates, OBJ lines and numbers in messages

/// Loads `xml` with OBJ files `objs` (name, text) beside it; returns the result and the
/// folder's path (already removed).
fn load_with_objs(xml: &str, objs: &[(&str, &str)], tag: &str) -> Result<SceneDesc, Error> {
    let dir = temp_dir(tag);
    for (name, text) in objs {
        std::fs::write(dir.join(name), text).unwrap();
    }
    let result = load_str(xml, &dir, FILE);
    std::fs::remove_dir_all(&dir).unwrap();
    result
}

/// The message of an [`Error::Scene`], checking its line and element.
#[track_caller]
fn scene_error(result: Result<SceneDesc, Error>, line: u32, element: &str) -> String {
    match result {
        Err(Error::Scene {
            line: got_line,
            element: got_element,
            message,
            ..
        }) => {
            assert_eq!(
                (got_line, got_element.as_str()),
                (line, element),
                "{message}"
            );
            message
        }
        other => panic!("expected Error::Scene, got {other:?}"),
    }
}

/// No decimal expansion longer than 20 digits (f32's `Display` prints 3e38 as 39 digits).
#[track_caller]
fn assert_short_numbers(message: &str) {
    let longest = message
        .split(|c: char| !c.is_ascii_digit())
        .map(str::len)
        .max()
        .unwrap_or(0);
    assert!(longest <= 20, "a {longest}-digit number in: {message}");
}

/// The OBJ ground plane `y = 0` reaching `s` (one triangle facing `+y` over the origin).
fn ground_obj(s: &str) -> String {
    format!("# ground\nv -{s} 0 {s}\nv {s} 0 {s}\nv 0 0 -{s}\nf 1 2 3\n")
}

/// Issue 10: an OBJ triangle with coordinates of 1e10 to 1e38 was invisible (the image equalled
/// the scene without it). Up to the coordinate limit it now renders what the closed form says:
/// a Lambertian floor of albedo 0.5 under a point light of intensity 10 at height 1, seen
/// straight down through a 0.2° field of view, is ρ/π · I/h² (the footprint changes it by
/// < 1e-5). Before the fix the pixel was black.
#[test]
fn huge_obj_ground_renders_the_closed_form() {
    let xml = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="0.2"/>
        <transform name="to_world"><lookat origin="0, 3, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
        <film type="hdrfilm"><integer name="width" value="1"/><integer name="height" value="1"/><rfilter type="box"/></film>
    </sensor>
    <emitter type="point"><rgb name="intensity" value="10"/><point name="position" value="0, 1, 0"/></emitter>
    <shape type="obj">
        <string name="filename" value="ground.obj"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    </shape>
</scene>"#;
    let exact = 0.5 / std::f64::consts::PI * 10.0;
    for s in ["10", "1e10", "1e15", "1e18"] {
        let scene = load_with_objs(xml, &[("ground.obj", &ground_obj(s))], "ground")
            .unwrap_or_else(|err| panic!("s = {s}: {err}"));
        assert_eq!(mesh(&scene, 0).normals, Some(vec![Vec3::Y; 3]), "s = {s}");
        let world = World::new(&scene);
        assert_eq!(world.bvh.len(), 1, "s = {s}: the triangle was dropped");
        let mut sum = 0.0f64;
        for sample in 0..16 {
            let mut rng = SampleStream::new(11, 0, sample);
            let l = radiance(&world, 0, 0, &mut rng);
            sum += (f64::from(l.x) + f64::from(l.y) + f64::from(l.z)) / 3.0;
        }
        let mean = sum / 16.0;
        assert!(
            (mean - exact).abs() < 1e-4 * exact,
            "s = {s}: {mean} vs {exact}"
        );
    }
}

/// Beyond the coordinate limit (1e18) the scene is refused, naming the OBJ file and line, the
/// shape, the offending value and the limit, instead of rendering without the shape.
#[test]
fn coordinates_beyond_the_limit_are_refused_with_file_shape_and_value() {
    for (s, shown) in [("1e20", "1e20"), ("1e38", "1e38")] {
        let xml = scene(
            r#"<shape type="obj">
        <string name="filename" value="huge.obj"/>
    </shape>"#,
        );
        let result = load_with_objs(&xml, &[("huge.obj", &ground_obj(s))], "huge");
        let message = scene_error(result, line_of(&xml, "<shape"), "shape type=\"obj\"");
        for fragment in ["huge.obj, line 2", shown, "±1e18"] {
            assert!(message.contains(fragment), "{fragment:?} not in {message}");
        }
        assert_short_numbers(&message);
    }
    // The same through to_world, and for the other shapes, lights and the camera.
    let cases = [
        (
            r#"<shape type="cube"><transform name="to_world"><scale value="1e30"/></transform></shape>"#,
            "<shape",
            "shape type=\"cube\"",
            "1e30",
        ),
        (
            r#"<shape type="sphere"><point name="center" x="1e19" y="0" z="0"/></shape>"#,
            "<shape",
            "shape type=\"sphere\"",
            "1e19",
        ),
        (
            r#"<shape type="disk"><transform name="to_world"><translate z="-3e20"/></transform></shape>"#,
            "<shape",
            "shape type=\"disk\"",
            "3e20",
        ),
        (
            r#"<emitter type="point"><rgb name="intensity" value="1"/><point name="position" value="0, 2e18, 0"/></emitter>"#,
            "<emitter",
            "emitter type=\"point\"",
            "2e18",
        ),
    ];
    for (body, needle, element, shown) in cases {
        let xml = scene(body);
        let message = scene_error(load(&xml), line_of(&xml, needle), element);
        assert!(message.contains(shown), "{shown} not in {message}");
        assert!(message.contains("±1e18"), "{message}");
        assert_short_numbers(&message);
    }
    let xml = r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><translate x="5e18"/></transform>
        <film type="hdrfilm"><rfilter type="box"/></film>
    </sensor>
</scene>"#;
    let message = scene_error(
        load(xml),
        line_of(xml, "<transform"),
        "transform name=\"to_world\"",
    );
    assert!(
        message.contains("camera position (5e18, 0, 0)"),
        "{message}"
    );
}

/// Issue 10: OBJ parse errors named neither the OBJ line nor the offending text ("cannot parse
/// OBJ file m.obj: face parse error").
#[test]
fn obj_errors_name_the_obj_file_and_line() {
    let cases = [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "line 4", "\"x\""),
        (
            "v 0 0 0\nv 1 0 0\n# a comment\nv 0 1 zero\nf 1 2 3\n",
            "line 4",
            "\"zero\"",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 4\n",
            "line 5",
            "index 4 is out of range",
        ),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "line 4", "index 0"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 0\nf 1 2 3\n",
            "line 4",
            "zero length",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
            "line 4",
            "at least 3 vertices",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 1e39 1 0\nf 1 2 3\n",
            "line 3",
            "not a finite",
        ),
        (
            "v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nvn 0 0 1\r\nf 1//1 2//1 3//1\r\nf 1 2 3\r\n",
            "line 6",
            "no normal",
        ),
    ];
    for (text, line, fragment) in cases {
        let xml = scene(r#"<shape type="obj"><string name="filename" value="bad.obj"/></shape>"#);
        let result = load_with_objs(&xml, &[("bad.obj", text)], "badobj");
        let message = scene_error(result, line_of(&xml, "<string"), "string name=\"filename\"");
        let located = format!("bad.obj, {line}: ");
        assert!(message.contains(&located), "{located:?} not in {message}");
        assert!(message.contains(fragment), "{fragment:?} not in {message}");
    }
}

/// Issue 10: numbers in loader messages print short (f32's `Display` wrote 3e38 as 39 digits),
/// and integers beyond the 64-bit range say so.
#[test]
fn numbers_in_messages_are_short() {
    let cases = [
        (
            r#"<sensor type="perspective"><float name="fov" value="3e38"/><film type="hdrfilm"><rfilter type="box"/></film></sensor>"#,
            "<float",
            "float name=\"fov\"",
            "fov = 3e38",
        ),
        (
            r#"<sensor type="perspective"><float name="fov" value="45"/><float name="near_clip" value="1e30"/><film type="hdrfilm"><rfilter type="box"/></film></sensor>"#,
            "<float name=\"near",
            "float name=\"near_clip\"",
            "far_clip = 10000 must exceed near_clip = 1e30",
        ),
        (
            r#"<shape type="sphere"><float name="radius" value="-1e38"/></shape>"#,
            "<float name=\"radius\"",
            "float name=\"radius\"",
            "radius = -1e38",
        ),
        (
            r#"<shape type="cube"><transform name="to_world"><matrix value="1e38 0 0 0 0 1e38 0 0 0 0 1e38 0 0 0 0 1"/><scale value="1e30"/></transform></shape>"#,
            "<transform",
            "transform name=\"to_world\"",
            "not finite: [inf 0 0 0;",
        ),
        (
            r#"<sensor type="perspective"><float name="fov" value="45"/><film type="hdrfilm"><integer name="width" value="99999999999999999999"/><rfilter type="box"/></film></sensor>"#,
            "<integer",
            "integer name=\"width\"",
            "out of the 64-bit integer range",
        ),
        (
            r#"<sensor type="perspective"><float name="fov" value="45"/><film type="hdrfilm"><integer name="height" value="4294967296"/><rfilter type="box"/></film></sensor>"#,
            "<integer",
            "integer name=\"height\"",
            "height = 4294967296: must be in 1..=4294967295",
        ),
    ];
    for (body, needle, element, fragment) in cases {
        // Without the default sensor where the case brings its own.
        let xml = if body.starts_with("<sensor") {
            format!("<scene version=\"3.0.0\">\n{body}\n</scene>\n")
        } else {
            scene(body)
        };
        let message = scene_error(load(&xml), line_of(&xml, needle), element);
        assert!(message.contains(fragment), "{fragment:?} not in {message}");
        if !fragment.contains("integer") && !fragment.contains("4294967296") {
            assert_short_numbers(&message);
        }
    }
}

/// Loading is linear in the scene's size: 20,000 spheres load, and an error after them names
/// its line (the loader finds lines in an index built once instead of scanning the file from
/// its start for each element). The non-timing guard against the quadratic loader is the unit
/// test `a_successful_load_looks_up_no_line` in `src/render/mitsuba/mod.rs`.
#[test]
fn large_scenes_load_and_late_errors_name_their_line() {
    let mut body = String::new();
    for i in 0..20_000 {
        body.push_str(&format!(
            "<shape type=\"sphere\" id=\"s{i}\"><point name=\"center\" x=\"{i}\" y=\"0\" z=\"0\"/><float name=\"radius\" value=\"0.4\"/></shape>\n"
        ));
    }
    let xml = scene(&body);
    assert_eq!(load(&xml).expect("loads").shapes.len(), 20_000);
    let bad = scene(&format!(
        "{body}<shape type=\"sphere\"><float name=\"radius\" value=\"0\"/></shape>"
    ));
    let message = scene_error(
        load(&bad),
        line_of(&bad, "value=\"0\""),
        "float name=\"radius\"",
    );
    assert!(message.contains("radius = 0"), "{message}");
    let dup = scene(&format!("{body}<shape type=\"cube\" id=\"s19999\"/>"));
    let message = scene_error(
        load(&dup),
        line_of(&dup, "<shape type=\"cube\""),
        "shape type=\"cube\"",
    );
    let first = line_of(&dup, "id=\"s19999\"");
    assert!(message.contains(&format!("at line {first}")), "{message}");
}

/// Mitsuba gives a shape without a BSDF a diffuse one of reflectance 0.5, except when the shape
/// carries an area emitter: then the default is black (Mitsuba 3.9.1's `Shape` constructor;
/// `mi.load_dict({'type': 'rectangle', 'emitter': {...}}).bsdf()` prints reflectance 0). With
/// 0.5 on the light, the path floor → light's front → floor added ~0.2% to the feature scenes.
/// Deterministic: it cannot fail by chance.
#[test]
fn a_light_without_a_bsdf_reflects_nothing() {
    let xml = scene(
        r#"<shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
    <shape type="rectangle"/>
    <shape type="rectangle">
        <bsdf type="diffuse"><rgb name="reflectance" value="0.9"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>"#,
    );
    let scene = load(&xml).unwrap();
    assert!(same(&scene.shapes[0].bsdf, &Diffuse::new(Vec3::ZERO)));
    assert!(same(&scene.shapes[1].bsdf, &Diffuse::new(Vec3::splat(0.5))));
    assert!(same(&scene.shapes[2].bsdf, &Diffuse::new(Vec3::splat(0.9))));
}
