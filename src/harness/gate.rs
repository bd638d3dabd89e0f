//! Regression gating against a committed baseline (`results.csv` of an earlier run).
//!
//! A change is a regression only when it is both *significant* — a two-sample z-test on the
//! two runs' 95% intervals, one-sided towards "worse", Holm across every compared metric at
//! `family_alpha` — and *practically large*, beyond a configured margin. Noise alone fails a
//! gate with probability at most `family_alpha`, and far less in practice because it must
//! also clear the margin; a real 2% bias shift fails it at the default sizes.
//!
//! Gated metrics: `relative_bias` (worse = further from 0), `variance` and
//! `median_abs_rel_error` (worse = larger, relative margin) and `firefly_rate` (worse =
//! larger, absolute margin). A cell without an interval in either run (e.g. the mean's
//! variance on an infinite-variance law) is listed as not gated.

use super::metrics::{Metric, Row, Z};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, Normal};
use std::collections::BTreeMap;

/// Practical margins and the family-wise level of the gate.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GateConfig {
    /// Probability that noise alone flags any regression (Holm across all comparisons).
    pub family_alpha: f64,
    /// Smallest change of `|relative bias|` that counts (0.01 = 1% of the true mean).
    pub relative_bias_margin: f64,
    /// Smallest relative increase of the variance that counts (0.1 = 10%).
    pub variance_margin: f64,
    /// Smallest relative increase of the median absolute relative error that counts.
    pub median_error_margin: f64,
    /// Smallest absolute increase of the firefly rate that counts.
    pub firefly_rate_margin: f64,
}

impl Default for GateConfig {
    fn default() -> Self {
        GateConfig {
            family_alpha: 0.01,
            relative_bias_margin: 0.01,
            variance_margin: 0.10,
            median_error_margin: 0.10,
            firefly_rate_margin: 0.01,
        }
    }
}

/// One compared metric.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// Distribution label.
    pub distribution: String,
    /// Estimator spec string.
    pub estimator: String,
    /// Sample count.
    pub n: usize,
    /// Metric.
    pub metric: Metric,
    /// Baseline value.
    pub baseline: f64,
    /// Current value.
    pub now: f64,
    /// Change in the "worse" direction (positive: worse).
    pub worsening: f64,
    /// 95% interval of `worsening` (independent-runs approximation).
    pub interval: Option<(f64, f64)>,
    /// Margin the worsening must exceed.
    pub margin: f64,
    /// One-sided p-value of "no worsening" (`None`: not gated).
    pub p_value: Option<f64>,
    /// Holm level it was compared with.
    pub holm_alpha: Option<f64>,
    /// Significant and beyond the margin.
    pub regression: bool,
}

fn se(r: &Row) -> Option<f64> {
    match (r.ci_low, r.ci_high) {
        (Some(l), Some(h)) if h >= l => Some((h - l) / (2.0 * Z)),
        _ => None,
    }
}

/// Compares every gated metric present in both tables.
pub fn compare(baseline: &[Row], now: &[Row], cfg: &GateConfig) -> Vec<Comparison> {
    let key = |r: &Row| (r.distribution.clone(), r.estimator.clone(), r.n, r.metric);
    let base: BTreeMap<_, &Row> = baseline.iter().map(|r| (key(r), r)).collect();
    let std = Normal::new(0.0, 1.0).expect("standard normal");
    let mut out = Vec::new();
    for r in now {
        let Some(b) = base.get(&key(r)) else { continue };
        let (worsening, margin) = match r.metric {
            Metric::RelativeBias => (r.value.abs() - b.value.abs(), cfg.relative_bias_margin),
            Metric::Variance => (r.value - b.value, cfg.variance_margin * b.value.abs()),
            Metric::MedianAbsRelError => {
                (r.value - b.value, cfg.median_error_margin * b.value.abs())
            }
            Metric::FireflyRate => (r.value - b.value, cfg.firefly_rate_margin),
            _ => continue,
        };
        let (interval, p_value) = match (se(r), se(b)) {
            (Some(s1), Some(s0)) => {
                let s = (s1 * s1 + s0 * s0).sqrt();
                let p = if s > 0.0 {
                    std.sf(worsening / s)
                } else if worsening > 0.0 {
                    0.0
                } else {
                    1.0
                };
                (Some((worsening - Z * s, worsening + Z * s)), Some(p))
            }
            _ => (None, None),
        };
        out.push(Comparison {
            distribution: r.distribution.clone(),
            estimator: r.estimator.clone(),
            n: r.n,
            metric: r.metric,
            baseline: b.value,
            now: r.value,
            worsening,
            interval,
            margin,
            p_value,
            holm_alpha: None,
            regression: false,
        });
    }
    // Holm over the gated comparisons; a regression also needs to clear its margin.
    let mut order: Vec<usize> = (0..out.len())
        .filter(|&i| out[i].p_value.is_some())
        .collect();
    order.sort_by(|&a, &b| {
        out[a]
            .p_value
            .unwrap_or(1.0)
            .total_cmp(&out[b].p_value.unwrap_or(1.0))
    });
    let m = order.len();
    for (rank, &i) in order.iter().enumerate() {
        let level = cfg.family_alpha / (m - rank) as f64;
        out[i].holm_alpha = Some(level);
        if out[i].p_value.unwrap_or(1.0) > level {
            break;
        }
        out[i].regression = out[i].worsening > out[i].margin;
    }
    out
}

/// A readable table of every comparison, regressions first.
pub fn table(comparisons: &[Comparison]) -> String {
    let mut rows: Vec<&Comparison> = comparisons.iter().collect();
    rows.sort_by_key(|c| (!c.regression, c.p_value.is_none()));
    let mut s = String::from(
        "| verdict | distribution | estimator | n | metric | baseline | now | worse by | 95% interval | margin | p |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for c in rows {
        let verdict = match (c.regression, c.p_value) {
            (true, _) => "**REGRESSION**",
            (false, None) => "not gated (no interval)",
            (false, Some(_)) => "ok",
        };
        let interval = c
            .interval
            .map_or("–".to_string(), |(l, h)| format!("[{l:.3e}, {h:.3e}]"));
        let p = c.p_value.map_or("–".to_string(), |p| format!("{p:.2e}"));
        s.push_str(&format!(
            "| {verdict} | {} | `{}` | {} | {} | {:.4e} | {:.4e} | {:.3e} | {interval} | {:.2e} | {p} |\n",
            c.distribution, c.estimator, c.n, c.metric, c.baseline, c.now, c.worsening, c.margin
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(metric: &str, value: f64, half: f64) -> Row {
        Row {
            distribution: "d".into(),
            estimator: "mean".into(),
            n: 16,
            metric: metric.parse().unwrap(),
            value,
            ci_low: Some(value - half),
            ci_high: Some(value + half),
            se: Some(half / Z),
            level: Some(0.95),
            caveat: None,
        }
    }

    #[test]
    fn significant_and_large_is_a_regression_small_or_noisy_is_not() {
        let cfg = GateConfig::default();
        let base = [row("relative_bias", 0.0, 0.002)];
        // 2% bias with a tight interval: regression.
        let c = compare(&base, &[row("relative_bias", 0.02, 0.002)], &cfg);
        assert!(c[0].regression, "{c:?}");
        // Significant but within the 1% margin: not a regression.
        let c = compare(&base, &[row("relative_bias", 0.008, 0.001)], &cfg);
        assert!(!c[0].regression);
        // Large but not significant: not a regression.
        let c = compare(
            &[row("relative_bias", 0.0, 0.05)],
            &[row("relative_bias", 0.03, 0.05)],
            &cfg,
        );
        assert!(!c[0].regression);
        // Bias moving towards zero is an improvement.
        let c = compare(
            &[row("relative_bias", 0.05, 0.001)],
            &[row("relative_bias", -0.01, 0.001)],
            &cfg,
        );
        assert!(!c[0].regression && c[0].worsening < 0.0);
    }

    #[test]
    fn cells_without_intervals_are_listed_not_gated() {
        let mut r = row("variance", 5.0, 0.0);
        r.ci_low = None;
        r.ci_high = None;
        let c = compare(
            std::slice::from_ref(&r),
            &[row("variance", 50.0, 1.0)],
            &GateConfig::default(),
        );
        assert!(c[0].p_value.is_none() && !c[0].regression);
        assert!(table(&c).contains("not gated"));
    }
}
