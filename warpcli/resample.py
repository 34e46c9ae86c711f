"""Resample stage: turning an inverse coordinate map into an output image."""

from __future__ import annotations

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
    x = coords[..., 0].ravel()
    y = coords[..., 1].ravel()
    # NaN compares false, so this also drops pixels outside the target polygon.
    valid = np.flatnonzero((x >= 0) & (x <= w) & (y >= 0) & (y <= h))
    bg = np.broadcast_to(np.asarray(background, dtype=np.float64), (nc,))
    work_dtype = np.float64 if img.dtype == np.float64 else np.float32
    out = np.empty((x.size, nc), dtype=work_dtype)
    out[:] = bg.astype(work_dtype)

    src = img.astype(work_dtype, copy=True)
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

        sample = _kernels.sample_linear if interp == "linear" else _kernels.sample_nearest
        points = np.ascontiguousarray(coords.reshape(-1, 2))
        sample(np.ascontiguousarray(src), points, out)
    if alpha_channel is not None:
        a = out[valid, alpha_channel] / alpha_scale
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(a > 0, 1.0 / a, 0.0).astype(work_dtype)
        for c in range(nc):
            if c != alpha_channel:
                out[valid, c] *= inv
    return _to_dtype(out.reshape(*out_shape, nc), img.dtype)


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
