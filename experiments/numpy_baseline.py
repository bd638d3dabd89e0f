#!/usr/bin/env python3
"""What a user would otherwise write: the mean and median of means of heavy-tailed pixel
samples over many independent trials, in NumPy, timed against `fireflies` on the same task.

The task (issue 4, "Speed and scale"), identical to `experiments/throughput.toml`:
  for each of T trials, draw n = 4096 samples from a Pareto law of shape 1.5 and scale 1/3
  (the `infinite-variance` preset, mean 1) by inverse transform, S = scale * U^(-1/shape) with
  U uniform on (0, 1] from NumPy's default Generator (PCG64); estimate the mean, and MoN(21):
  sample i goes to set i mod 21, the estimate is the median of the 21 set means.

NumPy code is vectorised over trials in batches (one (batch, n) array reused), so the work is
elementwise and single-threaded: the comparison is against `fireflies run --threads 1`.

Usage (any CPython >= 3.9 with the venv module and pip; nothing else needs to be installed):

    python3 experiments/numpy_baseline.py [--trials T] [--batch B] [--seed S] [--skip-fireflies]

The script makes its own virtual environment in experiments/.venv (ignored by git through a
`.gitignore` it writes inside), installs NumPy there if it is missing, and re-runs itself
inside it. It then runs `target/release/fireflies run experiments/throughput.toml` on 1 and 2
threads (build it first with `cargo build --release`) and prints one JSON object with samples
per second for each and the ratios against NumPy on one core.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import venv
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
VENV_DIR = HERE / ".venv"
EXPERIMENT = HERE / "throughput.toml"
BINARY = ROOT / "target" / "release" / "fireflies"
# Set in the environment of the re-executed script, so a broken venv cannot loop forever.
REEXEC_FLAG = "FIREFLIES_NUMPY_BASELINE_IN_VENV"

SHAPE = 1.5
SCALE = 1.0 / 3.0
N = 4096
SETS = 21


def venv_python() -> Path:
    if os.name == "nt":
        return VENV_DIR / "Scripts" / "python.exe"
    return VENV_DIR / "bin" / "python"


def in_venv() -> bool:
    return Path(sys.prefix).resolve() == VENV_DIR.resolve()


def ensure_venv_and_reexec() -> None:
    """Creates experiments/.venv with NumPy if needed and replaces this process by the script
    running inside it."""
    if os.environ.get(REEXEC_FLAG):
        sys.exit(f"re-executed inside {VENV_DIR} but sys.prefix is {sys.prefix}; "
                 f"delete {VENV_DIR} and run again")
    python = venv_python()
    if not python.exists():
        print(f"creating virtual environment {VENV_DIR}", file=sys.stderr)
        venv.EnvBuilder(with_pip=True, clear=True).create(VENV_DIR)
        (VENV_DIR / ".gitignore").write_text("# Made by numpy_baseline.py\n*\n")
    has_numpy = subprocess.run(
        [str(python), "-c", "import numpy"], stderr=subprocess.DEVNULL
    ).returncode == 0
    if not has_numpy:
        print("installing numpy into the virtual environment", file=sys.stderr)
        subprocess.run(
            [str(python), "-m", "pip", "install", "--quiet", "numpy"], check=True
        )
    env = dict(os.environ)
    env[REEXEC_FLAG] = "1"
    # The workload is elementwise: no BLAS call is made. OPENBLAS_CORETYPE (set on some of
    # our machines) would only matter if one were; drop it so it cannot slow anything down,
    # and keep any BLAS single-threaded so the run stays on one core.
    env.pop("OPENBLAS_CORETYPE", None)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = "1"
    os.execve(str(python), [str(python), str(Path(__file__).resolve()), *sys.argv[1:]], env)


def numpy_run(trials: int, batch: int, seed: int) -> dict:
    """Draws and estimates every trial; returns timing and summaries of the estimates."""
    import numpy as np

    rng = np.random.default_rng(seed)  # PCG64
    exponent = -1.0 / SHAPE
    full = N // SETS * SETS  # samples in whole rounds of the 21 sets
    rem = N - full  # the last partial round: sets 0..rem get one sample more
    counts = np.full(SETS, N // SETS, dtype=np.float64)
    counts[:rem] += 1.0
    buf = np.empty((batch, N))
    means = np.empty(trials)
    mons = np.empty(trials)

    start = time.perf_counter()
    done = 0
    while done < trials:
        b = min(batch, trials - done)
        x = buf[:b]
        # Inverse transform in place: U on [0, 1) -> 1 - U on (0, 1] -> scale * U^(-1/shape),
        # the power written as exp(ln(U) * (-1/shape)): NumPy's log and exp are SIMD loops,
        # np.power is not, and this form is 1.3x faster on the draw (measured, NumPy 2.4).
        rng.random(out=x)
        np.subtract(1.0, x, out=x)
        np.log(x, out=x)
        x *= exponent
        np.exp(x, out=x)
        x *= SCALE
        means[done:done + b] = x.mean(axis=1)
        # Set j holds samples j, j + 21, ...: whole rounds as a (b, rounds, 21) view.
        sums = x[:, :full].reshape(b, full // SETS, SETS).sum(axis=1)
        sums[:, :rem] += x[:, full:]
        mons[done:done + b] = np.median(sums / counts, axis=1)
        done += b
    elapsed = time.perf_counter() - start

    samples = trials * N
    return {
        "numpy": np.__version__,
        "python": sys.version.split()[0],
        "trials": trials,
        "n": N,
        "batch": batch,
        "seconds": elapsed,
        "samples_per_s": samples / elapsed,
        # Sanity: the mean is unbiased (mu = 1) but its average converges slowly on this tail;
        # MoN is biased low here.
        "mean_of_means": float(means.mean()),
        "median_of_mons": float(np.median(mons)),
    }


def fireflies_run(trials: int, threads: int) -> dict:
    """Runs the experiment with the release binary; returns its manifest's speed fields."""
    with tempfile.TemporaryDirectory(prefix="fireflies-throughput-") as out:
        cmd = [str(BINARY), "run", str(EXPERIMENT), "--out", out,
               "--trials", str(trials), "--threads", str(threads)]
        done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode != 0:
            sys.exit(f"{' '.join(cmd)} exited {done.returncode}:\n{done.stderr}")
        manifest = json.loads((Path(out) / "manifest.json").read_text())
    return {
        "command": " ".join(cmd[:3] + ["--out", "DIR"] + cmd[5:]),
        "threads": threads,
        "wall_s": manifest["wall_s"],
        "samples_per_s": manifest["samples_per_s"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=20000, help="trials (default 20000)")
    parser.add_argument("--batch", type=int, default=64,
                        help="trials per vectorised batch (default 64: a 2 MB array)")
    parser.add_argument("--seed", type=int, default=20261121)
    parser.add_argument("--skip-fireflies", action="store_true",
                        help="time NumPy only")
    args = parser.parse_args()
    if args.trials < 1 or args.batch < 1:
        parser.error("--trials and --batch must be positive")

    if not in_venv():
        ensure_venv_and_reexec()

    report = {"task": f"mean + MoN({SETS}) of pareto(scale=1/3, shape={SHAPE}), n = {N}"}
    report["numpy_1_core"] = numpy_run(args.trials, args.batch, args.seed)
    if not args.skip_fireflies:
        if not BINARY.exists():
            report["fireflies"] = f"{BINARY} not found: run `cargo build --release` first"
        else:
            base = report["numpy_1_core"]["samples_per_s"]
            runs = [fireflies_run(args.trials, k) for k in (1, 2)]
            for r in runs:
                r["ratio_vs_numpy_1_core"] = r["samples_per_s"] / base
            report["fireflies"] = runs
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
