"""Makes the bitmap/checkerboard texture fixture: tiny images written by Mitsuba 3 and Mitsuba's
own eval/eval_1/mean on them, for tests/textures.rs.

Run from this folder with the Mitsuba 3.9.1 venv:
    /work/main/experiments/.venv-mitsuba/bin/python make_fixture.py
It is deterministic (fixed seed). Outputs: the images, cases.csv (one row per texture
configuration, with Mitsuba's mean()), points.csv (Mitsuba's eval and eval_1 per uv point),
checker.csv (the checkerboard) and real.csv (the living-room scene's textures).
"""
import csv
import os

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
rng = np.random.default_rng(20240611)
PF = mi.Bitmap.PixelFormat
REAL = "../../../experiments/scenes/living-room/textures"


def f(x):
    """Shortest text of an f32 that reads back exactly."""
    return repr(float(np.float32(x)))


def write_images():
    rgb8 = rng.integers(0, 256, (5, 6, 3), dtype=np.uint8)
    rgb8[0, 0] = [0, 10, 255]  # both branches of the sRGB curve
    mi.Bitmap(rgb8, pixel_format=PF.RGB).write("rgb8.png")
    rgba8 = rng.integers(0, 256, (4, 5, 4), dtype=np.uint8)
    rgba8[..., 3] = rng.choice([0, 77, 255], (4, 5))
    mi.Bitmap(rgba8, pixel_format=PF.RGBA).write("rgba8.png")
    mi.Bitmap(rng.integers(0, 256, (3, 4, 1), dtype=np.uint8), pixel_format=PF.Y).write("y8.png")
    mi.Bitmap(rng.integers(0, 256, (3, 4, 2), dtype=np.uint8), pixel_format=PF.YA).write("ya8.png")
    mi.Bitmap(rng.integers(0, 65536, (3, 4, 3), dtype=np.uint16), pixel_format=PF.RGB).write("rgb16.png")
    mi.Bitmap(rng.integers(0, 65536, (3, 3, 2), dtype=np.uint16), pixel_format=PF.YA).write("ya16.png")
    # Every 8-bit code once per column, to pin the decoding curve.
    codes = np.tile(np.arange(256, dtype=np.uint8), (2, 1))[:, :, None]
    mi.Bitmap(codes, pixel_format=PF.Y).write("codes8.png")
    # A smooth image, so that JPEG artefacts stay small; and a grey one.
    yy, xx = np.mgrid[0:12, 0:16]
    smooth = np.stack([xx * 15 + 10, yy * 20 + 5, 255 - xx * 8 - yy * 6], -1).astype(np.uint8)
    mi.Bitmap(smooth, pixel_format=PF.RGB).write("rgb.jpg", quality=95)
    mi.Bitmap(smooth[..., 1:2].copy(), pixel_format=PF.Y).write("y.jpg", quality=95)
    # Float images with values outside [0, 1] (no clamping anywhere).
    half = (rng.normal(0.5, 0.8, (3, 4, 3))).astype(np.float16)
    mi.Bitmap(half).write("rgb_half.exr")
    rgba = rng.normal(0.5, 0.8, (4, 3, 4)).astype(np.float32)
    rgba[..., 3] = rng.choice([0.0, 0.5, 1.0], (4, 3))
    mi.Bitmap(rgba, pixel_format=PF.RGBA).write("rgba_float.exr")
    mi.Bitmap(rng.uniform(0, 3, (3, 4, 1)).astype(np.float32), pixel_format=PF.Y).write("y_float.exr")
    mi.Bitmap(rng.uniform(0, 40, (4, 5, 3)).astype(np.float32)).write("rgb.hdr")
    # 1-pixel-high image: Mitsuba pads it to 2 rows.
    mi.Bitmap(rng.integers(0, 256, (1, 3, 3), dtype=np.uint8), pixel_format=PF.RGB).write("row.png")


T = np.array([[0.8, 0.6, 0.1], [-0.6, 0.8, 0.3], [0.0, 0.0, 1.0]])
I = np.eye(3)

# (file, raw, filter, wrap, to_uv)
CASES = [
    ("rgb8.png", False, "bilinear", "repeat", I),
    ("rgb8.png", False, "nearest", "repeat", I),
    ("rgb8.png", False, "bilinear", "mirror", I),
    ("rgb8.png", False, "nearest", "mirror", I),
    ("rgb8.png", False, "bilinear", "clamp", I),
    ("rgb8.png", False, "nearest", "clamp", I),
    ("rgb8.png", True, "bilinear", "repeat", I),
    ("rgb8.png", False, "bilinear", "repeat", T),
    ("rgba8.png", False, "bilinear", "repeat", I),
    ("rgba8.png", True, "nearest", "repeat", I),
    ("y8.png", False, "bilinear", "repeat", I),
    ("y8.png", True, "bilinear", "mirror", I),
    ("ya8.png", False, "bilinear", "clamp", I),
    ("rgb16.png", False, "bilinear", "repeat", I),
    ("rgb16.png", True, "nearest", "repeat", I),
    ("ya16.png", False, "bilinear", "repeat", I),
    ("codes8.png", False, "nearest", "repeat", I),
    ("codes8.png", True, "nearest", "repeat", I),
    ("rgb.jpg", False, "bilinear", "repeat", I),
    ("y.jpg", False, "nearest", "repeat", I),
    ("rgb_half.exr", False, "bilinear", "repeat", I),
    ("rgb_half.exr", True, "nearest", "mirror", I),
    ("rgba_float.exr", False, "bilinear", "clamp", I),
    ("y_float.exr", False, "bilinear", "repeat", T),
    ("rgb.hdr", False, "bilinear", "repeat", I),
    ("row.png", False, "bilinear", "repeat", I),
]


def texture(path, raw, filt, wrap, m):
    return mi.load_dict({
        "type": "bitmap", "filename": path, "raw": raw, "filter_type": filt,
        "wrap_mode": wrap, "to_uv": mi.ScalarAffineTransform3f(m),
    })


def evaluate(tex, u, v):
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(u, v)
    c = tex.eval(si)
    return [c[0], c[1], c[2]], tex.eval_1(si)


def uv_points(w, h, name):
    if name.startswith("codes8"):  # every pixel centre
        return [((i + 0.5) / w, 0.25) for i in range(w)]
    pts = [tuple(p) for p in rng.uniform(-1.5, 2.5, (40, 2))]
    pts += [tuple(p) for p in rng.uniform(0, 1, (10, 2))]
    pts += [((x + 0.5) / w, (y + 0.5) / h) for x, y in [(0, 0), (w - 1, 0), (0, h - 1), (1, 1)]]
    pts += [(0.0, 0.0), (1.0, 1.0), (0.5, 0.0), (1.0 / w, 1.0 / h)]
    return [(float(np.float32(u)), float(np.float32(v))) for u, v in pts]


def main():
    write_images()
    with open("cases.csv", "w", newline="") as cf, open("points.csv", "w", newline="") as pf:
        cw, pw = csv.writer(cf), csv.writer(pf)
        cw.writerow(["case", "file", "raw", "filter", "wrap", "m00", "m01", "m02", "m10", "m11",
                     "m12", "width", "height", "mean"])
        pw.writerow(["case", "u", "v", "r", "g", "b", "eval_1"])
        for i, (name, raw, filt, wrap, m) in enumerate(CASES):
            tex = texture(name, raw, filt, wrap, m)
            w, h = tex.resolution()
            cw.writerow([i, name, int(raw), filt, wrap] + [f(m[r][c]) for r in range(2)
                        for c in range(3)] + [w, h, f(tex.mean())])
            for u, v in uv_points(w, h, name):
                rgb, y = evaluate(tex, u, v)
                pw.writerow([i, f(u), f(v)] + [f(c) for c in rgb] + [f(y)])
    with open("checker.csv", "w", newline="") as out:
        cw = csv.writer(out)
        cw.writerow(["case", "c0r", "c0g", "c0b", "c1r", "c1g", "c1b", "sx", "sy", "mean", "u",
                     "v", "r", "g", "b", "eval_1"])
        checkers = [
            ({}, [0.4] * 3, [0.2] * 3, (1, 1)),
            ({"color0": {"type": "rgb", "value": [0.9, 0.1, 0.2]},
              "color1": {"type": "rgb", "value": [0.1, 0.5, 0.3]},
              "to_uv": mi.ScalarTransform4f().scale([4, 2, 1])},
             [0.9, 0.1, 0.2], [0.1, 0.5, 0.3], (4, 2)),
        ]
        for i, (extra, c0, c1, s) in enumerate(checkers):
            tex = mi.load_dict({"type": "checkerboard", **extra})
            pts = [tuple(p) for p in rng.uniform(-2, 2, (60, 2))]
            pts += [(0.5 / s[0], 0.25 / s[1]), (0.25 / s[0], 0.5 / s[1]), (0.5 / s[0], 0.5 / s[1])]
            for u, v in pts:
                rgb, y = evaluate(tex, float(np.float32(u)), float(np.float32(v)))
                cw.writerow([i] + [f(x) for x in c0 + c1] + list(s) + [f(tex.mean()), f(u), f(v)]
                            + [f(c) for c in rgb] + [f(y)])
    with open("real.csv", "w", newline="") as out:
        cw = csv.writer(out)
        cw.writerow(["file", "mean", "u", "v", "r", "g", "b", "eval_1"])
        for name in ["wood.jpg", "picture8.jpg", "leaf.png", "Sky 19.exr"]:
            tex = texture(os.path.join(REAL, name), False, "bilinear", "repeat", I)
            for u, v in rng.uniform(0, 1, (25, 2)):
                u, v = float(np.float32(u)), float(np.float32(v))
                rgb, y = evaluate(tex, u, v)
                cw.writerow([name, f(tex.mean()), f(u), f(v)] + [f(c) for c in rgb] + [f(y)])


main()
