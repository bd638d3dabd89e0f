//! The command line as a user drives it: `fireflies eval` and `fireflies run`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fireflies"))
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fireflies-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(path: &Path, text: &str) -> PathBuf {
    std::fs::write(path, text).unwrap();
    path.to_path_buf()
}

fn json_lines(out: &Output) -> Vec<serde_json::Value> {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone())
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

const RUNNING_EXAMPLE: &str = "0.6 1.5\n0\n2.2 4.8\n350\n4.1\n";

#[test]
fn eval_prints_one_json_object_per_estimator_in_order() {
    let dir = scratch("eval");
    let file = write(&dir.join("s.txt"), RUNNING_EXAMPLE);
    let out = bin()
        .args([
            "eval",
            "--estimator",
            "mean",
            "-e",
            "gmon:M=5",
            "-e",
            "jung:sigma_image=40",
        ])
        .arg(&file)
        .output()
        .unwrap();
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[0]["estimator"], "mean");
    assert_eq!(lines[0]["n"], 7);
    assert_eq!(lines[0]["estimate"].as_f64().unwrap(), 363.2 / 7.0);
    assert_eq!(lines[1]["estimator"], "gmon:M=5");
    assert!((lines[1]["estimate"].as_f64().unwrap() - 3.266666666666667).abs() < 1e-12);
    assert!((lines[1]["gini"].as_f64().unwrap() - 0.7632631010264719).abs() < 1e-12);
    assert_eq!(lines[2]["M"], 5);
    assert_eq!(lines[2]["estimate"].as_f64().unwrap(), 2.8);
    // Keys keep the documented order: estimator, n, estimate, then extras.
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.lines()
            .next()
            .unwrap()
            .starts_with(r#"{"estimator":"mean","n":7,"estimate":"#)
    );
}

#[test]
fn eval_reads_stdin_when_no_file_or_dash() {
    for args in [
        vec!["eval", "-e", "mon:M=5"],
        vec!["eval", "-e", "mon:M=5", "-"],
    ] {
        let mut child = bin()
            .args(&args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        child
            .stdin
            .take()
            .unwrap()
            .write_all(RUNNING_EXAMPLE.as_bytes())
            .unwrap();
        let lines = json_lines(&child.wait_with_output().unwrap());
        assert_eq!(lines[0]["estimate"].as_f64().unwrap(), 2.8);
    }
}

#[test]
fn eval_input_errors_exit_2_and_name_the_problem() {
    let dir = scratch("eval-errors");
    let cases = [
        (
            "bad.txt",
            "1 2\n3 x4\n",
            "mean",
            "bad.txt:2: malformed number 'x4'",
        ),
        (
            "neg.txt",
            "1\n-2\n",
            "mean",
            "neg.txt:2: invalid sample at index 1: -2",
        ),
        ("empty.txt", "\n  \n", "mean", "no samples"),
        ("ok.txt", "1", "median:M=3", "unknown estimator 'median'"),
        ("ok2.txt", "1", "mon:M=0", "M = 0"),
    ];
    for (name, text, spec, expected) in cases {
        let file = write(&dir.join(name), text);
        let out = bin()
            .args(["eval", "-e", spec])
            .arg(&file)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{name}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expected), "{name}: {err}");
    }
    let out = bin()
        .args(["eval", "-e", "mean", "/nonexistent/x.txt"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/x.txt"));
    let out = bin().args(["eval"]).output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(2),
        "missing --estimator is a usage error"
    );
}

#[test]
fn eval_block_evaluates_the_centre_with_its_neighbours() {
    let dir = scratch("block");
    let neighbour = "1 1 1 1 1 1 1\n";
    let files: Vec<PathBuf> = (0..9)
        .map(|i| {
            let text = if i == 4 { RUNNING_EXAMPLE } else { neighbour };
            write(&dir.join(format!("p{i}.txt")), text)
        })
        .collect();
    let out = bin()
        .args(["eval", "-e", "zirr:J=6", "-e", "mean", "--block"])
        .args(&files)
        .output()
        .unwrap();
    let lines = json_lines(&out);
    assert!((lines[0]["estimate"].as_f64().unwrap() - 1.8857142857142857).abs() < 1e-12);
    // Extras (Zirr's per-buffer `counts`) never replace the fixed keys.
    assert_eq!(lines[0]["n"], 7);
    assert_eq!(lines[0]["counts"].as_array().unwrap().len(), 6);
    assert_eq!(lines[1]["estimate"].as_f64().unwrap(), 363.2 / 7.0);
    // An empty file is a pixel outside the image; an empty centre is an error.
    write(&dir.join("p0.txt"), "");
    let out = bin()
        .args(["eval", "-e", "zirr", "--block"])
        .args(&files)
        .output()
        .unwrap();
    assert!(out.status.success());
    write(&dir.join("p4.txt"), "");
    let out = bin()
        .args(["eval", "-e", "zirr", "--block"])
        .args(&files)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

const TINY: &str = r#"
name = "tiny"
seed = 7
trials = 600
checkpoints = [8, 64]
estimators = ["mean", "mon:M=21", "gmon:M=5", "zirr"]
[[distributions]]
dist = { kind = "preset", name = "caustic" }
[[distributions]]
label = "pareto"
dist = { kind = "pareto", scale = 1.0, shape = 2.5 }
[checks]
robust = ["mon:M=21"]
firefly_ceiling = 0.5
"#;

#[test]
fn run_writes_every_table_and_is_identical_across_thread_counts() {
    let dir = scratch("run");
    let exp = write(&dir.join("tiny.toml"), TINY);
    let mut csvs = Vec::new();
    for threads in ["1", "2"] {
        let out_dir = dir.join(format!("out{threads}"));
        let out = bin()
            .arg("run")
            .arg(&exp)
            .args(["--threads", threads, "--out"])
            .arg(&out_dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        for f in ["results.csv", "summary.md", "manifest.json", "checks.json"] {
            assert!(out_dir.join(f).metadata().unwrap().len() > 0, "{f}");
        }
        let csv = std::fs::read_to_string(out_dir.join("results.csv")).unwrap();
        // Timing rows legitimately differ between runs; everything else must not.
        let stable: Vec<String> = csv
            .lines()
            .filter(|l| !l.contains("ns_per_sample"))
            .map(String::from)
            .collect();
        csvs.push(stable);
        let manifest: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out_dir.join("manifest.json")).unwrap())
                .unwrap();
        assert_eq!(manifest["trials"], 600);
        assert!(manifest["samples_per_s"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(csvs[0], csvs[1]);
    assert!(csvs[0].len() > 100);
}

#[test]
fn run_errors_name_the_line_and_the_path() {
    let dir = scratch("run-errors");
    let exp = write(
        &dir.join("bad.toml"),
        &TINY.replace("trials = 600", "trials = 600\ntrails = 2"),
    );
    let out = bin().arg("run").arg(&exp).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("trails") && err.contains("line"), "{err}");
    let exp = write(&dir.join("ok.toml"), TINY);
    let out = bin()
        .arg("run")
        .arg(&exp)
        .args(["--out", "/proc/fireflies-not-writable"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/proc/fireflies-not-writable"));
}

#[test]
fn embedded_default_and_hard_cases_run_with_finite_estimates() {
    let dir = scratch("shipped");
    let hard = concat!(env!("CARGO_MANIFEST_DIR"), "/experiments/hard_cases.toml");
    for (args, name) in [
        (vec!["run", "--trials", "256"], "default"),
        (vec!["run", hard, "--trials", "512"], "hard"),
    ] {
        let out_dir = dir.join(name);
        let out = bin()
            .args(&args)
            .arg("--out")
            .arg(&out_dir)
            .output()
            .unwrap();
        // A non-finite estimate would stop the run with exit code 2 and name it.
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let csv = std::fs::read_to_string(out_dir.join("results.csv")).unwrap();
        assert!(csv.lines().count() > 500, "{name}");
        assert!(out_dir.join("median_error.png").metadata().unwrap().len() > 10_000);
    }
}

#[test]
fn dist_relative_variance_is_exact_where_the_variance_overflows() {
    use fireflies::dist::{Dist, LogNormal};
    let tiny = Dist::from(LogNormal::new(-690.0, 1.0).unwrap());
    let huge = Dist::from(LogNormal::new(690.0, 1.0).unwrap());
    let want = 1f64.exp_m1();
    for d in [tiny, huge] {
        let rv = d.relative_variance().unwrap();
        assert!((rv - want).abs() < 1e-12 * want, "{d}: {rv}");
    }
}

/// Runs `cmd` with `input` on its standard input, killing it and failing the test if it has not
/// exited within `limit` (an unbounded read of an endless input must not hang the suite).
fn output_within(cmd: &mut Command, input: &[u8], limit: std::time::Duration) -> Output {
    let mut child = cmd
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let input = input.to_vec();
    // The child may exit before reading everything: a broken pipe is expected then.
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(&input);
    });
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("still running after {limit:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    writer.join().unwrap();
    child.wait_with_output().unwrap()
}

/// Issue 10, item 2: every input is read once, so a spec repeated, or standard input named in
/// several slots, sees the same samples.
#[test]
fn eval_block_reads_each_input_once_and_repeated_specs_agree() {
    let dir = scratch("block-once");
    let empty = write(&dir.join("E"), "");
    let centre = write(&dir.join("p4.txt"), RUNNING_EXAMPLE);
    let neighbour = "1 1 1 1 1 1 1\n";
    let p0 = write(&dir.join("p0.txt"), neighbour);
    let specs = [
        "-e", "zirr-ref", "-e", "zirr-ref", "-e", "zirr", "-e", "zirr", "--block",
    ];
    let timeout = std::time::Duration::from_secs(60);
    // The issue's command: stdin in slot 0 must not be found empty by the second estimator.
    let mut cmd = bin();
    cmd.arg("eval").args(specs).arg("-");
    cmd.args([
        &empty, &empty, &empty, &centre, &empty, &empty, &empty, &empty,
    ]);
    let piped = json_lines(&output_within(&mut cmd, neighbour.as_bytes(), timeout));
    let mut cmd = bin();
    cmd.arg("eval").args(specs).arg(&p0);
    cmd.args([
        &empty, &empty, &empty, &centre, &empty, &empty, &empty, &empty,
    ]);
    let from_file = json_lines(&cmd.output().unwrap());
    assert_eq!(piped, from_file);
    assert_eq!(piped[0], piped[1]);
    assert_eq!(piped[2], piped[3]);
    assert!((piped[0]["estimate"].as_f64().unwrap() - 4.25756195335277).abs() < 1e-12);
    // Stdin filling several slots, the centre among them, is read once and fed to each.
    let neighbours: Vec<PathBuf> = (0..9)
        .map(|i| write(&dir.join(format!("n{i}.txt")), RUNNING_EXAMPLE))
        .collect();
    let all_stdin = ["-", "-", "E", "-", "-", "E", "-", "-", "-"];
    let mut cmd = bin();
    cmd.current_dir(&dir)
        .args([
            "eval", "-e", "zirr-ref", "-e", "mean", "-e", "zirr-ref", "--block",
        ])
        .args(all_stdin);
    let piped = json_lines(&output_within(
        &mut cmd,
        RUNNING_EXAMPLE.as_bytes(),
        timeout,
    ));
    let files: Vec<&Path> = (0..9)
        .map(|i| match all_stdin[i] {
            "-" => neighbours[i].as_path(),
            _ => empty.as_path(),
        })
        .collect();
    let out = bin()
        .args([
            "eval", "-e", "zirr-ref", "-e", "mean", "-e", "zirr-ref", "--block",
        ])
        .args(&files)
        .output()
        .unwrap();
    assert_eq!(piped, json_lines(&out));
    assert_eq!(piped[0], piped[2]);
    assert_eq!(piped[1]["n"], 7);
}

/// Issue 10, item 8: `/dev/zero` and other binary input are errors naming the line and column,
/// found at once, not after reading without bound.
#[test]
fn eval_binary_input_fails_at_once_naming_line_and_column() {
    let timeout = std::time::Duration::from_secs(10);
    #[cfg(unix)]
    {
        let out = output_within(
            bin().args(["eval", "-e", "mean", "/dev/zero"]),
            b"",
            timeout,
        );
        assert_eq!(out.status.code(), Some(2));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(r"/dev/zero:1: NUL byte '\0'") && err.contains("(column 1)"),
            "{err}"
        );
    }
    let cases: [(&[u8], &str); 4] = [
        (
            b"1 2\n3 4\x005",
            r"-:2: NUL byte '\0': sample files are text (column 4)",
        ),
        (
            b"1\n\n 2 \xff\xfe",
            r"-:3: invalid UTF-8 '\xff': sample files are text (column 4)",
        ),
        (
            "1 \u{feff}2".as_bytes(),
            r"-:1: malformed number '\u{feff}2' (column 3)",
        ),
        (
            b"7\n\x1b[31m",
            r"-:2: malformed number '\u{1b}[31m' (column 1)",
        ),
    ];
    for (input, expected) in cases {
        let out = output_within(bin().args(["eval", "-e", "mean"]), input, timeout);
        assert_eq!(out.status.code(), Some(2), "{expected}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expected), "{err}");
        // Only the final newline is a raw control character.
        assert!(!err.trim_end().chars().any(char::is_control), "{err:?}");
    }
    // A byte-order mark at the start of the file is skipped.
    let out = output_within(
        bin().args(["eval", "-e", "mean"]),
        "\u{feff}1 2\n3".as_bytes(),
        timeout,
    );
    assert_eq!(json_lines(&out)[0]["estimate"].as_f64().unwrap(), 2.0);
}

/// Issue 10, items 8 and 11: a token over the limit is an error naming its line and column that
/// quotes about 40 characters of it, and sample values print in the short form of `Num`.
#[test]
fn eval_messages_quote_little_input_and_print_short_numbers() {
    let dir = scratch("eval-quotes");
    let limit = fireflies::samples::MAX_TOKEN_BYTES;
    let long = write(
        &dir.join("long.txt"),
        &format!("1 2\n3 {}\n", "9".repeat(50 * limit)),
    );
    let malformed = write(&dir.join("bad.txt"), &format!("1 {}x", "9".repeat(300)));
    let huge = write(&dir.join("neg.txt"), "0.5\n-1e300\n");
    let cases = [
        (
            long,
            format!(
                "long.txt:2: token longer than the limit of {limit} bytes: '{}…' \
                 (more than {limit} bytes) (column 3)",
                "9".repeat(40)
            ),
        ),
        (
            malformed,
            format!(
                "bad.txt:1: malformed number '{}…' (301 bytes) (column 3)",
                "9".repeat(40)
            ),
        ),
        (
            huge,
            "neg.txt:2: invalid sample at index 1: -1e300 (column 1)".to_string(),
        ),
    ];
    for (file, expected) in cases {
        let out = bin()
            .args(["eval", "-e", "mean"])
            .arg(&file)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{expected}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(&expected), "{err}");
        assert!(
            err.len() < expected.len() + dir.as_os_str().len() + 20,
            "{err}"
        );
    }
}

/// Issue 10, item 8: a single line of any length is read in bounded memory. The child's peak
/// resident set (`VmHWM`, which only grows) is read while the end of a 64 MB line is still to
/// come, so the line has nearly all passed through the reader; reading it whole into one
/// string, as before, would hold at least 64 MB.
#[cfg(target_os = "linux")]
#[test]
fn eval_reads_a_long_single_line_in_bounded_memory() {
    const LINE_BYTES: usize = 64 << 20;
    /// Far above the binary's own footprint (a few MB), far below the line.
    const MAX_PEAK_KB: u64 = 24 << 10;
    let mut child = bin()
        .args(["eval", "-e", "mean", "-e", "gmon:M=21", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let chunk = "0.5 1.5 ".repeat(8192);
    let mut stdin = child.stdin.take().unwrap();
    let chunks = LINE_BYTES / chunk.len();
    for _ in 0..chunks {
        stdin.write_all(chunk.as_bytes()).unwrap();
    }
    // A pipe holds 64 KB at most: the child has read all but that much of the line.
    let status = std::fs::read_to_string(format!("/proc/{}/status", child.id())).unwrap();
    let peak_kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap();
    stdin.write_all(b"2\n").unwrap();
    drop(stdin);
    let lines = json_lines(&child.wait_with_output().unwrap());
    assert_eq!(lines[0]["n"], (chunks * 8192 * 2 + 1) as u64);
    assert!(peak_kb < MAX_PEAK_KB, "peak resident set {peak_kb} kB");
}
