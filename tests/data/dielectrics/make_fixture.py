"""Reference values of Mitsuba 3.9.1's `roughdielectric` and `thindielectric` (scalar_rgb) for
`tests/render_dielectrics.rs`.

Run from the repository root with the Mitsuba venv:

    experiments/.venv-mitsuba/bin/python tests/data/dielectrics/make_fixture.py

Writes, in this directory:

* `rough_eval.csv` — `config,wi(3),wo(3),value(3),pdf` from `bsdf.eval` / `bsdf.pdf`, for the
  configurations in `CONFIGS` (both distributions, indices above and below 1, Mitsuba's default
  indices, tinted and untinted), `wi` outside and inside (normal to 89.5 degrees), `wo` in the
  reflection and transmission half-spaces: random directions, directions near the specular
  reflection and refraction, and near-grazing ones;
* `rough_sample.csv` — `config,wi(3),u_lobe,u1,u2,wo(3),weight(3),pdf,eta` from `bsdf.sample`
  (a zero weight means Mitsuba's sample is invalid);
* `thin_sample.csv` — `int_ior,ext_ior,tinted,wi(3),u_lobe,wo(3),weight(3),pdf,eta` from
  `thindielectric`'s `bsdf.sample` (its `pdf` is the discrete probability of the chosen lobe).

Every input is an f32 value, written with enough digits to round-trip. The tints, where used, are
`specular_reflectance = (0.9, 0.5, 0.2)` and `specular_transmittance = (0.3, 0.6, 0.8)`.
"""

import csv
import os

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")

HERE = os.path.dirname(os.path.abspath(__file__))

REFLECT_TINT = [0.9, 0.5, 0.2]
TRANSMIT_TINT = [0.3, 0.6, 0.8]

# name, distribution, alpha, int_ior (None: Mitsuba's default bk7), ext_ior (None: air), tinted
CONFIGS = [
    ("beckmann_default", "beckmann", None, None, None, False),
    ("beckmann_0.3_1.5", "beckmann", 0.3, 1.5, 1.0, True),
    ("beckmann_0.05_2.4", "beckmann", 0.05, 2.4, 1.0, False),
    ("ggx_0.1_1.5", "ggx", 0.1, 1.5, 1.0, False),
    ("ggx_0.3_1.33", "ggx", 0.3, 1.33, 1.0, True),
    ("ggx_0.5_inverted", "ggx", 0.5, 1.0, 1.5, False),
]


def f32(x):
    return float(np.float32(x))


def fmt(x):
    return repr(float(np.float32(x)))


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    v = v / np.linalg.norm(v)
    return [f32(c) for c in v]


def make_bsdf(dist, alpha, int_ior, ext_ior, tinted):
    d = {"type": "roughdielectric", "distribution": dist}
    if alpha is not None:
        d["alpha"] = alpha
    if int_ior is not None:
        d["int_ior"] = int_ior
    if ext_ior is not None:
        d["ext_ior"] = ext_ior
    if tinted:
        d["specular_reflectance"] = {"type": "rgb", "value": REFLECT_TINT}
        d["specular_transmittance"] = {"type": "rgb", "value": TRANSMIT_TINT}
    return mi.load_dict(d)


def directions_for(wi, eta, rng):
    """Outgoing directions to evaluate for incident `wi` (eta = int/ext)."""
    wi = np.asarray(wi, dtype=np.float64)
    out = []
    # Uniform random directions.
    for _ in range(6):
        out.append(unit(rng.normal(size=3)))
    # Around the specular reflection.
    refl = np.array([-wi[0], -wi[1], wi[2]])
    for _ in range(3):
        out.append(unit(refl + 0.15 * rng.normal(size=3)))
    # Around the specular refraction (if any).
    e = eta if wi[2] > 0 else 1.0 / eta
    sin2_t = (1.0 - wi[2] ** 2) / (e * e)
    if sin2_t < 1.0:
        cos_t = np.sqrt(1.0 - sin2_t)
        refr = np.array([-wi[0] / e, -wi[1] / e, -np.sign(wi[2]) * cos_t])
        for _ in range(4):
            out.append(unit(refr + 0.15 * rng.normal(size=3)))
    # Near-grazing on both sides.
    for z in [0.02, -0.02]:
        phi = rng.uniform(0, 2 * np.pi)
        s = np.sqrt(1 - z * z)
        out.append(unit([s * np.cos(phi), s * np.sin(phi), z]))
    return out


def incident_directions():
    out = []
    for deg in [0.0, 30.0, 60.0, 85.0, 89.5]:
        t = np.radians(deg)
        w = unit([np.sin(t) * np.cos(0.7), np.sin(t) * np.sin(0.7), np.cos(t)])
        out.append(w)
        out.append([w[0], w[1], -w[2]])
    return out


def main():
    rng = np.random.default_rng(20240531)
    ctx = mi.BSDFContext()
    eval_rows, sample_rows = [], []
    for name, dist, alpha, int_ior, ext_ior, tinted in CONFIGS:
        bsdf = make_bsdf(dist, alpha, int_ior, ext_ior, tinted)
        eta = (int_ior or 1.5046) / (ext_ior or 1.000277)
        for wi in incident_directions():
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wi)
            for wo in directions_for(wi, eta, rng):
                value = bsdf.eval(ctx, si, mi.Vector3f(*wo))
                pdf = bsdf.pdf(ctx, si, mi.Vector3f(*wo))
                eval_rows.append([name] + [fmt(c) for c in wi + wo]
                                 + [fmt(value[i]) for i in range(3)] + [fmt(pdf)])
            for _ in range(6):
                u = [f32(rng.uniform()) for _ in range(3)]
                bs, w = bsdf.sample(ctx, si, u[0], mi.Point2f(u[1], u[2]))
                sample_rows.append([name] + [fmt(c) for c in wi + u]
                                   + [fmt(bs.wo[i]) for i in range(3)]
                                   + [fmt(w[i]) for i in range(3)] + [fmt(bs.pdf), fmt(bs.eta)])
    with open(os.path.join(HERE, "rough_eval.csv"), "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["config", "wix", "wiy", "wiz", "wox", "woy", "woz", "r", "g", "b", "pdf"])
        wr.writerows(eval_rows)
    with open(os.path.join(HERE, "rough_sample.csv"), "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["config", "wix", "wiy", "wiz", "u_lobe", "u1", "u2", "wox", "woy", "woz",
                     "r", "g", "b", "pdf", "eta"])
        wr.writerows(sample_rows)

    thin_rows = []
    for int_ior, ext_ior, tinted in [(1.5, 1.0, False), (3.0, 1.0, True), (1.0, 1.33, False),
                                     (None, None, False)]:
        d = {"type": "thindielectric"}
        if int_ior is not None:
            d["int_ior"] = int_ior
            d["ext_ior"] = ext_ior
        if tinted:
            d["specular_reflectance"] = {"type": "rgb", "value": REFLECT_TINT}
            d["specular_transmittance"] = {"type": "rgb", "value": TRANSMIT_TINT}
        bsdf = mi.load_dict(d)
        for wi in incident_directions():
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wi)
            for u_lobe in [0.0, 0.05, 0.3, 0.9]:
                bs, w = bsdf.sample(ctx, si, u_lobe, mi.Point2f(0.5, 0.5))
                thin_rows.append([fmt(int_ior or 1.5046), fmt(ext_ior or 1.000277), int(tinted)]
                                 + [fmt(c) for c in wi] + [fmt(u_lobe)]
                                 + [fmt(bs.wo[i]) for i in range(3)]
                                 + [fmt(w[i]) for i in range(3)] + [fmt(bs.pdf), fmt(bs.eta)])
    with open(os.path.join(HERE, "thin_sample.csv"), "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["int_ior", "ext_ior", "tinted", "wix", "wiy", "wiz", "u_lobe", "wox", "woy",
                     "woz", "r", "g", "b", "pdf", "eta"])
        wr.writerows(thin_rows)
    print(len(eval_rows), "eval rows,", len(sample_rows), "sample rows,", len(thin_rows),
          "thin rows")


if __name__ == "__main__":
    main()
