//! `fireflies reference`: a converged reference image (the plain mean at high spp) with its own
//! standard error, resumable. Writes `FILE.exr` (the mean), `FILE.exr.state` (per-pixel count,
//! mean and M2: what `--resume` continues) and `FILE.exr.json` (spp, sample ranges, scene, and
//! the reference's relative standard error).

use super::render::FilterOverride;
use clap::Args;
use fireflies::limits::{self, MemoryLimit};
use fireflies::render::mitsuba;
use fireflies::render::reference::{REFERENCE_SEED, Reference, SceneKey, scene_hash, sidecar};
use fireflies::render::world::World;
use fireflies::report::tables::git_commit;
use fireflies::{Error, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::ffi::OsString;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// A run saves its state at least this often, so a killed run loses at most this much.
const SAVE_EVERY: Duration = Duration::from_secs(600);

/// Passes per run, for progress and saving (each pass traces every pixel).
const PASSES: u64 = 64;

#[derive(Debug, Args)]
pub struct ReferenceArgs {
    /// Scene file (Mitsuba 3 XML subset; see the README).
    scene: PathBuf,
    /// Samples per pixel to add.
    #[arg(long)]
    spp: u64,
    /// The reference image (OpenEXR); its state and report go beside it as `FILE.state` and
    /// `FILE.json` with the suffix appended.
    #[arg(long)]
    out: PathBuf,
    /// First sample index of the new range (default 0, or with `--resume` the end of the
    /// samples already in the reference). Sample `i` of pixel `p` is the stream (seed, p, i).
    #[arg(long)]
    seed_start: Option<u64>,
    /// Seed of every stream (default: a fixed seed unlike `render`'s, so a reference never
    /// shares random numbers with the renders it judges; with `--resume`, the reference's).
    #[arg(long)]
    seed: Option<u64>,
    /// Add samples to an existing reference (its state file must exist and be of this scene).
    #[arg(long)]
    resume: bool,
    /// Worker threads (default: all cores). The reference does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Reconstruction filter override, as for `render`.
    #[arg(long, value_enum)]
    rfilter: Option<FilterOverride>,
}

/// Fails early when `out` cannot be written: creates its folder and a file beside it.
fn check_writable(out: &Path) -> Result<()> {
    let name = out.file_name().ok_or_else(|| Error::Io {
        path: out.display().to_string(),
        message: "not a file path".into(),
    })?;
    if out.is_dir() {
        return Err(Error::Io {
            path: out.display().to_string(),
            message: "is a directory".into(),
        });
    }
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir).map_err(|e| Error::io(out.display(), &e))?;
    let mut probe = OsString::from(".");
    probe.push(name);
    probe.push(format!(".probe-{}", std::process::id()));
    let probe = dir.join(probe);
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .map_err(|e| Error::io(out.display(), &e))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// Writes the reference's files, with this command's run and build in its report.
fn save(reference: &Reference, out: &Path, run: &serde_json::Value) -> Result<()> {
    let mut extra = serde_json::Map::new();
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().to_string());
    extra.insert("image".into(), serde_json::json!(name(out)));
    extra.insert(
        "state".into(),
        serde_json::json!(name(&sidecar(out, ".state"))),
    );
    extra.insert("last_run".into(), run.clone());
    extra.insert("git_commit".into(), serde_json::json!(git_commit()));
    reference.save(out, extra)
}

pub fn run(args: &ReferenceArgs, memory: MemoryLimit) -> Result<ExitCode> {
    if args.spp == 0 {
        return Err(Error::param("spp", 0, "must be at least 1"));
    }
    let threads = limits::threads(args.threads)?;
    let state_path = sidecar(&args.out, ".state");
    let text =
        std::fs::read_to_string(&args.scene).map_err(|e| Error::io(args.scene.display(), &e))?;
    let key = SceneKey {
        path: args.scene.display().to_string(),
        hash: scene_hash(&text),
        box_filter: args.rfilter == Some(FilterOverride::Box),
    };
    let options = mitsuba::LoadOptions {
        box_filter: key.box_filter,
    };
    let scene = mitsuba::load_file_with(&args.scene, options)?;
    let world = World::new(&scene);
    let (width, height) = (world.camera.width(), world.camera.height());

    let mut reference = if args.resume {
        let bytes = std::fs::read(&state_path).map_err(|e| Error::Io {
            path: state_path.display().to_string(),
            message: format!("nothing to resume ({e}); run without --resume first"),
        })?;
        let r = Reference::from_bytes(&bytes, &state_path.display().to_string())?;
        let old = r.scene();
        if old.hash != key.hash {
            return Err(Error::param(
                "scene",
                format!("{} ({})", key.path, key.hash),
                format!(
                    "{} was made from another scene, {} ({})",
                    args.out.display(),
                    old.path,
                    old.hash
                ),
            ));
        }
        if old.box_filter != key.box_filter {
            return Err(Error::param(
                "rfilter",
                if key.box_filter { "box" } else { "(none)" },
                format!(
                    "{} was made {} --rfilter box",
                    args.out.display(),
                    if old.box_filter { "with" } else { "without" }
                ),
            ));
        }
        if (r.width(), r.height()) != (width, height) {
            return Err(Error::param(
                "scene",
                format!("{width}x{height}"),
                format!("{} is {}x{}", args.out.display(), r.width(), r.height()),
            ));
        }
        if let Some(seed) = args.seed.filter(|&s| s != r.seed()) {
            return Err(Error::param(
                "seed",
                seed,
                format!(
                    "{} was traced with seed {}; a reference keeps one seed",
                    args.out.display(),
                    r.seed()
                ),
            ));
        }
        r
    } else {
        if state_path.exists() {
            return Err(Error::Io {
                path: state_path.display().to_string(),
                message: "a reference is already here: pass --resume to add samples to it, \
                          or remove it to start over"
                    .into(),
            });
        }
        Reference::new(
            key,
            width,
            height,
            args.seed.unwrap_or(REFERENCE_SEED),
            memory,
        )?
    };
    let start = args.seed_start.unwrap_or(reference.next_start());
    let end = start.checked_add(args.spp).ok_or_else(|| {
        Error::param(
            "seed-start",
            start,
            format!("plus --spp {} passes the last sample index", args.spp),
        )
    })?;
    reference.check_range(&(start..end))?;
    // Fail on an unwritable output before spending the render.
    check_writable(&args.out)?;

    let pool = limits::thread_pool(threads)?;
    let bar = if std::io::stderr().is_terminal() {
        let bar = ProgressBar::new(args.spp);
        bar.set_style(
            ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} spp")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
    let started = Instant::now();
    let mut saved = Instant::now();
    let pass = args.spp.div_ceil(PASSES);
    let mut done = start;
    let run_info = |done: u64, wall_s: f64| {
        let samples = u64::from(width) * u64::from(height) * (done - start);
        serde_json::json!({
            "sample_range": [start, done],
            "threads": pool.current_num_threads(),
            "wall_s": wall_s,
            "samples_per_s": samples as f64 / wall_s,
            "peak_rss_bytes": limits::peak_rss_bytes(),
        })
    };
    while done < end {
        let next = (done + pass).min(end);
        pool.install(|| reference.trace(&world, done..next))?;
        done = next;
        bar.set_position(done - start);
        if done < end && saved.elapsed() >= SAVE_EVERY {
            save(
                &reference,
                &args.out,
                &run_info(done, started.elapsed().as_secs_f64()),
            )?;
            saved = Instant::now();
        }
    }
    let wall_s = started.elapsed().as_secs_f64();
    bar.finish_and_clear();
    save(&reference, &args.out, &run_info(done, wall_s))?;

    let a = reference.accuracy();
    let show = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.3e}"));
    eprintln!(
        "reference {} -> {}: samples [{start}, {end}) in {wall_s:.2} s; {} spp in total \
         ({} invalid samples); relative standard error: {} per pixel (RMS), {} of the image mean",
        args.scene.display(),
        args.out.display(),
        reference.spp(),
        reference.invalid_samples(),
        show(a.pixel_relative_se_rms),
        show(a.image_mean_relative_se),
    );
    Ok(ExitCode::SUCCESS)
}
