//! Accuracy metrics over independent trials (docs/estimators.md §7), as mergeable accumulators.
//!
//! Each (distribution, estimator, n) cell keeps central moments of the estimate, of its
//! squared error and of its absolute relative error, a log-binned histogram of the absolute
//! relative error (for quantiles: no per-trial list is stored, so a million trials cost the
//! same memory as a thousand), and event counts. Accumulators merge exactly; the runner
//! merges fixed-size trial chunks in chunk order, so results do not depend on thread count.
//!
//! The median absolute relative error is the primary metric: it and its order-statistic
//! interval stay meaningful when the estimator's error has infinite variance, where the
//! variance and MSE intervals do not. Quantiles come from the histogram, so they are exact to
//! within one bin: a factor `10^(1/BINS_PER_DECADE)` (2.3%).

use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::collections::BTreeMap;

/// Serde for `f64` as its bit pattern: exact, and non-finite values survive JSON.
mod f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(x.to_bits())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        u64::deserialize(d).map(f64::from_bits)
    }
}

/// [`f64_bits`] for an optional value.
mod opt_f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(x: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        match x {
            Some(v) => s.serialize_some(&v.to_bits()),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        Option::<u64>::deserialize(d).map(|o| o.map(f64::from_bits))
    }
}

/// Two-sided 95% normal quantile used by every interval (docs/estimators.md §7).
pub const Z: f64 = 1.96;

/// Histogram resolution of the relative-error quantiles.
pub const BINS_PER_DECADE: f64 = 100.0;

/// Running count, mean and central moments M2..M4, with Pébay's exact pairwise merge.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Moments {
    n: u64,
    #[serde(with = "f64_bits")]
    mean: f64,
    #[serde(with = "f64_bits")]
    m2: f64,
    #[serde(with = "f64_bits")]
    m3: f64,
    #[serde(with = "f64_bits")]
    m4: f64,
}

impl Moments {
    /// Adds one observation (Terriberry's update).
    pub fn push(&mut self, x: f64) {
        let n1 = self.n as f64;
        self.n += 1;
        let n = self.n as f64;
        let delta = x - self.mean;
        let dn = delta / n;
        let dn2 = dn * dn;
        let term1 = delta * dn * n1;
        self.mean += dn;
        self.m4 += term1 * dn2 * (n * n - 3.0 * n + 3.0) + 6.0 * dn2 * self.m2 - 4.0 * dn * self.m3;
        self.m3 += term1 * dn * (n - 2.0) - 3.0 * dn * self.m2;
        self.m2 += term1;
    }

    /// Combines with another accumulator as if all observations had gone through one.
    pub fn merge(&mut self, b: &Moments) {
        if b.n == 0 {
            return;
        }
        if self.n == 0 {
            *self = *b;
            return;
        }
        let (na, nb) = (self.n as f64, b.n as f64);
        let n = na + nb;
        let d = b.mean - self.mean;
        let (d2, d3, d4) = (d * d, d * d * d, d * d * d * d);
        let m2 = self.m2 + b.m2 + d2 * na * nb / n;
        let m3 = self.m3
            + b.m3
            + d3 * na * nb * (na - nb) / (n * n)
            + 3.0 * d * (na * b.m2 - nb * self.m2) / n;
        let m4 = self.m4
            + b.m4
            + d4 * na * nb * (na * na - na * nb + nb * nb) / (n * n * n)
            + 6.0 * d2 * (na * na * b.m2 + nb * nb * self.m2) / (n * n)
            + 4.0 * d * (na * b.m3 - nb * self.m3) / n;
        self.mean += d * nb / n;
        self.n += b.n;
        (self.m2, self.m3, self.m4) = (m2, m3, m4);
    }

    /// Number of observations.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// Mean.
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Sample variance (divisor n - 1).
    pub fn sample_variance(&self) -> f64 {
        self.m2 / (self.n as f64 - 1.0)
    }

    /// Fourth central moment with divisor n.
    pub fn m4(&self) -> f64 {
        self.m4 / self.n as f64
    }

    /// Standard error of the mean, `s / sqrt(n)`.
    pub fn standard_error(&self) -> f64 {
        (self.sample_variance() / self.n as f64).sqrt()
    }
}

/// Log-binned histogram of non-negative values. Zeros and exact ones have their own atoms: an
/// estimate of exactly 0 has a relative error of exactly 1, which is common (black pixels) and
/// must print as 1, not as the centre of the bin holding it. Integer counts, so merging is exact
/// in any order.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LogHistogram {
    zeros: u64,
    #[serde(default)]
    ones: u64,
    bins: BTreeMap<i32, u64>,
}

/// Where an order statistic lies: exactly on an atom, or at a rank's position inside a bin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Located {
    /// Exactly this value.
    Exact(f64),
    /// Inside `[low, high)`, the `position`-th fraction of the way through the bin's values
    /// by rank (the `i`-th of `c` values sits at `(i - 1/2) / c`).
    Bin {
        /// Lower edge.
        low: f64,
        /// Upper edge.
        high: f64,
        /// In (0, 1).
        position: f64,
    },
}

impl Located {
    /// The atom, or the bin's values taken as spread evenly in `log x` and read at the rank's
    /// position: within the bin, so never an impossible value, and two different ranks in one
    /// bin give two different values (an interval between them never has zero width).
    pub fn value(self) -> f64 {
        match self {
            Located::Exact(v) => v,
            Located::Bin {
                low,
                high,
                position,
            } => low * (high / low).powf(position),
        }
    }
}

fn bin_edge(b: i32) -> f64 {
    10f64.powf(f64::from(b) / BINS_PER_DECADE)
}

impl LogHistogram {
    /// Adds a value (non-finite values land in the top bin).
    pub fn push(&mut self, x: f64) {
        if x <= 0.0 {
            self.zeros += 1;
            return;
        }
        if x == 1.0 {
            self.ones += 1;
            return;
        }
        let bin = (x.log10() * BINS_PER_DECADE)
            .floor()
            .clamp(-40_000.0, 40_000.0) as i32;
        *self.bins.entry(bin).or_insert(0) += 1;
    }

    /// Adds another histogram's counts.
    pub fn merge(&mut self, other: &LogHistogram) {
        self.zeros += other.zeros;
        self.ones += other.ones;
        for (&b, &c) in &other.bins {
            *self.bins.entry(b).or_insert(0) += c;
        }
    }

    /// Total count.
    pub fn count(&self) -> u64 {
        self.zeros + self.ones + self.bins.values().sum::<u64>()
    }

    /// Where the `rank`-th smallest value (1-based) lies. The atom 1 sorts inside bin 0
    /// (`[1, 1.023)`), before every value of that bin.
    pub fn locate(&self, rank: u64) -> Located {
        let mut seen = self.zeros;
        if rank <= seen {
            return Located::Exact(0.0);
        }
        let mut ones_done = false;
        for (&b, &c) in &self.bins {
            if b >= 0 && !ones_done {
                ones_done = true;
                seen += self.ones;
                if rank <= seen {
                    return Located::Exact(1.0);
                }
            }
            if rank <= seen + c {
                return Located::Bin {
                    low: bin_edge(b),
                    high: bin_edge(b + 1),
                    position: ((rank - seen) as f64 - 0.5) / c as f64,
                };
            }
            seen += c;
        }
        if !ones_done && rank <= seen + self.ones {
            return Located::Exact(1.0);
        }
        Located::Exact(f64::INFINITY)
    }

    /// The `rank`-th smallest value (1-based): the atom, or its place inside its bin.
    pub fn order_statistic(&self, rank: u64) -> f64 {
        self.locate(rank).value()
    }

    /// The q-quantile (`q` in [0, 1]) by the nearest-rank rule.
    pub fn quantile(&self, q: f64) -> f64 {
        let n = self.count();
        let rank = ((q * n as f64).ceil() as u64).clamp(1, n.max(1));
        self.order_statistic(rank)
    }

    /// The share of `sum |x - centre|^power` that the `k` values farthest from `centre`
    /// carry; see [`Self::top_share_by`].
    pub fn top_share(&self, centre: f64, k: u64, power: i32) -> f64 {
        self.top_share_by(k, |v| (v - centre).abs().powi(power))
    }

    /// The share of `sum w(x)` that the `k` values of largest weight carry, each of them taken
    /// at its bin's heavier edge and the rest at their bins' centres (so the share errs high);
    /// 1 when every weight is 0 (the run saw nothing to weigh). `w` must be non-negative and
    /// monotone on either side of one point (true of `|x - c|^p` and `(x^2 - c)^2` for
    /// `x >= 0`), so that its largest value in a bin is at an edge. Whether a moment of this
    /// run rests on a handful of observations.
    pub fn top_share_by(&self, k: u64, w: impl Fn(f64) -> f64) -> f64 {
        // (heaviest weight, typical weight, count) of every atom and bin.
        let mut groups: Vec<(f64, f64, u64)> =
            vec![(w(0.0), w(0.0), self.zeros), (w(1.0), w(1.0), self.ones)];
        for (&b, &c) in &self.bins {
            let (lo, hi) = (bin_edge(b), bin_edge(b + 1));
            groups.push((w(lo).max(w(hi)), w((lo * hi).sqrt()), c));
        }
        groups.sort_by(|a, b| b.0.total_cmp(&a.0));
        let (mut top, mut total, mut left) = (0.0, 0.0, k);
        for (far, typical, count) in groups {
            let taken = count.min(left);
            left -= taken;
            top += taken as f64 * far;
            total += taken as f64 * far + (count - taken) as f64 * typical;
        }
        if total > 0.0 { top / total } else { 1.0 }
    }
}

/// Every metric a report row can carry. One list: the tables write these names, the plots and
/// the gate read them, and a name that is not here is an error when a table is read back, so a
/// renamed metric cannot silently drop out of a comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Metric {
    /// `mean(X) - mu`, in the law's units.
    Bias,
    /// `(mean(X) - mu) / mu`.
    RelativeBias,
    /// Sample variance of the estimates over trials.
    Variance,
    /// The estimator's exact variance from the law (the mean's `sigma^2 / n`), no sampling.
    ExactVariance,
    /// Mean squared error against the true mean.
    Mse,
    /// `sqrt(MSE) / mu`.
    RelativeRmse,
    /// Median over trials of `|X - mu| / mu` (the primary metric).
    MedianAbsRelError,
    /// Mean over trials of `|X - mu| / mu`.
    MeanAbsRelError,
    /// Quantiles of `|X - mu| / mu`.
    RelErrorQ05,
    /// See [`Metric::RelErrorQ05`].
    RelErrorQ25,
    /// See [`Metric::RelErrorQ05`].
    RelErrorQ50,
    /// See [`Metric::RelErrorQ05`].
    RelErrorQ75,
    /// See [`Metric::RelErrorQ05`].
    RelErrorQ95,
    /// See [`Metric::RelErrorQ05`].
    RelErrorQ99,
    /// `P(X > (1 + tau) mu)`.
    FireflyRate,
    /// Trials holding a sample at or above `n mu`.
    OutlierTrials,
    /// Among outlier trials, the fraction whose estimate stayed at or below `(1 + tau) mu`.
    RejectionRate,
    /// Mean over trials of `|X - mu|/mu - |mean - mu|/mu`.
    PairedAbsRelVsMean,
    /// Mean over trials of `(X - mu)^2 - (mean - mu)^2`.
    PairedMseVsMean,
    /// Largest per-pixel state at the end of a trial, bytes.
    StateBytesMax,
    /// Mean per-pixel state at the end of a trial, bytes.
    StateBytesMean,
    /// Push and estimate cost, nanoseconds per sample on one thread (`speed.csv`).
    NsPerSample,
    /// Cost of drawing a sample (`speed.csv`, estimator `(generator)`).
    GenerateNsPerSample,
}

impl Metric {
    /// Every metric, in the order a cell's rows are written.
    pub const ALL: [Metric; 23] = [
        Metric::Bias,
        Metric::RelativeBias,
        Metric::Variance,
        Metric::ExactVariance,
        Metric::Mse,
        Metric::RelativeRmse,
        Metric::MedianAbsRelError,
        Metric::MeanAbsRelError,
        Metric::RelErrorQ05,
        Metric::RelErrorQ25,
        Metric::RelErrorQ50,
        Metric::RelErrorQ75,
        Metric::RelErrorQ95,
        Metric::RelErrorQ99,
        Metric::FireflyRate,
        Metric::OutlierTrials,
        Metric::RejectionRate,
        Metric::PairedAbsRelVsMean,
        Metric::PairedMseVsMean,
        Metric::StateBytesMax,
        Metric::StateBytesMean,
        Metric::NsPerSample,
        Metric::GenerateNsPerSample,
    ];

    /// The error quantiles written per cell, with their levels.
    pub const QUANTILES: [(f64, Metric); 6] = [
        (0.05, Metric::RelErrorQ05),
        (0.25, Metric::RelErrorQ25),
        (0.50, Metric::RelErrorQ50),
        (0.75, Metric::RelErrorQ75),
        (0.95, Metric::RelErrorQ95),
        (0.99, Metric::RelErrorQ99),
    ];

    /// The name in tables.
    pub fn name(self) -> &'static str {
        match self {
            Metric::Bias => "bias",
            Metric::RelativeBias => "relative_bias",
            Metric::Variance => "variance",
            Metric::ExactVariance => "exact_variance",
            Metric::Mse => "mse",
            Metric::RelativeRmse => "relative_rmse",
            Metric::MedianAbsRelError => "median_abs_rel_error",
            Metric::MeanAbsRelError => "mean_abs_rel_error",
            Metric::RelErrorQ05 => "rel_error_q05",
            Metric::RelErrorQ25 => "rel_error_q25",
            Metric::RelErrorQ50 => "rel_error_q50",
            Metric::RelErrorQ75 => "rel_error_q75",
            Metric::RelErrorQ95 => "rel_error_q95",
            Metric::RelErrorQ99 => "rel_error_q99",
            Metric::FireflyRate => "firefly_rate",
            Metric::OutlierTrials => "outlier_trials",
            Metric::RejectionRate => "rejection_rate",
            Metric::PairedAbsRelVsMean => "paired_abs_rel_vs_mean",
            Metric::PairedMseVsMean => "paired_mse_vs_mean",
            Metric::StateBytesMax => "state_bytes_max",
            Metric::StateBytesMean => "state_bytes_mean",
            Metric::NsPerSample => "ns_per_sample",
            Metric::GenerateNsPerSample => "generate_ns_per_sample",
        }
    }
}

impl std::fmt::Display for Metric {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Metric {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Metric::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Metric::ALL.iter().map(|m| m.name()).collect();
                format!("unknown metric \"{s}\"; known: {}", names.join(", "))
            })
    }
}

impl Serialize for Metric {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Metric {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// Why a row's value carries no interval that could be trusted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Caveat {
    /// The metric's spread comes from tail events expected fewer than [`TAIL_EVENTS`] times in
    /// the run: the sample value is what this run saw, and no interval is printed.
    TailDominated,
    /// The true value is infinite (e.g. the mean's variance on an infinite-variance law); the
    /// value column holds `inf` or `-inf`.
    InfiniteTruth,
}

impl Caveat {
    /// The word the summary prints.
    pub fn label(self) -> &'static str {
        match self {
            Caveat::TailDominated => "tail-dominated",
            Caveat::InfiniteTruth => "infinite",
        }
    }
}

/// A cell's spread counts as tail-dominated when more than half of it comes from events the run
/// expects fewer than this many times.
pub const TAIL_EVENTS: f64 = 10.0;

/// One row of a tidy results table (`results.csv`, `speed.csv`, gate baselines).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Distribution label.
    pub distribution: String,
    /// Estimator spec string.
    pub estimator: String,
    /// Sample count.
    pub n: usize,
    /// Metric.
    pub metric: Metric,
    /// Point value (`inf`/`-inf` where the truth is infinite).
    pub value: f64,
    /// Lower bound of the interval (empty: none meaningful).
    pub ci_low: Option<f64>,
    /// Upper bound of the interval.
    pub ci_high: Option<f64>,
    /// Standard error of `value`, as the gate uses it (empty: none meaningful).
    pub se: Option<f64>,
    /// Confidence level of the interval (0.95), empty without one.
    pub level: Option<f64>,
    /// Why no interval is given, if that is the reason.
    pub caveat: Option<Caveat>,
}

/// A point estimate with a 95% confidence interval and standard error (`None` where none is
/// meaningful).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Interval {
    /// Point estimate.
    pub value: f64,
    /// Lower bound.
    pub low: Option<f64>,
    /// Upper bound.
    pub high: Option<f64>,
    /// Standard error of the point estimate.
    pub se: Option<f64>,
}

impl Interval {
    /// `value ± Z·se`.
    pub fn symmetric(value: f64, se: f64) -> Self {
        Interval {
            value,
            low: Some(value - Z * se),
            high: Some(value + Z * se),
            se: Some(se),
        }
    }

    /// A value with no interval.
    pub fn bare(value: f64) -> Self {
        Interval {
            value,
            low: None,
            high: None,
            se: None,
        }
    }

    /// An interval for a non-negative quantity estimated by `value` with standard error `se`:
    /// a scaled chi-square (Satterthwaite) with `2 value^2 / se^2` degrees of freedom, which
    /// never reaches below 0 and is skewed upwards as the sampling law of a variance is.
    pub fn non_negative(value: f64, se: f64) -> Self {
        if !(value >= 0.0 && se >= 0.0 && value.is_finite() && se.is_finite()) {
            return Interval::bare(value);
        }
        if value == 0.0 || se == 0.0 {
            // Every trial agreed (or the spread underflowed): the interval is the point.
            return Interval {
                value,
                low: Some(value),
                high: Some(value),
                se: Some(se),
            };
        }
        let df = 2.0 * (value / se).powi(2);
        let quantile = |p: f64| {
            ChiSquared::new(df)
                .map(|c| c.inverse_cdf(p))
                .unwrap_or(f64::NAN)
        };
        Interval {
            value,
            low: Some(value * df / quantile(1.0 - LEVEL_TAIL)),
            high: Some(value * df / quantile(LEVEL_TAIL)),
            se: Some(se),
        }
    }

    /// The interval mapped through an increasing function (e.g. a square root); `se` is the
    /// standard error of the mapped value.
    pub fn map(self, f: impl Fn(f64) -> f64, se: Option<f64>) -> Self {
        Interval {
            value: f(self.value),
            low: self.low.map(&f),
            high: self.high.map(&f),
            se,
        }
    }
}

/// Each tail of a two-sided 95% interval.
const LEVEL_TAIL: f64 = 0.025;

/// Confidence level of every interval.
pub const LEVEL: f64 = 0.95;

/// One-sided 95% Poisson lower bounds on the expected count after observing 1, 2 and 3
/// events: half the 5% quantile of a chi-square with 2, 4 and 6 degrees of freedom.
const POISSON_LOW: [f64; 3] = [
    0.051_293_294_387_550_5,
    0.355_361_510_698_662,
    0.817_691_447_163_953_4,
];

/// Wilson score interval for `successes` out of `trials` (docs/estimators.md §7), with Brown,
/// Cai and DasGupta's modification near the ends (Statistical Science 16(2), 2001, §4.1.1): at
/// 1, 2 or 3 successes (or failures) the Wilson end on that side is replaced by the one-sided
/// Poisson bound. Plain Wilson covers as little as 84% when the expected count is about 0.18
/// (one firefly seen where 0.18 were due); the modified interval stays at or above 92.7%.
pub fn wilson(successes: u64, trials: u64) -> Interval {
    let m = trials as f64;
    let p = successes as f64 / m;
    let z2 = Z * Z;
    let centre = (p + z2 / (2.0 * m)) / (1.0 + z2 / m);
    let half = Z * (p * (1.0 - p) / m + z2 / (4.0 * m * m)).sqrt() / (1.0 + z2 / m);
    let poisson = |count: u64| {
        POISSON_LOW
            .get((count as usize).wrapping_sub(1))
            .map(|l| l / m)
    };
    // At 0 or all successes the end on that side is exactly 0 or 1 (rounding would otherwise
    // leave 0.9999999999999999, excluding a true rate of 1).
    let low = match (successes, poisson(successes)) {
        (0, _) => 0.0,
        (_, Some(l)) if trials > 3 => l,
        _ => (centre - half).max(0.0),
    };
    let high = match (trials - successes, poisson(trials - successes)) {
        (0, _) => 1.0,
        (_, Some(l)) if trials > 3 => 1.0 - l,
        _ => (centre + half).min(1.0),
    };
    Interval {
        value: p,
        low: Some(low),
        high: Some(high),
        // The Wilson half-width over Z: never 0, even when no trial succeeded.
        se: Some(half / Z),
    }
}

/// Mergeable per-cell statistics of one estimator at one sample count.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CellAccumulator {
    estimate: Moments,
    squared_error: Moments,
    abs_rel_error: Moments,
    abs_rel_hist: LogHistogram,
    /// The relative estimates `X / mu` themselves, for how much of their spread a few trials
    /// carry.
    #[serde(default)]
    estimate_hist: LogHistogram,
    /// `|paired differences|` (absolute error, squared error) against the mean, for how much
    /// of their spread a few trials carry.
    #[serde(default)]
    paired_hists: [LogHistogram; 2],
    /// Paired difference of absolute relative error against the mean on the same trial.
    paired_abs_rel: Moments,
    /// Paired difference of squared error against the mean on the same trial.
    paired_squared: Moments,
    fireflies: u64,
    outlier_trials: u64,
    rejected: u64,
    /// Trials where this estimator gave a firefly and the mean did not.
    firefly_not_mean: u64,
    /// Trials where the mean gave a firefly and this estimator did not.
    mean_not_firefly: u64,
    /// A bound on `|X - mu|` a check tests (Chebyshev, median-of-means), if any.
    #[serde(with = "opt_f64_bits")]
    deviation_threshold: Option<f64>,
    /// Trials with `|X - mu| > deviation_threshold`.
    exceedances: u64,
}

/// One trial's observation for a cell.
#[derive(Debug, Clone, Copy)]
pub struct Observation {
    /// The estimator's estimate.
    pub estimate: f64,
    /// The plain mean's estimate on the same samples (for paired differences).
    pub mean_estimate: f64,
    /// Whether the trial's first n samples hold one at or above `n mu` ([Z] eq. 4).
    pub outlier: bool,
}

impl CellAccumulator {
    /// An empty cell that also counts trials whose error exceeds `threshold`.
    pub fn with_deviation_threshold(threshold: Option<f64>) -> Self {
        CellAccumulator {
            deviation_threshold: threshold,
            ..Self::default()
        }
    }

    /// The deviation bound being counted, and how many trials exceeded it.
    pub fn exceedances(&self) -> Option<(f64, u64)> {
        self.deviation_threshold.map(|t| (t, self.exceedances))
    }

    /// Discordant firefly pairs against the mean: (this estimator only, the mean only).
    pub fn firefly_discordance(&self) -> (u64, u64) {
        (self.firefly_not_mean, self.mean_not_firefly)
    }

    /// Trials whose estimate exceeded `(1 + tau) mu`.
    pub fn fireflies(&self) -> u64 {
        self.fireflies
    }

    /// Moments of the relative estimate `X / mu` (for checks).
    pub fn relative_estimate_moments(&self) -> &Moments {
        &self.estimate
    }

    /// Adds one trial against the true mean `mu` with firefly threshold `(1 + tau) mu`.
    ///
    /// Moments are kept on the relative estimate `X / mu`, so a law at scale 1e300 or
    /// 1e-300 accumulates numbers near 1; absolute metrics are scaled back at the end (and may
    /// then over- or underflow, which is what they are).
    pub fn push(&mut self, o: Observation, mu: f64, tau: f64) {
        let x = o.estimate / mu;
        let x_mean = o.mean_estimate / mu;
        let (err, mean_err) = (x - 1.0, x_mean - 1.0);
        let rel = err.abs();
        self.estimate.push(x);
        self.squared_error.push(err * err);
        self.abs_rel_error.push(rel);
        self.abs_rel_hist.push(rel);
        self.estimate_hist.push(x);
        self.paired_hists[0].push((rel - mean_err.abs()).abs());
        self.paired_hists[1].push((err * err - mean_err * mean_err).abs());
        self.paired_abs_rel.push(rel - mean_err.abs());
        self.paired_squared.push(err * err - mean_err * mean_err);
        let firefly = o.estimate > (1.0 + tau) * mu;
        let mean_firefly = o.mean_estimate > (1.0 + tau) * mu;
        self.fireflies += u64::from(firefly);
        self.firefly_not_mean += u64::from(firefly && !mean_firefly);
        self.mean_not_firefly += u64::from(mean_firefly && !firefly);
        if let Some(t) = self.deviation_threshold {
            self.exceedances += u64::from((o.estimate - mu).abs() > t);
        }
        self.outlier_trials += u64::from(o.outlier);
        self.rejected += u64::from(o.outlier && !firefly);
    }

    /// Adds another accumulator's trials.
    pub fn merge(&mut self, b: &CellAccumulator) {
        self.estimate.merge(&b.estimate);
        self.squared_error.merge(&b.squared_error);
        self.abs_rel_error.merge(&b.abs_rel_error);
        self.abs_rel_hist.merge(&b.abs_rel_hist);
        self.estimate_hist.merge(&b.estimate_hist);
        for (a, b) in self.paired_hists.iter_mut().zip(&b.paired_hists) {
            a.merge(b);
        }
        self.paired_abs_rel.merge(&b.paired_abs_rel);
        self.paired_squared.merge(&b.paired_squared);
        self.fireflies += b.fireflies;
        self.outlier_trials += b.outlier_trials;
        self.rejected += b.rejected;
        self.firefly_not_mean += b.firefly_not_mean;
        self.mean_not_firefly += b.mean_not_firefly;
        self.exceedances += b.exceedances;
    }

    /// Trials accumulated.
    pub fn trials(&self) -> u64 {
        self.estimate.count()
    }

    /// Every metric with its interval, from the trials alone; `None` with fewer than 4 trials
    /// (docs/estimators.md §7). What the law adds (exact values, tail-dominance) is applied by
    /// [`super::law`].
    pub fn metrics(&self, mu: f64) -> Option<CellMetrics> {
        let t = self.trials();
        if t < 4 {
            return None;
        }
        let tf = t as f64;
        let mu2 = mu * mu;
        // Relative units throughout; `* mu` and `* mu2` convert to sample units at the end.
        let s2 = self.estimate.sample_variance();
        let var_se = ((self.estimate.m4() - s2 * s2 * (tf - 3.0) / (tf - 1.0)) / tf)
            .max(0.0)
            .sqrt();
        let mse = self.squared_error.mean();
        let mae = self.abs_rel_error.mean();
        let mse_se = self.squared_error.standard_error();
        let mse_interval = Interval::non_negative(mse, mse_se);
        let rel_rmse = mse.sqrt();
        let relative_rmse = mse_interval.map(
            f64::sqrt,
            (rel_rmse > 0.0).then(|| mse_se / (2.0 * rel_rmse)),
        );
        let half_width = Z * tf.sqrt() / 2.0;
        let j = ((tf / 2.0 - half_width).floor() as u64).max(1);
        let k = ((1.0 + tf / 2.0 + half_width).ceil() as u64).min(t);
        let h = &self.abs_rel_hist;
        let median = if t % 2 == 1 {
            h.order_statistic(t / 2 + 1)
        } else {
            (h.order_statistic(t / 2) + h.order_statistic(t / 2 + 1)) / 2.0
        };
        let (low, high) = (h.order_statistic(j), h.order_statistic(k));
        Some(CellMetrics {
            trials: t,
            bias: Interval::symmetric(
                (self.estimate.mean() - 1.0) * mu,
                self.estimate.standard_error() * mu,
            ),
            variance: Interval::non_negative(s2, var_se).map(|v| v * mu2, Some(var_se * mu2)),
            mse: mse_interval.map(|v| v * mu2, Some(mse_se * mu2)),
            relative_rmse,
            median_abs_rel_error: Interval {
                value: median,
                low: Some(low),
                high: Some(high),
                // McKean and Schrader's standard error of a median: the distribution-free
                // interval's width over 2 Z.
                se: Some((high - low) / (2.0 * Z)),
            },
            mean_abs_rel_error: Interval::non_negative(mae, self.abs_rel_error.standard_error()),
            rel_error_quantiles: Metric::QUANTILES.map(|(q, m)| (m, h.quantile(q))),
            firefly_rate: wilson(self.fireflies, t),
            outlier_trials: self.outlier_trials,
            rejection_rate: (self.outlier_trials > 0)
                .then(|| wilson(self.rejected, self.outlier_trials)),
            paired_abs_rel_vs_mean: Interval::symmetric(
                self.paired_abs_rel.mean(),
                self.paired_abs_rel.standard_error(),
            ),
            paired_mse_vs_mean: Interval::symmetric(
                self.paired_squared.mean() * mu2,
                self.paired_squared.standard_error() * mu2,
            ),
            top_share: {
                let k = TAIL_EVENTS as u64;
                let (x, e) = (&self.estimate_hist, h);
                let centre = self.estimate.mean();
                TopShares {
                    deviation: [x.top_share(centre, k, 2), x.top_share(centre, k, 4)],
                    error: [
                        spread_share(
                            &self.abs_rel_error,
                            e.top_share_by(k, |a| (a - mae).powi(2)),
                        )
                        .max(e.top_share_by(k, |a| a)),
                        spread_share(
                            &self.squared_error,
                            e.top_share_by(k, |a| (a * a - mse).powi(2)),
                        )
                        .max(e.top_share_by(k, |a| a * a)),
                    ],
                    paired: self.paired_hists.each_ref().map(|h| {
                        // Differences at rounding level only: the estimator never parted from
                        // the mean in this run, so what it does when it does is unseen.
                        if h.quantile(1.0) <= ROUNDING_DIFFERENCE {
                            1.0
                        } else {
                            h.top_share(0.0, k, 2)
                        }
                    }),
                }
            },
        })
    }
}

/// All metrics of one cell, each with its interval.
#[derive(Debug, Clone, Serialize)]
pub struct CellMetrics {
    /// Number of trials T.
    pub trials: u64,
    /// `mean(X) - mu`.
    pub bias: Interval,
    /// Sample variance of the estimates (divisor T - 1).
    pub variance: Interval,
    /// Mean squared error against the true mean.
    pub mse: Interval,
    /// `sqrt(MSE) / mu` (delta-method interval).
    pub relative_rmse: Interval,
    /// Median of `|X - mu| / mu` (primary metric), order-statistic interval.
    pub median_abs_rel_error: Interval,
    /// Mean of `|X - mu| / mu`.
    pub mean_abs_rel_error: Interval,
    /// Quantiles of `|X - mu| / mu`, by metric.
    pub rel_error_quantiles: [(Metric, f64); 6],
    /// `P(X > (1 + tau) mu)`, Wilson interval.
    pub firefly_rate: Interval,
    /// Trials holding a sample at or above `n mu`.
    pub outlier_trials: u64,
    /// Among outlier trials, the fraction whose estimate stayed at or below `(1 + tau) mu`.
    pub rejection_rate: Option<Interval>,
    /// Mean over trials of `|X - mu|/mu - |mean - mu|/mu` (negative: better than the mean).
    pub paired_abs_rel_vs_mean: Interval,
    /// Mean over trials of `(X - mu)^2 - (mean - mu)^2` (negative: better than the mean).
    pub paired_mse_vs_mean: Interval,
    /// How much of the run's spread its [`TAIL_EVENTS`] most extreme trials carry.
    pub top_share: TopShares,
}

/// The largest paired difference against the mean (relative units) that is still rounding:
/// sums taken in another order differ by about 1e-16; an estimator that acts on a sample moves
/// its estimate by a sample over n, 1e-2 or more.
const ROUNDING_DIFFERENCE: f64 = 1e-12;

/// A spread's top share, or 1 when the moments saw no spread at all (values that sit inside
/// one histogram bin would otherwise look evenly spread).
fn spread_share(moments: &Moments, share: f64) -> f64 {
    if moments.sample_variance() > 0.0 {
        share
    } else {
        1.0
    }
}

/// Shares of a cell's second and fourth moments carried by its [`TAIL_EVENTS`] most extreme
/// trials: above 1/2, the run's spread rests on a handful of trials (or, at 1, on none).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct TopShares {
    /// Of `sum (X - mean X)^2` and `sum (X - mean X)^4`: behind bias and variance.
    pub deviation: [f64; 2],
    /// Behind the mean absolute error `a = |X - mu| / mu` and the MSE `a^2`: the larger of the
    /// share of the value (`sum a`, `sum a^2`) and of its spread (`sum (a - mean a)^2`,
    /// `sum (a^2 - mean a^2)^2`). The spread matters on its own: when every trial misses by
    /// the same amount (a MoN that returns 0 on a mostly black pixel) the run has seen none of
    /// the rare trials that carry the true MSE, and its interval would be a point.
    pub error: [f64; 2],
    /// Of `sum d^2` for the paired differences `d` against the mean (absolute error, squared
    /// error), taken around 0: a difference that is 0 but in a few trials rests on those; 1
    /// when no difference exceeds rounding (Zirr on `diffuse`: the truth, -3.6e-6, comes from
    /// rare trials where Zirr acts, and a run without one printed an interval of rounding noise).
    pub paired: [f64; 2],
}

#[cfg(test)]
mod tests {
    use super::*;

    fn accumulate(xs: &[f64], mu: f64) -> CellAccumulator {
        let mut acc = CellAccumulator::default();
        for &x in xs {
            let o = Observation {
                estimate: x,
                mean_estimate: mu,
                outlier: false,
            };
            acc.push(o, mu, 1.0);
        }
        acc
    }

    #[test]
    fn mse_decomposes_into_bias_and_variance() {
        let xs = [0.9, 1.3, 0.7, 1.1, 5.0, 0.95];
        let m = accumulate(&xs, 1.0).metrics(1.0).unwrap();
        let t = xs.len() as f64;
        let lhs = m.mse.value;
        let rhs = m.bias.value.powi(2) + (t - 1.0) / t * m.variance.value;
        assert!((lhs - rhs).abs() < 1e-12 * lhs, "{lhs} vs {rhs}");
        assert_eq!(m.firefly_rate.value, 1.0 / 6.0);
    }

    #[test]
    fn merged_moments_equal_single_pass() {
        let xs: Vec<f64> = (0..1000)
            .map(|i| ((i * 7919) % 1013) as f64 / 17.0)
            .collect();
        let mut all = Moments::default();
        xs.iter().for_each(|&x| all.push(x));
        let mut parts = Moments::default();
        for chunk in xs.chunks(37) {
            let mut m = Moments::default();
            chunk.iter().for_each(|&x| m.push(x));
            parts.merge(&m);
        }
        for (a, b) in [
            (all.mean, parts.mean),
            (all.m2, parts.m2),
            (all.m3, parts.m3),
            (all.m4, parts.m4),
        ] {
            assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "{a} vs {b}");
        }
        // Against a direct two-pass computation.
        let mean = xs.iter().sum::<f64>() / 1000.0;
        let m4: f64 = xs.iter().map(|x| (x - mean).powi(4)).sum::<f64>();
        assert!((all.m4 - m4).abs() < 1e-9 * m4);
    }

    #[test]
    fn wilson_reaches_the_bounds_exactly() {
        for m in [1, 7, 107, 122, 4096] {
            assert_eq!(wilson(m, m).high, Some(1.0), "{m}");
            assert_eq!(wilson(0, m).low, Some(0.0), "{m}");
        }
    }

    #[test]
    fn wilson_ends_use_poisson_bounds_at_one_to_three_events() {
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        for (k, &bound) in POISSON_LOW.iter().enumerate() {
            let chi = ChiSquared::new(2.0 * (k + 1) as f64).unwrap();
            let got = chi.inverse_cdf(0.05) / 2.0;
            assert!((got - bound).abs() < 1e-9, "{k}: {got} vs {bound}");
        }
        // One firefly in 4096 trials: the lower end is 0.0513/4096, not Wilson's 0.1765/4096,
        // so a true rate of 0.1/4096 is inside.
        let w = wilson(1, 4096);
        assert_eq!(w.low, Some(POISSON_LOW[0] / 4096.0));
        assert!(w.low.unwrap() < 0.1 / 4096.0 && w.high.unwrap() > 4.0 / 4096.0);
        // Mirrored at the other end; four events and more are plain Wilson.
        assert_eq!(wilson(4093, 4096).high, Some(1.0 - POISSON_LOW[2] / 4096.0));
        let plain = wilson(4, 4096);
        assert!(
            (plain.low.unwrap() * 4096.0 - 1.55).abs() < 0.05,
            "{plain:?}"
        );
    }

    #[test]
    fn wilson_matches_hand_computation() {
        // p = 0.5 over 100 trials: half-width 1.96*sqrt(0.0025 + 1.96^2/40000)/(1 + 1.96^2/100).
        let w = wilson(50, 100);
        let half = 1.96 * (0.0025f64 + 3.8416 / 40000.0).sqrt() / 1.038416;
        assert!((w.low.unwrap() - (0.5 - half)).abs() < 1e-12);
        assert!((w.high.unwrap() - (0.5 + half)).abs() < 1e-12);
    }

    #[test]
    fn median_interval_uses_order_statistics_within_a_bin() {
        // abs rel errors 0.01..1.00; j = floor(50 - 9.8) = 40, k = ceil(51 + 9.8) = 61.
        let xs: Vec<f64> = (1..=100).map(|i| 1.0 + i as f64 / 100.0).collect();
        let m = accumulate(&xs, 1.0).metrics(1.0).unwrap();
        let bin = 10f64.powf(1.0 / BINS_PER_DECADE);
        let within = |got: f64, want: f64| got / want < bin && want / got < bin;
        assert!(within(m.median_abs_rel_error.value, 0.505));
        // The ends are the 40th and 61st values, read inside their bins.
        let (low, high) = (
            m.median_abs_rel_error.low.unwrap(),
            m.median_abs_rel_error.high.unwrap(),
        );
        assert!(within(low, 0.40), "{low}");
        assert!(within(high, 0.61), "{high}");
        // Ten equal values in one bin still give an interval of positive width inside it.
        let mut h = LogHistogram::default();
        (0..10).for_each(|_| h.push(0.5));
        let (a, b) = (h.order_statistic(3), h.order_statistic(7));
        assert!(a < b && within(a, 0.5) && within(b, 0.5), "{a} {b}");
    }

    #[test]
    fn an_error_of_exactly_one_is_an_atom() {
        // Estimates of exactly 0 against mu = 1: every error is exactly 1, and so is the
        // interval (an atom, not a bin: 1, not the bin centre 1.012).
        let m = accumulate(&[0.0; 9], 1.0).metrics(1.0).unwrap();
        assert_eq!(m.median_abs_rel_error.value, 1.0);
        assert_eq!(m.median_abs_rel_error.low, Some(1.0));
        assert_eq!(m.median_abs_rel_error.high, Some(1.0));
        // Mixed with values on both sides, the atom sorts between bins -1 and 0.
        let mut h = LogHistogram::default();
        for x in [0.5, 1.0, 1.01, 0.0, 1.0] {
            h.push(x);
        }
        let order: Vec<f64> = (1..=5).map(|r| h.order_statistic(r)).collect();
        assert_eq!(order[0], 0.0);
        assert!((order[1] / 0.5 - 1.0).abs() < 0.012);
        assert_eq!((order[2], order[3]), (1.0, 1.0));
        assert!((order[4] / 1.01 - 1.0).abs() < 0.012);
    }

    #[test]
    fn variance_and_mse_intervals_stay_non_negative() {
        // One huge error among small ones: the symmetric interval would reach below 0.
        let mut xs = vec![1.0; 20];
        xs[3] = 40.0;
        let m = accumulate(&xs, 1.0).metrics(1.0).unwrap();
        for iv in [m.variance, m.mse, m.relative_rmse, m.mean_abs_rel_error] {
            assert!(
                iv.low.unwrap() >= 0.0 && iv.low.unwrap() < iv.value,
                "{iv:?}"
            );
            assert!(iv.high.unwrap() > iv.value, "{iv:?}");
        }
        // Against the chi-square quantiles by hand: df = 2 (v/se)^2 = 8 gives
        // [8 v / 17.5345, 8 v / 2.17973].
        let iv = Interval::non_negative(2.0, 1.0);
        assert!((iv.low.unwrap() - 16.0 / 17.534_546).abs() < 1e-5, "{iv:?}");
        assert!((iv.high.unwrap() - 16.0 / 2.179_731).abs() < 1e-5, "{iv:?}");
    }

    /// Paired differences at rounding level carry no evidence: the share is 1 (marked), while
    /// real differences spread over many trials are not; and an MSE where every trial missed by
    /// the same amount is marked through its spread, not its value.
    #[test]
    fn rounding_level_differences_and_constant_errors_are_no_evidence() {
        let push_all = |pairs: &[(f64, f64)]| {
            let mut acc = CellAccumulator::default();
            for &(estimate, mean_estimate) in pairs {
                let o = Observation {
                    estimate,
                    mean_estimate,
                    outlier: false,
                };
                acc.push(o, 1.0, 1.0);
            }
            acc.metrics(1.0).unwrap().top_share
        };
        let rounding: Vec<(f64, f64)> = (0..1000)
            .map(|i| {
                let m = 0.5 + i as f64 / 1000.0;
                (m * (1.0 + 2e-16), m)
            })
            .collect();
        assert_eq!(push_all(&rounding).paired, [1.0, 1.0]);
        let real: Vec<(f64, f64)> = (0..1000)
            .map(|i| {
                let m = 0.5 + i as f64 / 1000.0;
                (m * if i % 2 == 0 { 0.9 } else { 1.05 }, m)
            })
            .collect();
        let shares = push_all(&real).paired;
        assert!(shares.iter().all(|&s| s < 0.1), "{shares:?}");
        // Every trial returned 0: the error is exactly 1 everywhere.
        let zeros: Vec<(f64, f64)> = (0..1000).map(|i| (0.0, 0.5 + i as f64 / 1000.0)).collect();
        assert_eq!(push_all(&zeros).error, [1.0, 1.0]);
    }

    #[test]
    fn top_share_sees_a_run_resting_on_few_trials() {
        let mut h = LogHistogram::default();
        for _ in 0..1000 {
            h.push(0.1);
        }
        // Ten errors of 0.1 among a thousand: about 1% of the squares.
        assert!(
            h.top_share(0.0, 10, 2) < 0.011,
            "{}",
            h.top_share(0.0, 10, 2)
        );
        // No spread at all (every value exactly 0): nothing to estimate a spread from.
        let mut zeros = LogHistogram::default();
        (0..1000).for_each(|_| zeros.push(0.0));
        assert_eq!(zeros.top_share(0.0, 10, 2), 1.0);
        h.push(100.0);
        // One error of 100 carries nearly all of sum e^2 = 10 + 10^4.
        assert!(h.top_share(0.0, 10, 2) > 0.99);
    }

    #[test]
    fn metric_names_round_trip_and_unknown_names_are_errors() {
        for m in Metric::ALL {
            assert_eq!(m.name().parse::<Metric>(), Ok(m));
        }
        let e = "relative_bais".parse::<Metric>().unwrap_err();
        assert!(
            e.contains("relative_bais") && e.contains("relative_bias"),
            "{e}"
        );
    }

    #[test]
    fn histogram_merge_is_order_free() {
        let mut a = LogHistogram::default();
        let mut b = LogHistogram::default();
        [0.0, 1e-3, 2.0, 5e5].iter().for_each(|&x| a.push(x));
        [3.0, 0.0].iter().for_each(|&x| b.push(x));
        let mut ab = a.clone();
        ab.merge(&b);
        let mut ba = b.clone();
        ba.merge(&a);
        assert_eq!(ab, ba);
        assert_eq!(ab.count(), 6);
        assert_eq!(ab.order_statistic(2), 0.0);
    }
}
