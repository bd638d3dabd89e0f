//! `fireflies run`: an experiment from a TOML file (or the embedded default) to a report.

use clap::Args;
use fireflies::harness::runner::{self, Shard};
use fireflies::harness::shards::ShardFile;
use fireflies::harness::{self, Experiment, RunOptions, RunOutput};
use fireflies::limits::MemoryLimit;
use fireflies::{Result, report};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args, Default)]
pub struct RunArgs {
    /// Experiment file; without it, the embedded `experiments/default.toml`.
    experiment: Option<PathBuf>,
    /// Report directory (default: `reports/<experiment name>`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Overrides the experiment's trial count.
    #[arg(long)]
    trials: Option<u64>,
    /// Worker threads (default: one per core). Results do not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Overrides the experiment's seed (not with --shard: shards must share the file's seed).
    #[arg(long, conflicts_with = "shard")]
    seed: Option<u64>,
    /// Run only shard i of k (`i/k`, 0-based) and write its mergeable statistics to
    /// `DIR/shard-i-of-k.json`; `fireflies merge` combines the shards into the report.
    #[arg(long, value_name = "i/k")]
    shard: Option<String>,
    /// Write the tables only, no figures (for runs repeated over many seeds).
    #[arg(long)]
    no_plots: bool,
}

pub fn run(args: &RunArgs, memory: MemoryLimit) -> Result<ExitCode> {
    let exp = load(args.experiment.as_deref(), args.seed)?;
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("reports").join(&exp.name));
    // Fail on an unusable directory before spending the run. A report replaces `dir` as a
    // whole; a shard is one file written into it.
    if args.shard.is_some() {
        std::fs::create_dir_all(&dir).map_err(|e| fireflies::Error::io(dir.display(), &e))?;
    } else {
        report::prepare_report_dir(&dir)?;
    }
    let opts = RunOptions {
        trials: args.trials,
        threads: args.threads,
        progress: std::io::stderr().is_terminal(),
        build: None,
        memory,
    };
    eprintln!(
        "running {} ({} distributions x {} estimators, {} trials, n up to {})",
        exp.name,
        exp.distributions.len(),
        exp.estimators.len(),
        opts.trials.unwrap_or(exp.file.trials),
        exp.max_n()
    );
    for w in &exp.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(text) = &args.shard {
        let shard = Shard::parse(text)?;
        let output = runner::run_shard(&exp, &opts, shard)?;
        let path = dir.join(ShardFile::file_name(shard.index, shard.count));
        let json = serde_json::to_vec(&ShardFile::new(&exp, output))
            .map_err(|e| fireflies::Error::io(path.display(), &std::io::Error::other(e)))?;
        report::write_atomic(&path, &json)?;
        eprintln!("wrote {}", path.display());
        return Ok(ExitCode::SUCCESS);
    }
    let out = harness::run(&exp, &opts)?;
    report_run(&dir, &exp, &out, !args.no_plots)
}

/// The experiment at `path` (or the embedded default), with its seed optionally replaced.
pub fn load(path: Option<&std::path::Path>, seed: Option<u64>) -> Result<Experiment> {
    let mut exp = match path {
        Some(path) => Experiment::load(path)?,
        None => Experiment::default_experiment()?,
    };
    if let Some(seed) = seed {
        exp.file.seed = seed;
    }
    Ok(exp)
}

/// Checks, tables and plots of a finished run, replacing the report at `dir` as a unit; exit
/// code 1 when a gating check failed.
pub fn report_run(
    dir: &std::path::Path,
    exp: &Experiment,
    out: &RunOutput,
    with_plots: bool,
) -> Result<ExitCode> {
    let checks = harness::checks::evaluate(exp, out);
    report::write_report(dir, exp, out, &checks, with_plots)?;
    let failed: Vec<_> = checks.iter().filter(|c| !c.passed).collect();
    let fails_run = checks.iter().any(|c| c.fails_run());
    eprintln!(
        "wrote {} in {:.1} s ({:.3e} samples/s); {} checks, {} failed",
        dir.display(),
        out.wall_s,
        out.samples_per_s(),
        checks.len(),
        failed.len()
    );
    for c in &failed {
        eprintln!(
            "{} {} on {} / {} at n = {}: {} (observed {}, p = {:.3e})",
            if c.gating {
                "FAILED"
            } else {
                "finding: violated"
            },
            c.check,
            c.distribution,
            c.estimator,
            c.n,
            c.claim,
            c.observed,
            c.p_value
        );
    }
    Ok(if !fails_run {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
