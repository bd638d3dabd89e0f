//! Arbitrary experiment files (issue 10, "Also"): mutations of a valid experiment, and raw
//! bytes, go through the same parse-and-run path as `fireflies run`. Whatever the input, the
//! result is a run or an error, never a panic, an abort or an unbounded allocation (the memory
//! limit is 8 MiB here, so a mutation that asks for a huge run is refused, not attempted).

use fireflies::harness::{self, Experiment, RunOptions};
use fireflies::limits::MemoryLimit;
use proptest::prelude::*;
use proptest::test_runner::Config;

/// Cases per property: each case that parses runs 4 trials, so the file takes seconds.
const CASES: u32 = 200;

const BASE: &str = r#"name = "fuzz"
seed = 7
trials = 64
checkpoints = [4, 16]
tau = 1.0
estimators = ["mean", "mon:M=5", "gmon:M=5", "zirr", "pajot-rot:learn=4"]

[[distributions]]
dist = { kind = "preset", name = "diffuse" }

[[distributions]]
label = "tail"
dist = { kind = "pareto", scale = 1.0, shape = 2.5 }

[checks]
family_alpha = 0.01
findings = ["zirr-bound"]
"#;

/// Values a hostile or careless user writes.
const HOSTILE: &[&str] = &[
    "0",
    "-1",
    "1e309",
    "-0.0",
    "nan",
    "inf",
    "18446744073709551615",
    "18446744073709551616",
    "4294967296",
    "1e-320",
    "\"../x\"",
    "\"/abs/x\"",
    "\"\"",
    "[]",
    "[0]",
    "[16, 4]",
    "[4, 4]",
    "[4, 10000000000]",
    "{}",
    "\"mon:M=1048577\"",
    "[\"mean\", \"mean\"]",
    "[\"zirr:u=5e-324\"]",
    "[\"clamp:c=1e308\"]",
    "{ kind = \"pareto\", scale = 1e308, shape = 1.0000001 }",
    "{ kind = \"lognormal\", mu = 700, sigma = 30 }",
    "{ kind = \"point-mass\", value = 0 }",
    "\"\u{feff}\"",
    "\"\\u0000\"",
];

/// One line of the base experiment, edited.
#[derive(Debug, Clone)]
enum Edit {
    Keep,
    Drop,
    Value(usize),
    Garbage(String),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        6 => Just(Edit::Keep),
        1 => Just(Edit::Drop),
        2 => (0..HOSTILE.len()).prop_map(Edit::Value),
        1 => "\\PC{0,12}".prop_map(Edit::Garbage),
    ]
}

fn mutate(edits: &[Edit]) -> String {
    let mut out = String::new();
    for (line, e) in BASE.lines().zip(edits.iter().cycle()) {
        match e {
            Edit::Keep => out.push_str(line),
            Edit::Drop => {}
            Edit::Value(i) => match line.split_once('=') {
                Some((key, _)) => out.push_str(&format!("{key}= {}", HOSTILE[*i])),
                None => out.push_str(line),
            },
            Edit::Garbage(g) => {
                out.push_str(line);
                out.push_str(g);
            }
        }
        out.push('\n');
    }
    out
}

/// Parses and, when the file is valid, runs it small; either outcome is fine, a panic is not.
fn parse_and_run(text: &str) {
    let Ok(exp) = Experiment::from_toml(text, "fuzz.toml", "fuzz") else {
        return;
    };
    let opts = RunOptions {
        trials: Some(4),
        threads: Some(1),
        memory: MemoryLimit(8 << 20),
        ..RunOptions::default()
    };
    let _ = harness::run(&exp, &opts);
}

#[test]
fn the_base_experiment_is_valid_and_runs() {
    let exp = Experiment::from_toml(BASE, "fuzz.toml", "fuzz").unwrap();
    let opts = RunOptions {
        trials: Some(4),
        threads: Some(1),
        memory: MemoryLimit(8 << 20),
        ..RunOptions::default()
    };
    assert!(harness::run(&exp, &opts).is_ok());
}

proptest! {
    #![proptest_config(Config { cases: CASES, ..Config::default() })]

    #[test]
    fn mutated_experiments_never_panic(edits in proptest::collection::vec(edit(), 1..24)) {
        parse_and_run(&mutate(&edits));
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        parse_and_run(&String::from_utf8_lossy(&bytes));
    }
}

/// Every hostile value in every line, one at a time: the systematic half of the fuzz test.
#[test]
fn every_hostile_value_in_every_line_is_handled() {
    let lines = BASE.lines().count();
    for line in 0..lines {
        for value in 0..HOSTILE.len() {
            let mut edits = vec![Edit::Keep; lines];
            edits[line] = Edit::Value(value);
            parse_and_run(&mutate(&edits));
        }
    }
}
