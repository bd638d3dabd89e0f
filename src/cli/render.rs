//! `fireflies render`: path-trace a Mitsuba 3 scene into per-pixel estimator banks and write
//! one image per estimator (and per checkpoint) plus `render.json`.

use clap::Args;
use fireflies::estimators::EstimatorSpec;
use fireflies::limits::{self, MemoryLimit, shorten};
use fireflies::render::film::{self, FilmConfig, file_stem};
use fireflies::render::mitsuba;
use fireflies::render::world::World;
use fireflies::report::{tables::git_commit, write_atomic};
use fireflies::{Error, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Scene file (Mitsuba 3 XML subset; see the README).
    scene: PathBuf,
    /// Samples per pixel (default: the scene's `sample_count`).
    #[arg(long)]
    spp: Option<u32>,
    /// Seed of every random stream.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Comma-separated estimator specs, e.g. `mean,gmon:M=21,gmonb:M=21,threshold=0.3`
    /// (a `key=value` item continues the spec before it).
    #[arg(long, default_value = "mean")]
    estimators: String,
    /// Comma-separated sample counts at which every estimator's image is also written.
    #[arg(long, value_delimiter = ',')]
    checkpoints: Vec<u32>,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Worker threads (default: all cores). The image does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Pixels whose raw luminance streams are written, `x,y;x,y;...`, one sample per line in
    /// `pixel_<x>_<y>.txt` (readable by `fireflies eval`).
    #[arg(long, value_name = "X,Y;...")]
    dump_pixels: Option<String>,
    /// Reconstruction filter override: `box` renders a scene whose film asks for another filter
    /// (tent, gaussian, ...) with a box filter, so that every sample belongs to one pixel;
    /// `render.json` records what the scene asked for. Without it such a scene is an error.
    #[arg(long, value_enum)]
    rfilter: Option<FilterOverride>,
    /// Exposure multiplier of the PNG previews (the EXR files are linear and unscaled).
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    /// Also write the buffers NFOR denoising reads: colour and features (normal, albedo, depth,
    /// visibility) of two independent halves of the samples with their variances, and every
    /// estimator on each half (README, "Buffers for denoising"). Needs at least 4 spp.
    #[arg(long)]
    nfor: bool,
}

/// The reconstruction filters `--rfilter` may force.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FilterOverride {
    /// A box of one pixel: each sample counts for the pixel it was taken in.
    Box,
}

/// Splits `mean,gmonb:M=21,threshold=0.3,gmon` into specs: an item without `:` that holds
/// `=` continues the previous spec.
pub fn parse_estimator_list(text: &str) -> Result<Vec<EstimatorSpec>> {
    let mut items: Vec<String> = Vec::new();
    for token in text.split(',').map(str::trim) {
        match items.last_mut() {
            Some(last) if token.contains('=') && !token.contains(':') => {
                last.push(',');
                last.push_str(token);
            }
            _ => items.push(token.to_string()),
        }
    }
    items.iter().map(|t| t.parse()).collect()
}

/// Parses `x,y;x,y`. A well-formed coordinate beyond any image is reported as out of range
/// (the film then names the image size), not as malformed.
fn parse_pixels(text: &str) -> Result<Vec<(u32, u32)>> {
    text.split(';')
        .filter(|t| !t.trim().is_empty())
        .map(|t| {
            let shown = shorten(t);
            let (x, y) = t.split_once(',').ok_or_else(|| {
                Error::param("dump-pixels", &shown, "expected x,y (two integers)")
            })?;
            let coordinate = |c: &str, axis: &str| -> Result<u32> {
                let c = c.trim();
                if !c.is_empty() && c.bytes().all(|b| b.is_ascii_digit()) {
                    c.parse().map_err(|_| {
                        Error::param(
                            "dump-pixels",
                            &shown,
                            format!(
                                "{axis} = {} is out of range (at most {})",
                                shorten(c),
                                u32::MAX
                            ),
                        )
                    })
                } else {
                    Err(Error::param(
                        "dump-pixels",
                        &shown,
                        format!("{axis} must be a non-negative integer"),
                    ))
                }
            };
            Ok((coordinate(x, "x")?, coordinate(y, "y")?))
        })
        .collect()
}

pub fn run(args: &RenderArgs, memory: MemoryLimit) -> Result<ExitCode> {
    if !(args.exposure.is_finite() && args.exposure > 0.0) {
        return Err(Error::param(
            "exposure",
            args.exposure,
            "must be finite and > 0",
        ));
    }
    let threads = limits::threads(args.threads)?;
    let load_start = Instant::now();
    let options = mitsuba::LoadOptions {
        box_filter: args.rfilter == Some(FilterOverride::Box),
    };
    let scene = mitsuba::load_file_with(&args.scene, options)?;
    let load_s = load_start.elapsed().as_secs_f64();
    let estimators = parse_estimator_list(&args.estimators)?;
    let cfg = FilmConfig {
        estimators,
        spp: args.spp.unwrap_or(scene.camera.spp),
        checkpoints: args.checkpoints.clone(),
        seed: args.seed,
        dump_pixels: match &args.dump_pixels {
            Some(t) => parse_pixels(t)?,
            None => Vec::new(),
        },
        memory,
    };
    // Fail on an unwritable output before spending the render.
    std::fs::create_dir_all(&args.out).map_err(|e| Error::io(args.out.display(), &e))?;
    let pool = limits::thread_pool(threads)?;
    let bar = if std::io::stderr().is_terminal() {
        let bar = ProgressBar::new(u64::from(cfg.spp));
        bar.set_style(
            ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} spp")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
    let start = Instant::now();
    let world = World::new(&scene);
    let build_s = start.elapsed().as_secs_f64();
    let out = pool.install(|| {
        film::render_with_nfor(&world, &cfg, args.nfor, |done| {
            bar.set_position(u64::from(done))
        })
    })?;
    let wall_s = start.elapsed().as_secs_f64();
    bar.finish_and_clear();

    let mut written = Vec::new();
    for img in &out.images {
        let stem = file_stem(&cfg.estimators[img.estimator]);
        let mut names = Vec::new();
        if img.spp == cfg.spp {
            names.push(stem.clone());
        }
        if cfg.checkpoints.contains(&img.spp) {
            names.push(format!("{stem}@{}", img.spp));
        }
        for name in names {
            img.image.write_exr(&args.out.join(format!("{name}.exr")))?;
            img.image
                .write_png(&args.out.join(format!("{name}.png")), args.exposure)?;
            written.push(name);
        }
    }
    for ((x, y), stream) in &out.dumps {
        let mut text = String::with_capacity(stream.len() * 24);
        for v in stream {
            text.push_str(&format!("{v:e}\n"));
        }
        write_atomic(
            &args.out.join(format!("pixel_{x}_{y}.txt")),
            text.as_bytes(),
        )?;
    }
    let nfor = match &out.nfor {
        Some(buffers) => {
            let mut manifest = buffers.write(&args.out)?;
            manifest["extra_bytes_per_pixel"] = serde_json::json!(nfor_bytes(&cfg, &out));
            Some(manifest)
        }
        None => None,
    };
    let mut report = serde_json::json!({
        "scene": args.scene.display().to_string(),
        "width": world.camera.width(),
        "height": world.camera.height(),
        "spp": cfg.spp,
        "seed": cfg.seed,
        "threads": pool.current_num_threads(),
        "estimators": cfg.estimators.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "checkpoints": cfg.checkpoints,
        "rfilter": {
            "used": "box",
            "scene_asked_for": scene.camera.replaced_filter.as_deref().unwrap_or("box"),
            "override": scene.camera.replaced_filter.is_some(),
        },
        "load_s": load_s,
        "wall_s": wall_s,
        "build_s": build_s,
        // The render alone, after the BVH and emitter tables are built: what Mitsuba's
        // `mi.render` times (its `load_file` builds the scene).
        "render_s": wall_s - build_s,
        "estimate_s": out.estimate_seconds,
        "samples": out.samples,
        "samples_per_s": out.samples as f64 / wall_s,
        "invalid_samples": out.invalid_samples,
        "state_bytes_per_pixel": cfg.estimators.iter().zip(&out.state_bytes)
            .map(|(s, b)| (s.to_string(), serde_json::json!(b)))
            .collect::<serde_json::Map<_, _>>(),
        "images": written,
        "peak_rss_bytes": limits::peak_rss_bytes(),
        "git_commit": git_commit(),
    });
    if let Some(nfor) = nfor {
        report["nfor"] = nfor;
    }
    let text = serde_json::to_string_pretty(&report).unwrap_or_default();
    write_atomic(&args.out.join("render.json"), text.as_bytes())?;
    eprintln!(
        "rendered {} at {} spp in {:.2} s ({:.3e} samples/s, {} invalid samples) -> {}",
        args.scene.display(),
        cfg.spp,
        wall_s,
        out.samples as f64 / wall_s,
        out.invalid_samples,
        Path::new(&args.out).display()
    );
    Ok(ExitCode::SUCCESS)
}

/// What the NFOR halves add per pixel: two more banks (their measured state) plus the moments
/// and final images ([`film::nfor_bytes_per_pixel`]).
fn nfor_bytes(cfg: &FilmConfig, out: &film::FilmOutput) -> usize {
    let bank: f64 = out.state_bytes.iter().sum();
    let boxes = cfg.estimators.len() * 2 * size_of::<usize>();
    film::nfor_bytes_per_pixel(bank.round() as usize + boxes, cfg.estimators.len())
}
