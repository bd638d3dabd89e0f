//! Fitting a generator to one real pixel's luminance stream, so the synthetic harness can be run
//! on the kind of samples a scene really produces. No I/O: the command line reads the stream.
//!
//! # The model
//!
//! A finite [`Mixture`](super::Mixture) of the crate's own laws, in this order:
//!
//! 1. **Zero mass** — a [`PointMass`] at 0 weighted by the fraction of samples exactly 0 (paths
//!    that found no light). Only present when some sample is 0.
//! 2. **Point masses** — a light seen directly, or an environment seen through specular
//!    bounces, returns (nearly) the same radiance every time. Two rules, applied in order, for
//!    at most [`MAX_ATOMS`] atoms in all ([`find_atoms`]):
//!    - *Clusters*: the densest window `[x, x (1 + NEAR_WIDTH)]` of positive samples holding
//!      at least a fraction [`NEAR_MIN_FRACTION`] of the stream (and [`ATOM_MIN_COUNT`]
//!      samples) becomes a point mass; repeated on what is left. A continuous law puts about
//!      `NEAR_WIDTH * density(ln x)` of its mass in such a window — under 1% unless the spread
//!      of `ln x` is below about 0.004, a law indistinguishable from a spike — whatever the
//!      stream's length. Real pixels need this rule: renderers store luminance as `f32`, so a
//!      nearly constant contribution (a light sampled by next-event estimation, a caustic
//!      spike through glass) lands on a handful of neighbouring `f32` values rather than on one.
//!    - *Exact repeats*: a remaining positive value occurring in at least [`ATOM_MIN_COUNT`]
//!      samples and at least a fraction [`ATOM_MIN_FRACTION`] of the stream, the most frequent
//!      first. Chance repeats of continuous `f32` values (2^23 per octave) are a few counts in a
//!      million samples, far below the fraction.
//!
//!    An atom sits on its samples' most frequent value, where they are, not between them at
//!    their mean; the difference (at most `NEAR_WIDTH` of the atom's value) goes into the mean
//!    of the heaviest body part, or, without a lognormal body, the atoms move to their means.
//! 3. **Pareto tail** — above a threshold `u` chosen by the rule of Clauset, Shalizi & Newman
//!    (2009, SIAM Review 51(4), §3.3): over candidate tail sizes `k` (the `k` largest continuous
//!    samples, at most half of them; the threshold is the next one down), fit the shape by
//!    Hill's estimator `a = k / sum ln(x_i / u)` and keep the `k` whose Pareto fit has the
//!    smallest Kolmogorov-Smirnov distance to the tail samples ([`choose_tail`]). The tail is
//!    kept when the continuous samples are heavier-tailed than a lognormal: when one lognormal
//!    below `u` spliced with the Pareto above it beats one lognormal for all by the Bayesian
//!    information criterion for the two extra parameters (`u` and `a`), a log-likelihood gain
//!    above `ln m`, `m` the number of continuous samples. The largest tail samples that the
//!    Pareto fit of the others makes wildly improbable become point masses of weight `1 / n`
//!    (outliers, [`Role::Outlier`]: a caustic path found once). The rest is a
//!    [`TruncatedPareto`] from `u` whose upper end is solved so that its mean equals its samples'
//!    mean ([`TailMeanRule`]); truncation keeps the mean finite whatever the Hill shape, so a
//!    tail with `a <= 1` is no obstacle.
//! 4. **Lognormal body** — the other continuous samples (all of them without a tail): a mixture
//!    of one to [`MAX_BODY_PARTS`] lognormals fitted by expectation-maximisation on the logs,
//!    the number of parts chosen by the Bayesian information criterion ([`fit_body`]). Each
//!    part then becomes the maximum-likelihood lognormal among those whose mean is its own
//!    (responsibility-weighted) samples' mean ([`mean_constrained`]; the unconstrained fit is
//!    reported as `mu_mle`, `sigma_mle`, and the two agree when the samples' mean is the fit's
//!    own). The crate has no lognormal truncated at `u`, so the body parts are untruncated,
//!    weighted by the samples they stand for: their small mass above `u` overlaps the tail's.
//!    That is the approximation: the mixture matches every part's mass and mean exactly, and
//!    its CDF near `u` is off by that overlap (it shows in [`Fit::ks_log`]). Continuous samples
//!    that are all equal are a point mass instead.
//!
//! Every weight is a sample fraction and every component's mean is its own samples' mean, so
//! **the fitted mean equals the stream's mean** up to rounding (relative 1e-9 or better): it is
//! finite and within any tolerance of the stream's.
//!
//! A stream of only zeros (a black pixel) is fitted exactly by the point mass at 0, mean 0
//! ([`Fit::is_black`]). The harness measures every estimator relative to the true mean
//! (relative bias, relative MSE), so on that generator its relative metrics are undefined (NaN);
//! the fit is still valid, and its mean equals the stream's.

use serde::Serialize;

use super::special::ln_norm_cdf;
use super::{ComponentSpec, Dist, DistSpec, LogNormal, PointMass, TruncatedPareto};
use crate::error::{Error, Result};

/// A positive value must repeat in at least this many samples to be an atom.
pub const ATOM_MIN_COUNT: usize = 3;
/// ... and in at least this fraction of the stream.
pub const ATOM_MIN_FRACTION: f64 = 1e-4;
/// The most lognormal parts of the body (see [`fit_body`]).
pub const MAX_BODY_PARTS: usize = 4;
/// The most iterations of expectation-maximisation for the body.
pub const EM_MAX_ITER: usize = 300;
/// EM stops when an iteration gains less than this log-likelihood per sample: far below the
/// `ln(m) / 2` per parameter that the choice of the number of parts weighs.
pub const EM_TOLERANCE: f64 = 1e-7;
/// The smallest variance of a body part's logs (a spread of 0.1%).
pub const EM_VAR_FLOOR: f64 = 1e-6;
/// The most samples EM runs on; longer bodies are thinned to evenly spaced order statistics.
pub const EM_MAX_SAMPLES: usize = 20_000;
/// Relative width of a cluster of nearly equal values: `[x, x (1 + NEAR_WIDTH)]`.
pub const NEAR_WIDTH: f64 = 1e-4;
/// A cluster of nearly equal values must hold at least this fraction of the stream.
pub const NEAR_MIN_FRACTION: f64 = 0.01;
/// The most atoms kept (the most frequent); a stream rounded to few digits would otherwise
/// turn into hundreds of point masses.
pub const MAX_ATOMS: usize = 16;
/// The fewest samples a Pareto tail is fitted to (Hill's standard error is `a / sqrt(k)`).
pub const TAIL_MIN_K: usize = 10;
/// The fewest samples left for the lognormal body when a tail is split off.
pub const BODY_MIN_N: usize = 10;
/// Every tail size up to this is a candidate; above it candidates are spaced geometrically
/// by [`K_GRID_RATIO`], so the search costs O(m log m) rather than O(m^2) on long streams.
pub const DENSE_K: usize = 1000;
/// Ratio between successive candidate tail sizes above [`DENSE_K`].
pub const K_GRID_RATIO: f64 = 1.01;
/// A tail maximum is an outlier when the Pareto fit to the samples below it expects fewer than
/// this many samples at least as large (see [`Role::Outlier`]).
pub const OUTLIER_P: f64 = 0.01;
/// The smallest Pareto shape the mean-matching rule will use (see [`TailMeanRule`]).
pub const MIN_SHAPE: f64 = 1e-3;

/// Hill's estimate of the tail index from the `k` largest samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Hill {
    /// Number of tail samples.
    pub k: usize,
    /// The threshold `u`: the largest sample below the tail.
    pub threshold: f64,
    /// `a = k / sum_{i <= k} ln(x_(i) / u)`.
    pub shape: f64,
    /// Asymptotic standard error `a / sqrt(k)`.
    pub se: f64,
}

/// Hill's estimator on `desc`, positive samples sorted in decreasing order: the tail is
/// `desc[..k]` and the threshold `desc[k]`.
///
/// # Errors
///
/// [`Error::InvalidParameter`] naming `k` when `k` is 0 or leaves no threshold sample
/// (`k >= desc.len()`), or when the tail does not lie strictly above a positive threshold
/// (`desc[k - 1] > desc[k] > 0`), the condition for a finite, positive estimate.
///
/// # Examples
///
/// ```
/// use fireflies::dist::fit::hill;
///
/// // ln(e^3) + ln(e^2) + ln(e^1) = 6 above u = 1: a = 3 / 6.
/// let desc = [3f64.exp(), 2f64.exp(), 1f64.exp(), 1.0];
/// let h = hill(&desc, 3)?;
/// assert!((h.shape - 0.5).abs() < 1e-15 && h.threshold == 1.0);
/// # Ok::<(), fireflies::Error>(())
/// ```
pub fn hill(desc: &[f64], k: usize) -> Result<Hill> {
    if k == 0 || k >= desc.len() {
        return Err(Error::param(
            "k",
            k,
            format!(
                "needs 1 <= k < {} (the sample count): the threshold is the (k+1)-th largest",
                desc.len()
            ),
        ));
    }
    let u = desc[k];
    if !(desc[k - 1] > u && u > 0.0) {
        return Err(Error::param(
            "k",
            k,
            format!(
                "the tail must lie strictly above a positive threshold, but the k-th largest \
                 sample is {} and the next {u}",
                desc[k - 1]
            ),
        ));
    }
    let ln_u = u.ln();
    let sum: f64 = desc[..k].iter().map(|x| x.ln() - ln_u).sum();
    let shape = k as f64 / sum;
    Ok(Hill {
        k,
        threshold: u,
        shape,
        se: shape / (k as f64).sqrt(),
    })
}

/// Kolmogorov-Smirnov distance between the tail samples `desc[..h.k]` and the Pareto law
/// `P(X > x) = (u / x)^a` fitted to them.
pub fn tail_ks(desc: &[f64], h: &Hill) -> f64 {
    let k = h.k as f64;
    let ln_u = h.threshold.ln();
    let mut d: f64 = 0.0;
    // desc[i] is the (k - i)-th smallest: the empirical CDF jumps from (k-i-1)/k to (k-i)/k.
    for (i, &x) in desc[..h.k].iter().enumerate() {
        let f = -(-h.shape * (x.ln() - ln_u)).exp_m1();
        let below = (h.k - i - 1) as f64 / k;
        let at = (h.k - i) as f64 / k;
        d = d.max((f - below).abs()).max((at - f).abs());
    }
    d
}

/// The threshold rule's choice: the tail size with the smallest KS distance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TailChoice {
    /// Hill's fit at the chosen size.
    pub hill: Hill,
    /// Its KS distance to the tail samples.
    pub ks: f64,
    /// How many tail sizes were tried.
    pub candidates: usize,
}

/// The candidate tail sizes for `m` continuous samples: every `k` from [`TAIL_MIN_K`] to
/// [`DENSE_K`], then a geometric grid, up to half the samples (a tail is the minority above
/// the body: on a multimodal stream the KS rule would otherwise take a Pareto across modes)
/// and leaving [`BODY_MIN_N`].
fn candidate_ks(m: usize) -> Vec<usize> {
    let Some(k_max) = m.checked_sub(BODY_MIN_N) else {
        return Vec::new();
    };
    let k_max = k_max.min(m / 2);
    let mut ks: Vec<usize> = (TAIL_MIN_K..=k_max.min(DENSE_K)).collect();
    let mut k = DENSE_K as f64;
    loop {
        k = (k * K_GRID_RATIO).ceil();
        if k > k_max as f64 {
            break;
        }
        ks.push(k as usize);
    }
    ks
}

/// The threshold rule (Clauset, Shalizi & Newman 2009): among the candidate tail sizes `k` of
/// `desc` (positive samples in decreasing order) whose tail lies strictly above its threshold,
/// the one whose Hill fit has the smallest KS distance to its tail samples; ties go to the
/// larger `k`. `None` when there is no candidate (fewer than `TAIL_MIN_K + BODY_MIN_N`
/// samples, or ties everywhere).
pub fn choose_tail(desc: &[f64]) -> Option<TailChoice> {
    let ks = candidate_ks(desc.len());
    let mut best: Option<TailChoice> = None;
    let mut tried = 0;
    for k in ks {
        let Ok(h) = hill(desc, k) else { continue };
        tried += 1;
        let ks = tail_ks(desc, &h);
        if best.is_none_or(|b| ks <= b.ks) {
            best = Some(TailChoice {
                hill: h,
                ks,
                candidates: 0,
            });
        }
    }
    best.map(|b| TailChoice {
        candidates: tried,
        ..b
    })
}

/// A point mass of the fit: a value repeated exactly, or a cluster of nearly equal values
/// (see the module docs), placed at the cluster's most frequent value.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Atom {
    /// Where the point mass sits: the value, or the cluster's most frequent value (see
    /// [`fit`] for where the difference from the cluster's mean goes).
    pub value: f64,
    /// The mean of the samples it stands for.
    pub mean: f64,
    /// Samples it stands for.
    pub count: usize,
    /// The smallest and largest of them (equal for an exact repeat).
    pub low: f64,
    /// See `low`.
    pub high: f64,
}

/// The atoms of `asc` (positive samples, increasing; `n` samples in the whole stream) and the
/// samples left continuous, by the rules of the module docs: first the densest windows
/// `[x, x (1 + NEAR_WIDTH)]` holding at least `NEAR_MIN_FRACTION` of the stream, one at a
/// time, then the most frequent exactly repeated values, up to [`MAX_ATOMS`] in all. Atoms come
/// back in increasing order of value.
pub fn find_atoms(asc: &[f64], n: usize) -> (Vec<Atom>, Vec<f64>) {
    let need = |fraction: f64| (fraction * n as f64).ceil().max(ATOM_MIN_COUNT as f64) as usize;
    let mut rest = asc.to_vec();
    let mut atoms = Vec::new();
    let near_min = need(NEAR_MIN_FRACTION);
    while atoms.len() < MAX_ATOMS {
        // The window holding the most samples (the first of equals).
        let (mut best, mut j) = ((0, 0), 0);
        for i in 0..rest.len() {
            let top = rest[i] * (1.0 + NEAR_WIDTH);
            j = j.max(i);
            while j < rest.len() && rest[j] <= top {
                j += 1;
            }
            if j - i > best.1 - best.0 {
                best = (i, j);
            }
        }
        let (i, j) = best;
        if j - i < near_min {
            break;
        }
        atoms.push(atom_of(&rest[i..j]));
        rest.drain(i..j);
    }
    let exact_min = need(ATOM_MIN_FRACTION);
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut i = 0;
    while i < rest.len() {
        let v = rest[i];
        let j = i + rest[i..].partition_point(|&x| x == v);
        if j - i >= exact_min {
            runs.push((i, j));
        }
        i = j;
    }
    runs.sort_by(|a, b| (b.1 - b.0).cmp(&(a.1 - a.0)).then(b.0.cmp(&a.0)));
    runs.truncate(MAX_ATOMS - atoms.len());
    runs.sort_by_key(|r| std::cmp::Reverse(r.0));
    for (i, j) in runs {
        atoms.push(atom_of(&rest[i..j]));
        rest.drain(i..j);
    }
    atoms.sort_by(|a, b| a.value.total_cmp(&b.value));
    (atoms, rest)
}

/// The atom standing for `xs` (increasing, not empty): at their most frequent value (the
/// smallest of equals), with their mean kept beside it.
fn atom_of(xs: &[f64]) -> Atom {
    let (low, high) = (xs[0], xs[xs.len() - 1]);
    let (mut mode, mut best, mut i) = (low, 0, 0);
    while i < xs.len() {
        let j = i + xs[i..].partition_point(|&x| x == xs[i]);
        if j - i > best {
            (mode, best) = (xs[i], j - i);
        }
        i = j;
    }
    Atom {
        value: mode,
        mean: if low == high { low } else { mean_of(xs) },
        count: xs.len(),
        low,
        high,
    }
}

/// One lognormal part of the body (see [`fit_body`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Body {
    /// Body samples it stands for: the sum of their responsibilities.
    pub count: f64,
    /// Location used in the generator; `exp(mu + sigma^2 / 2)` is `mean`.
    pub mu: f64,
    /// Spread used in the generator.
    pub sigma: f64,
    /// The mixture fit's location (the responsibility-weighted mean of the logs).
    pub mu_mle: f64,
    /// The mixture fit's spread (the responsibility-weighted spread of the logs).
    pub sigma_mle: f64,
    /// The generator's mean: `sample_mean`, plus the atoms' offsets for the heaviest part.
    pub mean: f64,
    /// The responsibility-weighted mean of the samples.
    pub sample_mean: f64,
}

/// How the tail's upper end (and, if need be, its shape) was set so that the tail
/// component's mean equals its samples' mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum TailMeanRule {
    /// Hill's shape kept; the upper end solved (always possible when the shape is <= 1, whose
    /// untruncated mean is infinite).
    Upper,
    /// Hill's shape above 1 gives an untruncated mean below the samples' mean (one huge
    /// sample): the upper end is the largest sample and the shape is lowered until the mean
    /// matches.
    Shape,
    /// Even the shape [`MIN_SHAPE`] up to the largest sample falls short (the tail samples
    /// crowd at its top): shape [`MIN_SHAPE`], upper end solved beyond the largest sample.
    ShapeAndUpper,
}

/// The Pareto tail as searched and, if kept, as fitted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tail {
    /// The threshold rule's choice (reported whether or not the tail is kept).
    pub choice: TailChoice,
    /// `ln L(body + tail) - ln L(lognormal)`, the log-likelihood gain of splitting off the
    /// tail, over the continuous samples.
    pub loglik_gain: f64,
    /// The gain needed to keep the tail: `ln m` (BIC for two extra parameters).
    pub loglik_needed: f64,
    /// The fitted component, when the gain suffices.
    pub fitted: Option<TailFit>,
}

/// The truncated Pareto of a kept tail.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TailFit {
    /// Lower end: the threshold.
    pub scale: f64,
    /// Shape used: Hill's unless the rule says otherwise.
    pub shape: f64,
    /// Upper end.
    pub upper: f64,
    /// The tail samples' mean, which the component's mean equals.
    pub mean: f64,
    /// How the mean was matched.
    pub rule: TailMeanRule,
    /// Hill's fit to the samples the component stands for (the tail less its outliers).
    pub hill: Hill,
    /// Tail samples set apart as outliers (see [`Role::Outlier`]).
    pub outliers: usize,
}

/// What a mixture component stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Role {
    /// Samples exactly 0.
    Zero,
    /// An exactly repeated positive value, or a cluster of nearly equal ones.
    Atom,
    /// The lognormal body (or a point mass when its samples are all equal).
    Body,
    /// The Pareto tail.
    Tail,
    /// A tail sample so far above the others that their Pareto fit expects fewer than
    /// [`OUTLIER_P`] such samples: a point mass of weight `1 / n` at its value (a rare spike,
    /// such as a caustic path found once), so that the Pareto fit describes the rest.
    Outlier,
}

/// One component of the fitted mixture.
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// What it stands for.
    pub role: Role,
    /// Samples it stands for, its weight being `count / n`: whole, except for lognormal body
    /// parts, which share the body samples by their responsibilities.
    pub count: f64,
    /// Its law.
    pub law: DistSpec,
    /// What the fit knows about it beyond its law.
    pub detail: Detail,
}

/// How a component was fitted, where there is more to say than its law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Detail {
    /// Nothing more: the zero mass, an outlier, or a body part whose samples are all equal.
    None,
    /// A point mass for repeated values.
    Atom(Atom),
    /// A lognormal body part.
    Body(Body),
    /// The Pareto tail.
    Tail(TailFit),
}

/// A generator fitted to a stream, with what it was fitted from.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    /// Samples in the stream.
    pub n: usize,
    /// The stream's mean.
    pub stream_mean: f64,
    /// The components, in mixture order: zero, atoms (increasing value), body parts
    /// (increasing), tail, outliers (decreasing value).
    pub components: Vec<Component>,
    /// The tail search, when there were enough continuous samples for one.
    pub tail: Option<Tail>,
    /// The fitted generator.
    pub dist: Dist,
    /// Kolmogorov-Smirnov distance between the fitted and the empirical CDF, on log scale (see
    /// [`ks_distance`]).
    pub ks_log: f64,
}

impl Fit {
    /// Whether every sample is 0: the fit is the point mass at 0, on which the harness's
    /// relative metrics are undefined.
    pub fn is_black(&self) -> bool {
        self.stream_mean == 0.0
    }

    /// The lognormal body parts (up to [`MAX_BODY_PARTS`]).
    pub fn bodies(&self) -> Vec<Body> {
        self.components
            .iter()
            .filter_map(|c| match c.detail {
                Detail::Body(b) => Some(b),
                _ => None,
            })
            .collect()
    }

    /// The point masses for repeated values.
    pub fn atoms(&self) -> Vec<Atom> {
        self.components
            .iter()
            .filter_map(|c| match c.detail {
                Detail::Atom(a) => Some(a),
                _ => None,
            })
            .collect()
    }

    /// The fitted generator's exact mean.
    pub fn mean(&self) -> f64 {
        self.dist.mean()
    }

    /// The generator as an experiment file names it: one law, or a mixture of the components
    /// weighted by their sample fractions.
    pub fn spec(&self) -> DistSpec {
        spec_of(&self.components, self.n)
    }

    /// The threshold of the tail QQ plot: the threshold rule's `u` when there was a search,
    /// else `None`.
    pub fn qq_threshold(&self) -> Option<f64> {
        self.tail.map(|t| t.choice.hill.threshold)
    }

    /// Points of the tail QQ plot: every sample above the threshold (in increasing order,
    /// atoms included) against the fitted law's quantile at the same plotting position
    /// `(j - 1/2) / K` of its conditional law above the threshold. `samples` is the stream the
    /// fit was made from, in any order. Empty when there was no tail search.
    pub fn tail_qq(&self, samples: &[f64]) -> Vec<(f64, f64)> {
        let Some(u) = self.qq_threshold() else {
            return Vec::new();
        };
        let mut above: Vec<f64> = samples.iter().copied().filter(|&x| x > u).collect();
        above.sort_by(f64::total_cmp);
        let k = above.len() as f64;
        let sf_u = self.dist.sf(u);
        above
            .iter()
            .enumerate()
            .map(|(j, &x)| {
                let p = (j as f64 + 0.5) / k;
                (conditional_quantile(&self.dist, u, sf_u, p), x)
            })
            .collect()
    }
}

/// The smallest `x > u` with `P(X > x | X > u) <= 1 - p`, by bisection in `ln x`.
fn conditional_quantile(dist: &Dist, u: f64, sf_u: f64, p: f64) -> f64 {
    let target = (1.0 - p) * sf_u;
    let mut lo = u.ln();
    let top = dist.support().1;
    let mut hi = if top.is_finite() {
        top.ln()
    } else {
        let mut h = lo + 1.0;
        while dist.sf(h.exp()) > target && h < 700.0 {
            h = lo + 2.0 * (h - lo);
        }
        h
    };
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if dist.sf(mid.exp()) > target {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-14 * hi.abs().max(1.0) {
            break;
        }
    }
    hi.exp()
}

fn spec_of(components: &[Component], n: usize) -> DistSpec {
    if let [only] = components {
        return only.law.clone();
    }
    DistSpec::Mixture {
        components: components
            .iter()
            .map(|c| ComponentSpec {
                weight: c.count / n as f64,
                dist: c.law.clone(),
            })
            .collect(),
    }
}

/// Kolmogorov-Smirnov distance `sup |F_fit - F_emp|` between `dist` and the empirical law of
/// `asc`, samples sorted in increasing order, counting atoms exactly (both the left limit and
/// the value at every sample are compared).
///
/// It is the distance on log scale too: KS is unchanged by the increasing map `x -> ln x`, so
/// the number is the same whether the CDFs are drawn against `x` or `ln x`. Zeros sit at
/// `ln 0 = -inf`, where both CDFs jump by their zero mass; the fit's zero mass equals the
/// stream's zero fraction, so zeros add nothing to the distance.
pub fn ks_distance(dist: &Dist, asc: &[f64]) -> f64 {
    let n = asc.len() as f64;
    let atoms = dist.atoms();
    let mut d: f64 = 0.0;
    let mut i = 0;
    while i < asc.len() {
        let v = asc[i];
        let mut j = i;
        while j < asc.len() && asc[j] == v {
            j += 1;
        }
        let at = dist.cdf(v);
        let mass: f64 = atoms.iter().filter(|a| a.0 == v).map(|a| a.1).sum();
        let before = (at - mass).max(0.0);
        d = d
            .max((before - i as f64 / n).abs())
            .max((at - j as f64 / n).abs());
        i = j;
    }
    d
}

/// Mean of `xs` (not empty).
fn mean_of(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len() as f64
}

/// Mean and maximum-likelihood spread of the logs of positive `xs` (not empty).
fn log_moments(xs: &[f64]) -> (f64, f64) {
    let m = xs.len() as f64;
    let mu = xs.iter().map(|x| x.ln()).sum::<f64>() / m;
    let var = xs
        .iter()
        .map(|x| {
            let d = x.ln() - mu;
            d * d
        })
        .sum::<f64>()
        / m;
    (mu, var.sqrt())
}

/// The maximum-likelihood lognormal `(mu, sigma)` of samples whose logs have mean `mu_mle`
/// and maximum-likelihood spread `sigma_mle`, among the lognormals with mean `mean`.
///
/// Writing `mu = ln(mean) - v / 2` with `v = sigma^2`, the log-likelihood per sample is
/// `-ln(v) / 2 - (s^2 + (v / 2 - delta)^2) / (2 v)` with `s = sigma_mle` and
/// `delta = ln(mean) - mu_mle`; setting its derivative to zero gives
/// `v^2 / 4 + v = s^2 + delta^2`, so `v = 2 (sqrt(1 + s^2 + delta^2) - 1)`. When the samples'
/// mean is the unconstrained fit's own mean (`delta = s^2 / 2`) this is `v = s^2`: the
/// constraint costs nothing. Moving `sigma` as well as `mu` keeps the fit near the samples'
/// median and spread where shifting `mu` alone would slide the whole law.
pub fn mean_constrained(mu_mle: f64, sigma_mle: f64, mean: f64) -> (f64, f64) {
    let ln_mean = mean.ln();
    let delta = ln_mean - mu_mle;
    let r = (sigma_mle * sigma_mle + delta * delta).sqrt();
    // sqrt(1 + r^2) - 1 without cancellation when r is small.
    let v = 2.0 * r * r / ((1.0 + r * r).sqrt() + 1.0);
    (ln_mean - 0.5 * v, v.sqrt())
}

/// Fits the model of the module docs to `samples` (any order).
///
/// # Errors
///
/// [`Error::EmptyStream`] for no samples; [`Error::InvalidSample`] for a NaN, infinite or
/// negative one, naming its index.
///
/// # Examples
///
/// ```
/// use fireflies::dist::fit::fit;
///
/// let f = fit(&[0.0, 0.0, 1.0, 2.0, 4.0, 8.0])?;
/// assert!((f.mean() - 2.5).abs() < 1e-12);
/// assert_eq!(f.components.len(), 2); // zero mass and lognormal body
/// # Ok::<(), fireflies::Error>(())
/// ```
pub fn fit(samples: &[f64]) -> Result<Fit> {
    if samples.is_empty() {
        return Err(Error::EmptyStream("the stream to fit".into()));
    }
    if let Some((index, &value)) = samples
        .iter()
        .enumerate()
        .find(|(_, x)| !(**x >= 0.0 && x.is_finite()))
    {
        return Err(Error::InvalidSample {
            index: index as u64,
            value,
        });
    }
    let n = samples.len();
    let mut asc = samples.to_vec();
    asc.sort_by(f64::total_cmp);
    let stream_mean = mean_of(&asc);
    let zeros = asc.partition_point(|&x| x == 0.0);
    if zeros == n {
        let components = vec![Component {
            role: Role::Zero,
            count: n as f64,
            law: DistSpec::PointMass { value: 0.0 },
            detail: Detail::None,
        }];
        return Ok(Fit {
            n,
            stream_mean,
            components,
            tail: None,
            dist: PointMass::ZERO.into(),
            ks_log: 0.0,
        });
    }
    let positive = &asc[zeros..];

    let (atoms, continuous) = find_atoms(positive, n);

    let mut components = Vec::new();
    if zeros > 0 {
        components.push(Component {
            role: Role::Zero,
            count: zeros as f64,
            law: DistSpec::PointMass { value: 0.0 },
            detail: Detail::None,
        });
    }
    for a in &atoms {
        components.push(Component {
            role: Role::Atom,
            count: a.count as f64,
            law: DistSpec::PointMass { value: a.value },
            detail: Detail::Atom(*a),
        });
    }
    // A cluster's atom sits on its most frequent value, where its samples are, rather than
    // between them at their mean (which would cost the KS distance the cluster's whole weight
    // for a shift of 1e-4); the body's mean takes up the difference. Without a lognormal body
    // the atoms move to their means instead.
    let excess: f64 = atoms
        .iter()
        .map(|a| a.count as f64 * (a.mean - a.value))
        .sum();
    let (tail, absorbed) = fit_continuous(&continuous, &mut components, excess)?;
    if !absorbed {
        for c in &mut components {
            if let Detail::Atom(a) = &mut c.detail {
                a.value = a.mean;
                c.law = DistSpec::PointMass { value: a.mean };
            }
        }
    }
    let spec = spec_of(&components, n);
    let dist = spec.build()?;
    let ks_log = ks_distance(&dist, &asc);
    Ok(Fit {
        n,
        stream_mean,
        components,
        tail,
        dist,
        ks_log,
    })
}

/// Fits the body and tail to the continuous samples `asc` (increasing), appending their
/// components. The largest lognormal body part's mean carries `excess` beyond its samples'
/// sum (the atoms' offsets from their means); the flag says whether it could.
fn fit_continuous(
    asc: &[f64],
    components: &mut Vec<Component>,
    excess: f64,
) -> Result<(Option<Tail>, bool)> {
    let m = asc.len();
    if m == 0 {
        return Ok((None, false));
    }
    let (_, sigma_all) = log_moments(asc);
    if !(sigma_all > 0.0) {
        // All equal (too few to be an atom): a point mass.
        components.push(Component {
            role: Role::Body,
            count: m as f64,
            law: DistSpec::PointMass { value: asc[0] },
            detail: Detail::None,
        });
        return Ok((None, false));
    }
    let desc: Vec<f64> = asc.iter().rev().copied().collect();
    let mut tail = None;
    let mut outliers = Vec::new();
    let mut split = m;
    if let Some(choice) = choose_tail(&desc) {
        let k = choice.hill.k;
        let (gain, needed) = tail_gain(
            &one_lognormal(asc),
            &one_lognormal(&asc[..m - k]),
            m,
            &choice.hill,
        );
        let fitted = if gain > needed {
            split = m - k;
            let (fitted, peeled) = fit_tail(&desc[..k], choice.hill.threshold);
            outliers = peeled;
            Some(fitted)
        } else {
            None
        };
        tail = Some(Tail {
            choice,
            loglik_gain: gain,
            loglik_needed: needed,
            fitted,
        });
    }
    let parts = fit_body(&asc[..split]).parts;
    // The atoms' offsets from their means go to the heaviest part (the first of equals).
    let heaviest = (0..parts.len())
        .rev()
        .max_by(|&i, &j| parts[i].count.total_cmp(&parts[j].count))
        .unwrap_or(0);
    let mut absorbed = false;
    for (i, mut part) in parts.into_iter().enumerate() {
        if i == heaviest {
            part.mean = part.sample_mean + excess / part.count;
        }
        (part.mu, part.sigma) = mean_constrained(part.mu_mle, part.sigma_mle, part.mean);
        match LogNormal::new(part.mu, part.sigma) {
            Ok(_) if part.mean > 0.0 => {
                absorbed |= i == heaviest;
                components.push(Component {
                    role: Role::Body,
                    count: part.count,
                    law: DistSpec::LogNormal {
                        mu: part.mu,
                        sigma: part.sigma,
                    },
                    detail: Detail::Body(part),
                });
            }
            _ => {
                // A spread too small (or too large) for an f64 lognormal: its mean as a point.
                PointMass::new(part.sample_mean)?;
                components.push(Component {
                    role: Role::Body,
                    count: part.count,
                    law: DistSpec::PointMass {
                        value: part.sample_mean,
                    },
                    detail: Detail::None,
                });
            }
        }
    }
    if let Some(t) = tail.and_then(|t| t.fitted) {
        components.push(Component {
            role: Role::Tail,
            count: t.hill.k as f64,
            law: DistSpec::TruncatedPareto {
                scale: t.scale,
                shape: t.shape,
                upper: t.upper,
            },
            detail: Detail::Tail(t),
        });
    }
    for x in outliers {
        components.push(Component {
            role: Role::Outlier,
            count: 1.0,
            law: DistSpec::PointMass { value: x },
            detail: Detail::None,
        });
    }
    Ok((tail, absorbed))
}

/// The body: a mixture of lognormals fitted to `asc` (positive samples, increasing) by
/// expectation-maximisation on their logs, with 1 to [`MAX_BODY_PARTS`] parts chosen by the
/// Bayesian information criterion (log-likelihood less `(3K - 1) / 2 ln m`). Real pixel bodies
/// are often multimodal (a light reached or occluded, an environment seen directly or through
/// a bounce), which one lognormal misdescribes. A mixture with a part standing for fewer than
/// [`BODY_MIN_N`] samples is not considered.
///
/// EM for `K` parts starts from the `K` runs of [`split_runs`] and stops when an iteration
/// gains less than `m` times [`EM_TOLERANCE`] in log-likelihood (at most [`EM_MAX_ITER`]
/// iterations); a part's variance of logs is kept at least [`EM_VAR_FLOOR`] (repeated values
/// would otherwise collapse it), and a part whose weight vanishes is dropped. Streams longer than
/// [`EM_MAX_SAMPLES`] are fitted on that many evenly spaced order statistics. A last
/// expectation step over all samples gives each part its responsibility-weighted count, log
/// moments and sample mean; the counts sum to `m` and the counts times the means to the
/// samples' sum, so parts fitted to their own means keep the body's mean exactly. Each part's
/// `mu`, `sigma` are left for the caller to set (from [`mean_constrained`]).
pub fn fit_body(asc: &[f64]) -> BodyFit {
    let m = asc.len();
    let stride = m.div_ceil(EM_MAX_SAMPLES).max(1);
    let thin: Vec<f64> = asc
        .iter()
        .skip(stride / 2)
        .step_by(stride)
        .copied()
        .collect();
    let logs: Vec<f64> = thin.iter().map(|x| x.ln()).collect();
    let mut best: Option<(Vec<Gauss>, f64)> = None;
    for runs in split_runs(&logs) {
        let k = runs.len() as f64;
        let init = runs.iter().map(|r| Gauss::of(r, logs.len())).collect();
        let (parts, ll) = em(&logs, init);
        // A part must stand for BODY_MIN_N samples (of the thinned set when thinned).
        let smallest = parts.iter().map(|g| g.weight).fold(1.0, f64::min);
        if runs.len() > 1 && smallest * (logs.len() as f64) < BODY_MIN_N as f64 {
            continue;
        }
        let bic = ll - 0.5 * (3.0 * k - 1.0) * (logs.len() as f64).ln();
        if best.as_ref().is_none_or(|b| bic > b.1) {
            best = Some((parts, bic));
        }
    }
    let parts = best.map(|b| b.0).unwrap_or_default();
    // The last expectation step, over every sample.
    let mut acc = vec![[0.0f64; 4]; parts.len()];
    let mut l = vec![0.0; parts.len()];
    let mut loglik = 0.0;
    for &x in asc {
        let y = x.ln();
        loglik += responsibilities(&parts, y, &mut l);
        for (a, r) in acc.iter_mut().zip(&l) {
            a[0] += r;
            a[1] += r * y;
            a[2] += r * y * y;
            a[3] += r * x;
        }
    }
    let parts = acc
        .iter()
        .filter(|a| a[0] > 0.0)
        .map(|a| {
            let mu = a[1] / a[0];
            let var = (a[2] / a[0] - mu * mu).max(0.0);
            Body {
                count: a[0],
                mu: 0.0,
                sigma: 0.0,
                mu_mle: mu,
                sigma_mle: var.max(EM_VAR_FLOOR).sqrt(),
                mean: a[3] / a[0],
                sample_mean: a[3] / a[0],
            }
        })
        .collect();
    BodyFit { parts, loglik }
}

/// The body's lognormal mixture and its fit.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyFit {
    /// The parts, in increasing order of location as EM left them.
    pub parts: Vec<Body>,
    /// Log-likelihood of all the body samples' logs under the mixture.
    pub loglik: f64,
}

impl BodyFit {
    /// Free parameters: a location, a spread and a weight per part, less one weight.
    pub fn parameters(&self) -> usize {
        (3 * self.parts.len()).saturating_sub(1)
    }

    /// `ln P(X <= u)` under the mixture (of the parts' fitted logs, weighted by their counts).
    pub fn ln_cdf(&self, u: f64) -> f64 {
        let total: f64 = self.parts.iter().map(|p| p.count).sum();
        let ln_u = u.ln();
        // A sum of logs, so that a far-off threshold does not underflow to ln 0.
        let terms: Vec<f64> = self
            .parts
            .iter()
            .map(|p| (p.count / total).ln() + ln_norm_cdf((ln_u - p.mu_mle) / p.sigma_mle))
            .collect();
        let top = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        top + terms.iter().map(|t| (t - top).exp()).sum::<f64>().ln()
    }
}

/// A normal part of the mixture of logs.
#[derive(Clone, Copy, Debug)]
struct Gauss {
    weight: f64,
    mu: f64,
    var: f64,
}

impl Gauss {
    /// The maximum-likelihood normal of `ys`, weighted `ys.len() / m`.
    fn of(ys: &[f64], m: usize) -> Self {
        let n = ys.len() as f64;
        let mu = ys.iter().sum::<f64>() / n;
        let var = ys.iter().map(|y| (y - mu) * (y - mu)).sum::<f64>() / n;
        Gauss {
            weight: n / m as f64,
            mu,
            var: var.max(EM_VAR_FLOOR),
        }
    }
}

/// Fills `r` with the parts' responsibilities for `y`; returns `ln` of the mixture density.
fn responsibilities(parts: &[Gauss], y: f64, r: &mut [f64]) -> f64 {
    let ln_2pi = std::f64::consts::TAU.ln();
    let mut top = f64::NEG_INFINITY;
    for (g, ri) in parts.iter().zip(r.iter_mut()) {
        let d = y - g.mu;
        *ri = g.weight.ln() - 0.5 * (ln_2pi + g.var.ln()) - 0.5 * d * d / g.var;
        top = top.max(*ri);
    }
    let mut sum = 0.0;
    for ri in r.iter_mut() {
        *ri = (*ri - top).exp();
        sum += *ri;
    }
    r.iter_mut().for_each(|ri| *ri /= sum);
    top + sum.ln()
}

/// Expectation-maximisation for a normal mixture of `ys` from `parts`; returns the parts and
/// the log-likelihood at them.
fn em(ys: &[f64], mut parts: Vec<Gauss>) -> (Vec<Gauss>, f64) {
    let m = ys.len() as f64;
    let centre = ys.iter().sum::<f64>() / m;
    let mut previous = f64::NEG_INFINITY;
    let mut r = vec![0.0; parts.len()];
    for _ in 0..EM_MAX_ITER {
        let mut acc = vec![[0.0f64; 3]; parts.len()];
        let mut ll = 0.0;
        r.resize(parts.len(), 0.0);
        for &y in ys {
            ll += responsibilities(&parts, y, &mut r);
            let d = y - centre;
            for (a, ri) in acc.iter_mut().zip(&r) {
                a[0] += ri;
                a[1] += ri * d;
                a[2] += ri * d * d;
            }
        }
        if ll - previous < EM_TOLERANCE * m {
            return (parts, ll.max(previous));
        }
        previous = ll;
        parts = acc
            .iter()
            .filter(|a| a[0] > 1e-9 * m)
            .map(|a| {
                let mean = a[1] / a[0];
                Gauss {
                    weight: a[0] / m,
                    mu: centre + mean,
                    var: (a[2] / a[0] - mean * mean).max(EM_VAR_FLOOR),
                }
            })
            .collect();
    }
    let ll = ys
        .iter()
        .map(|&y| responsibilities(&parts, y, &mut r))
        .sum();
    (parts, ll)
}

/// Starting points for EM: `ys` (increasing) as 1 run, then cut at the best split of
/// [`split_body`] of any run, the run gaining most each time, up to [`MAX_BODY_PARTS`] runs
/// (fewer when no run can be split).
pub fn split_runs(ys: &[f64]) -> Vec<Vec<&[f64]>> {
    let mut runs = vec![ys];
    let mut all = vec![runs.clone()];
    while runs.len() < MAX_BODY_PARTS {
        let best = runs
            .iter()
            .enumerate()
            .filter_map(|(i, p)| split_body(p).map(|(s, gain)| (i, s, gain)))
            .max_by(|a, b| a.2.total_cmp(&b.2));
        let Some((i, s, _)) = best else { break };
        let (a, b) = runs[i].split_at(s);
        runs.splice(i..=i, [a, b]);
        all.push(runs.clone());
    }
    all
}

/// The best place to cut `ys` (logs of samples, increasing) in two normal runs, with its
/// classification log-likelihood gain over one normal: the cut `ys[..s]`, `ys[s..]` (each at
/// least [`BODY_MIN_N`] values, between unequal ones) maximising
/// `sum_runs [-(n_j / 2) ln v_j + n_j ln(n_j / m)]`, `v_j` the run's variance. `None` when no
/// cut leaves two runs with a spread.
pub fn split_body(ys: &[f64]) -> Option<(usize, f64)> {
    let m = ys.len();
    if m < 2 * BODY_MIN_N {
        return None;
    }
    let centre = ys.iter().sum::<f64>() / m as f64;
    // Prefix sums of the centred values and their squares.
    let (mut s1, mut s2) = (vec![0.0; m + 1], vec![0.0; m + 1]);
    for (i, y) in ys.iter().enumerate() {
        let d = y - centre;
        s1[i + 1] = s1[i] + d;
        s2[i + 1] = s2[i] + d * d;
    }
    let var = |a: usize, b: usize| {
        let n = (b - a) as f64;
        let mean = (s1[b] - s1[a]) / n;
        (s2[b] - s2[a]) / n - mean * mean
    };
    let mf = m as f64;
    let v_all = var(0, m);
    if !(v_all > 0.0) {
        return None;
    }
    let one = -0.5 * mf * v_all.ln();
    let mut best: Option<(usize, f64)> = None;
    for s in BODY_MIN_N..=m - BODY_MIN_N {
        if ys[s - 1] == ys[s] {
            continue;
        }
        let (va, vb) = (var(0, s), var(s, m));
        // Rounding can leave a tiny or negative variance for a near-constant run.
        if !(va > 1e-12 * v_all && vb > 1e-12 * v_all) {
            continue;
        }
        let (na, nb) = (s as f64, (m - s) as f64);
        let ll =
            -0.5 * na * va.ln() - 0.5 * nb * vb.ln() + na * (na / mf).ln() + nb * (nb / mf).ln();
        if best.is_none_or(|(_, b)| ll > b) {
            best = Some((s, ll));
        }
    }
    best.map(|(s, ll)| (s, ll - one))
}

/// One lognormal fitted to `asc` by maximum likelihood, as a [`BodyFit`] of one part (`mu`,
/// `sigma` left at 0 like [`fit_body`]'s): what the tail decision compares against.
fn one_lognormal(asc: &[f64]) -> BodyFit {
    let m = asc.len() as f64;
    let (mu, sigma) = log_moments(asc);
    let sample_mean = mean_of(asc);
    BodyFit {
        parts: vec![Body {
            count: m,
            mu: 0.0,
            sigma: 0.0,
            mu_mle: mu,
            sigma_mle: sigma,
            mean: sample_mean,
            sample_mean,
        }],
        // At the maximum-likelihood fit the squares sum to m sigma^2.
        loglik: -m * sigma.ln() - 0.5 * m * std::f64::consts::TAU.ln() - 0.5 * m,
    }
}

/// The log-likelihood gain of splitting a Pareto tail off the `m` continuous samples, and the
/// gain the Bayesian information criterion asks for, over the logs of the samples. Without a
/// tail every sample is drawn from the lognormal (mixture) `whole`; with one, the `m - k` body
/// samples from the one `body` fitted to them, renormalised below the threshold `u`, and
/// the `k` tail samples from Hill's Pareto (whose log-likelihood on logs is `k ln a - k` at
/// Hill's estimate), with weights `(m - k) / m` and `k / m`. The tail adds two parameters (`u`
/// and `a`) to the body's; each parameter asks for `ln(m) / 2`.
fn tail_gain(whole: &BodyFit, body: &BodyFit, m: usize, h: &Hill) -> (f64, f64) {
    let (mf, k) = (m as f64, h.k as f64);
    let b = mf - k;
    let ll_body = body.loglik - b * body.ln_cdf(h.threshold);
    let ll_tail = k * h.shape.ln() - k;
    let ll_weights = b * (b / mf).ln() + k * (k / mf).ln();
    let gain = ll_body + ll_tail + ll_weights - whole.loglik;
    let extra = (body.parameters() + 2) as f64 - whole.parameters() as f64;
    let gain = if gain.is_nan() {
        f64::NEG_INFINITY
    } else {
        gain
    };
    (gain, 0.5 * extra * mf.ln())
}

/// Peels outliers off `tail` (the tail samples, decreasing, all above `u`), then fits the
/// truncated Pareto from `u` to the rest whose mean is the rest's mean, by the first
/// [`TailMeanRule`] that can reach it. Returns the fit and the outliers (decreasing).
///
/// The largest remaining sample `x` is an outlier when the Hill fit `a` of the samples below it
/// expects fewer than [`OUTLIER_P`] samples as large among all of them: `k (u / x)^a <
/// OUTLIER_P`, `k` counting `x` too. Under a true Pareto tail `k (u / x_max)^a` is about a
/// standard exponential, so its maximum is called an outlier with probability about
/// `OUTLIER_P`. At least [`TAIL_MIN_K`] samples stay in the tail.
fn fit_tail(tail: &[f64], u: f64) -> (TailFit, Vec<f64>) {
    let ln_u = u.ln();
    let hill_of = |xs: &[f64]| -> Hill {
        let k = xs.len();
        let shape = k as f64 / xs.iter().map(|x| x.ln() - ln_u).sum::<f64>();
        Hill {
            k,
            threshold: u,
            shape,
            se: shape / (k as f64).sqrt(),
        }
    };
    let mut start = 0;
    while tail.len() - start > TAIL_MIN_K {
        let below = hill_of(&tail[start + 1..]);
        let k = (tail.len() - start) as f64;
        let expected = k * (-below.shape * (tail[start].ln() - ln_u)).exp();
        if !(expected < OUTLIER_P) {
            break;
        }
        start += 1;
    }
    let (outliers, kept) = tail.split_at(start);
    let h = hill_of(kept);
    let target = mean_of(kept);
    let x_max = kept[0];
    let done = |shape: f64, upper: f64, rule| TailFit {
        scale: u,
        shape,
        upper,
        mean: target,
        rule,
        hill: h,
        outliers: start,
    };
    let fitted = if let Some(upper) = solve_upper(u, h.shape, target) {
        done(h.shape, upper, TailMeanRule::Upper)
    } else if let Some(shape) = solve_shape(u, x_max, h.shape, target) {
        done(shape, x_max, TailMeanRule::Shape)
    } else {
        // The mean at MIN_SHAPE rises without bound in the upper end.
        let upper = solve_upper(u, MIN_SHAPE, target).unwrap_or(x_max);
        done(MIN_SHAPE, upper, TailMeanRule::ShapeAndUpper)
    };
    (fitted, outliers.to_vec())
}

/// The shape in `[MIN_SHAPE, shape_max]` with `TruncatedPareto(u, shape, upper).mean() ==
/// target`, if one exists (the mean falls as the shape rises).
fn solve_shape(u: f64, upper: f64, shape_max: f64, target: f64) -> Option<f64> {
    let mean_at = |a: f64| TruncatedPareto::new(u, a, upper).ok().map(|d| d.mean());
    if !(mean_at(MIN_SHAPE)? >= target && mean_at(shape_max)? <= target) {
        return None;
    }
    let (mut lo, mut hi) = (MIN_SHAPE.ln(), shape_max.ln());
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mean_at(mid.exp())? >= target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let shape = lo.exp();
    let mean = mean_at(shape)?;
    ((mean - target).abs() <= 1e-9 * target).then_some(shape)
}

/// The upper end `U` with `TruncatedPareto(u, shape, U).mean() == target`, if one exists
/// (the mean rises from `u` as `U` grows, towards `u shape / (shape - 1)` or without bound).
fn solve_upper(u: f64, shape: f64, target: f64) -> Option<f64> {
    if !(target > u) {
        return None;
    }
    let mean_at = |z: f64| {
        TruncatedPareto::new(u, shape, u * z.exp())
            .ok()
            .map(|d| d.mean())
    };
    // Largest z with u e^z finite, less a margin for the mean's own range.
    let z_max = (f64::MAX / u).ln() - 1.0;
    let mut hi = 1.0f64.min(z_max);
    loop {
        match mean_at(hi) {
            Some(m) if m >= target => break,
            Some(_) if hi < z_max => hi = (2.0 * hi).min(z_max),
            _ => return None,
        }
    }
    let mut lo = 0.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        match mean_at(mid) {
            Some(m) if m < target => lo = mid,
            _ => hi = mid,
        }
    }
    let upper = u * hi.exp();
    let mean = TruncatedPareto::new(u, shape, upper).ok()?.mean();
    ((mean - target).abs() <= 1e-9 * target).then_some(upper)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_are_dense_then_geometric() {
        assert!(candidate_ks(19).is_empty());
        assert_eq!(candidate_ks(20), vec![10]);
        assert_eq!(*candidate_ks(25).last().unwrap(), 12);
        let ks = candidate_ks(100_000);
        assert_eq!(ks[..3], [10, 11, 12]);
        assert_eq!(ks[990], 1000);
        assert_eq!(ks[991], 1010);
        assert!(*ks.last().unwrap() <= 50_000);
        assert!(ks.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn tail_ks_of_exact_quantiles() {
        // Pareto quantiles at the midpoints (i - 1/2) / k: the KS distance is exactly 1/(2k)
        // when the shape and threshold are the true ones.
        let (u, a, k) = (2.0, 1.5, 8usize);
        let mut desc: Vec<f64> = (0..k)
            .map(|i| u * (1.0 - (i as f64 + 0.5) / k as f64).powf(-1.0 / a))
            .collect();
        desc.reverse();
        desc.push(u);
        let h = Hill {
            k,
            threshold: u,
            shape: a,
            se: 0.0,
        };
        assert!((tail_ks(&desc, &h) - 1.0 / 16.0).abs() < 1e-12);
    }

    #[test]
    fn solve_upper_hits_the_target_or_says_none() {
        let u = 1.0;
        for (shape, target) in [(0.5, 3.0), (1.0, 50.0), (2.0, 1.9), (0.2, 1e6)] {
            let upper = solve_upper(u, shape, target).unwrap();
            let m = TruncatedPareto::new(u, shape, upper).unwrap().mean();
            assert!((m - target).abs() < 1e-9 * target, "{shape} {target} {m}");
        }
        // Shape 2 cannot reach a mean above 2 (its untruncated mean), nor one at or below u.
        assert_eq!(solve_upper(u, 2.0, 2.001), None);
        assert_eq!(solve_upper(u, 2.0, 1.0), None);
    }
}
