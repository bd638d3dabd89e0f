//! Shard files: one shard's mergeable statistics plus what it was run from, so `merge` can
//! refuse a missing, duplicated or mismatched shard by name before combining anything.

use super::experiment::Experiment;
use super::runner::{self, RunOutput, ShardOutput};
use crate::error::{Error, Result};
use crate::limits::shorten;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Version of the shard file layout.
const FORMAT: u32 = 1;

/// One shard on disk.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShardFile {
    /// Layout version.
    pub format: u32,
    /// `fireflies` version that wrote it (statistics of different versions do not mix).
    pub crate_version: String,
    /// The experiment's TOML text, so the merge rebuilds exactly the same experiment.
    pub experiment_toml: String,
    /// The experiment's name.
    pub experiment: String,
    /// Its seed (also inside the TOML; repeated for error messages).
    pub seed: u64,
    /// The statistics.
    pub output: ShardOutput,
}

impl ShardFile {
    /// File name of shard `i` of `k`.
    pub fn file_name(index: u64, count: u64) -> String {
        format!("shard-{index}-of-{count}.json")
    }

    /// Wraps a shard's output.
    pub fn new(exp: &Experiment, output: ShardOutput) -> Self {
        ShardFile {
            format: FORMAT,
            crate_version: env!("CARGO_PKG_VERSION").to_string(),
            experiment_toml: exp.source_toml.clone(),
            experiment: exp.name.clone(),
            seed: exp.file.seed,
            output,
        }
    }

    /// Reads one shard file.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path.display(), &e))?;
        serde_json::from_str(&text).map_err(|e| Error::Io {
            path: path.display().to_string(),
            message: format!("not a fireflies shard file: {e}"),
        })
    }
}

/// The first line (1-based) where two texts differ, and that line in each.
fn first_difference<'a>(a: &'a str, b: &'a str) -> (usize, &'a str, &'a str) {
    let (mut la, mut lb) = (a.lines(), b.lines());
    for line in 1.. {
        match (la.next(), lb.next()) {
            (Some(x), Some(y)) if x == y => continue,
            (None, None) => return (line, "", ""),
            (x, y) => {
                return (
                    line,
                    x.unwrap_or("(end of file)"),
                    y.unwrap_or("(end of file)"),
                );
            }
        }
    }
    unreachable!("the loop returns at the first difference")
}

/// Every `shard-*-of-*.json` in the given directories (or the files themselves), sorted.
pub fn find_shard_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for input in inputs {
        if input.is_file() {
            files.push(input.clone());
            continue;
        }
        let entries = std::fs::read_dir(input).map_err(|e| Error::io(input.display(), &e))?;
        for entry in entries {
            let path = entry.map_err(|e| Error::io(input.display(), &e))?.path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
            if name.is_some_and(|n| n.starts_with("shard-") && n.ends_with(".json")) {
                files.push(path);
            }
        }
    }
    files.sort();
    if files.is_empty() {
        return Err(Error::param(
            "shards",
            format!("{inputs:?}"),
            "no shard-*-of-*.json files found",
        ));
    }
    Ok(files)
}

/// Checks that the shards are exactly 0..k of one run of one experiment with one version, then
/// folds them. Returns the experiment and the merged output.
pub fn merge(files: &[PathBuf]) -> Result<(Experiment, RunOutput)> {
    let shards = files
        .iter()
        .map(|f| ShardFile::read(f).map(|s| (f, s)))
        .collect::<Result<Vec<_>>>()?;
    let (first_path, first) = &shards[0];
    let mismatch = |path: &Path, what: &str, here: String, there: String| Error::Io {
        path: path.display().to_string(),
        message: format!(
            "mismatched shard: {what} is {here} here but {there} in {}",
            first_path.display()
        ),
    };
    let count = first.output.shard.count;
    // Counts and indices come from the files: keep what was seen in a map, never in a vector
    // sized by a count a file claims.
    let mut seen: BTreeMap<u64, &PathBuf> = BTreeMap::new();
    for (path, s) in &shards {
        if s.format != first.format {
            return Err(mismatch(
                path,
                "format",
                s.format.to_string(),
                first.format.to_string(),
            ));
        }
        if s.crate_version != first.crate_version {
            return Err(mismatch(
                path,
                "version",
                s.crate_version.clone(),
                first.crate_version.clone(),
            ));
        }
        if s.seed != first.seed {
            return Err(mismatch(
                path,
                "the seed",
                s.seed.to_string(),
                first.seed.to_string(),
            ));
        }
        if s.output.trials != first.output.trials {
            return Err(mismatch(
                path,
                "the trial count",
                s.output.trials.to_string(),
                first.output.trials.to_string(),
            ));
        }
        if s.experiment_toml != first.experiment_toml {
            let (line, here, there) = first_difference(&s.experiment_toml, &first.experiment_toml);
            return Err(mismatch(
                path,
                &format!("line {line} of experiment '{}'", shorten(&s.experiment)),
                format!("`{}`", shorten(here)),
                format!("`{}`", shorten(there)),
            ));
        }
        if s.output.shard.count != count {
            return Err(mismatch(
                path,
                "the shard count",
                s.output.shard.count.to_string(),
                count.to_string(),
            ));
        }
        let index = s.output.shard.index;
        if index >= count {
            return Err(Error::Io {
                path: path.display().to_string(),
                message: format!("shard index {index} is not below its count {count}"),
            });
        }
        if let Some(other) = seen.insert(index, path) {
            return Err(Error::Io {
                path: path.display().to_string(),
                message: format!(
                    "duplicated shard {index}/{count}: also in {}",
                    other.display()
                ),
            });
        }
    }
    // The first gap is found within `seen.len() + 1` steps, however large `count` is.
    if let Some(missing) = (0..count).find(|i| !seen.contains_key(i)) {
        return Err(Error::param(
            "shards",
            format!("{missing}/{count}"),
            format!("is missing ({} of {count} shard files given)", shards.len()),
        ));
    }
    let exp = Experiment::from_toml(
        &first.experiment_toml,
        "shard experiment",
        &first.experiment,
    )?;
    let outputs: Vec<ShardOutput> = shards.into_iter().map(|(_, s)| s.output).collect();
    let merged = runner::fold(&exp, &outputs)?;
    Ok((exp, merged))
}
