//! The Mitsuba 3 XML loader: the Cornell box, transforms, shapes, OBJ meshes and the errors that
//! name file, line and element.

use std::path::{Path, PathBuf};

use fireflies::Error;
use fireflies::render::mitsuba::{load_file, load_str};
use fireflies::render::scene::{BsdfDesc, FovAxis, GeometryDesc, MeshDesc, SceneDesc};
use glam::{Mat4, Vec3};

const FILE: &str = "test.xml";

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
    assert!(scene.point_lights.is_empty());
    assert_eq!(scene.environment, None);

    let camera = scene.camera;
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
    assert_eq!(
        scene.shapes[5].bsdf,
        BsdfDesc::Diffuse {
            reflectance: Vec3::new(0.570068, 0.043014, 0.044371)
        }
    );

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
    assert_eq!(scene.shapes[0].bsdf, BsdfDesc::default());

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
    let metal = BsdfDesc::RoughConductor {
        alpha: 0.3,
        specular_reflectance: Vec3::new(0.9, 0.8, 0.7),
    };
    assert_eq!(scene.shapes[0].bsdf, metal);
    assert_eq!(scene.shapes[1].bsdf, metal);
    assert_eq!(
        scene.shapes[2].bsdf,
        BsdfDesc::Dielectric {
            int_ior: 1.3330,
            ext_ior: 1.000277,
            specular_reflectance: Vec3::ONE,
            specular_transmittance: Vec3::ONE,
        }
    );
    assert_eq!(
        scene.shapes[3].bsdf,
        BsdfDesc::TwoSided(Box::new(BsdfDesc::Conductor {
            specular_reflectance: Vec3::ONE
        }))
    );
    assert_eq!(
        scene.shapes[4].bsdf,
        BsdfDesc::Diffuse {
            reflectance: Vec3::splat(0.25)
        }
    );
    assert_eq!(scene.point_lights.len(), 2);
    assert_eq!(scene.point_lights[0].position, Vec3::new(1.0, 2.0, 3.0));
    assert_eq!(scene.point_lights[0].intensity, Vec3::splat(5.0));
    assert_eq!(scene.point_lights[1].position, Vec3::new(4.0, 0.0, 0.0));
    assert_eq!(scene.environment, Some(Vec3::new(0.1, 0.2, 0.3)));
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
    let xml = scene(r#"<shape type="cube"><bsdf type="plastic"/></shape>"#);
    expect_error(
        &xml,
        "<shape",
        "bsdf type=\"plastic\"",
        &["\"plastic\"", "diffuse"],
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
fn error_roughconductor_without_distribution() {
    let xml = scene(
        r#"<shape type="cube">
        <bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf>
    </shape>"#,
    );
    expect_error(
        &xml,
        "<bsdf",
        "bsdf type=\"roughconductor\"",
        &["distribution", "beckmann", "ggx"],
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
    expect_error(&xml, "<texture", "texture type=\"bitmap\"", &["<texture>"]);
    let xml = scene(r#"<shape type="sphere"><integer name="radius" value="2"/></shape>"#);
    expect_error(
        &xml,
        "<integer",
        "integer name=\"radius\"",
        &["<float>", "<integer>"],
    );
    let xml = "<scene version=\"2.1.0\">\n</scene>";
    expect_error(xml, "<scene", "scene", &["2.1.0"]);
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
