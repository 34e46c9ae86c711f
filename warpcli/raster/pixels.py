"""Pixel values: what 1.0 is in each pixel type, and conversions that keep values' meaning."""

from __future__ import annotations

import numpy as np
from numpy.typing import DTypeLike, NDArray


def unit(dtype: DTypeLike) -> float:
    """The stored value that means 1.0 (full intensity, opaque alpha) in a pixel type.

    >>> unit(np.uint8), unit(np.uint16), unit(np.float32)
    (255.0, 65535.0, 1.0)
    """
    dt = np.dtype(dtype)
    return float(np.iinfo(dt).max) if np.issubdtype(dt, np.integer) else 1.0


def to_unit(pixels: NDArray) -> NDArray[np.float64]:
    """Pixels as float64 where 1.0 means full intensity (integers divided by their maximum)."""
    px = np.asarray(pixels)
    x = px.astype(np.float64)
    scale = unit(px.dtype)
    if scale != 1.0:
        x /= scale
    return x


def from_unit(values: NDArray[np.float64], dtype: DTypeLike) -> NDArray:
    """Values where 1.0 is full intensity, stored in ``dtype``: integers rounded and clipped.

    >>> from_unit(np.array([-0.5, 0.5, 2.0]), np.uint8).tolist()
    [0, 128, 255]
    """
    dt = np.dtype(dtype)
    if np.issubdtype(dt, np.integer):
        top = unit(dt)
        return np.clip(np.rint(values * top), 0, top).astype(dt)
    return values.astype(dt)


def premultiplied(pixels: NDArray, alpha_channel: int) -> NDArray:
    """Colour multiplied by alpha (0..1), in the pixels' own type.

    For straight colour written to a format whose colour is premultiplied by
    definition (OpenEXR).

    Parameters
    ----------
    pixels : (H, W, C) ndarray
    alpha_channel : int

    Returns
    -------
    (H, W, C) ndarray
        Of ``pixels``' type; alpha unchanged.

    Examples
    --------
    >>> premultiplied(np.array([[[200, 100, 128]]], dtype=np.uint8), 2).tolist()
    [[[100, 50, 128]]]
    """
    x = to_unit(pixels)
    colour = [c for c in range(pixels.shape[2]) if c != alpha_channel]
    x[:, :, colour] *= x[:, :, alpha_channel : alpha_channel + 1]
    return from_unit(x, pixels.dtype)
