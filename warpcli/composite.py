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

With a feather of F pixels (``--feather F``) the warp is blended into the
base over a band F pixels wide inside the target's edge, as GIMP and
Photoshop feather a selection: the output is ``w * warp + (1 - w * coverage)
* base`` with ``w = smoothstep(d / F)`` (``3 s^2 - 2 s^3``, s clipped to
[0, 1]) at a pixel centre at distance d inside the target, 0 at centres
outside it (`feather_weights`). It hides a seam; it does not remove it: the
map still jumps at the target's edge, the band shows both images at once
(a ghost where they differ). A retouch within a fixed outline (``--within``)
maps the whole picture continuously and is the seamless choice.

`whole_image_map` is the map of such a retouch as points (identity outside
the target), for ``--save-map``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError
from .grid import window
from .options import VACATED


def polygon_coverage(
    vertices: ArrayLike, width: int, height: int, *, rows: tuple[int, int] | None = None
) -> NDArray[np.float32]:
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
    rows : (int, int) or None
        Only rows ``start <= r < stop`` (a strip).

    Returns
    -------
    (height, width) ndarray of float32
        Coverage in [0, 1] (with ``rows``: the strip's rows only).
    """
    from .raster.resample import edge_coverage

    v = np.asarray(vertices, dtype=np.float64)
    r_lo, r_hi = (0, height) if rows is None else rows
    out = np.zeros((r_hi - r_lo, width), dtype=np.float32)
    lo, hi = v.min(axis=0), v.max(axis=0)
    r0, r1, c0, c1 = window((lo[0], lo[1], hi[0], hi[1]), width, height)
    r0, r1 = max(r0, r_lo), min(r1, r_hi)
    if r0 >= r1 or c0 >= c1:
        return out
    inside = _scanline_inside(v, r0, r1, c0, c1)
    cov = inside.astype(np.float32)
    edge = edge_coverage(v, inside, (r0, c0))
    cov.ravel()[edge.pixels] = edge.fraction
    out[r0 - r_lo : r1 - r_lo, c0:c1] = cov
    return out


def feather_weights(
    vertices: ArrayLike, width: int, height: int, band: float, *, rows: tuple[int, int] | None = None
) -> NDArray[np.float32]:
    """The feather's weight of the warp at every pixel centre: ``smoothstep(d / band)`` inside, 0 outside.

    ``d`` is the exact Euclidean distance from the pixel centre to the
    polygon's boundary (the nearest point of its nearest edge), computed only
    for the pixels within ``band`` of an edge: for each edge and each row it
    reaches, the columns within ``band`` of the part of the edge that comes
    within ``band`` of the row, so the cost grows with the band's pixels (a
    few times them), not with the polygon's area. Pixels farther inside get 1.

    Parameters
    ----------
    vertices : (n, 2) array_like of float
        The target polygon, in the grid's continuous coordinates.
    width, height : int
        The grid.
    band : float
        The band's width in pixels, > 0.
    rows : (int, int) or None
        Only rows ``start <= r < stop`` (a strip; the values are the whole
        grid's).

    Returns
    -------
    (rows, width) ndarray of float32
        Weights in [0, 1].

    Examples
    --------
    >>> w = feather_weights([[0, 0], [8, 0], [8, 8], [0, 8]], 8, 8, 2.0)
    >>> [round(float(x), 4) for x in w[3, :4]]  # d = 0.5, 1.5, 2.5, 3.5
    [0.1562, 0.8438, 1.0, 1.0]
    """
    v = np.asarray(vertices, dtype=np.float64)
    r_lo, r_hi = (0, height) if rows is None else rows
    out = np.zeros((r_hi - r_lo, width), dtype=np.float32)
    lo, hi = v.min(axis=0), v.max(axis=0)
    r0, r1, c0, c1 = window((lo[0], lo[1], hi[0], hi[1]), width, height)
    r0, r1 = max(r0, r_lo), min(r1, r_hi)
    if r0 >= r1 or c0 >= c1 or not band > 0:
        return out
    inside = _scanline_inside(v, r0, r1, c0, c1)
    h, w = r1 - r0, c1 - c0
    dist = np.full(h * w, np.inf)
    a, b = v, np.roll(v, -1, axis=0)
    # (edge, row) pairs: rows whose centre is within `band` of the edge's y range.
    ylo, yhi = np.minimum(a[:, 1], b[:, 1]) - band, np.maximum(a[:, 1], b[:, 1]) + band
    first = np.clip(np.ceil(ylo - 0.5).astype(np.int64), r0, r1)
    last = np.clip(np.floor(yhi - 0.5).astype(np.int64) + 1, r0, r1)
    count = np.maximum(last - first, 0)
    edge = np.repeat(np.arange(len(v)), count)
    row = np.repeat(first, count) + np.arange(edge.size) - np.repeat(np.cumsum(count) - count, count)
    y = row + 0.5
    ea, eb = a[edge], b[edge]
    dy = eb[:, 1] - ea[:, 1]
    # The part of the edge within `band` of the row vertically: parameters t0..t1.
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = np.where(dy != 0, (y - band - ea[:, 1]) / dy, 0.0)
        tb = np.where(dy != 0, (y + band - ea[:, 1]) / dy, 1.0)
    t0 = np.clip(np.minimum(ta, tb), 0.0, 1.0)
    t1 = np.clip(np.maximum(ta, tb), 0.0, 1.0)
    xa = ea[:, 0] + t0 * (eb[:, 0] - ea[:, 0])
    xb = ea[:, 0] + t1 * (eb[:, 0] - ea[:, 0])
    x_lo, x_hi = np.minimum(xa, xb) - band, np.maximum(xa, xb) + band
    col0 = np.clip(np.ceil(x_lo - 0.5).astype(np.int64), c0, c1)
    col1 = np.clip(np.floor(x_hi - 0.5).astype(np.int64) + 1, c0, c1)
    span = np.maximum(col1 - col0, 0)
    pair = np.repeat(np.arange(edge.size), span)
    col = np.repeat(col0, span) + np.arange(pair.size) - np.repeat(np.cumsum(span) - span, span)
    if pair.size:
        from .polygon.predicates import point_segment_distance

        p = np.stack([col + 0.5, row[pair] + 0.5], axis=1)
        d = point_segment_distance(p, ea[pair], eb[pair])
        np.minimum.at(dist, (row[pair] - r0) * w + (col - c0), d)
    s = np.clip(dist.reshape(h, w) / band, 0.0, 1.0)
    weight = np.where(inside, s * s * (3.0 - 2.0 * s), 0.0)
    out[r0 - r_lo : r1 - r_lo, c0:c1] = weight
    return out


def whole_image_map(
    points: NDArray[np.float64], *, src: ArrayLike | None = None, vacated: str = "keep"
) -> NDArray[np.float64]:
    """The map of a retouch (``outside="input"``) over the whole image: the warp's points inside the target, identity elsewhere.

    A map cannot blend: a pixel of the target's edge takes the warp's point
    if its centre is inside the target (as ``points`` says), the identity
    otherwise; with ``vacated="background"`` the pixels whose centres lie in
    the source polygon but not in the target have no point (NaN: applying
    the map gives them the background, without the paste's antialiased edge).
    A feather's blend is not in the map either.

    Parameters
    ----------
    points : (H, W, 2) ndarray of float
        The warp's source point of every pixel centre (NaN outside the target).
    src : (n, 2) array_like of float or None
        The source polygon (for ``vacated="background"``).
    vacated : {"keep", "background"}

    Returns
    -------
    (H, W, 2) ndarray of float

    Raises
    ------
    InputError
        If ``vacated`` is unknown, or ``"background"`` without ``src``.

    Examples
    --------
    >>> pts = np.full((1, 3, 2), np.nan)
    >>> pts[0, 1] = [7.0, 0.25]
    >>> whole_image_map(pts)[0].tolist()
    [[0.5, 0.5], [7.0, 0.25], [2.5, 0.5]]
    """
    if vacated not in VACATED:
        raise InputError(f"unknown --vacated {vacated!r}; choose one of {', '.join(VACATED)}")
    h, w = points.shape[:2]
    out = np.array(points, dtype=np.float64)
    free = ~np.isfinite(out).all(axis=2)
    ys, xs = np.mgrid[0:h, 0:w]
    out[..., 0] = np.where(free, xs + 0.5, out[..., 0])
    out[..., 1] = np.where(free, ys + 0.5, out[..., 1])
    if vacated == "background":
        if src is None:
            raise InputError("vacated='background' needs the source polygon")
        v = np.asarray(src, dtype=np.float64)
        lo, hi = v.min(axis=0), v.max(axis=0)
        r0, r1, c0, c1 = window((lo[0], lo[1], hi[0], hi[1]), w, h)
        if r0 < r1 and c0 < c1:
            vacant = np.zeros((h, w), dtype=bool)
            vacant[r0:r1, c0:c1] = _scanline_inside(v, r0, r1, c0, c1)
            out[vacant & free] = np.nan
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
    feather: float = 0.0,
    dst: ArrayLike | None = None,
    rows: tuple[int, int] | None = None,
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
    feather : float
        The width in pixels of the band inside the target's edge over which
        the warp is blended into the base (0: none; see the module docstring).
    dst : (n, 2) array_like of float or None
        The target polygon (for ``feather``).
    rows : (int, int) or None
        ``image`` is rows ``start <= r < stop`` of the image (a strip of a
        warp in parts), and ``warp`` gives those rows of the warp.

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
    y0, y1 = (0, h) if rows is None else rows
    scale = float(unit(image.dtype))
    work = np.float64 if image.dtype == np.float64 else np.float32
    straight = alpha_channel is not None and not associated_alpha
    carrier = carrier_pixels(image, alpha_channel, associated_alpha)
    base = carrier[:, :, :nc].copy()
    warped = warp(carrier, nc)
    del carrier
    cov = warped[:, :, nc:] / scale
    untouched = cov[:, :, 0] == 0
    if vacated == "background":
        bg = np.broadcast_to(np.asarray(background, dtype=np.float64), (nc,)).astype(work)[None, None, :].copy()
        if straight:
            _multiply_colour(bg, bg[:, :, alpha_channel] / scale, alpha_channel)
        s = polygon_coverage(src, w, y1, rows=(y0, y1))
        untouched &= s == 0
        s = s[:, :, None]
        base *= 1 - s
        base += bg * s
    out = warped[:, :, :nc]
    if feather > 0:
        if dst is None:
            raise InputError("feather needs the target polygon")
        weight = feather_weights(dst, w, y1, feather, rows=(y0, y1))[:, :, None].astype(work)
        out *= weight
        out += base * (1 - weight * cov)
    else:
        out += base * (1 - cov)
    if straight:
        alpha = out[:, :, alpha_channel] / scale
        with np.errstate(divide="ignore", invalid="ignore"):
            _multiply_colour(out, np.where(alpha > 0, 1.0 / alpha, 0.0).astype(work), alpha_channel)
    out = _to_dtype(np.ascontiguousarray(out), image.dtype)
    # Pixels neither warped onto nor vacated are the input's, bit for bit.
    out[untouched] = image[untouched]
    return out


def carrier_pixels(pixels: NDArray, alpha_channel: int | None, associated_alpha: bool) -> NDArray:
    """What a paste resamples: the pixels in premultiplied float, then one channel of 1 (the carrier).

    Resampled against a background of 0 with the target's edge coverage
    applied to every channel, the carrier comes out as the target's coverage
    (see `paste_over`).

    Parameters
    ----------
    pixels : (h, w, C) ndarray
        The input, or a part of it.
    alpha_channel : int or None
    associated_alpha : bool

    Returns
    -------
    (h, w, C + 1) ndarray of float32 (float64 for a float64 input)
        In the input's units (an integer type's range).
    """
    from .raster.pixels import unit

    scale = float(unit(pixels.dtype))
    work = np.float64 if pixels.dtype == np.float64 else np.float32
    h, w, nc = pixels.shape
    out = np.empty((h, w, nc + 1), dtype=work)
    out[:, :, :nc] = pixels
    if alpha_channel is not None and not associated_alpha:
        _multiply_colour(out[:, :, :nc], out[:, :, alpha_channel] / scale, alpha_channel)
    out[:, :, nc] = scale
    return out


def _multiply_colour(pixels: NDArray, factor: NDArray, alpha_channel: int) -> None:
    """Every channel but alpha times ``factor`` (H, W), in place."""
    for c in range(pixels.shape[2]):
        if c != alpha_channel:
            pixels[:, :, c] *= factor
