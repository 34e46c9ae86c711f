"""Resample stage: turning an inverse coordinate map (and its Jacobians) into an output image."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._arrays import sorted_unique
from .._native import Kernels, cores, parallel
from ..errors import InputError
from ..grid import clip_segments
from ..options import INTERPOLATIONS
from .pixels import unit

#: The compiled samplers and rounding (`warpcli.raster._kernels`), loaded without numba.
_compiled = Kernels("warpcli.raster._kernels")

#: With antialiasing, a footprint is covered by at most this many samples per side.
MAX_FOOTPRINT_SAMPLES = 16

#: Alpha (0..1) at or below which a resampled pixel counts as fully transparent.
ALPHA_EPSILON = 1e-12


def resample(
    image: ArrayLike,
    inverse_map: ArrayLike,
    *,
    interp: str = "linear",
    background: ArrayLike = 0.0,
    alpha_channel: int | None = None,
    associated_alpha: bool = False,
    jacobian: ArrayLike | None = None,
    coverage: EdgeCoverage | None = None,
    part: tuple[int, int, int, int] | None = None,
    working: NDArray | None = None,
) -> NDArray:
    """Sample ``image`` at the source positions of the output pixels.

    Parameters
    ----------
    image : (H, W, C) array_like
        Input pixels, any numeric dtype. Integer images are read as their
        stored values (0..255 for uint8), floats as they are.
    inverse_map : (H2, W2, 2) array_like of float
        For each output pixel, the point ``(x, y)`` of the input image it
        comes from, in continuous image coordinates (pixel ``(r, c)`` has its
        centre at ``(c + 0.5, r + 0.5)``); NaN where the output pixel has no
        pre-image (outside the target polygon).
    interp : {"nearest", "linear", "cubic"}
        ``linear`` is bilinear and reproduces linear data exactly; ``cubic``
        is the interpolating cubic B-spline; ``nearest`` takes the pixel the
        point falls in.
    background : float or (C,) array_like of float
        Value of output pixels with no pre-image, or whose pre-image lies
        outside the input's area ``0 <= x <= W, 0 <= y <= H``; in the image's
        own units (0..255 for uint8).
    alpha_channel : int or None
        Index of the alpha channel. Colour is resampled premultiplied by
        alpha, so the colour of transparent pixels never bleeds into the result.
    associated_alpha : bool
        Whether colour is already premultiplied (then it is resampled as it
        is); straight colour is premultiplied to blend and divided back after
        (``nearest`` does not blend, so it takes pixels exactly as they are).
    jacobian : (H2, W2, 2, 2) array_like of float or None
        The Jacobian of the inverse map at each output pixel (d source /
        d output; NaN where unknown), for antialiasing: with ``linear``, each
        pixel is averaged over its footprint in the source where the map
        shrinks (see `warpcli.raster._kernels.sample_linear_aa`); with
        ``linear`` and ``cubic``, pixels crossed by the pre-image of the
        input's border are covered in proportion (see `_border_coverage`).
    coverage : EdgeCoverage or None
        Antialias the target polygon's edge: the fraction of each edge pixel
        inside the polygon goes into alpha (with an alpha channel) or blends
        the pixel with the background (without).
    part : (x0, y0, W, H) or None
        ``image`` is only the part of a W x H image whose top-left pixel is
        column x0, row y0 (`warpcli.tiled` reads images part by part). It must
        hold every pixel the samples reach, then the result is that of the
        whole image, bit for bit with ``nearest`` and ``linear``; ``cubic``
        prefilters the part only, so it agrees to rounding given a margin of
        a dozen pixels.
    working : ndarray or None
        `working_copy` of ``image`` with these ``interp``, ``alpha_channel``
        and ``associated_alpha``, made once by a caller that resamples one
        image in many calls; None: made here when needed.

    Returns
    -------
    (H2, W2, C) ndarray of the input's dtype
        Integer results are rounded and clipped to the type's range; float
        results are neither clipped nor quantized.

    Raises
    ------
    InputError
        If ``interp`` is unknown or the arrays' shapes do not fit.
    """
    if interp not in INTERPOLATIONS:
        raise InputError(f"unknown interpolation {interp!r}; choose one of {', '.join(INTERPOLATIONS)}")
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[:, :, None]
    h, w, nc = img.shape
    x0, y0 = 0, 0
    if part is not None:
        x0, y0, w, h = (int(v) for v in part)
    coords = np.asarray(inverse_map, dtype=np.float64)
    if coords.ndim != 3 or coords.shape[2] != 2:
        raise InputError(f"inverse_map must be (H, W, 2), got shape {coords.shape}")
    out_shape = coords.shape[:2]
    points = np.ascontiguousarray(coords.reshape(-1, 2))
    # Some pixels take another source point than the map's (below). The
    # caller's array is not copied for them (64 MB at 4 MP): they are sampled
    # again on their own, ``patch`` (pixel indices, ascending) at ``patch_xy``.
    # Every output pixel depends on its own point and Jacobian only, so the
    # result is the same.
    patch = np.zeros(0, dtype=np.int64)
    patch_xy = np.zeros((0, 2))
    if coverage is not None:
        # Edge pixels whose centre lies outside the polygon take their colour
        # from the nearest point of its boundary.
        missing = ~np.isfinite(points[coverage.pixels, 0])
        if missing.any():
            patch, patch_xy = _merged(
                patch, patch_xy, np.asarray(coverage.pixels[missing], dtype=np.int64),
                np.asarray(coverage.source_points[missing], dtype=np.float64).reshape(-1, 2),
            )  # fmt: skip
    border = None
    jac = None
    if jacobian is not None and interp != "nearest":
        jac = np.ascontiguousarray(np.asarray(jacobian, dtype=np.float64).reshape(-1, 2, 2))
        if len(jac) != len(points):
            raise InputError(f"jacobian has {len(jac)} entries for {len(points)} output pixels")
        border = _border_coverage(points, jac, w, h, patch, patch_xy)
        if border is not None:
            # Pixels just beyond the input's border take the colour at the
            # border, blended by how much of them the input covers.
            xy = _points_at(points, patch, patch_xy, border[0])
            xy[:, 0] = np.clip(xy[:, 0], 0.0, w)
            xy[:, 1] = np.clip(xy[:, 1], 0.0, h)
            patch, patch_xy = _merged(patch, patch_xy, border[0], xy)
    bg = np.ascontiguousarray(np.broadcast_to(np.asarray(background, dtype=np.float64), (nc,)))
    work_dtype = _work_dtype(img.dtype)
    alpha_channel_blend = _premultiplied_by(interp, alpha_channel, associated_alpha)
    if working is None:
        working = working_copy(img, interp=interp, alpha_channel=alpha_channel, associated_alpha=associated_alpha)
    src = np.ascontiguousarray(img) if working is None else working
    alpha_scale = unit(img.dtype)
    out = np.empty((points.shape[0], nc), dtype=work_dtype)
    if interp == "cubic":
        from scipy.ndimage import map_coordinates

        if patch.size:
            points = points.copy()
            points[patch] = patch_xy
        x = points[:, 0]
        y = points[:, 1]
        out[:] = bg.astype(work_dtype)
        valid = np.flatnonzero((x >= 0) & (x <= w) & (y >= 0) & (y <= h))
        # Array index i has its centre at coordinate i + 0.5.
        idx = np.stack([y[valid] - (0.5 + y0), x[valid] - (0.5 + x0)])
        for c in range(nc):
            out[valid, c] = map_coordinates(src[:, :, c], idx, order=3, mode="nearest", prefilter=True)
    else:

        def sample(xy, j, dest):
            if interp == "nearest":
                _compiled.sample_nearest(src, x0, y0, w, h, xy, bg, dest)
            elif j is None:
                _compiled.sample_linear(src, x0, y0, w, h, xy, bg, dest)
            else:
                _compiled.sample_linear_aa(src, x0, y0, w, h, xy, j, MAX_FOOTPRINT_SAMPLES, bg, dest, np.zeros(nc))

        # Pixels are independent: runs of them are sampled on all cores.
        n = len(points)
        step = max(1 << 15, -(-n // (4 * cores())))

        def run(lo: int) -> None:
            hi = min(lo + step, n)
            sample(points[lo:hi], None if jac is None else jac[lo:hi], out[lo:hi])

        parallel(run, range(0, n, step))
        if patch.size:
            dest = np.empty((len(patch), nc), dtype=work_dtype)
            sample(patch_xy, None if jac is None else jac[patch], dest)
            out[patch] = dest
    if alpha_channel_blend is not None:
        a = out[:, alpha_channel_blend] / alpha_scale
        # Alpha below ALPHA_EPSILON (a cubic spline's ringing around 0, say)
        # is transparent: its colour would be divided by nearly nothing.
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inv = np.where(a > ALPHA_EPSILON, 1.0 / a, 0.0).astype(work_dtype)
        for c in range(nc):
            if c != alpha_channel_blend:
                out[:, c] *= inv
    if coverage is not None:
        _blend(out, coverage.pixels, coverage.fraction.astype(work_dtype), bg.astype(work_dtype), alpha_channel, associated_alpha)
    if border is not None:
        _blend(out, border[0], border[1].astype(work_dtype), bg.astype(work_dtype), alpha_channel, associated_alpha)
    return _to_dtype(out.reshape(*out_shape, nc), img.dtype)


def _work_dtype(dtype: np.dtype) -> type:
    """The type samples are computed in: float64 for float64 images and for integers wider than
    16 bits (float32 holds integers exactly only up to 2^24: a 32-bit id would move by up to
    128 even under ``nearest``), float32 otherwise."""
    dtype = np.dtype(dtype)
    wide_integer = dtype.kind in "iu" and dtype.itemsize > 2
    return np.float64 if dtype == np.float64 or wide_integer else np.float32


def _premultiplied_by(interp: str, alpha_channel: int | None, associated_alpha: bool) -> int | None:
    """The alpha channel colour is premultiplied by to be resampled (straight colour blended), or None."""
    return None if associated_alpha or interp == "nearest" else alpha_channel


def samples_as_is(dtype: np.dtype, *, interp: str, alpha_channel: int | None = None, associated_alpha: bool = False) -> bool:
    """Whether `resample` samples an image of this type as it is (`working_copy` makes none):
    a type the kernels read (uint8, uint16, float32, float64) with no straight colour to
    premultiply by its alpha."""
    return _premultiplied_by(interp, alpha_channel, associated_alpha) is None and np.dtype(dtype) in _NATIVE


def working_copy(
    image: NDArray, *, interp: str, alpha_channel: int | None = None, associated_alpha: bool = False
) -> NDArray | None:
    """What `resample` samples instead of ``image``, or None when it samples ``image`` as it is.

    The kernels read uint8, uint16, float32 and float64 as they are; other
    types (half, 32-bit integers), and straight colour to premultiply by its
    alpha (every interpolation but ``nearest``), are copied to the working type
    first: the whole image, whatever part of it the call samples. A caller
    that resamples one image in many calls (`warpcli.plan.SamplingPlan.render_rows`,
    band by band) makes it once and passes it as ``working``.
    """
    img = image if image.ndim == 3 else image[:, :, None]
    if samples_as_is(img.dtype, interp=interp, alpha_channel=alpha_channel, associated_alpha=associated_alpha):
        return None
    blend = _premultiplied_by(interp, alpha_channel, associated_alpha)
    src = img.astype(_work_dtype(img.dtype), copy=True)
    if blend is not None:
        a = src[:, :, blend] / unit(img.dtype)
        for c in range(src.shape[2]):
            if c != blend:
                src[:, :, c] *= a
    return src


def _blend(out, pixels, fraction, bg, alpha_channel, associated_alpha) -> None:
    """Pixels covered only by ``fraction``: alpha scaled by it, or blended with the background."""
    cov = fraction[:, None]
    if alpha_channel is not None:
        if associated_alpha:
            out[pixels] *= cov
        else:
            out[pixels, alpha_channel] *= cov[:, 0]
    else:
        out[pixels] = cov * out[pixels] + (1 - cov) * bg


def _points_at(points, patch, patch_xy, pixels):
    """The source points of ``pixels`` (ascending), ``patch_xy`` where patched: (K, 2), a new array."""
    xy = points[pixels]
    if patch.size:
        pos = np.minimum(np.searchsorted(patch, pixels), len(patch) - 1)
        hit = patch[pos] == pixels
        xy[hit] = patch_xy[pos[hit]]
    return xy


def _merged(patch, patch_xy, pixels, xy):
    """The patch with ``pixels`` set to ``xy``: indices ascending and distinct; for an index
    given more than once the last of ``xy`` wins, as in ``points[pixels] = xy``."""
    idx = np.concatenate([patch, pixels])
    pts = np.concatenate([patch_xy, xy])
    order = np.argsort(idx, kind="stable")
    idx, pts = idx[order], pts[order]
    last = np.r_[idx[1:] != idx[:-1], True]
    return idx[last], np.ascontiguousarray(pts[last])


def _border_coverage(points, jacobian, w: int, h: int, patch=None, patch_xy=None):
    """Output pixels crossed by the pre-image of the input's border, and the share of each inside.

    Where the source polygon runs past the input image, the input's border
    is an edge in the output like the target polygon's: it gets the same
    distance-field coverage, ``clip(1/2 + s, 0, 1)`` with s the signed
    distance from the source point to the border measured in output pixels
    (the distance in source pixels over ``|J^T n|``, n the border's normal).
    Only for pixels sampled once (columns of J at most 1.3 long, where the
    map does not shrink): where it shrinks, the footprint sampler already
    averages over the border. ``points`` with the pixels ``patch`` (ascending)
    at ``patch_xy`` instead.

    Returns
    -------
    (pixels, fraction) or None
        Flat pixel indices and coverages in (0, 1); None if there are none.
    """
    if patch is None:
        patch, patch_xy = np.zeros(0, dtype=np.int64), np.zeros((0, 2))
    # Pixels whose point lies within one pixel of the border: one compiled
    # pass over the points (numpy would make five image-sized temporaries).
    found = np.empty(len(points), dtype=np.int64)
    near = found[: _compiled.near_border(points, float(w), float(h), found)]
    if patch.size:
        found = np.empty(len(patch), dtype=np.int64)
        moved = patch[found[: _compiled.near_border(patch_xy, float(w), float(h), found)]]
        # np.union1d(near[~np.isin(near, patch)], moved), computed without np.unique (see `warpcli._arrays`).
        at = np.minimum(np.searchsorted(patch, near), patch.size - 1)
        near = sorted_unique(np.concatenate([near[patch[at] != near], moved]))
    if near.size == 0:
        return None
    xy = _points_at(points, patch, patch_xy, near)
    x = xy[:, 0]
    y = xy[:, 1]
    dx = np.minimum(x, w - x)
    dy = np.minimum(y, h - y)
    j = jacobian[near]
    single = (j[:, 0, 0] ** 2 + j[:, 1, 0] ** 2 <= 1.69) & (j[:, 0, 1] ** 2 + j[:, 1, 1] ** 2 <= 1.69)
    near, j, dx, dy = near[single], j[single], dx[single], dy[single]
    gx = np.hypot(j[:, 0, 0], j[:, 0, 1])  # |J^T e_x|: how fast x changes per output pixel
    gy = np.hypot(j[:, 1, 0], j[:, 1, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.minimum(dx / gx, dy / gy)
    frac = np.clip(0.5 + s, 0.0, 1.0)
    keep = (frac > 0) & (frac < 1)
    if not keep.any():
        return None
    return near[keep], frac[keep]


# Image types the compiled samplers read directly.
_NATIVE = (np.dtype(np.uint8), np.dtype(np.uint16), np.dtype(np.float32), np.dtype(np.float64))


@dataclass(frozen=True)
class EdgeCoverage:
    """Output pixels crossed by the target polygon's edge.

    Attributes
    ----------
    pixels : (K,) ndarray of int64
        Flat pixel indices (row-major).
    fraction : (K,) ndarray of float
        Share of each pixel inside the polygon, in (0, 1).
    edge, t : (K,) ndarrays of int and float
        The nearest point of the boundary to each pixel centre: parameter t
        along polygon edge i.
    source_points : (K, 2) ndarray of float or None
        The source point to sample for a pixel whose centre is outside the
        polygon: the pre-image of that nearest boundary point (by the exact
        boundary map; filled in by the caller, who knows the map).
    """

    pixels: NDArray[np.int64]
    fraction: NDArray[np.float64]
    edge: NDArray[np.intp]
    t: NDArray[np.float64]
    source_points: NDArray[np.float64] | None = None


def edge_coverage(
    dst: NDArray[np.float64], inside: NDArray[np.bool_], origin: tuple[int, int] = (0, 0)
) -> EdgeCoverage:
    """Coverage of the pixels along polygon ``dst``'s boundary, and their nearest boundary points.

    A pixel's share inside the polygon is taken as ``clip(1/2 + s, 0, 1)``,
    s the signed distance (in pixels, positive inside) from its centre to the
    boundary: exact for an edge parallel to an axis, and exact on average along
    any straight edge, so the coverages sum to the polygon's area up to
    corner effects (the usual distance-field antialiasing). Only edges near a
    pixel are measured: the part of each edge that crosses the window is
    sampled every half pixel and offers itself to the 3 x 3 pixels around each
    sample, so the cost is linear in the length of boundary inside the window,
    whatever the polygon's size.

    Parameters
    ----------
    dst : (n, 2) array of float
        The target polygon, in the grid's coordinates.
    inside : (h, w) array of bool
        Whether each pixel centre of the window lies inside ``dst``.
    origin : (int, int)
        ``(row, column)`` of the window's top-left pixel in the grid.

    Returns
    -------
    EdgeCoverage
        ``pixels`` are flat indices into the window.
    """
    height, width = inside.shape
    r0, c0 = origin
    n = len(dst)
    a = dst
    d = np.roll(dst, -1, axis=0) - dst
    length = np.hypot(d[:, 0], d[:, 1])
    # The part of each edge within one pixel of the window (Liang-Barsky).
    t_lo, t_hi = clip_segments(a, d, (c0 - 1.0, r0 - 1.0, c0 + width + 1.0, r0 + height + 1.0))
    crosses = np.flatnonzero(t_lo <= t_hi)
    span = (t_hi - t_lo)[crosses]
    count = np.ceil(length[crosses] * span / 0.5).astype(np.int64) + 1
    edge = np.repeat(crosses, count)
    first = np.cumsum(count) - count
    step = (np.arange(edge.size) - np.repeat(first, count)) / np.repeat(np.maximum(count - 1, 1), count)
    t = np.repeat(t_lo[crosses], count) + np.repeat(span, count) * step
    samples = a[edge] + t[:, None] * d[edge]
    base = np.floor(samples).astype(np.int64)
    offs = np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)])
    col = (base[:, None, 0] + offs[None, :, 0]).ravel() - c0
    row = (base[:, None, 1] + offs[None, :, 1]).ravel() - r0
    edge = np.repeat(edge, len(offs))
    ok = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    pix = row[ok] * width + col[ok]
    key = sorted_unique(pix * n + edge[ok])
    if key.size == 0:
        empty = np.zeros(0)
        return EdgeCoverage(np.zeros(0, dtype=np.int64), empty, np.zeros(0, dtype=np.intp), empty)
    pix = key // n
    edge = key % n
    cx = (pix % width + c0) + 0.5
    cy = (pix // width + r0) + 0.5
    dd = np.einsum("ij,ij->i", d, d)
    t = np.clip(((cx - a[edge, 0]) * d[edge, 0] + (cy - a[edge, 1]) * d[edge, 1]) / dd[edge], 0.0, 1.0)
    dist = np.hypot(a[edge, 0] + t * d[edge, 0] - cx, a[edge, 1] + t * d[edge, 1] - cy)
    # The nearest edge of each pixel: sort by pixel, then distance.
    order = np.lexsort((dist, pix))
    pix, edge, t, dist = pix[order], edge[order], t[order], dist[order]
    head = np.flatnonzero(np.r_[True, pix[1:] != pix[:-1]])
    pix, edge, t, dist = pix[head], edge[head], t[head], dist[head]
    sign = np.where(inside.ravel()[pix], 1.0, -1.0)
    frac = np.clip(0.5 + sign * dist, 0.0, 1.0)
    keep = (frac > 0) & (frac < 1)
    return EdgeCoverage(pix[keep], frac[keep], edge[keep], t[keep])


def footprint_bounds(
    points: NDArray, jacobian: NDArray | None, limits: tuple[float, float, float, float]
) -> tuple[float, float, float, float] | None:
    """The least and greatest x and y that samples at ``points`` reach, each clipped to ``limits``.

    A sample reads around the points of its footprint, the parallelogram
    ``J [-1/2, 1/2]^2`` about its source point: a finite point (x, y) reaches
    x -+ (|J00| + |J01|) / 2 and y -+ (|J10| + |J11|) / 2 (``jacobian`` None:
    the point alone; a NaN half-extent counts as none, an infinite one
    reaches the limit). One compiled pass over the points: a strip of a
    gigapixel warp holds a million of them (`warpcli.tiled`), and numpy's
    dozen full-size passes took 15 ms a strip.

    Parameters
    ----------
    points : (..., 2) ndarray of float
        Source points; NaN (no pre-image) reach nothing.
    jacobian : (..., 2, 2) ndarray of float or None
        Their Jacobians (d source / d target).
    limits : (xmin, xmax, ymin, ymax)
        Where each bound is clipped to.

    Returns
    -------
    (xmin, xmax, ymin, ymax) or None
        None when no point reaches anything.
    """
    xy = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    if jacobian is None:
        jac, with_jac = np.zeros((1, 2, 2)), 0
    else:
        jac, with_jac = np.ascontiguousarray(jacobian, dtype=np.float64).reshape(-1, 2, 2), 1
    out = np.zeros(8)
    out[4:] = limits
    if not _compiled.footprint_bounds(xy, jac, with_jac, out):
        return None
    return float(out[0]), float(out[1]), float(out[2]), float(out[3])


def _to_dtype(values: NDArray, dtype: np.dtype) -> NDArray:
    """Round half to even and clip for integer types; a plain cast for floats."""
    if values.dtype == dtype:
        return values
    if dtype == np.float16:
        return values.astype(dtype)
    out = np.empty(values.shape, dtype=dtype)
    flat_in, flat_out = np.ascontiguousarray(values).reshape(-1), out.reshape(-1)
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        _compiled.store(flat_in, flat_out, float(info.min), float(info.max), True)
    else:
        _compiled.store(flat_in, flat_out, 0.0, 0.0, False)
    return out
