"""Reference values of Mitsuba 3.9.1's `MicrofacetDistribution` (scalar_rgb) for
`src/render/bsdfs/microfacet.rs`.

Run from the repository root with the Mitsuba venv:

    experiments/.venv-mitsuba/bin/python tests/data/microfacet/make_fixture.py

Writes `tests/data/microfacet/microfacet.csv`, one row per (distribution, roughness, wi, m, wo,
u) point, with Mitsuba's

* `d`       = `eval(m)`
* `g1`      = `smith_g1(wi, m)`, `g1_wo` = `smith_g1(wo, m)`
* `g`       = `G(wi, wo, m)`
* `pdf_vis` = `pdf(wi, m)` with `sample_visible=True`
* `pdf_all` = `pdf(wi, m)` with `sample_visible=False` (i.e. D(m) cos(theta_m))
* `svx,svy,svz` = normal from `sample(wi, u)` with `sample_visible=True`
* `sax,say,saz,sa_pdf` = normal and pdf from `sample(wi, u)` with `sample_visible=False`

Rows with `wi` below the horizon test `smith_g1` (Mitsuba's G1 is defined on both sides); their
pdf and sampling columns are whatever Mitsuba returns and are not meaningful (callers flip `wi`
to the upper side first). Points come from a seeded numpy generator,
so rerunning reproduces the file exactly.
"""

import csv
import os

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")

HERE = os.path.dirname(os.path.abspath(__file__))
rng = np.random.default_rng(20240611)


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def sph(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return unit([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


ROUGHNESS = [(0.05, 0.05), (0.3, 0.3), (1.0, 1.0), (0.2, 0.6), (0.7, 0.15), (1e-5, 1e-5)]
DISTS = {"beckmann": mi.MicrofacetType.Beckmann, "ggx": mi.MicrofacetType.GGX}

rows = []
for name, kind in DISTS.items():
    for au, av in ROUGHNESS:
        vis = mi.MicrofacetDistribution(kind, au, av, True)
        allm = mi.MicrofacetDistribution(kind, au, av, False)
        # Fixed directions: normal incidence, moderate, grazing, and a few random ones.
        wis = [sph(0, 0), sph(30, 20), sph(60, 135), sph(85, 250), sph(89.5, 10)]
        wis += [sph(rng.uniform(0, 89), rng.uniform(0, 360)) for _ in range(4)]
        for wi in wis:
            for j in range(4):
                u = (float(np.float32(rng.uniform())), float(np.float32(rng.uniform())))
                if j == 0:
                    # A visible normal of this wi (always inside the lobe).
                    m = np.array(vis.sample(mi.Vector3f(*wi), mi.Point2f(*u))[0], dtype=np.float64)
                    wo = 2 * np.dot(wi, m) * m - wi
                elif j == 1:
                    # The half vector of wi and a random upper-hemisphere wo.
                    wo = sph(rng.uniform(0, 89), rng.uniform(0, 360))
                    m = unit(wi + wo)
                elif j == 2:
                    # A random normal, possibly far from the lobe, and a wo below the horizon.
                    m = sph(rng.uniform(0, 89), rng.uniform(0, 360))
                    wo = sph(rng.uniform(91, 179), rng.uniform(0, 360))
                else:
                    # wi seen from below: G1 of a back-side direction (roughdielectric uses it).
                    m = sph(rng.uniform(0, 60), rng.uniform(0, 360))
                    wo = -wi
                m = unit(m)
                wo = unit(wo)
                v_wi, v_m, v_wo = mi.Vector3f(*wi), mi.Vector3f(*m), mi.Vector3f(*wo)
                v_wi_in = v_wi if j != 3 else -v_wi
                sv = vis.sample(v_wi_in, mi.Point2f(*u))[0]
                sa, sa_pdf = allm.sample(v_wi_in, mi.Point2f(*u))
                rows.append(
                    [name, au, av]
                    + [float(x) for x in v_wi_in]
                    + [float(x) for x in v_m]
                    + [float(x) for x in v_wo]
                    + list(u)
                    + [
                        vis.eval(v_m),
                        vis.smith_g1(v_wi_in, v_m),
                        vis.smith_g1(v_wo, v_m),
                        vis.G(v_wi_in, v_wo, v_m),
                        vis.pdf(v_wi_in, v_m),
                        allm.pdf(v_wi_in, v_m),
                    ]
                    + [float(x) for x in sv]
                    + [float(x) for x in sa]
                    + [sa_pdf]
                )

header = (
    "dist,alpha_u,alpha_v,wix,wiy,wiz,mx,my,mz,wox,woy,woz,u1,u2,"
    "d,g1,g1_wo,g,pdf_vis,pdf_all,svx,svy,svz,sax,say,saz,sa_pdf"
).split(",")
with open(os.path.join(HERE, "microfacet.csv"), "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(header)
    for r in rows:
        w.writerow([r[0]] + [repr(float(x)) for x in r[1:]])
print(f"wrote {len(rows)} rows")
