"""Makes the bumpmap fixture for tests/render_bumpmap.rs: Mitsuba 3.9.1's own `bitmap`
`eval_1_grad` and `bumpmap` `eval`/`pdf` (over a `diffuse`) on small float textures.

Run from this folder with the Mitsuba 3.9.1 venv:
    /work/main/experiments/.venv-mitsuba/bin/python make_fixture.py
It is deterministic (fixed seed). Outputs:
  textures.csv  one row per texture: size, channels, filter, wrap, to_uv (row-major 2x3) and
                the texels (row by row from the top, channels interleaved, space-separated);
  grad.csv      Mitsuba's eval_1_grad at uv points (inside and outside [0, 1]^2);
  eval.csv      hand-made surface interactions (uv, dp_du, dp_dv, geometric normal n, shading
                normal ns; the shading frame is Frame3f(ns), whose tangents are the same as our
                Frame::new) with wi, wo in that frame, and Mitsuba's bumpmap eval (RGB) and pdf,
                with its flip_invalid_normals and use_shadowing_function both true (the defaults)
                in 2 of 5 cases and each combination of the others in 1 of 5.
  hits.csv      rays at quad.obj (two triangles with vt and vn, one with a mirrored uv
                mapping; written here) under HIT_TO_WORLD, and Mitsuba's uv, dp_du, dp_dv,
                geometric normal n and shading normal ns at the hit.
Float32 texels and raw=true keep Mitsuba from converting anything, so both sides see the same
numbers.
"""
import csv

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
rng = np.random.default_rng(20250214)
PF = mi.Bitmap.PixelFormat

I = np.eye(3)
# A rotation with scale and offset: makes Mitsuba's order of to_uv and resolution visible.
T = np.array([[1.6, 1.2, 0.1], [-0.6, 0.8, 0.3], [0.0, 0.0, 1.0]])

# (channels, width, height, filter, wrap, to_uv)
TEXTURES = [
    (1, 5, 3, "bilinear", "repeat", I),
    (1, 5, 3, "bilinear", "mirror", T),
    (1, 4, 6, "bilinear", "clamp", I),
    (3, 6, 4, "bilinear", "repeat", I),
    (3, 6, 4, "bilinear", "repeat", T),
    (3, 3, 2, "bilinear", "mirror", I),
    (1, 5, 3, "nearest", "repeat", I),
]

REFLECTANCE = [0.2, 0.5, 0.8]


def f(x):
    """Shortest text of an f32 that reads back exactly."""
    return repr(float(np.float32(x)))


def texture(spec, data):
    channels, _, _, filt, wrap, m = spec
    fmt = PF.Y if channels == 1 else PF.RGB
    return {
        "type": "bitmap",
        "bitmap": mi.Bitmap(data, pixel_format=fmt),
        "raw": True,
        "filter_type": filt,
        "wrap_mode": wrap,
        "to_uv": mi.ScalarTransform3f(mi.ScalarMatrix3f(m)),
    }


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return (v / np.linalg.norm(v)).astype(np.float32)


QUAD_OBJ = """# Two triangles; the second one's uvs run the other way round (mirrored mapping).
v -1 -1 0
v 1 -1 0.2
v 1 1 0
v -1 1 -0.3
vt 0.1 0.2
vt 0.9 0.25
vt 0.8 0.95
vt 0.3 0.1
vt 0.95 0.7
vn 0.1 0 1
vn 0 0.2 1
vn -0.2 0.1 1
vn 0 0 1
f 1/1/1 2/2/2 3/3/3
f 1/4/1 3/3/3 4/5/4
"""
HIT_TO_WORLD = "translate(0.3,-0.2,1) rotate(axis (1,2,0.5)/|.|, 50 deg) scale(0.5,2,1)"


def hit_to_world():
    axis = np.array([1.0, 2.0, 0.5])
    axis = (axis / np.linalg.norm(axis)).tolist()
    return mi.ScalarTransform4f().translate([0.3, -0.2, 1]).rotate(axis, 50).scale([0.5, 2, 1])


def write_hits():
    with open("quad.obj", "w") as out:
        out.write(QUAD_OBJ)
    scene = mi.load_dict({"type": "scene", "quad": {"type": "obj", "filename": "quad.obj",
                                                     "to_world": hit_to_world()}})
    with open("hits.csv", "w", newline="") as out:
        w = csv.writer(out)
        w.writerow([f"{k}{c}" for k in ["o", "d"] for c in "xyz"] + ["u", "v"]
                   + [f"{k}{c}" for k in ["dpdu", "dpdv", "n", "ns"] for c in "xyz"])
        found = 0
        while found < 12:
            target = hit_to_world() @ mi.ScalarPoint3f(*rng.uniform(-1, 1, 2), 0.0)
            o = np.array(target) + rng.normal(size=3) * 3
            d = unit(np.array(target) - o)
            si = scene.ray_intersect(mi.Ray3f(mi.Point3f(o.astype(np.float32)), mi.Vector3f(d)))
            if not si.is_valid():
                continue
            found += 1
            w.writerow([f(x) for x in o.astype(np.float32)] + [f(x) for x in d]
                       + [f(si.uv[0]), f(si.uv[1])]
                       + [f(x) for v in [si.dp_du, si.dp_dv, si.n, si.sh_frame.n] for x in v])


def main():
    datas = []
    with open("textures.csv", "w", newline="") as out:
        w = csv.writer(out)
        w.writerow(["id", "channels", "width", "height", "filter", "wrap",
                    "m00", "m01", "m02", "m10", "m11", "m12", "texels"])
        for i, spec in enumerate(TEXTURES):
            channels, width, height, filt, wrap, m = spec
            data = rng.uniform(-0.5, 2.0, (height, width, channels)).astype(np.float32)
            datas.append(data)
            w.writerow([i, channels, width, height, filt, wrap]
                       + [f(m[r, c]) for r in range(2) for c in range(3)]
                       + [" ".join(f(x) for x in data.ravel())])

    with open("grad.csv", "w", newline="") as out:
        w = csv.writer(out)
        w.writerow(["id", "u", "v", "gu", "gv"])
        for i, spec in enumerate(TEXTURES):
            tex = mi.load_dict(texture(spec, datas[i]))
            for _ in range(40):
                uv = rng.uniform(-0.7, 1.7, 2).astype(np.float32)
                si = mi.SurfaceInteraction3f()
                si.uv = mi.Point2f(uv)
                g = tex.eval_1_grad(si)
                w.writerow([i, f(uv[0]), f(uv[1]), f(g[0]), f(g[1])])

    with open("eval.csv", "w", newline="") as out:
        w = csv.writer(out)
        w.writerow(["id", "scale", "flip", "shadow", "u", "v"]
                   + [f"{k}{c}" for k in ["dpdu", "dpdv", "n", "ns", "wi", "wo"] for c in "xyz"]
                   + ["r", "g", "b", "pdf"])
        ctx = mi.BSDFContext()
        for i in [0, 1, 3, 4]:
            for scale in [0.05, 0.3, -0.2]:
                options = [(True, True), (True, True), (False, True), (True, False), (False, False)]
                bsdfs = {o: mi.load_dict({
                    "type": "bumpmap",
                    "height": texture(TEXTURES[i], datas[i]),
                    "scale": scale,
                    "flip_invalid_normals": o[0],
                    "use_shadowing_function": o[1],
                    "bsdf": {"type": "diffuse",
                             "reflectance": {"type": "rgb", "value": REFLECTANCE}},
                }) for o in set(options)}
                for k in range(25):
                    flip, shadow = options[k % len(options)]
                    bsdf = bsdfs[(flip, shadow)]
                    n = unit(rng.normal(size=3))
                    ns = unit(n + 0.3 * rng.normal(size=3))
                    if np.dot(ns, n) < 0:
                        ns = -ns
                    # Tangents of a sheared, scaled uv parametrisation of the plane of n.
                    a = unit(np.cross(n, rng.normal(size=3)))
                    b = np.cross(n, a)
                    dp_du = (rng.uniform(0.3, 3) * a).astype(np.float32)
                    dp_dv = (rng.uniform(0.3, 3) * (b + rng.uniform(-0.5, 0.5) * a)).astype(np.float32)
                    if rng.uniform() < 0.3:
                        dp_dv = -dp_dv  # a mirrored parametrisation
                    uv = rng.uniform(-0.3, 1.3, 2).astype(np.float32)
                    wi = unit(rng.normal(size=3))
                    if wi[2] < 0 and rng.uniform() < 0.8:
                        wi[2] = -wi[2]
                    wo = unit(rng.normal(size=3))
                    if wo[2] < 0 and rng.uniform() < 0.8:
                        wo[2] = -wo[2]
                    si = mi.SurfaceInteraction3f()
                    si.uv = mi.Point2f(uv)
                    si.dp_du = mi.Vector3f(dp_du)
                    si.dp_dv = mi.Vector3f(dp_dv)
                    si.n = mi.Normal3f(n)
                    si.sh_frame = mi.Frame3f(mi.Vector3f(ns))
                    si.wi = mi.Vector3f(wi)
                    value = bsdf.eval(ctx, si, mi.Vector3f(wo))
                    pdf = bsdf.pdf(ctx, si, mi.Vector3f(wo))
                    w.writerow([i, f(scale), int(flip), int(shadow), f(uv[0]), f(uv[1])]
                               + [f(x) for v in [dp_du, dp_dv, n, ns, wi, wo] for x in v]
                               + [f(value[0]), f(value[1]), f(value[2]), f(pdf)])

    write_hits()


main()
