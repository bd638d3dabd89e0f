"""The named indices of refraction Mitsuba 3.9.1 (scalar_rgb) accepts, as it actually uses them,
for `src/render/bsdfs/ior.rs`.

Run from the repository root with the Mitsuba venv:

    experiments/.venv-mitsuba/bin/python tests/data/ior/extract_ior.py

Writes, in this directory:

* `dielectric.csv` — `name,ior`: every name of Mitsuba's `ior_data` table
  (`include/mitsuba/render/ior.h`, shipped with the wheel), each read back through a `dielectric`
  plugin built with `int_ior=<name>, ext_ior=1` (`mi.traverse` exposes `eta = int_ior/ext_ior`).
  The list of names is the table itself: we parse it from the installed header, and check that
  Mitsuba rejects a name outside it.
* `conductor.csv` — `name,eta_r,eta_g,eta_b,k_r,k_g,k_b`: every conductor `material` preset.
  Mitsuba resolves `material=<name>` to the files `data/ior/<name>.eta.spd` and
  `data/ior/<name>.k.spd` (case-sensitive file names) and converts each spectrum to linear sRGB
  once at load time; `none` (the default) is eta 0, k 1. For every name we instantiate
  `{'type': 'conductor', 'material': name}` and read `eta.value` / `k.value` from
  `mi.traverse(bsdf)`. To confirm those are the values rendering uses, we also sample the
  conductor at cos(theta_i) = 0.6 and check that the sample weight equals
  `mi.fresnel_conductor(0.6, eta + i k)` per channel.

Values are written as the shortest decimal that round-trips the f32 Mitsuba stores.
"""

import csv
import os
import re

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")

HERE = os.path.dirname(os.path.abspath(__file__))
PKG = os.path.dirname(mi.__file__)


def rgb(v):
    """A traversed texture value as three floats (`none` stores uniform scalars)."""
    try:
        return [float(x) for x in v]
    except TypeError:
        return [float(v)] * 3


def f32s(x):
    return repr(np.float32(x)).replace("np.float32(", "").rstrip(")")


# --- dielectrics -------------------------------------------------------------------------------
header = open(os.path.join(PKG, "include", "mitsuba", "render", "ior.h")).read()
table = header[header.index("ior_data[]"):header.index("nullptr")]
names = re.findall(r'\{\s*"([^"]+)"\s*,', table)
rows = []
for name in names:
    b = mi.load_dict({"type": "dielectric", "int_ior": name, "ext_ior": 1.0})
    rows.append([name, f32s(mi.traverse(b)["eta"])])
try:
    mi.load_dict({"type": "dielectric", "int_ior": "not-a-material"})
    raise SystemExit("Mitsuba accepted an unknown IOR name")
except RuntimeError:
    pass
# Lookup is case-insensitive (Mitsuba lower-cases the name).
assert mi.traverse(mi.load_dict({"type": "dielectric", "int_ior": "BK7", "ext_ior": 1.0}))["eta"] \
    == mi.traverse(mi.load_dict({"type": "dielectric", "int_ior": "bk7", "ext_ior": 1.0}))["eta"]
with open(os.path.join(HERE, "dielectric.csv"), "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["name", "ior"])
    w.writerows(rows)
print(f"dielectric.csv: {len(rows)} names")

# --- conductors --------------------------------------------------------------------------------
ior_dir = os.path.join(PKG, "data", "ior")
eta_files = {f[: -len(".eta.spd")] for f in os.listdir(ior_dir) if f.endswith(".eta.spd")}
k_files = {f[: -len(".k.spd")] for f in os.listdir(ior_dir) if f.endswith(".k.spd")}
assert eta_files == k_files, eta_files ^ k_files
materials = ["none"] + sorted(eta_files)

ctx = mi.BSDFContext()
si = mi.SurfaceInteraction3f()
cos_i = 0.6
si.wi = mi.Vector3f(0.8, 0.0, cos_i)
rows = []
for name in materials:
    b = mi.load_dict({"type": "conductor", "material": name})
    p = mi.traverse(b)
    eta, k = rgb(p["eta.value"]), rgb(p["k.value"])
    _, weight = b.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5))
    for c in range(3):
        expect = mi.fresnel_conductor(mi.Float(cos_i), mi.Complex2f(eta[c], k[c]))
        assert abs(weight[c] - expect) <= 1e-6 * max(1.0, abs(expect)), (name, c, weight, expect)
    rows.append([name] + [f32s(x) for x in eta + k])
try:
    mi.load_dict({"type": "conductor", "material": "au"})
    raise SystemExit("Mitsuba accepted a lower-case material name")
except RuntimeError:
    pass
with open(os.path.join(HERE, "conductor.csv"), "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["name", "eta_r", "eta_g", "eta_b", "k_r", "k_g", "k_b"])
    w.writerows(rows)
print(f"conductor.csv: {len(rows)} materials")
