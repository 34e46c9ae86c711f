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


#: The rocket's cage (scikit-image's ``rocket``, 640x427): a hexagon round its upper body, the
#: bottom edge fixed, the top edge moved 34 px to the right and the middle vertices 12 px: a bend.
ROCKET_CAGE = [[296, 300], [296, 205], [300, 112], [346, 112], [350, 205], [350, 300]]
ROCKET_BENT = [[296, 300], [308, 205], [334, 112], [380, 112], [362, 205], [350, 300]]


def within_figure() -> dict:
    """rocket_within.png: the rocket bent three ways, side by side, each captioned with its folds and seam.

    1. a single-cage retouch (``--outside input``): the cage pasted over the photograph;
    2. the same cage ``--within image``: the ring between the cage and the image's border mapped too;
    3. scikit-image's ThinPlateSplineTransform through the cage's vertices, with the image's corners
       and edge midpoints pinned.

    Folds: output pixels where the inverse map's Jacobian has det <= 0 (warpcli's from its
    Jacobians, the spline's by central differences on the pixel grid). Seam: the mean jump of
    neighbouring pixel values (0..255, largest over the channels) across the target cage's edges,
    against the mean jump elsewhere (`warpcli.report.seam.seam_jump`), and the largest jump across
    over the 99th percentile of the jumps elsewhere. Ghost: pixels of the source cage the target no longer covers, which keep the old
    picture beside the moved one. The numbers are written to rocket_within.json.
    """
    import skimage.data
    from skimage.transform import ThinPlateSplineTransform, warp

    from warpcli import warp_image
    from warpcli.grid import inside_polygon, pixel_centres
    from warpcli.report.figures import side_by_side
    from warpcli.report.seam import seam_jump

    rocket = skimage.data.rocket()
    h, w = rocket.shape[:2]
    src, dst = np.array(ROCKET_CAGE, dtype=float), np.array(ROCKET_BENT, dtype=float)
    write_json("rocket_cage.json", ROCKET_CAGE, "hexagon round the rocket's upper body in scikit-image's rocket (640x427)")
    write_json("rocket_cage_bent.json", ROCKET_BENT, "the same hexagon, its top edge moved 34 px right: the rocket bends")

    def det(jac: np.ndarray) -> np.ndarray:
        return jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]

    centres = pixel_centres(w, h)
    ghost = int((inside_polygon(centres, src) & ~inside_polygon(centres, dst)).sum())
    panels, numbers = [], {}
    retouch = warp_image(rocket, src, dst, outside="input")
    within = warp_image(rocket, src, dst, within="image")
    # The spline maps output points to input points (the inverse map, as warp() wants it), in
    # warpcli's coordinates (pixel centres at +0.5); pinned: the corners and edge midpoints.
    pins = np.array([[x, y] for x in (0, w / 2, w) for y in (0, h / 2, h) if (x, y) != (w / 2, h / 2)])
    tps = ThinPlateSplineTransform.from_estimate(np.concatenate([dst, pins]), np.concatenate([src, pins]))
    inverse = tps(centres).reshape(h, w, 2)
    spline = warp(rocket, lambda rc: tps(rc + 0.5) - 0.5, order=1, mode="edge", preserve_range=True)
    jx_col, jx_row = np.gradient(inverse[..., 0], axis=1), np.gradient(inverse[..., 0], axis=0)
    jy_col, jy_row = np.gradient(inverse[..., 1], axis=1), np.gradient(inverse[..., 1], axis=0)
    tps_det = jx_col * jy_row - jx_row * jy_col
    cases = (
        ("single-cage retouch", retouch.pixels, int(np.sum(det(retouch.jacobian) <= 0)), ghost),
        ("--within image", within.pixels, int(np.sum(det(within.jacobian) <= 0)), 0),
        ("thin-plate spline, corners pinned", spline, int(np.sum(tps_det <= 0)), 0),
    )
    for label, pixels, folds, vacated in cases:
        seam = seam_jump(np.asarray(pixels, dtype=float), dst)
        ratio = seam.across_max / seam.elsewhere_p99
        elsewhere_mean = float(seam.elsewhere.mean())
        numbers[label] = {
            "folds": folds, "ghost_pixels": vacated, "seam_across_max": round(seam.across_max, 2),
            "seam_across_mean": round(seam.across_mean, 2), "elsewhere_p99": round(seam.elsewhere_p99, 2),
            "elsewhere_mean": round(elsewhere_mean, 2), "seam_max_over_p99": round(ratio, 2),
        }  # fmt: skip
        crop = np.clip(np.asarray(pixels, dtype=float), 0, 255).astype(np.uint8)[40:427, 170:470]
        lines = [label, f"folds {folds}" + (f", ghost {vacated} px" if vacated else ""),
                 f"seam: jump {seam.across_mean:.1f} across, {elsewhere_mean:.1f} elsewhere"]  # fmt: skip
        panels.append(_captioned(crop, lines))
    figure = panels[0]
    for panel in panels[1:]:
        figure = side_by_side(figure, panel)
    write_png("rocket_within.png", figure)
    with open(os.path.join(HERE, "rocket_within.json"), "w") as fh:
        json.dump(numbers, fh, indent=1)
        fh.write("\n")
    return numbers


def _captioned(rgb: np.ndarray, lines: list) -> np.ndarray:
    """The picture with lines of text below it (OpenImageIO's text)."""
    import OpenImageIO as oiio

    h, w = rgb.shape[:2]
    size = 15
    out = np.full((h + 8 + (size + 4) * len(lines), w, 3), 255, dtype=np.uint8)
    out[:h] = rgb
    buf = oiio.ImageBuf(oiio.ImageSpec(w, out.shape[0], 3, "uint8"))
    buf.set_pixels(oiio.ROI(), out)
    for k, line in enumerate(lines):
        oiio.ImageBufAlgo.render_text(buf, 4, h + 4 + (size + 4) * (k + 1) - 4, line, size, "DroidSans", (0.0, 0.0, 0.0))
    return np.asarray(buf.get_pixels(oiio.UINT8))


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
    within_figure()


if __name__ == "__main__":
    main()
