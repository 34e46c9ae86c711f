"""Resample stage: turning an inverse coordinate map into an output image."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Interpolation filters by name, with their spline order in scipy.ndimage.
INTERPOLATIONS = {"nearest": 0, "linear": 1, "cubic": 3}


def resample(
    image: ArrayLike,
    inverse_map: ArrayLike,
    *,
    interp: str = "linear",
    background: ArrayLike = 0.0,
    alpha_channel: int | None = None,
    associated_alpha: bool = False,
    footprint: Footprint | None = None,
    coverage: EdgeCoverage | None = None,
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
    footprint : Footprint or None
        With ``linear``: average each pixel over its footprint in the source
        (antialiasing where the map shrinks; see warpcli._kernels.sample_linear_aa).
    coverage : EdgeCoverage or None
        Antialias the target polygon's edge: the fraction of each edge pixel
        inside the polygon goes into alpha (with an alpha channel) or blends
        the pixel with the background (without).

    Returns
    -------
    (H2, W2, C) ndarray of the input's dtype
        Integer results are rounded and clipped to the type's range; float
        results are neither clipped nor quantized.
    """
    if interp not in INTERPOLATIONS:
        raise ValueError(f"interp must be one of {sorted(INTERPOLATIONS)}, got {interp!r}")
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[:, :, None]
    h, w, nc = img.shape
    coords = np.asarray(inverse_map, dtype=np.float64)
    out_shape = coords.shape[:2]
    if coverage is not None:
        # Edge pixels whose centre lies outside the polygon take their colour
        # from the nearest point of its boundary.
        coords = coords.reshape(-1, 2).copy()
        missing = ~np.isfinite(coords[coverage.pixels, 0])
        coords[coverage.pixels[missing]] = coverage.source_points[missing]
        coords = coords.reshape(*out_shape, 2)
    x = coords[..., 0].ravel()
    y = coords[..., 1].ravel()
    # NaN compares false, so this also drops pixels outside the target polygon.
    valid = np.flatnonzero((x >= 0) & (x <= w) & (y >= 0) & (y <= h))
    bg = np.broadcast_to(np.asarray(background, dtype=np.float64), (nc,))
    work_dtype = np.float64 if img.dtype == np.float64 else np.float32
    out = np.empty((x.size, nc), dtype=work_dtype)
    out[:] = bg.astype(work_dtype)

    src = img.astype(work_dtype, copy=True)
    original_alpha = alpha_channel
    alpha_scale = None
    if associated_alpha or interp == "nearest":
        alpha_channel = None  # nothing to premultiply
    if alpha_channel is not None:
        alpha_scale = _alpha_unit(img.dtype)
        a = src[:, :, alpha_channel] / alpha_scale
        for c in range(nc):
            if c != alpha_channel:
                src[:, :, c] *= a
    if interp == "cubic":
        from scipy.ndimage import map_coordinates

        # Array index i has its centre at coordinate i + 0.5.
        idx = np.stack([y[valid] - 0.5, x[valid] - 0.5])
        for c in range(nc):
            out[valid, c] = map_coordinates(src[:, :, c], idx, order=3, mode="nearest", prefilter=True)
    else:
        from . import _kernels

        points = np.ascontiguousarray(coords.reshape(-1, 2))
        if interp == "nearest":
            _kernels.sample_nearest(np.ascontiguousarray(src), points, out)
        elif footprint is None:
            _kernels.sample_linear(np.ascontiguousarray(src), points, out)
        else:
            f = footprint
            _kernels.sample_linear_aa(
                np.ascontiguousarray(src), points, f.where0.ravel(), f.where1.ravel(), f.j0inv, f.j1,
                f.max_samples, bg.astype(np.float64), out,
            )  # fmt: skip
    if alpha_channel is not None:
        a = out[valid, alpha_channel] / alpha_scale
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(a > 0, 1.0 / a, 0.0).astype(work_dtype)
        for c in range(nc):
            if c != alpha_channel:
                out[valid, c] *= inv
    if coverage is not None:
        cov = coverage.fraction.astype(work_dtype)[:, None]
        px = coverage.pixels
        alpha = original_alpha
        if alpha is not None:
            if associated_alpha:
                out[px] *= cov
            else:
                out[px, alpha] *= cov[:, 0]
        else:
            out[px] = cov * out[px] + (1 - cov) * bg.astype(work_dtype)
    return _to_dtype(out.reshape(*out_shape, nc), img.dtype)


@dataclass(frozen=True)
class Footprint:
    """Per-pixel Jacobians of the inverse map, as triangle pairs.

    The Jacobian at output pixel p is ``j0inv[where0[p]] @ j1[where1[p]]``
    (-1 entries: no Jacobian, sampled at the centre only).
    """

    where0: NDArray[np.int32]
    where1: NDArray[np.int32]
    j0inv: NDArray[np.float64]
    j1: NDArray[np.float64]
    max_samples: int = 16


@dataclass(frozen=True)
class EdgeCoverage:
    """Output pixels crossed by the target polygon's edge.

    Attributes
    ----------
    pixels : (K,) flat pixel indices (row-major)
    fraction : (K,) share of each pixel inside the polygon, in (0, 1)
    source_points : (K, 2) source point to sample for a pixel whose centre is
        outside the polygon: the pre-image of the nearest boundary point.
    """

    pixels: NDArray[np.int64]
    fraction: NDArray[np.float64]
    source_points: NDArray[np.float64]


def edge_coverage(
    dst: NDArray[np.float64], src: NDArray[np.float64], width: int, height: int, samples: int = 5
) -> EdgeCoverage:
    """Coverage of the pixels along polygon ``dst``'s boundary, with boundary pre-images.

    Each candidate pixel (near the boundary) is tested at ``samples`` x
    ``samples`` points with the even-odd rule. The pre-image of the nearest
    boundary point uses the boundary map exactly: parameter t along edge i of
    ``dst`` comes from parameter t along edge i of ``src``.
    """
    n = len(dst)
    a = dst
    b = np.roll(dst, -1, axis=0)
    # Candidates: pixels within a pixel of points every 0.5 px along the edges.
    pts = []
    for i in range(n):
        m = int(np.ceil(np.hypot(*(b[i] - a[i])) / 0.5)) + 1
        t = np.linspace(0.0, 1.0, m)[:, None]
        pts.append(a[i] + t * (b[i] - a[i]))
    p = np.floor(np.concatenate(pts)).astype(np.int64)
    offs = np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)])
    cand = (p[:, None, :] + offs[None]).reshape(-1, 2)
    cand = cand[(cand[:, 0] >= 0) & (cand[:, 0] < width) & (cand[:, 1] >= 0) & (cand[:, 1] < height)]
    flat = np.unique(cand[:, 1] * width + cand[:, 0])
    cx = (flat % width) + 0.5
    cy = (flat // width) + 0.5
    sub = (np.arange(samples) + 0.5) / samples - 0.5
    su, sv = np.meshgrid(sub, sub)
    su = su.ravel()
    sv = sv.ravel()
    frac = np.empty(len(flat))
    # Bound memory: pixels x samples x edges per block.
    block = max(1, (1 << 22) // (len(su) * n))
    for s in range(0, len(flat), block):
        x = (cx[s : s + block, None] + su[None]).reshape(-1, 1)
        y = (cy[s : s + block, None] + sv[None]).reshape(-1, 1)
        crosses = (a[:, 1] > y) != (b[:, 1] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xint = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
        inside = (crosses & (x < xint)).sum(axis=1) % 2 == 1
        frac[s : s + block] = inside.reshape(-1, len(su)).mean(axis=1)
    keep = (frac > 0) & (frac < 1)
    flat, frac, cx, cy = flat[keep], frac[keep], cx[keep], cy[keep]
    # Nearest boundary point of each kept pixel's centre, and its pre-image.
    best = np.full(len(flat), np.inf)
    src_pts = np.zeros((len(flat), 2))
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    for i in range(n):
        t = np.clip(((cx - a[i, 0]) * d[i, 0] + (cy - a[i, 1]) * d[i, 1]) / dd[i], 0.0, 1.0)
        dist = np.hypot(a[i, 0] + t * d[i, 0] - cx, a[i, 1] + t * d[i, 1] - cy)
        better = dist < best
        best[better] = dist[better]
        j = (i + 1) % n
        src_pts[better] = (1 - t[better, None]) * src[i] + t[better, None] * src[j]
    return EdgeCoverage(flat, frac, src_pts)


def _alpha_unit(dtype: np.dtype) -> float:
    """The value of an opaque alpha in this pixel type."""
    if np.issubdtype(dtype, np.integer):
        return float(np.iinfo(dtype).max)
    return 1.0


def _to_dtype(values: NDArray, dtype: np.dtype) -> NDArray:
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        return np.clip(np.rint(values), info.min, info.max).astype(dtype)
    return values.astype(dtype, copy=False)
