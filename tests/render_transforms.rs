//! `<rotate>` in the Mitsuba loader, checked against the matrices Mitsuba 3.9.1 itself builds.
//!
//! Mitsuba 3 (Dr.Jit's `rotate`) does not normalise the axis: for an axis `a` and angle θ it
//! builds `cos θ·I + (1 − cos θ)·a·aᵀ + sin θ·[a]×`, which for a non-unit axis is not a pure
//! rotation (`<rotate x="0" y="1" z="1" angle="15"/>` stretches). The renderer must build the
//! same matrix, or a scene renders differently from Mitsuba's.
//!
//! Every constant below was printed by Mitsuba 3.9.1 (`scalar_rgb`, Dr.Jit 1.5.0) in the venv
//! that `experiments/crosscheck_mitsuba.py` makes, with the command given above each table.
//! Mitsuba's XML parser evaluates transforms in double precision and rounds the result to
//! float, so a cosine of exactly 90° comes out as 6.1e-17, not as float's -4.4e-8.

use std::path::{Path, PathBuf};

use fireflies::Error;
use fireflies::render::mitsuba::{load_file, load_str};
use fireflies::render::scene::{GeometryDesc, SceneDesc};
use glam::{Mat4, Vec3};

const FILE: &str = "test.xml";

/// Agreement asked of every matrix entry and coordinate: 1e-6 relative, against at least 1 (so
/// that an entry of 6e-17 in Mitsuba and 0 here agree).
const RTOL: f64 = 1e-6;

const SENSOR: &str = r#"<sensor type="perspective">
        <float name="fov" value="45"/>
        <film type="hdrfilm"><rfilter type="box"/></film>
    </sensor>"#;

fn scene(body: &str) -> String {
    format!("<scene version=\"3.0.0\">\n    {SENSOR}\n{body}\n</scene>\n")
}

fn load(xml: &str) -> Result<SceneDesc, Error> {
    load_str(xml, Path::new("."), FILE)
}

fn assert_close(ours: f32, mitsuba: f64, what: &str) {
    let tol = RTOL * mitsuba.abs().max(1.0);
    assert!(
        (f64::from(ours) - mitsuba).abs() <= tol,
        "{what}: ours {ours:e}, Mitsuba {mitsuba:e} (difference {:e}, tolerance {tol:e})",
        f64::from(ours) - mitsuba
    );
}

/// Compares the whole 4x4 `ours` with Mitsuba's row-major `rows`.
fn assert_matrix(ours: Mat4, rows: &[[f64; 4]; 4], what: &str) {
    for (i, row) in rows.iter().enumerate() {
        for (j, &want) in row.iter().enumerate() {
            assert_close(ours.row(i)[j], want, &format!("{what}, entry ({i}, {j})"));
        }
    }
}

/// A rotation's 3x3 block as a 4x4 matrix without translation.
fn affine(rows: &[[f64; 3]; 3]) -> [[f64; 4]; 4] {
    let r = |i: usize| [rows[i][0], rows[i][1], rows[i][2], 0.0];
    [r(0), r(1), r(2), [0.0, 0.0, 0.0, 1.0]]
}

/// The `to_world` the loader gives a disk whose transform is `ops`.
fn disk_to_world(ops: &str) -> Mat4 {
    let xml = scene(&format!(
        r#"<shape type="disk"><transform name="to_world">{ops}</transform></shape>"#
    ));
    let scene = load(&xml).unwrap_or_else(|err| panic!("{ops}: {err}"));
    match scene.shapes[0].geometry {
        GeometryDesc::Disk { to_world } => to_world,
        ref other => panic!("expected a disk, got {other:?}"),
    }
}

/// `(axis, angle in degrees, Mitsuba's 3x3 matrix row by row)`; the fourth row and column are
/// those of the identity in every case. Printed by Mitsuba 3.9.1 through its XML parser (a disk
/// whose `to_world` is the single `<rotate>`), from the repository root, with
///
/// ```text
/// experiments/.venv-mitsuba/bin/python - <<'EOF'
/// import mitsuba as mi, numpy as np
/// mi.set_variant('scalar_rgb')
/// for ax in [(1,0,0), (0,1,0), (0,0,1), (0,1,1), (2,0,0), (0.3,-1.2,0.5)]:
///     for ang in (15, 90, -200):
///         s = mi.load_string(f'<scene version="3.0.0"><shape type="disk" id="d">'
///             f'<transform name="to_world"><rotate x="{ax[0]}" y="{ax[1]}" z="{ax[2]}" '
///             f'angle="{ang}"/></transform></shape></scene>')
///         m = np.array(mi.traverse(s)['d.to_world'].matrix, dtype=np.float32)
///         rows = ", ".join("[" + ", ".join(repr(float(v)) for v in m[i, :3]) + "]" for i in range(3))
///         print(f"({ax}, {ang}, [{rows}]),")
/// EOF
/// ```
///
/// `mi.ScalarTransform4f().rotate(axis, angle).matrix`, the same formula evaluated in float,
/// agrees with these to 1.2e-7 (relative to max(1, |entry|)).
#[rustfmt::skip]
const MITSUBA_ROTATIONS: [([f32; 3], f32, [[f64; 3]; 3]); 18] = [
    ([1.0, 0.0, 0.0], 15.0, [[1.0, 0.0, 0.0], [0.0, 0.9659258127212524, -0.258819043636322], [0.0, 0.258819043636322, 0.9659258127212524]]),
    ([1.0, 0.0, 0.0], 90.0, [[1.0, 0.0, 0.0], [0.0, 6.123234262925839e-17, -1.0], [0.0, 1.0, 6.123234262925839e-17]]),
    ([1.0, 0.0, 0.0], -200.0, [[1.0, 0.0, 0.0], [0.0, -0.9396926164627075, -0.3420201539993286], [0.0, 0.3420201539993286, -0.9396926164627075]]),
    ([0.0, 1.0, 0.0], 15.0, [[0.9659258127212524, 0.0, 0.258819043636322], [0.0, 1.0, 0.0], [-0.258819043636322, 0.0, 0.9659258127212524]]),
    ([0.0, 1.0, 0.0], 90.0, [[6.123234262925839e-17, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 6.123234262925839e-17]]),
    ([0.0, 1.0, 0.0], -200.0, [[-0.9396926164627075, 0.0, 0.3420201539993286], [0.0, 1.0, 0.0], [-0.3420201539993286, 0.0, -0.9396926164627075]]),
    ([0.0, 0.0, 1.0], 15.0, [[0.9659258127212524, -0.258819043636322, 0.0], [0.258819043636322, 0.9659258127212524, 0.0], [0.0, 0.0, 1.0]]),
    ([0.0, 0.0, 1.0], 90.0, [[6.123234262925839e-17, -1.0, 0.0], [1.0, 6.123234262925839e-17, 0.0], [0.0, 0.0, 1.0]]),
    ([0.0, 0.0, 1.0], -200.0, [[-0.9396926164627075, -0.3420201539993286, 0.0], [0.3420201539993286, -0.9396926164627075, 0.0], [0.0, 0.0, 1.0]]),
    ([0.0, 1.0, 1.0], 15.0, [[0.9659258127212524, -0.258819043636322, 0.258819043636322], [0.258819043636322, 1.0, 0.034074172377586365], [-0.258819043636322, 0.034074172377586365, 1.0]]),
    ([0.0, 1.0, 1.0], 90.0, [[6.123234262925839e-17, -1.0, 1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]]),
    ([0.0, 1.0, 1.0], -200.0, [[-0.9396926164627075, -0.3420201539993286, 0.3420201539993286], [0.3420201539993286, 1.0, 1.9396926164627075], [-0.3420201539993286, 1.9396926164627075, 1.0]]),
    ([2.0, 0.0, 0.0], 15.0, [[1.1022225618362427, 0.0, 0.0], [0.0, 0.9659258127212524, -0.517638087272644], [0.0, 0.517638087272644, 0.9659258127212524]]),
    ([2.0, 0.0, 0.0], 90.0, [[4.0, 0.0, 0.0], [0.0, 6.123234262925839e-17, -2.0], [0.0, 2.0, 6.123234262925839e-17]]),
    ([2.0, 0.0, 0.0], -200.0, [[6.819077968597412, 0.0, 0.0], [0.0, -0.9396926164627075, -0.6840403079986572], [0.0, 0.6840403079986572, -0.9396926164627075]]),
    ([0.3, -1.2, 0.5], 15.0, [[0.9689925312995911, -0.14167623221874237, -0.3054717183113098], [0.11714281886816025, 1.014992594718933, -0.09809021651744843], [0.3156939744949341, 0.05720121040940285, 0.9744443893432617]]),
    ([0.3, -1.2, 0.5], 90.0, [[0.09000000357627869, -0.8600000143051147, -1.0499999523162842], [0.14000000059604645, 1.440000057220459, -0.8999999761581421], [1.350000023841858, -0.30000001192092896, 0.25]]),
    ([0.3, -1.2, 0.5], -200.0, [[-0.765120267868042, -0.8692994117736816, -0.1194702759385109], [-0.527279257774353, 1.8534647226333618, -1.2664215564727783], [0.7013780474662781, -1.0612095594406128, -0.45476946234703064]]),
];

#[test]
fn rotate_builds_mitsubas_matrix() {
    for (axis, angle, rows) in MITSUBA_ROTATIONS {
        let [x, y, z] = axis;
        let ops = format!(r#"<rotate x="{x}" y="{y}" z="{z}" angle="{angle}"/>"#);
        assert_matrix(disk_to_world(&ops), &affine(&rows), &ops);
        // The same operation written with value="x, y, z".
        let ops = format!(r#"<rotate value="{x}, {y}, {z}" angle="{angle}"/>"#);
        assert_matrix(disk_to_world(&ops), &affine(&rows), &ops);
    }
}

#[test]
fn a_non_unit_axis_is_not_normalised() {
    // The axis of Mitsuba's hello.xml: with a normalised axis this would be a pure rotation,
    // with det 1 and every column of length 1.
    let m = disk_to_world(r#"<rotate x="0" y="1" z="1" angle="15"/>"#);
    let c = 15f32.to_radians().cos();
    // Along the axis a, M·a = (c + (1 − c)|a|²)·a = (2 − c)·a.
    let along = m.transform_vector3(Vec3::new(0.0, 1.0, 1.0));
    assert!(
        (along - (2.0 - c) * Vec3::new(0.0, 1.0, 1.0))
            .abs()
            .max_element()
            < 1e-6,
        "{along}"
    );
    assert!(m.determinant() > 1.05, "det {}", m.determinant());
    // A unit axis still gives a rotation, whatever its length was written as.
    let unit = disk_to_world(r#"<rotate x="0" y="0.6" z="0.8" angle="-200"/>"#);
    assert!((unit.determinant() - 1.0).abs() < 1e-6);
    let back = unit.transpose() * unit;
    assert!(back.abs_diff_eq(Mat4::IDENTITY, 1e-6), "{back}");
}

#[test]
fn a_zero_axis_is_an_error() {
    // Mitsuba 3.9.1 refuses it too ("rotation axis cannot be zero").
    for op in [
        r#"<rotate x="0" y="0" z="0" angle="15"/>"#,
        r#"<rotate value="0, 0, 0" angle="15"/>"#,
        r#"<rotate angle="15"/>"#,
        r#"<rotate x="-0" angle="0"/>"#,
    ] {
        let xml = scene(&format!(
            "<shape type=\"disk\"><transform name=\"to_world\">\n{op}\n</transform></shape>"
        ));
        let err = load(&xml).expect_err(op);
        let text = err.to_string();
        match &err {
            Error::Scene {
                file,
                line,
                element,
                message,
            } => {
                assert_eq!(file, FILE, "{text}");
                // The scene line, the sensor's four lines, the shape line, then the op.
                assert_eq!(*line, 7, "{text}");
                assert_eq!(element, "rotate", "{text}");
                assert!(message.contains("rotation axis"), "{text}");
                assert!(message.contains("is zero"), "{text}");
            }
            other => panic!("{op}: expected Error::Scene, got {other:?}"),
        }
    }
}

/// A fresh folder under the system temp dir.
fn temp_dir(tag: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    let dir = std::env::temp_dir().join(format!(
        "fireflies_render_transforms_{tag}_{}_{nanos}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const TRIANGLE_OBJ: &str = "v 1 2 3\nv -1 0.5 0\nv 0 0 -2\nf 1 2 3\n";

/// Rotations about non-unit axes composed with a translation, on an OBJ mesh and on the
/// camera (which only allows rigid transforms, so its axes are unit).
const COMPOSED_XML: &str = r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <film type="hdrfilm"><rfilter type="box"/></film>
        <transform name="to_world"><rotate x="0" y="0" z="1" angle="-200"/><rotate x="1" y="0" z="0" angle="15"/><translate x="1" y="2" z="3"/></transform>
    </sensor>
    <shape type="obj">
        <string name="filename" value="tri.obj"/>
        <transform name="to_world"><rotate x="0.3" y="-1.2" z="0.5" angle="-200"/><translate x="1" y="-2" z="0.5"/><rotate x="0" y="1" z="1" angle="15"/></transform>
    </shape>
</scene>
"#;

/// Mitsuba 3.9.1's world-space vertices of `TRIANGLE_OBJ` and its camera-to-world matrix (row
/// by row) for `COMPOSED_XML` (here with `id="tri"` on the shape), printed from the repository
/// root by
///
/// ```text
/// experiments/.venv-mitsuba/bin/python - <<'EOF'
/// import mitsuba as mi, numpy as np, pathlib, tempfile
/// mi.set_variant('scalar_rgb')
/// d = pathlib.Path(tempfile.mkdtemp())
/// (d / 'tri.obj').write_text('v 1 2 3\nv -1 0.5 0\nv 0 0 -2\nf 1 2 3\n')
/// (d / 'scene.xml').write_text("""<scene version="3.0.0">
///     <sensor type="perspective">
///         <float name="fov" value="45"/>
///         <film type="hdrfilm"><rfilter type="box"/></film>
///         <transform name="to_world"><rotate x="0" y="0" z="1" angle="-200"/><rotate x="1" y="0" z="0" angle="15"/><translate x="1" y="2" z="3"/></transform>
///     </sensor>
///     <shape type="obj" id="tri">
///         <string name="filename" value="tri.obj"/>
///         <transform name="to_world"><rotate x="0.3" y="-1.2" z="0.5" angle="-200"/><translate x="1" y="-2" z="0.5"/><rotate x="0" y="1" z="1" angle="15"/></transform>
///     </shape>
/// </scene>""")
/// s = mi.load_file(str(d / 'scene.xml'))
/// v = np.array(mi.traverse(s)['tri.vertex_positions'], dtype=np.float32).reshape(-1, 3)
/// m = np.array(s.sensors()[0].world_transform().matrix, dtype=np.float32)
/// for r in [*v, *m]: print("[" + ", ".join(repr(float(x)) for x in r) + "],")
/// EOF
/// ```
#[rustfmt::skip]
const MITSUBA_TRIANGLE: [[f64; 3]; 3] = [
    [-1.7121652364730835, -3.179440498352051, -1.892655849456787],
    [1.236997127532959, -0.22657901048660278, -1.094938039779663],
    [1.4236302375793457, 0.9015334844589233, 1.1070337295532227],
];
#[rustfmt::skip]
const MITSUBA_CAMERA: [[f64; 4]; 4] = [
    [-0.9396926164627075, -0.3420201539993286, 0.0, 1.0],
    [0.3303660750389099, -0.9076733589172363, -0.258819043636322, 2.0],
    [0.0885213240981102, -0.2432103455066681, 0.9659258127212524, 3.0],
    [0.0, 0.0, 0.0, 1.0],
];

#[test]
fn composed_rotations_place_geometry_and_camera_as_mitsuba_does() {
    let dir = temp_dir("composed");
    std::fs::write(dir.join("tri.obj"), TRIANGLE_OBJ).unwrap();
    std::fs::write(dir.join("scene.xml"), COMPOSED_XML).unwrap();
    let loaded = load_file(&dir.join("scene.xml"));
    std::fs::remove_dir_all(&dir).unwrap();
    let scene = loaded.unwrap();

    assert_matrix(scene.camera.to_world, &MITSUBA_CAMERA, "camera to_world");
    let GeometryDesc::Mesh(mesh) = &scene.shapes[0].geometry else {
        panic!("expected a mesh, got {:?}", scene.shapes[0].geometry);
    };
    assert_eq!(mesh.positions.len(), 3);
    assert_eq!(mesh.indices, vec![[0, 1, 2]]);
    for (k, (ours, want)) in mesh.positions.iter().zip(&MITSUBA_TRIANGLE).enumerate() {
        for axis in 0..3 {
            assert_close(ours[axis], want[axis], &format!("vertex {k}, axis {axis}"));
        }
    }
}

#[test]
fn a_camera_rotated_about_a_non_unit_axis_is_an_error() {
    // The matrix then scales, which Mitsuba 3.9.1 refuses for a camera as well ("Scale factors
    // in the camera-to-world transformation are not allowed!").
    let xml = r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <film type="hdrfilm"><rfilter type="box"/></film>
        <transform name="to_world"><rotate x="0" y="1" z="1" angle="15"/></transform>
    </sensor>
</scene>
"#;
    let err = load(xml).expect_err("a scaling camera transform must not load");
    assert!(err.to_string().contains("scales or shears"), "{err}");
}
