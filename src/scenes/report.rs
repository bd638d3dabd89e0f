//! Writes the scene experiment's report: the CSVs, `summary.md`, `manifest.json` and the
//! figures. Each file is written atomically; the reference cache beside them is left alone.

use super::experiment::ScenesExperiment;
use super::run::SceneResult;
use super::tables::{
    self, CostRow, DelayedRow, MetricRow, RankRow, SceneInfo, Table2Row, ZirrPoint, to_csv,
};
use crate::atomic::ReportFiles;
use crate::error::{Error, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// How the run went, for the summary and the manifest.
#[derive(Debug, Clone)]
pub struct RunInfo {
    /// The command line, as run.
    pub command: String,
    /// Wall seconds of the whole experiment.
    pub wall_s: f64,
    /// Worker threads.
    pub threads: usize,
    /// Scenes of the experiment not run yet (a report is rewritten after every scene).
    pub pending: Vec<String>,
}

/// The opening of a summary: its title (marked when the run is quick), which scenes are still
/// pending, and the experiment's description.
pub(crate) fn summary_head(
    s: &mut String,
    title: &str,
    quick: bool,
    pending: &[String],
    description: &str,
) {
    let quick = if quick {
        " — QUICK RUN (scaled down by `--quick`; not the experiment's numbers)"
    } else {
        ""
    };
    let _ = writeln!(s, "# {title}{quick}\n");
    if !pending.is_empty() {
        let _ = writeln!(
            s,
            "**Partial report**: the run has not done {} yet.\n",
            pending.join(", ")
        );
    }
    if !description.is_empty() {
        let _ = writeln!(s, "{}\n", description.trim());
    }
}

/// Writes every table and figure of `results` into `dir`; returns the paths written.
///
/// # Errors
///
/// A file that cannot be written.
pub fn write_report(
    dir: &Path,
    exp: &ScenesExperiment,
    results: &[SceneResult],
    run: &RunInfo,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir.display(), &e))?;
    let rows: Vec<MetricRow> = results.iter().flat_map(|r| r.rows.clone()).collect();
    let costs: Vec<CostRow> = results.iter().flat_map(|r| r.costs.clone()).collect();
    let delayed: Vec<DelayedRow> = results.iter().flat_map(|r| r.delayed.clone()).collect();
    let infos: Vec<SceneInfo> = results.iter().map(|r| r.info.clone()).collect();
    let t1 = tables::table1(&rows);
    let thresholds = &exp.file.ssim_thresholds;
    let t2 = tables::table2(&rows, thresholds);
    let zirr = tables::zirr_points(&rows);
    let ranking = tables::ranking(&rows);

    let mut files = ReportFiles::new(dir);
    files.put("metrics.csv", &to_csv(&rows)?)?;
    files.put("costs.csv", &to_csv(&costs)?)?;
    files.put("delayed.csv", &to_csv(&delayed)?)?;
    files.put("scenes.csv", &to_csv(&infos)?)?;
    files.put("table1.csv", &to_csv(&t1)?)?;
    files.put("table2.csv", &tables::table2_csv(&t2, thresholds)?)?;
    files.put("zirr_kappa.csv", &to_csv(&zirr)?)?;
    files.put("ranking.csv", &to_csv(&ranking)?)?;
    let summary = summary_md(
        exp, run, &infos, &rows, &costs, &delayed, &t2, &zirr, &ranking,
    );
    files.put("summary.md", summary.as_bytes())?;
    let manifest = serde_json::json!({
        "experiment": exp.source,
        "quick": exp.quick,
        "seed": exp.file.seed,
        "threads": run.threads,
        "command": run.command,
        "wall_s": run.wall_s,
        "pending_scenes": run.pending,
        "scenes": infos.iter().map(|i| serde_json::json!({
            "scene": i.scene,
            "reference_wall_s": i.reference_wall_s,
            "reference_total_wall_s": i.reference_total_wall_s,
            "render_wall_s": i.render_wall_s,
            "analysis_wall_s": i.analysis_wall_s,
        })).collect::<Vec<_>>(),
        "peak_rss_bytes": crate::limits::peak_rss_bytes(),
        "crate_version": env!("CARGO_PKG_VERSION"),
        "git_commit": crate::report::tables::git_commit(),
    });
    files.put(
        "manifest.json",
        serde_json::to_string_pretty(&manifest)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    let plotted: Vec<String> = exp
        .plot
        .iter()
        .map(|&i| exp.estimators[i].to_string())
        .collect();
    files.extend(super::plots::write_plots(
        dir, &rows, &plotted, &zirr, results, exp.quick,
    )?);
    Ok(files.into_paths())
}

fn opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map_or_else(|| "—".to_string(), f)
}

/// Scenes in order.
fn scene_names(infos: &[SceneInfo]) -> Vec<&str> {
    infos.iter().map(|i| i.scene.as_str()).collect()
}

/// Estimators in order of first appearance, with labels.
fn estimator_order(rows: &[MetricRow]) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = Vec::new();
    for r in rows {
        if !out.iter().any(|(e, _)| *e == r.estimator) {
            out.push((r.estimator.clone(), r.label.clone()));
        }
    }
    out
}

#[allow(clippy::too_many_arguments)]
fn summary_md(
    exp: &ScenesExperiment,
    run: &RunInfo,
    infos: &[SceneInfo],
    rows: &[MetricRow],
    costs: &[CostRow],
    delayed: &[DelayedRow],
    t2: &[Table2Row],
    zirr: &[ZirrPoint],
    ranking: &[RankRow],
) -> String {
    let mut s = String::new();
    let scenes = scene_names(infos);
    let ests = estimator_order(rows);
    summary_head(
        &mut s,
        "Scene experiment",
        exp.quick,
        &run.pending,
        &exp.file.description,
    );
    let traced_now: f64 = infos.iter().map(|i| i.reference_wall_s).sum();
    let traced_ever: Option<f64> = infos.iter().map(|i| i.reference_total_wall_s).sum();
    let from_scratch = match traced_ever {
        Some(t) => format!(
            "; the references took {t:.0} s to trace (in this and earlier runs, as their JSON \
             records), so from scratch the run takes about {:.0} s",
            run.wall_s - traced_now + t
        ),
        None => String::new(),
    };
    let _ = writeln!(
        s,
        "`{}` — {:.0} s wall on {} threads{from_scratch}; commit {}. Every estimator runs in one render per \
         scene and is read at every checkpoint; images are judged against the scene's \
         reference (the mean of its own samples, another seed). Files: `metrics.csv` (one row \
         per scene, estimator and checkpoint), `costs.csv`, `delayed.csv`, `scenes.csv`, \
         `table1.csv`, `table2.csv`, `zirr_kappa.csv`, `ranking.csv`, and the figures listed \
         at the end.\n",
        run.command,
        run.wall_s,
        run.threads,
        crate::report::tables::git_commit().unwrap_or_else(|| "unknown".into())
    );

    s.push_str("## Scenes, references and render time\n\n");
    s.push_str(
        "| scene | size | spp | reference spp | its trace wall s | reference rel. SE per pixel (RMS) | of the image mean | \
         its relMSE floor | render wall s | render CPU s | trace ns/sample | bank ns/sample (model) | \
         render ns/sample (measured) | mean-alone render ns/sample (measured) |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for i in infos {
        let _ = writeln!(
            s,
            "| {} | {}x{}{} | {} | {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.0} | {:.0} | {:.0} | {} |",
            i.scene,
            i.width,
            i.height,
            if i.rfilter_box_override { " (box)" } else { "" },
            i.spp,
            i.reference_spp,
            opt(i.reference_total_wall_s, |v| format!("{v:.0}")),
            opt(i.reference_pixel_relative_se, |v| format!(
                "{:.2}%",
                100.0 * v
            )),
            opt(i.reference_image_mean_relative_se, |v| format!(
                "{:.3}%",
                100.0 * v
            )),
            opt(i.reference_expected_relmse, |v| format!("{v:.2e}")),
            i.render_wall_s,
            i.render_cpu_s,
            i.trace_ns_per_sample,
            i.modelled_ns_per_sample,
            i.measured_ns_per_sample,
            match (i.mean_render_ns_per_sample, i.mean_render_spp) {
                (Some(ns), Some(spp)) => format!(
                    "{ns:.0} ({spp} spp; bank {:.0}% of the full render)",
                    100.0 * (1.0 - ns / i.measured_ns_per_sample)
                ),
                _ => "—".into(),
            },
        );
    }
    s.push_str(
        "\nA reference's relMSE floor (`expected_relmse`) is about what its own noise adds to \
         any image's relMSE against it. Trace and bank costs per sample are CPU time on one \
         thread from the cost measurement (`costs.csv`); the measured column is the render's \
         CPU time over its samples, estimate reads excluded (all threads' CPU time, so it \
         also holds the thread pool's waiting); the last column is the same for a render with \
         the mean alone, and `1 − mean alone / full` is the whole bank's share of the full \
         render as measured inside renders.\n\n",
    );

    s.push_str("## Estimator cost as a fraction of render time\n\n");
    s.push_str(
        "Share of a render's CPU time taken by the estimator, `push / (trace + push)` for a \
         render with it alone (CPU ns per sample in brackets); the last row is the whole bank \
         `Σ push / (trace + Σ push)`.\n\n| estimator |",
    );
    scene_columns(&mut s, &scenes, "---:|");
    for (e, label) in &ests {
        let _ = write!(s, "| {label} |");
        for sc in &scenes {
            match costs.iter().find(|c| c.scene == *sc && c.estimator == *e) {
                Some(c) => {
                    let _ = write!(
                        s,
                        " {:.1}% ({:.0}) |",
                        100.0 * c.fraction_alone,
                        c.push_ns_per_sample
                    );
                }
                None => s.push_str(" — |"),
            }
        }
        s.push('\n');
    }
    s.push_str("| **all together** |");
    for sc in &scenes {
        let own: Vec<&CostRow> = costs.iter().filter(|c| c.scene == *sc).collect();
        let push: f64 = own.iter().map(|c| c.push_ns_per_sample).sum();
        let trace = own.first().map_or(0.0, |c| c.trace_ns_per_sample);
        let _ = write!(
            s,
            " {:.1}% ({:.0} of {:.0}) |",
            100.0 * push / (trace + push).max(f64::MIN_POSITIVE),
            push,
            trace + push
        );
    }
    s.push_str("\n\n");

    s.push_str(
        "## Buisine et al., Table 1: SSIM at the largest spp, ranked per scene for each M\n\n",
    );
    s.push_str(&tables::table1_md(&tables::table1(rows)));
    s.push('\n');

    let th = &exp.file.ssim_thresholds;
    let _ = writeln!(
        s,
        "## Buisine et al., Table 2: spp needed to reach SSIM {}\n",
        th.iter()
            .map(|t| t.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(
        s,
        "Each cell: the first power-of-two checkpoint at which SSIM reaches {} (\"NR\": not \
         reached by the scene's spp).\n",
        th.iter()
            .map(|t| t.to_string())
            .collect::<Vec<_>>()
            .join(" / ")
    );
    s.push_str("| estimator |");
    scene_columns(&mut s, &scenes, "---:|");
    for (e, label) in &ests {
        let _ = write!(s, "| {label} |");
        for sc in &scenes {
            match t2.iter().find(|r| r.scene == *sc && r.estimator == *e) {
                Some(r) => {
                    let cells: Vec<String> =
                        r.reached.iter().map(|v| tables::reach_text(*v)).collect();
                    let _ = write!(s, " {} |", cells.join(" / "));
                }
                None => s.push_str(" — |"),
            }
        }
        s.push('\n');
    }
    s.push('\n');

    s.push_str("## Zirr et al., Figure 6: RMSE against κ (`zirr_kappa.png`)\n\n");
    if zirr.is_empty() {
        s.push_str("No `zirr` estimator in the experiment.\n\n");
    } else {
        let mut kappas: Vec<f64> = zirr.iter().map(|p| p.kappa).collect();
        kappas.sort_by(f64::total_cmp);
        kappas.dedup();
        s.push_str("| scene | spp | b | mean |");
        for k in &kappas {
            let _ = write!(s, " κ = {k} |");
        }
        s.push_str("\n|---|---:|---:|---:|");
        for _ in &kappas {
            s.push_str("---:|");
        }
        s.push('\n');
        let mut keys: Vec<(&str, f64)> = Vec::new();
        for p in zirr {
            if !keys.contains(&(p.scene.as_str(), p.b)) {
                keys.push((&p.scene, p.b));
            }
        }
        for (sc, b) in keys {
            let own: Vec<&ZirrPoint> = zirr.iter().filter(|p| p.scene == sc && p.b == b).collect();
            let first = own[0];
            let _ = write!(
                s,
                "| {sc} | {} | {b} | {} |",
                first.spp,
                opt(first.mean_rmse, |v| format!("{v:.4e}"))
            );
            for k in &kappas {
                match own.iter().find(|p| p.kappa == *k) {
                    Some(p) => {
                        let _ = write!(s, " {:.4e} |", p.rmse);
                    }
                    None => s.push_str(" — |"),
                }
            }
            s.push('\n');
        }
        s.push_str("\nRMSE over pixels and channels, linear radiance.\n\n");
    }

    let _ = writeln!(
        s,
        "## Pajot et al., Table 4: fraction of samples delayed at {} spp\n",
        exp.file.delayed_spp
    );
    if delayed.is_empty() {
        s.push_str("No delayed estimators in the experiment.\n\n");
    } else {
        s.push_str(
            "Samples still delayed (not accepted) after the last sample, summed over every \
             pixel, over the valid samples traced (the render's own streams; Pajot et al. \
             report 1.4% for ADR+ROT on their living room). relMSE at that spp next to the \
             mean's, where the render read it.\n\n| scene | estimator | samples | delayed | \
             pixels with a delayed sample | relMSE | mean's relMSE |\n\
             |---|---|---:|---:|---:|---:|---:|\n",
        );
        for d in delayed {
            let at = |e: &str| tables::find(rows, &d.scene, e, d.spp).map(|r| r.relmse);
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.3}% | {:.1}% | {} | {} |",
                d.scene,
                d.label,
                d.samples,
                100.0 * d.fraction,
                100.0 * d.pixels_with_delayed,
                opt(at(&d.estimator), |v| format!("{v:.3e}")),
                opt(at("mean"), |v| format!("{v:.3e}")),
            );
        }
        s.push('\n');
    }

    s.push_str("## Every estimator at the largest spp: SSIM and relMSE, ranked per scene\n\n");
    s.push_str("Each cell: SSIM (rank) · relMSE (rank) · relative mean bias.\n\n| estimator |");
    scene_columns(&mut s, &scenes, "---|");
    for (e, label) in &ests {
        let _ = write!(s, "| {label} |");
        for sc in &scenes {
            match ranking.iter().find(|r| r.scene == *sc && r.estimator == *e) {
                Some(r) => {
                    let _ = write!(
                        s,
                        " {:.4} ({}) · {:.2e} ({}) · {} |",
                        r.ssim,
                        r.ssim_rank,
                        r.relmse,
                        r.relmse_rank,
                        opt(r.mean_bias_relative, |v| format!("{:+.2}%", 100.0 * v))
                    );
                }
                None => s.push_str(" — |"),
            }
        }
        s.push('\n');
    }
    s.push_str(
        "\n## Figures\n\n\
         - `ssim_vs_spp.png`, `relmse_vs_spp.png`: convergence per scene (log spp).\n\
         - `speed_vs_error.png`: CPU time of a render with the estimator alone against relMSE.\n\
         - `zirr_kappa.png`: Zirr et al.'s Figure 6.\n\
         - `bias_<scene>.png`: signed luminance difference from the reference at the largest spp.\n\
         - `crops.png`: the firefly crops side by side.\n",
    );
    s
}

/// The rest of a table's header: one column per scene, then the separator row with `align`
/// (`---|` or `---:|`) under each.
fn scene_columns(s: &mut String, scenes: &[&str], align: &str) {
    for sc in scenes {
        let _ = write!(s, " {sc} |");
    }
    s.push_str("\n|---|");
    for _ in scenes {
        s.push_str(align);
    }
    s.push('\n');
}
