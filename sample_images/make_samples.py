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


def write_png(path: str, pixels: np.ndarray) -> None:
    """Write 8-bit pixels (H, W, C) as a PNG (a bare name lands in this folder)."""
    import OpenImageIO as oiio

    path = os.path.join(HERE, path)
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(path)
    out.open(path, oiio.ImageSpec(w, h, c, "uint8"))
    out.write_image(pixels)
    out.close()


#: (name, image, source polygon, target polygon) of each sample.
SAMPLES = (
    ("grid", "grid.png", "grid_L.json", "grid_hexagon.json"),
    ("chelsea", "chelsea.png", "chelsea_ring.json", "chelsea_star.json"),
)


def _warp(image: str, src: str, dst: str, out: str, *extra: str) -> None:
    import subprocess
    import sys

    subprocess.run(
        [sys.executable, "-m", "warpcli", os.path.join(HERE, image), out,
         "--src", os.path.join(HERE, src), "--dst", os.path.join(HERE, dst), "-q", *extra],
        check=True,
    )  # fmt: skip


def readme_figure() -> None:
    """before_after.png: each sample with its source polygon, then the warp result."""
    import tempfile

    from warpcli.raster.imageio import read_image
    from warpcli.report.figures import display_rgb, draw_outline, side_by_side

    def picture(path: str, polygon: str) -> np.ndarray:
        """The image at 300 px tall, with the polygon's outline drawn at that size."""
        img = read_image(path)
        scale = 300 / img.height
        points = np.asarray(json.load(open(os.path.join(HERE, polygon)))["points"]) * scale
        return draw_outline(_resize(display_rgb(img.pixels, img.alpha_channel), scale), points, (255, 40, 160))

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for _, image, src, dst in SAMPLES:
            out = os.path.join(tmp, "out.png")
            _warp(image, src, dst, out)
            rows.append(side_by_side(picture(os.path.join(HERE, image), src), picture(out, dst)))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 8), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    write_png("before_after.png", np.concatenate(rows, axis=0)[:-8])


def retouch_figure() -> None:
    """retouch.png: a small polygon around Chelsea's left eye, its inner side pulled towards the
    nose, pasted over the photograph (``--outside input``): before | after."""
    import tempfile

    from warpcli.raster.imageio import read_image
    from warpcli.report.figures import display_rgb, side_by_side

    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "out.png")
        _warp("chelsea.png", "chelsea_eye.json", "chelsea_eye_wide.json", out, "--outside", "input")
        before = display_rgb(read_image(os.path.join(HERE, "chelsea.png")).pixels, None)
        after = display_rgb(read_image(out).pixels, None)
        write_png("retouch.png", side_by_side(before, after))


def map_pictures() -> None:
    """<sample>_grid.png and <sample>_heatmap.png: warp's own --grid and --heatmap output."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        for name, image, src, dst in SAMPLES:
            _warp(image, src, dst, os.path.join(tmp, "out.png"),
                  "--grid", os.path.join(HERE, f"{name}_grid.png"),
                  "--heatmap", os.path.join(HERE, f"{name}_heatmap.png"))  # fmt: skip


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
    # A retouch: an octagon around the left eye; the three vertices on the nose's side move
    # towards it, the other five stay put, and the warp is pasted over the photograph.
    eye = ring(8, 172, 116, 64, 50, 0.0)
    wide = [list(p) for p in eye]
    for k, dx in ((0, 24.0), (1, 12.0), (7, 12.0)):
        wide[k][0] = round(wide[k][0] + dx, 2)
    write_json("chelsea_eye.json", eye, "octagon around the left eye in chelsea.png (451x300)")
    write_json("chelsea_eye_wide.json", wide, "the same octagon, its three vertices nearest the nose moved right")
    readme_figure()
    retouch_figure()
    map_pictures()


if __name__ == "__main__":
    main()
