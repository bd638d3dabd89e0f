//! Subcommands of the `fireflies` binary; each lives in its own module.

mod compare;
mod denoise;
mod denoise_experiment;
mod eval;
mod fit;
mod gate;
mod merge;
mod reference;
mod render;
mod run;
mod scenes;
mod transfer;

use clap::{Parser, Subcommand};
use fireflies::Result;
use fireflies::limits::MemoryLimit;
use std::process::ExitCode;

/// Validates robust Monte Carlo pixel estimators on heavy-tailed samples.
#[derive(Debug, Parser)]
#[command(name = "fireflies", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// The most memory a run or render may plan to hold, e.g. `8GiB` (default: the
    /// FIREFLIES_MAX_MEMORY environment variable, else 3/4 of physical memory). A plan above
    /// it is refused before anything is allocated.
    #[arg(long, global = true, value_name = "SIZE")]
    max_memory: Option<String>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Evaluate estimators on sample files (one JSON object per estimator on stdout).
    Eval(eval::EvalArgs),
    /// Fit a generator to one pixel's luminance stream (one JSON object on stdout).
    Fit(fit::FitArgs),
    /// Run an experiment (default: the embedded one) and write its report.
    Run(run::RunArgs),
    /// Compare a run with a committed baseline; exit 1 on a regression.
    Gate(gate::GateArgs),
    /// Merge shard files of one run into its report.
    Merge(merge::MergeArgs),
    /// Path-trace a Mitsuba 3 scene into per-pixel estimator banks.
    Render(render::RenderArgs),
    /// Trace a converged reference (the mean at high spp, resumable) with its standard error.
    Reference(reference::ReferenceArgs),
    /// Image metrics (RMSE, relMSE, PSNR, SSIM, bias, fireflies) of an EXR against a reference.
    Compare(compare::CompareArgs),
    /// Every estimator on real scenes against references: convergence, the seeds' tables, plots.
    Scenes(scenes::ScenesArgs),
    /// Denoise a `render --nfor` directory with NFOR (Bitterli et al. 2016).
    Denoise(denoise::DenoiseArgs),
    /// NFOR behind the mean and robust estimators on every scene, against references.
    DenoiseExperiment(denoise_experiment::DenoiseExperimentArgs),
    /// Do synthetic results transfer to scenes? Harness predictions on fitted pixels vs renders.
    Transfer(transfer::TransferArgs),
}

/// Runs the chosen subcommand; `Err` exits with status 2.
pub fn run(cli: Cli) -> Result<ExitCode> {
    let memory = MemoryLimit::from_setting(cli.max_memory.as_deref())?;
    match cli.command {
        Some(Command::Eval(args)) => eval::run(&args),
        Some(Command::Fit(args)) => fit::run(&args),
        Some(Command::Run(args)) => run::run(&args, memory),
        Some(Command::Merge(args)) => merge::run(&args),
        Some(Command::Gate(args)) => gate::run(&args, memory),
        Some(Command::Render(args)) => render::run(&args, memory),
        Some(Command::Reference(args)) => reference::run(&args, memory),
        Some(Command::Compare(args)) => compare::run(&args),
        Some(Command::Scenes(args)) => scenes::run(&args, memory),
        Some(Command::Transfer(args)) => transfer::run(&args, memory),
        Some(Command::Denoise(args)) => denoise::run(&args),
        Some(Command::DenoiseExperiment(args)) => denoise_experiment::run(&args, memory),
        None => run::run(&run::RunArgs::default(), memory),
    }
}
