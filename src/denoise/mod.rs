//! Denoising: NFOR (Bitterli et al. 2016) on a render's half buffers, so that the project can
//! measure whether a robust estimator in front of a denoiser helps. It reads planes, not files:
//! the command line loads a render's outputs ([`crate::render::nfor_buffers`]) and hands them
//! over.

pub mod nfor;
pub mod nlmeans;
pub mod planes;
pub mod regression;

pub use nfor::{NforInput, NforOutput, NforParams, nfor};
pub use planes::Planes;
