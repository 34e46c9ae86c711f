"""Maps as files: STMaps (normalized source coordinates per pixel) in OpenEXR.

Convention (OpenImageIO's ``st_warp``; Nuke's STMap node with ``t`` up): the
pixel at (row r, column c) of an STMap holds, in channels R and G, the point
``(s, t)`` it takes its value from, normalized by the size ``W x H`` of the
image it samples: ``s = x / W`` and ``t = y / H`` for the continuous point
``(x, y)`` (x right, y down, pixel centres at +0.5, so the centre of pixel
``(i, j)`` is at ``s = (i + 0.5) / W``). ``t`` runs down the image by default,
as ``st_warp`` reads it; with ``t_up`` it runs up, ``t = 1 - y / H``, as Nuke's
STMap node reads it. Channel A is 1 where the map is defined and 0 elsewhere,
where R and G hold -1 (outside any image, so tools that ignore A sample
black); B is 0. The header says which way t runs and what the map is.
"""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import NDArray

from ..errors import ImageInputError
from .imageio import RasterImage, read_image, write_image
from .pixels import to_unit

#: Header attributes: what the map is ("inverse": output -> input, "forward":
#: input -> output) and which way t runs ("down" or "up").
KIND_ATTRIBUTE = "warpcli:map"
T_ATTRIBUTE = "warpcli:t"


def save_stmap(
    path: str | os.PathLike[str],
    points: NDArray[np.float64],
    size: tuple[int, int],
    *,
    kind: str = "inverse",
    t_up: bool = False,
) -> None:
    """Write a map as a float32 RGBA OpenEXR STMap (atomically).

    Parameters
    ----------
    points : (H, W, 2) ndarray of float
        For each pixel of the map, the continuous point it refers to in an
        image of ``size``; NaN where the map is undefined.
    size : (width, height)
        Size of the image the points refer to (the normalization).
    kind : {"inverse", "forward"}
    t_up : bool
        Nuke's orientation (t up) instead of OpenImageIO's (t down).
    """
    w, h = size
    s = points[..., 0] / w
    t = points[..., 1] / h
    if t_up:
        t = 1.0 - t
    ok = np.isfinite(s) & np.isfinite(t)
    rgba = np.zeros(points.shape[:2] + (4,), dtype=np.float32)
    rgba[..., 0] = np.where(ok, s, -1.0)
    rgba[..., 1] = np.where(ok, t, -1.0)
    rgba[..., 3] = ok
    attrs = (
        (KIND_ATTRIBUTE, "string", kind),
        (T_ATTRIBUTE, "string", "up" if t_up else "down"),
        ("compression", "string", "zip"),
    )
    write_image(path, RasterImage(rgba, ("R", "G", "B", "A"), 3, attrs))


def load_stmap(
    path: str | os.PathLike[str], size: tuple[int, int], *, t_up: bool | None = None
) -> NDArray[np.float64]:
    """Read an STMap as continuous points in an image of ``size``.

    Parameters
    ----------
    size : (width, height)
        Size of the image the map samples.
    t_up : bool or None
        Which way t runs; None: as the file's header says, else down.

    Returns
    -------
    (H, W, 2) ndarray of float
        NaN where the map is undefined (alpha 0, or non-finite s, t).

    Raises
    ------
    ImageInputError
        If the file is not an image with at least two channels.
    """
    name = os.fspath(path)
    img = read_image(name)
    px = to_unit(img.pixels)  # an integer STMap spans 0..1
    if px.shape[2] < 2:
        raise ImageInputError(f"{name}: an STMap needs two channels (s, t), this image has {px.shape[2]}")
    if t_up is None:
        header = dict((n, v) for n, _, v in img.attributes)
        t_up = header.get(T_ATTRIBUTE) == "up"
    w, h = size
    s = px[..., 0]
    t = px[..., 1]
    if t_up:
        t = 1.0 - t
    ok = np.isfinite(s) & np.isfinite(t)
    if img.alpha_channel is not None:
        ok &= px[..., img.alpha_channel] > 0
    points = np.stack([s * w, t * h], axis=-1)
    points[~ok] = np.nan
    return points
