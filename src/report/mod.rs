//! Reports: tables (CSV, JSON, Markdown) and plots. Analysis writes data; plotting only reads
//! it. Every file is written atomically, so an interrupted run leaves earlier results intact.

pub mod plots;
pub mod tables;

pub use crate::atomic::write_atomic;

use crate::error::Result;
use std::path::Path;

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
