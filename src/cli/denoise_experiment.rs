//! `fireflies denoise-experiment`: does a robust estimator in front of NFOR help? Every scene of
//! the experiment file at several sample counts, each colour source noisy and denoised, against
//! cached references, and NFOR's own MSE estimate checked over seeds
//! (`fireflies::scenes::denoise_run`).

use clap::Args;
use fireflies::limits::{self, MemoryLimit};
use fireflies::scenes::RunInfo;
use fireflies::scenes::denoise_experiment::DenoiseExperiment;
use fireflies::scenes::denoise_report::write_denoise_report;
use fireflies::scenes::denoise_run::run_denoise_scene;
use fireflies::{Error, Result};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct DenoiseExperimentArgs {
    /// The experiment file (e.g. `experiments/denoise.toml`).
    experiment: PathBuf,
    /// Report directory.
    #[arg(long, default_value = "reports/denoise")]
    out: PathBuf,
    /// Reference cache: references are read from here, extended, or made and kept here
    /// (default: `<out>/references`; `reports/scenes/references` holds the same scenes).
    #[arg(long)]
    references: Option<PathBuf>,
    /// Scale the experiment down as its `[quick]` section says (smaller images, fewer spp).
    #[arg(long)]
    quick: bool,
    /// Worker threads (default: all cores). Images do not depend on it; timings do.
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(args: &DenoiseExperimentArgs, memory: MemoryLimit) -> Result<ExitCode> {
    let started = Instant::now();
    let threads = limits::threads(args.threads)?;
    let exp = DenoiseExperiment::load(&args.experiment, args.quick)?;
    let references = args
        .references
        .clone()
        .unwrap_or_else(|| args.out.join("references"));
    std::fs::create_dir_all(&args.out).map_err(|e| Error::io(args.out.display(), &e))?;
    let pool = limits::thread_pool(threads)?;
    let mut log = |line: String| eprintln!("[{:7.1} s] {line}", started.elapsed().as_secs_f64());
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let mut results = Vec::new();
    let mut written = Vec::new();
    // The report is rewritten after every scene, so a run stopped late keeps what it did.
    for i in 0..exp.scenes.len() {
        let r = pool.install(|| run_denoise_scene(&exp, i, &references, memory, &mut log))?;
        results.push(r);
        let info = RunInfo {
            command: command.clone(),
            wall_s: started.elapsed().as_secs_f64(),
            threads: pool.current_num_threads(),
            pending: exp.scenes[i + 1..]
                .iter()
                .map(|s| s.scene.name.clone())
                .collect(),
        };
        written = pool.install(|| write_denoise_report(&args.out, &exp, &results, &info))?;
    }
    log(format!(
        "wrote {} files to {} in {:.1} s",
        written.len(),
        args.out.display(),
        started.elapsed().as_secs_f64()
    ));
    Ok(ExitCode::SUCCESS)
}
