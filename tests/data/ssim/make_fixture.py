"""Writes fixture.json: small deterministic RGB images and, for pairs of them, scikit-image's SSIM
and numpy's other image metrics, so that tests/image_metrics.rs can check
src/image/metrics.rs against an independent implementation without Python.

Set up once (the venv is gitignored):

    python3 -m venv tests/data/ssim/.venv
    tests/data/ssim/.venv/bin/pip install scikit-image numpy
    tests/data/ssim/.venv/bin/python tests/data/ssim/make_fixture.py

Pixel values are integer codes times 2^-10, exact in float32 and float64, so that both sides
read the very same image. The formulas below are the ones the Rust module documents: the
display image is the sRGB curve of each channel clamped to [0, 1]; SSIM runs on its Rec. 709
luma with Wang et al.'s settings.
"""

import json
import os

import numpy as np
import skimage
from skimage.metrics import structural_similarity

SCALE = 2.0**-10
REC709 = np.array([0.2126, 0.7152, 0.0722])
EPSILON = 0.01
FIREFLY_FACTOR = 4.0
FIREFLY_FLOOR = 0.1


def quantise(img):
    """Non-negative integer codes of an image (values rounded to multiples of SCALE)."""
    return np.rint(np.clip(img, 0.0, None) / SCALE).astype(np.int64)


def srgb(v):
    v = np.clip(v, 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1.0 / 2.4) - 0.055)


def luminance(img):
    return img @ REC709


def metrics(x, r):
    d = x - r
    display = srgb(x) - srgb(r)
    lum_x, lum_r = luminance(x), luminance(r)
    mean_x, mean_r = lum_x.mean(), lum_r.mean()
    fireflies = int(np.sum(lum_x > FIREFLY_FACTOR * lum_r + FIREFLY_FLOOR))
    mse_d = np.mean(display**2)
    return {
        "rmse": float(np.sqrt(np.mean(d**2))),
        "relmse": float(np.mean(d**2 / (r**2 + EPSILON))),
        "psnr_db": float(-10.0 * np.log10(mse_d)) if mse_d > 0 else None,
        "ssim": float(
            structural_similarity(
                luminance(srgb(x)),
                luminance(srgb(r)),
                gaussian_weights=True,
                sigma=1.5,
                use_sample_covariance=False,
                data_range=1.0,
            )
        ),
        "mean_luminance": float(mean_x),
        "reference_mean_luminance": float(mean_r),
        "mean_bias": float(mean_x - mean_r),
        "firefly_pixels": fireflies,
    }


def main():
    rng = np.random.default_rng(20240514)
    w, h = 32, 24
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    ref = np.stack(
        [
            0.05 + 1.1 * xx / (w - 1),  # passes display white on the right
            0.8 * yy / (h - 1),
            0.3 + 0.2 * np.sin(xx / 4.0) * np.cos(yy / 3.0),
        ],
        axis=-1,
    )
    noisy = ref + rng.normal(0.0, 0.08, ref.shape)
    fireflies = noisy.copy()
    for _ in range(8):
        y, x = rng.integers(0, h), rng.integers(0, w)
        fireflies[y, x] = rng.uniform(5.0, 60.0) * rng.uniform(0.5, 1.0, 3)
    biased = 0.7 * ref + 0.03
    texture = rng.uniform(0.0, 1.5, ref.shape)
    black = np.zeros_like(ref)
    small_a = rng.uniform(0.0, 1.0, (13, 11, 3))
    small_b = small_a + rng.normal(0.0, 0.1, small_a.shape)

    images = {
        "ref": ref,
        "noisy": noisy,
        "fireflies": fireflies,
        "biased": biased,
        "texture": texture,
        "black": black,
        "small_a": small_a,
        "small_b": small_b,
    }
    codes = {k: quantise(v) for k, v in images.items()}
    exact = {k: c.astype(np.float64) * SCALE for k, c in codes.items()}
    pairs = [
        ("ref", "ref"),
        ("noisy", "ref"),
        ("fireflies", "ref"),
        ("biased", "ref"),
        ("texture", "ref"),
        ("texture", "noisy"),
        ("noisy", "black"),
        ("small_b", "small_a"),
    ]
    fixture = {
        "generator": "tests/data/ssim/make_fixture.py",
        "scikit_image": skimage.__version__,
        "numpy": np.__version__,
        "scale": SCALE,
        "firefly_factor": FIREFLY_FACTOR,
        "firefly_floor": FIREFLY_FLOOR,
        "images": {
            k: {"width": c.shape[1], "height": c.shape[0], "codes": c.reshape(-1).tolist()}
            for k, c in codes.items()
        },
        "pairs": [
            {"test": t, "reference": r, **metrics(exact[t], exact[r])} for t, r in pairs
        ],
    }
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fixture.json")
    with open(path, "w") as f:
        json.dump(fixture, f, separators=(",", ":"))
        f.write("\n")
    for p in fixture["pairs"]:
        print(p["test"], p["reference"], "ssim", p["ssim"], "fireflies", p["firefly_pixels"])


if __name__ == "__main__":
    main()
