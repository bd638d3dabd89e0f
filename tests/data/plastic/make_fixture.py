"""Writes tests/data/plastic/plastic.csv: Mitsuba 3.9.1 (scalar_rgb) `plastic` and
`roughplastic` values for tests/render_plastic.rs.

    /work/main/experiments/.venv-mitsuba/bin/python tests/data/plastic/make_fixture.py

Each material is built with `mi.load_dict` from the parameters in its row. Rows of kind `eval`
hold `bsdf.eval` (RGB, cosine included), `bsdf.pdf` and `bsdf.eval_pdf` at (wi, wo); rows of
kind `sample` hold `bsdf.sample(ctx, si, u_lobe, (u1, u2))`: the direction, Mitsuba's pdf and
the weight. Directions run from normal incidence to grazing (cos 1e-3), near the mirror
direction (where the specular lobe dominates), far from it, and below the horizon.
"""
import csv
import math
from pathlib import Path

import mitsuba as mi

mi.set_variant("scalar_rgb")

# (plugin, distribution, alpha, int_ior, ext_ior, nonlinear, specular (None = not given),
#  diffuse rgb, sample_visible)
CONFIGS = [
    ("plastic", "", 0.0, 1.49, 1.000277, False, None, (0.5, 0.5, 0.5), True),
    ("plastic", "", 0.0, 1.5, 1.0, True, 0.6, (0.8, 0.25, 0.1), True),
    ("plastic", "", 0.0, 1.0, 1.33, False, None, (0.2, 0.45, 0.75), True),
    ("roughplastic", "ggx", 0.3, 1.5, 1.000277, False, None, (0.8, 0.4, 0.1), True),
    ("roughplastic", "ggx", 0.05, 1.5, 1.0, True, None, (0.2, 0.45, 0.75), True),
    ("roughplastic", "ggx", 0.2, 1.5, 1.0, True, 0.7, (0.8, 0.8, 0.8), True),
    ("roughplastic", "ggx", 0.4, 1.0, 1.33, False, None, (0.3, 0.6, 0.2), True),
    ("roughplastic", "ggx", 0.3, 1.5, 1.0, False, None, (0.8, 0.4, 0.1), False),
    ("roughplastic", "beckmann", 0.1, 1.49, 1.000277, False, None, (0.5, 0.5, 0.5), True),
    ("roughplastic", "beckmann", 0.3, 1.5, 1.0, True, None, (0.2, 0.45, 0.75), True),
    ("roughplastic", "beckmann", 0.02, 1.7, 1.0, False, 0.5, (0.9, 0.1, 0.4), True),
    ("roughplastic", "beckmann", 0.5, 1.0, 1.5, True, None, (0.6, 0.6, 0.3), True),
]


def direction(cos_theta, phi):
    s = math.sqrt(max(0.0, 1.0 - cos_theta * cos_theta))
    return (s * math.cos(phi), s * math.sin(phi), cos_theta)


def pairs():
    """(wi, wo) pairs: near-mirror, off-mirror, grazing, and below the horizon."""
    out = []
    for ci in [1.0, 0.9, 0.6, 0.3, 0.05, 1e-3]:
        wi = direction(ci, 0.4)
        mirror = (-wi[0], -wi[1], wi[2])
        out.append((wi, mirror))
        for co, dphi in [(ci, 0.1), (min(1.0, ci + 0.05), 0.05), (0.8, 1.7), (0.5, math.pi),
                         (0.02, 2.5), (1e-3, 0.4 + math.pi)]:
            out.append((wi, direction(co, 0.4 + math.pi + dphi)))
    out.append((direction(0.7, 0.2), direction(-0.3, 1.0)))
    out.append((direction(-0.5, 0.2), direction(0.6, 2.0)))
    return out


SAMPLES = [(c, ul, (u1, u2)) for c in [0.95, 0.5, 0.1]
           for ul in [0.02, 0.3, 0.97] for (u1, u2) in [(0.3, 0.8), (0.71, 0.15), (0.5, 0.5)]]


def load(cfg):
    plugin, dist, alpha, int_ior, ext_ior, nonlinear, spec, diff, visible = cfg
    d = {"type": plugin, "int_ior": int_ior, "ext_ior": ext_ior, "nonlinear": nonlinear,
         "diffuse_reflectance": {"type": "rgb", "value": list(diff)}}
    if spec is not None:
        d["specular_reflectance"] = spec
    if plugin == "roughplastic":
        d.update(distribution=dist, alpha=alpha, sample_visible=visible)
    return mi.load_dict(d)


def main():
    path = Path(__file__).with_name("plastic.csv")
    ctx = mi.BSDFContext()
    with path.open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["kind", "plugin", "distribution", "alpha", "int_ior", "ext_ior", "nonlinear",
                    "specular", "dr", "dg", "db", "sample_visible",
                    "wix", "wiy", "wiz", "a", "b", "c",
                    "r", "g", "bl", "pdf", "ep_r", "ep_g", "ep_b", "ep_pdf"])
        for cfg in CONFIGS:
            bsdf = load(cfg)
            head = [cfg[0], cfg[1], cfg[2], cfg[3], cfg[4], int(cfg[5]),
                    -1 if cfg[6] is None else cfg[6], *cfg[7], int(cfg[8])]
            for wi, wo in pairs():
                si = mi.SurfaceInteraction3f()
                si.wi = mi.Vector3f(*wi)
                v = bsdf.eval(ctx, si, mi.Vector3f(*wo))
                p = bsdf.pdf(ctx, si, mi.Vector3f(*wo))
                ev, ep = bsdf.eval_pdf(ctx, si, mi.Vector3f(*wo))
                w.writerow(["eval", *head, *map(repr, wi), *map(repr, wo),
                            *map(float, v), float(p), *map(float, ev), float(ep)])
            for c, ul, u in SAMPLES:
                wi = direction(c, 1.1)
                si = mi.SurfaceInteraction3f()
                si.wi = mi.Vector3f(*wi)
                bs, weight = bsdf.sample(ctx, si, ul, mi.Point2f(*u))
                delta = int(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta))
                w.writerow(["sample" if not delta else "sample_delta", *head,
                            *map(repr, wi), ul, u[0], u[1],
                            *map(float, weight), float(bs.pdf), *map(float, bs.wo), 0.0])
    print("wrote", path)


main()
