//! NFOR's collaborative first-order regression (Bitterli et al. 2016, §4 and §5.2).
//!
//! For every pixel `c`, the colour in its `(2R+1)²` window is fitted by weighted least squares
//! as an affine function of the pixel offset and of the feature buffers; the weights are the
//! NL-means weights of each neighbour's colour patch against `c`'s, from a guide image. The
//! fitted model is evaluated at *every* pixel of the window, and each pixel's output is the
//! weighted average of all the predictions made for it (collaborative filtering, as in Moon
//! et al.'s weighted local regression).
//!
//! Choices the paper leaves open, as made here:
//! * **Weights from several channels**: one weight per neighbour, the smallest of the colour
//!   channels' NL-means weights (the largest channel distance), as in Bitterli's released code.
//! * **Design matrix**: a constant, the offsets `Δx`, `Δy`, and each feature channel minus its
//!   value at `c`, every non-constant column divided by its largest magnitude in the window
//!   (so columns lie in `[−1, 1]`). This "normalisation in the window" does not change the fit
//!   in exact arithmetic (the columns span the same space); it keeps the normal equations well
//!   scaled. A column that is exactly constant in the window is dropped.
//! * **Solver**: the normal equations `XᵀWX β = XᵀWY` in `f64`, by Cholesky (nalgebra), with a
//!   ridge of [`RIDGE`]·Σw on the non-constant columns so that nearly collinear features (the
//!   three normal components on a plane) stay solvable. Released code used pivoted QR; the
//!   ridge moves a prediction by about `RIDGE` relative to the colour range. Should Cholesky
//!   still fail, the pixel falls back to its weighted mean.
//! * Neighbours whose weight underflows to 0 take no part (they would add nothing).
//! * **Predictions stay within the window's colours** (not in the paper): each window's fitted
//!   values are clamped, per channel, to the range of the colours of the pixels it was fitted
//!   on (those of non-zero weight). A plane tilted by a few bright pixels (a caustic's fireflies
//!   at 16 spp) otherwise extrapolates below zero on the window's far side: `caustic`'s NFOR
//!   output had 764 negative pixels at 16 spp, a black hole between the sphere and the caustic
//!   where the floor is grey, and none with the clamp (relMSE 3.19 and 3.37 against the noisy
//!   3.5·10¹: the clamp removes the hole, not the caustic's spread). An affine signal is
//!   reproduced unchanged, since its fitted values are its own colours.

use super::nlmeans::{
    Guide, MIN_CENTER_WEIGHT, NlMeansParams, Rect, Scratch, TILE, patch_distances, tiles, weight,
};
use super::planes::Planes;
use crate::error::{Error, Result};
use crate::simd::vectorized;
use nalgebra::DMatrix;
use rayon::prelude::*;

/// Offsets whose distances are transposed together (16 floats: one cache line per pixel).
const BLOCK: usize = 16;

/// Whether each window's predictions are clamped to the range of the colours it was fitted on
/// (module docs); a constant so that a test can show what it guards against.
const CLAMP_TO_WINDOW: bool = true;

/// Ridge on the normalised normal equations, relative to the sum of weights.
pub const RIDGE: f64 = 1e-6;

/// What one tile contributes: weighted predictions and weights over the tile grown by `R`.
struct TileSum {
    rect: Rect,
    acc: [Vec<f32>; 3],
    wsum: Vec<f32>,
}

/// Filters the three colour channels of `image` by collaborative first-order regression on
/// `features`, once per bandwidth of `bandwidths`, with NL-means weights (patch and window
/// radii of `params`; its `k` is not used) from `guide` and its variance `guide_var`.
///
/// The patch distances are computed once, at `k = 1`, and divided by `k²` for each bandwidth.
/// This equals the distance at `k` except where a per-pixel distance reaches the clamp (the
/// patch's weight is then below e⁻²⁰⁰ at either `k`) or where both variances are near `ε`.
pub fn collaborative_regression(
    image: &Planes,
    guide: &Planes,
    guide_var: &Planes,
    features: &Planes,
    params: NlMeansParams,
    bandwidths: &[f32],
) -> Result<Vec<Planes>> {
    for (p, what) in [
        (guide, "the regression guide"),
        (guide_var, "the guide's variance"),
        (features, "the features"),
    ] {
        image.same_size(p, what)?;
    }
    if image.channels() != 3 || guide.channels() != guide_var.channels() {
        return Err(Error::param(
            "channels",
            format!(
                "{}/{}/{}",
                image.channels(),
                guide.channels(),
                guide_var.channels()
            ),
            "the regression filters RGB with a guide and a variance of as many channels",
        ));
    }
    for &k in bandwidths {
        NlMeansParams::new(params.patch_radius, params.window_radius, k)?;
    }
    let problem = Problem {
        image,
        guide,
        guide_var,
        features,
        params,
        bandwidths,
    };
    let (w, h) = (image.width(), image.height());
    let mut acc = vec![Planes::zeros(w, h, 3); bandwidths.len()];
    let mut wsum = vec![vec![0.0f32; w * h]; bandwidths.len()];
    let all = tiles(w, h);
    // One band of tiles at a time: their sums overlap only within a band and its neighbours,
    // so memory stays a band of tile sums, not a weight per pixel and offset.
    for band in all.chunk_by(|a, b| a.y0 == b.y0) {
        let sums: Vec<Vec<TileSum>> = band
            .par_iter()
            .map_init(Workspace::default, |ws, &rect| {
                vectorized(RegressTile {
                    ws,
                    problem: &problem,
                    rect,
                })
            })
            .collect();
        for per_k in sums {
            for ((s, acc), wsum) in per_k.into_iter().zip(&mut acc).zip(&mut wsum) {
                for y in s.rect.y0..s.rect.y1 {
                    let i = (y - s.rect.y0) * s.rect.width();
                    let o = y * w + s.rect.x0;
                    let n = s.rect.width();
                    for c in 0..3 {
                        for (a, v) in acc.plane_mut(c)[o..o + n]
                            .iter_mut()
                            .zip(&s.acc[c][i..i + n])
                        {
                            *a += v;
                        }
                    }
                    for (a, v) in wsum[o..o + n].iter_mut().zip(&s.wsum[i..i + n]) {
                        *a += v;
                    }
                }
            }
        }
    }
    for (acc, wsum) in acc.iter_mut().zip(&wsum) {
        for c in 0..3 {
            for (v, s) in acc.plane_mut(c).iter_mut().zip(wsum) {
                *v /= s;
            }
        }
    }
    Ok(acc)
}

/// Per-thread buffers of the regression.
#[derive(Default)]
struct Workspace {
    scratch: Scratch,
    /// Patch distances (at `k = 1`) of every tile pixel to its neighbours: the window offsets
    /// of tile pixel `t` are contiguous at `t·(2R+1)²`, so a window's distances are a few runs.
    dists: Vec<f32>,
    /// One offset's distances over the tile, per channel and their maximum.
    dist: Vec<f32>,
    dmax: Vec<f32>,
    /// The window of the current centre: its patch distances, colours (column-major `n×3`)
    /// and normalised design columns (column-major `n×d`, constant first).
    dwin: Vec<f32>,
    y: Vec<f32>,
    x: Vec<f32>,
    /// The weighted design and colours of every bandwidth (`n × (d+3)` each, column-major).
    wz: Vec<f32>,
    /// Every bandwidth's predictions (`n × 3` each, column-major).
    pred: Vec<f32>,
    /// Weights of every bandwidth, `n` each.
    ws: Vec<f32>,
    window: Rect,
    centre: usize,
    /// Design columns in use (the rest were constant in the window).
    used: usize,
}

/// One tile of the regression: a job for [`vectorized`], so that its loops are compiled for
/// the CPU's widest vector units.
struct RegressTile<'a> {
    ws: &'a mut Workspace,
    problem: &'a Problem<'a>,
    rect: Rect,
}

impl pulp::WithSimd for RegressTile<'_> {
    type Output = Vec<TileSum>;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Self::Output {
        self.ws.tile(self.problem, self.rect)
    }
}

/// The inputs of one [`collaborative_regression`], checked.
struct Problem<'a> {
    image: &'a Planes,
    guide: &'a Planes,
    guide_var: &'a Planes,
    features: &'a Planes,
    params: NlMeansParams,
    bandwidths: &'a [f32],
}

/// `Σ aᵢbᵢ` with eight running sums, so that the loop vectorises.
#[inline(always)]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    acc.iter().sum::<f32>() + tail
}

impl Workspace {
    #[inline(always)]
    fn tile(&mut self, problem: &Problem<'_>, rect: Rect) -> Vec<TileSum> {
        let Problem {
            image,
            guide,
            guide_var,
            features,
            params,
            bandwidths,
        } = *problem;
        let (w, h) = (image.width(), image.height());
        let r = params.window_radius;
        let side = 2 * r + 1;
        let offsets_n = side * side;
        let area = rect.area();
        self.dists.clear();
        self.dists.resize(offsets_n * area, 0.0);
        self.dist.resize(TILE * TILE, 0.0);
        self.dmax.resize(BLOCK * TILE * TILE, 0.0);
        for (o, (dy, dx)) in offsets(r).enumerate() {
            // A block of offsets at a time, transposed into `dists` below with whole cache
            // lines written per tile pixel.
            let slot = o % BLOCK;
            let dmax = &mut self.dmax[slot * area..(slot + 1) * area];
            dmax.fill(f32::NEG_INFINITY);
            for c in 0..guide.channels() {
                let g = Guide {
                    value: guide.plane(c),
                    var: guide_var.plane(c),
                    width: w,
                    height: h,
                };
                patch_distances(
                    g,
                    rect,
                    dx,
                    dy,
                    params.patch_radius,
                    1.0,
                    params.pair_distance,
                    &mut self.scratch,
                    &mut self.dist,
                );
                for (m, d) in dmax.iter_mut().zip(&self.dist[..area]) {
                    *m = m.max(*d);
                }
            }
            if slot == BLOCK - 1 || o == offsets_n - 1 {
                let first = o - slot;
                for t in 0..area {
                    let row = &mut self.dists[t * offsets_n + first..][..=slot];
                    for (q, v) in row.iter_mut().enumerate() {
                        *v = self.dmax[q * area + t];
                    }
                }
            }
        }
        let out = Rect {
            x0: rect.x0.saturating_sub(r),
            x1: (rect.x1 + r).min(w),
            y0: rect.y0.saturating_sub(r),
            y1: (rect.y1 + r).min(h),
        };
        let mut sums: Vec<TileSum> = bandwidths
            .iter()
            .map(|_| TileSum {
                rect: out,
                acc: std::array::from_fn(|_| vec![0.0; out.area()]),
                wsum: vec![0.0; out.area()],
            })
            .collect();
        // The window's columns do not depend on the bandwidth: gather once, solve every `k`.
        let dists = std::mem::take(&mut self.dists);
        for y in rect.y0..rect.y1 {
            for x in rect.x0..rect.x1 {
                let t = (y - rect.y0) * rect.width() + (x - rect.x0);
                let window_dists = &dists[t * offsets_n..(t + 1) * offsets_n];
                self.gather(image, features, r, window_dists, (x, y));
                self.solve_and_spread(bandwidths, &mut sums);
            }
        }
        self.dists = dists;
        sums
    }

    /// Collects the window of centre `(x, y)`, row by row: patch distances (from the centre's
    /// distances to every offset, `dists`), colours and the normalised design columns,
    /// constant first; columns constant in the window are dropped ([`Self::used`] are kept).
    #[inline(always)]
    fn gather(
        &mut self,
        image: &Planes,
        features: &Planes,
        r: usize,
        dists: &[f32],
        (x, y): (usize, usize),
    ) {
        let (w, h) = (image.width(), image.height());
        let win = Rect {
            x0: x.saturating_sub(r),
            x1: (x + r + 1).min(w),
            y0: y.saturating_sub(r),
            y1: (y + r + 1).min(h),
        };
        self.window = win;
        let n = win.area();
        let ww = win.width();
        let ncols = 3 + features.channels();
        self.x.resize(ncols * n, 0.0);
        self.y.resize(3 * n, 0.0);
        self.dwin.resize(n, 0.0);
        let side = 2 * r + 1;
        self.centre = (y - win.y0) * ww + (x - win.x0);
        let fc: Vec<f32> = (0..features.channels())
            .map(|j| features.plane(j)[y * w + x])
            .collect();
        for (i, wy) in (win.y0..win.y1).enumerate() {
            let at = i * ww..(i + 1) * ww;
            let o = (wy + r - y) * side + r + win.x0 - x;
            self.dwin[at.clone()].copy_from_slice(&dists[o..o + ww]);
            let row = wy * w + win.x0..wy * w + win.x1;
            for c in 0..3 {
                self.y[c * n..][at.clone()].copy_from_slice(&image.plane(c)[row.clone()]);
            }
            for (v, wx) in self.x[n..][at.clone()].iter_mut().zip(win.x0..win.x1) {
                *v = wx as f32 - x as f32;
            }
            self.x[2 * n..][at.clone()].fill(wy as f32 - y as f32);
            for (j, &centre) in fc.iter().enumerate() {
                let f = &features.plane(j)[row.clone()];
                for (v, fv) in self.x[(3 + j) * n..][at.clone()].iter_mut().zip(f) {
                    *v = fv - centre;
                }
            }
        }
        self.x[..n].fill(1.0);
        let mut kept = 1;
        for j in 1..ncols {
            let col = &mut self.x[j * n..(j + 1) * n];
            let scale = col.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            if scale > 0.0 && scale.is_finite() {
                // A division, not a product with 1/scale: that overflows for subnormal scales.
                col.iter_mut().for_each(|v| *v /= scale);
                if kept != j {
                    self.x.copy_within(j * n..(j + 1) * n, kept * n);
                }
                kept += 1;
            }
        }
        self.used = kept;
    }

    /// Solves the weighted least squares of the gathered window for every bandwidth and adds
    /// each prediction, weighted, to that bandwidth's sum.
    #[inline(always)]
    fn solve_and_spread(&mut self, bandwidths: &[f32], sums: &mut [TileSum]) {
        let (d, n, nk) = (self.used, self.dwin.len(), bandwidths.len());
        // Plain indexed loops here and below: iterator adapters such as `extend` are not
        // inlined into the vectorised job and would run with baseline instructions.
        self.ws.resize(nk * n, 0.0);
        for (wk, &k) in self.ws.chunks_exact_mut(n).zip(bandwidths) {
            let scale = 1.0 / (k * k);
            for (o, &v) in wk.iter_mut().zip(&self.dwin) {
                *o = weight(v * scale);
            }
            wk[self.centre] = wk[self.centre].max(MIN_CENTER_WEIGHT);
        }
        // W·X and W·Y of every bandwidth, then each moment as one dot product with X.
        let block = d + 3;
        self.wz.resize(n * nk * block, 0.0);
        for (kk, wk) in self.ws.chunks_exact(n).enumerate() {
            let cols = self.x[..d * n]
                .chunks_exact(n)
                .chain(self.y.chunks_exact(n));
            for (j, col) in cols.enumerate() {
                let dst = &mut self.wz[(kk * block + j) * n..][..n];
                for ((o, v), wt) in dst.iter_mut().zip(col).zip(wk) {
                    *o = v * wt;
                }
            }
        }
        self.pred.clear();
        self.pred.resize(n * 3 * nk, 0.0);
        for (kk, wk) in self.ws.chunks_exact(n).enumerate() {
            let wz = &self.wz[kk * block * n..(kk + 1) * block * n];
            let x = |j: usize| &self.x[j * n..(j + 1) * n];
            let wsum: f64 = wk.iter().map(|&v| f64::from(v)).sum();
            let mut gram = DMatrix::<f64>::zeros(d, d);
            for i in 0..d {
                for j in i..d {
                    let g = f64::from(dot(x(i), &wz[j * n..(j + 1) * n]));
                    gram[(i, j)] = g;
                    gram[(j, i)] = g;
                }
                if i > 0 {
                    gram[(i, i)] += RIDGE * wsum;
                }
            }
            let mut rhs = DMatrix::<f64>::zeros(d, 3);
            for c in 0..3 {
                for i in 0..d {
                    rhs[(i, c)] = f64::from(dot(x(i), &wz[(d + c) * n..(d + c + 1) * n]));
                }
            }
            let beta = match gram.cholesky() {
                Some(ch) => ch.solve(&rhs),
                None => {
                    let mut b = DMatrix::<f64>::zeros(d, 3);
                    for c in 0..3 {
                        b[(0, c)] = rhs[(0, c)] / wsum;
                    }
                    b
                }
            };
            for c in 0..3 {
                let pred = &mut self.pred[(3 * kk + c) * n..][..n];
                for j in 0..d {
                    let b = beta[(j, c)] as f32;
                    for (p, v) in pred.iter_mut().zip(&self.x[j * n..(j + 1) * n]) {
                        *p += v * b;
                    }
                }
                if CLAMP_TO_WINDOW {
                    // The model is trusted only within the colours it was fitted on.
                    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                    for (y, &wt) in self.y[c * n..(c + 1) * n].iter().zip(wk) {
                        if wt > 0.0 {
                            lo = lo.min(*y);
                            hi = hi.max(*y);
                        }
                    }
                    for p in pred.iter_mut() {
                        *p = p.clamp(lo, hi);
                    }
                }
            }
        }
        // Weighted predictions, row by row into each bandwidth's tile sums.
        let win = self.window;
        for (kk, (sum, wk)) in sums.iter_mut().zip(self.ws.chunks_exact(n)).enumerate() {
            let (rw, ww) = (sum.rect.width(), win.width());
            for (i, wy) in (win.y0..win.y1).enumerate() {
                let k = (wy - sum.rect.y0) * rw + (win.x0 - sum.rect.x0);
                let src = i * ww..(i + 1) * ww;
                for c in 0..3 {
                    let p = &self.pred[(3 * kk + c) * n..][src.clone()];
                    for ((a, p), wt) in sum.acc[c][k..k + ww]
                        .iter_mut()
                        .zip(p)
                        .zip(&wk[src.clone()])
                    {
                        *a += p * wt;
                    }
                }
                for (a, p) in sum.wsum[k..k + ww].iter_mut().zip(&wk[src]) {
                    *a += p;
                }
            }
        }
    }
}

/// Window offsets `(dy, dx)`, row by row.
fn offsets(r: usize) -> impl Iterator<Item = (isize, isize)> {
    let r = r as isize;
    (-r..=r).flat_map(move |dy| (-r..=r).map(move |dx| (dy, dx)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rgb(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> Planes {
        let px: Vec<[f32; 3]> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect();
        Planes::from_planes(
            w,
            h,
            (0..3).map(|c| px.iter().map(|p| p[c]).collect()).collect(),
        )
        .unwrap()
    }

    /// A colour that is exactly affine in the position and in a feature is reproduced exactly
    /// (up to the ridge and f32 rounding), whatever the weights: first-order regression has no
    /// bias on first-order signals.
    #[test]
    fn affine_signals_pass_unchanged() {
        let (w, h) = (45, 38);
        let feature = Planes::from_planes(
            w,
            h,
            vec![
                (0..w * h)
                    .map(|i| ((i * 7919) % 13) as f32 / 13.0)
                    .collect(),
            ],
        )
        .unwrap();
        let f = feature.plane(0).to_vec();
        let image = rgb(w, h, |x, y| {
            let v = f[y * w + x];
            [
                0.2 + 0.01 * x as f32 + 0.5 * v,
                1.0 - 0.02 * y as f32,
                0.3 * v,
            ]
        });
        // A flat guide gives every neighbour weight 1: the fit sees whole windows.
        let guide = rgb(w, h, |_, _| [1.0; 3]);
        let var = Planes::zeros(w, h, 3);
        let p = NlMeansParams::new(3, 4, 1.0).unwrap();
        let out = collaborative_regression(&image, &guide, &var, &feature, p, &[1.0])
            .unwrap()
            .remove(0);
        for c in 0..3 {
            for (a, b) in out.plane(c).iter().zip(image.plane(c)) {
                assert!((a - b).abs() < 2e-4, "channel {c}: {a} vs {b}");
            }
        }
    }

    /// A feature that varies only by subnormal amounts is normalised by division: the product
    /// with `1/scale` overflows to ∞ there and turned the whole window into NaN.
    #[test]
    fn subnormal_feature_variation_stays_finite() {
        let (w, h) = (12, 10);
        let feature = Planes::from_planes(
            w,
            h,
            vec![(0..w * h).map(|i| (i % 3) as f32 * 1e-40).collect()],
        )
        .unwrap();
        let image = rgb(w, h, |x, y| [0.1 * x as f32, 0.2 * y as f32, 1.0]);
        let var = Planes::zeros(w, h, 3);
        let p = NlMeansParams::new(1, 3, 1.0).unwrap();
        let out = collaborative_regression(&image, &image, &var, &feature, p, &[0.5, 1.0]).unwrap();
        for o in &out {
            assert_eq!(o.first_non_finite(), None);
        }
    }

    /// One bright pixel at a window's edge tilts every plane fitted through it; the windows'
    /// predictions must stay within the colours they saw, so no pixel ends below the darkest
    /// input or above the brightest (without the clamp, the far side of the windows went
    /// negative).
    #[test]
    fn predictions_stay_within_the_window_colours() {
        let (w, h) = (15, 15);
        let bright = |x: usize, y: usize| x == 2 && y == 7;
        let image = rgb(
            w,
            h,
            |x, y| if bright(x, y) { [100.0; 3] } else { [0.1; 3] },
        );
        let var = rgb(
            w,
            h,
            |x, y| if bright(x, y) { [2500.0; 3] } else { [1e-3; 3] },
        );
        let p = NlMeansParams::new(1, 6, 1.0).unwrap();
        let out =
            collaborative_regression(&image, &image, &var, &Planes::zeros(w, h, 0), p, &[1.0])
                .unwrap()
                .remove(0);
        let low = out.plane(0).iter().cloned().fold(f32::INFINITY, f32::min);
        assert!(
            low >= 0.1 - 1e-6,
            "a prediction went below every input: {low}"
        );
        assert!(out.plane(0).iter().all(|&v| v <= 100.0));
    }

    /// Constant features (dropped columns) and a guide whose weights are all tiny leave a
    /// constant image constant, with no NaN.
    #[test]
    fn degenerate_windows_stay_finite() {
        let image = rgb(20, 9, |_, _| [0.5, 0.25, 0.0]);
        let features = Planes::zeros(20, 9, 2);
        let var = Planes::zeros(20, 9, 3);
        let p = NlMeansParams::new(1, 3, 0.5).unwrap();
        let out = collaborative_regression(&image, &image, &var, &features, p, &[0.5])
            .unwrap()
            .remove(0);
        for c in 0..3 {
            for (a, b) in out.plane(c).iter().zip(image.plane(c)) {
                assert!((a - b).abs() < 1e-6);
            }
        }
        let one = rgb(1, 1, |_, _| [2.0, 3.0, 4.0]);
        let out = collaborative_regression(
            &one,
            &one,
            &Planes::zeros(1, 1, 3),
            &Planes::zeros(1, 1, 1),
            p,
            &[0.5, 1.0],
        )
        .unwrap()
        .remove(1);
        assert_eq!(out.plane(2), &[4.0]);
    }
}
