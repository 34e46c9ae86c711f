"""Regenerate the sample images and polygon pairs in this folder.

    python sample_images/make_samples.py

grid.png is drawn here; chelsea.png is copied from scikit-image's data
(CC0, photographer Stefan van der Walt). The polygons are written out so that
each vertex pair is easy to read and edit.
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


def main() -> None:
    write_png("grid.png", grid_image())
    # An L-shaped source goes onto a 6-pointed... no: onto a plain hexagon-like
    # convex target, and back: both directions show the concave corner.
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


if __name__ == "__main__":
    main()
