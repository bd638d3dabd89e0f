"""Reference values of Mitsuba 3.9.1's Fresnel helpers (scalar_rgb) for
`src/render/bsdfs/fresnel.rs`.

Run from the repository root with the Mitsuba venv:

    experiments/.venv-mitsuba/bin/python tests/data/fresnel/make_fixture.py

Writes, in this directory:

* `dielectric.csv` — `cos_theta_i,eta,f,cos_theta_t,eta_it,eta_ti` from `mi.fresnel`, both sides
  of the interface, `eta` above and below 1, index-matched, grazing and total internal reflection;
* `conductor.csv` — `cos_theta_i,eta,k,f` from `mi.fresnel_conductor(cos, mi.Complex2f(eta, k))`,
  including Mitsuba's `none` material (eta 0, k 1);
* `diffuse.csv` — `eta,fdr` from `mi.fresnel_diffuse_reflectance`.

All inputs are exactly representable in f32 (they are rounded before being passed to Mitsuba and
written as the rounded value).
"""

import csv
import os

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")

HERE = os.path.dirname(os.path.abspath(__file__))


def f32(x):
    return float(np.float32(x))


def write(name, header, rows):
    with open(os.path.join(HERE, name), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for r in rows:
            w.writerow([repr(float(x)) for x in r])
    print(f"{name}: {len(rows)} rows")


COS = [1.0, 0.99, 0.9, 0.7, 0.5, 0.3, 0.1, 0.02, 1e-3, 0.0]

rows = []
for eta in [1.5046, 1.33, 1.0, 1 / 1.5046, 2.419, 1.000277, 0.5]:
    for c in COS:
        for sign in [1.0, -1.0]:
            ci, e = f32(sign * c), f32(eta)
            r = mi.fresnel(ci, e)
            rows.append([ci, e] + [float(x) for x in r])
write("dielectric.csv", ["cos_theta_i", "eta", "f", "cos_theta_t", "eta_it", "eta_ti"], rows)

rows = []
# (eta, k) pairs: none material, Au/Cu/Al-like values, dielectric-like (k = 0), large k.
PAIRS = [(0.0, 1.0), (0.143, 3.983), (0.2, 2.4), (1.44, 1.6), (1.5, 0.0), (1.1, 7.0), (0.05, 0.5)]
for eta, k in PAIRS:
    for c in COS:
        ci, e, kk = f32(c), f32(eta), f32(k)
        rows.append([ci, e, kk, mi.fresnel_conductor(ci, mi.Complex2f(e, kk))])
write("conductor.csv", ["cos_theta_i", "eta", "k", "f"], rows)

rows = []
for eta in [0.3, 0.5, 1 / 1.5046, 1 / 1.49, 0.9, 0.999, 1.0, 1.001, 1.2, 1.33, 1.49, 1.5046, 2.0,
            2.419, 5.0, 10.0]:
    e = f32(eta)
    rows.append([e, mi.fresnel_diffuse_reflectance(e)])
write("diffuse.csv", ["eta", "fdr"], rows)
