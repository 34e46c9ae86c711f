"""Cross-parameterization (the paper's §4.2): textures and vertex attributes moved between two charts through the map.

The map between the two surfaces is g = S1^-1 o f o S0 (§4.2), f the
bijective map between their UV charts, whose boundary loops are the
polygons. A texture is a function on SRC's chart: DST's texture at a texel y
is SRC's at f^-1(y), which is exactly what a warp's sampling plan computes,
with the texture as the input image (`warpcli.plan.SamplingPlan.from_map`).
A per-vertex attribute is read at f^-1 of each DST vertex's UV, interpolated
in SRC's triangle there.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..boundary import nearest_edge, on_boundary
from ..errors import InputError
from ..maps.compose import BijectiveMap, PullBack
from ..maps.fem.locate import TriangleLocator
from ..options import MapOptions, WarpOptions, resolve_options
from ..plan import SamplingPlan
from ..polygon import Polygon
from .chart import Chart, chart_of, uv_to_pixels
from .correspond import LoopPair, corresponding_loops
from .mesh import UVMesh

__all__ = [
    "ATTRIBUTE_SIZE", "EDGE_MARGIN", "PADDING", "ChartMap", "TextureTransfer", "chart_map", "transfer_attributes",
    "transfer_texture",
]  # fmt: skip

log = logging.getLogger("warpcli")

#: Default padding, in texels, around the chart in a moved texture: the chart's
#: edge texels are repeated outwards that far (as texture bakers' "margin" or
#: "dilation" does), so that mipmaps and bilinear lookups near the seam never
#: reach the background.
PADDING = 8
#: Texels of SRC's texture repeated beyond its border before resampling
#: (clamp-to-edge): a chart that touches the texture's border samples the
#: border's texels there, not the background.
EDGE_MARGIN = 8
#: The nominal texture size in which charts are mapped when only vertex
#: attributes are moved (no texture): the polygons' units, 1/512 of UV. The
#: FEM map's automatic mesh is some 0.02 units from the exact map at any size,
#: 4e-5 of the chart here, far below what interpolated vertex values show;
#: a size of 1024 costs about 4 times as much.
ATTRIBUTE_SIZE = (512, 512)


@dataclass(frozen=True, eq=False)
class ChartMap:
    """The map between two charts, in pixel coordinates of their textures.

    Attributes
    ----------
    map : BijectiveMap
        From SRC's texture pixels to DST's (``inverse``: back).
    src, dst : Chart
    src_xy, dst_xy : (T, 2) ndarray of float
        Every texture coordinate of each mesh in its texture's pixels.
    pair : LoopPair
        The polygons and their corners.
    """

    map: BijectiveMap
    src: Chart
    dst: Chart
    src_xy: NDArray[np.float64]
    dst_xy: NDArray[np.float64]
    pair: LoopPair


def _pair(value, what: str) -> tuple:
    if isinstance(value, (tuple, list)):
        if len(value) != 2:
            raise InputError(f"{what} must be one value or a (source, target) pair, got {value!r}")
        return tuple(value)
    return (value, value)


def chart_map(
    src: UVMesh,
    dst: UVMesh,
    src_size: tuple[int, int],
    dst_size: tuple[int, int],
    options: MapOptions | None = None,
    *,
    flip_v: bool | tuple[bool, bool] = False,
    src_start: int | None = None,
    dst_start: int | None = None,
    src_corners: Sequence[int] | None = None,
    dst_corners: Sequence[int] | None = None,
) -> ChartMap:
    """Build the bijective map between two surface patches' UV charts.

    Parameters
    ----------
    src, dst : UVMesh
        Disk-shaped patches (`warpcli.surface.chart.chart_of` checks them).
    src_size, dst_size : (int, int)
        The textures' sizes (width, height): the pixel units of the polygons.
    options : MapOptions or None
        The method and Theta, as for a warp.
    flip_v : bool or (bool, bool)
        v runs down (for both, or per side); by default up, as in OBJ.
    src_start, dst_start, src_corners, dst_corners
        The boundary correspondence (`warpcli.surface.correspond.corresponding_loops`).

    Returns
    -------
    ChartMap

    Raises
    ------
    MeshError
        For charts that are not disks, or a correspondence that cannot be made.
    PolygonError
        If a chart's boundary is not a simple polygon (it crosses itself in UV space).
    """
    fs, fd = _pair(flip_v, "flip_v")
    cs, cd = chart_of(src), chart_of(dst)
    src_xy = uv_to_pixels(src.uv, src_size, bool(fs))
    dst_xy = uv_to_pixels(dst.uv, dst_size, bool(fd))
    pair = corresponding_loops(
        src_xy[cs.loop], dst_xy[cd.loop], cs.loop_vertices, cd.loop_vertices, src_name=src.name, dst_name=dst.name,
        src_start=src_start, dst_start=dst_start, src_corners=src_corners, dst_corners=dst_corners,
    )  # fmt: skip
    ps = Polygon(pair.src, name=src.name)
    pd = Polygon(pair.dst, name=dst.name)
    if (ps.signed_area > 0) != (pd.signed_area > 0):
        log.info("%s and %s run in opposite directions in UV space: the map between the charts mirrors", src.name, dst.name)
    regions = ((0.0, 0.0, float(src_size[0]), float(src_size[1])), (0.0, 0.0, float(dst_size[0]), float(dst_size[1])))
    fmap = BijectiveMap.between(ps, pd, options or MapOptions(), regions=regions)
    return ChartMap(fmap, cs, cd, src_xy, dst_xy, pair)


@dataclass(frozen=True, eq=False)
class TextureTransfer:
    """A texture moved into another chart's layout.

    Attributes
    ----------
    pixels : (H, W, C) ndarray
        In the input texture's type.
    chart : (H, W) ndarray of bool
        The texels the chart covers (before padding).
    map : ChartMap
    """

    pixels: NDArray
    chart: NDArray[np.bool_]
    map: ChartMap


def transfer_texture(
    texture: ArrayLike,
    src: UVMesh,
    dst: UVMesh,
    options: WarpOptions | None = None,
    *,
    padding: int = PADDING,
    alpha_channel: int | None = None,
    associated_alpha: bool = False,
    chart: ChartMap | None = None,
    flip_v: bool | tuple[bool, bool] = False,
    src_start: int | None = None,
    dst_start: int | None = None,
    src_corners: Sequence[int] | None = None,
    dst_corners: Sequence[int] | None = None,
    **changes,
) -> TextureTransfer:
    """Move SRC's texture into DST's UV layout through the map between the charts.

    Each texel of DST's chart takes SRC's texture at its pre-image, with the
    warp's filters and antialiasing (``options.interp``, ``antialias``: with
    ``linear`` each texel is averaged over its footprint where the map
    shrinks). The texels the chart's edge crosses take the texture's value
    whole rather than blended with the background (with ``padding`` > 0;
    ``padding=0`` blends them, as `warp` does), and then the ``padding``
    texels around the chart repeat the nearest chart texel (a baker's
    dilation, so that filtering near a seam never reaches the background);
    everything farther is ``options.background``. SRC's texture is sampled
    clamped to its edge (its border texels repeat outwards).

    Parameters
    ----------
    texture : (H, W) or (H, W, C) array_like
        SRC's texture, any numeric type; the result has its type.
    src, dst : UVMesh
    options : WarpOptions or None
        ``size`` is DST's texture size (default: SRC's texture's);
        ``interp``, ``antialias``, ``background`` and ``map`` as for a warp.
    padding : int
        Texels of dilation around the chart (0 to 4096).
    alpha_channel, associated_alpha
        As for `warpcli.warp_image`.
    chart : ChartMap or None
        A map already built for these meshes and sizes.
    flip_v, src_start, dst_start, src_corners, dst_corners
        See `chart_map`.
    **changes
        Fields of `WarpOptions` or `MapOptions` to change.

    Returns
    -------
    TextureTransfer

    Raises
    ------
    InputError
        For bad meshes, options or correspondences.
    FoldOverError
        If the map would fold (never returned).

    References
    ----------
    Schneider & Hormann, CAGD 2015, §4.2: g = S1^-1 o f o S0.
    """
    opts = resolve_options(options, changes)
    if opts.outside != "background":
        raise InputError("a texture is moved onto the background (outside='background'), not pasted over its input")
    if isinstance(padding, bool) or not isinstance(padding, (int, np.integer)) or not 0 <= padding <= 4096:
        raise InputError(f"padding must be a whole number of texels from 0 to 4096, got {padding!r}")
    img = np.asarray(texture)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3 or 0 in img.shape or img.dtype.kind not in "uif":
        raise InputError(f"texture must be a non-empty (H, W) or (H, W, C) array of numbers, got shape {img.shape}")
    src_size = (img.shape[1], img.shape[0])
    size = opts.size if opts.size is not None else src_size
    from ..pipeline import check_output

    check_output(opts, size, src_size, img[:1, :1])  # memory and background, before any map
    if chart is None:
        chart = chart_map(
            src, dst, src_size, size, opts.map, flip_v=flip_v, src_start=src_start, dst_start=dst_start,
            src_corners=src_corners, dst_corners=dst_corners,
        )  # fmt: skip
    xmin, ymin, xmax, ymax = chart.map.src.bounds
    if xmin < 0 or ymin < 0 or xmax > src_size[0] or ymax > src_size[1]:
        log.warning("%s: the chart reaches beyond its texture (UVs outside 0..1): its edge texels repeat there", src.name)
    width, height = size
    plan = SamplingPlan.from_map(
        chart.map, width, height, interp=opts.interp, antialias=opts.antialias, background=opts.background
    )
    m = EDGE_MARGIN
    pull = plan.pull
    shifted = PullBack(pull.points + m, pull.jacobian, pull.origin, pull.size)
    coverage = plan.coverage
    if coverage is not None:
        # Texels the edge crosses are the chart's too: taken whole when padding follows.
        fraction = np.ones_like(coverage.fraction) if padding > 0 else coverage.fraction
        source = None if coverage.source_points is None else coverage.source_points + m
        coverage = dataclasses.replace(coverage, fraction=fraction, source_points=source)
    plan = dataclasses.replace(plan, pull=shifted, coverage=coverage)
    padded = np.pad(img, ((m, m), (m, m), (0, 0)), mode="edge")
    out = plan.render(padded, alpha_channel=alpha_channel, associated_alpha=associated_alpha)
    mask = np.zeros((height, width), dtype=bool)
    r, c = pull.origin
    window = np.isfinite(pull.points[..., 0])
    if coverage is not None and coverage.pixels.size:
        flat = window.reshape(-1)
        flat[coverage.pixels] = True
    mask[r : r + window.shape[0], c : c + window.shape[1]] = window
    if padding > 0 and mask.any() and not mask.all():
        out = _dilated(out, mask, padding)
    return TextureTransfer(out, mask, chart)


def _dilated(pixels: NDArray, mask: NDArray[np.bool_], padding: int) -> NDArray:
    """Texels within ``padding`` of the chart (Euclidean) take the nearest chart texel's value."""
    from scipy.ndimage import distance_transform_edt

    # Only the box the padding can reach is transformed.
    ys, xs = np.nonzero(mask)
    y0, y1 = max(int(ys.min()) - padding, 0), min(int(ys.max()) + padding + 1, mask.shape[0])
    x0, x1 = max(int(xs.min()) - padding, 0), min(int(xs.max()) + padding + 1, mask.shape[1])
    sub = mask[y0:y1, x0:x1]
    dist, (iy, ix) = distance_transform_edt(~sub, return_indices=True)
    fill = (~sub) & (dist <= padding)
    out = pixels.copy()
    box = out[y0:y1, x0:x1]
    box[fill] = box[iy[fill], ix[fill]]
    return out


def transfer_attributes(
    src: UVMesh,
    dst: UVMesh,
    names: Sequence[str] | None = None,
    options: MapOptions | None = None,
    *,
    size: tuple[int, int] = ATTRIBUTE_SIZE,
    chart: ChartMap | None = None,
    flip_v: bool | tuple[bool, bool] = False,
    src_start: int | None = None,
    dst_start: int | None = None,
    src_corners: Sequence[int] | None = None,
    dst_corners: Sequence[int] | None = None,
) -> dict:
    """SRC's per-vertex attributes at DST's vertices, through the map between the charts.

    Each DST vertex's UV is pulled back through the map (boundary vertices
    by the exact boundary correspondence), located in SRC's UV triangulation
    and the attributes of that triangle's three vertices are interpolated
    barycentrically. A point that rounding puts just outside SRC's chart
    takes the nearest point of its boundary. A DST vertex used by no face
    has no UV to pull back: it gets NaN.

    Parameters
    ----------
    src, dst : UVMesh
    names : sequence of str or None
        Which of SRC's attributes; None: all.
    options : MapOptions or None
    size : (int, int)
        The texture size in which both charts are mapped (pixel units for the
        map and its checks; the result hardly depends on it).
    chart : ChartMap or None
        A map already built between these meshes.
    flip_v, src_start, dst_start, src_corners, dst_corners
        See `chart_map`.

    Returns
    -------
    dict of str to (V,) ndarray of float
        Per DST vertex (position), in SRC's units.

    Raises
    ------
    InputError
        If SRC has no attributes, or one of ``names``.
    """
    chosen = list(src.attributes) if names is None else list(names)
    if not chosen:
        raise InputError(f"{src.name}: the vertices carry no attributes (colours or other properties) to move")
    missing = [k for k in chosen if k not in src.attributes]
    if missing:
        have = ", ".join(src.attributes) or "none"
        raise InputError(f"{src.name}: no vertex attribute {missing[0]!r} (it has {have})")
    if chart is None:
        chart = chart_map(
            src, dst, size, size, options, flip_v=flip_v, src_start=src_start, dst_start=dst_start,
            src_corners=src_corners, dst_corners=dst_corners,
        )  # fmt: skip
    fmap = chart.map
    if len(dst.uv) == len(dst.positions) and np.array_equal(dst.triangles_pos, dst.triangles_uv):
        pos_uv = np.arange(len(dst.positions))  # per-vertex UVs (PLY): every vertex has one
    else:
        pos_uv = dst.position_to_uv()
    has_uv = pos_uv >= 0
    q = chart.dst_xy[pos_uv[has_uv]]
    p = fmap.inverse(q)
    # Boundary vertices go by the exact boundary map, not through Theta and back.
    dpoly = fmap.dst.points
    on_loop = np.isin(pos_uv[has_uv], chart.dst.loop)
    span = float(np.ptp(dpoly, axis=0).max())
    idx = np.flatnonzero(on_loop)
    if idx.size:
        hit, edge, t = on_boundary(q[idx], dpoly, 1e-9 * span)
        p[idx[hit]] = fmap.inverse_boundary(edge, t)
    lost = ~np.isfinite(p).all(axis=1)
    if lost.any():
        edge, t, dist = nearest_edge(q[lost], dpoly)
        far = int((dist > 1e-6 * span).sum())
        if far:
            log.warning("%s: %d vertices lie outside the chart's boundary: they take the nearest boundary point", dst.name, far)
        p[lost] = fmap.inverse_boundary(edge, t)
    values = _interpolate(src, chart, p, chosen)
    out = {}
    for k in chosen:
        v = np.full(len(dst.positions), np.nan)
        v[has_uv] = values[k]
        out[k] = v
    return out


def _interpolate(src: UVMesh, chart: ChartMap, points: NDArray[np.float64], names: list) -> dict:
    """SRC's attributes at points of its chart (pixels): barycentric in the UV triangle holding each."""
    tri = src.triangles_uv
    where, bary = TriangleLocator(chart.src_xy, tri).locate(points)
    corner_pos = src.triangles_pos
    out = {}
    lost = where < 0
    if lost.any():
        # Rounding puts a few points a hair outside: the nearest point of the boundary loop.
        loop = chart.src.loop
        edge, t, _ = nearest_edge(points[lost], chart.src_xy[loop])
        uv_pos = src.uv_to_position()
        a = uv_pos[loop[edge]]
        b = uv_pos[loop[(edge + 1) % len(loop)]]
    found = ~lost
    for k in names:
        attr = np.asarray(src.attributes[k], dtype=np.float64)
        v = np.empty(len(points))
        f = where[found]
        b3 = bary[found]
        v[found] = b3[:, 0] * attr[corner_pos[f, 0]] + b3[:, 1] * attr[corner_pos[f, 1]] + b3[:, 2] * attr[corner_pos[f, 2]]
        if lost.any():
            v[lost] = (1.0 - t) * attr[a] + t * attr[b]
        out[k] = v
    return out
