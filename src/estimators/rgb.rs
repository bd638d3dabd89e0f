//! Estimators of an RGB pixel, for the path tracer's film.
//!
//! The film feeds each pixel's RGB samples (`[f64; 3]`, finite and non-negative, validated by
//! the caller) to the estimators an [`EstimatorSpec`] names, built by [`build_rgb`]. As the
//! project's issue puts it: "MoN-family estimators run per RGB channel; Zirr's cascade and
//! Pajot's methods classify by luminance (Rec. 709 weights 0.2126, 0.7152, 0.0722) and apply
//! their weight or decision to the RGB sample, as in their papers."
//!
//! * **Per channel** (`clamp`, `mon`, `gini`, `gmonb`, `gmon`, `jung`): three scalar
//!   estimators, one per channel; the estimate of channel `c` is the scalar estimator's estimate
//!   of the channel-`c` stream. A block of samples is split into channels through stack
//!   buffers ([`CHUNK`] samples a channel, not part of the pixel's state), so each channel sees
//!   one `push_slice` per chunk and no dynamic dispatch per sample; an
//!   [`RgbBank`](super::RgbBank) splits once for all its estimators and lets the MoN family
//!   share partitions per channel. `jung` in image mode takes one `σ_image` per channel
//!   ([`RgbEstimator::set_image_sigma`]).
//! * **Mean** (`mean`): per channel as well, with the same result bit for bit as three scalar
//!   means, but the three channels are summed together in one SIMD step per sample and the
//!   block is not split (`super::mean`).
//! * **Zirr** (`zirr`, `zirr-ref`): the cascade runs on the luminance `L` of each sample, exactly
//!   as the scalar method on the luminance stream (same `N`, buffers, counts, weights). Beside
//!   each luminance buffer the pixel keeps an RGB buffer, into which each sample's RGB goes with
//!   the fractions its luminance went with ([`Splat`]): `a` and `1 − a` between two buffers,
//!   1 for a whole sample, and `c_{J−1}/L` at `zirr-ref`'s clamped top buffer ([Z] §4.2 splats
//!   colour with luminance-derived weights). The estimate is `Σ_j w_j·B_j(RGB)` with the `w_j`
//!   the scalar method composes from the luminance buffers (in ascending `j`, like the scalar
//!   sum), so `luminance(estimate)` equals the scalar estimate on the luminances up to
//!   rounding. [`RgbEstimator::block_estimate`] averages the rejection counts over the 3×3
//!   block exactly as [`Zirr::block_estimate`] does.
//! * **Pajot** (`pajot-rot`, `pajot-adr`, `pajot-hybrid`): the scalar estimator runs on the
//!   luminances; a sample is accepted iff its luminance is (black always; otherwise
//!   `ln L ≤ m`, the final bound, read "as if learning ended now" during learning, like the
//!   scalar estimate). The estimate is the compensated mean of the accepted RGB samples
//!   (divisor: the accepted count; `[0, 0, 0]` when none is). Besides the scalar state the
//!   pixel keeps the accepted RGB sums and count and the not-yet-accepted samples as a list of
//!   `(L, rgb)` sorted by `L`, released into the sums (in ascending `L`, as the scalar ledger
//!   does) whenever the bound grows. During learning that list holds every non-black sample
//!   (the scalar method stores them too); afterwards only the delayed ones.
//!
//! # Decisions
//!
//! * **Luminance** is `0.2126·r + 0.7152·g + 0.0722·b`, evaluated left to right, except that a
//!   grey sample (`r == g == b`) has luminance `r` exactly. The weights sum to 1, but the
//!   rounded products do not always add back to `r` (they miss it for about 3 samples in 10);
//!   with the exception a grey RGB stream is classified, split and weighted bit for bit as the
//!   scalar stream, so grey pixels give the scalar estimate in every channel. The change is at
//!   most an ulp, only at grey samples.
//! * **Black** means `L == 0.0`, the scalar methods' test on the luminance. With positive
//!   weights that happens only for `rgb = 0` — or for RGB made of a few subnormals (`0.2126 ×
//!   5e-324` rounds to 0). Such a sample is treated as black, as its luminance says: Zirr puts
//!   its RGB wholly into buffer 0 (where every sample below `u` goes; it counts in `N`), Pajot
//!   accepts it and adds its RGB (at most a few subnormals) to the accepted sums.
//! * **Sample order**: each per-channel or luminance estimator sees the samples in arrival
//!   order, so any split of the stream into `push_slice` calls gives the same state.
//! * **Display**: the scalar estimator's form followed by `[RGB]` (`MoN(M=21)[RGB]`); `spec()`
//!   is the scalar spec (for `jung` after [`RgbEstimator::set_image_sigma`], with the red
//!   channel's `σ_image`).
//! * **State** ([`RgbEstimator::state_bytes`]): the struct plus every heap allocation held —
//!   per channel, three scalar states; Zirr, the scalar luminance state plus 48 bytes per RGB
//!   buffer (three compensated sums); Pajot, the scalar luminance state plus 32 bytes per
//!   listed `(L, rgb)`.
//!
//! [Z]: super::zirr

use super::numeric::{ScaledSum, ScaledSums};
use super::zirr::Splat;
use super::{BoundStrategy, Estimator, EstimatorSpec, Pajot, Partition, Zirr, empty};
use crate::error::{Error, Result};
use std::fmt;

/// Rec. 709 luminance weights of red, green and blue.
pub const REC709: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Rec. 709 luminance `0.2126·r + 0.7152·g + 0.0722·b` (summed left to right); exactly `r` for
/// a grey sample `r == g == b` (see the module docs).
#[inline]
pub fn luminance(rgb: [f64; 3]) -> f64 {
    let [r, g, b] = rgb;
    if r == g && g == b {
        return r;
    }
    REC709[0] * r + REC709[1] * g + REC709[2] * b
}

/// A per-pixel streaming estimator of the mean of an RGB random variable.
pub trait RgbEstimator: Send + Sync + fmt::Display {
    /// Adds a block of samples in order. The caller guarantees every channel is finite and
    /// non-negative.
    fn push_slice(&mut self, samples: &[[f64; 3]]);

    /// Number of samples pushed so far.
    fn count(&self) -> u64;

    /// The current estimate; an error when no sample has been pushed.
    fn estimate(&self) -> Result<[f64; 3]>;

    /// The estimate of this pixel given its 3×3 neighbourhood (row-major, index 4 = this
    /// pixel, `None` outside the image); only Zirr uses the neighbours ([Z] §5.3.1). The
    /// default ignores them and returns [`RgbEstimator::estimate`].
    ///
    /// [Z]: super::zirr
    fn block_estimate(&self, block: &[Option<&dyn RgbEstimator>; 9]) -> Result<[f64; 3]> {
        let _ = block;
        self.estimate()
    }

    /// Jung's image mode: the film sets the per-channel `σ_image` (finite, `≥ 0`) before
    /// reading estimates. A no-op for every other estimator.
    fn set_image_sigma(&mut self, sigma: [f64; 3]) -> Result<()> {
        let _ = sigma;
        Ok(())
    }

    /// Bytes of per-pixel state held right now (struct plus heap).
    fn state_bytes(&self) -> usize;

    /// The scalar spec this estimator was built from.
    fn spec(&self) -> EstimatorSpec;

    /// The luminance cascade of a Zirr pixel, which its neighbours read in
    /// [`RgbEstimator::block_estimate`]: an optional capability, `None` by default.
    fn luminance_cascade(&self) -> Option<&Zirr> {
        None
    }

    /// Per channel, the round-robin partitions of a per-channel estimator (see
    /// [`Estimator::partitions`]), which an [`RgbBank`](super::RgbBank) hands to later
    /// estimators with as many sets: an optional capability, none by default.
    fn channel_partitions(&self) -> [&[Partition]; 3] {
        [&[], &[], &[]]
    }

    /// [`RgbEstimator::push_slice`] given the block also split into `channels`, and, when
    /// `shared` is given, per-channel partitions that have been fed this estimator's whole
    /// stream, `samples` included (see [`Estimator::push_slice_sharing`]). Same result as
    /// `push_slice(samples)`; the default ignores both.
    fn push_channels(
        &mut self,
        samples: &[[f64; 3]],
        channels: [&[f64]; 3],
        shared: Option<[&Partition; 3]>,
    ) {
        let _ = (channels, shared);
        self.push_slice(samples);
    }

    /// Whether [`RgbEstimator::push_channels`] reads the block split into channels; a bank
    /// none of whose estimators does skips the split. False by default, as the default
    /// `push_channels` ignores the split.
    fn reads_channels(&self) -> bool {
        false
    }
}

/// Most samples split into channels at a time: three 512-byte stack buffers (zeroed on every
/// call, so small: a pixel's block is often a few samples), long enough that a chunk holds a
/// round of the usual M, so partitions can be shared chunk by chunk.
pub(super) const CHUNK: usize = 64;

/// Calls `f(chunk, [red, green, blue])` for consecutive chunks of at most [`CHUNK`] samples,
/// with each chunk split into its three channels.
pub(super) fn for_each_chunk(samples: &[[f64; 3]], mut f: impl FnMut(&[[f64; 3]], [&[f64]; 3])) {
    let mut bufs = [[0.0f64; CHUNK]; 3];
    for chunk in samples.chunks(CHUNK) {
        for (c, buf) in bufs.iter_mut().enumerate() {
            for (slot, px) in buf.iter_mut().zip(chunk) {
                *slot = px[c];
            }
        }
        let [r, g, b] = &bufs;
        let n = chunk.len();
        f(chunk, [&r[..n], &g[..n], &b[..n]]);
    }
}

/// Builds the RGB estimator for a spec (every method), checking every parameter as
/// [`EstimatorSpec::build`] does; the same as [`EstimatorSpec::build_rgb`].
pub fn build_rgb(spec: &EstimatorSpec) -> Result<Box<dyn RgbEstimator>> {
    spec.build_rgb()
}

/// The per-channel RGB estimator: three scalar estimators from `make`.
pub(super) fn per_channel<E: Estimator + 'static>(
    make: impl Fn() -> Result<E>,
) -> Result<Box<dyn RgbEstimator>> {
    Ok(Box::new(PerChannel {
        ch: [make()?, make()?, make()?],
    }))
}

/// Zirr's RGB estimator around the scalar cascade `lum` on the luminance.
pub(super) fn zirr_rgb(lum: Zirr) -> Box<dyn RgbEstimator> {
    Box::new(ZirrRgb::new(lum))
}

/// Pajot's RGB estimator around the scalar method `lum` on the luminance.
pub(super) fn pajot_rgb<B: BoundStrategy>(lum: Pajot<B>, learn: usize) -> Box<dyn RgbEstimator> {
    Box::new(PajotRgb::new(lum, learn))
}

/// The heap part of a scalar estimator's state (its struct is embedded in ours).
fn heap_of<E: Estimator>(e: &E) -> usize {
    e.state_bytes().saturating_sub(size_of::<E>())
}

/// The channel names, for error messages.
const CHANNELS: [&str; 3] = ["red", "green", "blue"];

// ---------------------------------------------------------------------------------------------
// Per channel

/// Three scalar estimators, one per channel.
#[derive(Debug, Clone)]
struct PerChannel<E> {
    ch: [E; 3],
}

impl<E: Estimator> fmt::Display for PerChannel<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}[RGB]", self.ch[0])
    }
}

impl<E: Estimator + 'static> RgbEstimator for PerChannel<E> {
    fn push_slice(&mut self, samples: &[[f64; 3]]) {
        if let [one] = samples {
            for (e, &x) in self.ch.iter_mut().zip(one) {
                e.push(x);
            }
            return;
        }
        for_each_chunk(samples, |chunk, channels| {
            self.push_channels(chunk, channels, None);
        });
    }

    fn channel_partitions(&self) -> [&[Partition]; 3] {
        let [r, g, b] = &self.ch;
        [r.partitions(), g.partitions(), b.partitions()]
    }

    fn reads_channels(&self) -> bool {
        true
    }

    fn push_channels(
        &mut self,
        _samples: &[[f64; 3]],
        channels: [&[f64]; 3],
        shared: Option<[&Partition; 3]>,
    ) {
        for (c, e) in self.ch.iter_mut().enumerate() {
            match shared {
                Some(p) => e.push_slice_sharing(channels[c], p[c]),
                None => e.push_slice(channels[c]),
            }
        }
    }

    fn count(&self) -> u64 {
        self.ch[0].count()
    }

    fn estimate(&self) -> Result<[f64; 3]> {
        if self.count() == 0 {
            return Err(empty(self));
        }
        Ok([
            self.ch[0].estimate()?,
            self.ch[1].estimate()?,
            self.ch[2].estimate()?,
        ])
    }

    /// Sets each channel's `σ_image`, checking all three before changing any (only where the
    /// scalar estimator uses it).
    fn set_image_sigma(&mut self, sigma: [f64; 3]) -> Result<()> {
        if !self.ch[0].uses_image_sigma() {
            return Ok(());
        }
        for (s, name) in sigma.iter().zip(CHANNELS) {
            if !(*s >= 0.0 && s.is_finite()) {
                return Err(Error::param(
                    "sigma_image",
                    s,
                    format!("must be finite and >= 0 (the {name} channel's)"),
                ));
            }
        }
        for (e, s) in self.ch.iter_mut().zip(sigma) {
            e.set_image_sigma(s)?;
        }
        Ok(())
    }

    fn state_bytes(&self) -> usize {
        size_of::<Self>() + self.ch.iter().map(heap_of).sum::<usize>()
    }

    fn spec(&self) -> EstimatorSpec {
        self.ch[0].spec()
    }
}

// ---------------------------------------------------------------------------------------------
// Zirr

/// Zirr's cascade on the luminance, with an RGB buffer beside each luminance buffer.
#[derive(Debug, Clone)]
struct ZirrRgb {
    /// The scalar method on the luminance stream: `N`, luminance buffers, weights.
    lum: Zirr,
    /// Compensated RGB sums `A_j(RGB)`, channel `c` of buffer `j` at index `3j + c`, grown as
    /// the samples reach higher buffers (a buffer the luminance cascade has but no sample
    /// reached yet is absent here, i.e. zero). Each is rescaled on its own before it would
    /// overflow, as the luminance buffers are.
    rgb: ScaledSums,
}

impl ZirrRgb {
    fn new(lum: Zirr) -> Self {
        ZirrRgb {
            lum,
            rgb: ScaledSums::new(0),
        }
    }

    /// Makes sure the RGB buffers `0..len` exist (grown exactly).
    #[inline]
    fn grow(&mut self, len: usize) {
        if self.rgb.len() < 3 * len {
            self.rgb.grow(3 * len);
        }
    }

    /// Adds `rgb` to buffer `j`, each channel scaled by `f(channel value)`.
    #[inline]
    fn add(&mut self, j: usize, px: [f64; 3], f: impl Fn(f64) -> f64) {
        for (c, &x) in px.iter().enumerate() {
            self.rgb.add(3 * j + c, f(x));
        }
    }

    /// `Σ_j w_j·B_j(RGB)`, in ascending `j` as the scalar compose sums (saturated at
    /// `f64::MAX` as the scalar one is: the real sum is at most the channel's mean).
    fn compose(&self, weights: &[f64]) -> [f64; 3] {
        let nf = self.lum.count() as f64;
        let mut e = [0.0f64; 3];
        for (j, w) in weights.iter().enumerate().take(self.rgb.len() / 3) {
            for (c, e) in e.iter_mut().enumerate() {
                *e = (*e + w * self.rgb.mean(3 * j + c, nf)).min(f64::MAX);
            }
        }
        e
    }
}

impl fmt::Display for ZirrRgb {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}[RGB]", self.lum)
    }
}

impl RgbEstimator for ZirrRgb {
    fn push_slice(&mut self, samples: &[[f64; 3]]) {
        for &px in samples {
            let l = luminance(px);
            match self.lum.push_split(l) {
                Splat::Whole { j } => {
                    self.grow(j + 1);
                    self.add(j, px, |x| x);
                }
                Splat::Split { j, a } => {
                    self.grow(j + 2);
                    for (c, &x) in px.iter().enumerate() {
                        let part = a * x;
                        self.rgb.add(3 * j + c, part);
                        self.rgb.add(3 * (j + 1) + c, x - part);
                    }
                }
                Splat::Clamped { j, v } => {
                    // l >= c_{J-1} > 0: each channel keeps the fraction v/l of itself.
                    self.grow(j + 1);
                    self.add(j, px, |x| v * (x / l));
                }
            }
        }
    }

    fn count(&self) -> u64 {
        self.lum.count()
    }

    fn estimate(&self) -> Result<[f64; 3]> {
        if self.count() == 0 {
            return Err(empty(self));
        }
        Ok(self.compose(&self.lum.weights()?))
    }

    /// The 3×3 estimate ([Z] §5.3.1): index 4 is taken to be this pixel whatever the block
    /// holds there; every other present pixel must be a Zirr pixel (one with a
    /// [`RgbEstimator::luminance_cascade`]; an error names its index otherwise) and, as in the
    /// scalar method, have the same parameters.
    ///
    /// [Z]: super::zirr
    fn block_estimate(&self, block: &[Option<&dyn RgbEstimator>; 9]) -> Result<[f64; 3]> {
        let mut lum: [Option<&Zirr>; 9] = [None; 9];
        for (k, (slot, px)) in lum.iter_mut().zip(block).enumerate() {
            if k == 4 {
                *slot = Some(&self.lum);
                continue;
            }
            let Some(px) = px else { continue };
            let Some(z) = px.luminance_cascade() else {
                return Err(Error::param(
                    "block index",
                    k,
                    format!(
                        "pixel {k} is {px} but the centre is {self}; all pixels of a block \
                         must be the same RGB estimator"
                    ),
                ));
            };
            *slot = Some(z);
        }
        Ok(self.compose(&Zirr::block_weights(&lum)?))
    }

    fn state_bytes(&self) -> usize {
        size_of::<Self>() + heap_of(&self.lum) + self.rgb.heap_bytes()
    }

    fn spec(&self) -> EstimatorSpec {
        self.lum.spec()
    }

    fn luminance_cascade(&self) -> Option<&Zirr> {
        Some(&self.lum)
    }
}

// ---------------------------------------------------------------------------------------------
// Pajot

/// Pajot's method on the luminance; accepted RGB samples are averaged.
#[derive(Debug, Clone)]
struct PajotRgb<B> {
    /// The scalar method on the luminance stream (decides acceptance).
    lum: Pajot<B>,
    /// The learning-phase length.
    learn: u64,
    /// The bound the list was last released against (after learning).
    m: f64,
    /// Compensated sums of the accepted RGB samples (rescaled before they would overflow).
    sum: [ScaledSum; 3],
    /// Accepted samples, black ones included.
    accepted: u64,
    /// Samples not accepted yet, `(L, rgb)` ascending in `L`: every non-black sample during
    /// learning, the delayed ones afterwards.
    pending: Vec<(f64, [f64; 3])>,
}

impl<B: BoundStrategy> PajotRgb<B> {
    fn new(lum: Pajot<B>, learn: usize) -> Self {
        PajotRgb {
            lum,
            learn: u64::try_from(learn).unwrap_or(u64::MAX),
            m: f64::NEG_INFINITY,
            sum: [ScaledSum::new(); 3],
            accepted: 0,
            pending: Vec::new(),
        }
    }

    #[inline]
    fn accept(sum: &mut [ScaledSum; 3], accepted: &mut u64, px: [f64; 3]) {
        for c in 0..3 {
            sum[c].add(px[c]);
        }
        *accepted += 1;
    }

    fn delay(&mut self, l: f64, px: [f64; 3]) {
        if self.pending.capacity() == 0 && self.lum.count() <= self.learn {
            self.pending
                .reserve_exact(usize::try_from(self.learn).unwrap_or(usize::MAX).min(1024));
        }
        let at = self.pending.partition_point(|&(x, _)| x <= l);
        self.pending.insert(at, (l, px));
    }

    /// Accepts the listed samples with `ln L ≤ m`, in ascending `L` (as the scalar ledger).
    fn release(&mut self) {
        let m = self.m;
        let k = self.pending.partition_point(|&(l, _)| l.ln() <= m);
        if k == 0 {
            return;
        }
        for &(_, px) in &self.pending[..k] {
            Self::accept(&mut self.sum, &mut self.accepted, px);
        }
        self.pending.drain(..k);
        if self.pending.capacity() > 16 && self.pending.len() * 4 < self.pending.capacity() {
            self.pending.shrink_to(self.pending.len() * 2);
        }
    }

    fn push_one(&mut self, px: [f64; 3]) {
        let l = luminance(px);
        self.lum.push(l);
        let n = self.lum.count();
        if n <= self.learn {
            // Learning: black samples are accepted on arrival, the rest wait for its end.
            if l == 0.0 {
                Self::accept(&mut self.sum, &mut self.accepted, px);
            } else {
                self.delay(l, px);
            }
            if n == self.learn {
                self.m = self.lum.bound();
                self.release();
            }
            return;
        }
        let m = self.lum.bound();
        if m != self.m {
            // m never decreases: the list releases its samples now at or below it.
            self.m = m;
            self.release();
        }
        if l == 0.0 || l.ln() <= m {
            Self::accept(&mut self.sum, &mut self.accepted, px);
        } else {
            self.delay(l, px);
        }
    }
}

impl<B: BoundStrategy> fmt::Display for PajotRgb<B> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}[RGB]", self.lum)
    }
}

impl<B: BoundStrategy> RgbEstimator for PajotRgb<B> {
    fn push_slice(&mut self, samples: &[[f64; 3]]) {
        for &px in samples {
            self.push_one(px);
        }
    }

    fn count(&self) -> u64 {
        self.lum.count()
    }

    fn estimate(&self) -> Result<[f64; 3]> {
        let n = self.count();
        if n == 0 {
            return Err(empty(self));
        }
        let (mut sum, mut accepted) = (self.sum, self.accepted);
        if n < self.learn {
            // As if learning ended now: the scalar bound of a settled copy, applied to the
            // stored samples in ascending L; the state is unchanged.
            let m = self.lum.bound();
            for &(l, px) in &self.pending {
                if !(l.ln() <= m) {
                    break;
                }
                Self::accept(&mut sum, &mut accepted, px);
            }
        }
        if accepted == 0 {
            return Ok([0.0; 3]);
        }
        Ok(sum.map(|s| s.mean(accepted)))
    }

    fn state_bytes(&self) -> usize {
        size_of::<Self>()
            + heap_of(&self.lum)
            + self.pending.capacity() * size_of::<(f64, [f64; 3])>()
    }

    fn spec(&self) -> EstimatorSpec {
        self.lum.spec()
    }
}
