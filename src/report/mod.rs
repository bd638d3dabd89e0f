//! Reports: tables (CSV, JSON, Markdown) and plots. Analysis writes data; plotting only reads
//! it. Every file is written atomically, so an interrupted run leaves earlier results intact.

pub mod plots;
pub mod tables;

use crate::error::{Error, Result};
use std::fs;
use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename, so
/// readers see either the old file or the complete new one, never a torn write.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    fs::create_dir_all(dir).map_err(|e| Error::io(dir.display(), &e))?;
    let name = path
        .file_name()
        .ok_or_else(|| Error::Io {
            path: path.display().to_string(),
            message: "not a file path".into(),
        })?
        .to_string_lossy();
    let tmp = dir.join(format!(".{name}.tmp.{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut f = fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        fs::rename(&tmp, path)
    };
    write().map_err(|e| {
        let _ = fs::remove_file(&tmp);
        Error::io(path.display(), &e)
    })
}

/// Writes `results.csv`, `speed.csv`, `summary.md`, `checks.json` and `manifest.json` into
/// `dir`, each atomically. Returns the rows of both CSVs (what the plots read).
pub fn write_tables(
    dir: &Path,
    exp: &crate::harness::Experiment,
    out: &crate::harness::RunOutput,
    checks: &[crate::harness::CheckResult],
) -> Result<Vec<tables::Row>> {
    let mut rows = tables::rows(exp, out);
    write_atomic(&dir.join("results.csv"), &tables::results_csv(&rows)?)?;
    let speed = tables::speed_rows(exp, out);
    write_atomic(&dir.join("speed.csv"), &tables::results_csv(&speed)?)?;
    // The generator's cost stays in speed.csv; the plots compare estimators only.
    rows.extend(speed.into_iter().filter(|r| r.metric == "ns_per_sample"));
    write_atomic(
        &dir.join("summary.md"),
        tables::summary_md(exp, out, checks).as_bytes(),
    )?;
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
    use super::*;

    #[test]
    fn replaces_whole_file_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("fireflies-atomic-{}", std::process::id()));
        let path = dir.join("out.txt");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second");
        let leftovers = fs::read_dir(&dir).unwrap().count();
        assert_eq!(leftovers, 1);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unwritable_path_is_an_error_naming_it() {
        let e = write_atomic(Path::new("/proc/fireflies/x.csv"), b"x").unwrap_err();
        assert!(e.to_string().contains("/proc/fireflies"), "{e}");
    }
}
