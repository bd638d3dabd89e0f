//! Converged references: the plain mean of many samples per pixel, with per-pixel running
//! sufficient statistics (count, mean and M2 of R, G, B and luminance) so that the reference's
//! own standard error is known, and a state that can be saved, resumed and merged.
//!
//! # Samples
//!
//! Sample `i` of pixel `p` is the film's:
//! [`SampleStream::new`](super::sampler::SampleStream::new)`(seed, p, i)` through
//! [`radiance`], NaN, infinite and negative samples counted and left out. A reference holds a
//! set of disjoint ranges of sample indices; adding a range continues every pixel's
//! accumulator sample by sample in index order, so tracing `[0, N)` then `[N, 2N)` gives the
//! same bits as tracing `[0, 2N)` at once, on any number of threads. References traced apart
//! (other machines, other ranges) combine with [`Reference::merge`] (Chan et al.'s pairwise
//! update), equal to a single run up to rounding.
//!
//! The default seed, [`REFERENCE_SEED`], differs from `fireflies render`'s default 0, so that a
//! reference never reuses the random numbers of the renders it judges.
//!
//! # State file
//!
//! [`Reference::to_bytes`]: the magic line `fireflies-reference\n`, a little-endian `u32`
//! format version, a `u64` byte length and that many bytes of JSON header (scene key, size,
//! seed, sample ranges, invalid samples), then per pixel in row-major order a `u64` count and
//! eight `f64` (means of R, G, B, luminance, then their M2), all little-endian.

use super::integrator::{pushable, radiance};
use super::sampler::PixelStreams;
use super::world::World;
use crate::error::{Error, Result};
use crate::estimators::luminance;
use crate::image::Image;
use crate::image::metrics::RELMSE_EPSILON;
use crate::limits::MemoryLimit;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Default seed of a reference's streams: the ASCII bytes of `fireflyR`, far from the small
/// seeds renders use.
pub const REFERENCE_SEED: u64 = u64::from_be_bytes(*b"fireflyR");

/// First bytes of a state file.
const MAGIC: &[u8] = b"fireflies-reference\n";

/// Format version of the state file.
const VERSION: u32 = 1;

/// Bytes of one pixel's record in the state file.
const RECORD: usize = 8 + 8 * 8;

/// Channels a pixel keeps statistics of: R, G, B and Rec. 709 luminance (so that a luminance
/// standard error needs no covariances).
const CHANNELS: usize = 4;

/// What a reference was traced from: resuming or merging with another scene is an error.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneKey {
    /// The scene file as given when the reference was started.
    pub path: String,
    /// [`scene_hash`] of the scene file's text.
    pub hash: String,
    /// Whether the film's reconstruction filter was replaced by a box (`--rfilter box`).
    pub box_filter: bool,
}

/// A hash of a scene's text (FNV-1a, 64 bits) naming the scene in a reference's state. It
/// tells scenes apart, not files they load (meshes, textures), and is no defence against
/// deliberate collisions.
pub fn scene_hash(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in text.as_bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("fnv1a64:{h:016x}")
}

/// Count, means and M2 (sum of squared deviations from the mean) of one pixel's R, G, B and
/// luminance samples. Unlike [`crate::estimators::Welford`] it shares one count among four
/// channels and exposes its state, which the state file stores.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PixelStats {
    count: u64,
    mean: [f64; CHANNELS],
    m2: [f64; CHANNELS],
}

impl PixelStats {
    /// Adds one RGB sample (Welford's update, per channel).
    #[inline]
    pub fn push(&mut self, rgb: [f64; 3]) {
        self.count += 1;
        let n = self.count as f64;
        let v = [rgb[0], rgb[1], rgb[2], luminance(rgb)];
        for ((x, mean), m2) in v.into_iter().zip(&mut self.mean).zip(&mut self.m2) {
            let d = x - *mean;
            *mean += d / n;
            *m2 += d * (x - *mean);
        }
    }

    /// Combines two pixels' statistics as if all samples had gone through one (Chan, Golub
    /// and LeVeque 1979: `M2 = M2a + M2b + d² na nb / n` with `d` the difference of means).
    pub fn merge(&mut self, other: &PixelStats) {
        if other.count == 0 {
            return;
        }
        if self.count == 0 {
            *self = *other;
            return;
        }
        let (na, nb) = (self.count as f64, other.count as f64);
        let n = na + nb;
        for c in 0..CHANNELS {
            let d = other.mean[c] - self.mean[c];
            self.mean[c] += d * nb / n;
            self.m2[c] += other.m2[c] + d * d * na * nb / n;
        }
        self.count += other.count;
    }

    /// Valid samples seen.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Mean of R, G, B (0 before any sample).
    pub fn mean_rgb(&self) -> [f64; 3] {
        [self.mean[0], self.mean[1], self.mean[2]]
    }

    /// Mean luminance.
    pub fn mean_luminance(&self) -> f64 {
        self.mean[3]
    }

    /// M2 of R, G, B and luminance.
    pub fn m2(&self) -> [f64; CHANNELS] {
        self.m2
    }

    /// Squared standard error of the mean of channel `c` (0..3 for R, G, B, 3 for luminance):
    /// the sample variance `M2 / (n − 1)` over `n`; `None` with fewer than two samples.
    pub fn squared_error(&self, c: usize) -> Option<f64> {
        (self.count >= 2).then(|| {
            let n = self.count as f64;
            self.m2[c] / (n - 1.0) / n
        })
    }
}

/// How accurate a reference is, from its per-pixel standard errors `se` (see
/// [`PixelStats::squared_error`]). Pixels with fewer than two valid samples have no error
/// estimate; they are left out and counted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Accuracy {
    /// Sample indices traced per pixel.
    pub spp: u64,
    /// RMS over pixels of the luminance's relative standard error
    /// `se_L / sqrt(mean_L² + 0.01)` (relMSE's ε keeps black pixels finite).
    pub pixel_relative_se_rms: Option<f64>,
    /// Relative standard error of the image's mean luminance: `sqrt(Σ se_L²) / P` over the
    /// mean luminance (pixels are independent); `None` for a black image.
    pub image_mean_relative_se: Option<f64>,
    /// `sqrt(mean over pixels and channels of se²)`: a test image's expected RMSE against this
    /// reference is `sqrt(RMSE_true² + expected_rmse²)`.
    pub expected_rmse: Option<f64>,
    /// Mean over pixels and channels of `se² / (mean² + 0.01)`: about what the reference's own
    /// noise adds to a test image's relMSE against it.
    pub expected_relmse: Option<f64>,
    /// Pixels with fewer than two valid samples.
    pub pixels_without_error: u64,
}

/// The header of a state file.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Header {
    scene: SceneKey,
    width: u32,
    height: u32,
    seed: u64,
    ranges: Vec<[u64; 2]>,
    invalid_samples: u64,
}

/// A reference in progress: per-pixel statistics of the samples in a set of index ranges.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    scene: SceneKey,
    width: u32,
    height: u32,
    seed: u64,
    /// Disjoint, sorted, coalesced half-open ranges of sample indices.
    ranges: Vec<[u64; 2]>,
    invalid: u64,
    pixels: Vec<PixelStats>,
}

/// The file beside a reference's EXR that holds `suffix` (`ref.exr` -> `ref.exr.state`,
/// `ref.exr.json`).
pub fn sidecar(exr: &Path, suffix: &str) -> PathBuf {
    let mut name = exr.file_name().unwrap_or_default().to_os_string();
    name.push(suffix);
    exr.with_file_name(name)
}

impl Reference {
    /// Writes the state (first: it is what a resume reads), the image, and `exr.json` with
    /// what the reference is and how accurate it is, plus the caller's `extra` fields.
    pub fn save(
        &self,
        exr: &Path,
        extra: serde_json::Map<String, serde_json::Value>,
    ) -> Result<()> {
        crate::atomic::write_atomic(&sidecar(exr, ".state"), &self.to_bytes())?;
        self.image().write_exr(exr)?;
        let scene = self.scene();
        let mut report = serde_json::json!({
            "scene": scene.path,
            "scene_hash": scene.hash,
            "rfilter_box_override": scene.box_filter,
            "width": self.width(),
            "height": self.height(),
            "seed": self.seed(),
            "sample_ranges": self.ranges(),
            "spp": self.spp(),
            "invalid_samples": self.invalid_samples(),
            "accuracy": self.accuracy(),
        });
        if let Some(fields) = report.as_object_mut() {
            fields.extend(extra);
        }
        let text = serde_json::to_string_pretty(&report).unwrap_or_default();
        crate::atomic::write_atomic(&sidecar(exr, ".json"), text.as_bytes())
    }

    /// An empty reference of a `width × height` image.
    ///
    /// # Errors
    ///
    /// A side is 0, or the per-pixel statistics would not fit in `memory`.
    pub fn new(
        scene: SceneKey,
        width: u32,
        height: u32,
        seed: u64,
        memory: MemoryLimit,
    ) -> Result<Self> {
        let pixels = pixel_count(width, height)?;
        let needed = pixels as u128 * (size_of::<PixelStats>() + size_of::<[f32; 3]>()) as u128;
        memory.check(
            format!("reference of {width}x{height} pixels ({RECORD} bytes each)"),
            needed,
        )?;
        Ok(Reference {
            scene,
            width,
            height,
            seed,
            ranges: Vec::new(),
            invalid: 0,
            pixels: vec![PixelStats::default(); pixels],
        })
    }

    /// The scene it was traced from.
    pub fn scene(&self) -> &SceneKey {
        &self.scene
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Seed of its streams.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The sample-index ranges traced, sorted and disjoint, `[start, end)` each.
    pub fn ranges(&self) -> &[[u64; 2]] {
        &self.ranges
    }

    /// Sample indices traced per pixel (valid or not).
    pub fn spp(&self) -> u64 {
        self.ranges.iter().map(|[a, b]| b - a).sum()
    }

    /// The first index after every range traced (0 when empty): where a resumed run starts.
    pub fn next_start(&self) -> u64 {
        self.ranges.last().map_or(0, |r| r[1])
    }

    /// Samples left out for being NaN, infinite or negative.
    pub fn invalid_samples(&self) -> u64 {
        self.invalid
    }

    /// Per-pixel statistics, row-major.
    pub fn pixels(&self) -> &[PixelStats] {
        &self.pixels
    }

    /// Checks that `samples` is non-empty and shares no index with the ranges traced.
    ///
    /// # Errors
    ///
    /// The range is empty, or overlaps a traced one (both are named).
    pub fn check_range(&self, samples: &Range<u64>) -> Result<()> {
        if samples.start >= samples.end {
            return Err(Error::param(
                "samples",
                format!("[{}, {})", samples.start, samples.end),
                "an empty range of sample indices",
            ));
        }
        if let Some([a, b]) = self
            .ranges
            .iter()
            .find(|[a, b]| samples.start < *b && *a < samples.end)
        {
            return Err(Error::param(
                "seed-start",
                samples.start,
                format!(
                    "samples [{}, {}) overlap the reference's samples [{a}, {b}) (seed {}); \
                     a reference's samples must be independent",
                    samples.start, samples.end, self.seed
                ),
            ));
        }
        Ok(())
    }

    /// Traces samples `samples` of every pixel of `world` into the statistics (rows in
    /// parallel on the current rayon pool; the result does not depend on it).
    ///
    /// # Errors
    ///
    /// The range fails [`Reference::check_range`], or the camera's image is not this
    /// reference's size.
    pub fn trace(&mut self, world: &World, samples: Range<u64>) -> Result<()> {
        self.check_range(&samples)?;
        let (w, h) = (world.camera.width(), world.camera.height());
        if (w, h) != (self.width, self.height) {
            return Err(Error::param(
                "scene",
                format!("{w}x{h}"),
                format!("the reference is {}x{}", self.width, self.height),
            ));
        }
        let (seed, width) = (self.seed, self.width as usize);
        let invalid: u64 = self
            .pixels
            .par_chunks_mut(width)
            .enumerate()
            .map(|(y, row)| {
                let mut invalid = 0u64;
                for (x, stats) in row.iter_mut().enumerate() {
                    let streams = PixelStreams::new(seed, (y * width + x) as u64);
                    for s in samples.clone() {
                        let mut rng = streams.sample(s);
                        match pushable(radiance(world, x as u32, y as u32, &mut rng)) {
                            Some(v) => stats.push(v),
                            None => invalid += 1,
                        }
                    }
                }
                invalid
            })
            .sum();
        self.invalid += invalid;
        self.add_range([samples.start, samples.end]);
        Ok(())
    }

    /// Adds `other`'s samples to this reference (Chan et al.'s merge per pixel).
    ///
    /// # Errors
    ///
    /// The two differ in scene, size or seed, or share sample indices.
    pub fn merge(&mut self, other: &Reference) -> Result<()> {
        if self.scene.hash != other.scene.hash || self.scene.box_filter != other.scene.box_filter {
            return Err(Error::param(
                "reference",
                format!("{} ({})", other.scene.path, other.scene.hash),
                format!(
                    "is of another scene than {} ({})",
                    self.scene.path, self.scene.hash
                ),
            ));
        }
        if (self.width, self.height, self.seed) != (other.width, other.height, other.seed) {
            return Err(Error::param(
                "reference",
                format!("{}x{} seed {}", other.width, other.height, other.seed),
                format!(
                    "cannot merge into {}x{} seed {}",
                    self.width, self.height, self.seed
                ),
            ));
        }
        for &[a, b] in &other.ranges {
            self.check_range(&(a..b))?;
        }
        for (p, q) in self.pixels.iter_mut().zip(&other.pixels) {
            p.merge(q);
        }
        self.invalid += other.invalid;
        for &r in &other.ranges {
            self.add_range(r);
        }
        Ok(())
    }

    fn add_range(&mut self, r: [u64; 2]) {
        self.ranges.push(r);
        self.ranges.sort_unstable();
        let mut merged: Vec<[u64; 2]> = Vec::with_capacity(self.ranges.len());
        for r in self.ranges.drain(..) {
            match merged.last_mut() {
                Some(last) if last[1] == r[0] => last[1] = r[1],
                _ => merged.push(r),
            }
        }
        self.ranges = merged;
    }

    /// The reference image: every pixel's mean (black where no sample was valid).
    pub fn image(&self) -> Image {
        let px = self
            .pixels
            .iter()
            .map(|p| p.mean_rgb().map(|v| v as f32))
            .collect();
        Image::from_pixels(self.width as usize, self.height as usize, px)
            .expect("one statistic per pixel")
    }

    /// How accurate the reference is (see [`Accuracy`]).
    pub fn accuracy(&self) -> Accuracy {
        let (mut rel2, mut se2_lum, mut mean_lum) = (0.0f64, 0.0f64, 0.0f64);
        let (mut se2_rgb, mut rel2_rgb) = (0.0f64, 0.0f64);
        let mut with_error = 0u64;
        for p in &self.pixels {
            let Some(lum2) = p.squared_error(3) else {
                continue;
            };
            with_error += 1;
            let m = p.mean_luminance();
            rel2 += lum2 / (m * m + RELMSE_EPSILON);
            se2_lum += lum2;
            mean_lum += m;
            for c in 0..3 {
                let e2 = p.squared_error(c).unwrap_or(0.0);
                let m = p.mean[c];
                se2_rgb += e2;
                rel2_rgb += e2 / (m * m + RELMSE_EPSILON);
            }
        }
        let pixels_without_error = self.pixels.len() as u64 - with_error;
        if with_error == 0 {
            return Accuracy {
                spp: self.spp(),
                pixel_relative_se_rms: None,
                image_mean_relative_se: None,
                expected_rmse: None,
                expected_relmse: None,
                pixels_without_error,
            };
        }
        let n = with_error as f64;
        Accuracy {
            spp: self.spp(),
            pixel_relative_se_rms: Some((rel2 / n).sqrt()),
            image_mean_relative_se: (mean_lum != 0.0).then(|| se2_lum.sqrt() / mean_lum.abs()),
            expected_rmse: Some((se2_rgb / (3.0 * n)).sqrt()),
            expected_relmse: Some(rel2_rgb / (3.0 * n)),
            pixels_without_error,
        }
    }

    /// The state file's bytes (see the module docs).
    pub fn to_bytes(&self) -> Vec<u8> {
        let header = Header {
            scene: self.scene.clone(),
            width: self.width,
            height: self.height,
            seed: self.seed,
            ranges: self.ranges.clone(),
            invalid_samples: self.invalid,
        };
        let json = serde_json::to_vec(&header).expect("a header serialises");
        let mut out =
            Vec::with_capacity(MAGIC.len() + 12 + json.len() + RECORD * self.pixels.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(json.len() as u64).to_le_bytes());
        out.extend_from_slice(&json);
        for p in &self.pixels {
            out.extend_from_slice(&p.count.to_le_bytes());
            for v in p.mean.iter().chain(&p.m2) {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    /// Reads a state file's bytes; `source` names the file in errors.
    ///
    /// # Errors
    ///
    /// Not a state file, another format version, a malformed header, or a length that does
    /// not match the header's image size.
    pub fn from_bytes(bytes: &[u8], source: &str) -> Result<Self> {
        let fail = |message: String| Error::Io {
            path: source.to_string(),
            message,
        };
        let rest = bytes
            .strip_prefix(MAGIC)
            .ok_or_else(|| fail("not a fireflies reference state file".into()))?;
        let (version, rest) = take::<4>(rest).ok_or_else(|| fail("truncated header".into()))?;
        let version = u32::from_le_bytes(version);
        if version != VERSION {
            return Err(fail(format!(
                "state format version {version}; this program reads version {VERSION}"
            )));
        }
        let (len, rest) = take::<8>(rest).ok_or_else(|| fail("truncated header".into()))?;
        let len = usize::try_from(u64::from_le_bytes(len))
            .ok()
            .filter(|&l| l <= rest.len())
            .ok_or_else(|| fail("truncated header".into()))?;
        let header: Header = serde_json::from_slice(&rest[..len])
            .map_err(|e| fail(format!("malformed header: {e}")))?;
        let body = &rest[len..];
        let pixels = pixel_count(header.width, header.height)?;
        if pixels.checked_mul(RECORD) != Some(body.len()) {
            return Err(fail(format!(
                "{} bytes of pixel statistics; a {}x{} reference has {}",
                body.len(),
                header.width,
                header.height,
                pixels.saturating_mul(RECORD)
            )));
        }
        let mut stats = Vec::with_capacity(pixels);
        for rec in body.chunks_exact(RECORD) {
            let word = |i: usize| -> [u8; 8] {
                let mut w = [0u8; 8];
                w.copy_from_slice(&rec[8 * i..8 * i + 8]);
                w
            };
            let mut p = PixelStats {
                count: u64::from_le_bytes(word(0)),
                ..PixelStats::default()
            };
            for c in 0..CHANNELS {
                p.mean[c] = f64::from_le_bytes(word(1 + c));
                p.m2[c] = f64::from_le_bytes(word(1 + CHANNELS + c));
            }
            stats.push(p);
        }
        let mut reference = Reference {
            scene: header.scene,
            width: header.width,
            height: header.height,
            seed: header.seed,
            ranges: Vec::new(),
            invalid: header.invalid_samples,
            pixels: stats,
        };
        for &[a, b] in &header.ranges {
            reference
                .check_range(&(a..b))
                .map_err(|e| fail(format!("inconsistent sample ranges: {e}")))?;
            reference.add_range([a, b]);
        }
        Ok(reference)
    }
}

/// The first `N` bytes and the rest, if there are `N`.
fn take<const N: usize>(bytes: &[u8]) -> Option<([u8; N], &[u8])> {
    let (head, rest) = bytes.split_first_chunk::<N>()?;
    Some((*head, rest))
}

fn pixel_count(width: u32, height: u32) -> Result<usize> {
    if width == 0 || height == 0 {
        return Err(Error::param(
            "reference size",
            format!("{width}x{height}"),
            "both sides must be at least 1",
        ));
    }
    usize::try_from(u64::from(width) * u64::from(height)).map_err(|_| {
        Error::param(
            "reference size",
            format!("{width}x{height}"),
            "more pixels than this machine can address",
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welford_and_chan_match_the_two_pass_formulas() {
        let xs = [
            [1.0, 2.0, 0.5],
            [3.0, 0.0, 0.5],
            [2.0, 4.0, 0.5],
            [10.0, 1.0, 0.5],
        ];
        let mut all = PixelStats::default();
        for x in xs {
            all.push(x);
        }
        // R: mean 4, deviations -3, -1, -2, 6: M2 = 9 + 1 + 4 + 36 = 50.
        assert_eq!(all.count(), 4);
        assert_eq!(all.mean_rgb(), [4.0, 1.75, 0.5]);
        assert_eq!(all.m2()[0], 50.0);
        assert_eq!(all.m2()[2], 0.0);
        // se² = 50 / 3 / 4.
        assert_eq!(all.squared_error(0), Some(50.0 / 3.0 / 4.0));
        let (mut a, mut b) = (PixelStats::default(), PixelStats::default());
        a.push(xs[0]);
        for x in &xs[1..] {
            b.push(*x);
        }
        a.merge(&b);
        assert_eq!(a.count(), 4);
        for c in 0..CHANNELS {
            assert!((a.mean[c] - all.mean[c]).abs() <= 1e-15 * all.mean[c].abs());
            assert!((a.m2[c] - all.m2[c]).abs() <= 1e-13 * all.m2[c].abs().max(1.0));
        }
        let mut empty = PixelStats::default();
        empty.merge(&all);
        assert_eq!(empty, all);
        assert_eq!(PixelStats::default().squared_error(0), None);
    }

    #[test]
    fn scene_hash_is_fnv1a() {
        // FNV-1a 64 of "" and "a" (the published test vectors).
        assert_eq!(scene_hash(""), "fnv1a64:cbf29ce484222325");
        assert_eq!(scene_hash("a"), "fnv1a64:af63dc4c8601ec8c");
    }

    fn key() -> SceneKey {
        SceneKey {
            path: "s.xml".into(),
            hash: scene_hash("s"),
            box_filter: false,
        }
    }

    #[test]
    fn ranges_coalesce_and_overlaps_are_refused() {
        let mut r = Reference::new(key(), 2, 1, 7, MemoryLimit(1 << 30)).unwrap();
        r.add_range([4, 8]);
        r.add_range([0, 4]);
        r.add_range([10, 12]);
        assert_eq!(r.ranges(), &[[0, 8], [10, 12]]);
        assert_eq!((r.spp(), r.next_start()), (10, 12));
        assert!(r.check_range(&(8..10)).is_ok());
        let e = r.check_range(&(6..9)).unwrap_err().to_string();
        assert!(e.contains("[6, 9)") && e.contains("[0, 8)"), "{e}");
        assert!(r.check_range(&(3..3)).is_err());
    }

    #[test]
    fn state_round_trips_and_bad_files_are_named() {
        let mut r = Reference::new(key(), 3, 2, 7, MemoryLimit(1 << 30)).unwrap();
        r.add_range([0, 2]);
        r.invalid = 3;
        for (i, p) in r.pixels.iter_mut().enumerate() {
            p.push([i as f64, 0.5, 1e-300]);
            p.push([2.0 * i as f64, 0.25, 3.0]);
        }
        let bytes = r.to_bytes();
        assert_eq!(Reference::from_bytes(&bytes, "x.state").unwrap(), r);
        let e = Reference::from_bytes(&bytes[..bytes.len() - 1], "x.state")
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.state") && e.contains("3x2"), "{e}");
        let e = Reference::from_bytes(b"hello", "y.state")
            .unwrap_err()
            .to_string();
        assert!(e.contains("y.state") && e.contains("not a"), "{e}");
        assert!(Reference::new(key(), 0, 2, 7, MemoryLimit(1 << 30)).is_err());
        let e = Reference::new(key(), 1000, 1000, 7, MemoryLimit(1000))
            .unwrap_err()
            .to_string();
        assert!(e.contains("1000x1000"), "{e}");
    }

    #[test]
    fn accuracy_of_hand_made_pixels() {
        let mut r = Reference::new(key(), 2, 1, 7, MemoryLimit(1 << 30)).unwrap();
        r.add_range([0, 4]);
        // Pixel 0: grey 1, 3, 1, 3: mean 2, M2 4, se² = 4/3/4 = 1/3.
        // Pixel 1: grey 0 four times: mean 0, se² 0.
        for v in [1.0, 3.0, 1.0, 3.0] {
            r.pixels[0].push([v; 3]);
            r.pixels[1].push([0.0; 3]);
        }
        let a = r.accuracy();
        assert_eq!(a.spp, 4);
        assert_eq!(a.pixels_without_error, 0);
        let rel: f64 = (1.0 / 3.0) / (4.0 + 0.01) / 2.0;
        assert!((a.pixel_relative_se_rms.unwrap() - rel.sqrt()).abs() < 1e-15);
        assert!((a.expected_relmse.unwrap() - rel).abs() < 1e-15);
        assert!((a.expected_rmse.unwrap() - (1.0f64 / 3.0 / 2.0).sqrt()).abs() < 1e-15);
        // Image mean 1, sqrt(1/3) / 2 pixels.
        let image = (1.0f64 / 3.0).sqrt() / 2.0;
        assert!((a.image_mean_relative_se.unwrap() - image).abs() < 1e-15);
    }
}
