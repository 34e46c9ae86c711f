"""Maps as files: STMaps (normalized source coordinates per pixel) in float OpenEXR or TIFF.

Convention (OpenImageIO's ``st_warp``; Nuke's STMap node with ``t`` up): the
pixel at (row r, column c) of an STMap holds, in channels R and G, the point
``(s, t)`` it takes its value from, normalized by the size ``W x H`` of the
image it samples: ``s = x / W`` and ``t = y / H`` for the continuous point
``(x, y)`` (x right, y down, pixel centres at +0.5, so the centre of pixel
``(i, j)`` is at ``s = (i + 0.5) / W``). ``t`` runs down the image by default,
as ``st_warp`` reads it; with ``t_up`` it runs up, ``t = 1 - y / H``, as Nuke's
STMap node reads it. Channel A is 1 where the map is defined and 0 elsewhere,
where R and G hold -1 (outside any image, so tools that ignore A sample
black); B is 0. The header says which way t runs and what the map is, and,
when the image the points refer to has another size than the map's own
(a warp with ``--size``), that size (``warpcli:source``, ``WxH``).

Normalized points would let a map fit any image; `load_stmap` still refuses,
by default, an image of another size than the map was made for (a 480x320
map silently applied to a 512x512 image stretches it): ``scale="stretch"``
scales the map's coordinates to the image.
"""

from __future__ import annotations

import os
import re

import numpy as np
from numpy.typing import NDArray

from ..errors import ImageInputError
from .imageio import RasterImage, read_image, write_image
from .pixels import to_unit

#: Header attributes: what the map is ("inverse": output -> input, "forward":
#: input -> output) and which way t runs ("down" or "up").
KIND_ATTRIBUTE = "warpcli:map"
T_ATTRIBUTE = "warpcli:t"
#: Header attribute: the size ``WxH`` of the image the points refer to, written when it is not the map's own.
SOURCE_ATTRIBUTE = "warpcli:source"
#: How `load_stmap` takes an image of another size than the map's: refuse it, or stretch the map to it.
SCALES = ("refuse", "stretch")
#: The kinds of map.
KINDS = ("inverse", "forward")
#: File extensions an STMap may have: formats that store float32.
STMAP_EXTENSIONS = (".exr", ".tif", ".tiff")

# TIFF keeps no attribute of its own choosing: the header is repeated in the
# ImageDescription, where every format keeps it.
_DESCRIPTION = "warpcli STMap: " + KIND_ATTRIBUTE + "={kind}, " + T_ATTRIBUTE + "={t}"
_DESCRIBED = re.compile(r"(warpcli:map|warpcli:t|warpcli:source)=(\w+)")


def check_stmap_path(path: str | os.PathLike[str]) -> None:
    """Refuse, before any work, an STMap path in a format that cannot hold float.

    An 8-bit map (PNG, JPEG) quantizes s and t to 1/255 of the image: a
    blocky warp. `save_stmap` writes float32, so the file must be OpenEXR or
    TIFF.

    Raises
    ------
    ImageInputError
        If the extension is not one of `STMAP_EXTENSIONS`.

    >>> check_stmap_path("map.exr")
    >>> check_stmap_path("map.png")
    Traceback (most recent call last):
    ...
    warpcli.errors.ImageInputError: map.png: an STMap must be float OpenEXR (.exr) or TIFF (.tif, .tiff)
    """
    name = os.fspath(path)
    if os.path.splitext(name)[1].lower() not in STMAP_EXTENSIONS:
        raise ImageInputError(f"{name}: an STMap must be float OpenEXR (.exr) or TIFF (.tif, .tiff)")


def save_stmap(
    path: str | os.PathLike[str],
    points: NDArray[np.float64],
    size: tuple[int, int],
    *,
    kind: str = "inverse",
    t_up: bool = False,
) -> None:
    """Write a map as a float32 RGBA STMap, OpenEXR or TIFF (atomically).

    The path is checked first (`check_stmap_path`): an STMap is never written
    as 8-bit PNG or JPEG. The header (``warpcli:map``, ``warpcli:t``) is also
    written in the ImageDescription, which TIFF keeps.

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

    Raises
    ------
    ImageInputError
        If ``path`` is not an .exr, .tif or .tiff file, or cannot be written.
    ImageIOError
        If writing fails.
    """
    check_stmap_path(path)
    if kind not in KINDS:
        raise ValueError(f"unknown map kind {kind!r}; choose one of {', '.join(KINDS)}")
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
    t_dir = "up" if t_up else "down"
    description = _DESCRIPTION.format(kind=kind, t=t_dir)
    source: tuple = ()
    if (int(w), int(h)) != (points.shape[1], points.shape[0]):
        # Only then: maps of the input's own size keep the bytes they always had.
        source = ((SOURCE_ATTRIBUTE, "string", f"{int(w)}x{int(h)}"),)
        description += f", {SOURCE_ATTRIBUTE}={int(w)}x{int(h)}"
    attrs = (
        (KIND_ATTRIBUTE, "string", kind),
        (T_ATTRIBUTE, "string", t_dir),
        *source,
        ("ImageDescription", "string", description),
        ("compression", "string", "zip"),
    )
    write_image(path, RasterImage(rgba, ("R", "G", "B", "A"), 3, attrs))


def load_stmap(
    path: str | os.PathLike[str],
    size: tuple[int, int],
    *,
    t_up: bool | None = None,
    kind: str = "inverse",
    scale: str = "stretch",
    image_name: str = "the image",
) -> NDArray[np.float64]:
    """Read an STMap as continuous points in an image of ``size``.

    A map whose header says it is of the other kind is refused: applying a
    forward map as if it were the inverse gives a wrong warp without any sign
    of it. A map without a header (from Nuke, say) is taken to be ``kind``.

    Parameters
    ----------
    size : (width, height)
        Size of the image the map samples.
    t_up : bool or None
        Which way t runs; None: as the file's header says, else down.
    kind : {"inverse", "forward"}
        The kind of map wanted: "inverse" (output -> input, what apply-map
        applies; written by ``--save-map``) or "forward" (input -> output,
        ``--save-forward-map``).
    scale : {"stretch", "refuse"}
        ``refuse``: the image must have the size the map was made for (its
        ``warpcli:source`` header, else the map's own size); ``stretch``:
        the map's normalized coordinates are scaled to any image.
    image_name : str
        How the message of a refused size names the image.

    Returns
    -------
    (H, W, 2) ndarray of float
        NaN where the map is undefined (alpha 0, or non-finite s, t).

    Raises
    ------
    ImageInputError
        If the file is not an image with at least two channels, or its header
        says it is a map of the other kind.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown map kind {kind!r}; choose one of {', '.join(KINDS)}")
    name = os.fspath(path)
    img = read_image(name)
    px = to_unit(img.pixels)  # an integer STMap spans 0..1
    if px.shape[2] < 2:
        raise ImageInputError(f"{name}: an STMap needs two channels (s, t), this image has {px.shape[2]}")
    header = _header(img.attributes)
    found = header.get(KIND_ATTRIBUTE, kind)
    if found != kind:
        if found == "forward":
            raise ImageInputError(
                f"{name}: this is a forward map (input -> output); apply-map needs the inverse map "
                "(output -> input) written by --save-map"
            )
        if found == "inverse":
            raise ImageInputError(f"{name}: this is an inverse map (output -> input), not a forward map")
        raise ImageInputError(f"{name}: an STMap of unknown kind {KIND_ATTRIBUTE}={found!r}, not {kind!r}")
    if scale not in SCALES:
        raise ValueError(f"unknown map scale {scale!r}; choose one of {', '.join(SCALES)}")
    w, h = size
    if scale == "refuse":
        made_for = _size(header.get(SOURCE_ATTRIBUTE)) or (px.shape[1], px.shape[0])
        if tuple(made_for) != (int(w), int(h)):
            raise ImageInputError(
                f"{name}: the map is for a {made_for[0]}x{made_for[1]} image but {image_name} is {w}x{h} "
                "(--map-scale stretch scales the map to it)"
            )
    if t_up is None:
        t_up = header.get(T_ATTRIBUTE) == "up"
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


def _size(text: object) -> tuple[int, int] | None:
    """``"WxH"`` as ``(W, H)``, else None."""
    m = re.fullmatch(r"(\d+)x(\d+)", text) if isinstance(text, str) else None
    return (int(m.group(1)), int(m.group(2))) if m else None


def _header(attributes) -> dict:
    """warpcli's header: its own attributes, else what the ImageDescription says."""
    attrs = {name: value for name, _, value in attributes}
    header = {key: value for key, value in attrs.items() if key in (KIND_ATTRIBUTE, T_ATTRIBUTE, SOURCE_ATTRIBUTE)}
    description = attrs.get("ImageDescription")
    if isinstance(description, str) and description.startswith("warpcli STMap:"):
        for key, value in _DESCRIBED.findall(description):
            header.setdefault(key, value)
    return header
