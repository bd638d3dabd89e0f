#!/usr/bin/env python3
"""Cross-checks `fireflies render` against Mitsuba 3 on the same scenes: bias and speed.

For each scene both renderers make K independent images at the same sample count (seeds
0..K-1): Mitsuba 3.9.1 in its `scalar_rgb` variant, in process (`mi.render`), and ours with
`target/release/fireflies render SCENE --spp N --seed k --estimators mean --out DIR`, whose
`DIR/mean.exr` is the plain per-pixel mean (the box filter makes Mitsuba's pixel the plain mean
too) and whose `DIR/render.json` gives `wall_s`, `samples_per_s` and `invalid_samples`.

Bias test, after Jung, Hanika and Dachsbacher, "Detecting Bias in Monte Carlo Renderers using
Welch's t-test", JCGT 9(2), 2020: each image is averaged over blocks of B x B pixels (partial
blocks at the right and bottom edges are averaged over the pixels they have); the K seeds give K
independent samples of every block mean for each renderer, and every block and colour channel
gets a Welch t-test (unequal variances) of "same expectation". The family of all those tests in
a scene is held at alpha = 0.01 by a Sidak correction, alpha_test = 1 - (1 - alpha)^(1/#tests).
Without bias the expected number of rejecting tests in a scene is about alpha (that is, almost
always zero), so a single rejecting test fails the scene, and a single failing scene fails the
run. What passing does not prove: a bias smaller than the block mean's noise at K seeds goes
unseen (the JSON report gives the smallest p-value per scene and the relative difference of the
image means with its standard error, which bounds what the test could see); and on heavy-tailed
scenes the t statistic is only approximately t-distributed at small K.

Speed: samples per second = width * height * spp / seconds, where seconds is the wall clock of
the `mi.render` call alone for Mitsuba and the renderer's own `wall_s` for ours, summed over the
seeds; both run on the same number of threads (`--threads`, default all cores).

Usage (any CPython 3.11 with the venv module and pip; nothing else needs to be installed):

    python3 experiments/crosscheck_mitsuba.py [SCENE.xml ...] [--spp N] [--seeds K]
        [--block B] [--threads T] [--quick] [--no-build] [--mitsuba-only] [--out DIR]

Scenes default to every *.xml in experiments/scenes/. The script makes its own virtual environment in experiments/.venv-mitsuba,
installs the pinned Mitsuba, Dr.Jit, NumPy and SciPy there if they are missing, and re-runs
itself inside it. It builds the binary with `cargo build --release` unless --no-build or
--mitsuba-only. It prints a Markdown table and writes it with a JSON report to
reports/crosscheck/ (crosscheck.md, crosscheck.json, and the seed-averaged images of each
renderer under images/).

Exit status: 0 when no scene shows bias, 1 when any scene does, 2 when a scene could not be
rendered or compared (and none showed bias), 3 when the build or the environment failed.
"""

import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import venv
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
VENV_DIR = HERE / ".venv-mitsuba"
BINARY = ROOT / "target" / "release" / "fireflies"
OUR_SCENES = HERE / "scenes"
DEFAULT_OUT = ROOT / "reports" / "crosscheck"
# Set in the environment of the re-executed script, so a broken venv cannot loop forever.
REEXEC_FLAG = "FIREFLIES_CROSSCHECK_IN_VENV"

MITSUBA_VERSION = "3.9.1"
DRJIT_VERSION = "1.5.0"
REQUIREMENTS = [f"mitsuba=={MITSUBA_VERSION}", f"drjit=={DRJIT_VERSION}", "numpy", "scipy"]
VARIANT = "scalar_rgb"

# Family-wise significance level of all block tests of one scene (Sidak-corrected per test).
# At 0.01 a correct renderer fails a given scene about once in a hundred runs.
FAMILY_ALPHA = 0.01
DEFAULT_SPP = 64
DEFAULT_SEEDS = 8
QUICK_SPP = 16
QUICK_SEEDS = 4
DEFAULT_BLOCK = 8
# A block whose K values are (numerically) the same in both renderers has no t statistic:
# such a block (a constant background, a black corner) passes when the two means agree to
# this relative tolerance, which allows for float32 rounding, and fails otherwise.
DEGENERATE_RTOL = 1e-4
DEGENERATE_ATOL = 1e-7

EXIT_OK, EXIT_BIAS, EXIT_ERROR, EXIT_SETUP = 0, 1, 2, 3


# --- environment -----------------------------------------------------------------------------

def venv_python() -> Path:
    if os.name == "nt":
        return VENV_DIR / "Scripts" / "python.exe"
    return VENV_DIR / "bin" / "python"


def in_venv() -> bool:
    return Path(sys.prefix).resolve() == VENV_DIR.resolve()


def requirements_met(python: Path) -> bool:
    check = (
        "import importlib.metadata as m, numpy, scipy, drjit, mitsuba\n"
        f"assert m.version('mitsuba') == {MITSUBA_VERSION!r}, m.version('mitsuba')\n"
        f"assert m.version('drjit') == {DRJIT_VERSION!r}, m.version('drjit')\n"
    )
    done = subprocess.run([str(python), "-c", check],
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return done.returncode == 0


def ensure_venv_and_reexec() -> None:
    """Creates experiments/.venv-mitsuba with the pinned packages if needed and replaces this
    process by the script running inside it."""
    if os.environ.get(REEXEC_FLAG):
        print(f"re-executed inside {VENV_DIR} but sys.prefix is {sys.prefix}; "
              f"delete {VENV_DIR} and run again", file=sys.stderr)
        sys.exit(EXIT_SETUP)
    if sys.version_info[:2] != (3, 11):
        print(f"note: running on Python {platform.python_version()}; the pinned Mitsuba "
              f"{MITSUBA_VERSION} is tested on CPython 3.11", file=sys.stderr)
    python = venv_python()
    if not python.exists():
        print(f"creating virtual environment {VENV_DIR}", file=sys.stderr)
        venv.EnvBuilder(with_pip=True, clear=True).create(VENV_DIR)
        (VENV_DIR / ".gitignore").write_text("# Made by crosscheck_mitsuba.py\n*\n")
    if not requirements_met(python):
        print(f"installing {' '.join(REQUIREMENTS)} into the virtual environment",
              file=sys.stderr)
        done = subprocess.run([str(python), "-m", "pip", "install", "--quiet",
                               "--disable-pip-version-check", *REQUIREMENTS])
        if done.returncode != 0 or not requirements_met(python):
            print(f"could not install {' '.join(REQUIREMENTS)} into {VENV_DIR}",
                  file=sys.stderr)
            sys.exit(EXIT_SETUP)
    env = dict(os.environ)
    env[REEXEC_FLAG] = "1"
    os.execve(str(python), [str(python), str(Path(__file__).resolve()), *sys.argv[1:]], env)


# --- scenes and renderers ----------------------------------------------------------------------

def default_scenes() -> list:
    return sorted(OUR_SCENES.glob("*.xml"))


def label(path: Path) -> str:
    """The scene's name in the report: its path relative to the repository, so equal file
    names in different folders stay apart."""
    return os.path.relpath(path.resolve(), ROOT)


def rgb(array):
    """Float64 (height, width, 3) from an image array: alpha dropped, grey broadcast."""
    import numpy as np

    a = np.asarray(array, dtype=np.float64)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return a[:, :, :3]


def render_mitsuba(path: Path, spp: int, seeds: list) -> dict:
    """Renders the scene once per seed; returns the images and the render-call timings."""
    import mitsuba as mi
    import numpy as np

    scene = mi.load_file(str(path))
    images, seconds = [], []
    for seed in seeds:
        start = time.perf_counter()
        result = mi.render(scene, spp=spp, seed=seed)
        elapsed = time.perf_counter() - start
        images.append(rgb(np.array(result)))
        seconds.append(elapsed)
    height, width = images[0].shape[:2]
    return {
        "images": np.stack(images),
        "seconds": seconds,
        "samples_per_s": width * height * spp * len(seeds) / sum(seconds),
    }


def render_ours(binary: Path, path: Path, spp: int, seeds: list, threads: int) -> dict:
    """Runs `fireflies render` once per seed; returns the mean images and its own timings."""
    import mitsuba as mi
    import numpy as np

    images, seconds, reported, invalid = [], [], [], 0
    for seed in seeds:
        with tempfile.TemporaryDirectory(prefix="fireflies-crosscheck-") as out:
            cmd = [str(binary), "render", str(path), "--spp", str(spp), "--seed", str(seed),
                   "--estimators", "mean", "--threads", str(threads), "--out", out]
            done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  text=True)
            if done.returncode != 0:
                raise RuntimeError(f"{' '.join(cmd)} exited {done.returncode}:\n"
                                   f"{done.stderr.strip()}")
            exr = Path(out) / "mean.exr"
            manifest = Path(out) / "render.json"
            for needed in (exr, manifest):
                if not needed.exists():
                    raise RuntimeError(f"{' '.join(cmd)} wrote no {needed.name}")
            images.append(rgb(np.array(mi.Bitmap(str(exr)))))
            info = json.loads(manifest.read_text())
            seconds.append(float(info["wall_s"]))
            reported.append(float(info["samples_per_s"]))
            invalid += int(info.get("invalid_samples", 0))
    height, width = images[0].shape[:2]
    return {
        "images": np.stack(images),
        "seconds": seconds,
        "samples_per_s": width * height * spp * len(seeds) / sum(seconds),
        "reported_samples_per_s": reported,
        "invalid_samples": invalid,
    }


# --- statistics --------------------------------------------------------------------------------

def block_means(images, block: int):
    """(K, H, W, C) images -> (K, rows, cols, C) block means; edge blocks may be partial."""
    import numpy as np

    _, height, width, _ = images.shape
    rows = np.arange(0, height, block)
    cols = np.arange(0, width, block)
    sums = np.add.reduceat(np.add.reduceat(images, rows, axis=1), cols, axis=2)
    row_n = np.diff(np.append(rows, height))
    col_n = np.diff(np.append(cols, width))
    return sums / (row_n[:, None] * col_n[None, :])[None, :, :, None]


def welch_blocks(ref, ours, block: int) -> dict:
    """Welch's t-test per block and channel between K reference and K test images."""
    import numpy as np
    from scipy import stats

    a = block_means(ref, block).reshape(ref.shape[0], -1)
    b = block_means(ours, block).reshape(ours.shape[0], -1)
    tests = a.shape[1]
    level = 1.0 - (1.0 - FAMILY_ALPHA) ** (1.0 / tests)

    mean_a, mean_b = a.mean(axis=0), b.mean(axis=0)
    se = np.sqrt(a.var(axis=0, ddof=1) / a.shape[0] + b.var(axis=0, ddof=1) / b.shape[0])
    scale = np.maximum(np.abs(mean_a), np.abs(mean_b))
    # No spread in either renderer (beyond float32 noise): no t statistic; compare the means.
    degenerate = se <= DEGENERATE_RTOL * scale + DEGENERATE_ATOL
    with np.errstate(divide="ignore", invalid="ignore"):
        p = stats.ttest_ind(a, b, axis=0, equal_var=False).pvalue
    agree = np.abs(mean_a - mean_b) <= DEGENERATE_RTOL * scale + DEGENERATE_ATOL
    p = np.where(degenerate, np.where(agree, 1.0, 0.0), p)
    p = np.where(np.isnan(p), 1.0, p)
    reject = p < level
    worst = int(np.argmin(p))
    return {
        "tests": int(tests),
        "rejecting": int(reject.sum()),
        "fraction_rejecting": float(reject.mean()),
        "degenerate": int(degenerate.sum()),
        "level": level,
        "min_p": float(p[worst]),
        "min_p_block": {  # where the smallest p-value is: block row, column, channel
            "row": int(worst // 3 // ((ref.shape[2] + block - 1) // block)),
            "col": int(worst // 3 % ((ref.shape[2] + block - 1) // block)),
            "channel": "RGB"[worst % 3],
        },
    }


def relative_difference(ref, ours) -> dict:
    """ours / ref - 1 of the image means, with its delta-method standard error over seeds."""
    import numpy as np

    ma = ref.mean(axis=(1, 2, 3))
    mb = ours.mean(axis=(1, 2, 3))
    ka, kb = len(ma), len(mb)
    a, b = ma.mean(), mb.mean()
    ratio = b / a
    se = abs(ratio) * np.sqrt(mb.var(ddof=1) / kb / b**2 + ma.var(ddof=1) / ka / a**2)
    return {"rel_diff": float(ratio - 1.0), "se": float(se),
            "mitsuba_mean": float(a), "ours_mean": float(b)}


# --- output ------------------------------------------------------------------------------------

def write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_image_atomic(path: Path, image) -> None:
    import mitsuba as mi
    import numpy as np

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.exr")
    mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32)).write(str(tmp))
    os.replace(tmp, path)


def fmt_rate(x) -> str:
    return "—" if x is None else f"{x / 1e6:.3f}"


def markdown(settings: dict, rows: list) -> str:
    lines = [
        "# Cross-check against Mitsuba 3",
        "",
        f"Mitsuba {settings['mitsuba']} (`{VARIANT}`, Dr.Jit {settings['drjit']}) against "
        f"`fireflies render --estimators mean`, {settings['threads']} thread(s) each, "
        f"seeds 0..{settings['seeds'] - 1}, {settings['block']}x{settings['block']}-pixel "
        f"blocks. Welch's t-test per block and channel (Jung, Hanika and Dachsbacher, JCGT "
        f"2020) at family alpha = {FAMILY_ALPHA} per scene, Sidak-corrected; without bias "
        f"about {FAMILY_ALPHA:.0%} of scenes show one rejecting test by chance, and a single "
        f"rejecting scene fails the check. Samples/s = width x height x spp / wall-clock "
        f"seconds of the render (Mitsuba: the `mi.render` call; ours: `wall_s`).",
        "",
        "| scene | spp | seeds | blocks rejecting / tests | mean rel. diff ± SE "
        "| Mitsuba Msamples/s | ours Msamples/s | ratio | verdict |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        ours = r.get("ours") or {}
        welch = r.get("welch")
        diff = r.get("difference")
        mits = r.get("mitsuba") or {}
        ratio = r.get("speed_ratio")
        lines.append("| " + " | ".join([
            f"`{r['scene']}`",
            str(r["spp"]),
            str(r["seeds"]),
            f"{welch['rejecting']} / {welch['tests']}" if welch else "—",
            f"{diff['rel_diff']:+.2%} ± {diff['se']:.2%}" if diff else "—",
            fmt_rate(mits.get("samples_per_s")),
            fmt_rate(ours.get("samples_per_s")),
            f"{ratio:.2f}" if ratio is not None else "—",
            r["verdict"],
        ]) + " |")
    lines.append("")
    lines.append(f"Generated {settings['date']} on {settings['machine']} "
                 f"({settings['cpus']} cores).")
    return "\n".join(lines) + "\n"


# --- main --------------------------------------------------------------------------------------

def build() -> None:
    print("cargo build --release", file=sys.stderr)
    done = subprocess.run(["cargo", "build", "--release"], cwd=ROOT)
    if done.returncode != 0:
        print("cargo build --release failed", file=sys.stderr)
        sys.exit(EXIT_SETUP)


def crosscheck(path: Path, args, seeds: list) -> dict:
    import numpy as np

    row = {"scene": label(path), "path": str(path), "spp": args.spp, "seeds": len(seeds)}
    print(f"{row['scene']}: Mitsuba, {len(seeds)} x {args.spp} spp", file=sys.stderr)
    mits = render_mitsuba(path, args.spp, seeds)
    height, width = mits["images"].shape[1:3]
    row["size"] = [int(width), int(height)]
    row["mitsuba"] = {"samples_per_s": mits["samples_per_s"], "seconds": mits["seconds"]}
    stem = label(path).replace("/", "_").replace(".._", "").removesuffix(".xml")
    images = args.out / "images"
    write_image_atomic(images / f"{stem}.mitsuba.exr", mits["images"].mean(axis=0))
    if args.mitsuba_only:
        row["verdict"] = "Mitsuba only"
        return row

    print(f"{row['scene']}: fireflies, {len(seeds)} x {args.spp} spp", file=sys.stderr)
    try:
        ours = render_ours(args.binary, path, args.spp, seeds, args.threads)
    except (RuntimeError, OSError, ValueError, KeyError) as e:
        row["error"] = str(e)
        row["verdict"] = "ERROR: render failed"
        print(f"  {e}", file=sys.stderr)
        return row
    row["ours"] = {k: ours[k] for k in
                   ("samples_per_s", "seconds", "reported_samples_per_s", "invalid_samples")}
    row["speed_ratio"] = ours["samples_per_s"] / mits["samples_per_s"]
    write_image_atomic(images / f"{stem}.ours.exr", ours["images"].mean(axis=0))
    if ours["images"].shape != mits["images"].shape:
        row["error"] = (f"image shapes differ: Mitsuba {mits['images'].shape[1:]}, "
                        f"ours {ours['images'].shape[1:]}")
        row["verdict"] = "ERROR: size"
        return row
    if not np.all(np.isfinite(ours["images"])):
        row["error"] = "our image has NaN or infinite pixels"
        row["verdict"] = "ERROR: non-finite"
        return row
    row["welch"] = welch_blocks(mits["images"], ours["images"], args.block)
    row["difference"] = relative_difference(mits["images"], ours["images"])
    biased = row["welch"]["rejecting"] > 0
    row["biased"] = biased
    row["verdict"] = "FAIL: bias" if biased else "pass"
    if ours["invalid_samples"]:
        row["verdict"] += f" ({ours['invalid_samples']} invalid samples)"
    return row


def main() -> None:
    global FAMILY_ALPHA
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene_args", nargs="*", metavar="SCENE", type=Path,
                        help="scene files (default: experiments/scenes/*.xml)")
    parser.add_argument("--scenes", nargs="+", type=Path, default=[], metavar="SCENE",
                        help="scene files, as the positional arguments")
    parser.add_argument("--spp", type=int, help=f"samples per pixel (default {DEFAULT_SPP}; "
                                                f"{QUICK_SPP} with --quick)")
    parser.add_argument("--seeds", type=int, help=f"independent renders per renderer "
                                                  f"(default {DEFAULT_SEEDS}; {QUICK_SEEDS} "
                                                  f"with --quick)")
    parser.add_argument("--block", type=int, default=DEFAULT_BLOCK,
                        help=f"block size in pixels (default {DEFAULT_BLOCK})")
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1,
                        help="threads for both renderers (default: all cores)")
    parser.add_argument("--alpha", type=float, default=FAMILY_ALPHA,
                        help=f"family-wise level of the block tests of one scene "
                        f"(default {FAMILY_ALPHA}; CI uses 0.001 over its four scenes)")
    parser.add_argument("--quick", action="store_true",
                        help=f"fewer samples and seeds ({QUICK_SPP} spp, {QUICK_SEEDS} seeds) "
                             f"unless given")
    parser.add_argument("--no-build", action="store_true",
                        help="do not run `cargo build --release` first")
    parser.add_argument("--mitsuba-only", action="store_true",
                        help="render and time Mitsuba only (a reference; no comparison)")
    parser.add_argument("--binary", type=Path, default=BINARY,
                        help=f"our renderer (default {os.path.relpath(BINARY, ROOT)})")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"report folder (default {os.path.relpath(DEFAULT_OUT, ROOT)})")
    args = parser.parse_args()
    if not 0.0 < args.alpha < 1.0:
        parser.error(f"--alpha must be in (0, 1), got {args.alpha}")
    FAMILY_ALPHA = args.alpha
    if args.spp is None:
        args.spp = QUICK_SPP if args.quick else DEFAULT_SPP
    if args.seeds is None:
        args.seeds = QUICK_SEEDS if args.quick else DEFAULT_SEEDS
    if args.spp < 1 or args.block < 1 or args.threads < 1:
        parser.error("--spp, --block and --threads must be positive")
    if args.seeds < 2:
        parser.error("--seeds must be at least 2 (the t-test needs a variance)")
    scenes = [*args.scene_args, *args.scenes] or default_scenes()
    if not scenes:
        parser.error("no scenes given and none found")
    missing = [str(s) for s in scenes if not s.is_file()]
    if missing:
        parser.error(f"no such scene file: {', '.join(missing)}")
    args.out = args.out.resolve()
    args.binary = args.binary.resolve()

    if not in_venv():
        ensure_venv_and_reexec()

    import drjit as dr
    import mitsuba as mi

    if not args.mitsuba_only:
        if not args.no_build:
            build()
        if not args.binary.exists():
            print(f"{args.binary} not found: build it with `cargo build --release`",
                  file=sys.stderr)
            sys.exit(EXIT_SETUP)
    mi.set_variant(VARIANT)
    mi.set_log_level(mi.LogLevel.Warn)
    dr.set_thread_count(args.threads)

    seeds = list(range(args.seeds))
    rows = []
    with tempfile.TemporaryDirectory(prefix="fireflies-crosscheck-bin-") as bindir:
        if not args.mitsuba_only:
            # Run a private copy: a `cargo build` during the run then neither removes the
            # binary under us nor mixes two versions in one report.
            original, args.binary = args.binary, Path(bindir) / args.binary.name
            shutil.copy2(original, args.binary)
        for path in scenes:
            try:
                rows.append(crosscheck(path, args, seeds))
            except Exception as e:  # a scene Mitsuba cannot load must not hide the others
                rows.append({"scene": label(path), "path": str(path), "spp": args.spp,
                             "seeds": args.seeds, "error": f"{type(e).__name__}: {e}",
                             "verdict": "ERROR: Mitsuba"})
                print(f"  {type(e).__name__}: {e}", file=sys.stderr)
        if not args.mitsuba_only:
            args.binary = original

    settings = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": platform.node() or "unknown",
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "mitsuba": mi.__version__,
        "drjit": dr.__version__,
        "variant": VARIANT,
        "threads": args.threads,
        "spp": args.spp,
        "seeds": args.seeds,
        "block": args.block,
        "family_alpha": FAMILY_ALPHA,
        "mitsuba_only": args.mitsuba_only,
        "binary": None if args.mitsuba_only else str(args.binary),
    }
    table = markdown(settings, rows)
    print(table)
    write_atomic(args.out / "crosscheck.md", table)
    write_atomic(args.out / "crosscheck.json",
                 json.dumps({"settings": settings, "scenes": rows}, indent=2) + "\n")
    print(f"wrote {args.out / 'crosscheck.md'} and crosscheck.json", file=sys.stderr)

    if any(r.get("biased") for r in rows):
        sys.exit(EXIT_BIAS)
    if any("error" in r for r in rows):
        sys.exit(EXIT_ERROR)
    sys.exit(EXIT_OK)


if __name__ == "__main__":
    main()
