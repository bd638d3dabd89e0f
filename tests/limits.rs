//! Hostile and mistyped inputs to `run`, `render` and `merge` (issue 10): each is refused with
//! exit code 2 and a message naming the parameter, before anything large is allocated or
//! anything is written outside the report directory.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fireflies"))
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fireflies-limits-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(path: &Path, text: &str) -> PathBuf {
    std::fs::write(path, text).unwrap();
    path.to_path_buf()
}

/// Runs `fireflies ARGS --out DIR/out INPUT`.
fn with_out(dir: &Path, args: &[&str], input: &Path) -> Output {
    bin()
        .args(args)
        .arg("--out")
        .arg(dir.join("out"))
        .arg(input)
        .output()
        .unwrap()
}

/// Asserts a usage error (exit 2, no panic) whose message contains every `needle`.
fn refused(out: &Output, needles: &[&str]) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.len() < 2000,
        "message too long: {} bytes",
        stderr.len()
    );
    for n in needles {
        assert!(stderr.contains(n), "missing {n:?} in: {stderr}");
    }
    stderr
}

/// A small experiment; `extra` replaces nothing, it is appended to the top-level keys.
fn experiment(name: &str, checkpoints: &str, estimators: &str) -> String {
    format!(
        "name = \"{name}\"\nseed = 1\ntrials = 64\ncheckpoints = {checkpoints}\n\
         estimators = {estimators}\n\n[[distributions]]\ndist = {{ kind = \"preset\", name = \"diffuse\" }}\n"
    )
}

/// A scene with a given film size: one sphere under a constant emitter.
fn scene(width: &str, height: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="1"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="{width}"/>
            <integer name="height" value="{height}"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
</scene>
"#
    )
}

#[test]
fn a_small_scene_renders_so_the_refusals_below_are_about_size() {
    let dir = scratch("small");
    let file = write(&dir.join("s.xml"), &scene("16", "16"));
    let out = with_out(&dir, &["render", "--spp", "2"], &file);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Item 3: 65536 x 65537 pixels wrapped a 32-bit pixel count and panicked; item 4: 1e8 x 1e8
/// aborted on allocation. Both are now refused by the memory estimate.
#[test]
fn huge_films_are_refused_before_allocation() {
    let dir = scratch("films");
    for (w, h) in [("65536", "65537"), ("100000000", "100000000")] {
        let file = write(&dir.join(format!("{w}x{h}.xml")), &scene(w, h));
        let out = with_out(&dir, &["render", "--spp", "1"], &file);
        refused(&out, &[&format!("film of {w}x{h} pixels"), "--max-memory"]);
    }
}

/// Item 4: MoN over 2^20 sets on 16x16 pixels holds 256 x 3 x 2^20 compensated sums (12 GiB);
/// refused under a 1 GiB limit, and the limit can be raised.
#[test]
fn estimator_state_counts_against_the_memory_limit() {
    let dir = scratch("state");
    let file = write(&dir.join("s.xml"), &scene("16", "16"));
    let render = |limit: &str| {
        bin()
            .args(["--max-memory", limit, "render", "--spp", "1"])
            .args(["--estimators", "mon:M=1048576", "--out"])
            .arg(dir.join("out"))
            .arg(&file)
            .output()
            .unwrap()
    };
    let e = refused(
        &render("1GiB"),
        &["mon:M=1048576", "1.0 GiB", "--max-memory"],
    );
    assert!(
        e.contains("12.0 GiB") || e.contains("needs at least 12"),
        "{e}"
    );
    let out = bin()
        .env("FIREFLIES_MAX_MEMORY", "1GiB")
        .args([
            "render",
            "--spp",
            "1",
            "--estimators",
            "mon:M=1048576",
            "--out",
        ])
        .arg(dir.join("out"))
        .arg(&file)
        .output()
        .unwrap();
    refused(&out, &["1.0 GiB"]);
    refused(&render("lots"), &["max-memory", "lots"]);
}

/// Item 4: a trillion trials and a checkpoint of 1e10 samples (80 GB per worker) aborted on
/// allocation. A single run now folds its blocks as they finish, so its memory no longer grows
/// with the trials (it would simply run for days); a shard still keeps every block's
/// statistics until the merge, so a trillion trials in one shard must be refused.
#[test]
fn runs_that_cannot_fit_are_refused_naming_the_parameter() {
    let dir = scratch("runs");
    let small = write(
        &dir.join("small.toml"),
        &experiment("small", "[4, 16]", "[\"mean\"]"),
    );
    let out = with_out(
        &dir,
        &["run", "--trials", "1000000000000", "--shard", "0/1"],
        &small,
    );
    refused(&out, &["trials = 1000000000000", "--max-memory"]);
    let big = write(
        &dir.join("big.toml"),
        &experiment("big", "[4, 10000000000]", "[\"mean\"]"),
    );
    let out = with_out(&dir, &["run"], &big);
    refused(&out, &["largest checkpoint = 10000000000", "--max-memory"]);
}

/// Item 5: `--threads 18446744073709551615` started 15,000 threads.
#[test]
fn thread_counts_are_capped() {
    let dir = scratch("threads");
    let small = write(
        &dir.join("small.toml"),
        &experiment("small", "[4]", "[\"mean\"]"),
    );
    let out = with_out(&dir, &["run", "--threads", "18446744073709551615"], &small);
    refused(&out, &["threads", "1024"]);
    let file = write(&dir.join("s.xml"), &scene("4", "4"));
    let out = with_out(&dir, &["render", "--threads", "5000"], &file);
    refused(&out, &["threads", "1024"]);
}

/// Item 6: a report name is one plain path component.
#[test]
fn experiment_names_cannot_leave_the_reports_directory() {
    let dir = scratch("names");
    for name in [
        "../escaped",
        "/tmp/abs-escaped",
        "a/b",
        "..",
        ".",
        "",
        " padded",
    ] {
        let file = write(&dir.join("e.toml"), &experiment(name, "[4]", "[\"mean\"]"));
        let out = bin()
            .current_dir(&dir)
            .arg("run")
            .arg(&file)
            .output()
            .unwrap();
        refused(&out, &["name", "plain file name", "e.toml"]);
    }
    assert!(!dir.join("escaped").exists() && !Path::new("/tmp/abs-escaped").exists());
    assert!(!dir.join("reports").exists(), "nothing is written");
}

/// Item 10: the same estimator twice wrote duplicate rows; item 11: a spec error inside an
/// experiment named neither the file nor the entry.
#[test]
fn experiment_entries_are_named_in_errors() {
    let dir = scratch("entries");
    let dup = write(
        &dir.join("dup.toml"),
        &experiment("dup", "[4]", "[\"mean\", \"mon:M=5\", \"mon:M=5\"]"),
    );
    let out = bin().arg("run").arg(&dup).output().unwrap();
    refused(
        &out,
        &[
            "dup.toml",
            "estimators[2] = \"mon:M=5\"",
            "estimators[1] = \"mon:M=5\"",
        ],
    );
    let bad = write(
        &dir.join("bad.toml"),
        &experiment("bad", "[4]", "[\"mean\", \"gmon:M=0\"]"),
    );
    let out = bin().arg("run").arg(&bad).output().unwrap();
    refused(&out, &["bad.toml", "estimators[1] = \"gmon:M=0\"", "M = 0"]);
    let huge = write(
        &dir.join("huge.toml"),
        &format!(
            "{}\n[checks]\nfamily_alpha = 1e300\n",
            experiment("huge", "[4]", "[\"mean\"]")
        ),
    );
    let out = bin().arg("run").arg(&huge).output().unwrap();
    refused(&out, &["huge.toml", "family_alpha = 1e300"]);
}

/// Item 10: `--exposure nan` and `inf` were accepted; item 11: a coordinate beyond u32 read
/// "expected x,y".
#[test]
fn render_options_are_checked() {
    let dir = scratch("options");
    let file = write(&dir.join("s.xml"), &scene("4", "4"));
    for exposure in ["nan", "inf", "0", "-1"] {
        let out = with_out(&dir, &["render", &format!("--exposure={exposure}")], &file);
        refused(&out, &["exposure"]);
    }
    let out = with_out(&dir, &["render", "--dump-pixels", "99999999999,1"], &file);
    refused(&out, &["x = 99999999999 is out of range"]);
    let out = with_out(&dir, &["render", "--dump-pixels", "9,1"], &file);
    refused(&out, &["9,1", "outside the 4x4 image"]);
}

/// Item 11: a seed mismatch in `merge` read "a different 'probe'".
#[test]
fn merge_names_the_mismatched_seed() {
    let dir = scratch("merge");
    for (seed, i) in [(1, 0), (2, 1)] {
        let file = write(
            &dir.join(format!("e{seed}.toml")),
            &experiment("probe", "[4]", "[\"mean\"]")
                .replace("seed = 1", &format!("seed = {seed}")),
        );
        let out = bin()
            .args([
                "run",
                "--trials",
                "4096",
                "--shard",
                &format!("{i}/2"),
                "--out",
            ])
            .arg(dir.join("shards"))
            .arg(&file)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let out = bin()
        .args(["merge", "--out"])
        .arg(dir.join("merged"))
        .arg(dir.join("shards"))
        .output()
        .unwrap();
    refused(&out, &["the seed is 2 here but 1 in"]);
}

/// Item 11: `zirr-ref:J=0` suggested `auto`, which zirr-ref does not take.
#[test]
fn zirr_ref_messages_do_not_suggest_auto() {
    for spec in ["zirr-ref:J=0", "zirr-ref:J=1"] {
        let e = spec
            .parse::<fireflies::EstimatorSpec>()
            .and_then(|s| s.build().map(|_| ()))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("J") && e.contains("2..=") && !e.contains("auto"),
            "{e}"
        );
    }
}
