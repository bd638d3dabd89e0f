//! Statistics over the denoising experiment's repeats: the mean of a metric with its Student-t
//! interval ([`mean_interval`]), the geometric mean with a log-scale interval
//! ([`geo_interval`]), and the paired comparison of sources within one render
//! ([`paired_comparisons`], `denoise_paired.csv`).
//!
//! Why paired: every source of one repeat is computed from the same render, so the render's
//! luck (a firefly path found or missed) moves all of them together. The ratio of two sources'
//! relMSE within one repeat cancels most of that shared noise, where two separate intervals per
//! cell keep it and overlap. Why logs: relMSE over repeats is heavy-tailed and positive, so its
//! symmetric mean ± half-width interval can cross zero; the log of a ratio is symmetric about
//! "no difference" (0) and closer to normal.

use super::denoise_run::DenoiseRow;
use crate::harness::metrics::LEVEL;
use serde::Serialize;
use statrs::distribution::{ContinuousCDF, StudentsT};

/// The mean of independent values and its two-sided Student-t interval at [`LEVEL`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanInterval {
    /// How many values.
    pub n: usize,
    /// Their mean.
    pub mean: f64,
    /// Standard error of the mean, `sd / √n` (sample sd, `n − 1` in the denominator); `None`
    /// for one value.
    pub se: Option<f64>,
    /// Half-width of the interval, `t(1 − (1 − LEVEL)/2, n − 1) · se`; `None` for one value.
    pub half_width: Option<f64>,
}

/// The quantile of Student's t with `dof` degrees of freedom that a two-sided [`LEVEL`]
/// interval multiplies the standard error by (NaN for `dof` ≤ 0).
pub fn t_quantile(dof: f64) -> f64 {
    StudentsT::new(0.0, 1.0, dof)
        .map(|d| d.inverse_cdf(0.5 + LEVEL / 2.0))
        .unwrap_or(f64::NAN)
}

/// The mean of `values` with its Student-t interval; `None` for no values. One value has a mean
/// and no interval.
///
/// ```
/// use fireflies::scenes::denoise_compare::mean_interval;
/// let m = mean_interval(&[1.0, 2.0, 3.0, 4.0]).unwrap();
/// assert_eq!(m.mean, 2.5);
/// // t(0.975, 3) · sd / √4 with sd = √(5/3).
/// assert!((m.half_width.unwrap() - 3.182446305 * (5.0f64 / 3.0).sqrt() / 2.0).abs() < 1e-8);
/// assert_eq!(mean_interval(&[7.0]).unwrap().half_width, None);
/// ```
pub fn mean_interval(values: &[f64]) -> Option<MeanInterval> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    let nf = n as f64;
    let mean = values.iter().sum::<f64>() / nf;
    if n < 2 {
        return Some(MeanInterval {
            n,
            mean,
            se: None,
            half_width: None,
        });
    }
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (nf - 1.0);
    let se = (var / nf).sqrt();
    Some(MeanInterval {
        n,
        mean,
        se: Some(se),
        half_width: Some(t_quantile(nf - 1.0) * se),
    })
}

/// A geometric mean and its interval: the Student-t interval of the mean of the logs, mapped
/// back by `exp`. It assumes the logs are roughly normal over the values (a log-normal metric
/// or ratio), and it is never below zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoInterval {
    /// How many values.
    pub n: usize,
    /// Mean of the logs.
    pub log_mean: f64,
    /// Its standard error; `None` for one value.
    pub log_se: Option<f64>,
    /// `exp(log_mean)`.
    pub geomean: f64,
    /// `exp(log_mean − t · log_se)`; `None` for one value.
    pub lo: Option<f64>,
    /// `exp(log_mean + t · log_se)`; `None` for one value.
    pub hi: Option<f64>,
}

/// The geometric interval of values given by their logs; `None` for none.
///
/// ```
/// use fireflies::scenes::denoise_compare::geo_interval_of_logs;
/// // ln 0.5 and ln 2: geometric mean 1, an interval on both sides of it.
/// let g = geo_interval_of_logs(&[0.5f64.ln(), 2f64.ln()]).unwrap();
/// assert!((g.geomean - 1.0).abs() < 1e-12);
/// assert!(g.lo.unwrap() < 1.0 && g.hi.unwrap() > 1.0);
/// ```
pub fn geo_interval_of_logs(logs: &[f64]) -> Option<GeoInterval> {
    let m = mean_interval(logs)?;
    Some(GeoInterval {
        n: m.n,
        log_mean: m.mean,
        log_se: m.se,
        geomean: m.mean.exp(),
        lo: m.half_width.map(|h| (m.mean - h).exp()),
        hi: m.half_width.map(|h| (m.mean + h).exp()),
    })
}

/// The geometric interval of `values`; `None` for none, or when a value is zero, negative or
/// not finite (it has no log).
pub fn geo_interval(values: &[f64]) -> Option<GeoInterval> {
    if !values.iter().all(|v| v.is_finite() && *v > 0.0) {
        return None;
    }
    let logs: Vec<f64> = values.iter().map(|v| v.ln()).collect();
    geo_interval_of_logs(&logs)
}

/// What a paired comparison says about a source against its baseline (lower relMSE is better).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Verdict {
    /// The whole interval of the ratio is below 1: the source has the lower relMSE.
    #[serde(rename = "helps")]
    Helps,
    /// The whole interval is above 1.
    #[serde(rename = "hurts")]
    Hurts,
    /// Every pair has exactly the same relMSE (e.g. G-MoN with 2 samples per half, which then
    /// equals the mean): no difference, not an open question.
    #[serde(rename = "same")]
    Same,
    /// The interval holds 1.
    #[serde(rename = "undecided")]
    Undecided,
    /// Fewer than two usable pairs: no interval.
    #[serde(rename = "n/a")]
    NoInterval,
}

impl Verdict {
    /// As `denoise_paired.csv` writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Helps => "helps",
            Verdict::Hurts => "hurts",
            Verdict::Same => "same",
            Verdict::Undecided => "undecided",
            Verdict::NoInterval => "n/a",
        }
    }
}

/// A source against its baseline over the repeats of one scene and spp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairedRatio {
    /// Usable pairs: repeats where both relMSEs are finite and positive.
    pub pairs: usize,
    /// Pairs left out because a relMSE is zero, negative or not finite (the log of the ratio
    /// does not exist or says nothing).
    pub skipped: usize,
    /// The geometric mean of `source / baseline` with its interval, over the usable pairs;
    /// `None` without any.
    pub ratio: Option<GeoInterval>,
    /// Two-sided p-value of the paired t-test of "mean log-ratio = 0" (below `1 − LEVEL`
    /// exactly when the interval excludes 1); `None` below two pairs.
    pub p_value: Option<f64>,
    /// What the interval says.
    pub verdict: Verdict,
}

/// Pairs `source[r]` with `baseline[r]` (same render `r`) and compares them on the log scale:
/// per pair `ln(source / baseline)`, their mean with a Student-t interval (`pairs − 1` degrees
/// of freedom) mapped back by `exp`. A pair with a relMSE that is zero, negative or not finite
/// is skipped and counted; the slices are cut to the shorter.
///
/// ```
/// use fireflies::scenes::denoise_compare::{Verdict, paired_ratio};
/// // Half the baseline in every render, however noisy the renders: helps, with certainty.
/// let p = paired_ratio(&[0.5, 5.0, 50.0], &[1.0, 10.0, 100.0]);
/// assert!((p.ratio.unwrap().geomean - 0.5).abs() < 1e-12);
/// assert_eq!(p.verdict, Verdict::Helps);
/// ```
pub fn paired_ratio(source: &[f64], baseline: &[f64]) -> PairedRatio {
    let usable = |v: f64| v.is_finite() && v > 0.0;
    let logs: Vec<f64> = source
        .iter()
        .zip(baseline)
        .filter(|&(&s, &b)| usable(s) && usable(b))
        .map(|(&s, &b)| (s / b).ln())
        .collect();
    let pairs = logs.len();
    let skipped = source.len().min(baseline.len()) - pairs;
    let ratio = geo_interval_of_logs(&logs);
    let (p_value, verdict) = match ratio {
        Some(g) if pairs >= 2 => {
            let se = g.log_se.unwrap_or(f64::NAN);
            let p = if se > 0.0 {
                StudentsT::new(0.0, 1.0, pairs as f64 - 1.0)
                    .map(|d| 2.0 * d.sf((g.log_mean / se).abs()))
                    .unwrap_or(f64::NAN)
            } else if g.log_mean == 0.0 {
                1.0
            } else {
                0.0
            };
            let verdict = if logs.iter().all(|&l| l == 0.0) {
                Verdict::Same
            } else if g.hi.is_some_and(|h| h < 1.0) {
                Verdict::Helps
            } else if g.lo.is_some_and(|l| l > 1.0) {
                Verdict::Hurts
            } else {
                Verdict::Undecided
            };
            (Some(p), verdict)
        }
        _ => (None, Verdict::NoInterval),
    };
    PairedRatio {
        pairs,
        skipped,
        ratio,
        p_value,
        verdict,
    }
}

/// Holm's step-down adjustment of `p` (family-wise error at most the level when each is
/// below it); `None` entries are not tested and stay `None`.
///
/// ```
/// use fireflies::scenes::denoise_compare::holm;
/// // Sorted 1/16, 1/8, 1/4 times 3, 2, 1, kept non-decreasing: 3/16, 1/4, 1/4.
/// let a = holm(&[Some(0.25), None, Some(0.0625), Some(0.125)]);
/// assert_eq!(a, [Some(0.25), None, Some(0.1875), Some(0.25)]);
/// ```
pub fn holm(p: &[Option<f64>]) -> Vec<Option<f64>> {
    let mut order: Vec<usize> = (0..p.len()).filter(|&i| p[i].is_some()).collect();
    order.sort_by(|&a, &b| p[a].unwrap_or(1.0).total_cmp(&p[b].unwrap_or(1.0)));
    let m = order.len();
    let mut out = vec![None; p.len()];
    let mut running: f64 = 0.0;
    for (j, &i) in order.iter().enumerate() {
        let raw = p[i].unwrap_or(1.0);
        running = running.max(((m - j) as f64 * raw).min(1.0));
        out[i] = Some(running);
    }
    out
}

/// One row of `denoise_paired.csv`: a source (and variance, after NFOR) against the stage's
/// baseline over the repeats of one scene and spp.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PairedRow {
    /// Scene name.
    pub scene: String,
    /// Samples per pixel.
    pub spp: u32,
    /// Source estimator spec.
    pub source: String,
    /// Its short label.
    pub label: String,
    /// Variance given to NFOR; empty for the noisy estimate.
    pub variance: String,
    /// `noisy` (the estimate before denoising, against the baseline's noisy estimate) or
    /// `denoised` (NFOR's output, against NFOR's output of the baseline).
    pub stage: String,
    /// The baseline: `source/variance` after NFOR, the source alone for the noisy stage.
    pub baseline: String,
    /// Usable pairs (repeats) the ratio is over.
    pub repeats: usize,
    /// Repeats without a usable pair: a relMSE zero, negative or not finite, or no baseline row.
    pub skipped: usize,
    /// Confidence level of the interval.
    pub level: f64,
    /// Geometric mean over repeats of `relMSE_source / relMSE_baseline`.
    pub ratio_geomean: Option<f64>,
    /// Lower end of its interval (empty below two pairs).
    pub ratio_lo: Option<f64>,
    /// Upper end.
    pub ratio_hi: Option<f64>,
    /// `helps`, `hurts`, `same`, `undecided` or `n/a`, from the interval alone.
    pub verdict: Verdict,
    /// Mean of the log-ratios.
    pub log_ratio_mean: Option<f64>,
    /// Its standard error.
    pub log_ratio_se: Option<f64>,
    /// The paired t-test's two-sided p-value.
    pub p_value: Option<f64>,
    /// That p-value after Holm's adjustment over every row of the same stage in the run.
    pub p_holm: Option<f64>,
    /// `helps` or `hurts` when `p_holm` is below `1 − level`, `undecided` when not; `same` and
    /// `n/a` as `verdict`. Holds for all rows of a stage together, at the level.
    pub verdict_holm: Verdict,
}

/// The paired comparisons of `rows` (as `denoise.csv` holds them), per scene, spp and stage in
/// order of first appearance. The baseline of a stage is its first source and variance in
/// `rows` — with the run's rows, the experiment file's first source and first variance (the
/// mean with `halves` in `experiments/denoise.toml`); every other source and variance of the
/// stage is compared with it, repeat by repeat. Holm's adjustment runs over each stage's rows
/// of the whole result.
pub fn paired_comparisons(rows: &[DenoiseRow]) -> Vec<PairedRow> {
    let mut groups: Vec<(&str, u32, &str)> = Vec::new();
    for r in rows {
        let g = (r.scene.as_str(), r.spp, r.stage.as_str());
        if !groups.contains(&g) {
            groups.push(g);
        }
    }
    let mut out = Vec::new();
    for (scene, spp, stage) in groups {
        let own: Vec<&DenoiseRow> = rows
            .iter()
            .filter(|r| r.scene == scene && r.spp == spp && r.stage == stage)
            .collect();
        let mut series: Vec<(&str, &str, &str)> = Vec::new();
        for r in &own {
            let s = (r.source.as_str(), r.variance.as_str(), r.label.as_str());
            if !series.iter().any(|&(a, b, _)| (a, b) == (s.0, s.1)) {
                series.push(s);
            }
        }
        let Some((&(base_src, base_var, _), others)) = series.split_first() else {
            continue;
        };
        let baseline = if base_var.is_empty() {
            base_src.to_string()
        } else {
            format!("{base_src}/{base_var}")
        };
        for &(src, var, label) in others {
            let (mut x, mut b) = (Vec::new(), Vec::new());
            let mut unpaired = 0;
            for r in own.iter().filter(|r| r.source == src && r.variance == var) {
                match own.iter().find(|o| {
                    o.source == base_src && o.variance == base_var && o.repeat == r.repeat
                }) {
                    Some(o) => {
                        x.push(r.relmse);
                        b.push(o.relmse);
                    }
                    None => unpaired += 1,
                }
            }
            let p = paired_ratio(&x, &b);
            out.push(PairedRow {
                scene: scene.to_string(),
                spp,
                source: src.to_string(),
                label: label.to_string(),
                variance: var.to_string(),
                stage: stage.to_string(),
                baseline: baseline.clone(),
                repeats: p.pairs,
                skipped: p.skipped + unpaired,
                level: LEVEL,
                ratio_geomean: p.ratio.map(|g| g.geomean),
                ratio_lo: p.ratio.and_then(|g| g.lo),
                ratio_hi: p.ratio.and_then(|g| g.hi),
                verdict: p.verdict,
                log_ratio_mean: p.ratio.map(|g| g.log_mean),
                log_ratio_se: p.ratio.and_then(|g| g.log_se),
                p_value: p.p_value,
                p_holm: None,
                verdict_holm: p.verdict,
            });
        }
    }
    let mut stages: Vec<String> = Vec::new();
    for r in &out {
        if !stages.contains(&r.stage) {
            stages.push(r.stage.clone());
        }
    }
    for stage in stages {
        let idx: Vec<usize> = (0..out.len()).filter(|&i| out[i].stage == stage).collect();
        let adjusted = holm(&idx.iter().map(|&i| out[i].p_value).collect::<Vec<_>>());
        for (&i, a) in idx.iter().zip(adjusted) {
            let r = &mut out[i];
            r.p_holm = a;
            if matches!(
                r.verdict,
                Verdict::Helps | Verdict::Hurts | Verdict::Undecided
            ) {
                r.verdict_holm = match (a, r.log_ratio_mean) {
                    (Some(a), Some(m)) if a < 1.0 - LEVEL && m < 0.0 => Verdict::Helps,
                    (Some(a), Some(m)) if a < 1.0 - LEVEL && m > 0.0 => Verdict::Hurts,
                    _ => Verdict::Undecided,
                };
            }
        }
    }
    out
}
