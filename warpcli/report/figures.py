"""Figures: a grid carried through the map, and distortion heatmaps with a legend."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..grid import clip_segments
from ..polygon import Polygon
from ..polygon.partition import Partition
from ..raster.pixels import to_unit
from ..raster.resample import resample

if TYPE_CHECKING:
    from ..raster.imageio import RasterImage

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
    if px.dtype == np.uint8 and alpha_channel is None:
        # Already 8-bit: the view is the pixels themselves (no float copy).
        return np.ascontiguousarray(np.repeat(px[:, :, :1], 3, axis=2) if px.shape[2] < 3 else px[:, :, :3])
    out = np.empty(px.shape[:2] + (3,), dtype=np.uint8)
    for r in range(0, px.shape[0], _rows(px.shape[1])):
        x = to_unit(px[r : r + _rows(px.shape[1])])
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
        out[r : r + len(x)] = np.round(rgb * 255).astype(np.uint8)
    return out


def _rows(width: int) -> int:
    """Rows per block so that a block holds about a million pixels."""
    return max(1, (1 << 20) // max(width, 1))


def stroke(height: int, width: int) -> int:
    """Width in pixels of grid lines and outlines: 1 up to 2000 px, growing with larger images."""
    return max(1, min(height, width) // 2000 + (1 if min(height, width) >= 2000 else 0))


def picture(rgb: NDArray[np.uint8]) -> RasterImage:
    """A figure as an image to write: large ones with fast PNG compression (they are diagnostics)."""
    from ..raster.imageio import RasterImage

    attrs = (("png:compressionLevel", "int", 1),) if rgb.shape[0] * rgb.shape[1] > (4 << 20) else ()
    return RasterImage(rgb, attributes=attrs)


def grid_figure(
    pixels: NDArray,
    inverse_map: NDArray[np.float64],
    src: Polygon | Partition,
    dst: Polygon | Partition,
    *,
    alpha_channel: int | None = None,
    spacing: int | None = None,
) -> NDArray[np.uint8]:
    """Input with a grid (left) beside the output with the same grid carried through the map.

    The gridded input is warped by the very map of the warp (``inverse_map``),
    so the right half shows where every grid line of the source goes. Polygon
    outlines are drawn on both halves; lines and outlines get wider on large
    images (`stroke`).

    Parameters
    ----------
    pixels : (H, W, C) ndarray
        The input image.
    inverse_map : (H2, W2, 2) ndarray of float
        Source point of every output pixel centre (NaN outside the target).
    src, dst : Polygon or Partition
        Drawn on each half: a polygon's outline, a cage mesh's faces.
    alpha_channel : int or None
    spacing : int or None
        Grid spacing in pixels; about a sixteenth of the image by default.

    Returns
    -------
    (max(H, H2), W + 8 + W2, 3) ndarray of uint8
    """
    gridded = display_rgb(pixels, alpha_channel).copy()
    h, w = gridded.shape[:2]
    step = spacing or max(8, int(round(min(h, w) / 16)))
    lw = stroke(h, w)
    rows = np.flatnonzero((np.arange(h) - step // 2) % step < lw)
    cols = np.flatnonzero((np.arange(w) - step // 2) % step < lw)
    # Each line pixel once: the rows whole, then the columns between them.
    gridded[rows] = _light(gridded[rows])
    between = np.setdiff1d(np.arange(h), rows)
    gridded[np.ix_(between, cols)] = _light(gridded[np.ix_(between, cols)])
    warped = resample(gridded, inverse_map, interp="linear", background=_OUTSIDE)
    left = _draw_shape(gridded, src)
    right = _draw_shape(warped, dst)
    return side_by_side(left, right)


def _draw_shape(img: NDArray[np.uint8], shape: Polygon | Partition) -> NDArray[np.uint8]:
    """A polygon's outline, or every face of a cage mesh."""
    if isinstance(shape, Partition):
        for k in range(shape.n_faces):
            img = draw_outline(img, shape.face_points(k), _OUTLINE)
        return img
    return draw_outline(img, shape.points, _OUTLINE)


def _light(rgb: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A grid line over the picture: a quarter of the picture, three quarters white."""
    return np.round(0.25 * rgb.astype(np.float64) + 0.75 * _GRID).astype(np.uint8)


def heatmap_figure(values: NDArray[np.float64], measure: str = "conformal") -> NDArray[np.uint8]:
    """Per-pixel distortion in colour, with a labelled colour bar.

    Parameters
    ----------
    values : (H, W) ndarray of float
        The measure at each output pixel, NaN outside the target.
    measure : {"conformal", "isometric", "det"}

    Returns
    -------
    (H, W + legend width, 3) ndarray of uint8
    """
    title, low, high, ticks = MEASURES[measure]
    rgb = np.empty(values.shape + (3,), dtype=np.uint8)
    step = _rows(values.shape[1])
    for r in range(0, values.shape[0], step):
        # A mirror map has negative determinants: colour by the area scale |det J|.
        v = np.abs(values[r : r + step]) if measure == "det" else values[r : r + step]
        block = rgb[r : r + step]
        block[:] = _OUTSIDE
        ok = np.isfinite(v) & (v > 0)
        block[ok] = colour(_unit(v[ok], low, high))
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

    # Everything scales with the picture (k = 1 up to 1000 px high).
    k = max(1, height // 1000)
    height = max(height, 120)
    width = 150 * k
    img = np.full((height, width, 3), 255, dtype=np.uint8)
    top, bottom = 30 * k, height - 14 * k
    bar = np.linspace(1.0, 0.0, bottom - top)
    img[top:bottom, 14 * k : 40 * k] = colour(bar)[:, None, :]
    size = 13 * k
    labels = []
    for tick in ticks:
        y = top + int(round((1.0 - _unit(np.array([tick]), low, high)[0]) * (bottom - top - 1)))
        img[y : y + k, 40 * k : 46 * k] = 0
        labels.append((y, f"{tick:g}" + ("+" if tick == ticks[-1] else "")))
    buf = oiio.ImageBuf(oiio.ImageSpec(width, height, 3, "uint8"))
    buf.set_pixels(oiio.ROI(), img)
    oiio.ImageBufAlgo.render_text(buf, 4 * k, 16 * k, title, size, "DroidSans", (0.0, 0.0, 0.0))
    for y, label in labels:
        oiio.ImageBufAlgo.render_text(buf, 50 * k, y + size // 2 - k, label, size, "DroidSans", (0.0, 0.0, 0.0))
    return np.asarray(buf.get_pixels(oiio.UINT8))


def draw_outline(img: NDArray[np.uint8], points: NDArray[np.float64], rgb) -> NDArray[np.uint8]:
    """A polygon's outline, 2 px wide, drawn onto a copy of an RGB image."""
    out = img.copy()
    h, w = out.shape[:2]
    pts = np.asarray(points, dtype=np.float64)
    # About 2 px wide, wider on large pictures.
    k = stroke(h, w)
    offsets = ((0.0, 0.0), (0.5, 0.0), (0.0, 0.5)) if k == 1 else tuple(
        (dx / 2, dy / 2) for dx in range(-k, k + 1) for dy in range(-k, k + 1)
    )
    # Only the part of each edge near the picture (a polygon may be far larger).
    d = np.roll(pts, -1, axis=0) - pts
    t_lo, t_hi = clip_segments(pts, d, (-2.0 * k - 2, -2.0 * k - 2, w + 2.0 * k + 2, h + 2.0 * k + 2))
    for a, b, lo, hi in zip(pts, np.roll(pts, -1, axis=0), t_lo, t_hi):
        if lo > hi:
            continue
        if lo > 0.0 or hi < 1.0:
            a, b = a + lo * (b - a), a + hi * (b - a)
        n = int(math.ceil(max(abs(b[0] - a[0]), abs(b[1] - a[1])) * 2)) + 2
        t = np.linspace(0.0, 1.0, n)[:, None]
        p = a + t * (b - a)
        # Pixel (r, c) covers [c, c+1] x [r, r+1].
        for dx, dy in offsets:
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
