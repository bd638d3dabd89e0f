//! A report directory is replaced as a unit (issue 12, item 8): whenever `fireflies run` is
//! killed, `--out` holds either the earlier report or the new one, each complete, and what
//! killed runs leave beside it is cleaned by the next run.
//!
//! What these tests can catch: a report mixing files of two runs (told apart by the seed, by the
//! content that depends only on the seed, and by the timings that summary.md shares with
//! manifest.json and speed.csv), a missing or extra file, write debris inside `--out`, more than
//! one leftover temporary beside it, leftovers that a successful run does not clean, a bad
//! `--out` that is not an error naming it.
//!
//! What they cannot: prove atomicity. The kills land at pseudo-random moments, so a short
//! inconsistent window can be missed (the swap itself is one system call, and the kills that
//! land inside the report-writing phase are only a fraction of the 20). A kill is not a power
//! cut: the fsyncs are not exercised. Only the atomic-exchange path runs here (on Linux); the
//! rename-aside fallback and its recovery are unit-tested in `src/atomic.rs`. Two runs whose
//! timings agree to the printed precision could not be told apart by the timing links.

use fireflies::harness::{self, Experiment, RunOptions};
use fireflies::report::{self, tables};
use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const EXPERIMENT: &str = r#"
name = "swap"
seed = 1
trials = 4096
checkpoints = [4, 16]
estimators = ["mean", "mon:M=3"]
[[distributions]]
label = "pareto"
dist = { kind = "pareto", scale = 1.0, shape = 2.5 }
"#;

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("report-swap-{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap();
    dir
}

fn names(dir: &Path) -> BTreeSet<String> {
    fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

fn contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    names(dir)
        .into_iter()
        .map(|n| {
            let bytes = fs::read(dir.join(&n)).unwrap();
            (n, bytes)
        })
        .collect()
}

/// Entries beside `out` that are temporaries of it (`.<name>.tmp-…`, `.<name>.old-…`).
fn temps_beside(out: &Path) -> Vec<String> {
    let prefix = format!(".{}.", out.file_name().unwrap().to_string_lossy());
    names(out.parent().unwrap())
        .into_iter()
        .filter(|n| n.starts_with(&prefix))
        .collect()
}

fn run_cmd(exp: &Path, seed: u64, out: &Path) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_fireflies"));
    cmd.arg("run")
        .arg(exp)
        .args(["--seed", &seed.to_string(), "--out"])
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    cmd
}

/// Runs to the end; returns the wall time.
fn run_ok(exp: &Path, seed: u64, out: &Path) -> Duration {
    let start = Instant::now();
    let output = run_cmd(exp, seed, out).output().unwrap();
    assert!(
        output.status.success(),
        "seed {seed}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    start.elapsed()
}

/// SplitMix64: the test's fixed-seed pseudo-random numbers in [0, 1).
fn uniform(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (z ^ (z >> 31)) as f64 / 2f64.powi(64)
}

/// What a complete report of each seed must hold.
struct Reference {
    /// Every file of a report.
    names: BTreeSet<String>,
    /// Per seed, the files whose bytes depend only on the seed (not on timings).
    fixed: BTreeMap<u64, BTreeMap<String, Vec<u8>>>,
}

impl Reference {
    /// Asserts that `out` holds one complete report, every file from one run; returns its seed.
    fn check(&self, out: &Path, context: &str) -> u64 {
        assert_eq!(
            names(out),
            self.names,
            "{context}: files of {}",
            out.display()
        );
        let manifest: serde_json::Value =
            serde_json::from_slice(&fs::read(out.join("manifest.json")).unwrap()).unwrap();
        let seed = manifest["seed"].as_u64().unwrap();
        // Content that depends only on the seed is that seed's, byte for byte.
        let fixed = &self.fixed[&seed];
        for (name, bytes) in fixed {
            assert!(
                fs::read(out.join(name)).unwrap() == *bytes,
                "{context}: {name} is not from the run of seed {seed} that wrote manifest.json"
            );
        }
        // Timing-dependent files are tied to the manifest through summary.md, which prints the
        // manifest's seed, wall time and rate and speed.csv's costs.
        let summary = fs::read_to_string(out.join("summary.md")).unwrap();
        let wall = manifest["wall_s"].as_f64().unwrap();
        let rate = manifest["samples_per_s"].as_f64().unwrap();
        let line = format!("seed {seed}, ");
        let timing = format!("{wall:.1} s wall, {rate:.3e} samples/s.");
        assert!(
            summary.contains(&line) && summary.contains(&timing),
            "{context}: summary.md is not from the run that wrote manifest.json ({line}{timing})"
        );
        let speed = tables::read_results_csv(&out.join("speed.csv")).unwrap();
        assert!(!speed.is_empty(), "{context}");
        for row in speed {
            let printed = match row.metric.name() {
                "ns_per_sample" => format!("| {:.2} |", row.value),
                _ => format!("Drawing samples: {:.2} ns/sample.", row.value),
            };
            assert!(
                summary.contains(&printed),
                "{context}: speed.csv ({} {}) is not from the run that wrote summary.md",
                row.estimator,
                row.metric
            );
        }
        for name in &self.names {
            assert!(
                fs::metadata(out.join(name)).unwrap().len() > 0,
                "{context}: {name}"
            );
        }
        seed
    }
}

/// (b) `kill -9` at pseudo-random moments of a run that replaces a report of another seed.
#[test]
fn a_killed_run_leaves_one_complete_report_and_the_next_run_cleans_up() {
    let dir = scratch("kill");
    let exp = dir.join("swap.toml");
    fs::write(&exp, EXPERIMENT).unwrap();
    let out = dir.join("report");
    // The report of seed 1 at `--out`, and two of seed 2 beside it to learn what is fixed.
    let mut longest = run_ok(&exp, 1, &out);
    let seed1 = contents(&out);
    let (ref_a, ref_b) = (dir.join("ref-a"), dir.join("ref-b"));
    longest = longest.max(run_ok(&exp, 2, &ref_a));
    longest = longest.max(run_ok(&exp, 2, &ref_b));
    let (seed2, seed2_again) = (contents(&ref_a), contents(&ref_b));
    let report_names: BTreeSet<String> = seed2.keys().cloned().collect();
    assert_eq!(report_names, seed1.keys().cloned().collect::<BTreeSet<_>>());
    for name in &report_names {
        assert!(
            report::is_report_file(name),
            "{name} is no known report file"
        );
    }
    let is_fixed = |name: &String| seed2[name] == seed2_again[name];
    for name in ["results.csv", "checks.json", "median_error.svg"] {
        assert!(is_fixed(&name.to_string()), "{name} depends on timings");
    }
    let pick = |files: &BTreeMap<String, Vec<u8>>| {
        files
            .iter()
            .filter(|(n, _)| is_fixed(n))
            .map(|(n, b)| (n.clone(), b.clone()))
            .collect::<BTreeMap<_, _>>()
    };
    let reference = Reference {
        names: report_names,
        fixed: BTreeMap::from([(1, pick(&seed1)), (2, pick(&seed2))]),
    };
    assert_ne!(
        reference.fixed[&1]["results.csv"],
        reference.fixed[&2]["results.csv"]
    );
    assert_eq!(reference.check(&out, "first run"), 1);

    let mut state = 12;
    let (mut kept_old, mut took_new) = (0, 0);
    for kill in 0..20 {
        let before = reference.check(&out, &format!("before kill {kill}"));
        let seed = 3 - before;
        let delay = longest.mul_f64(uniform(&mut state));
        let mut child = run_cmd(&exp, seed, &out)
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(delay);
        let _ = child.kill();
        child.wait().unwrap();
        let context = format!("kill {kill} after {delay:?}");
        let after = reference.check(&out, &context);
        if after == seed {
            took_new += 1;
        } else {
            kept_old += 1;
        }
        let temps = temps_beside(&out);
        assert!(temps.len() <= 1, "{context}: leftovers {temps:?}");
    }
    eprintln!("20 kills: {kept_old} left the old report, {took_new} the new one");
    // A successful run replaces the report and cleans every leftover.
    let seed = 3 - reference.check(&out, "before the last run");
    run_ok(&exp, seed, &out);
    assert_eq!(reference.check(&out, "last run"), seed);
    assert_eq!(temps_beside(&out), Vec::<String>::new());
    fs::remove_dir_all(&dir).unwrap();
}

/// (a) The library-level swap: old content replaced by new, only the new remains, no temporary.
#[test]
fn replace_dir_swaps_old_content_for_new() {
    let dir = scratch("lib");
    let target = dir.join("report");
    fs::create_dir(&target).unwrap();
    for name in ["a.txt", "shared.txt"] {
        fs::write(target.join(name), "old").unwrap();
    }
    // Debris of a run killed with the earlier per-file scheme, and of one killed mid-swap.
    fs::write(target.join(".results.csv.tmp.2147483647"), "orphan").unwrap();
    fs::create_dir(dir.join(".report.tmp-2147483647-3")).unwrap();
    let n = fireflies::atomic::replace_dir(&target, |staging| {
        fs::write(staging.join("shared.txt"), "new").unwrap();
        fs::write(staging.join("b.txt"), "new").unwrap();
        Ok(2)
    })
    .unwrap();
    assert_eq!(n, 2);
    assert_eq!(
        names(&target),
        BTreeSet::from(["b.txt".to_string(), "shared.txt".to_string()])
    );
    assert_eq!(
        fs::read_to_string(target.join("shared.txt")).unwrap(),
        "new"
    );
    assert_eq!(names(&dir), BTreeSet::from(["report".to_string()]));
    // The first write to a target that does not exist yet.
    let fresh = dir.join("fresh");
    fireflies::atomic::replace_dir(&fresh, |staging| {
        fs::write(staging.join("c.txt"), "c").map_err(|e| fireflies::Error::io("c.txt", &e))
    })
    .unwrap();
    assert_eq!(names(&fresh), BTreeSet::from(["c.txt".to_string()]));
    assert_eq!(
        names(&dir),
        BTreeSet::from(["fresh".to_string(), "report".to_string()])
    );
    fs::remove_dir_all(&dir).unwrap();
}

/// A report replaces an earlier one's files (and debris) but keeps files that are no report's.
#[test]
fn write_report_drops_the_old_report_and_keeps_foreign_files() {
    let dir = scratch("report");
    let exp_path = dir.join("swap.toml");
    fs::write(&exp_path, EXPERIMENT).unwrap();
    let exp = Experiment::load(&exp_path).unwrap();
    let run = harness::run(&exp, &RunOptions::default()).unwrap();
    let checks = harness::checks::evaluate(&exp, &run);
    let out = dir.join("report");
    fs::create_dir(&out).unwrap();
    for (name, text) in [
        ("bias.png", "a plot of an earlier run"),
        ("results.csv", "an earlier run"),
        (".manifest.json.tmp.2147483647", "debris"),
        ("shard-0-of-1.json", "{}"),
    ] {
        fs::write(out.join(name), text).unwrap();
    }
    report::prepare_report_dir(&out).unwrap();
    report::write_report(&out, &exp, &run, &checks, false).unwrap();
    let mut want: BTreeSet<String> = report::TABLE_FILES.iter().map(|s| s.to_string()).collect();
    want.insert("shard-0-of-1.json".into());
    assert_eq!(names(&out), want);
    assert_eq!(
        fs::read_to_string(out.join("shard-0-of-1.json")).unwrap(),
        "{}"
    );
    assert_ne!(
        fs::read_to_string(out.join("results.csv")).unwrap(),
        "an earlier run"
    );
    // A subdirectory cannot be carried atomically: an error naming it, the report untouched.
    fs::create_dir(out.join("sub")).unwrap();
    let before = contents(&out.join("sub"));
    for e in [
        report::prepare_report_dir(&out).unwrap_err(),
        report::write_report(&out, &exp, &run, &checks, true).unwrap_err(),
    ] {
        assert!(
            e.to_string()
                .contains(&out.join("sub").display().to_string()),
            "{e}"
        );
    }
    assert_eq!(contents(&out.join("sub")), before);
    want.insert("sub".into());
    assert_eq!(names(&out), want);
    assert_eq!(
        names(&dir),
        BTreeSet::from(["report".into(), "swap.toml".into()])
    );
    fs::remove_dir_all(&dir).unwrap();
}

/// A `--out` that is a file, the root or unwritable is an error naming it, before the run.
#[test]
fn bad_out_is_an_error_naming_it() {
    let dir = scratch("bad");
    let exp = dir.join("swap.toml");
    fs::write(&exp, EXPERIMENT).unwrap();
    let file = dir.join("file");
    fs::write(&file, "x").unwrap();
    let targets = [
        file.clone(),
        PathBuf::from("/"),
        PathBuf::from("/proc/fireflies-not-writable"),
    ];
    // The library refuses each before the binary is tried (which, if it did not, would write).
    for target in &targets {
        let e = report::prepare_report_dir(target).unwrap_err();
        assert!(
            e.to_string().starts_with(&target.display().to_string()),
            "{e}"
        );
    }
    for target in &targets {
        let output = run_cmd(&exp, 1, target).output().unwrap();
        let err = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{}: {err}", target.display());
        assert!(err.contains(&target.display().to_string()), "{err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    assert_eq!(fs::read_to_string(&file).unwrap(), "x");
    fs::remove_dir_all(&dir).unwrap();
}
