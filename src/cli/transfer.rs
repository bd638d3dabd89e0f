//! `fireflies transfer`: do synthetic results transfer to scenes? Per pixel of the experiment
//! file, the harness's predicted errors on a fitted generator beside the errors measured over
//! many renders (`fireflies::scenes::transfer`).

use clap::Args;
use fireflies::limits::{self, MemoryLimit};
use fireflies::scenes::transfer::{ScenePixel, TransferExperiment, transfer_pixel};
use fireflies::scenes::transfer_report::{RunInfo, write_report};
use fireflies::{Error, Result};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct TransferArgs {
    /// The experiment file (e.g. `experiments/transfer.toml`).
    experiment: PathBuf,
    /// Report directory.
    #[arg(long, default_value = "reports/transfer")]
    out: PathBuf,
    /// Use the file's `[quick]` counts (tiny: for CI and a first look).
    #[arg(long)]
    quick: bool,
    /// Fit the generator to this many samples instead of the file's `fit_spp`.
    #[arg(long, value_name = "N")]
    fit_spp: Option<u64>,
    /// Worker threads (default: all cores). Results do not depend on it; timings do.
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(args: &TransferArgs, memory: MemoryLimit) -> Result<ExitCode> {
    let started = Instant::now();
    let threads = limits::threads(args.threads)?;
    let mut exp = TransferExperiment::load(&args.experiment, args.quick)?;
    if let Some(n) = args.fit_spp {
        exp = exp.with_fit_spp(n)?;
    }
    std::fs::create_dir_all(&args.out).map_err(|e| Error::io(args.out.display(), &e))?;
    let pool = limits::thread_pool(threads)?;
    let log = |line: String| eprintln!("[{:7.1} s] {line}", started.elapsed().as_secs_f64());
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let mut results = Vec::new();
    let mut written = Vec::new();
    // The report is rewritten after every pixel, so a run stopped late keeps what it did.
    for (i, p) in exp.pixels.iter().enumerate() {
        log(format!(
            "{} ({}): {} ({}, {})",
            p.label,
            p.class,
            p.scene.display(),
            p.x,
            p.y
        ));
        let source = ScenePixel::load(p)?;
        let r = pool.install(|| {
            transfer_pixel(
                &source,
                &p.label,
                &p.class,
                &exp.settings,
                Some(threads),
                memory,
            )
        })?;
        log(format!(
            "{}: truth {:.4e} (rel. SE {:.2e}), fitted mean {:+.2}% off; wall s: truth {:.1}, \
             fit {:.1}, renders {:.1}, harness {:.1}",
            p.label,
            r.truth.mean,
            r.truth.relative_se(),
            100.0 * r.fit_error(),
            r.wall_s[0],
            r.wall_s[1],
            r.wall_s[2],
            r.wall_s[3]
        ));
        results.push(r);
        let info = RunInfo {
            command: command.clone(),
            wall_s: started.elapsed().as_secs_f64(),
            threads: pool.current_num_threads(),
            pending: exp.pixels[i + 1..]
                .iter()
                .map(|q| q.label.clone())
                .collect(),
        };
        written = write_report(&args.out, &exp, &results, &info)?;
    }
    log(format!(
        "wrote {} files to {} in {:.1} s",
        written.len(),
        args.out.display(),
        started.elapsed().as_secs_f64()
    ));
    Ok(ExitCode::SUCCESS)
}
