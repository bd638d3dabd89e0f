//! `fireflies merge`: shards of one run into the report a single run would have written.

use clap::Args;
use fireflies::Result;
use fireflies::harness::shards;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct MergeArgs {
    /// Directories holding `shard-i-of-k.json` files (or the files themselves).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Report directory.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: &MergeArgs) -> Result<ExitCode> {
    let files = shards::find_shard_files(&args.inputs)?;
    let (exp, out) = shards::merge(&files)?;
    fireflies::report::prepare_report_dir(&args.out)?;
    eprintln!("merged {} shards of {}", files.len(), exp.name);
    super::run::report_run(&args.out, &exp, &out, true)
}
