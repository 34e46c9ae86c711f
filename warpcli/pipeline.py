"""Pipeline: polygons -> meshes -> harmonic maps -> composed map -> resampled image."""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError
from .imageio import RasterImage, check_output_path, read_image, write_image
from .mapping import BijectiveMap
from .polygon import Polygon, check_pair, read_polygon
from .resample import INTERPOLATIONS, resample

log = logging.getLogger("warpcli")

#: The default resampling filter.
DEFAULT_INTERP = "linear"


@dataclass(frozen=True)
class WarpResult:
    """What a warp produced.

    Attributes
    ----------
    pixels : (H, W, C) ndarray
        The warped image, in the input's pixel type.
    map : BijectiveMap
    inverse_map : (H, W, 2) ndarray of float
        Source position of every output pixel centre; NaN outside the target.
    timings : dict of str to float
        Seconds per stage.
    """

    pixels: NDArray
    map: BijectiveMap
    inverse_map: NDArray[np.float64]
    timings: dict[str, float] = field(default_factory=dict)


def pixel_centres(width: int, height: int) -> NDArray[np.float64]:
    """Centres of a ``width`` x ``height`` pixel grid, row by row, as (H*W, 2) points.

    >>> pixel_centres(2, 1).tolist()
    [[0.5, 0.5], [1.5, 0.5]]
    """
    x = np.arange(width, dtype=np.float64) + 0.5
    y = np.arange(height, dtype=np.float64) + 0.5
    xx, yy = np.meshgrid(x, y)
    return np.stack([xx.ravel(), yy.ravel()], axis=1)


def warp_image(
    image: ArrayLike,
    src: Polygon | ArrayLike,
    dst: Polygon | ArrayLike,
    *,
    size: tuple[int, int] | None = None,
    interp: str = DEFAULT_INTERP,
    background: float | ArrayLike = 0.0,
    alpha_channel: int | None = None,
    max_area: float | None = None,
    warp_map: BijectiveMap | None = None,
    progress: Callable[[str], None] | None = None,
) -> WarpResult:
    """Warp an image so that polygon ``src`` goes onto polygon ``dst``.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        Pixels in any numeric type; the result has the same type.
    src, dst : Polygon or (n, 2) array_like of float
        Corresponding polygons: ``src`` in the input image's coordinates, ``dst``
        in the output's (x right, y down, pixel centres at +0.5).
    size : (width, height) or None
        Output size; the input's by default.
    interp : {"nearest", "linear", "cubic"}
    background : float or (C,) array_like
        Value of output pixels outside ``dst`` or whose pre-image lies outside
        the input, normalized: 0..1 spans an integer type's range, floats are
        taken as they are.
    alpha_channel : int or None
        Index of an alpha channel, resampled premultiplied.
    max_area : float or None
        Largest mesh triangle area in square pixels (None: automatic).
    warp_map : BijectiveMap or None
        A map already built for these polygons, to reuse.
    progress : callable or None
        Called with the name of each stage as it starts.

    Returns
    -------
    WarpResult

    Examples
    --------
    >>> img = np.zeros((8, 8), dtype=np.uint8)
    >>> tri = [[1, 1], [7, 1], [1, 7]]
    >>> warp_image(img, tri, tri).pixels.shape
    (8, 8, 1)
    """
    timings: dict[str, float] = {}
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3:
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {img.shape}")
    src = src if isinstance(src, Polygon) else Polygon(src, name="src")
    dst = dst if isinstance(dst, Polygon) else Polygon(dst, name="dst")
    check_pair(src, dst)
    if interp not in INTERPOLATIONS:
        raise InputError(f"unknown interpolation {interp!r}; choose one of {', '.join(INTERPOLATIONS)}")
    width, height = size if size is not None else (img.shape[1], img.shape[0])
    nc = img.shape[2]
    bg = np.asarray(background, dtype=np.float64).ravel()
    if bg.size not in (1, nc):
        raise InputError(f"background has {bg.size} values but the image has {nc} channels")
    if np.issubdtype(img.dtype, np.integer):
        bg = bg * np.iinfo(img.dtype).max

    report = progress or (lambda stage: None)
    fmap = warp_map
    if fmap is None:
        report("meshing and solving")
        fmap = BijectiveMap.between(src, dst, max_area=max_area, timings=timings)
    clock = time.perf_counter
    t0 = clock()
    report("composing the map")
    inverse = fmap.inverse_grid(width, height)
    t1 = clock()
    report("resampling")
    out = resample(img, inverse, interp=interp, background=bg, alpha_channel=alpha_channel)
    timings["compose"] = t1 - t0
    timings["resample"] = clock() - t1
    return WarpResult(out, fmap, inverse, timings)


def warp_file(
    input_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str],
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    **options,
) -> WarpResult:
    """Read an image and two polygon files, warp, and write the result atomically.

    Everything that can be checked before the work starts is checked first
    (polygons, input image, output path), so bad input fails fast and leaves
    no file behind. ``options`` are those of `warp_image`.
    """
    clock = time.perf_counter
    report = options.get("progress") or (lambda stage: None)
    check_output_path(output_path, inputs=(input_path, src_path, dst_path))
    src = read_polygon(src_path)
    dst = read_polygon(dst_path)
    check_pair(src, dst)
    t0 = clock()
    report("reading")
    image = read_image(input_path)
    t_read = clock() - t0
    _warn_if_outside(src, image.width, image.height, os.fspath(input_path))
    if not ((src.signed_area > 0) == (dst.signed_area > 0)):
        log.info("%s and %s run in opposite directions: the warp mirrors the image", src.name, dst.name)
    result = warp_image(image.pixels, src, dst, alpha_channel=image.alpha_channel, **options)
    t0 = clock()
    report("writing")
    write_image(
        output_path,
        RasterImage(result.pixels, image.channel_names, image.alpha_channel, image.attributes),
    )
    result.timings["read"] = t_read
    result.timings["write"] = clock() - t0
    return result


def _warn_if_outside(src: Polygon, width: int, height: int, image_name: str) -> None:
    xmin, ymin, xmax, ymax = src.bounds
    if xmax <= 0 or ymax <= 0 or xmin >= width or ymin >= height:
        log.warning(
            "%s lies entirely outside %s (%dx%d): the output will be all background",
            src.name,
            image_name,
            width,
            height,
        )
