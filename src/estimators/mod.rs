//! Per-pixel streaming estimators: the reusable core.
//!
//! Every estimator is a small struct with a checked constructor, fed one sample stream through
//! [`Estimator::push`]/[`Estimator::push_slice`] and read at any time through
//! [`Estimator::estimate`]. The contract, with worked examples, is `docs/estimators.md`.
//!
//! Samples are validated once, at the boundary ([`Bank`], the command line, the film); the
//! estimators themselves assume finite, non-negative input. This module does no I/O, draws no
//! random numbers and imports nothing of the crate but [`crate::error`].

mod bank;
mod clamp;
mod jung;
mod mean;
mod mon;
mod numeric;
mod pajot;
mod rgb;
mod spec;
pub mod zirr;

spec::methods! {
    Mean(mean::MeanSpec),
    Clamp(clamp::ClampSpec),
    Mon(mon::MonSpec),
    Gini(mon::GiniSpec),
    GmonB(mon::GmonBSpec),
    Gmon(mon::GmonSpec),
    Jung(jung::JungSpec),
    Zirr(zirr::ZirrSpec),
    ZirrRef(zirr::ZirrRefSpec),
    PajotRot(pajot::PajotRotSpec),
    PajotAdr(pajot::PajotAdrSpec),
    PajotHybrid(pajot::PajotHybridSpec),
}

pub use bank::{Bank, RgbBank, validate_samples};
pub use clamp::Clamp;
pub use jung::Jung;
pub use mean::Mean;
pub use mon::{GiniDiagnostic, Gmon, GmonB, Mon, Partition, gini};
pub use numeric::{Neumaier, Welford};
pub use pajot::{
    AdrBound, BoundStrategy, HybridBound, Pajot, PajotAdr, PajotHybrid, PajotMode, PajotRot,
    RotBound, adr_bandwidths,
};
pub use rgb::{REC709, RgbEstimator, build_rgb, luminance};
pub use spec::{CONSTANT_MEMORY_SET, CascadeSize, Key, Method};
pub use zirr::{Zirr, ZirrParams};

use crate::error::Result;
use std::fmt;

/// A value reported beside the estimate (`gini`, Jung's chosen `M`, Zirr's buffer weights...).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum Extra {
    /// A count.
    Int(u64),
    /// A real number (non-finite values serialise as JSON `null`).
    Float(f64),
    /// One real number per buffer or set.
    Floats(Vec<f64>),
    /// A flag.
    Bool(bool),
}

/// Named extras, in a stable order.
pub type Extras = Vec<(&'static str, Extra)>;

/// A per-pixel streaming estimator of the mean of a non-negative random variable.
pub trait Estimator: Send + Sync + fmt::Display {
    /// Adds one sample. The caller guarantees it is finite and non-negative.
    fn push(&mut self, sample: f64);

    /// Adds a block of samples in order; same result as pushing them one by one.
    fn push_slice(&mut self, samples: &[f64]) {
        for &s in samples {
            self.push(s);
        }
    }

    /// Number of samples pushed so far.
    fn count(&self) -> u64;

    /// The current estimate; an error when no sample has been pushed.
    fn estimate(&self) -> Result<f64>;

    /// Method-specific values for reports (empty by default).
    fn extras(&self) -> Extras {
        Vec::new()
    }

    /// Bytes of per-pixel state held right now (struct plus heap).
    fn state_bytes(&self) -> usize;

    /// The canonical spec string's structured form; `spec().build()` rebuilds an equal
    /// estimator with no samples.
    fn spec(&self) -> EstimatorSpec;

    /// Forgets every sample, keeping the parameters (lets a harness reuse allocations).
    fn reset(&mut self);

    /// The round-robin partitions the estimator keeps of its whole stream (one for MoN, Gini,
    /// G-MoN and G-MoN_b; Jung's nine), so that in a [`Bank`] an estimator that keeps exactly
    /// one can copy an earlier estimator's partition with as many sets instead of filling its
    /// own: an optional capability, none by default.
    fn partitions(&self) -> &[Partition] {
        &[]
    }

    /// [`Estimator::push_slice`] when `partition` (with as many sets as this estimator's one
    /// partition) has been fed this estimator's whole stream, `samples` included: the
    /// estimator adopts it and updates the rest of its state. Same result as
    /// `push_slice(samples)`.
    fn push_slice_sharing(&mut self, samples: &[f64], partition: &Partition) {
        let _ = partition;
        self.push_slice(samples);
    }

    /// Whether the estimator reads the image's sample spread `σ_image` (Jung's image mode,
    /// docs/estimators.md §4): an optional capability, false by default.
    fn uses_image_sigma(&self) -> bool {
        false
    }

    /// Sets the image's spread `σ_image` (finite, `≥ 0`) where
    /// [`Estimator::uses_image_sigma`]; a no-op otherwise.
    fn set_image_sigma(&mut self, sigma: f64) -> Result<()> {
        let _ = sigma;
        Ok(())
    }
}

/// The error for an estimate requested before any sample arrived.
pub(crate) fn empty(what: &dyn fmt::Display) -> crate::error::Error {
    crate::error::Error::EmptyStream(what.to_string())
}
