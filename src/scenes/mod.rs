//! The scene experiment (`fireflies scenes`): every estimator on real scenes, read at every
//! checkpoint of one render and judged against a converged reference, with the seeds' tables
//! (Buisine et al.'s Tables 1 and 2, Zirr et al.'s Figure 6, Pajot et al.'s Table 4) and
//! figures built from the rows.
//!
//! [`experiment`] reads the TOML schema, [`run`] does one scene (reference, render, metrics,
//! costs, delayed fractions), [`cost`] measures what estimators cost next to tracing,
//! [`tables`] turns rows into tables and [`plots`] into figures; [`report`] writes them.
//! [`nfor_input`] turns a render's half buffers into NFOR's input; the denoising experiment
//! (`fireflies denoise-experiment`) is [`denoise_experiment`] (schema), [`denoise_run`] (one
//! scene), [`denoise_compare`] (intervals over repeats and paired ratios), [`denoise_report`]
//! (its tables) and [`denoise_plots`] (its figures).
//! [`transfer`] is the loop between real pixels and the synthetic harness (`fireflies
//! transfer`), [`transfer_report`] writes its report.

pub mod cost;
pub mod denoise_compare;
pub mod denoise_experiment;
pub mod denoise_plots;
pub mod denoise_report;
pub mod denoise_run;
pub mod experiment;
pub mod nfor_input;
pub mod plots;
pub mod report;
pub mod run;
pub mod tables;
pub mod transfer;
pub mod transfer_report;

pub use experiment::{Scene, ScenesExperiment};
pub use report::{RunInfo, write_report};
pub use run::{SceneResult, run_scene};
