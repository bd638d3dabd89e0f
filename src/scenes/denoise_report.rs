//! The denoising experiment's report: `denoise.csv` (one row per scene, spp, source, variance
//! and stage), `mse_estimates.csv` (NFOR's MSE estimate against the truth), `scenes.csv`,
//! `summary.md`, `manifest.json`, and the figures `relmse_vs_spp.png`, `ssim_vs_spp.png` and
//! `montage.png`. Every file is written atomically; the reference cache beside them is left
//! alone.

use super::denoise_experiment::{DenoiseExperiment, variance_name};
use super::denoise_run::{DENOISED, DenoiseRow, DenoiseSceneInfo, DenoiseSceneResult, MseRow};
use super::report::{RunInfo, summary_head};
use super::tables::to_csv;
use crate::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::harness::metrics::LEVEL;
use serde::Serialize;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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
            let ratio = mean(&|r| r.ratio);
            let var = own.iter().map(|r| (r.ratio - ratio).powi(2)).sum::<f64>() / (nf - 1.0);
            let se = (var / nf).sqrt();
            let t = StudentsT::new(0.0, 1.0, nf - 1.0)
                .map(|d| d.inverse_cdf(0.5 + LEVEL / 2.0))
                .unwrap_or(f64::NAN);
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
                ratio_low: ratio - t * se,
                ratio_high: ratio + t * se,
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
    let mse: Vec<MseRow> = results.iter().flat_map(|r| r.mse.clone()).collect();
    let infos: Vec<DenoiseSceneInfo> = results.iter().map(|r| r.info.clone()).collect();
    let intervals = mse_intervals(&mse);
    let mut written = Vec::new();
    let mut put = |name: &str, bytes: &[u8]| -> Result<()> {
        let path = dir.join(name);
        write_atomic(&path, bytes)?;
        written.push(path);
        Ok(())
    };
    put("denoise.csv", &to_csv(&rows)?)?;
    put("mse_estimates.csv", &to_csv(&mse)?)?;
    put("mse_check.csv", &to_csv(&intervals)?)?;
    put("scenes.csv", &to_csv(&infos)?)?;
    put(
        "summary.md",
        summary_md(exp, run, &infos, &rows, &mse, &intervals).as_bytes(),
    )?;
    let manifest = serde_json::json!({
        "experiment": exp.source,
        "quick": exp.quick,
        "seed": exp.file.seed,
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
    put(
        "manifest.json",
        (serde_json::to_string_pretty(&manifest).unwrap_or_default() + "\n").as_bytes(),
    )?;
    if !rows.is_empty() {
        written.extend(super::denoise_plots::write_plots(dir, exp, &rows, results)?);
    }
    Ok(written)
}

fn opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map_or_else(|| "—".to_string(), f)
}

fn find<'a>(
    rows: &'a [DenoiseRow],
    scene: &str,
    spp: u32,
    source: &str,
    variance: &str,
) -> Option<&'a DenoiseRow> {
    rows.iter()
        .find(|r| r.scene == scene && r.spp == spp && r.source == source && r.variance == variance)
}

/// Distinct spp of a scene's rows, ascending.
fn scene_spps(rows: &[DenoiseRow], scene: &str) -> Vec<u32> {
    let mut v: Vec<u32> = rows
        .iter()
        .filter(|r| r.scene == scene)
        .map(|r| r.spp)
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

fn summary_md(
    exp: &DenoiseExperiment,
    run: &RunInfo,
    infos: &[DenoiseSceneInfo],
    rows: &[DenoiseRow],
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
        "`{}` — {:.0} s wall on {} threads; commit {}. Per scene and sample count, one render \
         with NFOR's half buffers runs every source's estimator on the whole stream and on each \
         half (even and odd samples); NFOR (Bitterli et al. 2016, the paper's parameters) \
         denoises each source's halves with each variance. Every image is judged against the \
         scene's converged reference (the mean of its own samples, another seed). Firefly \
         pixels: luminance above {} × the reference's + {}. Files: `denoise.csv` (one row per \
         scene, spp, source, variance and stage; the noisy rows have no variance), \
         `mse_estimates.csv`, `mse_check.csv`, `scenes.csv`, `manifest.json` and the figures at \
         the end.\n",
        run.command,
        run.wall_s,
        run.threads,
        crate::report::tables::git_commit().unwrap_or_else(|| "unknown".into()),
        exp.rule.factor(),
        exp.rule.floor(),
    );

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
         source's noisy estimate. The best cell of a row is bold.\n\n| scene | spp |",
    );
    for (_, _, title) in &columns {
        let _ = write!(s, " {title} |");
    }
    s.push_str("\n|---|---:|");
    for _ in &columns {
        s.push_str("---:|");
    }
    s.push('\n');
    for info in infos {
        for spp in scene_spps(rows, &info.scene) {
            let cells: Vec<Option<&DenoiseRow>> = columns
                .iter()
                .map(|(src, var, _)| find(rows, &info.scene, spp, src, var))
                .collect();
            let best = cells
                .iter()
                .flatten()
                .map(|r| r.relmse)
                .fold(f64::INFINITY, f64::min);
            let _ = write!(s, "| {} | {spp} |", info.scene);
            for (c, (src, var, _)) in cells.iter().zip(&columns) {
                match c {
                    Some(r) => {
                        let mut cell = format!("{:.3e}", r.relmse);
                        if r.relmse == best {
                            cell = format!("**{cell}**");
                        }
                        if !var.is_empty()
                            && let Some(n) = find(rows, &info.scene, spp, src, "")
                        {
                            let _ = write!(cell, " ({:.1}×)", n.relmse / r.relmse);
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

    s.push_str("## Per scene: every metric\n\n");
    s.push_str(
        "relMSE as above; SSIM of the display luma (higher is better); firefly pixels by the \
         rule above; relative bias = image-mean luminance over the reference's, minus 1; NFOR \
         wall seconds and seconds per megapixel.\n\n",
    );
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
            "| spp | source | variance | stage | relMSE | SSIM | firefly px | rel. bias | NFOR s | NFOR s/MP |\n\
             |---:|---|---|---|---:|---:|---:|---:|---:|---:|\n",
        );
        for r in rows.iter().filter(|r| r.scene == info.scene) {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {:.3e} | {:.4} | {} | {} | {} | {} |",
                r.spp,
                r.label,
                if r.variance.is_empty() {
                    "—"
                } else {
                    &r.variance
                },
                r.stage,
                r.relmse,
                r.ssim,
                r.firefly_pixels,
                opt(r.mean_bias_relative, |v| format!("{:+.2}%", 100.0 * v)),
                opt(r.nfor_s, |v| format!("{v:.2}")),
                opt(r.nfor_s_per_megapixel, |v| format!("{v:.1}")),
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
    s.push_str(
        "The same ratio on every render of the grid (one seed each; `mse_estimates.csv`), per \
         bandwidth k in the order NFOR tries them:\n\n| scene | source | variance |",
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
            let ratios: Vec<String> = mse
                .iter()
                .filter(|m| {
                    m.study == "grid"
                        && m.scene == scene
                        && m.source == source
                        && m.variance == variance
                        && m.spp == spp
                })
                .map(|m| format!("{:.2}", m.ratio))
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
    s.push_str(
        "## Figures\n\n\
         - `relmse_vs_spp.png`, `ssim_vs_spp.png`: per scene against spp; one colour per \
         source, dashed its noisy estimate, solid NFOR's output.\n\
         - `montage.png`: per scene, the crop holding the most firefly pixels of the noisy mean, \
         for the reference, every noisy estimate and every NFOR output.\n",
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
