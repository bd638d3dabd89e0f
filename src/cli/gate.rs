//! `fireflies gate`: did bias, variance, error or the firefly rate get worse than the
//! committed baseline, beyond noise and beyond a practical margin? Exit 1 on a regression or on
//! anything that makes a comparison impossible (missing or NaN rows, another experiment's
//! baseline); exit 2 on an error (unreadable files, `--update` from incomplete results).

use clap::Args;
use fireflies::harness::gate::{self, Identity, Snapshot};
use fireflies::harness::{self, RunOptions};
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
    /// Baseline to compare with (written by `--update`: the run's identity, then its rows).
    #[arg(long)]
    baseline: PathBuf,
    /// Rewrite the baseline (atomically) with the current results instead of comparing;
    /// refused unless the results hold every gated row of the experiment.
    #[arg(long)]
    update: bool,
    /// Compare an existing report directory (its `results.csv` and `manifest.json`) instead
    /// of running.
    #[arg(long, value_name = "DIR")]
    results: Option<PathBuf>,
    /// Where the current run's report goes (default: `reports/<experiment>`).
    #[arg(long, conflicts_with = "results")]
    out: Option<PathBuf>,
    /// Overrides the experiment's trial count.
    #[arg(long, conflicts_with = "results")]
    trials: Option<u64>,
    /// Worker threads.
    #[arg(long, conflicts_with = "results")]
    threads: Option<usize>,
    /// Overrides the experiment's seed (use one other than the baseline's, or the statistics
    /// compare a run with itself).
    #[arg(long, conflicts_with = "results")]
    seed: Option<u64>,
}

/// At most this many problems in an error message; the rest are counted.
const LISTED: usize = 12;

pub fn run(args: &GateArgs, memory: MemoryLimit) -> Result<ExitCode> {
    let exp = super::run::load(Some(&args.experiment), args.seed)?;
    let cfg = &exp.file.gate;
    let (dir, identity) = match &args.results {
        Some(dir) => (
            dir.clone(),
            Identity::from_manifest(&dir.join("manifest.json"), &exp)?,
        ),
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
            (dir, Identity::of(&exp, out.trials))
        }
    };
    let results = dir.join("results.csv");
    let now = Snapshot {
        identity,
        rows: tables::read_results_csv(&results)?,
        exact: gate::read_exact_tests(&dir.join("checks.json"))?,
    };
    if args.update {
        let problems = gate::incomplete(&now, cfg);
        if !problems.is_empty() {
            let why = if now.rows.is_empty() {
                "it holds no rows".to_string()
            } else {
                let mut lines: Vec<String> = problems
                    .iter()
                    .take(LISTED)
                    .map(|p| format!("\n  {p}"))
                    .collect();
                if problems.len() > LISTED {
                    lines.push(format!("\n  and {} more", problems.len() - LISTED));
                }
                format!(
                    "{} problem(s) with its gated rows:{}",
                    problems.len(),
                    lines.concat()
                )
            };
            return Err(Error::Io {
                path: results.display().to_string(),
                message: format!(
                    "refusing to update the baseline {} (left as it was): {why}",
                    args.baseline.display()
                ),
            });
        }
        report::write_atomic(&args.baseline, &now.to_csv()?)?;
        eprintln!(
            "baseline {} updated from {} (experiment {}, seed {}, {} trials)",
            args.baseline.display(),
            results.display(),
            now.identity.experiment,
            now.identity.seed,
            now.identity.trials
        );
        return Ok(ExitCode::SUCCESS);
    }
    let baseline = Snapshot::read(&args.baseline)?;
    eprintln!(
        "gate: baseline seed {} (fireflies {}), this run seed {} (fireflies {})",
        baseline.identity.seed,
        baseline.identity.crate_version,
        now.identity.seed,
        now.identity.crate_version
    );
    if baseline.identity.seed == now.identity.seed {
        eprintln!(
            "note: the run uses the baseline's seed, so it reproduces the baseline on unchanged \
             code and the statistics do not act; pass --seed with another value to test them"
        );
    }
    let outcome = gate::gate(&baseline, &now, cfg);
    println!("{}", gate::table(&outcome));
    let gated = outcome
        .comparisons
        .iter()
        .filter(|c| c.p_value.is_some())
        .count();
    eprintln!(
        "gate: {} metrics compared, {gated} gated (Holm, family-wise false-alarm rate {}), {} \
         not gated; {} regressions, {} problems",
        outcome.comparisons.len(),
        cfg.family_alpha,
        outcome.comparisons.len() - gated,
        outcome.regressions(),
        outcome.problems.len()
    );
    for p in &outcome.problems {
        eprintln!("gate: {p}");
    }
    Ok(if outcome.failed() {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
