//! NFOR: "Nonlinearly Weighted First-order Regression for Denoising Monte Carlo Renderings"
//! (Bitterli, Rousselle, Moon, Iglesias-Guitián, Adler, Mitchell, Jarosz, Novák; EGSR 2016).
//!
//! The pipeline, with the paper's section numbers:
//! 1. **Feature prefiltering (§5.1)**: each feature channel of half A is NL-means filtered with
//!    weights from half B (and B with A's), so that the filter of one half is independent of
//!    that half's own noise.
//! 2. **First-order regression (§5.2)**: each colour half is filtered by
//!    [`collaborative_regression`] on the *other* half's prefiltered features, with NL-means
//!    weights from the other half's colour, once per candidate bandwidth `k` (0.5 and 1).
//! 3. **MSE estimation and selection (§5.3)**: because the halves are independent, the squared
//!    difference between one half's filtered colour and the other half's noisy colour, less
//!    the noisy half's variance, estimates the filtered half's MSE; the average over both
//!    halves, less the residual variance `(f_B − f_A)²/4`, estimates the MSE of their average.
//!    These noisy estimates are NL-means filtered on the colour; each pixel and channel picks
//!    the bandwidth of least estimated MSE, and the 0/1 selection maps are filtered the same
//!    way and blend the candidates.
//! 4. **Second pass (§5.4)**: the blended halves are averaged; their halved difference gives
//!    the variance; the averaged features are filtered once more with themselves as guide; a
//!    last regression with `k` = 1 uses the first pass's output as its guide.
//!
//! Every parameter is a field of [`NforParams`]; [`NforParams::paper`] holds the paper's values
//! (those of its authors' released code where the paper is silent). What this implementation
//! chose where the paper leaves a choice open:
//! * **Variances are per half.** The renderer writes the variance of each half's mean, so the
//!   cross terms use the other half's own variance rather than twice the combined one.
//! * **Halves may differ by one sample** (odd spp): combined colour and variance weight each
//!   half by its sample count.
//! * **Guides of the MSE and selection filters** are the combined colour with its variance,
//!   per channel. **Features** are every channel of every feature buffer (normal 3, albedo 3,
//!   depth 1, visibility 1), each filtered on its own.
//! * **Bright details smaller than a patch stay where they are** (not in the paper nor in
//!   Bitterli's released code). A light one or two pixels wide, partly covering its pixels,
//!   gives them half variances thousands of times their neighbours', and the variance-cancelling
//!   distance then lets it look like anything: in the feature prefilter the backdrop around it
//!   took its features, and in the regression the light's own windows took the backdrop and
//!   spread a plane tilted by the light over it, while the backdrop's windows fitted the light
//!   through the leaked features. The result was black and bright blotches several pixels wide
//!   (`veach_mis` at 16 spp: relMSE 0.67 against the noisy input's 0.33). Two guards: the feature
//!   filters count the pixel pair's own distance ([`NlMeansParams::pair_distance`]), and the
//!   first pass's regressions see such a pixel's variance capped at a multiple of its
//!   neighbours' ([`detail_variances`]) where *both* halves show it with several samples in
//!   agreement. A firefly (one extreme sample, in one half or, rarely, both) fails that test and
//!   is treated as the paper treats it. Neither guard acts in the colour weights otherwise: a
//!   pair term there makes a half's filter follow the other half's own noise at the pixel and
//!   biases the MSE estimate low (to 0.2 of the true MSE in `tests/denoise.rs`).
//! * The NL-means and regression details are in [`super::nlmeans`] and [`super::regression`].

use super::nlmeans::{NlMeansParams, nl_means, nl_means_many};
use super::planes::Planes;
use super::regression::collaborative_regression;
use crate::error::{Error, Result};
use std::time::Instant;

/// Every parameter of NFOR.
#[derive(Debug, Clone, PartialEq)]
pub struct NforParams {
    /// Cross-half feature prefilter (§5.1): F = 3, R = 5, k = 0.5.
    pub prefilter: NlMeansParams,
    /// Patch and window radii of the regressions (§5.2): F = 3, R = 9 (7×7 patches in a
    /// 19×19 window); its `k` is unused, the bandwidths are [`Self::bandwidths`].
    pub regression: NlMeansParams,
    /// Candidate bandwidths of the first pass (§5.3): 0.5 and 1.
    pub bandwidths: Vec<f32>,
    /// Filter of the MSE estimates and selection maps (§5.3): F = 1, R = 9, k = 1.
    pub selection: NlMeansParams,
    /// Filter of the averaged features before the second pass (§5.4): F = 3, R = 2, k = 0.5.
    pub final_features: NlMeansParams,
    /// Bandwidth of the second pass (§5.4): 1.
    pub final_k: f32,
    /// Not in the paper: a pixel both halves show as a bright detail has its guide variance
    /// capped at this many times its neighbours' median in the first pass ([`detail_variances`]).
    pub detail_ratio: f32,
    /// Not in the paper: the least mean²/variance both halves must show at a bright detail (3:
    /// about three of a half's samples agree; one extreme sample gives about 1).
    pub detail_snr: f32,
}

impl NforParams {
    /// The paper's parameters.
    pub fn paper() -> Self {
        NforParams {
            prefilter: NlMeansParams {
                patch_radius: 3,
                window_radius: 5,
                k: 0.5,
                pair_distance: true,
            },
            regression: NlMeansParams {
                patch_radius: 3,
                window_radius: 9,
                k: 1.0,
                pair_distance: false,
            },
            bandwidths: vec![0.5, 1.0],
            selection: NlMeansParams {
                patch_radius: 1,
                window_radius: 9,
                k: 1.0,
                pair_distance: false,
            },
            final_features: NlMeansParams {
                patch_radius: 3,
                window_radius: 2,
                k: 0.5,
                pair_distance: true,
            },
            final_k: 1.0,
            detail_ratio: 16.0,
            detail_snr: 3.0,
        }
    }

    /// Checks the bandwidths (at least one, each finite and positive, as is `final_k`).
    pub fn check(&self) -> Result<()> {
        if self.bandwidths.is_empty() {
            return Err(Error::param("bandwidths", "[]", "NFOR needs at least one"));
        }
        for &k in self.bandwidths.iter().chain([&self.final_k]) {
            NlMeansParams::new(0, 0, k)?;
        }
        if !(self.detail_ratio.is_finite() && self.detail_ratio >= 1.0) {
            return Err(Error::param(
                "detail_ratio",
                self.detail_ratio,
                "must be finite and at least 1",
            ));
        }
        if !(self.detail_snr.is_finite() && self.detail_snr >= 0.0) {
            return Err(Error::param(
                "detail_snr",
                self.detail_snr,
                "must be finite and non-negative",
            ));
        }
        Ok(())
    }
}

/// One buffer in both halves: means and the variances of those means, A then B.
#[derive(Debug, Clone, PartialEq)]
pub struct Halves {
    /// Per-pixel mean of each half.
    pub mean: [Planes; 2],
    /// Per-pixel variance of that mean.
    pub var: [Planes; 2],
}

impl Halves {
    fn check(&self, name: &str, like: &Planes) -> Result<()> {
        let channels = self.mean[0].channels();
        for (h, half) in ["a", "b"].iter().enumerate() {
            for (p, kind) in [(&self.mean[h], "mean"), (&self.var[h], "variance")] {
                let what = format!("{name} half {half} {kind}");
                like.same_size(p, &what)?;
                if p.channels() != channels {
                    return Err(Error::param(
                        "channels",
                        format!("{what}: {}", p.channels()),
                        format!("must equal half a's mean: {channels}"),
                    ));
                }
                if let Some((c, i)) = p.first_non_finite() {
                    return Err(Error::param(
                        "values",
                        format!("{what}, channel {c}, pixel {i}"),
                        "must be finite",
                    ));
                }
            }
            if let Some(i) = self.var[h].all().iter().flatten().position(|&v| v < 0.0) {
                return Err(Error::param(
                    "values",
                    format!("{name} half {half} variance, value {i}"),
                    "must not be negative",
                ));
            }
        }
        Ok(())
    }
}

/// What NFOR reads: colour halves, their sample counts and the feature buffers.
#[derive(Debug, Clone, PartialEq)]
pub struct NforInput {
    /// The colour (or a robust estimate of it) of each half, with variances.
    pub color: Halves,
    /// Samples in halves A and B.
    pub counts: [u32; 2],
    /// Feature buffers by name, any number of channels each.
    pub features: Vec<(String, Halves)>,
}

/// One candidate bandwidth of the first pass.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Its bandwidth `k`.
    pub k: f32,
    /// The average of both filtered halves.
    pub filtered: Planes,
    /// The per-pixel, per-channel estimate of that average's MSE, before filtering.
    pub noisy_mse: Planes,
    /// The same, NL-means filtered (what selection compares).
    pub mse: Planes,
}

/// Seconds spent in each stage.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageSeconds {
    /// Feature prefiltering.
    pub prefilter: f64,
    /// First-pass regressions, all bandwidths, both halves.
    pub regression: f64,
    /// MSE filtering, selection and blending.
    pub selection: f64,
    /// Final feature filter and second-pass regression.
    pub second_pass: f64,
}

/// NFOR's output and what it estimated on the way.
#[derive(Debug, Clone, PartialEq)]
pub struct NforOutput {
    /// The denoised colour.
    pub image: Planes,
    /// The first pass per candidate bandwidth.
    pub candidates: Vec<Candidate>,
    /// Per candidate, its filtered selection weight (they sum to 1 per pixel and channel).
    pub selection: Vec<Planes>,
    /// Time per stage.
    pub seconds: StageSeconds,
}

/// Denoises `input` with NFOR. Errors name the buffer, half and pixel of inconsistent input.
pub fn nfor(input: &NforInput, params: &NforParams) -> Result<NforOutput> {
    params.check()?;
    let like = &input.color.mean[0];
    if like.channels() != 3 {
        return Err(Error::param(
            "channels",
            like.channels(),
            "colour must be RGB",
        ));
    }
    if like.is_empty() {
        return Err(Error::param("size", "0 pixels", "nothing to denoise"));
    }
    if input.counts.contains(&0) {
        return Err(Error::param(
            "spp",
            format!("{:?}", input.counts),
            "NFOR needs at least one sample in each half (spp >= 2)",
        ));
    }
    input.color.check("color", like)?;
    for (name, f) in &input.features {
        f.check(name, like)?;
    }
    let [na, nb] = input.counts.map(|n| n as f32);
    let (wa, wb) = (na / (na + nb), nb / (na + nb));
    let [ca, cb] = &input.color.mean;
    let [va, vb] = &input.color.var;
    let color = ca.zip_map(cb, |a, b| wa * a + wb * b);
    let color_var = va.zip_map(vb, |a, b| wa * wa * a + wb * wb * b);

    let mut seconds = StageSeconds::default();
    let t = Instant::now();
    let stack = |h: usize, var: bool| -> Result<Planes> {
        let parts: Vec<&Planes> = input
            .features
            .iter()
            .map(|(_, f)| if var { &f.var[h] } else { &f.mean[h] })
            .collect();
        if parts.is_empty() {
            Ok(Planes::zeros(like.width(), like.height(), 0))
        } else {
            Planes::stack(&parts)
        }
    };
    let (fa, fb, fva, fvb) = (
        stack(0, false)?,
        stack(1, false)?,
        stack(0, true)?,
        stack(1, true)?,
    );
    let pre_a = nl_means(&fa, &fb, &fvb, params.prefilter)?;
    let pre_b = nl_means(&fb, &fa, &fva, params.prefilter)?;
    seconds.prefilter = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let ks = &params.bandwidths;
    let [gva, gvb] = detail_variances(&input.color, params.detail_ratio, params.detail_snr);
    let filtered_a = collaborative_regression(ca, cb, &gvb, &pre_b, params.regression, ks)?;
    let filtered_b = collaborative_regression(cb, ca, &gva, &pre_a, params.regression, ks)?;
    seconds.regression = t.elapsed().as_secs_f64();
    let mut candidates = Vec::with_capacity(ks.len());
    let mut halves = Vec::with_capacity(ks.len());
    for ((&k, ra), rb) in ks.iter().zip(filtered_a).zip(filtered_b) {
        let mut noisy_mse = Planes::zeros(like.width(), like.height(), 3);
        for c in 0..3 {
            let out = noisy_mse.plane_mut(c);
            for (i, o) in out.iter_mut().enumerate() {
                let (a, b) = (ca.plane(c)[i], cb.plane(c)[i]);
                let (fa, fb) = (ra.plane(c)[i], rb.plane(c)[i]);
                let mse_a = (b - fa) * (b - fa) - vb.plane(c)[i];
                let mse_b = (a - fb) * (a - fb) - va.plane(c)[i];
                *o = 0.5 * (mse_a + mse_b) - 0.25 * (fb - fa) * (fb - fa);
            }
        }
        candidates.push(Candidate {
            k,
            filtered: ra.zip_map(&rb, |a, b| wa * a + wb * b),
            mse: Planes::zeros(0, 0, 0),
            noisy_mse,
        });
        halves.push((ra, rb));
    }

    let t = Instant::now();
    // One set of weights filters every candidate's MSE, another every selection map.
    let noisy: Vec<&Planes> = candidates.iter().map(|c| &c.noisy_mse).collect();
    let filtered = nl_means_many(&noisy, &color, &color_var, params.selection)?;
    for (cand, mse) in candidates.iter_mut().zip(filtered) {
        cand.mse = mse;
    }
    let (w, h) = (like.width(), like.height());
    let mut picks = Vec::with_capacity(candidates.len());
    for (i, _) in candidates.iter().enumerate() {
        let mut pick = Planes::zeros(w, h, 3);
        for c in 0..3 {
            for (p, v) in pick.plane_mut(c).iter_mut().enumerate() {
                let best = (0..candidates.len())
                    .min_by(|&x, &y| {
                        candidates[x].mse.plane(c)[p].total_cmp(&candidates[y].mse.plane(c)[p])
                    })
                    .unwrap_or(0);
                *v = if best == i { 1.0 } else { 0.0 };
            }
        }
        picks.push(pick);
    }
    let picks: Vec<&Planes> = picks.iter().collect();
    let selection = nl_means_many(&picks, &color, &color_var, params.selection)?;
    let blend = |half: usize| {
        let mut out = Planes::zeros(w, h, 3);
        for c in 0..3 {
            for (p, o) in out.plane_mut(c).iter_mut().enumerate() {
                let (mut s, mut n) = (0.0, 0.0);
                for (sel, hv) in selection.iter().zip(&halves) {
                    let r = if half == 0 { &hv.0 } else { &hv.1 };
                    s += sel.plane(c)[p] * r.plane(c)[p];
                    n += sel.plane(c)[p];
                }
                *o = s / n;
            }
        }
        out
    };
    let (res_a, res_b) = (blend(0), blend(1));
    drop(halves);
    seconds.selection += t.elapsed().as_secs_f64();

    let t = Instant::now();
    let feat = pre_a.zip_map(&pre_b, |a, b| 0.5 * (a + b));
    let feat_var = pre_a.zip_map(&pre_b, |a, b| 0.25 * (b - a) * (b - a));
    let final_features = nl_means(&feat, &feat, &feat_var, params.final_features)?;
    let combined = res_a.zip_map(&res_b, |a, b| wa * a + wb * b);
    let combined_var = res_a.zip_map(&res_b, |a, b| 0.25 * (b - a) * (b - a));
    let image = collaborative_regression(
        &combined,
        &combined,
        &combined_var,
        &final_features,
        params.regression,
        &[params.final_k],
    )?
    .remove(0);
    seconds.second_pass = t.elapsed().as_secs_f64();
    Ok(NforOutput {
        image,
        candidates,
        selection,
        seconds,
    })
}

/// The guide variances of the first pass: each half's colour variance, except at pixels both
/// halves show as a bright detail (module docs), where it is capped at `ratio` times the median
/// of its 8 neighbours' (same half and channel). A detail is a pixel whose variance exceeds
/// that cap in both halves and whose mean² is at least `snr` times its variance in both: several
/// of each half's samples agree, so the variance is the detail's own spread (a light partly
/// covering the pixel), not one extreme sample (a firefly, whose mean² is about its variance).
pub fn detail_variances(color: &Halves, ratio: f32, snr: f32) -> [Planes; 2] {
    let capped = |var: &Planes| -> Planes {
        let (w, h) = (var.width(), var.height());
        let mut out = var.clone();
        let mut near = Vec::with_capacity(8);
        for c in 0..var.channels() {
            let v = var.plane(c);
            for (i, o) in out.plane_mut(c).iter_mut().enumerate() {
                let (x, y) = (i % w, i / w);
                near.clear();
                for ny in y.saturating_sub(1)..(y + 2).min(h) {
                    for nx in x.saturating_sub(1)..(x + 2).min(w) {
                        if (nx, ny) != (x, y) {
                            near.push(v[ny * w + nx]);
                        }
                    }
                }
                near.sort_by(f32::total_cmp);
                if let Some(&m) = near.get(near.len() / 2) {
                    *o = v[i].min(ratio * m);
                }
            }
        }
        out
    };
    let caps = [capped(&color.var[0]), capped(&color.var[1])];
    let mut out = color.var.clone();
    for c in 0..3 {
        for i in 0..out[0].plane(c).len() {
            let detail = (0..2).all(|h| {
                let (m, v) = (color.mean[h].plane(c)[i], color.var[h].plane(c)[i]);
                caps[h].plane(c)[i] < v && m * m >= snr * v
            });
            if detail {
                for h in 0..2 {
                    out[h].plane_mut(c)[i] = caps[h].plane(c)[i];
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey3(w: usize, h: usize, f: impl Fn(usize) -> f32) -> Planes {
        let plane: Vec<f32> = (0..w * h).map(f).collect();
        Planes::from_planes(w, h, vec![plane.clone(), plane.clone(), plane]).unwrap()
    }

    /// A 5x5 backdrop (mean 0.1, variance 0.001) with, at pixel 12, a light seen by both halves
    /// (means 139 and 104, variances 2751 and 2581: three to five of eight samples on it) or a
    /// firefly (one sample of 800 in eight: mean 100, variance 10000, mean²/variance 1).
    fn halves(centre: [(f32, f32); 2]) -> Halves {
        let mean = centre.map(|(m, _)| grey3(5, 5, |i| if i == 12 { m } else { 0.1 }));
        let var = centre.map(|(_, v)| grey3(5, 5, |i| if i == 12 { v } else { 0.001 }));
        Halves { mean, var }
    }

    #[test]
    fn only_details_both_halves_agree_on_are_capped() {
        let light = halves([(139.0, 2751.0), (104.0, 2581.0)]);
        let [a, b] = detail_variances(&light, 16.0, 3.0);
        assert_eq!(a.plane(1)[12], 0.016);
        assert_eq!(b.plane(2)[12], 0.016);
        assert_eq!(a.plane(0)[11], 0.001, "the backdrop is untouched");
        // A firefly in one half, or one extreme sample in each: kept as the paper keeps it.
        for centre in [
            [(100.0, 10000.0), (0.1, 0.001)],
            [(100.0, 10000.0), (90.0, 8100.0)],
        ] {
            let [a, b] = detail_variances(&halves(centre), 16.0, 3.0);
            assert_eq!(a.plane(0)[12], centre[0].1);
            assert_eq!(b.plane(0)[12], centre[1].1);
        }
    }
}
