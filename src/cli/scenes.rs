//! `fireflies scenes`: every estimator on the experiment's scenes, read at every checkpoint of
//! one render per scene and judged against cached references, with the seeds' tables and
//! figures (`fireflies::scenes`).

use clap::Args;
use fireflies::limits::{self, MemoryLimit};
use fireflies::scenes::{self, RunInfo, ScenesExperiment};
use fireflies::{Error, Result};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct ScenesArgs {
    /// The experiment file (e.g. `experiments/scenes.toml`).
    experiment: PathBuf,
    /// Report directory.
    #[arg(long, default_value = "reports/scenes")]
    out: PathBuf,
    /// Reference cache: references are read from here, extended, or made and kept here
    /// (default: `<out>/references`).
    #[arg(long)]
    references: Option<PathBuf>,
    /// Scale the experiment down as its `[quick]` section says (smaller images, fewer spp).
    #[arg(long)]
    quick: bool,
    /// Run only these scenes (comma-separated names).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Worker threads (default: all cores). Images do not depend on it; timings do.
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(args: &ScenesArgs, memory: MemoryLimit) -> Result<ExitCode> {
    let started = Instant::now();
    let threads = limits::threads(args.threads)?;
    let mut exp = ScenesExperiment::load(&args.experiment, args.quick)?;
    if !args.only.is_empty() {
        for name in &args.only {
            if !exp.scenes.iter().any(|s| &s.name == name) {
                return Err(Error::param(
                    "only",
                    name,
                    format!(
                        "is not a scene of {}; its scenes: {}",
                        args.experiment.display(),
                        exp.scenes
                            .iter()
                            .map(|s| s.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
        }
        exp.scenes.retain(|s| args.only.contains(&s.name));
    }
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
    for (i, scene) in exp.scenes.iter().enumerate() {
        let r = pool.install(|| scenes::run_scene(&exp, scene, &references, memory, &mut log))?;
        results.push(r);
        let info = RunInfo {
            command: command.clone(),
            wall_s: started.elapsed().as_secs_f64(),
            threads: pool.current_num_threads(),
            pending: exp.scenes[i + 1..].iter().map(|s| s.name.clone()).collect(),
        };
        written = pool.install(|| scenes::write_report(&args.out, &exp, &results, &info))?;
    }
    log(format!(
        "wrote {} files to {} in {:.1} s",
        written.len(),
        args.out.display(),
        started.elapsed().as_secs_f64()
    ));
    Ok(ExitCode::SUCCESS)
}
