//! `fireflies denoise DIR --out FILE.exr`: NFOR on the half buffers of a `render --nfor`
//! directory, for the plain mean or a robust estimator the render ran on each half.

use clap::Args;
use fireflies::denoise::{NforParams, nfor};
use fireflies::error::Error;
use fireflies::limits;
use fireflies::render::nfor_buffers::NforBuffers;
use fireflies::scenes::nfor_input::{ColorSource, VarianceSource, nfor_input};
use fireflies::{Result, atomic};
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct DenoiseArgs {
    /// A directory written by `fireflies render --nfor`.
    dir: PathBuf,
    /// The denoised image (OpenEXR, linear RGB). A JSON summary is written beside it
    /// (`FILE.json`): the inputs, every NFOR parameter, time per stage and peak memory.
    #[arg(long, value_name = "FILE.exr")]
    out: PathBuf,
    /// What to denoise: `mean`, or an estimator of the render by spec (`gmon:M=21`) or file
    /// stem (`gmon_M=21`); its per-half images are used.
    #[arg(long, default_value = "mean")]
    estimator: String,
    /// Per-half colour variance: `sample` (the renderer's) or `halves` (from the halves'
    /// difference). Default: `sample` for the mean, `halves` for an estimator.
    #[arg(long, value_enum)]
    variance: Option<VarianceSource>,
    /// Worker threads (default: all cores). The image does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(args: &DenoiseArgs) -> Result<ExitCode> {
    if args.out.extension().and_then(|e| e.to_str()) != Some("exr") {
        return Err(Error::param(
            "out",
            args.out.display(),
            "must name an .exr file",
        ));
    }
    let threads = limits::threads(args.threads)?;
    let start = Instant::now();
    let buffers = NforBuffers::read(&args.dir)?;
    let source = ColorSource::parse(&args.estimator);
    let variance = args
        .variance
        .unwrap_or_else(|| VarianceSource::default_for(&source));
    let input = nfor_input(&buffers, &source, variance)?;
    let (spp, seed) = (buffers.spp, buffers.seed);
    drop(buffers);
    let load_s = start.elapsed().as_secs_f64();
    let params = NforParams::paper();
    let pool = limits::thread_pool(threads)?;
    let threads = pool.current_num_threads();
    let t = Instant::now();
    let out = pool.install(|| nfor(&input, &params))?;
    let denoise_s = t.elapsed().as_secs_f64();
    out.image.to_image()?.write_exr(&args.out)?;
    let (w, h) = (out.image.width(), out.image.height());
    let megapixels = (w * h) as f64 / 1e6;
    let peak = limits::peak_rss_bytes();
    let s = out.seconds;
    let summary = json!({
        "render": args.dir.display().to_string(),
        "image": args.out.display().to_string(),
        "estimator": source.name(),
        "variance": variance,
        "spp": spp,
        "seed": seed.to_string(),
        "width": w,
        "height": h,
        "threads": threads,
        "params": format!("{params:?}"),
        "load_seconds": load_s,
        "denoise_seconds": denoise_s,
        "seconds_per_megapixel": denoise_s / megapixels,
        "stage_seconds": {
            "prefilter": s.prefilter,
            "regression": s.regression,
            "selection": s.selection,
            "second_pass": s.second_pass,
        },
        "peak_rss_bytes": peak,
    });
    let json_path = args.out.with_extension("json");
    let text = serde_json::to_string_pretty(&summary).unwrap_or_default() + "\n";
    atomic::write_atomic(&json_path, text.as_bytes())?;
    eprintln!(
        "denoised {} ({}x{}, {} spp, {}) in {:.2} s ({:.1} s/MP on {threads} threads; peak {} MB) -> {}",
        args.dir.display(),
        w,
        h,
        spp,
        source.name(),
        denoise_s,
        denoise_s / megapixels,
        peak.map_or("?".into(), |b| format!("{:.0}", b as f64 / 1e6)),
        args.out.display()
    );
    Ok(ExitCode::SUCCESS)
}
