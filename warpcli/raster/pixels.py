"""Pixel values: what 1.0 is in each pixel type, and conversions that keep values' meaning."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, DTypeLike, NDArray


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


def fill(out: NDArray, value: ArrayLike) -> None:
    """``out[...] = value``: one pixel value (C,) over an image (H, W, C), in place.

    numpy broadcasts a (C,) value over (H, W, C) one pixel at a time (an inner
    loop of C elements): 9.6 ms for a 1 MP RGB image of bytes, the first thing a
    warp's output band maker did before its first band reached the encoder.
    Here the first row is filled that way and copied to the others (0.1 ms);
    the same values, bit for bit.

    >>> out = np.empty((2, 3, 2), dtype=np.uint8)
    >>> fill(out, [7, 9])
    >>> out[1, 2].tolist()
    [7, 9]
    """
    if out.ndim < 2 or out.shape[0] == 0:
        out[...] = value
        return
    out[0] = value
    out[1:] = out[0]
