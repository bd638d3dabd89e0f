//! Records the git commit the binary is built from, so a report's manifest names the code that
//! produced it (not whatever the checkout holds when the report is written).
//!
//! Cargo reruns a build script whenever a watched path is missing, so only files that exist are
//! watched: a fresh clone has no `.git/packed-refs`, and a source tarball has no `.git` at all
//! (the commit is then recorded as `unknown`).

use std::path::{Path, PathBuf};
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    Command::new("git")
        .args(args)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .filter(|s| !s.is_empty())
}

/// The paths whose change means HEAD moved: HEAD itself, the loose branch refs (a directory,
/// which Cargo scans, so a branch file created by a commit is seen) and packed-refs. In a linked
/// worktree HEAD is the worktree's own, but the branch refs live in the common directory: a
/// commit there changes only the latter.
fn watched_git_paths() -> Vec<PathBuf> {
    let Some(git_dir) = git(&["rev-parse", "--absolute-git-dir"]) else {
        return Vec::new();
    };
    let git_dir = PathBuf::from(git_dir);
    let common = git(&["rev-parse", "--git-common-dir"])
        .map(PathBuf::from)
        .map(|c| {
            if c.is_absolute() {
                c
            } else {
                std::env::current_dir().unwrap_or_default().join(c)
            }
        })
        .unwrap_or_else(|| git_dir.clone());
    let mut paths = vec![
        git_dir.join("HEAD"),
        common.join("refs").join("heads"),
        common.join("packed-refs"),
    ];
    paths.retain(|p| Path::new(p).exists());
    paths
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let commit = git(&["rev-parse", "HEAD"]).unwrap_or_else(|| "unknown".to_string());
    println!("cargo:rustc-env=FIREFLIES_GIT_COMMIT={commit}");
    for path in watched_git_paths() {
        println!("cargo:rerun-if-changed={}", path.display());
    }
}
