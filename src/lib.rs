//! # fireflies
//!
//! Validates robust Monte Carlo pixel estimators — the mean, clamping, median of means and its
//! Gini-adaptive variants, Jung et al.'s dynamic MoN, Zirr et al.'s firefly reweighting and
//! Pajot et al.'s outlier delaying — on heavy-tailed samples whose true mean is known exactly.
//!
//! Layers (arrows point down): the command line -> [`report`] / [`harness`] -> [`dist`] ->
//! [`estimators`] -> [`error`]; [`simd`] (run-time choice of vector units) is a leaf under
//! [`dist`] and [`denoise`].
//! The estimator contract, with worked examples, is `docs/estimators.md`.

#![deny(missing_docs)]
#![forbid(unsafe_code)]
// Parameter checks are written `if !(x > 0.0)` on purpose: NaN must fail them too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod atomic;
pub mod denoise;
pub mod dist;
pub mod error;
pub mod estimators;
pub mod harness;
pub mod image;
pub mod limits;
pub mod render;
pub mod report;
pub mod samples;
pub mod scenes;
pub mod simd;

pub use error::{Error, Result};
pub use estimators::{Bank, Estimator, EstimatorSpec};
