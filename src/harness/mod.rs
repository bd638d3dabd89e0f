//! Trials at scale: experiment files, the runner, metrics with confidence intervals, and the
//! checks that turn them into pass/fail verdicts with stated error rates.

pub mod checks;
pub mod claims;
pub mod experiment;
pub mod gate;
pub mod law;
pub mod metrics;
pub mod runner;
pub mod shards;
pub mod unseen;

pub use checks::CheckResult;
pub use experiment::Experiment;
pub use runner::{RunOptions, RunOutput, run};
