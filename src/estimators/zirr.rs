//! Zirr et al. cascade reweighting — placeholder replaced by the Zirr module's author.
use super::{Estimator, EstimatorSpec, ZirrParams};
use crate::error::{Error, Result};
use std::fmt;

/// Zirr et al.'s method as in the paper (spec §5).
#[derive(Debug, Clone)]
pub struct Zirr;
/// Zirr et al.'s method as in the released code (spec §5a).
#[derive(Debug, Clone)]
pub struct ZirrRef;
impl Zirr {
    /// Checked constructor.
    pub fn new(_p: ZirrParams) -> Result<Self> { Err(Error::param("zirr", "", "not built yet")) }
}
impl ZirrRef {
    /// Checked constructor.
    pub fn new(_p: ZirrParams) -> Result<Self> { Err(Error::param("zirr-ref", "", "not built yet")) }
}
macro_rules! placeholder {
    ($t:ty) => {
        impl fmt::Display for $t { fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result { write!(f, "placeholder") } }
        impl Estimator for $t {
            fn push(&mut self, _s: f64) {}
            fn count(&self) -> u64 { 0 }
            fn estimate(&self) -> Result<f64> { Err(Error::EmptyStream(String::new())) }
            fn state_bytes(&self) -> usize { 0 }
            fn spec(&self) -> EstimatorSpec { EstimatorSpec::Mean }
            fn reset(&mut self) {}
        }
    };
}
placeholder!(Zirr);
placeholder!(ZirrRef);
impl Zirr {
    /// Placeholder.
    pub fn block_estimate(_b: &[Option<&Self>; 9]) -> Result<(f64, super::Extras)> { Err(Error::EmptyStream(String::new())) }
}
impl ZirrRef {
    /// Placeholder.
    pub fn block_estimate(_b: &[Option<&Self>; 9]) -> Result<(f64, super::Extras)> { Err(Error::EmptyStream(String::new())) }
}
