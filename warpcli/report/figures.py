"""Figures: a grid carried through the map, and distortion heatmaps with a legend."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..polygon import Polygon
from ..raster.pixels import to_unit
from ..raster.resample import resample

# Viridis, sampled at nine evenly spaced points (perceptually uniform,
# readable in grey and by colour-blind viewers).
_VIRIDIS = np.array(
    [
        [68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
        [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37],
    ],
    dtype=np.float64,
)  # fmt: skip

#: Heatmap measures: (title, low, high, ticks); colours run on a log scale
#: from low to high, values beyond are clamped (the paper clamps at 10).
MEASURES = {
    "conformal": ("conformal distortion", 2.0, 10.0, (2, 3, 5, 10)),
    "isometric": ("isometric distortion", 1.0, 10.0, (1, 2, 5, 10)),
    "det": ("det J (area scale)", 0.1, 10.0, (0.1, 0.3, 1, 3, 10)),
}

_OUTSIDE = np.array([40, 40, 40], dtype=np.uint8)
_GRID = np.array([255, 255, 255], dtype=np.float64)
_OUTLINE = (255, 40, 160)


def display_rgb(pixels: NDArray, alpha_channel: int | None = None) -> NDArray[np.uint8]:
    """An 8-bit RGB view of any image: integers scaled, floats clipped to 0..1,
    grey replicated, alpha composited over mid grey."""
    px = np.asarray(pixels)
    if px.ndim == 2:
        px = px[:, :, None]
    x = to_unit(px)
    if not np.issubdtype(px.dtype, np.integer):
        x = np.clip(np.nan_to_num(x), 0.0, 1.0)
    a = None
    if alpha_channel is not None:
        a = x[:, :, alpha_channel : alpha_channel + 1]
        x = np.delete(x, alpha_channel, axis=2)
    if x.shape[2] == 0:
        x = np.zeros(x.shape[:2] + (1,))
    rgb = np.repeat(x[:, :, :1], 3, axis=2) if x.shape[2] < 3 else x[:, :, :3]
    if a is not None:
        rgb = rgb * a + 0.5 * (1.0 - a)
    return np.round(rgb * 255).astype(np.uint8)


def grid_figure(
    pixels: NDArray,
    inverse_map: NDArray[np.float64],
    src: Polygon,
    dst: Polygon,
    *,
    alpha_channel: int | None = None,
    spacing: int | None = None,
) -> NDArray[np.uint8]:
    """Input with a grid (left) beside the output with the same grid carried through the map.

    The gridded input is warped by the very map of the warp (``inverse_map``),
    so the right half shows where every grid line of the source goes. Polygon
    outlines are drawn on both halves.

    Returns
    -------
    (H, W, 3) ndarray of uint8
    """
    base = display_rgb(pixels, alpha_channel).astype(np.float64)
    h, w = base.shape[:2]
    step = spacing or max(8, int(round(min(h, w) / 16)))
    r = np.arange(h)[:, None]
    c = np.arange(w)[None, :]
    lines = ((r % step) == step // 2) | ((c % step) == step // 2)
    base[lines] = 0.25 * base[lines] + 0.75 * _GRID
    gridded = np.round(base).astype(np.uint8)
    warped = resample(gridded, inverse_map, interp="linear", background=_OUTSIDE)
    left = draw_outline(gridded, src.points, _OUTLINE)
    right = draw_outline(warped, dst.points, _OUTLINE)
    return side_by_side(left, right)


def heatmap_figure(values: NDArray[np.float64], measure: str = "conformal") -> NDArray[np.uint8]:
    """Per-pixel distortion in colour, with a labelled colour bar.

    Parameters
    ----------
    values : (H, W) ndarray of float
        The measure at each output pixel, NaN outside the target.
    measure : {"conformal", "isometric", "det"}
    """
    title, low, high, ticks = MEASURES[measure]
    # A mirror map has negative determinants: colour by the area scale |det J|.
    v = np.abs(values) if measure == "det" else values
    rgb = np.empty(values.shape + (3,), dtype=np.uint8)
    rgb[:] = _OUTSIDE
    ok = np.isfinite(v) & (v > 0)
    rgb[ok] = colour(_unit(v[ok], low, high))
    return side_by_side(rgb, _legend(values.shape[0], title, low, high, ticks), gap=0, fill=255)


def colour(t: NDArray[np.float64]) -> NDArray[np.uint8]:
    """Viridis colours for values in [0, 1].

    >>> colour(np.array([0.0, 1.0])).tolist()
    [[68, 1, 84], [253, 231, 37]]
    """
    x = np.clip(t, 0.0, 1.0) * (len(_VIRIDIS) - 1)
    i = np.minimum(x.astype(int), len(_VIRIDIS) - 2)
    f = (x - i)[..., None]
    return np.round(_VIRIDIS[i] * (1 - f) + _VIRIDIS[i + 1] * f).astype(np.uint8)


def _unit(v, low, high):
    return (np.log(np.clip(v, low, high)) - math.log(low)) / (math.log(high) - math.log(low))


def _legend(height: int, title: str, low: float, high: float, ticks) -> NDArray[np.uint8]:
    """A vertical colour bar, high values at the top, with tick labels (OpenImageIO text)."""
    import OpenImageIO as oiio

    height = max(height, 120)
    width = 150
    img = np.full((height, width, 3), 255, dtype=np.uint8)
    top, bottom = 30, height - 14
    bar = np.linspace(1.0, 0.0, bottom - top)
    img[top:bottom, 14:40] = colour(bar)[:, None, :]
    size = 13
    labels = []
    for tick in ticks:
        y = top + int(round((1.0 - _unit(np.array([tick]), low, high)[0]) * (bottom - top - 1)))
        img[y, 40:46] = 0
        labels.append((y, f"{tick:g}" + ("+" if tick == ticks[-1] else "")))
    buf = oiio.ImageBuf(oiio.ImageSpec(width, height, 3, "uint8"))
    buf.set_pixels(oiio.ROI(), img)
    oiio.ImageBufAlgo.render_text(buf, 4, 16, title, size, "DroidSans", (0.0, 0.0, 0.0))
    for y, label in labels:
        oiio.ImageBufAlgo.render_text(buf, 50, y + size // 2 - 1, label, size, "DroidSans", (0.0, 0.0, 0.0))
    return np.asarray(buf.get_pixels(oiio.UINT8))


def draw_outline(img: NDArray[np.uint8], points: NDArray[np.float64], rgb) -> NDArray[np.uint8]:
    """A polygon's outline, 2 px wide, drawn onto a copy of an RGB image."""
    out = img.copy()
    h, w = out.shape[:2]
    pts = np.asarray(points, dtype=np.float64)
    for a, b in zip(pts, np.roll(pts, -1, axis=0)):
        n = int(math.ceil(max(abs(b[0] - a[0]), abs(b[1] - a[1])) * 2)) + 2
        t = np.linspace(0.0, 1.0, n)[:, None]
        p = a + t * (b - a)
        # Pixel (r, c) covers [c, c+1] x [r, r+1].
        for dx, dy in ((0.0, 0.0), (0.5, 0.0), (0.0, 0.5)):
            col = np.floor(p[:, 0] + dx).astype(int)
            row = np.floor(p[:, 1] + dy).astype(int)
            ok = (col >= 0) & (col < w) & (row >= 0) & (row < h)
            out[row[ok], col[ok]] = rgb
    return out


def side_by_side(left: NDArray[np.uint8], right: NDArray[np.uint8], gap: int = 8, fill: int = 255) -> NDArray[np.uint8]:
    """Two RGB images next to each other, top-aligned, on a plain background."""
    h = max(left.shape[0], right.shape[0])
    out = np.full((h, left.shape[1] + gap + right.shape[1], 3), fill, dtype=np.uint8)
    out[: left.shape[0], : left.shape[1]] = left
    out[: right.shape[0], left.shape[1] + gap :] = right
    return out
