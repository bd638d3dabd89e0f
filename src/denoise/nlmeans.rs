//! Non-local means with the variance-cancelling patch distance of Rousselle, Manzi and Zwicker
//! ("Robust denoising using feature and color information", 2013), the filter NFOR uses to
//! prefilter features, to filter its MSE estimates and selection maps, and to weight its
//! regressions.
//!
//! The distance between pixels `p` and `q` in one channel of a guide `u` with per-pixel
//! variance `v` is
//!
//! ```text
//! d(p, q) = [ (u_p − u_q)² − (v_p + min(v_p, v_q)) ] / [ ε + k² (v_p + v_q) ]
//! ```
//!
//! clamped above at [`DISTANCE_CLAMP`] and averaged over the `(2F+1)²` patch offsets; the weight
//! is `exp(−max(0, D))`. Subtracting the variances removes the expected squared difference that
//! noise alone produces, so a noisy guide does not look dissimilar to itself.
//!
//! **Optionally the pair itself also counts** ([`NlMeansParams::pair_distance`]): `D` is then
//! the larger of that patch mean and `d(p, q)` of the two pixels alone. A detail smaller than a
//! patch (a light one or two pixels wide) holds a few of its 49 offsets, so by the patch mean
//! alone every neighbour looks like it and it like them. Off in the paper's filter; NFOR turns it
//! on for its feature filters ([`super::nfor`]). It costs some smoothing: an equal-variance pair
//! of the same mean has `d > 1/k²` (a weight below `e^(−1/k²)`) with probability 16%.
//!
//! Choices the papers leave open, as made here:
//! * Near the border a patch is cut to the pixels `p'` for which both `p'` and `p' + δ` lie in
//!   the image, and the distance is the mean over those; pixels whose `q` leaves the image get
//!   no weight. (Bitterli's released code also cuts patches at the border.)
//! * The centre pixel's own weight is at least [`MIN_CENTER_WEIGHT`], so a pixel whose every
//!   neighbour, itself included, looks dissimilar keeps its own value rather than dividing by 0.
//! * `ε` = [`EPSILON`] only guards the division where both variances are 0.
//!
//! Work is split into [`TILE`]-pixel square tiles, so scratch memory is a few tiles per thread,
//! never a weight per pixel and offset of the whole image.

use super::planes::Planes;
use crate::error::{Error, Result};
use crate::simd::vectorized;
use rayon::prelude::*;

/// Side of the square tiles the filters work on.
pub const TILE: usize = 32;
/// Guards the distance's division where both variances are 0.
pub const EPSILON: f32 = 1e-10;
/// Largest per-pixel distance: one outlier pixel cannot dominate a patch's mean beyond this.
pub const DISTANCE_CLAMP: f32 = 1e4;
/// Smallest weight of a pixel for itself.
pub const MIN_CENTER_WEIGHT: f32 = 1e-4;

/// One NL-means configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NlMeansParams {
    /// Patch radius `F`: patches are `(2F+1)²` pixels.
    pub patch_radius: usize,
    /// Window radius `R`: neighbours are searched in a `(2R+1)²` window.
    pub window_radius: usize,
    /// Bandwidth `k`: larger accepts more dissimilar neighbours.
    pub k: f32,
    /// Whether a distance is at least that of the pixel pair alone (module docs): on for the
    /// feature filters, off where the weights must not follow one pixel's own noise.
    pub pair_distance: bool,
}

impl NlMeansParams {
    /// Checked parameters: radii below 64, `k` finite and positive.
    pub fn new(patch_radius: usize, window_radius: usize, k: f32) -> Result<Self> {
        if patch_radius > 63 {
            return Err(Error::param(
                "patch_radius",
                patch_radius,
                "must be at most 63",
            ));
        }
        if window_radius > 63 {
            return Err(Error::param(
                "window_radius",
                window_radius,
                "must be at most 63",
            ));
        }
        if !(k.is_finite() && k > 0.0) {
            return Err(Error::param("k", k, "must be finite and positive"));
        }
        Ok(NlMeansParams {
            patch_radius,
            window_radius,
            k,
            pair_distance: false,
        })
    }

    /// The same, with the pair's own distance as a floor (or without).
    pub fn with_pair_distance(self, on: bool) -> Self {
        NlMeansParams {
            pair_distance: on,
            ..self
        }
    }
}

/// A half-open pixel rectangle.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Rect {
    pub x0: usize,
    pub x1: usize,
    pub y0: usize,
    pub y1: usize,
}

impl Rect {
    pub fn width(&self) -> usize {
        self.x1 - self.x0
    }
    pub fn height(&self) -> usize {
        self.y1 - self.y0
    }
    pub fn area(&self) -> usize {
        self.width() * self.height()
    }
}

/// The tiles covering a `width`×`height` image, row by row.
pub(crate) fn tiles(width: usize, height: usize) -> Vec<Rect> {
    let mut out = Vec::new();
    for y0 in (0..height).step_by(TILE) {
        for x0 in (0..width).step_by(TILE) {
            out.push(Rect {
                x0,
                x1: (x0 + TILE).min(width),
                y0,
                y1: (y0 + TILE).min(height),
            });
        }
    }
    out
}

/// `[lo, hi)` of coordinates `a` with both `a` and `a + d` in `[0, n)`.
#[inline(always)]
fn valid_range(n: usize, d: isize) -> (usize, usize) {
    let lo = (-d).max(0) as usize;
    let hi = (n as isize - d).clamp(0, n as isize) as usize;
    (lo.min(hi), hi)
}

/// Per-thread scratch for [`patch_distances`].
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    dist: Vec<f32>,
    rows: Vec<f32>,
    cols: Vec<f32>,
    cx: Vec<f32>,
    /// Partial sums of 2, 4, 8, ... terms for [`box_sums`].
    levels: Vec<Vec<f32>>,
}

/// `out[j] = Σ_{s<len} x[j + s·stride]` for `j < out.len()`, by doubling: sums of 2, 4, 8, ...
/// consecutive terms, then one of each power in `len`'s binary expansion (a 7-term sum costs 4
/// additions per output instead of 6, in a fixed order). Each loop is a shifted addition of
/// whole slices, which vectorises; with `stride` 1 it sums along rows, with a row length down
/// columns.
#[inline(always)]
fn box_sums(x: &[f32], stride: usize, len: usize, levels: &mut Vec<Vec<f32>>, out: &mut [f32]) {
    let n = out.len();
    let top = usize::BITS - 1 - len.leading_zeros(); // largest power of two in len: 2^top
    levels.resize_with(top as usize, Vec::new);
    // levels[k - 1][j] = Σ_{s < 2^k} x[j + s·stride], wherever the output needs it.
    for k in 1..=top as usize {
        let half = (1usize << (k - 1)) * stride;
        let need = n + (len - (1 << k)) * stride;
        let (done, rest) = levels.split_at_mut(k - 1);
        let prev: &[f32] = if k == 1 { x } else { &done[k - 2] };
        let cur = &mut rest[0];
        cur.resize(need, 0.0);
        for ((c, a), b) in cur
            .iter_mut()
            .zip(&prev[..need])
            .zip(&prev[half..half + need])
        {
            *c = a + b;
        }
    }
    let first: &[f32] = if top == 0 {
        x
    } else {
        &levels[top as usize - 1]
    };
    out.copy_from_slice(&first[..n]);
    let mut offset = (1usize << top) * stride;
    for k in (0..top as usize).rev() {
        if len & (1 << k) != 0 {
            let part: &[f32] = if k == 0 { x } else { &levels[k - 1] };
            for (o, v) in out.iter_mut().zip(&part[offset..offset + n]) {
                *o += v;
            }
            offset += (1 << k) * stride;
        }
    }
}

/// One guide channel: values and their variances.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Guide<'a> {
    pub value: &'a [f32],
    pub var: &'a [f32],
    pub width: usize,
    pub height: usize,
}

/// Patch-averaged distances of `guide` between each pixel `p` of `rect` and `p + (dx, dy)`, or
/// the pair's own distance where that is larger (module docs), into `out` (row-major over
/// `rect`); `+∞` where `p + (dx, dy)` leaves the image.
///
/// The per-pixel distances are laid out with a margin of `f` zeros wherever a pixel or its
/// partner is missing, so that the patch sums are plain shifted additions (which vectorise);
/// the count of pixels that did exist divides them.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn patch_distances(
    guide: Guide<'_>,
    rect: Rect,
    dx: isize,
    dy: isize,
    f: usize,
    k: f32,
    pair: bool,
    scratch: &mut Scratch,
    out: &mut [f32],
) {
    let (w, h) = (guide.width, guide.height);
    let (vx0, vx1) = valid_range(w, dx);
    let (vy0, vy1) = valid_range(h, dy);
    out[..rect.area()].fill(f32::INFINITY);
    // Pixels of the rectangle with a partner.
    let (ox0, ox1) = (rect.x0.max(vx0), rect.x1.min(vx1));
    let (oy0, oy1) = (rect.y0.max(vy0), rect.y1.min(vy1));
    if ox0 >= ox1 || oy0 >= oy1 {
        return;
    }
    let (ow, oh) = (ox1 - ox0, oy1 - oy0);
    // The buffer spans [ox0 − f, ox1 + f) × [oy0 − f, oy1 + f); what exists of it is P.
    let (bw, bh) = (ow + 2 * f, oh + 2 * f);
    let (px0, px1) = (ox0.saturating_sub(f).max(vx0), (ox1 + f).min(vx1));
    let (py0, py1) = (oy0.saturating_sub(f).max(vy0), (oy1 + f).min(vy1));
    let (bx0, by0) = (ox0 as isize - f as isize, oy0 as isize - f as isize);
    let k2 = k * k;
    scratch.dist.clear();
    scratch.dist.resize(bw * bh, 0.0);
    let shift = dy * w as isize + dx;
    let (c0, c1) = ((px0 as isize - bx0) as usize, (px1 as isize - bx0) as usize);
    for y in py0..py1 {
        let r = (y as isize - by0) as usize;
        let p0 = y * w + px0;
        let q0 = (p0 as isize + shift) as usize;
        let n = px1 - px0;
        let (gp, gq) = (&guide.value[p0..p0 + n], &guide.value[q0..q0 + n]);
        let (vp, vq) = (&guide.var[p0..p0 + n], &guide.var[q0..q0 + n]);
        let row = &mut scratch.dist[r * bw + c0..r * bw + c1];
        for i in 0..n {
            let diff = gp[i] - gq[i];
            let d = (diff * diff - (vp[i] + vp[i].min(vq[i]))) / (EPSILON + k2 * (vp[i] + vq[i]));
            row[i] = d.min(DISTANCE_CLAMP);
        }
    }
    // Horizontal patch sums along the whole buffer (sums that would run past a row's end are
    // computed but never read), then vertical sums of those down the columns.
    let side = 2 * f + 1;
    scratch.rows.resize((bh - 1) * bw + ow, 0.0);
    box_sums(
        &scratch.dist,
        1,
        side,
        &mut scratch.levels,
        &mut scratch.rows,
    );
    scratch.cols.resize((oh - 1) * bw + ow, 0.0);
    box_sums(
        &scratch.rows,
        bw,
        side,
        &mut scratch.levels,
        &mut scratch.cols,
    );
    scratch.cx.clear();
    scratch
        .cx
        .extend((ox0..ox1).map(|x| ((x + f + 1).min(px1) - x.saturating_sub(f).max(px0)) as f32));
    for y in oy0..oy1 {
        let ny = ((y + f + 1).min(py1) - y.saturating_sub(f).max(py0)) as f32;
        let r0 = y - oy0;
        let o = (y - rect.y0) * rect.width() + (ox0 - rect.x0);
        let dst = &mut out[o..o + ow];
        let sums = &scratch.cols[r0 * bw..r0 * bw + ow];
        for (d, (s, cx)) in dst.iter_mut().zip(sums.iter().zip(&scratch.cx)) {
            *d = s / (cx * ny);
        }
        if pair {
            // The pair's own distance sits at the buffer's offset (f, f) from the output pixel.
            let own = &scratch.dist[(r0 + f) * bw + f..][..ow];
            for (d, own) in dst.iter_mut().zip(own) {
                *d = d.max(*own);
            }
        }
    }
}

/// The weight of a patch distance, `exp(−max(0, D))`; 0 for an absent partner (`D = +∞`)
/// and wherever the weight would be below `f32`'s normal range.
#[inline(always)]
pub(crate) fn weight(distance: f32) -> f32 {
    if distance >= 87.0 {
        0.0
    } else {
        exp_neg(-distance.max(0.0))
    }
}

/// `eˣ` for `x` in `[−87, 0]`, in plain arithmetic so that loops of it vectorise: `x = n·ln2 +
/// r` with `n` an integer (Cody and Waite's two-part ln 2 keeps `r` exact), `eʳ` from a
/// degree-6 Taylor series about −ln2/2, and `2ⁿ` built in the exponent bits. Relative error
/// below 10⁻⁶ (tested against `f64::exp` over the whole domain).
#[inline(always)]
pub(crate) fn exp_neg(x: f32) -> f32 {
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let x = x.max(-87.0);
    let n = (x * std::f32::consts::LOG2_E) as i32; // toward zero: n in [−125, 0]
    let nf = n as f32;
    let r = (x - nf * LN2_HI) - nf * LN2_LO; // in (−ln2, 0]
    let y = r + 0.5 * std::f32::consts::LN_2; // |y| <= ln2/2
    let p = 1.0
        + y * (1.0
            + y * (0.5
                + y * (1.0 / 6.0 + y * (1.0 / 24.0 + y * (1.0 / 120.0 + y * (1.0 / 720.0))))));
    let scale = f32::from_bits(((n + 127) as u32) << 23);
    p * std::f32::consts::FRAC_1_SQRT_2 * scale
}

/// Filters each channel of `image` with NL-means weights from the same channel of `guide`
/// (variance `var`). All three must have one size and one channel count.
pub fn nl_means(
    image: &Planes,
    guide: &Planes,
    var: &Planes,
    params: NlMeansParams,
) -> Result<Planes> {
    let mut out = nl_means_many(&[image], guide, var, params)?;
    Ok(out.pop().expect("one image in, one out"))
}

/// [`nl_means`] of several images with one guide: the weights are computed once.
pub fn nl_means_many(
    images: &[&Planes],
    guide: &Planes,
    var: &Planes,
    params: NlMeansParams,
) -> Result<Vec<Planes>> {
    guide.same_size(var, "the NL-means variance")?;
    for image in images {
        guide.same_size(image, "the NL-means image")?;
        if image.channels() != guide.channels() || var.channels() != guide.channels() {
            return Err(Error::param(
                "channels",
                format!(
                    "{}/{}/{}",
                    image.channels(),
                    guide.channels(),
                    var.channels()
                ),
                "image, guide and variance must have as many channels",
            ));
        }
    }
    let (w, h) = (guide.width(), guide.height());
    let tiles = tiles(w, h);
    let n_img = images.len();
    // Per tile: per channel, per image, the filtered tile.
    let blocks: Vec<Vec<Vec<Vec<f32>>>> = tiles
        .par_iter()
        .map_init(TileBuffers::default, |buffers, &rect| {
            vectorized(FilterTile {
                images,
                guide,
                var,
                params,
                rect,
                buffers,
            })
        })
        .collect();
    let mut out = vec![Planes::zeros(w, h, guide.channels()); n_img];
    for (rect, block) in tiles.iter().zip(blocks) {
        for (c, per_image) in block.into_iter().enumerate() {
            for (o, vals) in out.iter_mut().zip(per_image) {
                let plane = o.plane_mut(c);
                for y in rect.y0..rect.y1 {
                    let row = &vals[(y - rect.y0) * rect.width()..(y - rect.y0 + 1) * rect.width()];
                    plane[y * w + rect.x0..y * w + rect.x1].copy_from_slice(row);
                }
            }
        }
    }
    Ok(out)
}

/// Per-thread scratch of [`nl_means_many`].
#[derive(Default)]
struct TileBuffers {
    scratch: Scratch,
    dist: Vec<f32>,
    wts: Vec<f32>,
}

/// [`nl_means_many`] on one tile: per channel, per image, the filtered tile. A job for
/// [`vectorized`], so that its loops are compiled for the CPU's widest vector units.
struct FilterTile<'a> {
    images: &'a [&'a Planes],
    guide: &'a Planes,
    var: &'a Planes,
    params: NlMeansParams,
    rect: Rect,
    buffers: &'a mut TileBuffers,
}

impl pulp::WithSimd for FilterTile<'_> {
    type Output = Vec<Vec<Vec<f32>>>;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Self::Output {
        let FilterTile {
            images,
            guide,
            var,
            params,
            rect,
            buffers,
        } = self;
        let TileBuffers { scratch, dist, wts } = buffers;
        dist.resize(TILE * TILE, 0.0);
        wts.resize(TILE * TILE, 0.0);
        let (w, h) = (guide.width(), guide.height());
        let r = params.window_radius as isize;
        let n_img = images.len();
        let area = rect.area();
        (0..guide.channels())
            .map(|c| {
                let g = Guide {
                    value: guide.plane(c),
                    var: var.plane(c),
                    width: w,
                    height: h,
                };
                let mut acc = vec![vec![0.0f32; area]; n_img];
                let mut wsum = vec![0.0f32; area];
                for dy in -r..=r {
                    for dx in -r..=r {
                        patch_distances(
                            g,
                            rect,
                            dx,
                            dy,
                            params.patch_radius,
                            params.k,
                            params.pair_distance,
                            scratch,
                            dist,
                        );
                        for (wt, &d) in wts[..area].iter_mut().zip(&dist[..area]) {
                            *wt = weight(d);
                        }
                        if dx == 0 && dy == 0 {
                            wts[..area]
                                .iter_mut()
                                .for_each(|v| *v = v.max(MIN_CENTER_WEIGHT));
                        }
                        for (s, wt) in wsum.iter_mut().zip(&wts[..area]) {
                            *s += wt;
                        }
                        // Rows of the tile whose partners lie in the image.
                        let (vx0, vx1) = valid_range(w, dx);
                        let (vy0, vy1) = valid_range(h, dy);
                        let (x0, x1) = (rect.x0.max(vx0), rect.x1.min(vx1));
                        if x0 >= x1 {
                            continue;
                        }
                        for y in rect.y0.max(vy0)..rect.y1.min(vy1) {
                            let i0 = (y - rect.y0) * rect.width() + (x0 - rect.x0);
                            let q0 = ((y as isize + dy) as usize) * w + (x0 as isize + dx) as usize;
                            let n = x1 - x0;
                            let wrow = &wts[i0..i0 + n];
                            for (a, image) in acc.iter_mut().zip(images) {
                                let src = &image.plane(c)[q0..q0 + n];
                                for ((o, wt), v) in a[i0..i0 + n].iter_mut().zip(wrow).zip(src) {
                                    *o += wt * v;
                                }
                            }
                        }
                    }
                }
                for a in &mut acc {
                    for (v, s) in a.iter_mut().zip(&wsum) {
                        *v /= s;
                    }
                }
                acc
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planes(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Planes {
        let v = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y));
        Planes::from_planes(w, h, vec![v.collect()]).unwrap()
    }

    /// The distance of a hand-computed case: guide 1 and 3 with variances 0.5 and 0.25, k = 1,
    /// one-pixel patches: ((1−3)² − (0.5 + 0.25)) / (ε + 0.75) = 3.25 / 0.75.
    #[test]
    fn distance_matches_the_formula_by_hand() {
        let value = [1.0, 3.0];
        let var = [0.5, 0.25];
        let g = Guide {
            value: &value,
            var: &var,
            width: 2,
            height: 1,
        };
        let rect = Rect {
            x0: 0,
            x1: 2,
            y0: 0,
            y1: 1,
        };
        let mut out = [0.0; 2];
        patch_distances(
            g,
            rect,
            1,
            0,
            0,
            1.0,
            false,
            &mut Scratch::default(),
            &mut out,
        );
        assert!((out[0] - 3.25 / 0.75).abs() < 1e-6, "{}", out[0]);
        assert_eq!(out[1], f32::INFINITY, "its partner is outside the image");
        // From pixel 1 towards 0: v_p = 0.25, min(v_p, v_q) = 0.25.
        patch_distances(
            g,
            rect,
            -1,
            0,
            0,
            1.0,
            false,
            &mut Scratch::default(),
            &mut out,
        );
        assert!((out[1] - 3.5 / 0.75).abs() < 1e-6, "{}", out[1]);
    }

    /// A patch average near the border uses only pixels whose partners exist: on a 3x1 guide
    /// with F = 1 and δ = +1, pixel 0's patch is pixels {0, 1} (−1 is outside), both valid.
    #[test]
    fn border_patches_average_what_exists() {
        let value = [0.0, 2.0, 2.0];
        let var = [0.0; 3];
        let g = Guide {
            value: &value,
            var: &var,
            width: 3,
            height: 1,
        };
        let rect = Rect {
            x0: 0,
            x1: 3,
            y0: 0,
            y1: 1,
        };
        let mut out = [0.0; 3];
        patch_distances(
            g,
            rect,
            1,
            0,
            1,
            1.0,
            false,
            &mut Scratch::default(),
            &mut out,
        );
        // d(0,1) = 4/ε clamped to 1e4; d(1,2) = 0. Pixel 0: mean of {1e4, 0}; pixel 1: the
        // same two (pixel 2's partner is outside).
        assert_eq!(out[0], DISTANCE_CLAMP / 2.0);
        assert_eq!(out[1], DISTANCE_CLAMP / 2.0);
        assert_eq!(out[2], f32::INFINITY);
    }

    /// A constant image stays constant; a noise-free step edge is not blurred across (its
    /// distances hit the clamp); pure noise with its true variance is smoothed.
    #[test]
    fn filter_keeps_edges_and_smooths_noise() {
        let p = NlMeansParams::new(1, 3, 0.5).unwrap();
        let flat = planes(40, 37, |_, _| 0.7);
        let zero = planes(40, 37, |_, _| 0.0);
        let out = nl_means(&flat, &flat, &zero, p).unwrap();
        assert!(out.plane(0).iter().all(|&v| (v - 0.7).abs() < 1e-6));

        let step = planes(40, 37, |x, _| if x < 20 { 0.0 } else { 1.0 });
        let out = nl_means(&step, &step, &zero, p).unwrap();
        assert_eq!(out.plane(0), step.plane(0));

        // Deterministic pseudo-noise of variance 1/12 around 0.5 (a hash, no RNG needed).
        let noise = planes(64, 64, |x, y| {
            let h = (x as u32).wrapping_mul(73_856_093) ^ (y as u32).wrapping_mul(19_349_663);
            let h = h.wrapping_mul(2_654_435_761);
            (h >> 8) as f32 / (1u32 << 24) as f32
        });
        let var = planes(64, 64, |_, _| 1.0 / 12.0);
        let out = nl_means(&noise, &noise, &var, NlMeansParams::new(3, 5, 1.0).unwrap()).unwrap();
        let spread = |v: &[f32]| {
            let m = v.iter().sum::<f32>() / v.len() as f32;
            v.iter().map(|x| (x - m) * (x - m)).sum::<f32>() / v.len() as f32
        };
        let (before, after) = (spread(noise.plane(0)), spread(out.plane(0)));
        assert!(after < before / 10.0, "variance {before} -> {after}");
    }

    /// A one-pixel light in a flat guide (value 100 with the variance of a partly covered pixel,
    /// 2500; the rest 0.05 with 1e-4): the pair distance between the light and a neighbour is
    /// 16 at k = 0.5, but it is one of 49 offsets of a 7x7 patch whose other pairs count about
    /// −4 each (noise-free pixels of stated variance), so by the patch mean alone the light looks
    /// like its neighbours and its value spreads over the window. With the pair's own distance
    /// both stay apart.
    #[test]
    fn a_detail_smaller_than_a_patch_does_not_spread() {
        let (w, h) = (21, 21);
        let light = |x: usize, y: usize| x == 10 && y == 10;
        let image = planes(w, h, |x, y| if light(x, y) { 100.0 } else { 0.05 });
        let var = planes(w, h, |x, y| if light(x, y) { 2500.0 } else { 1e-4 });
        let p = NlMeansParams::new(3, 5, 0.5).unwrap();
        let patch_only = nl_means(&image, &image, &var, p).unwrap();
        assert!(
            patch_only.plane(0)[10 * w + 11] > 0.5,
            "the failure this guards against"
        );
        let out = nl_means(&image, &image, &var, p.with_pair_distance(true)).unwrap();
        for y in 0..h {
            for x in 0..w {
                let v = out.plane(0)[y * w + x];
                if light(x, y) {
                    assert!(v > 99.0, "the light kept {v}");
                } else {
                    assert!(
                        (v - 0.05).abs() < 1e-3,
                        "({x}, {y}) took {v} from the light"
                    );
                }
            }
        }
    }

    /// The vectorisable exponential against `f64::exp` over its whole domain.
    #[test]
    fn exp_neg_is_accurate() {
        let mut worst = 0.0f64;
        for i in 0..=870_000 {
            let x = -(i as f32) * 1e-4;
            let want = f64::from(x).exp();
            let got = f64::from(exp_neg(x));
            worst = worst.max(((got - want) / want).abs());
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
        assert_eq!(weight(f32::INFINITY), 0.0);
        assert_eq!(weight(-3.0), exp_neg(0.0));
        assert!((exp_neg(0.0) - 1.0).abs() < 2e-7);
    }

    #[test]
    fn bad_parameters_and_shapes_are_named() {
        assert!(
            NlMeansParams::new(1, 1, 0.0)
                .unwrap_err()
                .to_string()
                .contains("k")
        );
        assert!(NlMeansParams::new(64, 1, 1.0).is_err());
        let a = Planes::zeros(4, 4, 1);
        let b = Planes::zeros(4, 5, 1);
        let p = NlMeansParams::new(1, 1, 1.0).unwrap();
        assert!(nl_means(&a, &b, &a, p).is_err());
        let c = Planes::zeros(4, 4, 2);
        assert!(nl_means(&a, &c, &c, p).is_err());
    }
}
