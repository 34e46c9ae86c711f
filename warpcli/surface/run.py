"""``warp texture`` from files: two meshes in, a texture image or a mesh with moved vertex attributes out."""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..options import WarpOptions, resolve_options
from ..outputs import PendingOutputs, check_output_path, write_checked
from .formats import read_mesh
from .mesh import MESH_KINDS, MeshError
from .transfer import (
    ATTRIBUTE_SIZE,
    PADDING,
    ChartMap,
    chart_map,
    transfer_attributes,
    transfer_texture,
)

__all__ = ["COLOURS", "TransferResult", "transfer_file"]

log = logging.getLogger("warpcli")

#: Vertex properties that are colour channels: moved between types by what 1.0 is in each.
COLOURS = ("red", "green", "blue", "alpha")


@dataclass(frozen=True, eq=False)
class TransferResult:
    """What `transfer_file` wrote: ``kind`` ``"texture"`` or ``"mesh"``, the map, and the attributes moved."""

    kind: str
    map: ChartMap
    attributes: tuple = ()


def _unit(ptype: str) -> float:
    from .ply import TYPES

    dt = np.dtype(TYPES[ptype])
    return float(np.iinfo(dt).max) if dt.kind in "iu" else 1.0


def transfer_file(
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str],
    options: WarpOptions | None = None,
    *,
    texture: str | os.PathLike[str] | None = None,
    padding: int = PADDING,
    attributes: Sequence[str] | None = None,
    flip_v: bool | tuple[bool, bool] = False,
    src_start: int | None = None,
    dst_start: int | None = None,
    src_corners: Sequence[int] | None = None,
    dst_corners: Sequence[int] | None = None,
    **changes,
) -> TransferResult:
    """Move SRC's texture, or its vertex attributes, onto DST through the map between their UV charts.

    Parameters
    ----------
    src_path, dst_path : path-like
        Disk-shaped surface patches with texture coordinates (``.obj``, ``.ply``).
    output_path : path-like
        An image (any format OpenImageIO writes): SRC's texture in DST's UV
        layout (`warpcli.surface.transfer.transfer_texture`). Or a mesh of
        DST's format: DST with SRC's per-vertex attributes
        (`warpcli.surface.transfer.transfer_attributes`); an OBJ takes colours
        (``v x y z r g b``) only, every other line kept byte for byte; a PLY
        keeps its format (ASCII or binary) and gets the properties added, or
        replaced where it has them.
    options : WarpOptions or None
        The map (``map``) and, for a texture, resampling and output
        (``size``: DST's texture size, default SRC's texture's; ``dtype``).
    texture : path-like or None
        SRC's texture image; default the one SRC names (an OBJ material's
        ``map_Kd``, a PLY's ``comment TextureFile``).
    padding : int
        Texels of dilation around the chart (see `transfer_texture`).
    attributes : sequence of str or None
        Which vertex attributes to move; default all of SRC's (an OBJ output:
        its colours).
    flip_v, src_start, dst_start, src_corners, dst_corners
        See `warpcli.surface.transfer.chart_map`.

    Returns
    -------
    TransferResult

    Raises
    ------
    InputError
        For bad meshes, a missing texture, bad options or output paths
        (nothing is written).
    """
    opts = resolve_options(options, changes)
    src_name, dst_name, out_name = os.fspath(src_path), os.fspath(dst_path), os.fspath(output_path)
    out_kind = os.path.splitext(out_name)[1].lower()
    corr = dict(flip_v=flip_v, src_start=src_start, dst_start=dst_start, src_corners=src_corners, dst_corners=dst_corners)
    theta_file = opts.map.theta_file
    inputs = tuple(p for p in (src_name, dst_name, texture, theta_file) if p is not None)
    if out_kind in (".gltf", ".glb"):
        raise InputError(f"{out_name}: glTF meshes are read, not written: give a DST and an OUT of .ply or .obj")
    if out_kind in MESH_KINDS:
        dst_kind = os.path.splitext(dst_name)[1].lower()
        if out_kind != dst_kind:
            raise InputError(f"{out_name}: a mesh output has DST's format ({dst_kind or 'none'}), it is DST with new vertex values")
        check_output_path(out_name, inputs=inputs)
        return _mesh_output(src_name, dst_name, out_name, opts, attributes, corr)
    from ..pipeline import write_like
    from ..raster.imageio import check_image_output, read_image

    check_image_output(out_name, inputs=inputs)
    src = read_mesh(src_name)
    dst = read_mesh(dst_name)
    tex = texture if texture is not None else src.texture
    if tex is None:
        raise MeshError(f"{src_name}: names no texture (map_Kd of its material, or comment TextureFile): give --texture")
    if os.path.abspath(os.fspath(tex)) == os.path.abspath(out_name):
        raise InputError(f"{out_name}: the output would overwrite SRC's texture")
    image = read_image(tex)
    result = transfer_texture(
        image.pixels, src, dst, opts, padding=padding, alpha_channel=image.alpha_channel,
        associated_alpha=image.associated_alpha, **corr,
    )  # fmt: skip
    with PendingOutputs() as pending:
        write_like(pending.path(out_name), image, result.pixels, opts.dtype)
    return TransferResult("texture", result.map)


def _mesh_output(src_name, dst_name, out_name, opts: WarpOptions, names, corr) -> TransferResult:
    src = read_mesh(src_name)
    if out_name.lower().endswith(".obj"):
        from .obj import COLOURS as OBJ_COLOURS
        from .obj import read_obj

        target = read_obj(dst_name)
        chosen = list(names) if names is not None else [k for k in OBJ_COLOURS if k in src.attributes]
        others = [k for k in chosen if k not in OBJ_COLOURS]
        if others:
            raise InputError(f"{out_name}: an OBJ holds vertex colours only (red, green, blue), not {others[0]!r}: write a PLY")
        if sorted(chosen) != sorted(OBJ_COLOURS):
            raise InputError(f"{src_name}: an OBJ's vertex colours need red, green and blue, and SRC has {', '.join(src.attributes) or 'no attributes'}")
    else:
        from .ply import read_ply

        target = read_ply(dst_name)
        chosen = list(names) if names is not None else list(src.attributes)
    dst = target.mesh
    size = opts.size if opts.size is not None else ATTRIBUTE_SIZE
    chart = chart_map(src, dst, size, size, opts.map, **corr)
    moved = transfer_attributes(src, dst, chosen, chart=chart)
    unused = int((~np.isfinite(next(iter(moved.values())))).sum())
    if unused:
        log.warning("%s: %d vertices are in no face (no UV): they keep their values, or get 0", dst_name, unused)
    if out_name.lower().endswith(".obj"):
        rgb = np.stack([moved[k] / _unit(src.attribute_types.get(k, "float")) for k in OBJ_COLOURS], axis=1)
        old = np.stack([dst.attributes.get(k, np.zeros(len(dst.positions))) for k in OBJ_COLOURS], axis=1)
        rgb = np.where(np.isfinite(rgb), rgb, old)
        data = target.with_colours(rgb)
    else:
        vertex = target.element("vertex")
        have = {p.name: p.type for p in vertex.properties}
        values, types = {}, {}
        for k, v in moved.items():
            stype = src.attribute_types.get(k, "float")
            colour = k in COLOURS
            if k in have:
                types[k] = have[k]
            elif colour and stype == "float" and not src.name.lower().endswith(".ply"):
                types[k] = "uchar"  # OBJ and glTF colours (0..1) become PLY's usual 8-bit colours
            else:
                types[k] = stype
            if colour:
                v = v / _unit(stype) * _unit(types[k])
            old = vertex.data[k].astype(np.float64) if k in have else np.zeros(len(v))
            values[k] = np.where(np.isfinite(v), v, old)
        data = target.with_vertex_properties(values, types)
    with PendingOutputs() as pending:
        write_checked(pending.path(out_name), data, out_name)
    return TransferResult("mesh", chart, tuple(chosen))
