"""Reference values of Mitsuba 3.9.1's `envmap` emitter for tests/render_envmap.rs.

Run from anywhere with the project's Mitsuba venv:
    experiments/.venv-mitsuba/bin/python tests/data/envmap/make_fixture.py
Writes, next to this script:
  synthetic.exr  a 16x9 float32 RGB lat-long map (written by Mitsuba's own Bitmap writer);
  cases.csv      case, image (`synthetic.exr`, or `sky19` for the living-room scene's
                 textures/Sky 19.exr), scale, the 16 entries of to_world (row-major, as Mitsuba holds them);
  eval.csv       case, world direction d (unit, float32), Mitsuba's radiance for a ray escaping
                 along d, i.e. `eval` of a SurfaceInteraction3f with wi = -d.
Every number is printed with 9 significant digits, so it reads back as the same float32.
"""

import os

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")

HERE = os.path.dirname(os.path.abspath(__file__))
SKY = os.path.join(HERE, "..", "..", "..", "experiments", "scenes", "living-room", "textures", "Sky 19.exr")

# The living-room scene's envmap to_world, row-major as written in its XML.
LIVING_ROOM = np.array(
    [[-4.37114e-008, 0, 1, 0], [0, 1, 0, 0], [-1, 0, -4.37114e-008, 0], [0, 0, 0, 1]], dtype=np.float32
)


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def synthetic():
    """Smooth variation, a black block (zero luminance next to lit pixels), one bright texel,
    and distinct first/last columns so that the seam interpolation is visible."""
    h, w = 9, 16
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    rng = np.random.default_rng(3)
    img = np.stack(
        [
            1.0 + 0.8 * np.sin(2 * np.pi * x / w) * np.cos(np.pi * y / h),
            0.5 + 0.4 * np.cos(3 * np.pi * x / w) + 0.1 * y,
            0.2 + rng.uniform(0, 1, (h, w)),
        ],
        axis=2,
    )
    img[3:6, 5:8, :] = 0.0
    img[2, 11, :] = [80.0, 60.0, 20.0]
    img[:, 0, :] *= 2.0
    img[:, w - 1, :] *= 0.25
    return img.astype(np.float32)


def main():
    syn_path = os.path.join(HERE, "synthetic.exr")
    mi.Bitmap(synthetic()).write(syn_path)

    rot = mi.ScalarTransform4f().translate([1, 2, 3]).rotate(list(unit([1, 2, 3])), 37.0)
    half = mi.ScalarTransform4f().rotate(list(unit([-2, 1, 0.5])), 120.0).scale(0.5)
    cases = [
        # name, image, to_world, scale, number of random directions
        ("syn_rot", syn_path, rot, 1.7, 70),
        ("syn_lr", syn_path, mi.ScalarTransform4f(LIVING_ROOM), 1.0, 70),
        ("syn_half", syn_path, half, 0.75, 70),
        ("sky_lr", SKY, mi.ScalarTransform4f(LIVING_ROOM), 1.0, 80),
        ("sky_rot", SKY, rot, 0.5, 50),
    ]
    rng = np.random.default_rng(20240601)
    case_rows, eval_rows = [], []
    for name, image, to_world, scale, n in cases:
        emitter = mi.load_dict({"type": "envmap", "filename": image, "to_world": to_world, "scale": scale})
        m = np.array(to_world.matrix, dtype=np.float32)
        rel = "synthetic.exr" if image == syn_path else "sky19"
        case_rows.append([name, rel, "%.9g" % scale] + ["%.9g" % v for v in m.reshape(-1)])
        lin = m[:3, :3].astype(np.float64)
        dirs = [unit(v) for v in rng.normal(size=(n, 3))]
        # The poles, the seam (u = 0, local -z) and the back meridian, in local and world frames.
        local = [[0, 1, 0], [0, -1, 0], [0, 0, -1], [0, 0, 1], [1, 0, 0], [-1, 0, 0], [0.3, 0.2, -0.9]]
        dirs += [unit(v) for v in local]
        dirs += [unit(lin @ np.asarray(v, dtype=np.float64)) for v in local]
        for d in dirs:
            d = np.asarray(d, dtype=np.float32)
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = mi.Vector3f(*(-d))
            rgb = np.array(emitter.eval(si), dtype=np.float32)
            eval_rows.append([name] + ["%.9g" % v for v in d] + ["%.9g" % v for v in rgb])
    with open(os.path.join(HERE, "cases.csv"), "w") as f:
        f.write("case,image,scale," + ",".join("m%d%d" % (r, c) for r in range(4) for c in range(4)) + "\n")
        for r in case_rows:
            f.write(",".join(r) + "\n")
    with open(os.path.join(HERE, "eval.csv"), "w") as f:
        f.write("case,dx,dy,dz,r,g,b\n")
        for r in eval_rows:
            f.write(",".join(r) + "\n")


if __name__ == "__main__":
    main()
