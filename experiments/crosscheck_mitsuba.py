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
run. A block whose two means differ by under 0.05% of its mean (PRACTICAL_RTOL) agrees whatever
its t statistic: on nearly noise-free regions such as a directly seen sky, float32 rounding
differences between the renderers would otherwise reject. What passing does not prove: a bias smaller than the block mean's noise at K seeds goes
unseen (the JSON report gives the smallest p-value per scene and the relative difference of the
image means with its standard error, which bounds what the test could see); and on heavy-tailed
scenes the t statistic is only approximately t-distributed at small K.

Speed: samples per second = width * height * spp / seconds, where seconds is the wall clock of
the `mi.render` call alone for Mitsuba and the renderer's own `render_s` for ours (its `wall_s`
less `build_s`, the BVH and emitter tables, which Mitsuba builds in `load_file`), summed over the
seeds; both run on the same number of threads (`--threads`, default all cores), and they take
turns seed by seed, so that a drift of the machine's speed during the run falls on both alike.
Both load times are reported beside them.

Scene copies and overrides. Some scenes cannot be given to both renderers as they are; the
script then writes a modified copy of the XML next to the original (so that relative paths to
meshes and textures still resolve) under a temporary hidden name, gives that copy to the
renderer, and removes it afterwards; every change is printed and recorded in the report:
  - a film whose reconstruction filter is not `box` (Mitsuba's default, when none is given, is
    `gaussian`): Mitsuba renders with a box filter, and ours is run with `--rfilter box`, so
    both estimate the plain per-pixel mean that the test compares;
  - film parameters of the Mitsuba 0.5 format that Mitsuba 3 rejects (`high_quality_edges`)
    are dropped from Mitsuba's copy (it upgrades the other 0.5 names itself);
  - a per-scene resolution (SCENE_SETTINGS, or --size for all scenes) rewrites the film's
    width and height in both renderers' copies, and a per-scene spp and seed count replace
    the defaults (explicit --spp and --seeds win). living-room (1280x720, `max_depth` 65)
    runs this way at a reduced resolution.

Usage (any CPython 3.11 with the venv module and pip; nothing else needs to be installed):

    python3 experiments/crosscheck_mitsuba.py [SCENE.xml ...] [--spp N] [--seeds K]
        [--block B] [--threads T] [--quick] [--no-build] [--mitsuba-only] [--out DIR]
        [--size WxH] [--no-scene-settings]

Scenes default to experiments/scenes/*.xml, experiments/scenes/features/*.xml and
experiments/scenes/living-room/scene.xml. A scene is named by its file's stem, or by its folder
when the file is `scene.xml` (Bitterli's layout): that name keys SCENE_SETTINGS and the images.
The script makes its own virtual environment in experiments/.venv-mitsuba,
installs the pinned Mitsuba, Dr.Jit, NumPy and SciPy there if they are missing, and re-runs
itself inside it. It builds the binary with `cargo build --release` unless --no-build or
--mitsuba-only. It prints a Markdown table and writes it with a JSON report to
reports/crosscheck/ (crosscheck.md, crosscheck.json, and the seed-averaged images of each
renderer under images/).

Exit status: 0 when no scene shows bias, 1 when any scene does, 2 when a scene could not be
rendered or compared (and none showed bias), 3 when the build or the environment failed. A
scene that one renderer cannot render (for ours: a plugin it does not read yet, exit 2) is
reported as "could not be rendered" with the renderer's message, and the run goes on.
"""

import argparse
import datetime
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
import venv
import xml.etree.ElementTree as ET
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
# Fewest seeds a run may use. A block's variance over K seeds has K - 1 degrees of freedom: with
# K = 2 it falls below a hundredth of its expectation 8% of the time, and where the true spread is
# small (high spp) such a block passes for noise-free and its noise difference rejects. Seen on
# 2026-12-06: speed/ball.xml at 1024 spp, 2 seeds, 3 of 768 blocks rejected with p = 0 (the
# no-spread rule); the same renderers at 8 seeds, 0 of 768.
MIN_SEEDS = 4
# A block whose two means differ by less than this fraction of the block mean agrees, whatever
# its t statistic: the two renderers' float32 arithmetic differs by about this much on smooth,
# nearly noise-free regions (a sky seen directly: both evaluate the same map through float32
# camera rays, and the seeds' spread there is only the pixel jitter), where the t-test would
# otherwise turn a 0.01% rounding difference into a rejection. It is far below any bias worth
# finding (the smallest we chase is about 0.1%).
PRACTICAL_RTOL = 5e-4

EXIT_OK, EXIT_BIAS, EXIT_ERROR, EXIT_SETUP = 0, 1, 2, 3

# Per-scene settings, keyed by scene name (see scene_name): film size (both renderers), spp and
# seeds, and under "quick" what --quick uses instead. Explicit --spp, --seeds or --size win.
# living-room is 1280x720 with max_depth 65. Mitsuba 3.9.1 scalar_rgb on this machine (two
# cores), 16 spp, box filter: loading 0.5 s of CPU; rendering 2.0 s of CPU per seed at 160x90
# and 7.8 s at 320x180, which is 1.0 s and 3.9 s of wall clock on two idle cores (measured 1.1
# s and 4.5 s), and 4 s and 15 s while the machine was shared with builds (load ~6). So
# --quick (4 seeds x 16 spp at 160x90) costs Mitsuba 5 s idle and ~20 s shared, and the default
# (8 seeds x 64 spp at 320x180) about 2 minutes idle.
SCENE_SETTINGS = {
    "living-room": {
        "width": 320, "height": 180, "spp": 64, "seeds": 8,
        "quick": {"width": 160, "height": 90, "spp": 16, "seeds": 4},
    },
}
# Film parameters of the Mitsuba 0.5 format that Mitsuba 3 rejects as unreferenced; they only
# affect how 0.5 drew its film, so Mitsuba's copy drops them.
MITSUBA3_UNKNOWN_FILM_PARAMS = ("high_quality_edges",)


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
    scenes = sorted(OUR_SCENES.glob("*.xml")) + sorted((OUR_SCENES / "features").glob("*.xml"))
    living_room = OUR_SCENES / "living-room" / "scene.xml"
    if living_room.is_file():
        scenes.append(living_room)
    return scenes


def scene_name(path: Path) -> str:
    """The file's stem, or its folder's name for a `scene.xml` (one folder per scene)."""
    path = path.resolve()
    return path.parent.name if path.name == "scene.xml" else path.stem


def label(path: Path) -> str:
    """The scene's name in the report: its path relative to the repository, so equal file
    names in different folders stay apart."""
    return os.path.relpath(path.resolve(), ROOT)


def shorten(text: str, limit: int = 240) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


# --- scene copies ------------------------------------------------------------------------------

def parse_xml(path: Path):
    """The scene's element tree, comments kept (so a copy differs only where it was changed)."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    return ET.parse(str(path), parser=parser)


# What may stand before the root element: the XML declaration, comments, a doctype, space.
PROLOGUE_ITEM = re.compile(r"\s*(<\?.*?\?>|<!--.*?-->|<!DOCTYPE[^>]*>)\s*", re.S)


def prologue(text: str) -> str:
    """The text before the root element, which ElementTree does not keep."""
    end = 0
    while (m := PROLOGUE_ITEM.match(text, end)) and m.end() > end:
        end = m.end()
    return text[:end]


def film_elements(root) -> list:
    return [film for sensor in root.iter("sensor") for film in sensor.findall("film")]


def set_film_integer(film, name: str, value: int) -> None:
    for child in film:
        if child.tag == "integer" and child.get("name") == name:
            child.set("value", str(value))
            return
    ET.SubElement(film, "integer", {"name": name, "value": str(value)})


def plan_scene(path: Path, size) -> dict:
    """What each renderer needs changed in its copy of the scene. `size` is (width, height) or
    None. Returns {"rfilter": the film's filter type (or "gaussian" when none is given, as
    Mitsuba defaults), "mitsuba": [changes], "ours": [changes], "our_args": [...],
    "notes": [one line per change, for the report]}."""
    root = parse_xml(path).getroot()
    films = film_elements(root)
    plan = {"rfilter": None, "mitsuba": [], "ours": [], "our_args": [], "notes": []}
    if not films:
        return plan
    film = films[0]
    rfilter = film.find("rfilter")
    plan["rfilter"] = "gaussian" if rfilter is None else rfilter.get("type", "?")
    if plan["rfilter"] != "box":
        plan["mitsuba"].append(("rfilter", "box"))
        plan["our_args"] = ["--rfilter", "box"]
        given = "no rfilter (Mitsuba's default: gaussian)" if rfilter is None else \
            f"rfilter {plan['rfilter']}"
        plan["notes"].append(f"{given} -> box: Mitsuba renders a copy with a box filter, "
                             f"ours runs with --rfilter box")
    dropped = [c.get("name") for c in film if c.get("name") in MITSUBA3_UNKNOWN_FILM_PARAMS]
    for name in dropped:
        plan["mitsuba"].append(("drop", name))
        plan["notes"].append(f"film parameter {name} (Mitsuba 0.5) dropped from Mitsuba's "
                             f"copy: Mitsuba 3 rejects it")
    if size is not None:
        def current(name):
            for c in film:
                if c.tag == "integer" and c.get("name") == name:
                    return c.get("value")
            return "default"
        was = f"{current('width')}x{current('height')}"
        if was != f"{size[0]}x{size[1]}":
            for who in ("mitsuba", "ours"):
                plan[who].append(("size", size))
            plan["notes"].append(f"film {was} -> {size[0]}x{size[1]} in both renderers' copies")
    return plan


def remove_keeping_lines(parent, child) -> None:
    """Removes `child`, moving its tail (the newline after it) to what precedes it, so that the
    copy's line numbers, which the renderers' messages cite, stay those of the original."""
    children = list(parent)
    i = children.index(child)
    tail = child.tail or ""
    if i > 0:
        children[i - 1].tail = (children[i - 1].tail or "") + tail
    else:
        parent.text = (parent.text or "") + tail
    parent.remove(child)


def write_scene_copy(path: Path, changes: list, who: str) -> Path:
    """Writes the scene with `changes` applied next to the original, under a hidden temporary
    name (relative paths to meshes and textures still resolve), line for line as the original
    where nothing changed; the caller removes it."""
    tree = parse_xml(path)
    for film in film_elements(tree.getroot()):
        for kind, value in changes:
            if kind == "rfilter":
                old = film.findall("rfilter")
                new = ET.Element("rfilter", {"type": value})
                if old:
                    new.tail = old[0].tail  # the new element takes the old one's line
                    film.insert(list(film).index(old[0]), new)
                    film.remove(old[0])
                    for element in old[1:]:
                        remove_keeping_lines(film, element)
                else:
                    film.append(new)
            elif kind == "drop":
                for child in [c for c in film if c.get("name") == value]:
                    remove_keeping_lines(film, child)
            elif kind == "size":
                set_film_integer(film, "width", value[0])
                set_film_integer(film, "height", value[1])
    head = prologue(path.read_text(encoding="utf-8", errors="replace"))
    # The copy is written as UTF-8 whatever the original declared; the declaration says so.
    head = re.sub(r"<\?xml.*?\?>", '<?xml version="1.0" encoding="utf-8"?>', head, count=1,
                  flags=re.S)
    body = ET.tostring(tree.getroot(), encoding="unicode")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.crosscheck-", suffix=f".{who}.xml",
                               dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(head + body + "\n")
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return Path(tmp)


def unmask(text: str, copy: Path, original: Path) -> str:
    """A message about a scene copy, naming the original file instead of the copy."""
    if copy == original:
        return text
    for form in (str(copy.resolve()), str(copy), copy.name):
        text = text.replace(form, f"{original.name} (copy)" if form == copy.name
                            else f"{original} (copy)")
    return text


def scene_run_settings(path: Path, args) -> dict:
    """spp, seeds and film size (or None: the scene's own) for one scene."""
    table = {} if args.no_scene_settings else dict(SCENE_SETTINGS.get(scene_name(path), {}))
    if args.quick:
        table.update(table.pop("quick", {}))
    else:
        table.pop("quick", None)
    size = args.size or ((table["width"], table["height"]) if "width" in table else None)
    return {
        "spp": args.spp or table.get("spp") or (QUICK_SPP if args.quick else DEFAULT_SPP),
        "seeds": args.seeds or table.get("seeds") or (QUICK_SEEDS if args.quick
                                                      else DEFAULT_SEEDS),
        "size": size,
    }


def rgb(array):
    """Float64 (height, width, 3) from an image array: alpha dropped, grey broadcast."""
    import numpy as np

    a = np.asarray(array, dtype=np.float64)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return a[:, :, :3]


def load_mitsuba(path: Path):
    """Loads the scene into Mitsuba; returns it and the load time."""
    import mitsuba as mi

    start = time.perf_counter()
    scene = mi.load_file(str(path))
    return scene, time.perf_counter() - start


def render_mitsuba(scene, spp: int, seed: int):
    """One render of a loaded scene: its RGB image and the `mi.render` call's seconds."""
    import mitsuba as mi
    import numpy as np

    start = time.perf_counter()
    result = mi.render(scene, spp=spp, seed=seed)
    elapsed = time.perf_counter() - start
    return rgb(np.array(result)), elapsed


def gather(images: list, seconds: list, spp: int, **extra) -> dict:
    """The seeds' images stacked, with the summed render time as samples per second."""
    import numpy as np

    height, width = images[0].shape[:2]
    return {
        "images": np.stack(images),
        "seconds": seconds,
        "samples_per_s": width * height * spp * len(images) / sum(seconds),
        **extra,
    }


class RenderFailed(RuntimeError):
    """Our renderer exited non-zero or wrote no result; `brief` is the gist for the table."""

    def __init__(self, message: str, brief: str):
        super().__init__(message)
        self.brief = brief


def render_ours(binary: Path, path: Path, spp: int, seed: int, threads: int,
                extra_args: list = ()) -> dict:
    """Runs `fireflies render` once; returns its image and what its `render.json` reports."""
    import mitsuba as mi
    import numpy as np

    with tempfile.TemporaryDirectory(prefix="fireflies-crosscheck-") as out:
        cmd = [str(binary), "render", str(path), "--spp", str(spp), "--seed", str(seed),
               "--estimators", "mean", "--threads", str(threads), "--out", out,
               *extra_args]
        done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              text=True)
        if done.returncode != 0:
            lines = [ln for ln in done.stderr.strip().splitlines() if ln.strip()]
            gist = lines[0] if lines else "(no message)"
            raise RenderFailed(f"{' '.join(cmd)} exited {done.returncode}:\n"
                               f"{done.stderr.strip()}",
                               f"exit {done.returncode}: {shorten(gist)}")
        exr = Path(out) / "mean.exr"
        manifest = Path(out) / "render.json"
        for needed in (exr, manifest):
            if not needed.exists():
                raise RenderFailed(f"{' '.join(cmd)} wrote no {needed.name}",
                                   f"wrote no {needed.name}")
        info = json.loads(manifest.read_text())
        return {
            "image": rgb(np.array(mi.Bitmap(str(exr)))),
            # `render_s` since 2026-12-07; older binaries (`--binary`) report `wall_s` only.
            "seconds": float(info.get("render_s", info["wall_s"])),
            "build_s": float(info.get("build_s", 0.0)),
            "load_s": float(info.get("load_s", 0.0)),
            "reported_samples_per_s": float(info["samples_per_s"]),
            "invalid_samples": int(info.get("invalid_samples", 0)),
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
    negligible = np.abs(mean_a - mean_b) <= PRACTICAL_RTOL * scale + DEGENERATE_ATOL
    p = np.where(negligible, 1.0, p)
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
        f"seeds 0..K-1 (K per scene), {settings['block']}x{settings['block']}-pixel "
        f"blocks. Welch's t-test per block and channel (Jung, Hanika and Dachsbacher, JCGT "
        f"2020) at family alpha = {FAMILY_ALPHA} per scene, Sidak-corrected; without bias "
        f"about {FAMILY_ALPHA * 100:g}% of scenes show one rejecting test by chance, and a "
        f"single rejecting scene fails the check. Samples/s = width x height x spp / wall-clock "
        f"seconds of the render (Mitsuba: the `mi.render` call; ours: `render_s`, the render after the scene is built).",
        "",
        "| scene | size | spp | seeds | blocks rejecting / tests | mean rel. diff ± SE "
        "| Mitsuba Msamples/s | ours Msamples/s | ratio | verdict |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    notes = []
    for r in rows:
        ours = r.get("ours") or {}
        welch = r.get("welch")
        diff = r.get("difference")
        mits = r.get("mitsuba") or {}
        ratio = r.get("speed_ratio")
        size = r.get("size") or r.get("size_override")
        lines.append("| " + " | ".join([
            f"`{r['scene']}`",
            f"{size[0]}x{size[1]}" if size else "—",
            str(r["spp"]),
            str(r["seeds"]),
            f"{welch['rejecting']} / {welch['tests']}" if welch else "—",
            f"{diff['rel_diff']:+.2%} ± {diff['se']:.2%}" if diff else "—",
            fmt_rate(mits.get("samples_per_s")),
            fmt_rate(ours.get("samples_per_s")),
            f"{ratio:.2f}" if ratio is not None else "—",
            r["verdict"],
        ]) + " |")
        for override in r.get("overrides") or []:
            notes.append(f"- `{r['scene']}`: {override}.")
        if r.get("error"):
            notes.append(f"- `{r['scene']}`: {r['verdict']}: "
                         f"{r.get('error_brief') or shorten(r['error'])}")
    if notes:
        lines += ["", "Overrides and errors (full messages in crosscheck.json):", "", *notes]
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


def crosscheck(path: Path, args, row: dict) -> dict:
    """Renders one scene with both renderers (each on its own copy when the plan changes it)
    and fills in `row`; the copies are removed whatever happens."""
    copies = []
    try:
        plan = plan_scene(path, row["size_override"])
        row["rfilter"] = plan["rfilter"]
        row["overrides"] = plan["notes"]
        for note in plan["notes"]:
            print(f"{row['scene']}: {note}", file=sys.stderr)
        mitsuba_path = ours_path = path
        if plan["mitsuba"]:
            mitsuba_path = write_scene_copy(path, plan["mitsuba"], "mitsuba")
            copies.append(mitsuba_path)
        if plan["ours"] and not args.mitsuba_only:
            ours_path = write_scene_copy(path, plan["ours"], "ours")
            copies.append(ours_path)
        return compare(path, mitsuba_path, ours_path, plan["our_args"], args, row)
    finally:
        for copy in copies:
            copy.unlink(missing_ok=True)


def compare(path: Path, mitsuba_path: Path, ours_path: Path, our_args: list, args,
            row: dict) -> dict:
    import numpy as np

    spp, seeds = row["spp"], list(range(row["seeds"]))
    # The renderers take turns, seed by seed, so that a change in the machine's speed during
    # the run (this project's VM drifted by 25% within minutes) falls on both alike.
    both = not args.mitsuba_only
    who = "Mitsuba and fireflies in turn" if both else "Mitsuba"
    print(f"{row['scene']}: {who}, {len(seeds)} x {spp} spp", file=sys.stderr)
    m_images, m_seconds, runs, ours_error = [], [], [], None
    try:
        scene, load_s = load_mitsuba(mitsuba_path)
        for seed in seeds:
            image, elapsed = render_mitsuba(scene, spp, seed)
            m_images.append(image)
            m_seconds.append(elapsed)
            if both and ours_error is None:
                try:
                    runs.append(render_ours(args.binary, ours_path, spp, seed, args.threads,
                                            our_args))
                except (RuntimeError, OSError, ValueError, KeyError) as e:
                    ours_error = e
    except Exception as e:  # a scene Mitsuba cannot load must not hide the others
        message = unmask(f"{type(e).__name__}: {e}", mitsuba_path, path)
        row["error"] = message
        row["verdict"] = "could not be rendered (Mitsuba)"
        row["error_brief"] = shorten(message)
        print(f"  {message}", file=sys.stderr)
        return row
    mits = gather(m_images, m_seconds, spp, load_s=load_s)
    height, width = mits["images"].shape[1:3]
    row["size"] = [int(width), int(height)]
    row["mitsuba"] = {"samples_per_s": mits["samples_per_s"], "seconds": mits["seconds"],
                      "load_s": mits["load_s"]}
    print(f"  Mitsuba: load {mits['load_s']:.2f} s, render "
          f"{', '.join(f'{t:.2f}' for t in mits['seconds'])} s", file=sys.stderr)
    stem = label(path).replace("/", "_").replace(".._", "").removesuffix(".xml")
    images = args.out / "images"
    write_image_atomic(images / f"{stem}.mitsuba.exr", mits["images"].mean(axis=0))
    if not both:
        row["verdict"] = "Mitsuba only"
        return row
    if ours_error is not None:
        message = unmask(str(ours_error), ours_path, path)
        row["error"] = message
        row["error_brief"] = shorten(unmask(getattr(ours_error, "brief", message), ours_path,
                                            path))
        row["verdict"] = "could not be rendered (ours)"
        print(f"  {message}", file=sys.stderr)
        return row
    ours = gather([r["image"] for r in runs], [r["seconds"] for r in runs], spp,
                  **{k: [r[k] for r in runs]
                     for k in ("reported_samples_per_s", "load_s", "build_s")},
                  invalid_samples=sum(r["invalid_samples"] for r in runs))
    row["ours"] = {k: ours[k] for k in
                   ("samples_per_s", "seconds", "reported_samples_per_s", "invalid_samples",
                    "load_s", "build_s")}
    print(f"  ours: load {min(ours['load_s']):.2f} s + build {min(ours['build_s']):.2f} s, "
          f"render {', '.join(f'{t:.2f}' for t in ours['seconds'])} s", file=sys.stderr)
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


def parse_size(text: str):
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 160x90, got {text!r}")
    if width < 1 or height < 1:
        raise argparse.ArgumentTypeError(f"size must be positive, got {text!r}")
    return (width, height)


def main() -> None:
    global FAMILY_ALPHA
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene_args", nargs="*", metavar="SCENE", type=Path,
                        help="scene files (default: experiments/scenes/*.xml, "
                             "experiments/scenes/features/*.xml and "
                             "experiments/scenes/living-room/scene.xml)")
    parser.add_argument("--scenes", nargs="+", type=Path, default=[], metavar="SCENE",
                        help="scene files, as the positional arguments")
    parser.add_argument("--spp", type=int, help=f"samples per pixel, all scenes (default "
                                                f"{DEFAULT_SPP}, {QUICK_SPP} with --quick, "
                                                f"or the scene's SCENE_SETTINGS)")
    parser.add_argument("--seeds", type=int, help=f"independent renders per renderer, all "
                                                  f"scenes (default {DEFAULT_SEEDS}, "
                                                  f"{QUICK_SEEDS} with --quick, or the "
                                                  f"scene's SCENE_SETTINGS)")
    parser.add_argument("--size", type=parse_size, metavar="WxH",
                        help="film size for every scene, written into both renderers' copies "
                             "(default: the scene's own, or its SCENE_SETTINGS)")
    parser.add_argument("--no-scene-settings", action="store_true",
                        help="ignore SCENE_SETTINGS (render e.g. living-room at full size)")
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
    if (args.spp is not None and args.spp < 1) or args.block < 1 or args.threads < 1:
        parser.error("--spp, --block and --threads must be positive")
    if args.seeds is not None and args.seeds < MIN_SEEDS:
        parser.error(f"--seeds must be at least {MIN_SEEDS}: with fewer, a block's variance "
                     f"over seeds is often near zero by chance, and the no-spread rule "
                     f"(DEGENERATE_RTOL) then rejects a difference that is only noise")
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

    rows = []
    with tempfile.TemporaryDirectory(prefix="fireflies-crosscheck-bin-") as bindir:
        if not args.mitsuba_only:
            # Run a private copy: a `cargo build` during the run then neither removes the
            # binary under us nor mixes two versions in one report.
            original, args.binary = args.binary, Path(bindir) / args.binary.name
            shutil.copy2(original, args.binary)
        for path in scenes:
            run = scene_run_settings(path, args)
            row = {"scene": label(path), "name": scene_name(path), "path": str(path),
                   "spp": run["spp"], "seeds": run["seeds"],
                   "size_override": list(run["size"]) if run["size"] else None}
            try:
                rows.append(crosscheck(path, args, row))
            except Exception as e:  # e.g. XML we cannot parse: must not hide the others
                row["error"] = f"{type(e).__name__}: {e}"
                row["error_brief"] = shorten(row["error"])
                row["verdict"] = "could not be rendered (scene)"
                rows.append(row)
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
        "spp": args.spp,  # None: per scene (see each scene's spp and seeds)
        "seeds": args.seeds,
        "quick": args.quick,
        "size": list(args.size) if args.size else None,
        "scene_settings": None if args.no_scene_settings else SCENE_SETTINGS,
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
