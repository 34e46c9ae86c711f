"""Pasting a warped region back over its image (``--outside input``), as GIMP's cage transform does.

The warp of the target polygon is made in premultiplied colour with one extra
channel of 1s, against a background of 0s: that channel comes out as the
target's coverage (1 inside, the antialiased share along its edge, 0
outside), and the output is ``warp + (1 - coverage) * base`` (the image's own
alpha blends like a colour, so an identity warp gives the input back), with
the base:

- ``--vacated keep``: the base is the input itself, so the part of the source
  polygon the target no longer covers keeps the original pixels;
- ``--vacated background``: the base is the input with the source polygon
  filled with the background colour (antialiased along the source's edge), so
  the vacated part shows the background, GIMP's "fill the original position".

Everything is blended in premultiplied float and converted to the input's
type once, at the end (rounded half to even and clipped, like a plain warp).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError
from .grid import window
from .options import VACATED


def polygon_coverage(vertices: ArrayLike, width: int, height: int) -> NDArray[np.float32]:
    """The share of each pixel of a ``width`` x ``height`` grid inside a polygon, antialiased.

    Pixel centres inside (even-odd rule, by a scanline fill over the polygon's
    window: the cost grows with the window's area and the edges' crossings of
    its rows, not with the polygon's coordinates) count 1; pixels along the
    boundary get the distance-field coverage of
    `warpcli.raster.resample.edge_coverage`, the same as the target's edge.

    Parameters
    ----------
    vertices : (n, 2) array_like of float
        The polygon, in the grid's continuous coordinates.
    width, height : int

    Returns
    -------
    (height, width) ndarray of float32
        Coverage in [0, 1].
    """
    from .raster.resample import edge_coverage

    v = np.asarray(vertices, dtype=np.float64)
    out = np.zeros((height, width), dtype=np.float32)
    lo, hi = v.min(axis=0), v.max(axis=0)
    r0, r1, c0, c1 = window((lo[0], lo[1], hi[0], hi[1]), width, height)
    if r0 >= r1 or c0 >= c1:
        return out
    inside = _scanline_inside(v, r0, r1, c0, c1)
    cov = inside.astype(np.float32)
    edge = edge_coverage(v, inside, (r0, c0))
    cov.ravel()[edge.pixels] = edge.fraction
    out[r0:r1, c0:c1] = cov
    return out


def _scanline_inside(v: NDArray[np.float64], r0: int, r1: int, c0: int, c1: int) -> NDArray[np.bool_]:
    """Whether each pixel centre of rows r0..r1, columns c0..c1 lies inside the polygon (even-odd)."""
    h, w = r1 - r0, c1 - c0
    a = v
    b = np.roll(v, -1, axis=0)
    ylo, yhi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    # Rows whose centre y = r + 0.5 satisfies ylo <= y < yhi (half-open: a vertex counts once).
    first = np.clip(np.ceil(ylo - 0.5).astype(np.int64), r0, r1)
    last = np.clip(np.ceil(yhi - 0.5).astype(np.int64), r0, r1)  # exclusive
    count = np.maximum(last - first, 0)
    edge = np.repeat(np.arange(len(v)), count)
    offset = np.arange(edge.size) - np.repeat(np.cumsum(count) - count, count)
    row = np.repeat(first, count) + offset
    y = row + 0.5
    t = (y - a[edge, 1]) / (b[edge, 1] - a[edge, 1])
    x = a[edge, 0] + t * (b[edge, 0] - a[edge, 0])
    # A crossing at x toggles every pixel whose centre c + 0.5 lies right of it.
    col = np.clip(np.floor(x + 0.5).astype(np.int64), c0, c1) - c0
    toggles = np.zeros((h, w + 1), dtype=np.uint8)
    np.add.at(toggles, (row - r0, col), 1)
    return (np.cumsum(toggles[:, :w], axis=1, dtype=np.int64) & 1).astype(bool)


def paste_over(
    image: NDArray,
    warp: Callable[[NDArray, int], NDArray],
    *,
    src: ArrayLike,
    background: ArrayLike,
    alpha_channel: int | None,
    associated_alpha: bool,
    vacated: str = "keep",
) -> NDArray:
    """The warped region composited over the input (``--outside input``).

    Parameters
    ----------
    image : (H, W, C) ndarray
        The input pixels; the output has the same size.
    warp : callable
        ``warp(pixels, carrier)`` resamples a (H, W, C + 1) float image (the
        input in premultiplied colour, then a channel of 1s, ``carrier`` = C)
        against a background of 0, the target's edge coverage applied to
        every channel (``resample(..., alpha_channel=carrier,
        associated_alpha=True, background=0)``), into the (H, W, C + 1)
        output. The carrier comes out as the target's coverage.
    src : (n, 2) array_like of float
        The source polygon (for ``vacated="background"``).
    background : float or (C,) array_like of float
        The fill of the vacated area, in the image's units.
    alpha_channel : int or None
        The input's alpha channel, if it has one.
    associated_alpha : bool
        Whether the input's colour is premultiplied.
    vacated : {"keep", "background"}
        See the module docstring.

    Returns
    -------
    (H, W, C) ndarray of the input's dtype

    Raises
    ------
    InputError
        If ``vacated`` is unknown.
    """
    from .raster.pixels import unit
    from .raster.resample import _to_dtype

    if vacated not in VACATED:
        raise InputError(f"unknown --vacated {vacated!r}; choose one of {', '.join(VACATED)}")
    h, w, nc = image.shape
    scale = float(unit(image.dtype))
    work = np.float64 if image.dtype == np.float64 else np.float32
    straight = alpha_channel is not None and not associated_alpha
    base = image.astype(work)
    if straight:
        _multiply_colour(base, base[:, :, alpha_channel] / scale, alpha_channel)
    # One more channel, constant 1, that only the target's coverage changes.
    carrier = np.concatenate([base, np.full((h, w, 1), scale, dtype=work)], axis=2)
    warped = warp(carrier, nc)
    del carrier
    cov = warped[:, :, nc:] / scale
    untouched = cov[:, :, 0] == 0
    if vacated == "background":
        bg = np.broadcast_to(np.asarray(background, dtype=np.float64), (nc,)).astype(work)[None, None, :].copy()
        if straight:
            _multiply_colour(bg, bg[:, :, alpha_channel] / scale, alpha_channel)
        s = polygon_coverage(src, w, h)
        untouched &= s == 0
        s = s[:, :, None]
        base *= 1 - s
        base += bg * s
    out = warped[:, :, :nc]
    out += base * (1 - cov)
    if straight:
        alpha = out[:, :, alpha_channel] / scale
        with np.errstate(divide="ignore", invalid="ignore"):
            _multiply_colour(out, np.where(alpha > 0, 1.0 / alpha, 0.0).astype(work), alpha_channel)
    out = _to_dtype(np.ascontiguousarray(out), image.dtype)
    # Pixels neither warped onto nor vacated are the input's, bit for bit.
    out[untouched] = image[untouched]
    return out


def _multiply_colour(pixels: NDArray, factor: NDArray, alpha_channel: int) -> None:
    """Every channel but alpha times ``factor`` (H, W), in place."""
    for c in range(pixels.shape[2]):
        if c != alpha_channel:
            pixels[:, :, c] *= factor
