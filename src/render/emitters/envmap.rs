//! Mitsuba 3's `envmap` emitter: an infinitely distant environment given by a lat-long image,
//! evaluated exactly as Mitsuba 3.9.1 evaluates it, and importance-sampled for next-event
//! estimation.
//!
//! # Mitsuba's conventions (reproduced exactly by [`EnvMap::eval`])
//!
//! * **Load.** The image is used as linear RGB with nothing done to it: no clamping (Mitsuba keeps
//!   negative texels; we reject them, see [`EnvMap::new`]), and an alpha channel is dropped
//!   without un-premultiplying (checked: an RGBA EXR with alpha 0.5 evaluates to its stored RGB).
//!   Mitsuba needs at least 2×3 pixels. It appends a copy of column 0 after the last column so
//!   that interpolation across the seam needs no wrap-around; we store the same `(W + 1) × H`
//!   texels.
//! * **Direction to local frame.** `v = A·d` with `A` the upper-left 3×3 block of the *inverse*
//!   of the 4×4 `to_world` (translation plays no part). `v` is **not normalised**: with a scaled
//!   `to_world` Mitsuba reads the texture at `acos(clamp(v.y))` of the scaled vector (checked: a
//!   `to_world` of `scale(0.5)` gives `eval(d) = eval_identity(2d)`), and so do we.
//! * **Lat-long mapping.** `+y` is up. `u = atan2(v.x, −v.z) / 2π` (so `u = 0` looks along local
//!   `−z` and `u` grows towards `+x`), `t = acos(v.y) / π` (`t = 0` at `+y`). Inversely
//!   `v = (sin φ sin θ, cos θ, −cos φ sin θ)` with `φ = 2πu`, `θ = πt`. Image row 0 (the top of
//!   the file) is `+y`.
//! * **Texel positions.** Columns are cell-centred, rows are not: texel `(x, y)` sits at
//!   `u = (x + ½)/W`, `t = y/(H − 1)`. So the first and last rows lie exactly on the poles and
//!   rows are `π/(H − 1)` apart. In code: `u −= ½/W`, both coordinates wrapped to `[0, 1)` by
//!   `c − floor(c)`, scaled by `(W, H − 1)`, the integer part clamped to `(W − 1, H − 2)`, then
//!   **bilinear** interpolation of the four surrounding texels, times `scale`. Across the seam
//!   the appended column makes the interpolation continuous; at the poles every column meets and
//!   the value depends on `u` (the image is not averaged there). Exactly at a pole `u` is the
//!   `atan2` of two components that are rounding noise, so there Mitsuba's column (and ours)
//!   is arbitrary: one direction, of no weight in any integral.
//! * **One deliberate difference.** Mitsuba's wrap also turns `t = 1` into `t = 0`, so a
//!   direction whose `acos` rounds to exactly `π` reads the *top* row instead of the bottom one.
//!   Whether that happens depends on the last bit of `A·d` (the fixture has both outcomes), and
//!   it is a single direction, so no expectation can depend on it; we read the bottom row,
//!   continuous with the neighbourhood.
//!
//! # Sampling (ours; Mitsuba's differs)
//!
//! Each bilinear patch between texel rows `j, j+1` and columns `i, i+1` (the same cells
//! [`EnvMap::eval`] interpolates in) is one **cell** of the sampling distribution, with
//! probability proportional to `m·Ω`: `m` the mean luminance (Rec. 709 weights, as Mitsuba's
//! `luminance`) of its four corner texels, `Ω = (2π/W)·(cos θ_j − cos θ_{j+1})` its exact solid
//! angle, which is the integral of the `sin θ` Jacobian over the cell. Inside a cell the
//! direction is uniform in solid angle (`φ` uniform, `cos θ` uniform), so the density is
//! piecewise constant, `pdf = m / Σ m·Ω`, bounded even at the poles. Two alias draws (row,
//! then column within the row) make a sample O(1) ([`Cell`]).
//!
//! Mitsuba instead warps with a `Hierarchical2D` over the texels' `luminance · sin θ` with a
//! bilinear density in `(u, t)`. Both densities are positive wherever the texture is: a cell's
//! mean luminance is zero only if its four corners are black, and then the bilinear radiance is
//! zero on the whole cell. So for every direction with `eval > 0` (up to cell edges, a set of
//! measure zero) our `pdf > 0`, and the estimator `eval/pdf` (alone or MIS-weighted) has the
//! same expectation as Mitsuba's; only the variance differs.
//!
//! With a `to_world` whose linear part is not orthonormal, Mitsuba's distorted read-out above no
//! longer matches any density built on the undistorted image. Then the table is sampled on
//! normalised local directions (solid-angle Jacobian `|det A| / |A·d|³` to the world direction)
//! and mixed with a uniform-sphere density of weight [`DEFENSIVE`], which keeps `pdf > 0`
//! everywhere, hence unbiasedness. Scenes in practice use rotations, which take the exact path.
//!
//! # Use in an integrator
//!
//! The emitter is infinitely distant and not a delta light: [`EnvMap::sample`] ignores the
//! shading point, and its shadow ray must be unoccluded to infinity (Mitsuba tests it to twice
//! the scene's bounding sphere, which is the same). Divide by the emitter-selection probability
//! and use `selection · pdf` as the light strategy's density in the MIS weight, as Mitsuba's
//! `path` does; a BSDF-sampled ray that escapes the scene gets `eval` weighted against
//! `selection · pdf(d)` ([`EnvMap::eval_pdf`] gives both at once), and 1 after a delta lobe.
//! Camera rays that escape see [`EnvMap::eval`] unweighted.

use super::{Emitter, LightSample};
use crate::error::{Error, Result};
use crate::image::Image;
use crate::image::read::read_texture;
use crate::render::huge_table::HugeTable;
use crate::render::mitsuba::Params;
use crate::render::prefetch::prefetch;
use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI, TAU};
use std::fmt;
use std::sync::Arc;

/// Linear RGB radiance.
type Rgb = Vec3;

/// Luminance weights of linear sRGB / Rec. 709 primaries (Mitsuba's `luminance`).
const LUMINANCE: [f64; 3] = [0.212_671, 0.715_160, 0.072_169];

/// Probability of sampling the uniform sphere when `to_world` is not a rotation (see the module
/// documentation); large enough to bound `eval/pdf` by `4π·max radiance / DEFENSIVE`.
pub const DEFENSIVE: f32 = 0.25;

/// Largest deviation of `AᵀA` from the identity for `to_world` to count as a rotation (or
/// reflection): XML matrices written to 6 digits land far inside it.
const RIGID_TOLERANCE: f32 = 1e-5;

/// The largest `f32` below 1: where uniform variates are clamped so that a search never runs
/// off the end of a table.
const ONE_MINUS_EPS: f32 = 1.0 - f32::EPSILON / 2.0;

/// Mitsuba's `envmap` emitter. Cheap to share: all tables are built once in [`EnvMap::new`].
#[derive(Clone)]
pub struct EnvMap {
    /// Image width `W` (texel columns, without the appended seam column).
    width: usize,
    /// Image height `H` (texel rows, the first and last on the poles).
    height: usize,
    /// Mitsuba's `scale`, applied to every texel value.
    scale: f32,
    /// `A`: world to local, the linear part of `to_world⁻¹`.
    to_local: Mat3,
    /// `A⁻¹`: local to world, for sampled directions.
    to_world: Mat3,
    /// Whether `A` is orthonormal (within [`RIGID_TOLERANCE`]), so no Jacobian or mixture.
    rigid: bool,
    /// `|det A|`, the solid-angle Jacobian's numerator when `A` is not rigid.
    det_to_local: f32,
    /// Whether any cell has positive luminance; if not, nothing is sampled.
    has_mass: bool,
    /// Alias table of the cell rows (`H − 1` entries).
    rows: Vec<AliasEntry>,
    /// Per cell row, the alias table of its `W` cells given the row (row-major, as `cells`).
    buckets: HugeTable<AliasEntry>,
    /// The `(H − 1)·W` cells, row-major: corner texels and density.
    cells: HugeTable<Cell>,
    /// `1 − cos θ_k` at the `H` texel rows, exact near the north pole.
    one_minus_cos: Vec<f32>,
    /// `1 + cos θ_k` at the `H` texel rows, exact near the south pole.
    one_plus_cos: Vec<f32>,
    /// `[cos θ_k, sin θ_k]` at the `H` texel rows, to find a sampled direction's offset into
    /// its row without `atan2`; empty when a row spans more than [`SERIES_SPAN`].
    row_trig: Vec<[f64; 2]>,
}

/// The widest row (in radians) for which [`EnvMap::sample_table`] finds the offset into the
/// row from its sine by four terms of the `asin` series (left out: `35x⁹/1152`, below 2e-8 at
/// 0.2); maps of fewer than 17 rows use `atan2`.
const SERIES_SPAN: f64 = 0.2;

impl fmt::Debug for EnvMap {
    /// A summary: the texel and table contents would run to megabytes.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("EnvMap")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("scale", &self.scale)
            .field("to_local", &self.to_local)
            .field("rigid", &self.rigid)
            .field("has_mass", &self.has_mass)
            .finish_non_exhaustive()
    }
}

/// One bilinear patch of the map: what a read-out of it needs (radiance and density), in one
/// cache line.
///
/// Why not the texel grid and a density table: on a 2048x1024 map a read-out then touched
/// three scattered lines (density, two texel rows), and sampling and reading the map took a
/// quarter of the living room's render time. A cell repeats its four corners: 64 bytes per
/// cell, 134 MB for a 2048x1024 map (plus 16 MB of alias buckets), where the texels, densities
/// and buckets took 48 MB.
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
#[repr(C, align(64))]
struct Cell {
    /// Texels `(i, j)`, `(i + 1, j)`, `(i, j + 1)`, `(i + 1, j + 1)` (column `W` is column 0).
    corners: [Vec3; 4],
    /// Solid-angle density in the local frame (0 for a black cell or a black map).
    pdf: f32,
    /// Fills the cache line (plain data has no implicit padding).
    unused: [f32; 3],
}

const _: () = assert!(std::mem::size_of::<Cell>() == 64);

impl Cell {
    /// Bilinear blend of the corners, with weights `fu`, `ft` of the right and lower ones (in
    /// Mitsuba's order of operations).
    #[inline]
    fn bilinear(&self, fu: f32, ft: f32) -> Rgb {
        let [a, b, c, d] = self.corners;
        let (gu, gt) = (1.0 - fu, 1.0 - ft);
        let top = gu * a + fu * b;
        let bottom = gu * c + fu * d;
        gt * top + ft * bottom
    }
}

/// A cell and the position inside it, as produced by the table sampler.
struct CellSample {
    /// Local-frame unit direction.
    dir: Vec3,
    /// Cell column `i` and row `j`.
    i: usize,
    j: usize,
    /// Bilinear weights of the far corners (`u` and `t` fractions inside the cell).
    fu: f32,
    ft: f32,
}

/// Reads `<emitter type="envmap">`: `filename` (OpenEXR or Radiance HDR, relative to the scene's folder),
/// `scale` (default 1), `to_world`.
pub fn load(p: &mut Params) -> Result<Arc<dyn Emitter>> {
    let filename = p.string("filename")?;
    let scale = p.float("scale")?;
    let to_world = p.transform("to_world")?;
    p.finish()?;
    let Some((filename, at)) = filename else {
        return Err(p.err(
            None,
            "missing required parameter <string name=\"filename\">",
        ));
    };
    let to_world = to_world.map_or(Mat4::IDENTITY, |(m, _)| m);
    let path = p.loader().base_dir().join(&filename);
    let image = read_texture(&path, false)
        .and_then(|t| {
            let pixels = match t.channels {
                1 => t.data.iter().map(|&v| [v; 3]).collect(),
                _ => t.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            };
            Image::from_pixels(t.width, t.height, pixels)
        })
        .map_err(|e| p.err(Some(at), format!("cannot read the environment map: {e}")))?;
    let map = EnvMap::new(&image, to_world, scale.map_or(1.0, |(s, _)| s))
        .map_err(|e| p.err(scale.map(|(_, at)| at), e.to_string()))?;
    Ok(Arc::new(map))
}

impl Emitter for EnvMap {
    fn sample(&self, _from: Vec3, u: Vec2) -> Option<LightSample> {
        if self.rigid && self.has_mass {
            let (wi, key) = self.sample_direction(u);
            return Some(LightSample::deferred(wi, key));
        }
        let (wi, radiance, pdf) = EnvMap::sample(self, u)?;
        Some(LightSample::new(wi, f32::INFINITY, radiance, pdf, false))
    }

    fn prefetch(&self, u: Vec2) {
        if self.prefetches() {
            self.prefetch_draw(u);
        }
    }

    /// A rigid map with mass draws from its tables ([`EnvMap::sample_direction`]); the others
    /// take another path (or none).
    fn prefetches(&self) -> bool {
        self.rigid && self.has_mass
    }

    fn resolve(&self, key: [u32; 3]) -> (Rgb, f32) {
        self.read_cell(key)
    }

    fn is_infinite(&self) -> bool {
        true
    }

    fn eval_pdf_escaped(&self, d: Vec3) -> (Rgb, f32) {
        self.eval_pdf(d)
    }
}

impl EnvMap {
    /// An environment from `image` (linear RGB radiance, row 0 the top of the file = `+y`),
    /// Mitsuba's `to_world` and `scale`. Errors name the offending parameter: an image smaller
    /// than Mitsuba's 2×3 minimum, a NaN, infinite or negative texel (Mitsuba would keep a
    /// negative one, which has no meaning as radiance and no sampling density), a negative or
    /// non-finite `scale`, and a singular or non-finite `to_world`.
    pub fn new(image: &Image, to_world: Mat4, scale: f32) -> Result<EnvMap> {
        let (w, h) = (image.width(), image.height());
        if w < 2 || h < 3 {
            return Err(Error::param(
                "envmap image",
                format!("{w}x{h}"),
                "an environment map needs at least 2x3 pixels (as in Mitsuba)",
            ));
        }
        if !(scale.is_finite() && scale >= 0.0) {
            return Err(Error::param(
                "envmap scale",
                scale,
                "must be finite and >= 0",
            ));
        }
        let (to_local, to_world_lin) = linear_parts(to_world)?;

        // `H` rows of `W + 1` texels, the last column a copy of the first.
        let mut texels = Vec::with_capacity((w + 1) * h);
        for y in 0..h {
            for x in 0..w {
                let p = image.get(x, y);
                if !p.iter().all(|c| c.is_finite() && *c >= 0.0) {
                    return Err(Error::param(
                        "envmap pixel",
                        format!("({x}, {y}) = {p:?}"),
                        "radiance must be finite and >= 0",
                    ));
                }
                texels.push(Vec3::from(p));
            }
            texels.push(Vec3::from(image.get(0, y)));
        }

        let rigid = (to_local.transpose() * to_local - Mat3::IDENTITY)
            .to_cols_array()
            .iter()
            .all(|e| e.abs() <= RIGID_TOLERANCE);

        let mut map = EnvMap {
            width: w,
            height: h,
            scale,
            to_local,
            to_world: to_world_lin,
            rigid,
            det_to_local: to_local.determinant().abs(),
            has_mass: false,
            rows: Vec::new(),
            buckets: HugeTable::default(),
            cells: HugeTable::default(),
            one_minus_cos: Vec::new(),
            one_plus_cos: Vec::new(),
            row_trig: Vec::new(),
        };
        map.build_tables(&texels)?;
        Ok(map)
    }

    /// Builds the sampling tables (all sums in `f64`, so that a cell of tiny mass keeps its
    /// share until the final rounding to `f32`).
    fn build_tables(&mut self, texels: &[Vec3]) -> Result<()> {
        let (w, h) = (self.width, self.height);
        let rows = h - 1;
        let lum: Vec<f64> = texels
            .iter()
            .map(|t| {
                LUMINANCE[0] * t.x as f64 + LUMINANCE[1] * t.y as f64 + LUMINANCE[2] * t.z as f64
            })
            .collect();

        // 1 − cos θ = 2 sin²(θ/2) and 1 + cos θ = 2 cos²(θ/2) keep full relative precision
        // near the respective pole, where 1 − z² would cancel.
        let theta = |k: usize| k as f64 * std::f64::consts::PI / rows as f64;
        let omc: Vec<f64> = (0..h)
            .map(|k| 2.0 * (theta(k) / 2.0).sin().powi(2))
            .collect();
        self.one_minus_cos = omc.iter().map(|&c| c as f32).collect();
        self.one_plus_cos = (0..h)
            .map(|k| (2.0 * (theta(k) / 2.0).cos().powi(2)) as f32)
            .collect();
        self.row_trig = if std::f64::consts::PI / rows as f64 <= SERIES_SPAN {
            (0..h).map(|k| [theta(k).cos(), theta(k).sin()]).collect()
        } else {
            Vec::new()
        };

        let stride = w + 1;
        let mut mean = vec![0.0f64; rows * w];
        let mut row_mass = vec![0.0f64; rows];
        for j in 0..rows {
            let solid_angle = std::f64::consts::TAU / w as f64 * (omc[j + 1] - omc[j]);
            let mut sum = 0.0;
            for i in 0..w {
                let k = j * stride + i;
                let m = 0.25 * (lum[k] + lum[k + 1] + lum[k + stride] + lum[k + stride + 1]);
                mean[j * w + i] = m;
                sum += m;
            }
            row_mass[j] = sum * solid_angle;
        }
        let total: f64 = row_mass.iter().sum();
        self.has_mass = total > 0.0 && total.is_finite();
        if self.has_mass {
            self.rows = alias_table(&row_mass);
        }

        self.cells = HugeTable::zeroed(rows * w, "environment map cells")?;
        self.buckets = HugeTable::zeroed(rows * w, "environment map alias tables")?;
        for j in 0..rows {
            let row = &mean[j * w..(j + 1) * w];
            let buckets = if self.has_mass && row_mass[j] > 0.0 {
                alias_table(row)
            } else {
                // Never selected (zero row probability); any valid table will do.
                (0..w)
                    .map(|i| AliasEntry {
                        keep: 1.0,
                        alias: i as u32,
                    })
                    .collect()
            };
            self.buckets[j * w..(j + 1) * w].copy_from_slice(&buckets);
            for (i, &m) in row.iter().enumerate() {
                let k = j * stride + i;
                let pdf = if self.has_mass && m > 0.0 {
                    // Never round a lit cell's density to 0: `pdf > 0` wherever `eval > 0`.
                    (m / total).max(f32::MIN_POSITIVE as f64) as f32
                } else {
                    0.0
                };
                self.cells[j * w + i] = Cell {
                    corners: [
                        texels[k],
                        texels[k + 1],
                        texels[k + stride],
                        texels[k + stride + 1],
                    ],
                    pdf,
                    unused: [0.0; 3],
                };
            }
        }
        Ok(())
    }

    /// Radiance arriving along a ray that escaped with unit world direction `d` (Mitsuba's
    /// `eval` for a surface interaction with `wi = −d`).
    pub fn eval(&self, d: Vec3) -> Rgb {
        let v = self.to_local * d;
        let (u, t) = self.texel_coords(v);
        self.radiance_at(u, t)
    }

    /// Solid-angle density with which [`EnvMap::sample`] returns the unit world direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        if !self.has_mass {
            return 0.0;
        }
        let v = self.to_local * d;
        if self.rigid {
            let (u, t) = self.texel_coords(v);
            return self.locate(u, t).0.pdf;
        }
        let len2 = v.length_squared();
        let len = len2.sqrt();
        let (u, t) = self.texel_coords(v / len);
        let table = self.locate(u, t).0.pdf * self.det_to_local / (len2 * len);
        (1.0 - DEFENSIVE) * table + DEFENSIVE / (4.0 * PI)
    }

    /// `(eval(d), pdf(d))` with the direction mapped once: what an integrator needs when a
    /// BSDF-sampled ray escapes and is weighted by MIS.
    pub fn eval_pdf(&self, d: Vec3) -> (Rgb, f32) {
        if !(self.rigid && self.has_mass) {
            return (self.eval(d), self.pdf(d));
        }
        let v = self.to_local * d;
        let (u, t) = self.texel_coords(v);
        let (cell, fu, ft) = self.locate(u, t);
        (cell.bilinear(fu, ft) * self.scale, cell.pdf)
    }

    /// Next-event sample from two uniform variates in `[0, 1)`: a unit world direction towards
    /// the environment, the radiance arriving from it (= `eval` of that direction, up to
    /// rounding) and its solid-angle density (> 0). `None` when the map is black.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Rgb, f32)> {
        if !self.has_mass {
            return None;
        }
        if self.rigid {
            let (d, key) = self.sample_direction(u);
            let (radiance, pdf) = self.read_cell(key);
            return Some((d, radiance, pdf));
        }
        let d = if u.x < DEFENSIVE {
            uniform_sphere(Vec2::new(u.x / DEFENSIVE, u.y))
        } else {
            let ux = (u.x - DEFENSIVE) / (1.0 - DEFENSIVE);
            (self.to_world * self.sample_table(Vec2::new(ux, u.y)).dir).normalize()
        };
        let pdf = self.pdf(d);
        (pdf > 0.0 && d.is_finite()).then(|| (d, self.eval(d), pdf))
    }

    /// The direction half of [`EnvMap::sample`] for a rigid map with mass: a unit world
    /// direction and the key [`EnvMap::read_cell`] turns into its radiance and density.
    #[inline]
    fn sample_direction(&self, u: Vec2) -> (Vec3, [u32; 3]) {
        let s = self.sample_table(u);
        let d = (self.to_world * s.dir).normalize();
        let cell = (s.j * self.width + s.i) as u32;
        // Read by `read_cell` only after the shadow ray, which gives the line time to come.
        prefetch(&self.cells[cell as usize]);
        (d, [cell, s.fu.to_bits(), s.ft.to_bits()])
    }

    /// The radiance and density of a draw of [`EnvMap::sample_direction`].
    #[inline]
    fn read_cell(&self, [cell, fu, ft]: [u32; 3]) -> (Rgb, f32) {
        let cell = &self.cells[cell as usize];
        let radiance = cell.bilinear(f32::from_bits(fu), f32::from_bits(ft)) * self.scale;
        (radiance, cell.pdf)
    }

    /// Mitsuba's `(u − ½/W, t)` of a local direction, `u` wrapped to `[0, 1]`, `t` in `[0, 1]`
    /// (not wrapped, see the module documentation).
    #[inline]
    fn texel_coords(&self, v: Vec3) -> (f32, f32) {
        let u = v.x.atan2(-v.z) * (0.5 * FRAC_1_PI) - 0.5 / self.width as f32;
        let t = v.y.clamp(-1.0, 1.0).acos() * FRAC_1_PI;
        (u - u.floor(), t)
    }

    /// Mitsuba's bilinear read-out at texel coordinates from [`EnvMap::texel_coords`], times
    /// `scale`.
    #[inline]
    fn radiance_at(&self, u: f32, t: f32) -> Rgb {
        let (cell, fu, ft) = self.locate(u, t);
        cell.bilinear(fu, ft) * self.scale
    }

    /// The cell holding texel coordinates `(u, t)` and the position inside it (the bilinear
    /// weights of its right and lower corners).
    #[inline]
    fn locate(&self, u: f32, t: f32) -> (&Cell, f32, f32) {
        let x = u * self.width as f32;
        let y = t * (self.height - 1) as f32;
        // `as usize` floors these non-negative values (and maps NaN to 0).
        let i = (x as usize).min(self.width - 1);
        let j = (y as usize).min(self.height - 2);
        (&self.cells[j * self.width + i], x - i as f32, y - j as f32)
    }

    /// Starts loading the conditional bucket [`EnvMap::sample_table`] with `u` will read (the
    /// row's marginal table is small and stays cached): the one load of a draw that missed the
    /// cache.
    #[inline]
    fn prefetch_draw(&self, u: Vec2) {
        let (j, _) = alias_sample(&self.rows, u.y);
        let w = self.width;
        prefetch(&self.buckets[j * w + alias_bucket(w, u.x).0]);
    }

    /// Draws a cell (row by its marginal, then column by its conditional), then a direction
    /// uniform in solid angle inside it, reusing each variate's remainder for the position.
    fn sample_table(&self, u: Vec2) -> CellSample {
        let (w, h) = (self.width, self.height);
        let (j, rt) = alias_sample(&self.rows, u.y);
        let (i, ru) = alias_sample(&self.buckets[j * w..(j + 1) * w], u.x);

        let phi = TAU * ((i as f32 + 0.5 + ru) / w as f32);
        let (sin_phi, cos_phi) = phi.sin_cos();
        let (omc, opc) = (&self.one_minus_cos, &self.one_plus_cos);
        let (z, sin_theta) = if omc[j] + omc[j + 1] <= 2.0 {
            // Northern cell: interpolate 1 − z, exact near +y.
            let a = omc[j] + rt * (omc[j + 1] - omc[j]);
            (1.0 - a, (a * (2.0 - a)).max(0.0).sqrt())
        } else {
            let b = opc[j] + rt * (opc[j + 1] - opc[j]);
            (b - 1.0, (b * (2.0 - b)).max(0.0).sqrt())
        };
        let dir = Vec3::new(sin_phi * sin_theta, z, -cos_phi * sin_theta);
        // The bilinear weight along t is linear in θ, not in z: it is `(θ − θ_j)/Δθ`. From
        // `sin(θ − θ_j)` in f64 and a short series: `atan2`'s value without its cost (3% of the
        // living room's instructions), and more exact than `θ·(H−1)/π − j` in f32, which loses
        // the bits of `j` (see `row_offset_matches_atan2`).
        let ft = match self.row_trig.get(j) {
            Some(&row) => row_offset(sin_theta, z, row, h - 1),
            None => {
                let theta = sin_theta.atan2(z);
                (theta * ((h - 1) as f32 * FRAC_1_PI) - j as f32).clamp(0.0, 1.0)
            }
        };
        CellSample {
            dir,
            i,
            j,
            fu: ru,
            ft,
        }
    }
}

/// Where the direction at `θ` (given as `sin θ`, `cos θ`) lies between the texel row at
/// `θ_j` (0) and the next (1), for `row = [cos θ_j, sin θ_j]` and `rows` rows over `[0, π]`:
/// `(θ − θ_j)·rows/π`, with `θ − θ_j = asin(sin θ cos θ_j − cos θ sin θ_j)` by the series to
/// `x⁷` (rows at most [`SERIES_SPAN`] wide), clamped to `[0, 1]`.
#[inline]
fn row_offset(sin_theta: f32, z: f32, [c, s]: [f64; 2], rows: usize) -> f32 {
    let x = f64::from(sin_theta) * c - f64::from(z) * s;
    let x2 = x * x;
    let offset = x * (1.0 + x2 * (1.0 / 6.0 + x2 * (3.0 / 40.0 + x2 * (5.0 / 112.0))));
    ((offset * (rows as f64 * std::f64::consts::FRAC_1_PI)) as f32).clamp(0.0, 1.0)
}

/// The linear parts `(A, A⁻¹)` of `to_world⁻¹` and its inverse, as Mitsuba applies `to_world`
/// to directions; an error for a singular or non-finite matrix.
fn linear_parts(to_world: Mat4) -> Result<(Mat3, Mat3)> {
    let singular = || {
        Error::param(
            "envmap to_world",
            format!("{:?}", to_world.transpose().to_cols_array_2d()),
            "must be a finite, invertible matrix (rows shown)",
        )
    };
    let det = to_world.determinant();
    if !to_world.is_finite() || det == 0.0 || !det.is_finite() {
        return Err(singular());
    }
    let to_local = Mat3::from_mat4(to_world.inverse());
    let det_local = to_local.determinant();
    if !to_local.is_finite() || det_local == 0.0 || !det_local.is_finite() {
        return Err(singular());
    }
    let back = to_local.inverse();
    if !back.is_finite() {
        return Err(singular());
    }
    Ok((to_local, back))
}

/// One bucket of an alias table (Walker 1977, Vose 1991): keep the bucket's own item with
/// probability `keep`, else take `alias`.
///
/// Why not a cumulative table and a binary search: on a 2048x1024 map the column search's dozen
/// dependent reads each missed the cache, and sampling the map took a third of the living room's
/// render time. An alias draw reads one 8-byte entry.
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
#[repr(C)]
struct AliasEntry {
    keep: f32,
    alias: u32,
}

/// The alias table of non-negative `weights` with a positive, finite total: item `i` is drawn
/// with probability `weights[i] / total` (up to f32 rounding of `keep`), and zero-weight items
/// never.
fn alias_table(weights: &[f64]) -> Vec<AliasEntry> {
    let n = weights.len();
    let total: f64 = weights.iter().sum();
    let mut scaled: Vec<f64> = weights.iter().map(|&x| x * n as f64 / total).collect();
    let mut table: Vec<AliasEntry> = (0..n)
        .map(|i| AliasEntry {
            keep: 1.0,
            alias: i as u32,
        })
        .collect();
    let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| scaled[i] < 1.0);
    while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
        small.pop();
        table[s] = AliasEntry {
            keep: scaled[s] as f32,
            alias: l as u32,
        };
        // The large item gives the small bucket what it lacks.
        scaled[l] -= 1.0 - scaled[s];
        if scaled[l] < 1.0 {
            large.pop();
            small.push(l);
        }
    }
    // Left-overs are 1 up to rounding: they keep their own bucket (already so), except that
    // a zero-weight item must never keep one.
    for i in small.into_iter().chain(large) {
        if weights[i] == 0.0 {
            let donor = (0..n).find(|&k| weights[k] > 0.0).unwrap_or(i);
            table[i] = AliasEntry {
                keep: 0.0,
                alias: donor as u32,
            };
        }
    }
    table
}

/// The item the uniform `u` draws from `table`, and a fresh uniform in `[0, 1)` for use within
/// the item (the part of `u` the draw did not consume).
#[inline]
fn alias_sample(table: &[AliasEntry], u: f32) -> (usize, f32) {
    let (k, f) = alias_bucket(table.len(), u);
    let entry = table[k];
    if f < entry.keep {
        (k, (f / entry.keep).min(ONE_MINUS_EPS))
    } else {
        let r = (f - entry.keep) / (1.0 - entry.keep);
        (entry.alias as usize, r.clamp(0.0, ONE_MINUS_EPS))
    }
}

/// The bucket of a table of `n` that `u` falls in, and where in it (in `[0, 1)`).
#[inline]
fn alias_bucket(n: usize, u: f32) -> (usize, f32) {
    let x = u.clamp(0.0, ONE_MINUS_EPS) * n as f32;
    let k = (x as usize).min(n - 1);
    (k, (x - k as f32).clamp(0.0, ONE_MINUS_EPS))
}

/// Uniform direction on the unit sphere (density `1/4π`).
fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (TAU * u.x).sin_cos();
    Vec3::new(r * c, r * s, z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// A small map with what breaks careless code: a black block (zero luminance next to lit
    /// texels), one very bright texel, and different first and last columns (the seam).
    fn test_image() -> Image {
        let (w, h) = (12usize, 7usize);
        let mut px = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let a = 1.0 + 0.7 * (x as f32 * 0.9).sin() * (y as f32 * 0.5).cos();
                let mut p = [a, 0.5 + 0.05 * (x * y) as f32, 0.3 + 0.1 * x as f32];
                if (2..5).contains(&y) && (4..8).contains(&x) {
                    p = [0.0; 3];
                }
                if (x, y) == (9, 1) {
                    p = [60.0, 40.0, 10.0];
                }
                if x == 0 {
                    p[0] *= 3.0;
                }
                px.push(p);
            }
        }
        Image::from_pixels(w, h, px).unwrap()
    }

    /// A rotation about a skew axis, with a translation that must be ignored.
    fn rotation() -> Mat4 {
        Mat4::from_translation(Vec3::new(1.0, -2.0, 3.0))
            * Mat4::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.8)
    }

    /// Not orthonormal: rotation, anisotropic scale and shear.
    fn distortion() -> Mat4 {
        Mat4::from_axis_angle(Vec3::new(-2.0, 1.0, 0.5).normalize(), 2.1)
            * Mat4::from_cols_array(&[
                0.5, 0.1, 0.0, 0.0, 0.0, 0.7, 0.0, 0.0, 0.2, 0.0, 0.6, 0.0, 0.0, 0.0, 0.0, 1.0,
            ])
    }

    fn rng(seed: u64) -> Xoshiro256PlusPlus {
        Xoshiro256PlusPlus::seed_from_u64(seed)
    }

    fn u2(r: &mut Xoshiro256PlusPlus) -> Vec2 {
        Vec2::new(r.random::<f32>(), r.random::<f32>())
    }

    /// Midpoint quadrature over the sphere on an `n × n` grid in `(φ, z)` (equal-area cells):
    /// returns `Σ g(d)·4π/n²` in `f64`.
    fn sphere_quadrature(n: usize, mut g: impl FnMut(Vec3) -> f64) -> f64 {
        let mut sum = 0.0;
        for a in 0..n {
            let z = 1.0 - 2.0 * (a as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            for b in 0..n {
                let phi = std::f64::consts::TAU * (b as f64 + 0.5) / n as f64;
                let d = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                sum += g(d);
            }
        }
        sum * 4.0 * std::f64::consts::PI / (n * n) as f64
    }

    fn lum(c: Rgb) -> f64 {
        LUMINANCE[0] * c.x as f64 + LUMINANCE[1] * c.y as f64 + LUMINANCE[2] * c.z as f64
    }

    /// Texel-grid coordinates `(u·W, t·(H − 1))` of a world direction, for locating cell edges.
    fn grid_coords(map: &EnvMap, d: Vec3) -> (f32, f32) {
        let v = map.to_local * d;
        let (u, t) = map.texel_coords(v.normalize());
        (u * map.width as f32, t * (map.height - 1) as f32)
    }

    fn near_integer(x: f32, tol: f32) -> bool {
        (x - x.round()).abs() <= tol
    }

    #[test]
    fn sample_density_matches_pdf() {
        // A sample's own pdf is its cell's; `pdf(d)` re-derives the cell from `d` and can pick
        // the neighbour when rounding puts `d` on the other side of an edge. Each such case must
        // lie on a cell edge, and they must be rare (expected rate ~1e-6 here).
        for (to_world, name) in [(rotation(), "rotation"), (distortion(), "distortion")] {
            let map = EnvMap::new(&test_image(), to_world, 1.3).unwrap();
            assert_eq!(map.rigid, name == "rotation");
            let mut r = rng(11);
            let mut edge_cases = 0;
            for _ in 0..100_000 {
                let (d, radiance, pdf) = map.sample(u2(&mut r)).unwrap();
                assert!(
                    (d.length() - 1.0).abs() < 1e-5,
                    "{name}: |d| = {}",
                    d.length()
                );
                assert!(pdf > 0.0 && pdf.is_finite());
                let e = map.eval(d);
                // `eval` reads θ as acos(y) of a rounded f32 direction, whose error grows as
                // 1/sin θ towards the poles; the sample computes θ exactly in the local frame.
                let v = (map.to_local * d).normalize();
                let sin_theta = (v.x * v.x + v.z * v.z).sqrt().max(1e-3);
                assert!(
                    (radiance - e).abs().max_element()
                        <= 1e-4 * (1.0 + e.max_element()) / sin_theta,
                    "{name}: sample radiance {radiance} vs eval {e}"
                );
                let p = map.pdf(d);
                if (p - pdf).abs() > 1e-6 * pdf {
                    let (x, y) = grid_coords(&map, d);
                    assert!(
                        near_integer(x, 1e-3) || near_integer(y, 1e-3),
                        "{name}: pdf(d) = {p} vs sample pdf {pdf} away from a cell edge ({x}, {y})"
                    );
                    edge_cases += 1;
                }
                let (e2, p2) = map.eval_pdf(d);
                assert_eq!((e2, p2), (e, p));
            }
            assert!(edge_cases <= 10, "{name}: {edge_cases} edge mismatches");
        }
    }

    /// The offset into a row from the `asin` series against `atan2` in f64, on rows as wide as
    /// the series is used for (16 rows) and as narrow as a 2048x1024 map's, over random
    /// directions inside each row: within 2e-7 (about three f32 ulps of 1). A series cut one term
    /// short errs by 2e-6 on the wide rows; a sign slip in the angle difference, or the row's
    /// own angle from the wrong row, is off by whole rows. The f32 formula it replaced,
    /// `atan2(sin θ, cos θ)·rows/π − j`, erred by up to 1.3e-4 on the narrow rows (ulps of θ
    /// and of `j`, 200 000 draws in NumPy). Deterministic.
    #[test]
    fn row_offset_matches_atan2() {
        let mut r = rng(5);
        for rows in [16usize, 1023] {
            let theta = |k: usize| k as f64 * std::f64::consts::PI / rows as f64;
            for _ in 0..20_000 {
                let j = r.random_range(0..rows);
                let at = theta(j) + r.random::<f64>() * (theta(j + 1) - theta(j));
                let (sin_theta, z) = (at.sin() as f32, at.cos() as f32);
                let exact = (f64::from(sin_theta).atan2(f64::from(z)) - theta(j)) * rows as f64
                    / std::f64::consts::PI;
                let got = row_offset(sin_theta, z, [theta(j).cos(), theta(j).sin()], rows);
                assert!(
                    (f64::from(got) - exact.clamp(0.0, 1.0)).abs() <= 2e-7,
                    "rows {rows}, row {j}, θ {at}: {got} against {exact}"
                );
            }
        }
    }

    #[test]
    fn pdf_integrates_to_one() {
        // Quadrature of a piecewise-constant density: the error comes from grid points next to
        // cell edges and was measured below 1e-4 at n = 1200. The 1e-3 bound catches a density
        // normalised with a wrong solid angle (each pole row alone carries ~1% of the mass) or
        // a missing Jacobian (the distorted map is off by tens of percent without it).
        for to_world in [Mat4::IDENTITY, rotation(), distortion()] {
            let map = EnvMap::new(&test_image(), to_world, 1.0).unwrap();
            let integral = sphere_quadrature(1200, |d| map.pdf(d) as f64);
            assert!((integral - 1.0).abs() < 1e-3, "∫pdf = {integral}");
        }
    }

    #[test]
    fn next_event_estimate_is_unbiased() {
        // E[f·eval/pdf] under `sample` against quadrature of f·eval (n = 1500; it moves by
        // < 2e-5 relative from n = 1500 to 3000, the integrand being continuous). The Monte
        // Carlo side is judged at 5 standard errors: a correct implementation fails with
        // probability ~6e-7. The standard error is 0.12% (rotation) and 0.35% (distortion), so
        // a bias of ~0.7% resp. 2% is caught, e.g. a density off by 10% on a tenth of the sphere
        // with the rotation. [`sample_histogram_matches_pdf`] checks the density locally.
        let f = |d: Vec3| 1.0 + 0.5 * d.x as f64 - 0.3 * (d.y * d.z) as f64 + 0.2 * d.z as f64;
        for to_world in [rotation(), distortion()] {
            let map = EnvMap::new(&test_image(), to_world, 0.7).unwrap();
            let reference = sphere_quadrature(1500, |d| f(d) * lum(map.eval(d)));
            let mut r = rng(5);
            let n = 200_000;
            let (mut s, mut s2) = (0.0, 0.0);
            for _ in 0..n {
                let (d, radiance, pdf) = map.sample(u2(&mut r)).unwrap();
                let x = f(d) * lum(radiance) / pdf as f64;
                s += x;
                s2 += x * x;
            }
            let mean = s / n as f64;
            let sigma = ((s2 / n as f64 - mean * mean) / n as f64).sqrt();
            assert!(
                (mean - reference).abs() < 5.0 * sigma + 1e-4 * reference,
                "MC {mean} ± {sigma} vs quadrature {reference}"
            );
        }
    }

    #[test]
    fn sample_histogram_matches_pdf() {
        // Pearson's chi-square of 200k samples over 24 × 12 equal-area world bins (φ, z),
        // expected counts from a 30 × 30 quadrature of `pdf` per bin (relative error < 1e-3,
        // i.e. about one count, against a statistical spread of ~25). Threshold at the
        // 1 − 1e-6 quantile: a correct sampler fails once in a million seeds; a density off by
        // 15% in a single bin (~690 expected) already adds ~20 to a statistic whose
        // threshold lies ~100 above its mean, so broad or repeated defects are what it catches.
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        let (nphi, nz, sub) = (24usize, 12usize, 30usize);
        let bin = |d: Vec3| {
            let a = (((1.0 - d.z) / 2.0 * nz as f32) as usize).min(nz - 1);
            let phi = d.y.atan2(d.x).rem_euclid(TAU);
            let b = ((phi / TAU * nphi as f32) as usize).min(nphi - 1);
            a * nphi + b
        };
        for to_world in [rotation(), distortion()] {
            let map = EnvMap::new(&test_image(), to_world, 1.0).unwrap();
            let mut expected = vec![0.0f64; nphi * nz];
            let n = nphi * sub;
            for a in 0..nz * sub {
                let z = 1.0 - 2.0 * (a as f64 + 0.5) / (nz * sub) as f64;
                let r = (1.0 - z * z).sqrt();
                for b in 0..n {
                    let phi = std::f64::consts::TAU * (b as f64 + 0.5) / n as f64;
                    let d = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                    expected[(a / sub) * nphi + b / sub] += map.pdf(d) as f64;
                }
            }
            let samples = 200_000;
            let cell = 4.0 * std::f64::consts::PI / (n * nz * sub) as f64;
            expected
                .iter_mut()
                .for_each(|e| *e *= cell * samples as f64);
            let mut counts = vec![0u32; nphi * nz];
            let mut r = rng(17);
            for _ in 0..samples {
                let (d, _, _) = map.sample(u2(&mut r)).unwrap();
                counts[bin(d)] += 1;
            }
            // Bins the density says are empty must be; bins expecting under 5 samples are
            // pooled into one, as the chi-square approximation needs.
            let (mut chi2, mut bins) = (0.0, 0usize);
            let (mut pooled_e, mut pooled_c) = (0.0f64, 0u32);
            for (&c, &e) in counts.iter().zip(&expected) {
                if e == 0.0 {
                    assert_eq!(c, 0, "a bin of zero density holds {c} samples");
                } else if e < 5.0 {
                    pooled_e += e;
                    pooled_c += c;
                } else {
                    chi2 += (c as f64 - e).powi(2) / e;
                    bins += 1;
                }
            }
            if pooled_e > 0.0 {
                chi2 += (pooled_c as f64 - pooled_e).powi(2) / pooled_e;
                bins += 1;
            }
            let dof = (bins - 1) as f64;
            let limit = ChiSquared::new(dof).unwrap().inverse_cdf(1.0 - 1e-6);
            assert!(chi2 < limit, "chi2 = {chi2} over {dof} dof (limit {limit})");
        }
    }

    #[test]
    fn pdf_is_positive_wherever_radiance_is() {
        // Directions into the black block have zero radiance and zero density; everywhere else
        // radiance > 0 must come with pdf > 0. 200k uniform directions hit the block's interior
        // and its lit border many times over.
        let map = EnvMap::new(&test_image(), rotation(), 1.0).unwrap();
        let mut r = rng(3);
        let (mut dark, mut lit) = (0, 0);
        for _ in 0..200_000 {
            let d = uniform_sphere(u2(&mut r));
            let (e, p) = map.eval_pdf(d);
            if e.max_element() > 0.0 {
                lit += 1;
                assert!(p > 0.0, "eval {e} > 0 with pdf 0 at {d}");
            } else {
                dark += 1;
            }
        }
        assert!(dark > 1000 && lit > 1000, "dark {dark}, lit {lit}");
    }

    #[test]
    fn seam_and_poles_follow_mitsuba() {
        let img = test_image();
        let map = EnvMap::new(&img, Mat4::IDENTITY, 2.0).unwrap();
        let (w, h) = (img.width(), img.height());
        let texel = |x: usize, y: usize| Vec3::from(img.get(x, y)) * 2.0;
        let dir = |u: f32, t: f32| {
            let (phi, theta) = (TAU * u, PI * t);
            Vec3::new(
                phi.sin() * theta.sin(),
                theta.cos(),
                -phi.cos() * theta.sin(),
            )
        };
        // Texel centres: column x at u = (x + ½)/W, row y at t = y/(H − 1).
        for (x, y) in [(3, 1), (0, 2), (w - 1, 5), (9, 1)] {
            let e = map.eval(dir((x as f32 + 0.5) / w as f32, y as f32 / (h - 1) as f32));
            assert!((e - texel(x, y)).abs().max_element() < 1e-4 * texel(x, y).max_element());
        }
        // u = 0 (local −z) is halfway between the last and the first column.
        let e = map.eval(Vec3::new(0.0, 0.0, -1.0));
        let mid = (texel(w - 1, 3) + texel(0, 3)) * 0.5;
        assert!(
            (e - mid).abs().max_element() < 1e-4 * mid.max_element(),
            "{e} vs {mid}"
        );
        // Continuous across the seam.
        let (a, b) = (
            map.eval(Vec3::new(1e-4, 0.3, -1.0).normalize()),
            map.eval(Vec3::new(-1e-4, 0.3, -1.0).normalize()),
        );
        assert!((a - b).abs().max_element() < 1e-2 * a.max_element());
        // Poles: u = ½ with these signs of zero (atan2(+0, −0) = π; Mitsuba's u at a pole
        // follows them), row 0 at +y and row H − 1 at −y (Mitsuba: row 0 again, see the module
        // documentation).
        for (d, y) in [(Vec3::Y, 0), (Vec3::new(0.0, -1.0, 0.0), h - 1)] {
            let want = (texel(w / 2 - 1, y) + texel(w / 2, y)) * 0.5;
            let e = map.eval(d);
            assert!(
                (e - want).abs().max_element() < 1e-4 * want.max_element(),
                "{e}"
            );
        }
    }

    #[test]
    fn scaled_to_world_reads_unnormalised_direction() {
        // Mitsuba's quirk: with to_world = scale(0.5), eval(d) is the identity map's eval(2d).
        let img = test_image();
        let plain = EnvMap::new(&img, Mat4::IDENTITY, 1.0).unwrap();
        let half = EnvMap::new(&img, Mat4::from_scale(Vec3::splat(0.5)), 1.0).unwrap();
        assert!(!half.rigid);
        let d = Vec3::new(0.3, 0.4, -0.5).normalize();
        assert_eq!(half.eval(d), plain.eval(2.0 * d));
    }

    #[test]
    fn shareable_between_threads() {
        fn check<T: Send + Sync + Clone + fmt::Debug>() {}
        check::<EnvMap>();
    }

    #[test]
    fn black_map_samples_nothing() {
        let img = Image::new(4, 3);
        let map = EnvMap::new(&img, Mat4::IDENTITY, 1.0).unwrap();
        assert_eq!(map.sample(Vec2::new(0.3, 0.6)), None);
        assert_eq!(map.pdf(Vec3::Y), 0.0);
        assert_eq!(map.eval(Vec3::X), Vec3::ZERO);
    }

    #[test]
    fn bad_input_is_an_error() {
        let id = Mat4::IDENTITY;
        assert!(EnvMap::new(&Image::new(0, 0), id, 1.0).is_err());
        assert!(EnvMap::new(&Image::new(2, 2), id, 1.0).is_err());
        let mut px = vec![[1.0f32; 3]; 6];
        px[4] = [1.0, -0.5, 1.0];
        let neg = Image::from_pixels(2, 3, px.clone()).unwrap();
        let msg = EnvMap::new(&neg, id, 1.0).unwrap_err().to_string();
        assert!(msg.contains("(0, 2)"), "{msg}");
        px[4] = [f32::NAN, 1.0, 1.0];
        assert!(EnvMap::new(&Image::from_pixels(2, 3, px).unwrap(), id, 1.0).is_err());
        let ok = Image::new(2, 3);
        assert!(EnvMap::new(&ok, id, -1.0).is_err());
        assert!(EnvMap::new(&ok, id, f32::NAN).is_err());
        assert!(EnvMap::new(&ok, Mat4::from_scale(Vec3::new(1.0, 0.0, 1.0)), 1.0).is_err());
        assert!(EnvMap::new(&ok, Mat4::from_scale(Vec3::splat(f32::INFINITY)), 1.0).is_err());
        assert!(EnvMap::new(&ok, id, 1.0).is_ok());
    }
}
