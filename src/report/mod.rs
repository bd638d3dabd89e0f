//! Reports: tables (CSV, JSON, Markdown) and plots. Analysis writes data; plotting only reads
//! it. A report directory is replaced as a unit ([`write_report`]): an interrupted run leaves
//! either the earlier report, complete, or the new one, never a mix of two runs.

pub mod plots;
pub mod qq;
pub mod tables;

pub use crate::atomic::write_atomic;

use crate::atomic;
use crate::error::{Error, Result};
use std::fs;
use std::path::Path;

/// The tables every report holds.
pub const TABLE_FILES: [&str; 5] = [
    "results.csv",
    "speed.csv",
    "summary.md",
    "checks.json",
    "manifest.json",
];

/// The figures a report may hold, each as `<name>.png` and `<name>.svg` (see [`plots`]).
pub const PLOT_NAMES: [&str; 6] = [
    "median_error",
    "bias",
    "variance_mse",
    "firefly_rate",
    "error_quantiles",
    "speed_vs_error",
];

/// Whether `name` is a file that some report writes: an earlier report's copy of it belongs to
/// that report and goes when a new one replaces it.
pub fn is_report_file(name: &str) -> bool {
    TABLE_FILES.contains(&name)
        || [".png", ".svg"].iter().any(|ext| {
            name.strip_suffix(ext)
                .is_some_and(|stem| PLOT_NAMES.contains(&stem))
        })
}

/// Checks, before a run, that a report can be written to `dir` (see [`write_report`]): it is a
/// directory or can be created, is writable, is not the root or the current directory, and
/// holds no subdirectory. Cleans what killed writers left beside it. Errors name the path.
pub fn prepare_report_dir(dir: &Path) -> Result<()> {
    atomic::prepare_dir(dir)?;
    match fs::read_dir(dir) {
        Ok(entries) => {
            for e in entries {
                let e = e.map_err(|e| Error::io(dir.display(), &e))?;
                let kind = e
                    .file_type()
                    .map_err(|err| Error::io(e.path().display(), &err))?;
                if kind.is_dir() {
                    return Err(foreign_dir(&e.path()));
                }
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(Error::io(dir.display(), &e)),
    }
}

/// Writes a whole report into `dir` as a unit: the tables of [`write_tables`] and, with
/// `with_plots`, the figures of [`plots::write_plots`], all into a temporary directory beside
/// `dir` that then replaces it ([`atomic::replace_dir`]). Whenever the process is killed, `dir`
/// holds either the earlier report or this one, each complete.
///
/// Files of `dir` that are no report's (e.g. shard files, notes) are carried into the new
/// directory as hard links (copies where the filesystem has none); an earlier report's files
/// and debris of interrupted writes are not. A subdirectory cannot be carried atomically, so one
/// is an error naming it, and `dir` is left as it was. Returns the rows the plots read.
pub fn write_report(
    dir: &Path,
    exp: &crate::harness::Experiment,
    out: &crate::harness::RunOutput,
    checks: &[crate::harness::CheckResult],
    with_plots: bool,
) -> Result<Vec<tables::Row>> {
    atomic::replace_dir(dir, |staging| {
        let rows = write_tables(staging, exp, out, checks)?;
        if with_plots {
            plots::write_plots(staging, &rows)?;
        }
        carry_over(dir, staging)?;
        Ok(rows)
    })
}

/// Links into `staging` every entry of the old `dir` that belongs to no report.
fn carry_over(dir: &Path, staging: &Path) -> Result<()> {
    let entries = match fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(Error::io(dir.display(), &e)),
    };
    for e in entries {
        let e = e.map_err(|e| Error::io(dir.display(), &e))?;
        let name = e.file_name();
        let from = e.path();
        let to = staging.join(&name);
        let ours = name.to_str().is_some_and(is_report_file);
        if ours || atomic::is_temp_name(&name) || fs::symlink_metadata(&to).is_ok() {
            continue;
        }
        let kind = e
            .file_type()
            .map_err(|err| Error::io(from.display(), &err))?;
        let carried = if kind.is_file() {
            fs::hard_link(&from, &to).or_else(|_| fs::copy(&from, &to).map(|_| ()))
        } else if kind.is_symlink() {
            copy_symlink(&from, &to)
        } else if kind.is_dir() {
            return Err(foreign_dir(&from));
        } else {
            Err(std::io::Error::other(
                "not a regular file, link or directory; cannot be carried into the new report",
            ))
        };
        carried.map_err(|err| Error::io(from.display(), &err))?;
    }
    Ok(())
}

#[cfg(unix)]
fn copy_symlink(from: &Path, to: &Path) -> std::io::Result<()> {
    std::os::unix::fs::symlink(fs::read_link(from)?, to)
}

#[cfg(not(unix))]
fn copy_symlink(from: &Path, to: &Path) -> std::io::Result<()> {
    fs::copy(from, to).map(|_| ())
}

fn foreign_dir(path: &Path) -> Error {
    Error::Io {
        path: path.display().to_string(),
        message: "a directory inside the report directory: a report is replaced as a whole, so \
                  its directory must hold no subdirectory (move it, or choose another --out)"
            .into(),
    }
}

/// Writes `results.csv`, `speed.csv`, `summary.md`, `checks.json` and `manifest.json` into
/// `dir`, each atomically, but not as a unit: a report goes through [`write_report`]. Returns
/// the rows of both CSVs (what the plots read).
pub fn write_tables(
    dir: &Path,
    exp: &crate::harness::Experiment,
    out: &crate::harness::RunOutput,
    checks: &[crate::harness::CheckResult],
) -> Result<Vec<tables::Row>> {
    let mut rows = tables::rows(exp, out);
    write_atomic(&dir.join("results.csv"), &tables::results_csv(&rows)?)?;
    let summary = tables::summary_md(exp, out, &rows, checks);
    let speed = tables::speed_rows(exp, out);
    write_atomic(&dir.join("speed.csv"), &tables::results_csv(&speed)?)?;
    // The generator's cost stays in speed.csv; the plots compare estimators only.
    rows.extend(
        speed
            .into_iter()
            .filter(|r| r.metric == crate::harness::metrics::Metric::NsPerSample),
    );
    write_atomic(&dir.join("summary.md"), summary.as_bytes())?;
    let checks_json = serde_json::to_string_pretty(checks).unwrap_or_default();
    write_atomic(&dir.join("checks.json"), checks_json.as_bytes())?;
    write_atomic(
        &dir.join("manifest.json"),
        tables::manifest_json(exp, out, checks).as_bytes(),
    )?;
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::is_report_file;

    #[test]
    fn report_files_are_the_tables_and_the_known_figures() {
        for name in [
            "results.csv",
            "manifest.json",
            "bias.png",
            "speed_vs_error.svg",
        ] {
            assert!(is_report_file(name), "{name}");
        }
        for name in [
            "shard-0-of-2.json",
            "notes.png",
            "bias.pdf",
            ".results.csv.tmp.1",
        ] {
            assert!(!is_report_file(name), "{name}");
        }
    }
}
