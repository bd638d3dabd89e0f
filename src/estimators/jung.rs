//! Jung et al.'s dynamic median of means, as described by Buisine et al. ([B] §3.3, eq. 3):
//! the number of sets grows with how much noisier the pixel is than the image,
//! `M = 2(q+1)+1` for `2^q <= sigma_pixel / sigma_image`, capped at `M_max`.
//!
//! One partition per odd `M` in `1..=m_max` is kept so the choice can be made at estimate
//! time, when the pixel's spread is known. Image mode ([`Jung::set_sigma_image`]) lets a
//! renderer feed the running spread of all samples of the image (docs/estimators.md §4).
//!
//! `σ_pixel` comes from blocks merged with Chan et al.'s rule ([`Welford::push_block`], the
//! block form docs/estimators.md §1 allows), so no division per sample sits on a dependency
//! chain; single pushes take Welford's update. Overflow: `σ_pixel` is `+inf` once its squared
//! deviations overflow (samples spread over more than about `1e154`), which selects
//! `M = m_max` (`tests/hard_cases.rs` pins this). The sets' sums are rescaled before they overflow (see
//! [`Partition`]), so the estimate itself is finite for any finite samples.

use super::mon::{Partition, median_sorted};
use super::numeric::plain_total;
use super::rgb::per_channel;
use super::{Estimator, EstimatorSpec, Extra, Extras, Key, Method, RgbEstimator, Welford, empty};
use crate::error::{Error, Result};
use std::fmt;

/// Largest accepted `m_max`: the state holds `((m_max+1)/2)^2` sets, 262 KB at this cap.
pub const MAX_M_MAX: usize = 255;

/// `jung:sigma_image=,m_max=` (`sigma_image` required, `m_max` 17 by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JungSpec {
    /// Standard deviation of the image's samples.
    pub sigma_image: f64,
    /// Largest M (odd).
    pub m_max: usize,
}

impl Method for JungSpec {
    const NAME: &'static str = "jung";
    const KEYS: &'static [Key<Self>] = &[
        Key::required(Key::float("sigma_image", |s| &mut s.sigma_image)),
        Key::int("m_max", |s| &mut s.m_max),
    ];
    const DEFAULT: Self = JungSpec {
        sigma_image: f64::NAN,
        m_max: 17,
    };

    fn build(&self) -> Result<Box<dyn Estimator>> {
        Ok(Box::new(Jung::new(self.sigma_image, self.m_max)?))
    }

    fn build_rgb(&self) -> Result<Box<dyn RgbEstimator>> {
        per_channel(|| Jung::new(self.sigma_image, self.m_max))
    }
}

/// MoN whose M is chosen from the ratio of the pixel's and the image's sample spread.
#[derive(Debug, Clone)]
pub struct Jung {
    sigma_image: f64,
    m_max: usize,
    spread: Welford,
    /// `partitions[i]` has `2i + 1` sets.
    partitions: Vec<Partition>,
}

/// Jung's M for a pixel spread and an image spread (docs/estimators.md §4), `q` taken from the binary
/// exponent of the ratio so no rounded logarithm can move a boundary.
pub fn jung_m(sigma_pixel: f64, sigma_image: f64, m_max: usize) -> usize {
    if sigma_image == 0.0 {
        return if sigma_pixel == 0.0 { 1 } else { m_max };
    }
    let ratio = sigma_pixel / sigma_image;
    if ratio < 1.0 {
        return 1;
    }
    if !ratio.is_finite() {
        return m_max;
    }
    // ratio >= 1 is a normal number: its unbiased binary exponent is floor(log2(ratio)).
    let q = ((ratio.to_bits() >> 52) & 0x7ff) as usize - 1023;
    (2 * (q + 1) + 1).min(m_max)
}

impl Jung {
    /// `sigma_image` finite and > 0; `m_max` an odd integer in `1..=MAX_M_MAX`.
    pub fn new(sigma_image: f64, m_max: usize) -> Result<Self> {
        if !(sigma_image > 0.0 && sigma_image.is_finite()) {
            return Err(Error::param(
                "sigma_image",
                sigma_image,
                "must be finite and > 0",
            ));
        }
        if m_max % 2 == 0 || !(1..=MAX_M_MAX).contains(&m_max) {
            return Err(Error::param(
                "m_max",
                m_max,
                format!("must be an odd integer in 1..={MAX_M_MAX}"),
            ));
        }
        // Exactly as many as needed: collecting the `Result`s left the capacity at the next
        // power of two (16 for the default nine, 648 bytes a channel for nothing).
        let mut partitions = Vec::with_capacity(m_max.div_ceil(2));
        for i in 0..m_max.div_ceil(2) {
            partitions.push(Partition::new(2 * i + 1)?);
        }
        Ok(Jung {
            sigma_image,
            m_max,
            spread: Welford::new(),
            partitions,
        })
    }

    /// Image mode: the running spread of all samples of the image, read at estimate time.
    /// Zero (a black image so far) is allowed here; negative or non-finite values are not.
    pub fn set_sigma_image(&mut self, sigma_image: f64) -> Result<()> {
        if !(sigma_image >= 0.0 && sigma_image.is_finite()) {
            return Err(Error::param(
                "sigma_image",
                sigma_image,
                "must be finite and >= 0",
            ));
        }
        self.sigma_image = sigma_image;
        Ok(())
    }

    /// The M that an estimate made now would use.
    pub fn chosen_m(&self) -> usize {
        jung_m(self.spread.sigma(), self.sigma_image, self.m_max)
    }
}

impl fmt::Display for Jung {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Jung(sigma_image={},M_max={})",
            self.sigma_image, self.m_max
        )
    }
}

impl Estimator for Jung {
    #[inline]
    fn push(&mut self, sample: f64) {
        self.spread.push(sample);
        for p in &mut self.partitions {
            p.push(sample);
        }
    }

    fn push_slice(&mut self, samples: &[f64]) {
        self.spread.push_block(samples);
        let total = plain_total(samples);
        for p in &mut self.partitions {
            p.push_slice_totalled(samples, total);
        }
    }

    fn count(&self) -> u64 {
        self.spread.count()
    }

    fn partitions(&self) -> &[Partition] {
        &self.partitions
    }

    fn estimate(&self) -> Result<f64> {
        if self.count() == 0 {
            return Err(empty(self));
        }
        let mut theta = Vec::new();
        self.partitions[self.chosen_m() / 2].sorted_means(&mut theta);
        Ok(median_sorted(&theta))
    }

    fn extras(&self) -> Extras {
        vec![
            ("M", Extra::Int(self.chosen_m() as u64)),
            ("sigma_pixel", Extra::Float(self.spread.sigma())),
        ]
    }

    fn state_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.partitions.capacity() * std::mem::size_of::<Partition>()
            + self
                .partitions
                .iter()
                .map(Partition::heap_bytes)
                .sum::<usize>()
    }

    fn spec(&self) -> EstimatorSpec {
        JungSpec {
            sigma_image: self.sigma_image,
            m_max: self.m_max,
        }
        .into()
    }

    fn uses_image_sigma(&self) -> bool {
        true
    }

    fn set_image_sigma(&mut self, sigma: f64) -> Result<()> {
        self.set_sigma_image(sigma)
    }

    fn reset(&mut self) {
        self.spread = Welford::new();
        self.partitions.iter_mut().for_each(Partition::reset);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn m_boundaries_are_exact_powers_of_two() {
        assert_eq!(jung_m(0.999_999_999, 1.0, 17), 1);
        assert_eq!(jung_m(1.0, 1.0, 17), 3);
        assert_eq!(jung_m(1.999_999_999, 1.0, 17), 3);
        assert_eq!(jung_m(2.0, 1.0, 17), 5);
        assert_eq!(jung_m(4.0, 1.0, 17), 7);
        assert_eq!(jung_m(1e300, 1e-300, 17), 17);
        assert_eq!(jung_m(f64::INFINITY, 1.0, 17), 17);
        assert_eq!(jung_m(0.0, 0.0, 17), 1);
        assert_eq!(jung_m(1.0, 0.0, 17), 17);
    }

    #[test]
    fn bad_parameters_are_named() {
        assert!(
            Jung::new(0.0, 17)
                .unwrap_err()
                .to_string()
                .contains("sigma_image = 0")
        );
        assert!(
            Jung::new(1.0, 16)
                .unwrap_err()
                .to_string()
                .contains("m_max = 16")
        );
        assert!(
            Jung::new(1.0, 0)
                .unwrap_err()
                .to_string()
                .contains("m_max = 0")
        );
    }
}
