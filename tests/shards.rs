//! Shards merge into the same bits as a single run, and bad sets of shards are refused.

use fireflies::harness::runner::{self, Shard};
use fireflies::harness::shards::{self, ShardFile};
use fireflies::harness::{self, Experiment, RunOptions};
use fireflies::report;
use fireflies::report::tables;
use std::path::PathBuf;
use std::process::Command;

const SHARDED: &str = r#"
name = "sharded"
seed = 11
trials = 9000
checkpoints = [8, 128]
estimators = ["mean", "mon:M=21", "gmonb:M=21", "jung:sigma_image=1", "zirr", "zirr-ref"]
[[distributions]]
dist = { kind = "preset", name = "caustic" }
[[distributions]]
dist = { kind = "preset", name = "infinite-variance" }
"#;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fireflies-shards-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn results_csv(exp: &Experiment, out: &harness::RunOutput) -> Vec<u8> {
    tables::results_csv(&tables::rows(exp, out)).unwrap()
}

#[test]
fn shards_merge_bit_identically_for_any_split_and_thread_count() {
    let exp = Experiment::from_toml(SHARDED, "sharded", "sharded").unwrap();
    let single = |threads| {
        let opts = RunOptions {
            threads: Some(threads),
            ..RunOptions::default()
        };
        results_csv(&exp, &harness::run(&exp, &opts).unwrap())
    };
    let reference = single(1);
    assert_eq!(reference, single(2), "1 vs 2 threads");
    for k in [3u64, 7] {
        let dir = scratch(&format!("k{k}"));
        // Through files, as the cluster scripts do.
        for i in (0..k).rev() {
            let out = runner::run_shard(&exp, &RunOptions::default(), Shard { index: i, count: k })
                .unwrap();
            let path = dir.join(ShardFile::file_name(i, k));
            report::write_atomic(
                &path,
                &serde_json::to_vec(&ShardFile::new(&exp, out)).unwrap(),
            )
            .unwrap();
        }
        let files = shards::find_shard_files(&[dir]).unwrap();
        let (merged_exp, merged) = shards::merge(&files).unwrap();
        assert_eq!(results_csv(&merged_exp, &merged), reference, "{k} shards");
    }
}

#[test]
fn merge_refuses_missing_duplicated_and_mismatched_shards() {
    let exp = Experiment::from_toml(SHARDED, "sharded", "sharded").unwrap();
    let dir = scratch("refuse");
    let write = |exp: &Experiment, i: u64, k: u64, name: &str| {
        let out = runner::run_shard(
            exp,
            &RunOptions {
                trials: Some(600),
                ..RunOptions::default()
            },
            Shard { index: i, count: k },
        )
        .unwrap();
        let path = dir.join(name);
        report::write_atomic(
            &path,
            &serde_json::to_vec(&ShardFile::new(exp, out)).unwrap(),
        )
        .unwrap();
        path
    };
    let s0 = write(&exp, 0, 3, "shard-0-of-3.json");
    let s1 = write(&exp, 1, 3, "shard-1-of-3.json");
    let err = shards::merge(&[s0.clone(), s1.clone()])
        .unwrap_err()
        .to_string();
    assert!(err.contains("2/3") && err.contains("missing"), "{err}");
    let dup = dir.join("copy.json");
    std::fs::copy(&s1, &dup).unwrap();
    let s2 = write(&exp, 2, 3, "shard-2-of-3.json");
    let err = shards::merge(&[s0.clone(), s1.clone(), dup.clone(), s2.clone()])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("duplicated shard 1/3") && err.contains("copy.json"),
        "{err}"
    );
    let other =
        Experiment::from_toml(&SHARDED.replace("seed = 11", "seed = 12"), "x", "sharded").unwrap();
    let alien = write(&other, 2, 3, "alien.json");
    let err = shards::merge(&[s0.clone(), s1.clone(), alien])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("alien.json") && err.contains("mismatched"),
        "{err}"
    );
    assert!(shards::merge(&[s0, s1, s2]).is_ok());
}

#[test]
fn shard_cli_round_trip_as_the_cluster_scripts_run_it() {
    let dir = scratch("cli");
    let exp_path = dir.join("sharded.toml");
    std::fs::write(&exp_path, SHARDED).unwrap();
    let bin = env!("CARGO_BIN_EXE_fireflies");
    let shard_dir = dir.join("shards");
    for i in 0..3 {
        let st = Command::new(bin)
            .arg("run")
            .arg(&exp_path)
            .args(["--shard", &format!("{i}/3"), "--out"])
            .arg(&shard_dir)
            .status()
            .unwrap();
        assert!(st.success());
    }
    let merged = dir.join("merged");
    let st = Command::new(bin)
        .arg("merge")
        .arg(&shard_dir)
        .arg("--out")
        .arg(&merged)
        .status()
        .unwrap();
    assert!(st.success());
    let single = dir.join("single");
    let st = Command::new(bin)
        .arg("run")
        .arg(&exp_path)
        .arg("--out")
        .arg(&single)
        .status()
        .unwrap();
    assert!(st.success());
    let a = std::fs::read(merged.join("results.csv")).unwrap();
    let b = std::fs::read(single.join("results.csv")).unwrap();
    assert_eq!(a, b);
    // A bad shard spec is a usage error.
    let out = Command::new(bin)
        .arg("run")
        .arg(&exp_path)
        .args(["--shard", "3/3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}
