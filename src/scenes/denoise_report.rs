//! The denoising experiment's report: `denoise.csv` (one row per scene, spp, repeat, source,
//! variance and stage), `denoise_summary.csv` (per cell the mean over repeats with a Student-t
//! interval, [`denoise_cells`]), `denoise_paired.csv` (each source against the baseline, paired
//! within each render, [`paired_comparisons`]), `mse_estimates.csv` (NFOR's MSE estimate against
//! the truth), `scenes.csv`, `summary.md`, `manifest.json`, and the figures `relmse_vs_spp.png`, `ssim_vs_spp.png` and
//! `montage.png`. Every file is written atomically; the reference cache beside them is left
//! alone.

pub use super::denoise_compare::{MeanInterval, mean_interval};
use super::denoise_compare::{PairedRow, Verdict, geo_interval, paired_comparisons, t_quantile};
use super::denoise_experiment::{DenoiseExperiment, variance_name};
use super::denoise_run::{DENOISED, DenoiseRow, DenoiseSceneInfo, DenoiseSceneResult, MseRow};
use super::report::{RunInfo, summary_head};
use super::tables::to_csv;
use crate::atomic::ReportFiles;
use crate::error::{Error, Result};
use crate::harness::metrics::LEVEL;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One row of `denoise_summary.csv`: a cell of the experiment (scene, spp, source, variance,
/// stage) over its repeats. Each metric has its mean over repeats, the standard error of that
/// mean and the half-width of its 95% Student-t interval (`_ci95`: the interval is
/// `mean ± ci95`); with one repeat the `_se` and `_ci95` columns are empty. relMSE also has its
/// geometric mean over repeats with the log-scale interval `exp(mean ln ± t · se)`
/// ([`geo_interval`]): never below zero, fitting a heavy-tailed positive metric; empty when a
/// repeat's relMSE is zero or not finite. Every repeat is judged against the same reference,
/// so the interval holds the renders' noise, not the reference's (which is common to all
/// repeats).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct DenoiseCell {
    /// Scene name.
    pub scene: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Source estimator spec.
    pub source: String,
    /// Its short label.
    pub label: String,
    /// Variance given to NFOR; empty for the noisy estimate.
    pub variance: String,
    /// `noisy` or `denoised`.
    pub stage: String,
    /// Repeats (independent renders) the cell averages.
    pub repeats: usize,
    /// Confidence level of the `_ci95` columns.
    pub level: f64,
    /// Mean relMSE over repeats.
    pub relmse_mean: f64,
    /// Its standard error.
    pub relmse_se: Option<f64>,
    /// Its interval's half-width.
    pub relmse_ci95: Option<f64>,
    /// Geometric mean relMSE over repeats.
    pub relmse_geomean: Option<f64>,
    /// Lower end of its log-scale interval (empty with one repeat).
    pub relmse_geo_lo: Option<f64>,
    /// Upper end.
    pub relmse_geo_hi: Option<f64>,
    /// Mean SSIM.
    pub ssim_mean: f64,
    /// Its standard error.
    pub ssim_se: Option<f64>,
    /// Its interval's half-width.
    pub ssim_ci95: Option<f64>,
    /// Mean count of firefly pixels.
    pub firefly_pixels_mean: f64,
    /// Its standard error.
    pub firefly_pixels_se: Option<f64>,
    /// Its interval's half-width.
    pub firefly_pixels_ci95: Option<f64>,
    /// Denoised cells: mean fraction of pixels NFOR made worse by more than a factor 2
    /// ([`super::denoise_run::worse_fraction`]).
    pub worse_2x_fraction_mean: Option<f64>,
    /// Its interval's half-width.
    pub worse_2x_fraction_ci95: Option<f64>,
    /// Mean relative bias of the image-mean luminance (empty if any repeat has none).
    pub mean_bias_relative_mean: Option<f64>,
    /// Its standard error.
    pub mean_bias_relative_se: Option<f64>,
    /// Its interval's half-width.
    pub mean_bias_relative_ci95: Option<f64>,
    /// Mean NFOR seconds (denoised cells).
    pub nfor_s_mean: Option<f64>,
    /// Mean NFOR seconds per megapixel (denoised cells).
    pub nfor_s_per_megapixel_mean: Option<f64>,
    /// Its standard error.
    pub nfor_s_per_megapixel_se: Option<f64>,
    /// Its interval's half-width.
    pub nfor_s_per_megapixel_ci95: Option<f64>,
}

/// Mean, standard error and half-width of one metric over a cell's rows; all `None` when a row
/// lacks the metric.
fn metric(
    own: &[&DenoiseRow],
    f: impl Fn(&DenoiseRow) -> Option<f64>,
) -> (Option<f64>, Option<f64>, Option<f64>) {
    let values: Option<Vec<f64>> = own.iter().map(|r| f(r)).collect();
    values
        .and_then(|v| mean_interval(&v))
        .map_or((None, None, None), |m| (Some(m.mean), m.se, m.half_width))
}

/// The cells of `rows`, in order of first appearance: one per scene, spp, source, variance and
/// stage, over its repeats.
pub fn denoise_cells(rows: &[DenoiseRow]) -> Vec<DenoiseCell> {
    let key = |r: &DenoiseRow| {
        (
            r.scene.clone(),
            r.spp,
            r.source.clone(),
            r.variance.clone(),
            r.stage.clone(),
        )
    };
    let mut keys = Vec::new();
    for r in rows {
        let k = key(r);
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .filter_map(|k| {
            let own: Vec<&DenoiseRow> = rows.iter().filter(|r| key(r) == k).collect();
            let first = own.first()?;
            let (relmse_mean, relmse_se, relmse_ci95) = metric(&own, |r| Some(r.relmse));
            let geo = geo_interval(&own.iter().map(|r| r.relmse).collect::<Vec<_>>());
            let (ssim_mean, ssim_se, ssim_ci95) = metric(&own, |r| Some(r.ssim));
            let (ff_mean, ff_se, ff_ci95) = metric(&own, |r| Some(r.firefly_pixels as f64));
            let (bias_mean, bias_se, bias_ci95) = metric(&own, |r| r.mean_bias_relative);
            let (worse_mean, _, worse_ci95) = metric(&own, |r| r.worse_2x_fraction);
            let (nfor_s_mean, _, _) = metric(&own, |r| r.nfor_s);
            let (mp_mean, mp_se, mp_ci95) = metric(&own, |r| r.nfor_s_per_megapixel);
            Some(DenoiseCell {
                scene: first.scene.clone(),
                width: first.width,
                height: first.height,
                spp: first.spp,
                source: first.source.clone(),
                label: first.label.clone(),
                variance: first.variance.clone(),
                stage: first.stage.clone(),
                repeats: own.len(),
                level: LEVEL,
                relmse_mean: relmse_mean.unwrap_or(f64::NAN),
                relmse_se,
                relmse_ci95,
                relmse_geomean: geo.map(|g| g.geomean),
                relmse_geo_lo: geo.and_then(|g| g.lo),
                relmse_geo_hi: geo.and_then(|g| g.hi),
                ssim_mean: ssim_mean.unwrap_or(f64::NAN),
                ssim_se,
                ssim_ci95,
                firefly_pixels_mean: ff_mean.unwrap_or(f64::NAN),
                firefly_pixels_se: ff_se,
                firefly_pixels_ci95: ff_ci95,
                worse_2x_fraction_mean: worse_mean,
                worse_2x_fraction_ci95: worse_ci95,
                mean_bias_relative_mean: bias_mean,
                mean_bias_relative_se: bias_se,
                mean_bias_relative_ci95: bias_ci95,
                nfor_s_mean,
                nfor_s_per_megapixel_mean: mp_mean,
                nfor_s_per_megapixel_se: mp_se,
                nfor_s_per_megapixel_ci95: mp_ci95,
            })
        })
        .collect()
}

/// Which cells of a table row are bold, given each cell's mean and interval half-width (lower
/// is better). With intervals, only the lowest mean, and only when its interval lies wholly
/// below every other cell's: overlapping intervals (exact ties included) bold nothing. Without
/// any interval (one repeat), every cell equal to the lowest mean. Non-finite means are never
/// bold and are not compared.
pub fn clear_best(cells: &[Option<(f64, Option<f64>)>]) -> Vec<bool> {
    let finite = |c: &Option<(f64, Option<f64>)>| c.filter(|(m, _)| m.is_finite());
    let best = cells
        .iter()
        .filter_map(finite)
        .map(|(m, _)| m)
        .fold(f64::INFINITY, f64::min);
    if !best.is_finite() {
        return vec![false; cells.len()];
    }
    if cells.iter().filter_map(finite).all(|(_, h)| h.is_none()) {
        return cells
            .iter()
            .map(|c| finite(c).is_some_and(|(m, _)| m == best))
            .collect();
    }
    let Some(b) = cells
        .iter()
        .position(|c| finite(c).is_some_and(|(m, _)| m == best))
    else {
        return vec![false; cells.len()];
    };
    let high = |(m, h): (f64, Option<f64>)| m + h.unwrap_or(0.0);
    let low = |(m, h): (f64, Option<f64>)| m - h.unwrap_or(0.0);
    let top = cells[b].map_or(f64::NAN, high);
    let clear = cells
        .iter()
        .enumerate()
        .filter(|&(i, _)| i != b)
        .filter_map(|(_, c)| finite(c))
        .all(|c| top < low(c));
    (0..cells.len()).map(|i| clear && i == b).collect()
}

/// NFOR's MSE estimate over seeds for one bandwidth: the ratio of the image-mean estimate to
/// the image-mean true squared error, with a Student-t interval over the seeds.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MseInterval {
    /// Scene.
    pub scene: String,
    /// Samples per pixel.
    pub spp: u32,
    /// Source estimator.
    pub source: String,
    /// Variance given to NFOR.
    pub variance: String,
    /// First-pass bandwidth.
    pub k: f64,
    /// Seeds.
    pub seeds: usize,
    /// Mean over seeds of the estimated MSE.
    pub estimated_mse: f64,
    /// Mean over seeds of the true squared error.
    pub true_mse: f64,
    /// Mean over seeds of the per-seed ratio.
    pub ratio: f64,
    /// Median over seeds of the per-seed ratio (one wild seed moves the mean, not this).
    pub ratio_median: f64,
    /// Standard error of that mean.
    pub ratio_se: f64,
    /// Lower end of the interval.
    pub ratio_low: f64,
    /// Upper end.
    pub ratio_high: f64,
    /// The interval's confidence level.
    pub level: f64,
    /// The reference's own variance over the mean true squared error (what of the truth is the
    /// reference's noise).
    pub reference_share: f64,
}

/// The intervals of the `seeds` study in `rows`, one per scene, spp, source, variance and
/// bandwidth, in order of first appearance. Groups of fewer than two seeds are left out.
pub fn mse_intervals(rows: &[MseRow]) -> Vec<MseInterval> {
    let mut keys: Vec<(String, u32, String, String, u64)> = Vec::new();
    for r in rows.iter().filter(|r| r.study == "seeds") {
        let key = (
            r.scene.clone(),
            r.spp,
            r.source.clone(),
            r.variance.clone(),
            r.k.to_bits(),
        );
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    keys.into_iter()
        .filter_map(|(scene, spp, source, variance, k)| {
            let own: Vec<&MseRow> = rows
                .iter()
                .filter(|r| {
                    r.study == "seeds"
                        && r.scene == scene
                        && r.spp == spp
                        && r.source == source
                        && r.variance == variance
                        && r.k.to_bits() == k
                })
                .collect();
            let n = own.len();
            if n < 2 {
                return None;
            }
            let nf = n as f64;
            let mean = |f: &dyn Fn(&MseRow) -> f64| own.iter().map(|r| f(r)).sum::<f64>() / nf;
            let ratios: Vec<f64> = own.iter().map(|r| r.ratio).collect();
            let m = mean_interval(&ratios)?;
            let (ratio, se, half) = (
                m.mean,
                m.se.unwrap_or(f64::NAN),
                m.half_width.unwrap_or(f64::NAN),
            );
            let true_mse = mean(&|r| r.true_mse);
            let mut sorted: Vec<f64> = own.iter().map(|r| r.ratio).collect();
            sorted.sort_by(f64::total_cmp);
            let ratio_median = if n % 2 == 1 {
                sorted[n / 2]
            } else {
                0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
            };
            Some(MseInterval {
                scene,
                spp,
                source,
                variance,
                k: f64::from_bits(k),
                seeds: n,
                estimated_mse: mean(&|r| r.estimated_mse),
                true_mse,
                ratio,
                ratio_median,
                ratio_se: se,
                ratio_low: ratio - half,
                ratio_high: ratio + half,
                level: LEVEL,
                reference_share: mean(&|r| r.reference_variance) / true_mse,
            })
        })
        .collect()
}

/// Writes every table and figure of `results` into `dir`; returns the paths written.
///
/// # Errors
///
/// A file that cannot be written or a figure that cannot be drawn.
pub fn write_denoise_report(
    dir: &Path,
    exp: &DenoiseExperiment,
    results: &[DenoiseSceneResult],
    run: &RunInfo,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir.display(), &e))?;
    let rows: Vec<DenoiseRow> = results.iter().flat_map(|r| r.rows.clone()).collect();
    let cells = denoise_cells(&rows);
    let paired = paired_comparisons(&rows);
    let mse: Vec<MseRow> = results.iter().flat_map(|r| r.mse.clone()).collect();
    let infos: Vec<DenoiseSceneInfo> = results.iter().map(|r| r.info.clone()).collect();
    let intervals = mse_intervals(&mse);
    let mut files = ReportFiles::new(dir);
    files.put("denoise.csv", &to_csv(&rows)?)?;
    files.put("denoise_summary.csv", &to_csv(&cells)?)?;
    files.put("denoise_paired.csv", &to_csv(&paired)?)?;
    files.put("mse_estimates.csv", &to_csv(&mse)?)?;
    files.put("mse_check.csv", &to_csv(&intervals)?)?;
    files.put("scenes.csv", &to_csv(&infos)?)?;
    files.put(
        "summary.md",
        summary_md(exp, run, &infos, &rows, &cells, &paired, &mse, &intervals).as_bytes(),
    )?;
    let manifest = serde_json::json!({
        "experiment": exp.source,
        "quick": exp.quick,
        "seed": exp.file.seed,
        "repeats": exp.repeats,
        "repeat_seeds": (0..exp.repeats).map(|r| exp.repeat_seed(r)).collect::<Vec<_>>(),
        "threads": run.threads,
        "command": run.command,
        "wall_s": run.wall_s,
        "pending_scenes": run.pending,
        "scenes": infos,
        "nfor_params": format!("{:?}", crate::denoise::NforParams::paper()),
        "peak_rss_bytes": crate::limits::peak_rss_bytes(),
        "crate_version": env!("CARGO_PKG_VERSION"),
        "git_commit": crate::report::tables::git_commit(),
    });
    files.put(
        "manifest.json",
        (serde_json::to_string_pretty(&manifest).unwrap_or_default() + "\n").as_bytes(),
    )?;
    if !cells.is_empty() {
        files.extend(super::denoise_plots::write_plots(
            dir, exp, &cells, results,
        )?);
    }
    Ok(files.into_paths())
}

fn opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map_or_else(|| "—".to_string(), f)
}

/// `mean ± half-width` in the format `f`, or the mean alone without an interval.
fn pm(mean: f64, half: Option<f64>, f: impl Fn(f64) -> String) -> String {
    match half {
        Some(h) => format!("{} ± {}", f(mean), f(h)),
        None => f(mean),
    }
}

/// A relMSE `mean ± half-width`: the mean to four digits, the half-width to two.
fn pm_relmse(mean: f64, half: Option<f64>) -> String {
    match half {
        Some(h) => format!("{mean:.3e} ± {h:.1e}"),
        None => format!("{mean:.3e}"),
    }
}

fn find<'a>(
    cells: &'a [DenoiseCell],
    scene: &str,
    spp: u32,
    source: &str,
    variance: &str,
) -> Option<&'a DenoiseCell> {
    cells
        .iter()
        .find(|r| r.scene == scene && r.spp == spp && r.source == source && r.variance == variance)
}

/// Distinct spp of a scene's cells, ascending.
fn scene_spps(cells: &[DenoiseCell], scene: &str) -> Vec<u32> {
    let mut v: Vec<u32> = cells
        .iter()
        .filter(|r| r.scene == scene)
        .map(|r| r.spp)
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// A ratio to two or three significant digits, in scientific notation when very small or
/// large.
fn fmt_ratio(v: f64) -> String {
    let a = v.abs();
    if (100.0..10000.0).contains(&a) {
        format!("{v:.0}")
    } else if (10.0..100.0).contains(&a) {
        format!("{v:.1}")
    } else if (0.1..10.0).contains(&a) {
        format!("{v:.2}")
    } else if (0.01..0.1).contains(&a) {
        format!("{v:.3}")
    } else {
        format!("{v:.1e}")
    }
}

/// A paired cell: `0.38× [0.31, 0.46] helps`, bold when the verdict holds after Holm's
/// correction too.
fn paired_cell(r: &PairedRow) -> String {
    let Some(g) = r.ratio_geomean else {
        return r.verdict.as_str().to_string();
    };
    let mut cell = format!("{}×", fmt_ratio(g));
    if let (Some(lo), Some(hi)) = (r.ratio_lo, r.ratio_hi) {
        let _ = write!(cell, " [{}, {}]", fmt_ratio(lo), fmt_ratio(hi));
    }
    let _ = write!(cell, " {}", r.verdict.as_str());
    if r.skipped > 0 {
        let _ = write!(cell, " ({} skipped)", r.skipped);
    }
    if matches!(r.verdict_holm, Verdict::Helps | Verdict::Hurts) {
        cell = format!("**{cell}**");
    }
    cell
}

/// The series of one stage's paired rows in order of first appearance: source, variance, label.
fn paired_series<'a>(paired: &'a [PairedRow], stage: &str) -> Vec<(&'a str, &'a str, &'a str)> {
    let mut v: Vec<(&str, &str, &str)> = Vec::new();
    for r in paired.iter().filter(|r| r.stage == stage) {
        let k = (r.source.as_str(), r.variance.as_str(), r.label.as_str());
        if !v.contains(&k) {
            v.push(k);
        }
    }
    v
}

/// The section on paired ratios: what is compared and how, a table per stage, and the count of
/// verdicts.
fn paired_md(s: &mut String, exp: &DenoiseExperiment, paired: &[PairedRow]) {
    let first = &exp.sources[0];
    let base_var = first.variances.first().map_or("", |&v| variance_name(v));
    let _ = writeln!(
        s,
        "## Does a robust estimator help? Paired ratios against the {b}\n\n\
         Each source is compared with a baseline on the same renders. After NFOR, the baseline \
         is NFOR of the {b} with {base_var} variance (the experiment file's first source and \
         its first variance); every other source and variance after NFOR is compared with it. \
         Before NFOR, the baseline is the {b}'s noisy estimate: does the robust estimator help \
         before any denoising? All sources of one repeat are computed from the same render (the \
         same samples, split into the same halves), so the render's luck moves them together; \
         per repeat r the ratio relMSE(source, r) / relMSE(baseline, r) cancels most of it, \
         where separate intervals per cell would keep it. A cell is the geometric mean of that \
         ratio over the repeats, exp(mean of the log-ratios), below 1 when the source has the \
         lower relMSE, with its {lvl:.0}% interval exp(mean ± t · se): se is the standard \
         error of the mean log-ratio and t Student's quantile with repeats − 1 degrees of \
         freedom ({t_text}). The interval assumes independent repeats and log-ratios roughly \
         normal over them; a ratio of heavy-tailed relMSEs is far closer to that on the log \
         scale, where halving and doubling are symmetric.\n\n\
         Verdict: **helps** when the whole interval lies below 1, **hurts** when it lies above \
         1, **undecided** when it holds 1, **same** when every repeat's relMSE is exactly the \
         baseline's (as with G-MoN at two samples per half, where it equals the mean and NFOR \
         gets the same input), **n/a** with fewer than two usable pairs (no interval). A pair \
         with a relMSE that is zero or not finite on either side has no log-ratio: it is left \
         out and counted in the `skipped` column of `denoise_paired.csv` (and in the \
         cell){skipped}. Both sides are judged against the same reference, whose own noise adds \
         the same floor to both relMSEs and pulls the ratio towards 1. Each verdict is at \
         {lvl:.0}% for its own cell; over all cells of a stage some would be decided by chance, \
         so a **bold** cell's verdict also holds after Holm's correction over every cell of its \
         stage (`p_holm`, `verdict_holm` in `denoise_paired.csv`).\n",
        b = first.label,
        lvl = 100.0 * LEVEL,
        t_text = if exp.repeats < 2 {
            "with one repeat there is no interval".to_string()
        } else {
            let dof = f64::from(exp.repeats - 1);
            let t = t_quantile(dof);
            format!("{} here, t = {t:.2}", exp.repeats - 1)
        },
        skipped = match paired.iter().map(|r| r.skipped).sum::<usize>() {
            0 => "; none was in this run".to_string(),
            n => format!("; {n} were in this run"),
        },
    );
    for (stage, title) in [
        (
            DENOISED,
            format!(
                "After NFOR: against NFOR of the {} ({base_var} variance)",
                first.label
            ),
        ),
        (
            super::denoise_run::NOISY,
            format!(
                "Before NFOR: noisy estimates against the noisy {}",
                first.label
            ),
        ),
    ] {
        let series = paired_series(paired, stage);
        let _ = writeln!(
            s,
            "### {title}
"
        );
        if series.is_empty() {
            s.push_str(
                "Nothing to compare: the stage has one source.

",
            );
            continue;
        }
        s.push_str("| scene | spp |");
        for (_, var, label) in &series {
            if var.is_empty() {
                let _ = write!(s, " {label} noisy |");
            } else {
                let _ = write!(s, " NFOR {label} ({var}) |");
            }
        }
        s.push_str("\n|---|---:|");
        for _ in &series {
            s.push_str("---:|");
        }
        s.push('\n');
        let mut cells: Vec<(&str, u32)> = Vec::new();
        for r in paired.iter().filter(|r| r.stage == stage) {
            if !cells.contains(&(r.scene.as_str(), r.spp)) {
                cells.push((r.scene.as_str(), r.spp));
            }
        }
        for (scene, spp) in cells {
            let _ = write!(s, "| {scene} | {spp} |");
            for &(src, var, _) in &series {
                match paired.iter().find(|r| {
                    r.stage == stage
                        && r.scene == scene
                        && r.spp == spp
                        && r.source == src
                        && r.variance == var
                }) {
                    Some(r) => {
                        let _ = write!(s, " {} |", paired_cell(r));
                    }
                    None => s.push_str(" — |"),
                }
            }
            s.push('\n');
        }
        s.push('\n');
    }

    s.push_str(
        "### How often each source helps\n\n\
         (scene, spp) cells per verdict; the last two columns count the verdicts that hold \
         after Holm's correction over the stage.\n\n\
         | stage | source | variance | cells | helps | hurts | same | undecided | n/a | helps (Holm) | hurts (Holm) |\n\
         |---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let mut closing = Vec::new();
    for stage in [DENOISED, super::denoise_run::NOISY] {
        for (src, var, label) in paired_series(paired, stage) {
            let own: Vec<&PairedRow> = paired
                .iter()
                .filter(|r| r.stage == stage && r.source == src && r.variance == var)
                .collect();
            let count = |v: Verdict| own.iter().filter(|r| r.verdict == v).count();
            let holm = |v: Verdict| own.iter().filter(|r| r.verdict_holm == v).count();
            let _ = writeln!(
                s,
                "| {stage} | {label} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                if var.is_empty() { "—" } else { var },
                own.len(),
                count(Verdict::Helps),
                count(Verdict::Hurts),
                count(Verdict::Same),
                count(Verdict::Undecided),
                count(Verdict::NoInterval),
                holm(Verdict::Helps),
                holm(Verdict::Hurts),
            );
            if stage == DENOISED {
                let mut parts = vec![
                    format!("helps in {}", count(Verdict::Helps)),
                    format!("hurts in {}", count(Verdict::Hurts)),
                    format!("is undecided in {}", count(Verdict::Undecided)),
                ];
                for (v, what) in [
                    (Verdict::Same, "is the same in"),
                    (Verdict::NoInterval, "has no interval in"),
                ] {
                    if count(v) > 0 {
                        parts.push(format!("{what} {}", count(v)));
                    }
                }
                closing.push(format!(
                    "NFOR of {label} ({var}) {} of its {} (scene, spp) cells",
                    parts.join(", "),
                    own.len()
                ));
            }
        }
    }
    s.push('\n');
    if !closing.is_empty() {
        let _ = writeln!(
            s,
            "In short, against NFOR of the {} ({base_var} variance): {}.\n",
            first.label,
            closing.join("; ")
        );
    }
}

/// What the tables' `±` means, and how the best cell is chosen, for `repeats` renders.
fn repeats_text(exp: &DenoiseExperiment) -> String {
    let seeds = (0..exp.repeats.min(3))
        .map(|r| exp.repeat_seed(r).to_string())
        .collect::<Vec<_>>()
        .join(", ");
    if exp.repeats < 2 {
        format!(
            "One render per scene and sample count (repeats = 1, seed {seeds}): every number \
             below comes from a single render and has no interval (the `_se` and `_ci95` \
             columns of `denoise_summary.csv` are empty). Set `repeats` to 2 or more to see \
             which differences are larger than the render-to-render noise."
        )
    } else {
        format!(
            "Each cell is the mean over {} independent renders (repeats; seeds {seeds}{}, i.e. \
             seed + r·2³², apart from the MSE check's) with its {:.0}% Student-t interval, \
             written `mean ± half-width` (t quantile with {} degrees of freedom times the \
             standard error of the mean). Every repeat is judged against the same reference, so \
             the interval holds the renders' noise only: the reference's own noise is common to \
             all repeats and shifts every cell of a scene alike (its size is the relMSE floor in \
             the last table). The interval is symmetric: on heavy-tailed cells its lower end can \
             fall below zero. The per-scene tables therefore also give relMSE's geometric mean \
             over the repeats with a log-scale interval, exp(mean of ln relMSE ± t · its \
             standard error), which stays positive (`relmse_geomean`, `relmse_geo_lo`, \
             `relmse_geo_hi` in `denoise_summary.csv`; empty if a repeat's relMSE is zero). The \
             sources of one repeat share its render, so they are compared pairwise in the \
             section after the first table.",
            exp.repeats,
            if exp.repeats > 3 { ", …" } else { "" },
            100.0 * LEVEL,
            exp.repeats - 1,
        )
    }
}

#[allow(clippy::too_many_arguments)]
fn summary_md(
    exp: &DenoiseExperiment,
    run: &RunInfo,
    infos: &[DenoiseSceneInfo],
    rows: &[DenoiseRow],
    cells: &[DenoiseCell],
    paired: &[PairedRow],
    mse: &[MseRow],
    intervals: &[MseInterval],
) -> String {
    let mut s = String::new();
    summary_head(
        &mut s,
        "Denoising experiment: NFOR behind robust estimators",
        exp.quick,
        &run.pending,
        &exp.file.description,
    );
    let _ = writeln!(
        s,
        "`{}` — {:.0} s wall on {} threads; commit {}. Per scene and sample count, {} with \
         NFOR's half buffers {} every source's estimator on the whole stream and on each half \
         (even and odd samples); NFOR (Bitterli et al. 2016, the paper's parameters) denoises \
         each source's halves with each variance. Every image is judged against the scene's \
         converged reference (the mean of its own samples, another seed). Firefly pixels: \
         luminance above {} × the reference's + {}. Files: `denoise.csv` (one row per scene, \
         spp, repeat, source, variance and stage; the noisy rows have no variance), \
         `denoise_summary.csv` (per cell the mean over repeats with its standard error and \
         95% interval half-width, `<metric>_mean`, `<metric>_se`, `<metric>_ci95`), \
         `denoise_paired.csv` (each source's relMSE over the baseline's, paired within each \
         render), `mse_estimates.csv`, `mse_check.csv`, `scenes.csv`, `manifest.json` and the figures \
         at the end.\n",
        run.command,
        run.wall_s,
        run.threads,
        crate::report::tables::git_commit().unwrap_or_else(|| "unknown".into()),
        if exp.repeats == 1 {
            "one render".to_string()
        } else {
            format!("{} independent renders", exp.repeats)
        },
        if exp.repeats == 1 { "runs" } else { "each run" },
        exp.rule.factor(),
        exp.rule.floor(),
    );
    let _ = writeln!(s, "{}\n", repeats_text(exp));

    // Columns of the headline table: per source its noisy estimate, then NFOR per variance.
    let mut columns: Vec<(String, String, String)> = Vec::new();
    for src in &exp.sources {
        columns.push((
            src.spec.to_string(),
            String::new(),
            format!("{} noisy", src.label),
        ));
        for &v in &src.variances {
            columns.push((
                src.spec.to_string(),
                variance_name(v).to_string(),
                format!("NFOR {} ({})", src.label, variance_name(v)),
            ));
        }
    }
    s.push_str("## relMSE of every source, noisy and after NFOR\n\n");
    s.push_str(
        "relMSE = mean over pixels and channels of (x − r)² / (r² + 0.01), linear radiance; \
         lower is better. In brackets after an NFOR cell: how many times lower than the same \
         source's noisy estimate (ratio of the means). ",
    );
    if exp.repeats < 2 {
        s.push_str(
            "The lowest cell of a row is bold (all of them on an exact tie); with one render \
             per cell, a bold cell may win by noise alone.\n\n| scene | spp |",
        );
    } else {
        s.push_str(
            "A cell is bold only when it has the lowest mean of its row and its interval lies \
             wholly below every other cell's; a row without a bold cell has no clear winner at \
             this number of repeats (exact ties, such as G-MoN at 4 spp, where it equals the \
             mean, count as overlapping). Non-overlap of two 95% intervals is a conservative \
             test of a difference.\n\n| scene | spp |",
        );
    }
    for (_, _, title) in &columns {
        let _ = write!(s, " {title} |");
    }
    s.push_str("\n|---|---:|");
    for _ in &columns {
        s.push_str("---:|");
    }
    s.push('\n');
    for info in infos {
        for spp in scene_spps(cells, &info.scene) {
            let row: Vec<Option<&DenoiseCell>> = columns
                .iter()
                .map(|(src, var, _)| find(cells, &info.scene, spp, src, var))
                .collect();
            let bold = clear_best(
                &row.iter()
                    .map(|c| c.map(|c| (c.relmse_mean, c.relmse_ci95)))
                    .collect::<Vec<_>>(),
            );
            let _ = write!(s, "| {} | {spp} |", info.scene);
            for ((c, (src, var, _)), bold) in row.iter().zip(&columns).zip(bold) {
                match c {
                    Some(r) => {
                        let mut cell = pm_relmse(r.relmse_mean, r.relmse_ci95);
                        if bold {
                            cell = format!("**{cell}**");
                        }
                        if !var.is_empty()
                            && let Some(n) = find(cells, &info.scene, spp, src, "")
                        {
                            let _ = write!(cell, " ({:.1}×)", n.relmse_mean / r.relmse_mean);
                        }
                        let _ = write!(s, " {cell} |");
                    }
                    None => s.push_str(" — |"),
                }
            }
            s.push('\n');
        }
    }
    s.push('\n');
    paired_md(&mut s, exp, paired);

    s.push_str("## Per scene: every metric\n\n");
    s.push_str(
        "relMSE as above; SSIM of the display luma (higher is better); firefly pixels by the \
         rule above; px worse > 2x = the share of pixels whose relative error NFOR more than \
         doubled over its noisy input's, counting only errors above 10% (per-pixel relMSE term \
         above 0.01); relative bias = image-mean luminance over the reference's, minus 1; NFOR \
         wall seconds and seconds per megapixel.",
    );
    if exp.repeats >= 2 {
        let _ = write!(
            s,
            " Means over the {} repeats, after ± the half-width of their 95% interval (NFOR s: \
             the mean only).",
            exp.repeats
        );
    }
    s.push_str("\n\n");
    for info in infos {
        let _ = writeln!(
            s,
            "### {} ({}x{}{}, reference {} spp)\n",
            info.scene,
            info.width,
            info.height,
            if info.rfilter_box_override {
                ", box filter"
            } else {
                ""
            },
            info.reference_spp
        );
        s.push_str(
            "| spp | source | variance | stage | relMSE | relMSE, geometric mean [95%] | SSIM | firefly px | px worse > 2x | rel. bias | NFOR s | NFOR s/MP |\n\
             |---:|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for r in cells.iter().filter(|r| r.scene == info.scene) {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                r.spp,
                r.label,
                if r.variance.is_empty() {
                    "—"
                } else {
                    &r.variance
                },
                r.stage,
                pm_relmse(r.relmse_mean, r.relmse_ci95),
                match (r.relmse_geomean, r.relmse_geo_lo, r.relmse_geo_hi) {
                    (Some(g), Some(lo), Some(hi)) => format!("{g:.3e} [{lo:.2e}, {hi:.2e}]"),
                    (Some(g), _, _) => format!("{g:.3e}"),
                    _ => "—".to_string(),
                },
                pm(r.ssim_mean, r.ssim_ci95, |v| format!("{v:.4}")),
                if r.repeats < 2 {
                    format!("{}", r.firefly_pixels_mean)
                } else {
                    pm(r.firefly_pixels_mean, r.firefly_pixels_ci95, |v| {
                        format!("{v:.1}")
                    })
                },
                opt(r.worse_2x_fraction_mean, |v| {
                    match r.worse_2x_fraction_ci95 {
                        Some(h) => format!("{:.2}% ± {:.2}%", 100.0 * v, 100.0 * h),
                        None => format!("{:.2}%", 100.0 * v),
                    }
                }),
                opt(r.mean_bias_relative_mean, |v| {
                    match r.mean_bias_relative_ci95 {
                        Some(h) => format!("{:+.2}% ± {:.2}%", 100.0 * v, 100.0 * h),
                        None => format!("{:+.2}%", 100.0 * v),
                    }
                }),
                opt(r.nfor_s_mean, |v| format!("{v:.2}")),
                opt(r.nfor_s_per_megapixel_mean, |v| pm(
                    v,
                    r.nfor_s_per_megapixel_ci95,
                    |x| format!("{x:.1}")
                )),
            );
        }
        s.push('\n');
    }

    let c = &exp.mse_check;
    let check_scene = &exp.scenes[c.scene].scene.name;
    let _ = writeln!(
        s,
        "## Does NFOR's MSE estimate hold on a real scene?\n\n\
         NFOR picks its first-pass bandwidth per pixel by an estimate of each candidate's MSE \
         made from the two halves alone (`noisy_mse`, before its NL-means filtering). Over {} \
         renders of {check_scene} at {} spp (seeds {}..={}), {} with {} variance: the image \
         mean of that estimate over pixels and channels, against the image mean of the \
         candidate's true squared error against the reference, and their ratio with a \
         Student-t {:.0}% interval over the seeds. Nothing is subtracted from the truth for the \
         reference's own noise; the last column says how much of it that noise is (the \
         reference's mean squared standard error over the mean true squared error).\n",
        c.seeds,
        c.spp,
        exp.file.seed + 1,
        exp.file.seed + u64::from(c.seeds),
        exp.sources[c.source].label,
        c.variances
            .iter()
            .map(|&v| variance_name(v))
            .collect::<Vec<_>>()
            .join(" and with "),
        100.0 * LEVEL,
    );
    if intervals.is_empty() {
        s.push_str("Not run yet.\n\n");
    } else {
        s.push_str(
            "| scene | spp | source | variance | k | seeds | estimated MSE | true MSE | estimated / true (mean over seeds) | 95% interval | median over seeds | reference's share |\n\
             |---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for i in intervals {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {:.3e} | {:.3e} | {:.3} | [{:.3}, {:.3}] | {:.3} | {:.2}% |",
                i.scene,
                i.spp,
                i.source,
                i.variance,
                i.k,
                i.seeds,
                i.estimated_mse,
                i.true_mse,
                i.ratio,
                i.ratio_low,
                i.ratio_high,
                i.ratio_median,
                100.0 * i.reference_share
            );
        }
        s.push('\n');
    }
    let _ = write!(
        s,
        "The same ratio on the grid's renders (`mse_estimates.csv`), {}, per bandwidth k in the \
         order NFOR tries them:\n\n| scene | source | variance |",
        if exp.repeats < 2 {
            "one render each".to_string()
        } else {
            format!("the mean over its {} repeats", exp.repeats)
        }
    );
    let all_spps: Vec<u32> = {
        let mut v: Vec<u32> = rows.iter().map(|r| r.spp).collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    for spp in &all_spps {
        let _ = write!(s, " {spp} spp |");
    }
    s.push_str("\n|---|---|---|");
    for _ in &all_spps {
        s.push_str("---:|");
    }
    s.push('\n');
    let mut keys: Vec<(&str, &str, &str)> = Vec::new();
    for m in mse.iter().filter(|m| m.study == "grid") {
        let key = (m.scene.as_str(), m.source.as_str(), m.variance.as_str());
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    for (scene, source, variance) in keys {
        let _ = write!(s, "| {scene} | {source} | {variance} |");
        for &spp in &all_spps {
            let own: Vec<&MseRow> = mse
                .iter()
                .filter(|m| {
                    m.study == "grid"
                        && m.scene == scene
                        && m.source == source
                        && m.variance == variance
                        && m.spp == spp
                })
                .collect();
            let mut ks: Vec<f64> = Vec::new();
            for m in &own {
                if !ks.iter().any(|k| k.to_bits() == m.k.to_bits()) {
                    ks.push(m.k);
                }
            }
            let ratios: Vec<String> = ks
                .iter()
                .filter_map(|k| {
                    let v: Vec<f64> = own
                        .iter()
                        .filter(|m| m.k.to_bits() == k.to_bits())
                        .map(|m| m.ratio)
                        .collect();
                    mean_interval(&v).map(|m| format!("{:.2}", m.mean))
                })
                .collect();
            if ratios.is_empty() {
                s.push_str(" — |");
            } else {
                let _ = write!(s, " {} |", ratios.join(" / "));
            }
        }
        s.push('\n');
    }
    s.push('\n');

    s.push_str("## Scenes, references and time\n\n");
    s.push_str(
        "| scene | size | spp | reference spp | its relMSE floor | reference traced now, s | renders wall s (MSE check's included) | NFOR runs (grid) | NFOR wall s, median per run at the largest spp | s/MP (median over all runs) | stages: prefilter / regression / selection / second pass (s, summed) | NFOR peak RSS, MB (max) |\n\
         |---|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|\n",
    );
    for info in infos {
        let own: Vec<&DenoiseRow> = rows
            .iter()
            .filter(|r| r.scene == info.scene && r.stage == DENOISED)
            .collect();
        let last = own.iter().map(|r| r.spp).max().unwrap_or(0);
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            match v.len() {
                0 => None,
                n if n % 2 == 1 => Some(v[n / 2]),
                n => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
            }
        };
        let at_last = median(
            own.iter()
                .filter(|r| r.spp == last)
                .filter_map(|r| r.nfor_s)
                .collect(),
        );
        let per_mp = median(own.iter().filter_map(|r| r.nfor_s_per_megapixel).collect());
        let sum = |f: &dyn Fn(&DenoiseRow) -> Option<f64>| -> f64 {
            own.iter().filter_map(|r| f(r)).sum()
        };
        let peak = own.iter().filter_map(|r| r.nfor_peak_rss_bytes).max();
        let _ = writeln!(
            s,
            "| {} | {}x{}{} | {} | {} | {} | {:.0} | {:.1} | {} | {} | {} | {:.1} / {:.1} / {:.1} / {:.1} | {} |",
            info.scene,
            info.width,
            info.height,
            if info.rfilter_box_override {
                " (box)"
            } else {
                ""
            },
            info.spps.replace(';', ", "),
            info.reference_spp,
            opt(info.reference_expected_relmse, |v| format!("{v:.2e}")),
            info.reference_wall_s,
            info.render_wall_s,
            own.len(),
            opt(at_last, |v| format!("{v:.2}")),
            opt(per_mp, |v| format!("{v:.1}")),
            sum(&|r| r.prefilter_s),
            sum(&|r| r.regression_s),
            sum(&|r| r.selection_s),
            sum(&|r| r.second_pass_s),
            opt(peak.map(|b| b as f64 / 1e6), |v| format!("{v:.0}")),
        );
    }
    let reset = rows.iter().filter_map(|r| r.nfor_peak_rss_reset).all(|b| b);
    let _ = writeln!(
        s,
        "\nA reference's relMSE floor is about what its own noise adds to any relMSE against it. \
         NFOR time is wall time on {} threads, on the image sizes above. Peak RSS is the \
         process's resident high-water mark during NFOR ({}), so it holds the render's buffers \
         and the reference as well.\n",
        run.threads,
        if reset {
            "reset before every NFOR run"
        } else {
            "the process's peak so far: this system would not reset it"
        }
    );
    let _ = write!(
        s,
        "## Figures\n\n\
         - `relmse_vs_spp.png`, `ssim_vs_spp.png`: per scene against spp; one colour per \
         source, dashed its noisy estimate, solid NFOR's output{}.\n\
         - `montage.png`: per scene, the crop where NFOR of the mean is worst (the largest sum of \
         relMSE's per-pixel terms), for the reference, every noisy estimate and every NFOR \
         output, from the first repeat \
         (seed {}).\n",
        if exp.repeats < 2 {
            String::new()
        } else {
            format!(
                "; each line is the mean over the {} repeats and its shaded band (an error bar \
                 where a series has one point) the 95% Student-t interval of that mean, cut at \
                 SSIM's range [−1, 1]; on the log relMSE axis a band whose lower end is at or \
                 below zero runs down to the panel's floor",
                exp.repeats
            )
        },
        exp.repeat_seed(0),
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(seed: u64, k: f64, est: f64, truth: f64) -> MseRow {
        MseRow {
            study: "seeds".into(),
            scene: "s".into(),
            spp: 16,
            source: "mean".into(),
            variance: "sample".into(),
            seed,
            k,
            estimated_mse: est,
            true_mse: truth,
            ratio: est / truth,
            reference_variance: 0.01,
        }
    }

    #[test]
    fn mse_intervals_are_student_t_over_seeds() {
        // Ratios 0.9, 1.0, 1.1 for k = 1: mean 1, sd 0.1, se 0.1/sqrt(3); t(0.975, 2) =
        // 4.302652729749464.
        let mut rows = vec![
            row(1, 1.0, 0.9, 1.0),
            row(2, 1.0, 1.0, 1.0),
            row(3, 1.0, 1.1, 1.0),
            row(1, 0.5, 2.0, 1.0),
        ];
        rows.push(MseRow {
            study: "grid".into(),
            ..row(9, 1.0, 5.0, 1.0)
        });
        let got = mse_intervals(&rows);
        // k = 0.5 has one seed: no interval.
        assert_eq!(got.len(), 1);
        let i = &got[0];
        assert_eq!(i.seeds, 3);
        assert!((i.ratio - 1.0).abs() < 1e-12);
        let se = 0.1 / 3f64.sqrt();
        assert!((i.ratio_se - se).abs() < 1e-12);
        let half = 4.302652729749464 * se;
        assert!((i.ratio_high - (1.0 + half)).abs() < 1e-9, "{i:?}");
        assert!((i.ratio_low - (1.0 - half)).abs() < 1e-9);
        assert!((i.reference_share - 0.01).abs() < 1e-12);
        assert!((i.ratio_median - 1.0).abs() < 1e-12);
    }
}
