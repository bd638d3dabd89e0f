//! The experiment's data and the seeds' tables built from it: one [`MetricRow`] per scene,
//! estimator and checkpoint (`metrics.csv`), the estimators' costs (`costs.csv`), Pajot's
//! delayed fractions (`delayed.csv`), one [`SceneInfo`] per scene (`scenes.csv`), and the
//! tables of Buisine et al. (Table 1, Table 2), Zirr et al. (Figure 6) and Pajot et al.
//! (Table 4), as CSV and as Markdown in `summary.md`.
//!
//! Every table is a function of the rows alone (estimators are recognised by parsing their
//! spec strings), so a table can be rebuilt from `metrics.csv` and tested on hand-made rows.

use crate::error::{Error, Result};
use crate::estimators::{
    CascadeSize, ClampSpec, EstimatorSpec, GiniSpec, GmonBSpec, GmonSpec, JungSpec, MeanSpec,
    MonSpec, PajotAdrSpec, PajotHybridSpec, PajotRotSpec, ZirrRefSpec, ZirrSpec,
};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// The metrics of one estimator's image at one checkpoint of one scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricRow {
    /// Scene name.
    pub scene: String,
    /// Canonical spec string.
    pub estimator: String,
    /// Short name for tables and legends ([`label`]).
    pub label: String,
    /// Samples per pixel behind the image.
    pub spp: u32,
    /// Root mean squared error, linear RGB.
    pub rmse: f64,
    /// Relative MSE (ε = 0.01), linear RGB.
    pub relmse: f64,
    /// PSNR of the display images, dB.
    pub psnr_db: f64,
    /// SSIM of the display luma.
    pub ssim: f64,
    /// Mean luminance minus the reference's.
    pub mean_bias: f64,
    /// `mean_bias` over the reference's mean luminance (empty for a black reference).
    pub mean_bias_relative: Option<f64>,
    /// Firefly pixels (see the experiment's rule).
    pub firefly_pixels: u64,
    /// Their fraction of the image.
    pub firefly_fraction: f64,
    /// CPU seconds of a render with this estimator alone up to `spp`: tracing plus its pushes
    /// plus one read of every pixel ([`super::cost`]; a model from measured per-sample costs).
    pub render_cpu_s: f64,
    /// The estimator's share of `render_cpu_s`.
    pub estimator_cpu_s: f64,
}

/// One estimator's cost on one scene (see [`super::cost`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CostRow {
    /// Scene name.
    pub scene: String,
    /// Canonical spec string.
    pub estimator: String,
    /// Short name.
    pub label: String,
    /// CPU ns per RGB sample pushed.
    pub push_ns_per_sample: f64,
    /// CPU ns per pixel for one read of the estimate.
    pub read_ns_per_pixel: f64,
    /// CPU ns per camera sample traced.
    pub trace_ns_per_sample: f64,
    /// `push / (trace + push)`: its share of a render with it alone.
    pub fraction_alone: f64,
    /// `push / (trace + Σ push)`: its share of a render with the whole bank.
    pub fraction_of_bank: f64,
    /// Mean per-pixel state at the end of the render, bytes.
    pub state_bytes_per_pixel: f64,
}

/// Pajot et al.'s Table 4 on one scene: samples an estimator still delays after `spp`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DelayedRow {
    /// Scene name.
    pub scene: String,
    /// Canonical spec string.
    pub estimator: String,
    /// Short name.
    pub label: String,
    /// Samples per pixel traced.
    pub spp: u32,
    /// Pixels.
    pub pixels: u64,
    /// Valid samples pushed (NaN, infinite and negative ones are left out as the film does).
    pub samples: u64,
    /// Samples delayed (not accepted) after the last one, summed over pixels.
    pub delayed: u64,
    /// `delayed / samples`.
    pub fraction: f64,
    /// Fraction of pixels with at least one delayed sample.
    pub pixels_with_delayed: f64,
}

/// What one scene's run was: size, budget, reference, timings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneInfo {
    /// Scene name.
    pub scene: String,
    /// Scene file.
    pub file: String,
    /// Rendered size.
    pub width: u32,
    /// Rendered size.
    pub height: u32,
    /// Render spp.
    pub spp: u32,
    /// Checkpoints, `;`-separated.
    pub checkpoints: String,
    /// Whether the film's filter was replaced by a box.
    pub rfilter_box_override: bool,
    /// Reference spp (all its samples, also those of earlier runs).
    pub reference_spp: u64,
    /// RMS over pixels of the reference's relative standard error of luminance.
    pub reference_pixel_relative_se: Option<f64>,
    /// Relative standard error of the reference's mean luminance.
    pub reference_image_mean_relative_se: Option<f64>,
    /// About what the reference's own noise adds to a test image's relMSE.
    pub reference_expected_relmse: Option<f64>,
    /// Wall seconds spent tracing the reference in this run (0 when the cache had enough).
    pub reference_wall_s: f64,
    /// Wall seconds spent tracing the reference in every run that traced it (as its JSON
    /// records; empty when it does not say).
    pub reference_total_wall_s: Option<f64>,
    /// Worker threads.
    pub threads: usize,
    /// Wall seconds of the render with every estimator.
    pub render_wall_s: f64,
    /// CPU seconds of that render, all threads.
    pub render_cpu_s: f64,
    /// Wall seconds of it spent reading estimates into images.
    pub render_estimate_wall_s: f64,
    /// Camera samples of the render.
    pub samples: u64,
    /// NaN, infinite or negative samples left out.
    pub invalid_samples: u64,
    /// The render's CPU ns per sample (tracing and every push; reads excluded).
    pub measured_ns_per_sample: f64,
    /// CPU ns per sample of a render with the mean alone (estimate reads excluded), if made.
    pub mean_render_ns_per_sample: Option<f64>,
    /// Spp of that render.
    pub mean_render_spp: Option<u32>,
    /// Tracing alone, ns per sample (from the cost measurement).
    pub trace_ns_per_sample: f64,
    /// Tracing plus every estimator's push, ns per sample (from the cost measurement).
    pub modelled_ns_per_sample: f64,
    /// Wall seconds of the metrics, cost measurement and Pajot pass.
    pub analysis_wall_s: f64,
    /// Firefly crop `[x, y, size]` and its spp.
    pub crop: String,
}

/// A short name for tables and legends: `MoN M=21`, `G-MoN_b M=21`, `Zirr b=8 κ=1`,
/// `Pajot ADR+ROT`. Parameters at their defaults are left out. A method without a name of its
/// own here (the mean, and any method added later) is shown by its canonical spec string, so
/// adding a method needs no change in this file.
pub fn label(spec: &EstimatorSpec) -> String {
    let fmt = |v: f64| {
        if v == v.round() && v.abs() < 1e15 {
            format!("{}", v as i64)
        } else {
            format!("{v}")
        }
    };
    let zirr = |name: &str, p: &crate::estimators::ZirrParams, default_j: CascadeSize| {
        let mut s = format!("{name} b={} κ={}", fmt(p.b), fmt(p.kappa));
        if p.j != default_j {
            match p.j {
                CascadeSize::Auto => s.push_str(" J=auto"),
                CascadeSize::Fixed(j) => {
                    let _ = write!(s, " J={j}");
                }
            }
        }
        if p.kappa_min != 1.0 {
            let _ = write!(s, " κmin={}", fmt(p.kappa_min));
        }
        if p.u != 1.0 {
            let _ = write!(s, " u={}", fmt(p.u));
        }
        s
    };
    match spec {
        EstimatorSpec::Clamp(ClampSpec { c }) => format!("clamp c={}", fmt(*c)),
        EstimatorSpec::Mon(MonSpec { m }) => format!("MoN M={m}"),
        EstimatorSpec::Gini(GiniSpec { m }) => format!("Gini M={m}"),
        EstimatorSpec::GmonB(GmonBSpec { m, threshold }) => {
            if *threshold == 0.25 {
                format!("G-MoN_b M={m}")
            } else {
                format!("G-MoN_b M={m} t={}", fmt(*threshold))
            }
        }
        EstimatorSpec::Gmon(GmonSpec { m }) => format!("G-MoN M={m}"),
        EstimatorSpec::Jung(JungSpec { m_max, .. }) => format!("Jung m_max={m_max}"),
        EstimatorSpec::Zirr(ZirrSpec(p)) => zirr("Zirr", p, CascadeSize::Auto),
        EstimatorSpec::ZirrRef(ZirrRefSpec(p)) => zirr("zirr-ref", p, CascadeSize::Fixed(6)),
        EstimatorSpec::PajotRot(PajotRotSpec { learn }) => pajot("Pajot ROT", *learn),
        EstimatorSpec::PajotAdr(PajotAdrSpec { learn }) => pajot("Pajot ADR", *learn),
        EstimatorSpec::PajotHybrid(PajotHybridSpec { learn, .. }) => pajot("Pajot ADR+ROT", *learn),
        other => other.to_string(),
    }
}

fn pajot(name: &str, learn: usize) -> String {
    if learn == 50 {
        name.into()
    } else {
        format!("{name} learn={learn}")
    }
}

/// Serialises rows as CSV with a header.
///
/// # Errors
///
/// A row that does not serialise (not expected for these types).
pub fn to_csv<T: Serialize>(rows: &[T]) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.serialize(r).map_err(|e| Error::Io {
            path: "<csv>".into(),
            message: e.to_string(),
        })?;
    }
    w.into_inner().map_err(|e| Error::Io {
        path: "<csv>".into(),
        message: e.to_string(),
    })
}

/// Reads `metrics.csv` back (`source` names it in errors).
///
/// # Errors
///
/// A malformed file, naming it and the record.
pub fn read_metrics_csv(text: &str, source: &str) -> Result<Vec<MetricRow>> {
    let mut r = csv::Reader::from_reader(text.as_bytes());
    r.deserialize()
        .map(|row| {
            row.map_err(|e| Error::Io {
                path: source.into(),
                message: e.to_string(),
            })
        })
        .collect()
}

/// Scenes in order of first appearance.
fn scenes_of(rows: &[MetricRow]) -> Vec<&str> {
    let mut out: Vec<&str> = Vec::new();
    for r in rows {
        if !out.contains(&r.scene.as_str()) {
            out.push(&r.scene);
        }
    }
    out
}

/// Estimators of a scene in order of first appearance.
fn estimators_of<'a>(rows: &'a [MetricRow], scene: &str) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for r in rows.iter().filter(|r| r.scene == scene) {
        if !out.contains(&r.estimator.as_str()) {
            out.push(&r.estimator);
        }
    }
    out
}

/// The largest spp of a scene's rows.
pub fn largest_spp(rows: &[MetricRow], scene: &str) -> Option<u32> {
    rows.iter()
        .filter(|r| r.scene == scene)
        .map(|r| r.spp)
        .max()
}

/// The row of `estimator` at `spp` on `scene`.
pub fn find<'a>(
    rows: &'a [MetricRow],
    scene: &str,
    estimator: &str,
    spp: u32,
) -> Option<&'a MetricRow> {
    rows.iter()
        .find(|r| r.scene == scene && r.estimator == estimator && r.spp == spp)
}

/// Competition ranks ("1224") of `values`, the largest first; NaN ranks last.
pub fn ranks_descending(values: &[f64]) -> Vec<usize> {
    let key = |v: f64| if v.is_nan() { f64::NEG_INFINITY } else { v };
    values
        .iter()
        .map(|&v| {
            1 + values
                .iter()
                .filter(|&&o| key(o) > key(v) || (v.is_nan() && !o.is_nan()))
                .count()
        })
        .collect()
}

/// The four methods of Buisine et al.'s Table 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Family {
    /// The plain mean (the same for every M).
    Mean,
    /// Median of means.
    Mon,
    /// Mean or MoN by the Gini coefficient.
    GmonB,
    /// Gini-trimmed mean of means.
    Gmon,
}

impl Family {
    /// Column name.
    pub fn name(self) -> &'static str {
        match self {
            Family::Mean => "mean",
            Family::Mon => "MoN",
            Family::GmonB => "G-MoN_b",
            Family::Gmon => "G-MoN",
        }
    }
}

/// One cell of Buisine et al.'s Table 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table1Row {
    /// Scene name.
    pub scene: String,
    /// Number of sets M.
    #[serde(rename = "M")]
    pub m: usize,
    /// The method.
    pub method: Family,
    /// Spec string of the estimator.
    pub estimator: String,
    /// The scene's largest spp.
    pub spp: u32,
    /// SSIM there.
    pub ssim: f64,
    /// Rank among the four methods at this scene and M (1 = highest SSIM; ties share a rank).
    pub rank: usize,
}

/// Buisine et al.'s Table 1: per scene and M, the SSIM at the largest spp of the mean, MoN,
/// G-MoN_b and G-MoN, ranked. A method missing at some M is left out of that ranking (for
/// G-MoN_b the first threshold found is used).
pub fn table1(rows: &[MetricRow]) -> Vec<Table1Row> {
    let mut out = Vec::new();
    for scene in scenes_of(rows) {
        let Some(spp) = largest_spp(rows, scene) else {
            continue;
        };
        let at_end: Vec<(&MetricRow, EstimatorSpec)> = rows
            .iter()
            .filter(|r| r.scene == scene && r.spp == spp)
            .filter_map(|r| r.estimator.parse().ok().map(|s| (r, s)))
            .collect();
        let mean = at_end
            .iter()
            .find(|(_, s)| *s == EstimatorSpec::Mean(MeanSpec));
        let mut ms: Vec<usize> = at_end
            .iter()
            .filter_map(|(_, s)| match s {
                EstimatorSpec::Mon(MonSpec { m })
                | EstimatorSpec::GmonB(GmonBSpec { m, .. })
                | EstimatorSpec::Gmon(GmonSpec { m }) => Some(*m),
                _ => None,
            })
            .collect();
        ms.sort_unstable();
        ms.dedup();
        for m in ms {
            let mut cells: Vec<(Family, &MetricRow)> = Vec::new();
            if let Some((r, _)) = mean {
                cells.push((Family::Mean, r));
            }
            let of = |f: Family| {
                at_end.iter().find(|(_, s)| match (f, s) {
                    (Family::Mon, EstimatorSpec::Mon(MonSpec { m: k }))
                    | (Family::GmonB, EstimatorSpec::GmonB(GmonBSpec { m: k, .. }))
                    | (Family::Gmon, EstimatorSpec::Gmon(GmonSpec { m: k })) => *k == m,
                    _ => false,
                })
            };
            for f in [Family::Mon, Family::GmonB, Family::Gmon] {
                if let Some((r, _)) = of(f) {
                    cells.push((f, r));
                }
            }
            let ssims: Vec<f64> = cells.iter().map(|(_, r)| r.ssim).collect();
            for ((f, r), rank) in cells.iter().zip(ranks_descending(&ssims)) {
                out.push(Table1Row {
                    scene: scene.to_string(),
                    m,
                    method: *f,
                    estimator: r.estimator.clone(),
                    spp,
                    ssim: r.ssim,
                    rank,
                });
            }
        }
    }
    out
}

/// The first of `points` (spp, SSIM), taken in ascending spp, whose SSIM reaches `threshold`;
/// `None` ("NR") when none does. A later dip below it does not undo the reach.
pub fn spp_to_reach(points: &[(u32, f64)], threshold: f64) -> Option<u32> {
    let mut sorted = points.to_vec();
    sorted.sort_by_key(|p| p.0);
    sorted.iter().find(|p| p.1 >= threshold).map(|p| p.0)
}

/// One row of Buisine et al.'s Table 2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table2Row {
    /// Scene name.
    pub scene: String,
    /// Spec string.
    pub estimator: String,
    /// Short name.
    pub label: String,
    /// Per threshold (in the order given), the spp needed, or `None` (not reached).
    pub reached: Vec<Option<u32>>,
}

/// Buisine et al.'s Table 2 for every estimator of every scene: the smallest power-of-two
/// checkpoint at which SSIM reaches each threshold (other checkpoints, such as 100, are left
/// out so that every estimator is read on the same grid).
pub fn table2(rows: &[MetricRow], thresholds: &[f64]) -> Vec<Table2Row> {
    let mut out = Vec::new();
    for scene in scenes_of(rows) {
        for est in estimators_of(rows, scene) {
            let pts: Vec<(u32, f64)> = rows
                .iter()
                .filter(|r| r.scene == scene && r.estimator == est && r.spp.is_power_of_two())
                .map(|r| (r.spp, r.ssim))
                .collect();
            let label = rows
                .iter()
                .find(|r| r.scene == scene && r.estimator == est)
                .map(|r| r.label.clone())
                .unwrap_or_default();
            out.push(Table2Row {
                scene: scene.to_string(),
                estimator: est.to_string(),
                label,
                reached: thresholds.iter().map(|&t| spp_to_reach(&pts, t)).collect(),
            });
        }
    }
    out
}

/// One point of Zirr et al.'s Figure 6.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ZirrPoint {
    /// Scene name.
    pub scene: String,
    /// Cascade base.
    pub b: f64,
    /// Robustness κ.
    pub kappa: f64,
    /// Spec string.
    pub estimator: String,
    /// Samples per pixel.
    pub spp: u32,
    /// RMSE, linear RGB.
    pub rmse: f64,
    /// relMSE.
    pub relmse: f64,
    /// The mean's RMSE at the same spp (the figure's baseline).
    pub mean_rmse: Option<f64>,
}

/// Zirr et al.'s Figure 6: RMSE against κ per b, for every `zirr` estimator (the paper's
/// method) at the scene's largest spp, sorted by scene, b and κ.
pub fn zirr_points(rows: &[MetricRow]) -> Vec<ZirrPoint> {
    let mut out = Vec::new();
    for scene in scenes_of(rows) {
        let Some(spp) = largest_spp(rows, scene) else {
            continue;
        };
        let mean_rmse = find(rows, scene, "mean", spp).map(|r| r.rmse);
        let mut pts: Vec<ZirrPoint> = rows
            .iter()
            .filter(|r| r.scene == scene && r.spp == spp)
            .filter_map(|r| match r.estimator.parse() {
                Ok(EstimatorSpec::Zirr(ZirrSpec(p))) => Some(ZirrPoint {
                    scene: scene.to_string(),
                    b: p.b,
                    kappa: p.kappa,
                    estimator: r.estimator.clone(),
                    spp,
                    rmse: r.rmse,
                    relmse: r.relmse,
                    mean_rmse,
                }),
                _ => None,
            })
            .collect();
        pts.sort_by(|a, b| a.b.total_cmp(&b.b).then(a.kappa.total_cmp(&b.kappa)));
        out.extend(pts);
    }
    out
}

/// Every estimator of a scene at its largest spp, ranked by SSIM and by relMSE.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RankRow {
    /// Scene name.
    pub scene: String,
    /// Spec string.
    pub estimator: String,
    /// Short name.
    pub label: String,
    /// The scene's largest spp.
    pub spp: u32,
    /// SSIM.
    pub ssim: f64,
    /// Rank by SSIM (1 = highest).
    pub ssim_rank: usize,
    /// relMSE.
    pub relmse: f64,
    /// Rank by relMSE (1 = lowest).
    pub relmse_rank: usize,
    /// Relative mean bias.
    pub mean_bias_relative: Option<f64>,
}

/// Every estimator's SSIM and relMSE at each scene's largest spp, with ranks.
pub fn ranking(rows: &[MetricRow]) -> Vec<RankRow> {
    let mut out = Vec::new();
    for scene in scenes_of(rows) {
        let Some(spp) = largest_spp(rows, scene) else {
            continue;
        };
        let at: Vec<&MetricRow> = rows
            .iter()
            .filter(|r| r.scene == scene && r.spp == spp)
            .collect();
        let ssim = ranks_descending(&at.iter().map(|r| r.ssim).collect::<Vec<_>>());
        let relmse = ranks_descending(&at.iter().map(|r| -r.relmse).collect::<Vec<_>>());
        for ((r, s), m) in at.iter().zip(ssim).zip(relmse) {
            out.push(RankRow {
                scene: scene.to_string(),
                estimator: r.estimator.clone(),
                label: r.label.clone(),
                spp,
                ssim: r.ssim,
                ssim_rank: s,
                relmse: r.relmse,
                relmse_rank: m,
                mean_bias_relative: r.mean_bias_relative,
            });
        }
    }
    out
}

/// Table 2 as CSV: `scene, estimator, label, ssim_<t>...` with `NR` where not reached.
pub fn table2_csv(table: &[Table2Row], thresholds: &[f64]) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let io = |e: csv::Error| Error::Io {
        path: "table2.csv".into(),
        message: e.to_string(),
    };
    let mut header = vec!["scene".to_string(), "estimator".into(), "label".into()];
    header.extend(thresholds.iter().map(|t| format!("spp_to_ssim_{t}")));
    w.write_record(&header).map_err(io)?;
    for r in table {
        let mut rec = vec![r.scene.clone(), r.estimator.clone(), r.label.clone()];
        rec.extend(r.reached.iter().map(|v| reach_text(*v)));
        w.write_record(&rec).map_err(io)?;
    }
    w.into_inner().map_err(|e| Error::Io {
        path: "table2.csv".into(),
        message: e.to_string(),
    })
}

/// `NR` for not reached, else the spp.
pub fn reach_text(v: Option<u32>) -> String {
    v.map_or_else(|| "NR".to_string(), |s| s.to_string())
}

/// Markdown of Table 1: a row per scene and M, a column per method, `SSIM (rank)`, then the
/// mean rank of each method per M over the scenes.
pub fn table1_md(t: &[Table1Row]) -> String {
    let mut s = String::new();
    let methods = [Family::Mean, Family::Mon, Family::GmonB, Family::Gmon];
    s.push_str(
        "| scene | spp | M | mean | MoN | G-MoN_b | G-MoN |\n|---|---:|---:|---:|---:|---:|---:|\n",
    );
    let mut keys: Vec<(&str, usize, u32)> = Vec::new();
    for r in t {
        if !keys.contains(&(r.scene.as_str(), r.m, r.spp)) {
            keys.push((&r.scene, r.m, r.spp));
        }
    }
    let mut rank_sum: BTreeMap<(usize, Family), (usize, usize)> = BTreeMap::new();
    for (scene, m, spp) in keys {
        let _ = write!(s, "| {scene} | {spp} | {m} |");
        for f in methods {
            match t
                .iter()
                .find(|r| r.scene == scene && r.m == m && r.method == f)
            {
                Some(r) => {
                    let best = if r.rank == 1 { "**" } else { "" };
                    let _ = write!(s, " {best}{:.4}{best} ({}) |", r.ssim, r.rank);
                    let e = rank_sum.entry((m, f)).or_default();
                    e.0 += r.rank;
                    e.1 += 1;
                }
                None => s.push_str(" — |"),
            }
        }
        s.push('\n');
    }
    if !rank_sum.is_empty() {
        s.push_str("\nMean rank over the scenes (1 = best of the four):\n\n");
        s.push_str("| M | mean | MoN | G-MoN_b | G-MoN |\n|---:|---:|---:|---:|---:|\n");
        let ms: Vec<usize> = {
            let mut v: Vec<usize> = rank_sum.keys().map(|k| k.0).collect();
            v.dedup();
            v
        };
        for m in ms {
            let _ = write!(s, "| {m} |");
            for f in methods {
                match rank_sum.get(&(m, f)) {
                    Some((sum, n)) => {
                        let _ = write!(s, " {:.2} |", *sum as f64 / *n as f64);
                    }
                    None => s.push_str(" — |"),
                }
            }
            s.push('\n');
        }
    }
    s
}

/// Markdown of Table 2: a row per scene and estimator, a column per threshold.
pub fn table2_md(t: &[Table2Row], thresholds: &[f64]) -> String {
    let mut s = String::from("| scene | estimator |");
    for th in thresholds {
        let _ = write!(s, " SSIM ≥ {th} |");
    }
    s.push_str("\n|---|---|");
    for _ in thresholds {
        s.push_str("---:|");
    }
    s.push('\n');
    for r in t {
        let _ = write!(s, "| {} | {} |", r.scene, r.label);
        for v in &r.reached {
            let _ = write!(s, " {} |", reach_text(*v));
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_short() {
        let l = |s: &str| label(&s.parse().unwrap());
        assert_eq!(l("gmonb:M=21"), "G-MoN_b M=21");
        assert_eq!(l("gmonb:M=21,threshold=0.3"), "G-MoN_b M=21 t=0.3");
        assert_eq!(l("zirr:b=2,kappa=32"), "Zirr b=2 κ=32");
        assert_eq!(l("zirr-ref"), "zirr-ref b=8 κ=1");
        assert_eq!(l("pajot-hybrid:learn=50,T=2,delta=0"), "Pajot ADR+ROT");
        assert_eq!(l("jung:sigma_image=1,m_max=17"), "Jung m_max=17");
        assert_eq!(l("mean"), "mean");
    }

    #[test]
    fn ranks_share_ties_and_put_nan_last() {
        assert_eq!(ranks_descending(&[0.5, 0.9, 0.5, 0.1]), vec![2, 1, 2, 4]);
        assert_eq!(ranks_descending(&[f64::NAN, 0.2, 0.3]), vec![3, 2, 1]);
        assert_eq!(ranks_descending(&[]), Vec::<usize>::new());
    }
}
