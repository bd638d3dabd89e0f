//! The loader on what the seeds' scenes need besides Mitsuba 3 files: scenes in Mitsuba 0.5's
//! format (read as Mitsuba 3 upgrades them), film parameters without effect, the reconstruction
//! filter override, and the refusal of textures on shapes without texture coordinates.

use fireflies::Error;
use fireflies::render::mitsuba::{LoadOptions, load_file_with, load_str};
use fireflies::render::scene::{GeometryDesc, SceneDesc};
use glam::Vec3;
use std::path::Path;

fn load(xml: &str) -> Result<SceneDesc, Error> {
    load_str(xml, Path::new("."), "test.xml")
}

/// A scene in Mitsuba 0.5's format as Bitterli's scenes write it: camelCase parameter names,
/// `lookAt`, comma-separated colours, film parameters that only change file output.
const OLD: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<scene version="0.5.0">
    <integrator type="path"><integer name="maxDepth" value="65"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="90"/>
        <transform name="toWorld"><lookAt origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sampleCount" value="256"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="64"/>
            <integer name="height" value="36"/>
            <string name="fileFormat" value="openexr"/>
            <string name="pixelFormat" value="rgb"/>
            <boolean name="banner" value="false"/>
            <rfilter name="rfilter" type="box"/>
            <boolean name="high_quality_edges" value="true"/>
        </film>
    </sensor>
    <bsdf type="twosided" id="Walls">
        <bsdf type="diffuse"><rgb name="reflectance" value="0.1, 0.2, 0.3"/></bsdf>
    </bsdf>
    <bsdf type="dielectric" id="Glass">
        <float name="intIOR" value="1.5"/>
        <float name="extIOR" value="1"/>
    </bsdf>
    <shape type="rectangle">
        <transform name="toWorld"><matrix value="1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"/></transform>
        <ref id="Walls"/>
    </shape>
    <shape type="sphere"><ref id="Glass"/></shape>
</scene>
"#;

#[test]
fn mitsuba_05_names_are_upgraded_as_mitsuba_3_does() {
    let scene = load(OLD).expect("a 0.5 scene loads");
    assert_eq!(scene.integrator.max_depth, Some(65));
    assert_eq!(scene.camera.spp, 256);
    assert_eq!((scene.camera.width, scene.camera.height), (64, 36));
    assert_eq!(scene.camera.fov_deg, 90.0);
    // lookAt from +z towards the origin: the camera looks down -z.
    let dir = scene.camera.to_world.transform_vector3(Vec3::Z);
    assert!((dir - Vec3::NEG_Z).length() < 1e-6, "{dir}");
    let walls = format!("{:?}", scene.shapes[0].bsdf);
    assert!(walls.contains("0.1, 0.2, 0.3"), "{walls}");
    let glass = format!("{:?}", scene.shapes[1].bsdf);
    assert!(glass.contains("eta: 1.5"), "{glass}");
}

#[test]
fn camel_case_is_an_error_in_mitsuba_3_files() {
    let xml = OLD.replace("0.5.0", "3.0.0");
    let err = load(&xml)
        .expect_err("camelCase is not Mitsuba 3")
        .to_string();
    assert!(err.contains("unknown parameter \"maxDepth\""), "{err}");
}

#[test]
fn unknown_versions_are_refused() {
    for v in ["1.0.0", "4.0.0", "0.5", "x.y.z"] {
        let err = load(&OLD.replace("0.5.0", v)).expect_err(v).to_string();
        assert!(err.contains("is not a Mitsuba scene version"), "{err}");
    }
}

#[test]
fn non_box_filters_need_the_override() {
    let tent = OLD.replace(r#"type="box""#, r#"type="tent""#);
    let err = load(&tent)
        .expect_err("tent needs --rfilter box")
        .to_string();
    assert!(
        err.contains("asks for the \"tent\" reconstruction filter"),
        "{err}"
    );
    assert!(err.contains("--rfilter box"), "{err}");

    let dir = std::env::temp_dir().join(format!("fireflies-rfilter-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tent.xml");
    std::fs::write(&path, &tent).unwrap();
    let options = LoadOptions { box_filter: true };
    let scene = load_file_with(&path, options).expect("the override accepts it");
    assert_eq!(scene.camera.replaced_filter.as_deref(), Some("tent"));
    // A gaussian with its own parameter is replaced wholesale.
    let gauss = OLD.replace(
        r#"<rfilter name="rfilter" type="box"/>"#,
        r#"<rfilter type="gaussian"><float name="stddev" value="0.5"/></rfilter>"#,
    );
    std::fs::write(&path, &gauss).unwrap();
    let scene = load_file_with(&path, options).expect("gaussian under the override");
    assert_eq!(scene.camera.replaced_filter.as_deref(), Some("gaussian"));
    // A box stays a box, with nothing replaced.
    std::fs::write(&path, OLD).unwrap();
    let scene = load_file_with(&path, options).unwrap();
    assert_eq!(scene.camera.replaced_filter, None);
    // Without a film, Mitsuba's default (gaussian) is what the override replaces.
    let start = OLD.find("<film").unwrap();
    let end = OLD.find("</film>").unwrap() + "</film>".len();
    let no_film = format!("{}{}", &OLD[..start], &OLD[end..]);
    std::fs::write(&path, &no_film).unwrap();
    let scene = load_file_with(&path, options).unwrap();
    assert_eq!(scene.camera.replaced_filter.as_deref(), Some("gaussian"));
    assert_eq!((scene.camera.width, scene.camera.height), (768, 576));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn film_output_parameters_are_checked() {
    let bad = OLD.replace(r#"value="openexr""#, r#"value="jpeg2000""#);
    let err = load(&bad).expect_err("unknown file format").to_string();
    assert!(err.contains("\"jpeg2000\" is not one of"), "{err}");
}

#[test]
fn masks_load_with_their_nested_bsdf() {
    let xml = OLD.replace(
        r#"<shape type="sphere"><ref id="Glass"/></shape>"#,
        r#"<shape type="rectangle"><bsdf type="mask"><float name="opacity" value="0.25"/><ref id="Walls"/></bsdf></shape>"#,
    );
    let scene = load(&xml).expect("mask loads");
    let mask = format!("{:?}", scene.shapes[1].bsdf);
    assert!(mask.starts_with("Mask"), "{mask}");
    let twice = xml.replace(
        r#"<ref id="Walls"/></bsdf></shape>"#,
        r#"<ref id="Walls"/><ref id="Walls"/></bsdf></shape>"#,
    );
    let err = load(&twice).expect_err("two nested").to_string();
    assert!(err.contains("exactly one nested bsdf"), "{err}");
    // twosided refuses a mask (it transmits), as Mitsuba does.
    let wrapped = xml.replace(
        r#"<bsdf type="mask"><float name="opacity" value="0.25"/><ref id="Walls"/></bsdf>"#,
        r#"<bsdf type="twosided"><bsdf type="mask"><ref id="Walls"/></bsdf></bsdf>"#,
    );
    let err = load(&wrapped).expect_err("twosided over mask").to_string();
    assert!(err.contains("twosided cannot wrap"), "{err}");
}

#[test]
fn rectangles_have_mitsubas_texture_coordinates() {
    let scene = load(OLD).unwrap();
    let GeometryDesc::Mesh(mesh) = &scene.shapes[0].geometry else {
        panic!("a rectangle is a mesh");
    };
    let uvs = mesh.uvs.as_ref().expect("rectangles have uvs");
    for (p, uv) in mesh.positions.iter().zip(uvs) {
        assert_eq!(uv.x, (p.x + 1.0) / 2.0);
        assert_eq!(uv.y, (p.y + 1.0) / 2.0);
    }
}

/// Mitsuba 3.9.1's cube texture coordinates: `si.uv` of its `cube` hit at three points per face
/// (read in the venv with `scene.ray_intersect`), against ours; the mesh's vertices carry the
/// same map, which is linear on each face, so every interpolated hit agrees too.
#[test]
fn cubes_have_mitsubas_texture_coordinates() {
    use fireflies::render::shapes::mesh::cube_uv;
    use glam::Vec2;
    #[rustfmt::skip]
    let mitsuba: [([f32; 3], [f32; 2]); 18] = [
        ([-1.0, 0.5, 0.25], [0.75, 0.625]), ([-1.0, -0.5, 0.25], [0.25, 0.625]),
        ([-1.0, 0.5, -0.75], [0.75, 0.125]), ([1.0, 0.5, 0.25], [0.75, 0.375]),
        ([1.0, -0.5, 0.25], [0.25, 0.375]), ([1.0, 0.5, -0.75], [0.75, 0.875]),
        ([0.5, -1.0, 0.25], [0.625, 0.75]), ([-0.5, -1.0, 0.25], [0.625, 0.25]),
        ([0.5, -1.0, -0.75], [0.125, 0.75]), ([0.5, 1.0, 0.25], [0.25, 0.375]),
        ([-0.5, 1.0, 0.25], [0.75, 0.375]), ([0.5, 1.0, -0.75], [0.25, 0.875]),
        ([0.5, 0.25, -1.0], [0.375, 0.75]), ([-0.5, 0.25, -1.0], [0.375, 0.25]),
        ([0.5, -0.75, -1.0], [0.875, 0.75]), ([0.5, 0.25, 1.0], [0.625, 0.75]),
        ([-0.5, 0.25, 1.0], [0.625, 0.25]), ([0.5, -0.75, 1.0], [0.125, 0.75]),
    ];
    for (p, uv) in mitsuba {
        assert_eq!(cube_uv(Vec3::from(p)), Vec2::from(uv), "at {p:?}");
    }
    let xml = OLD.replace(
        r#"<shape type="sphere"><ref id="Glass"/></shape>"#,
        r#"<shape type="cube"/>"#,
    );
    let scene = load(&xml).unwrap();
    let GeometryDesc::Mesh(mesh) = &scene.shapes[1].geometry else {
        panic!("a cube is a mesh");
    };
    // Every triangle's interpolated uv at its centroid (inside one face, so the face is
    // unambiguous) is the face's map there; at the corner vertices themselves every axis has
    // |p| = 1, which once gave all corners the x face's coordinates.
    let uvs = mesh.uvs.as_ref().expect("cubes have uvs");
    for t in &mesh.indices {
        let p = t.map(|i| mesh.positions[i as usize]);
        let uv = t.map(|i| uvs[i as usize]);
        let centroid = (p[0] + p[1] + p[2]) / 3.0;
        let interpolated = (uv[0] + uv[1] + uv[2]) / 3.0;
        let want = cube_uv(centroid);
        assert!(
            (interpolated - want).abs().max_element() < 1e-6,
            "triangle at {centroid}: {interpolated} against {want}"
        );
    }
}
