//! `fireflies transfer` (issue 14, item 5): the experiment file is validated with errors that
//! name the entry and parameter; on a tiny scene the command writes its report; the report does
//! not depend on the thread count. The statistical property (a known law's mean is predicted)
//! is a unit test of `fireflies::scenes::transfer`.

use fireflies::scenes::transfer::TransferExperiment;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fireflies"))
}

fn scratch(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("fireflies-transfer-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A 16x16 scene: one diffuse sphere under a constant emitter, so the centre pixel's samples
/// vary (next-event and BSDF samples of the sky weighted by the cosine).
const SCENE: &str = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="1"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="16"/>
            <integer name="height" value="16"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
</scene>
"#;

/// A tiny experiment on `s.xml` beside it: three estimators, two checkpoints, a few renders.
const TOML: &str = r#"
seed = 3
renders = 24
fit_spp = 512
truth_spp = 4096
trials = 64
checkpoints = [4, 16]
estimators = ["mean", "gmon:M=5", "clamp:c=0.5"]

[quick]
renders = 8
fit_spp = 256
truth_spp = 1024
trials = 16
checkpoints = [4]

[[pixels]]
scene = "s.xml"
x = 8
y = 8
class = "plain"
"#;

fn setup(name: &str) -> (PathBuf, PathBuf) {
    let dir = scratch(name);
    std::fs::write(dir.join("s.xml"), SCENE).unwrap();
    let toml = dir.join("t.toml");
    std::fs::write(&toml, TOML).unwrap();
    (dir, toml)
}

fn transfer(toml: &Path, out: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("transfer")
        .arg(toml)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

/// The error message of loading `TOML` with `from` replaced by `to`.
fn rejected(dir: &Path, from: &str, to: &str) -> String {
    assert!(TOML.contains(from), "{from}");
    let text = TOML.replacen(from, to, 1);
    TransferExperiment::from_toml(&text, "t.toml", dir, false)
        .err()
        .unwrap_or_else(|| panic!("{from} -> {to} was accepted"))
        .to_string()
}

#[test]
fn the_experiment_file_is_validated() {
    let (dir, _) = setup("validate");
    let ok = TransferExperiment::from_toml(TOML, "t.toml", &dir, false).unwrap();
    assert_eq!(ok.settings.renders, 24);
    assert_eq!(ok.pixels[0].label, "s_8_8");
    let quick = TransferExperiment::from_toml(TOML, "t.toml", &dir, true).unwrap();
    assert_eq!(quick.settings.checkpoints, vec![4]);
    assert_eq!(quick.settings.renders, 8);

    let cases: [(&str, &str, &[&str]); 11] = [
        ("seed = 3", "seed = 3\nsede = 4", &["t.toml", "sede"]),
        (
            "class = \"plain\"",
            "class = \"plain\"\nwidht = 3",
            &["widht"],
        ),
        (
            "renders = 24",
            "renders = 2",
            &["renders = 2", "at least 4"],
        ),
        ("renders = 8", "renders = 1", &["quick.renders = 1"]),
        ("fit_spp = 512", "fit_spp = 10", &["fit_spp = 10"]),
        ("truth_spp = 4096", "truth_spp = 1", &["truth_spp = 1"]),
        ("trials = 64", "trials = 3", &["trials = 3"]),
        ("[4, 16]", "[16, 4]", &["checkpoints", "ascending"]),
        (
            "\"gmon:M=5\"",
            "\"gmon:M=0\"",
            &["estimators[1]", "gmon:M=0"],
        ),
        (
            "scene = \"s.xml\"",
            "scene = \"missing.xml\"",
            &["pixels[0]", "scene", "missing.xml"],
        ),
        (
            "class = \"plain\"",
            "class = \"plain\"\nrfilter = \"tent\"",
            &["pixels[0]", "rfilter", "tent"],
        ),
    ];
    for (from, to, needles) in cases {
        let e = rejected(&dir, from, to);
        for n in needles {
            assert!(e.contains(n), "{from} -> {to}: missing {n:?} in {e}");
        }
    }
    let e = rejected(&dir, "x = 8", "x = 8\nwidth = 16");
    assert!(e.contains("width/height"), "{e}");
    let e = rejected(&dir, "x = 8", "x = 20\nwidth = 16\nheight = 16");
    assert!(e.contains("x/y") && e.contains("16x16"), "{e}");
    let e = rejected(&dir, "\"mean\", ", "\"mean\", \"mean\", ");
    assert!(e.contains("estimators[1]") && e.contains("repeats"), "{e}");
    let e = rejected(&dir, "class = \"plain\"", "class = \"\"");
    assert!(e.contains("class"), "{e}");
}

/// A pixel outside the scene's own image is refused when the scene is loaded, naming it.
#[test]
fn a_pixel_outside_the_image_is_named() {
    let (dir, _) = setup("outside");
    let toml = dir.join("o.toml");
    std::fs::write(&toml, TOML.replace("x = 8", "x = 99")).unwrap();
    let out = transfer(&toml, &dir.join("out"), &["--quick"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("x/y") && stderr.contains("16x16"),
        "{stderr}"
    );
    let (_, toml) = setup("fit-spp");
    let out = transfer(&toml, &dir.join("out2"), &["--quick", "--fit-spp", "10"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("fit-spp") && stderr.contains("10"),
        "{stderr}"
    );
}

#[test]
fn a_tiny_scene_writes_the_report_and_threads_do_not_change_it() {
    let (dir, toml) = setup("run");
    let (one, two) = (dir.join("one"), dir.join("two"));
    for (out, threads) in [(&one, "1"), (&two, "2")] {
        let o = transfer(&toml, out, &["--threads", threads]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    for f in [
        "transfer.csv",
        "pixels.csv",
        "summary.md",
        "predicted_vs_measured.png",
    ] {
        assert!(one.join(f).is_file(), "{f} missing");
    }
    let csv = std::fs::read_to_string(one.join("transfer.csv")).unwrap();
    // A header, then 3 estimators x 2 checkpoints.
    assert_eq!(csv.lines().count(), 1 + 3 * 2, "{csv}");
    assert!(
        csv.lines()
            .nth(1)
            .unwrap()
            .starts_with("s_8_8,plain,mean,4,")
    );
    let summary = std::fs::read_to_string(one.join("summary.md")).unwrap();
    assert!(summary.contains("transfer") && summary.contains("s_8_8"));
    for f in ["transfer.csv", "pixels.csv"] {
        assert_eq!(
            std::fs::read(one.join(f)).unwrap(),
            std::fs::read(two.join(f)).unwrap(),
            "{f} differs between 1 and 2 threads"
        );
    }
}
