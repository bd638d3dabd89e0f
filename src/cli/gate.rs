//! `fireflies gate`: did bias, variance, error or the firefly rate get worse than the
//! committed baseline, beyond noise and beyond a practical margin?

use clap::Args;
use fireflies::harness::{self, RunOptions, gate};
use fireflies::limits::MemoryLimit;
use fireflies::report::{self, tables};
use fireflies::{Error, Result};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct GateArgs {
    /// Experiment file (its `[gate]` section sets the margins).
    experiment: PathBuf,
    /// Baseline `results.csv` to compare with.
    #[arg(long)]
    baseline: PathBuf,
    /// Rewrite the baseline (atomically) with the current results instead of failing.
    #[arg(long)]
    update: bool,
    /// Compare an existing report directory's `results.csv` instead of running.
    #[arg(long, value_name = "DIR")]
    results: Option<PathBuf>,
    /// Where the current run's report goes (default: `reports/<experiment>`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Overrides the experiment's trial count.
    #[arg(long)]
    trials: Option<u64>,
    /// Worker threads.
    #[arg(long)]
    threads: Option<usize>,
    /// Overrides the experiment's seed.
    #[arg(long)]
    seed: Option<u64>,
}

pub fn run(args: &GateArgs, memory: MemoryLimit) -> Result<ExitCode> {
    let exp = super::run::load(Some(&args.experiment), args.seed)?;
    let results = match &args.results {
        Some(dir) => dir.join("results.csv"),
        None => {
            let dir = args
                .out
                .clone()
                .unwrap_or_else(|| PathBuf::from("reports").join(&exp.name));
            report::prepare_report_dir(&dir)?;
            let opts = RunOptions {
                trials: args.trials,
                threads: args.threads,
                progress: std::io::stderr().is_terminal(),
                build: None,
                memory,
            };
            let out = harness::run(&exp, &opts)?;
            let checks = harness::checks::evaluate(&exp, &out);
            // The tables only (no plots), replacing the report at `dir` as a unit.
            report::write_report(&dir, &exp, &out, &checks, false)?;
            dir.join("results.csv")
        }
    };
    let now = tables::read_results_csv(&results)?;
    if args.update {
        report::write_atomic(&args.baseline, &tables::results_csv(&now)?)?;
        eprintln!(
            "baseline {} updated from {}",
            args.baseline.display(),
            results.display()
        );
        return Ok(ExitCode::SUCCESS);
    }
    let baseline = tables::read_results_csv(&args.baseline)?;
    let comparisons = gate::compare(&baseline, &now, &exp.file.gate);
    if comparisons.is_empty() {
        return Err(Error::param(
            "baseline",
            args.baseline.display(),
            "shares no gated metric with the current results (different experiment?)",
        ));
    }
    println!("{}", gate::table(&comparisons));
    let regressions = comparisons.iter().filter(|c| c.regression).count();
    let gated = comparisons.iter().filter(|c| c.p_value.is_some()).count();
    eprintln!(
        "gate: {} metrics compared ({gated} gated, family-wise false-alarm rate {}), {regressions} regressions",
        comparisons.len(),
        exp.file.gate.family_alpha
    );
    Ok(if regressions == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
