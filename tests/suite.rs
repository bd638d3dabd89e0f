//! The integration, property and statistical tests, as one binary.
//!
//! Each file of `tests/` is a module here: one release binary links and optimises the crate once
//! (thin LTO with one codegen unit takes about 40 s per binary, so 40 binaries made most of the
//! CI time). Run one file's tests with `cargo test --release --test suite -- NAME::`, e.g.
//! `cargo test --release --test suite -- statistics::`.

mod common;

mod cli;
mod denoise;
mod denoise_experiment;
mod dist;
mod eval_fuzz;
mod fit;
mod gate;
mod hard_cases;
mod image_metrics;
mod limits;
mod overflow;
mod pajot;
mod plots;
mod properties;
mod readme_plugins;
mod reference;
mod render;
mod render_bsdf;
mod render_bumpmap;
mod render_dielectrics;
mod render_envmap;
mod render_formats;
mod render_geometry;
mod render_loader;
mod render_nfor;
mod render_plastic;
mod render_textures;
mod render_transforms;
mod report_swap;
mod rgb_estimators;
mod run_fuzz;
mod scene_fuzz;
mod scenes;
mod shards;
mod spec_examples;
mod statistics;
mod transfer;
mod zirr;
