"""Regenerate the sample images, polygon pairs and the README's pictures in this folder.

    pip install '.[test]' && python sample_images/make_samples.py

grid.png is drawn here; chelsea.png is copied from scikit-image's data
(CC0, photographer Stefan van der Walt). before_after.png is made by running
the installed ``warp`` on the samples.
"""

from __future__ import annotations

import json
import math
import os
import shutil

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def grid_image(size: int = 512, step: int = 32) -> np.ndarray:
    """A colour ramp with black grid lines every ``step`` pixels and a 4x4 checker."""
    y, x = np.mgrid[0:size, 0:size] / (size - 1)
    img = np.stack([0.25 + 0.7 * x, 0.35 + 0.5 * y, 0.9 - 0.6 * x * y], axis=2)
    r, c = np.mgrid[0:size, 0:size]
    checker = ((r // (size // 4)) + (c // (size // 4))) % 2 == 0
    img[checker] *= 0.8
    lines = (r % step < 2) | (c % step < 2)
    img[lines] = 0.05
    return np.round(img * 255).astype(np.uint8)


def star(n: int, cx: float, cy: float, r_in: float, r_out: float, phase: float) -> list:
    pts = []
    for k in range(2 * n):
        r = r_out if k % 2 == 0 else r_in
        a = phase + math.pi * k / n
        pts.append([round(cx + r * math.cos(a), 2), round(cy + r * math.sin(a), 2)])
    return pts


def ring(n: int, cx: float, cy: float, rx: float, ry: float, phase: float) -> list:
    return [
        [round(cx + rx * math.cos(phase + 2 * math.pi * k / n), 2), round(cy + ry * math.sin(phase + 2 * math.pi * k / n), 2)]
        for k in range(n)
    ]


def write_json(name: str, points: list, note: str) -> None:
    with open(os.path.join(HERE, name), "w") as fh:
        json.dump({"note": note, "points": points}, fh, indent=1)
        fh.write("\n")


def write_png(name: str, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(os.path.join(HERE, name))
    out.open(os.path.join(HERE, name), oiio.ImageSpec(w, h, c, "uint8"))
    out.write_image(pixels)
    out.close()


def outline(pixels: np.ndarray, points: list, colour=(255, 40, 160)) -> np.ndarray:
    """Draw a polygon's outline (3 px) onto a copy of an RGB image."""
    from skimage.draw import line

    out = pixels.copy()
    # Pixel (r, c) has its centre at (c + 0.5, r + 0.5).
    rc = np.round(np.asarray(points)[:, ::-1] - 0.5).astype(int)
    for a, b in zip(rc, np.roll(rc, -1, axis=0)):
        rr, cc = line(a[0], a[1], b[0], b[1])
        for dr, dc in ((0, 0), (1, 0), (0, 1), (-1, 0), (0, -1)):  # 3 px wide
            r, c = rr + dr, cc + dc
            keep = (r >= 0) & (r < out.shape[0]) & (c >= 0) & (c < out.shape[1])
            out[r[keep], c[keep]] = colour
    return out


def read_rgb(path: str) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(path)
    px = inp.read_image(oiio.UINT8)
    inp.close()
    return px[:, :, :3]


def readme_figure() -> None:
    """before_after.png: each sample with its source polygon, then the warp result."""
    import subprocess
    import sys
    import tempfile

    rows = []
    pairs = [("grid.png", "grid_L.json", "grid_hexagon.json"), ("chelsea.png", "chelsea_ring.json", "chelsea_star.json")]
    with tempfile.TemporaryDirectory() as tmp:
        for image, src, dst in pairs:
            out = os.path.join(tmp, "out.png")
            subprocess.run(
                [sys.executable, "-m", "warpcli", os.path.join(HERE, image), "--src", os.path.join(HERE, src),
                 "--dst", os.path.join(HERE, dst), "-q", out],
                check=True,
            )
            load = lambda name: json.load(open(os.path.join(HERE, name)))["points"]  # noqa: E731
            before = outline(read_rgb(os.path.join(HERE, image)), load(src))
            after = outline(read_rgb(out), load(dst))
            scale = 300 / before.shape[0]
            rows.append(np.concatenate([_resize(before, scale), np.full((300, 8, 3), 255, np.uint8), _resize(after, scale)], axis=1))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 8), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    write_png("before_after.png", np.concatenate(rows, axis=0)[:-8])


def map_pictures() -> None:
    """<sample>_grid.png and <sample>_heatmap.png: warp's own --grid and --heatmap output."""
    import subprocess
    import sys
    import tempfile

    pairs = [("grid", "grid.png", "grid_L.json", "grid_hexagon.json"), ("chelsea", "chelsea.png", "chelsea_ring.json", "chelsea_star.json")]
    with tempfile.TemporaryDirectory() as tmp:
        for name, image, src, dst in pairs:
            subprocess.run(
                [sys.executable, "-m", "warpcli", os.path.join(HERE, image), os.path.join(tmp, "out.png"),
                 "--src", os.path.join(HERE, src), "--dst", os.path.join(HERE, dst), "-q",
                 "--grid", os.path.join(HERE, f"{name}_grid.png"),
                 "--heatmap", os.path.join(HERE, f"{name}_heatmap.png")],
                check=True,
            )


def _resize(px: np.ndarray, scale: float) -> np.ndarray:
    h, w = px.shape[:2]
    r = np.minimum((np.arange(round(h * scale)) / scale).astype(int), h - 1)
    c = np.minimum((np.arange(round(w * scale)) / scale).astype(int), w - 1)
    return px[r][:, c]


def main() -> None:
    write_png("grid.png", grid_image())
    # An L-shaped source (one reflex corner) goes onto a regular hexagon.
    write_json(
        "grid_L.json",
        [[40.5, 40.5], [300.5, 40.5], [300.5, 260.5], [470.5, 260.5], [470.5, 470.5], [40.5, 470.5]],
        "L shape in grid.png (512x512)",
    )
    write_json(
        "grid_hexagon.json",
        ring(6, 256, 256, 230, 230, -2 * math.pi / 3),
        "regular hexagon, same vertex count as grid_L.json",
    )
    import skimage.data

    src = os.path.join(os.path.dirname(skimage.data.__file__), "chelsea.png")
    shutil.copyfile(src, os.path.join(HERE, "chelsea.png"))
    # Chelsea (451x300): a 12-gon around the cat goes onto a 6-pointed star.
    write_json("chelsea_ring.json", ring(12, 225.5, 150, 215, 145, -math.pi / 2), "ellipse-like 12-gon in chelsea.png (451x300)")
    write_json("chelsea_star.json", star(6, 225.5, 150, 70, 148, -math.pi / 2), "6-pointed star (12 vertices)")
    readme_figure()
    map_pictures()


if __name__ == "__main__":
    main()
