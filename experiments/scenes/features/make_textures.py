#!/usr/bin/env python3
"""Writes the small textures, environment maps and OBJ meshes of the feature scenes.

Run with the Mitsuba venv's Python (it uses NumPy and `mitsuba.Bitmap` for PNG, JPEG and
OpenEXR; the Radiance HDR file is written here, run-length encoded, because Mitsuba writes
the `#?RGBE` signature while most files, and the `image` crate's decoder, use `#?RADIANCE`):

    experiments/.venv-mitsuba/bin/python experiments/scenes/features/make_textures.py

Every image is an analytic pattern (no random numbers), so a re-run writes the same pixels.
Each pattern is asymmetric in u and in v, so a renderer that flips or transposes texture
coordinates gives a different image from Mitsuba's, which the block t-test sees.

Outputs (committed; all together well under 1 MB):
  textures/uvgrid.png     64x32 RGB, 8-bit sRGB: u ramps red, v ramps blue, a 4x2 grid of
                          light/dark cells, a white square in the top-left cell and a green
                          one in the top-right cell.
  textures/cutout.png     64x64 RGBA, 8-bit sRGB: RGB is a leaf shape (green inside, black
                          outside, soft edge); alpha is a different shape (a centred square).
                          Mitsuba 3's `bitmap` drops the alpha channel, so a `mask` whose
                          opacity is this file cuts out by the RGB luminance, not by alpha.
  textures/height.png     64x64 grey (one channel), 8-bit: a 4x4 lattice of round bumps and a
                          diagonal ridge, as a bump-map height.
  textures/planks.jpg     128x64 RGB JPEG: wood-like planks with grain, the first plank darker.
  textures/albedo.exr     64x64 RGB float32 OpenEXR: linear reflectances in [0.03, 0.9], rings
                          around an off-centre point.
  textures/sky.exr        128x64 RGB half-float OpenEXR, latitude-longitude: a sky (blue at
                          the zenith, bright at the horizon), a dark ground, and a small sun
                          (about 2x2 texels, radiance ~300) that only importance sampling
                          finds reliably.
  textures/sky.hdr        the same map as Radiance RGBE (`#?RADIANCE`, new-style RLE).
  meshes/quad_uv.obj      the square [-1,1]^2 in z=0 facing +z, two triangles, UVs 0..1.
  meshes/quad_tiled.obj   the same square as one quad face with normals, UVs -0.5..1.5 (so
                          the texture repeats 2x2 and wraps).
  meshes/ball.obj         a coarse UV sphere (12 x 6 segments) with smooth vertex normals and
                          UVs, for `face_normals` (faceted vs smooth).
"""

import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TEXTURES = HERE / "textures"
MESHES = HERE / "meshes"


def bitmap_module():
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    return mi


def write_ldr(mi, path: Path, pixels: np.ndarray, **kwargs) -> None:
    """8-bit sRGB-encoded pixels (H, W[, C]) to PNG or JPEG, tagged as sRGB."""
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    if pixels.ndim == 2:
        fmt = mi.Bitmap.PixelFormat.Y
    else:
        fmt = {3: mi.Bitmap.PixelFormat.RGB, 4: mi.Bitmap.PixelFormat.RGBA}[pixels.shape[2]]
    bitmap = mi.Bitmap(pixels, fmt)
    bitmap.set_srgb_gamma(True)
    bitmap.write(str(path), **kwargs)


def to_u8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.round(x * 255.0), 0, 255).astype(np.uint8)


def texel_centres(width: int, height: int):
    """(u, v) at texel centres, v = 0 on the first (top) row of the file."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    return np.meshgrid(u, v)


def uvgrid() -> np.ndarray:
    w, h = 64, 32
    u, v = texel_centres(w, h)
    cell = ((np.floor(u * 4) + np.floor(v * 2)) % 2)
    img = np.stack([0.15 + 0.8 * u, 0.25 + 0.25 * cell, 0.15 + 0.8 * v], axis=-1)
    img *= (0.7 + 0.3 * cell)[..., None]
    top_left = (u > 0.05) & (u < 0.17) & (v > 0.1) & (v < 0.35)
    top_right = (u > 0.83) & (u < 0.95) & (v > 0.1) & (v < 0.35)
    img[top_left] = [1.0, 1.0, 1.0]
    img[top_right] = [0.1, 0.9, 0.1]
    return to_u8(img)


def cutout() -> np.ndarray:
    w = h = 64
    u, v = texel_centres(w, h)
    # A leaf: an ellipse tilted by 30 degrees, off centre, with a soft rim.
    x, y = u - 0.45, v - 0.5
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    a, b = (c * x + s * y) / 0.42, (-s * x + c * y) / 0.2
    r = np.sqrt(a * a + b * b)
    inside = np.clip((1.0 - r) / 0.15, 0.0, 1.0)
    vein = np.abs(b) < 0.08
    leaf = np.stack([0.35 + 0.3 * u, 0.85 - 0.2 * vein, 0.3 * np.ones_like(u)], axis=-1)
    rgb = leaf * inside[..., None]
    alpha = ((np.abs(u - 0.5) < 0.3) & (np.abs(v - 0.5) < 0.3)).astype(np.float64)
    return to_u8(np.concatenate([rgb, alpha[..., None]], axis=-1))


def height() -> np.ndarray:
    w = h = 64
    u, v = texel_centres(w, h)
    fu, fv = (u * 4) % 1.0 - 0.5, (v * 4) % 1.0 - 0.5
    bumps = np.clip(1.0 - np.sqrt(fu * fu + fv * fv) / 0.4, 0.0, 1.0) ** 2
    ridge = np.exp(-((u - v) / 0.05) ** 2)
    return to_u8(0.1 + 0.6 * bumps + 0.3 * ridge)


def planks() -> np.ndarray:
    w, h = 128, 64
    u, v = texel_centres(w, h)
    plank = np.floor(v * 4)
    grain = 0.5 + 0.5 * np.sin(2 * math.pi * (u * 6 + 0.35 * np.sin(2 * math.pi * v * 3)
                                                  + plank * 0.37))
    base = np.array([0.95, 0.72, 0.5])
    tone = (0.75 + 0.25 * grain) * np.where(plank == 0, 0.55, 1.0) * (0.85 + 0.05 * plank)
    img = base[None, None, :] * tone[..., None]
    seam = (v * 4) % 1.0 < 0.06
    img[seam] *= 0.4
    return to_u8(img)


def albedo() -> np.ndarray:
    w = h = 64
    u, v = texel_centres(w, h)
    r = np.sqrt((u - 0.3) ** 2 + (v - 0.35) ** 2)
    ring = 0.5 + 0.5 * np.cos(2 * math.pi * r * 6)
    img = np.stack([0.03 + 0.87 * ring, 0.1 + 0.6 * u, 0.05 + 0.75 * (1 - ring) * v], axis=-1)
    return img.astype(np.float32)


def sky() -> np.ndarray:
    """Latitude-longitude map, 128x64: row 0 is the zenith (+y), column u turns about y."""
    w, h = 128, 64
    u, v = texel_centres(w, h)
    theta = v * math.pi
    elevation = math.pi / 2 - theta
    zen = np.clip(np.sin(elevation), 0.0, 1.0)
    sky_rgb = np.stack([0.25 + 0.5 * (1 - zen), 0.45 + 0.4 * (1 - zen), 0.9 + 0.1 * (1 - zen)],
                       axis=-1)
    ground = np.array([0.12, 0.09, 0.06])
    img = np.where((elevation > 0)[..., None], sky_rgb, ground[None, None, :])
    # The sun: 2x2 texels at elevation ~ 37 degrees, a third of the way round.
    row, col = 16, 43
    img[row:row + 2, col:col + 2] = np.array([1.0, 0.9, 0.7]) * 300.0
    # A dimmer halo one texel around it, so the bright region is not a single point.
    img[row - 1:row + 3, col - 1:col + 3] += np.array([1.0, 0.9, 0.7]) * 10.0
    return img.astype(np.float32)


# --- Radiance HDR ------------------------------------------------------------------------------

def rgbe(pixels: np.ndarray) -> np.ndarray:
    """Float RGB (H, W, 3) -> RGBE bytes (H, W, 4): shared exponent of the largest component."""
    m = pixels.max(axis=-1)
    mantissa, exponent = np.frexp(m)
    scale = np.where(m > 1e-32, mantissa * 256.0 / np.where(m > 0, m, 1.0), 0.0)
    out = np.zeros(pixels.shape[:2] + (4,), dtype=np.uint8)
    out[..., :3] = np.clip(np.floor(pixels * scale[..., None]), 0, 255).astype(np.uint8)
    out[..., 3] = np.where(m > 1e-32, exponent + 128, 0).astype(np.uint8)
    return out


def rle_component(data: bytes) -> bytes:
    """New-style RLE of one component of one scanline: runs of 3..127 equal bytes as
    (128 + n, byte), everything else as literal chunks of at most 128 bytes (n, bytes...)."""
    out = bytearray()
    literal = bytearray()
    i = 0
    while i < len(data):
        run = 1
        while i + run < len(data) and run < 127 and data[i + run] == data[i]:
            run += 1
        if run >= 3:
            if literal:
                out += bytes([len(literal)]) + literal
                literal = bytearray()
            out += bytes([128 + run, data[i]])
            i += run
        else:
            literal.append(data[i])
            i += 1
            if len(literal) == 128:
                out += bytes([128]) + literal
                literal = bytearray()
    if literal:
        out += bytes([len(literal)]) + literal
    return bytes(out)


def write_hdr(path: Path, pixels: np.ndarray) -> None:
    height_px, width_px = pixels.shape[:2]
    assert 8 <= width_px < 32768, "new-style RLE needs 8 <= width < 32768"
    enc = rgbe(pixels)
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n")
    out += f"-Y {height_px} +X {width_px}\n".encode("ascii")
    for row in enc:
        out += bytes([2, 2, width_px >> 8, width_px & 0xFF])
        for c in range(4):
            out += rle_component(row[:, c].tobytes())
    path.write_bytes(bytes(out))


# --- meshes ------------------------------------------------------------------------------------

def quad_uv() -> str:
    return "\n".join([
        "# The square [-1,1]^2 in z = 0, facing +z; UVs 0..1 (v = 0 at y = -1). Two triangles.",
        "v -1 -1 0", "v 1 -1 0", "v 1 1 0", "v -1 1 0",
        "vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1",
        "f 1/1 2/2 3/3", "f 1/1 3/3 4/4", ""])


def quad_tiled() -> str:
    return "\n".join([
        "# The square [-1,1]^2 in z = 0, facing +z, as one quad with normals;",
        "# UVs -0.5..1.5, so a texture with wrap mode repeat shows 2x2 times.",
        "v -1 -1 0", "v 1 -1 0", "v 1 1 0", "v -1 1 0",
        "vt -0.5 -0.5", "vt 1.5 -0.5", "vt 1.5 1.5", "vt -0.5 1.5",
        "vn 0 0 1",
        "f 1/1/1 2/2/1 3/3/1 4/4/1", ""])


def unit(theta: float, phi: float):
    """The unit vector at polar angle theta from +y and azimuth phi."""
    return math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi)


def ball(segments: int = 12, rings: int = 6) -> str:
    """A unit UV sphere, poles on y, with smooth normals and UVs; faces wind outwards."""
    lines = [f"# A coarse unit UV sphere ({segments} x {rings}), smooth normals, UVs."]
    for j in range(rings + 1):
        theta = math.pi * j / rings
        for i in range(segments + 1):
            phi = 2 * math.pi * i / segments
            x, y, z = unit(theta, phi)
            lines.append(f"v {x:.6f} {y:.6f} {z:.6f}")
    for j in range(rings + 1):
        for i in range(segments + 1):
            lines.append(f"vt {i / segments:.6f} {1 - j / rings:.6f}")
    for j in range(rings + 1):
        theta = math.pi * j / rings
        for i in range(segments + 1):
            phi = 2 * math.pi * i / segments
            x, y, z = unit(theta, phi)
            lines.append(f"vn {x:.6f} {y:.6f} {z:.6f}")

    def idx(i, j):
        k = j * (segments + 1) + i + 1
        return f"{k}/{k}/{k}"

    for j in range(rings):
        for i in range(segments):
            a, b = idx(i, j), idx(i + 1, j)
            c, d = idx(i + 1, j + 1), idx(i, j + 1)
            # Outward winding: (a, b, c) turns from +phi towards +theta.
            if j > 0:
                lines.append(f"f {a} {b} {c}")
            if j < rings - 1:
                lines.append(f"f {a} {c} {d}")
    return "\n".join(lines) + "\n"


def main() -> None:
    mi = bitmap_module()
    TEXTURES.mkdir(exist_ok=True)
    MESHES.mkdir(exist_ok=True)
    write_ldr(mi, TEXTURES / "uvgrid.png", uvgrid())
    write_ldr(mi, TEXTURES / "cutout.png", cutout())
    write_ldr(mi, TEXTURES / "height.png", height())
    write_ldr(mi, TEXTURES / "planks.jpg", planks(), quality=90)
    mi.Bitmap(albedo(), mi.Bitmap.PixelFormat.RGB).write(str(TEXTURES / "albedo.exr"))
    sky_map = sky()
    half = mi.Bitmap(sky_map, mi.Bitmap.PixelFormat.RGB).convert(
        mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float16, False)
    half.write(str(TEXTURES / "sky.exr"))
    write_hdr(TEXTURES / "sky.hdr", sky_map)
    (MESHES / "quad_uv.obj").write_text(quad_uv())
    (MESHES / "quad_tiled.obj").write_text(quad_tiled())
    (MESHES / "ball.obj").write_text(ball())
    total = sum(p.stat().st_size for p in HERE.rglob("*") if p.is_file())
    print(f"wrote textures/ and meshes/; the folder is {total / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
