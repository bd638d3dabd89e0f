//! The scene loader never panics, whatever it is given: property tests on arbitrary bytes and on
//! mutations of a valid scene (the Cornell box plus one of every other shape, BSDF and emitter),
//! and hand-written hostile cases (sizes beyond every integer range, 1e308 radii, NaN strings,
//! nesting 100,000 deep, defaults that expand exponentially, a megabyte in one attribute).
//!
//! A scene that loads is also built into a [`World`] and traced for one sample, so a value the
//! loader accepts cannot panic the renderer either. Each property runs [`CASES`] cases from
//! proptest's fixed default seed handling (failures persist in a regressions file).

use std::cell::Cell;
use std::path::{Path, PathBuf};

use fireflies::Error;
use fireflies::render::SceneDesc;
use fireflies::render::integrator::radiance;
use fireflies::render::mitsuba::load_str;
use fireflies::render::sampler::SampleStream;
use fireflies::render::world::World;
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

/// Cases per property: a loader run on the Cornell box takes tens of microseconds, so this
/// keeps the file at about a second in release while reaching every attribute many times.
const CASES: u32 = 2048;

/// Longest error message accepted: user text is clipped in messages, so a hostile file cannot
/// make a megabyte-long one.
const MAX_MESSAGE: usize = 2000;

/// A valid OBJ quad with normals, and one malformed on its third line.
const MESH_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n";
const BAD_OBJ: &str = "v 0 0 0\nv 1 0 0\nf 1 2 x\n";

/// The Cornell box with one of every other element of the subset added before `</scene>`.
fn base_scene() -> String {
    let cbox = include_str!("../experiments/scenes/cbox.xml");
    let extra = r#"
    <default name="r" value="0.1"/>
    <bsdf type="twosided" id="grey"><bsdf type="roughconductor"><string name="distribution" value="ggx"/><float name="alpha" value="0.2"/></bsdf></bsdf>
    <emitter type="point"><rgb name="intensity" value="1"/><point name="position" x="0" y="0.5" z="0"/></emitter>
    <emitter type="constant"><rgb name="radiance" value="0.1"/></emitter>
    <shape type="sphere" id="ball"><point name="center" value="0.5, 0.5, 0"/><float name="radius" value="$r"/><ref id="grey"/></shape>
    <shape type="disk"><transform name="to_world"><scale value="0.2"/><translate y="0.9"/></transform><bsdf type="dielectric"><string name="int_ior" value="water"/></bsdf></shape>
    <shape type="obj"><string name="filename" value="mesh.obj"/><boolean name="face_normals" value="false"/><transform name="to_world"><matrix value="0.1 0 0 0 0 0.1 0 0 0 0 0.1 0 0 0 0 1"/></transform><bsdf type="conductor"/></shape>
"#;
    cbox.replacen("</scene>", &format!("{extra}</scene>"), 1)
}

/// A fresh folder with `mesh.obj` and `bad.obj`, removed when dropped.
struct Folder(PathBuf);

impl Folder {
    fn new(tag: &str) -> Folder {
        let dir =
            std::env::temp_dir().join(format!("fireflies_scene_fuzz_{tag}_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("mesh.obj"), MESH_OBJ).unwrap();
        std::fs::write(dir.join("bad.obj"), BAD_OBJ).unwrap();
        Folder(dir)
    }
}

impl Drop for Folder {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Loads `xml` and checks the outcome: an error is a short [`Error::Scene`]; a scene builds
/// and traces one sample (with the path depth capped, since a mutated scene may ask for
/// unbounded paths without Russian roulette).
fn check(xml: &str, dir: &Path) -> Result<(), TestCaseError> {
    match load_str(xml, dir, "fuzz.xml") {
        Ok(scene) => trace_one(scene),
        Err(err) => {
            let text = err.to_string();
            prop_assert!(matches!(err, Error::Scene { .. }), "{}", text);
            prop_assert!(text.len() <= MAX_MESSAGE, "{} bytes: {}", text.len(), text);
        }
    }
    Ok(())
}

/// Builds the world and traces one sample of pixel (0, 0).
fn trace_one(mut scene: SceneDesc) {
    let depth = scene.integrator.max_depth.map_or(8, |d| d.min(8));
    scene.integrator.max_depth = Some(depth);
    let world = World::new(&scene);
    let mut rng = SampleStream::new(1, 0, 0);
    let _ = radiance(&world, 0, 0, &mut rng);
}

fn runner() -> TestRunner {
    TestRunner::new(Config {
        cases: CASES,
        failure_persistence: None,
        ..Config::default()
    })
}

/// Attribute values a careless or hostile file may hold.
fn hostile_value() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => prop::sample::select(vec![
            "", "0", "-0", "-1", "1", "1e308", "-1e308", "1e38", "3.5e38", "1e30", "1e19",
            "1e-45", "NaN", "nan", "inf", "-inf", "99999999999999999999",
            "-9223372036854775808", "4294967295", "4294967296", "18446744073709551616",
            "1, 2", "1 2 3 4", ",,,", "$", "$r", "$x", "$$", "true", "FALSE", "x", "0x10", "1e",
            ".", "mesh.obj", "bad.obj", "missing.obj", "twosided", "diffuse", "sphere", "obj",
            "ggx", "3.0.0", "grey", "ball", "  7  ", "0, 0, 0", "1e20, 0, 0", "180",
        ])
        .prop_map(String::from),
        4 => (-10.0f32..10.0).prop_map(|x| x.to_string()),
        2 => (0u32..100).prop_map(|x| x.to_string()),
        2 => any::<f64>().prop_map(|x| x.to_string()),
        1 => any::<f32>().prop_map(|x| format!("{x:e}")),
        2 => any::<i64>().prop_map(|x| x.to_string()),
        1 => (any::<f32>(), any::<f32>(), any::<f32>())
            .prop_map(|(a, b, c)| format!("{a}, {b}, {c}")),
        2 => "[ -~]{0,16}",
        1 => ".{0,8}",
    ]
}

/// Fragments that break or deepen the structure when inserted anywhere.
fn hostile_snippet() -> impl Strategy<Value = String> {
    prop_oneof![
        3 => prop::sample::select(vec![
            "<shape type=\"sphere\"/>",
            "<bsdf type=\"twosided\">",
            "</bsdf>",
            "</shape>",
            "<ref id=\"grey\"/>",
            "<ref id=\"ball\"/>",
            "<default name=\"x\" value=\"$x$x\"/>",
            "<default name=\"r\" value=\"2\"/>",
            "<!--",
            "-->",
            "<![CDATA[ x ]]>",
            "&amp;",
            "&nope;",
            "<?xml version=\"1.0\"?>",
            "<transform name=\"to_world\"><scale value=\"1e20\"/></transform>",
            "<float name=\"radius\" value=\"1e19\"/>",
            "<integer name=\"max_depth\" value=\"-1\"/>",
            "<emitter type=\"area\"><rgb name=\"radiance\" value=\"1\"/></emitter>",
            "<sensor type=\"perspective\"/>",
            "<film type=\"hdrfilm\"/>",
            "<rfilter type=\"box\"/>",
            "<lookat origin=\"0,0,0\" target=\"0,0,0\" up=\"0,1,0\"/>",
            "<rotate x=\"0\" y=\"0\" z=\"0\" angle=\"90\"/>",
            "<matrix value=\"0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0\"/>",
            "<string name=\"filename\" value=\"bad.obj\"/>",
            "xmlns:a=\"b\"",
            "\"",
            "<",
            ">",
        ])
        .prop_map(String::from),
        1 => "[<>/=\" a-z0-9$.]{0,24}",
    ]
}

/// One edit of the scene's bytes; positions are fractions of the current length.
#[derive(Debug, Clone)]
enum Mutation {
    /// Cut the text here.
    Truncate(Index),
    /// Replace the value of one attribute (the index picks among all `value="..."` when the
    /// flag is set, else among all `="..."`).
    Attribute(bool, Index, String),
    /// Delete up to this many bytes.
    Delete(Index, usize),
    /// Copy a span elsewhere (duplicates elements, nests them, splits tags).
    Duplicate(Index, usize, Index),
    /// Insert a snippet.
    Insert(Index, String),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        1 => any::<Index>().prop_map(Mutation::Truncate),
        6 => (prop::bool::weighted(0.8), any::<Index>(), hostile_value())
            .prop_map(|(values, i, v)| Mutation::Attribute(values, i, v)),
        1 => (any::<Index>(), 0usize..200).prop_map(|(i, n)| Mutation::Delete(i, n)),
        1 => (any::<Index>(), 0usize..400, any::<Index>())
            .prop_map(|(i, n, j)| Mutation::Duplicate(i, n, j)),
        2 => (any::<Index>(), hostile_snippet()).prop_map(|(i, s)| Mutation::Insert(i, s)),
    ]
}

fn apply(text: &mut Vec<u8>, m: &Mutation) {
    let len = text.len();
    match m {
        Mutation::Truncate(at) => text.truncate(at.index(len + 1)),
        Mutation::Attribute(values_only, which, value) => {
            let key: &[u8] = if *values_only { b"value=\"" } else { b"=\"" };
            let starts: Vec<usize> = text
                .windows(key.len())
                .enumerate()
                .filter(|(_, w)| *w == key)
                .map(|(i, _)| i + key.len())
                .collect();
            if starts.is_empty() {
                return;
            }
            let start = starts[which.index(starts.len())];
            let end = text[start..]
                .iter()
                .position(|&b| b == b'"')
                .map_or(len, |k| start + k);
            text.splice(start..end, value.bytes());
        }
        Mutation::Delete(at, n) => {
            let start = at.index(len + 1);
            let end = start.saturating_add(*n).min(len);
            text.drain(start..end);
        }
        Mutation::Duplicate(from, n, to) => {
            let start = from.index(len + 1);
            let end = start.saturating_add(*n).min(len);
            let span = text[start..end].to_vec();
            let at = to.index(len + 1);
            text.splice(at..at, span);
        }
        Mutation::Insert(at, snippet) => {
            let at = at.index(len + 1);
            text.splice(at..at, snippet.bytes());
        }
    }
}

/// The base scene loads and renders, so mutations start from a valid file.
#[test]
fn the_base_scene_loads() {
    let dir = Folder::new("base");
    let scene = load_str(&base_scene(), &dir.0, "base.xml").expect("the base scene loads");
    assert_eq!(scene.shapes.len(), 11);
    trace_one(scene);
}

/// Property: arbitrary bytes, and XML-ish text under a scene root, give Ok or Err.
#[test]
fn arbitrary_text_never_panics_the_loader() {
    let dir = Folder::new("bytes");
    let text = prop_oneof![
        prop::collection::vec(any::<u8>(), 0..600)
            .prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        "[<>/=\" a-z0-9$.,\n-]{0,400}".prop_map(|s| format!("<scene version=\"3.0.0\">{s}")),
    ];
    runner().run(&text, |xml| check(&xml, &dir.0)).unwrap();
}

/// Property: one to four mutations of the valid scene (attribute values replaced by hostile
/// numbers and strings, truncation, deleted, duplicated and inserted spans) give Ok or Err.
#[test]
fn mutated_scenes_never_panic_the_loader() {
    let dir = Folder::new("mutations");
    let base = base_scene();
    let mutations = prop_oneof![
        2 => prop::collection::vec(mutation(), 1..2),
        1 => prop::collection::vec(mutation(), 2..5),
    ];
    let (runs, loaded) = (Cell::new(0u32), Cell::new(0u32));
    runner()
        .run(&mutations, |ms| {
            let mut bytes = base.clone().into_bytes();
            for m in &ms {
                apply(&mut bytes, m);
            }
            let xml = String::from_utf8_lossy(&bytes);
            runs.set(runs.get() + 1);
            if load_str(&xml, &dir.0, "fuzz.xml").is_ok() {
                loaded.set(loaded.get() + 1);
            }
            check(&xml, &dir.0)
        })
        .unwrap();
    // Both outcomes must be common, or the mutations test only one side of the loader.
    let (runs, loaded) = (runs.get(), loaded.get());
    eprintln!("{loaded} of {runs} mutated scenes loaded");
    assert!(
        loaded >= runs / 20 && loaded <= runs - runs / 20,
        "{loaded} of {runs} loaded"
    );
}

// Hand-written hostile cases -------------------------------------------------------------------

/// A scene with a sensor whose film has `film` as its children, and `body` after it.
fn with_film(film: &str, body: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="45"/>
        <film type="hdrfilm">{film}<rfilter type="box"/></film>
    </sensor>
{body}
</scene>"#
    )
}

fn load(xml: &str) -> Result<SceneDesc, Error> {
    load_str(xml, Path::new("."), "hostile.xml")
}

#[track_caller]
fn expect_err(xml: &str, fragment: &str) {
    let text = load(xml).expect_err("must not load").to_string();
    assert!(text.contains(fragment), "{fragment:?} not in {text}");
    assert!(text.len() <= MAX_MESSAGE, "{} bytes", text.len());
}

#[test]
fn huge_and_negative_image_sizes() {
    let size = |w: &str, h: &str| {
        with_film(
            &format!(r#"<integer name="width" value="{w}"/><integer name="height" value="{h}"/>"#),
            "",
        )
    };
    expect_err(
        &size("99999999999999999999999", "4"),
        "64-bit integer range",
    );
    expect_err(&size("4", "-5"), "height = -5");
    expect_err(&size("0", "4"), "width = 0");
    expect_err(&size("4294967296", "4"), "1..=4294967295");
    expect_err(&size("1e3", "4"), "not an integer");
    // The largest sizes load; the film refuses them for memory, not the loader.
    let scene = load(&size("4294967295", "4294967295")).expect("loads");
    assert_eq!(
        (scene.camera.width, scene.camera.height),
        (u32::MAX, u32::MAX)
    );
    let scene = load(&with_film(
        "",
        r#"<integrator type="path"><integer name="max_depth" value="9223372036854775807"/></integrator>"#,
    ));
    assert!(scene.is_err());
}

#[test]
fn extreme_radii_and_nan_strings() {
    let sphere = |radius: &str| {
        with_film(
            "",
            &format!(r#"<shape type="sphere"><float name="radius" value="{radius}"/></shape>"#),
        )
    };
    expect_err(&sphere("1e308"), "\"1e308\" is not a finite number");
    expect_err(&sphere("-1e308"), "not a finite number");
    expect_err(
        &sphere("1e38"),
        "radius 1e38 times the to_world scale) is inf",
    );
    expect_err(&sphere("1e19"), "±1e18");
    expect_err(&sphere("-1e38"), "radius = -1e38");
    expect_err(&sphere("NaN"), "not a finite number");
    expect_err(&sphere("inf"), "not a finite number");
    expect_err(&sphere("0"), "radius = 0");
    expect_err(&sphere("1e-45"), "world-space radius");
    for body in [
        r#"<shape type="cube"><bsdf type="diffuse"><rgb name="reflectance" value="nan, 1, 1"/></bsdf></shape>"#,
        r#"<shape type="cube"><transform name="to_world"><translate x="NaN"/></transform></shape>"#,
        r#"<shape type="cube"><transform name="to_world"><rotate x="1" angle="nan"/></transform></shape>"#,
        r#"<shape type="cube"><transform name="to_world"><lookat origin="nan, 0, 0" target="0, 0, 1" up="0, 1, 0"/></transform></shape>"#,
        r#"<emitter type="point"><rgb name="intensity" value="1"/><point name="position" x="-inf"/></emitter>"#,
    ] {
        expect_err(&with_film("", body), "not a finite number");
    }
    let fov = r#"<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="NaN"/></sensor></scene>"#;
    expect_err(fov, "not a finite number");
}

/// 100,000 levels of nesting: the old loader recursed into nested `twosided` BSDFs before
/// rejecting them and overflowed the stack (an abort, not even a panic).
#[test]
fn deep_nesting_is_an_error_not_a_stack_overflow() {
    let n = 100_000;
    let nest = |open: &str, close: &str| {
        with_film(
            "",
            &format!(
                "<shape type=\"sphere\">{}{}</shape>",
                open.repeat(n),
                close.repeat(n)
            ),
        )
    };
    expect_err(
        &nest("<bsdf type=\"twosided\">", "</bsdf>"),
        "twosided cannot wrap",
    );
    expect_err(
        &nest("<bsdf type=\"diffuse\">", "</bsdf>"),
        "not allowed inside",
    );
    expect_err(&nest("<a>", "</a>"), "unsupported element <a>");
    let transforms = with_film(
        "",
        &format!(
            "<shape type=\"cube\"><transform name=\"to_world\">{}{}</transform></shape>",
            "<scale value=\"2\">".repeat(n),
            "</scale>".repeat(n)
        ),
    );
    expect_err(&transforms, "unexpected element");
}

/// Defaults that use earlier defaults double in length each time; 64 of them asked for 2^64
/// bytes. Entity expansion (the XML "billion laughs") is refused by the XML parser.
#[test]
fn exponential_expansion_is_refused() {
    let mut defaults = String::from("<default name=\"d0\" value=\"0123456789\"/>\n");
    for i in 1..64 {
        defaults.push_str(&format!(
            "<default name=\"d{i}\" value=\"$d{}$d{}\"/>\n",
            i - 1,
            i - 1
        ));
    }
    let xml = with_film("", &defaults);
    expect_err(&xml, "substitution produces more than");

    let mut laughs =
        String::from("<?xml version=\"1.0\"?>\n<!DOCTYPE scene [\n<!ENTITY l0 \"ha\">\n");
    for i in 1..12 {
        laughs.push_str(&format!(
            "<!ENTITY l{i} \"{}\">\n",
            format!("&l{};", i - 1).repeat(10)
        ));
    }
    laughs.push_str("]>\n<scene version=\"3.0.0\"><default name=\"x\" value=\"&l11;\"/></scene>");
    let err = load(&laughs).expect_err("must not load");
    assert!(err.to_string().contains("malformed XML"), "{err}");
}

/// A plugin with 100,000 distinct parameters is read in linear time (names are hashed) and
/// the unknown one is reported; a megabyte in one attribute is clipped in the message.
#[test]
fn many_parameters_and_huge_attributes() {
    let params: String = (0..100_000)
        .map(|i| format!("<float name=\"p{i}\" value=\"1\"/>"))
        .collect();
    let xml = with_film(
        "",
        &format!("<shape type=\"cube\"><bsdf type=\"diffuse\">{params}</bsdf></shape>"),
    );
    expect_err(&xml, "unknown parameter \"p0\"");

    let huge = "9".repeat(1 << 20);
    for body in [
        format!(r#"<shape type="sphere"><float name="radius" value="{huge}x"/></shape>"#),
        format!(r#"<shape type="sphere"><float name="{huge}" value="1"/></shape>"#),
        format!(r#"<shape type="{huge}"/>"#),
        format!("<a{huge}/>"),
        format!(r#"<shape type="cube"><a{huge}/></shape>"#),
        format!(r#"<shape type="sphere"><float name="radius" value="$r{huge}"/></shape>"#),
    ] {
        let err = load(&with_film("", &body)).expect_err("must not load");
        assert!(
            err.to_string().len() <= MAX_MESSAGE,
            "{} bytes",
            err.to_string().len()
        );
    }
}

/// OBJ files with indices at and beyond every integer limit: errors with their line (tobj's
/// index arithmetic overflowed on some of these in debug builds).
#[test]
fn hostile_obj_files() {
    let dir = Folder::new("hostile_obj");
    let cases = [
        ("v 0 0 0\nvt 0 0\nf 1/0/1 1 1\n", "line 3"),
        ("v 0 0 0\nf -1 -2 -99999999999999\n", "line 2"),
        ("v 0 0 0\nf 9223372036854775807 1 1\n", "line 2"),
        ("v 0 0 0\nf -9223372036854775808 1 1\n", "line 2"),
        ("v 0 0 0\nvt 0 0\nf 1/-9223372036854775808 1 1\n", "line 3"),
        ("v 1 2\n", "line 1"),
        ("v 1e400 0 0\n", "line 1"),
        ("v nan 0 0\n", "line 1"),
        ("\u{feff}v 0 0 0\n", "no triangles"),
        ("\u{0}\u{ff}\n", "no triangles"),
    ];
    for (text, fragment) in cases {
        std::fs::write(dir.0.join("h.obj"), text).unwrap();
        let xml = with_film(
            "",
            r#"<shape type="obj"><string name="filename" value="h.obj"/></shape>"#,
        );
        let err = load_str(&xml, &dir.0, "hostile.xml").expect_err(text);
        assert!(
            err.to_string().contains(fragment),
            "{fragment:?} not in {err}"
        );
    }
}
