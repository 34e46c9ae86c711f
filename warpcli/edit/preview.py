"""The editor's preview: the image at preview size, and the real map at preview density, sent as a textured mesh."""

from __future__ import annotations

import dataclasses
import json
import math
import struct
import threading
import time
import zlib
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import PolygonError
from ..maps.base import ThetaMap
from ..maps.cage import CageMap
from ..maps.compose import BijectiveMap, theta_for
from ..maps.registry import METHODS
from ..options import MapOptions
from ..polygon import Polygon, check_pair
from ..polygon.partition import Partition
from ..raster.imageio import RasterImage, convert_pixels
from ..within import WithinPair

__all__ = [
    "PREVIEW_DRAG_TRIANGLES", "PREVIEW_SIDE", "PREVIEW_TRIANGLES", "PreviewImage", "PreviewMapper", "PreviewMesh", "encode_png", "preview_areas",
    "preview_image",
]  # fmt: skip

#: Longest side of the preview, in pixels: larger images are shown shrunk by a whole factor.
PREVIEW_SIDE = 1024
#: About how many triangles of the largest size each preview mesh has: the
#: preview's density (`preview_areas`), coarse enough to rebuild during a drag.
PREVIEW_TRIANGLES = 1500
#: The same for the side being dragged, while the pointer is down: a third of the
#: triangles rebuilds in half the time (the map at the full preview density
#: follows when the pointer is released).
PREVIEW_DRAG_TRIANGLES = 500


@dataclass(frozen=True)
class PreviewImage:
    """The image as the page shows it: RGBA bytes, shrunk by a whole ``factor``.

    Attributes
    ----------
    pixels : (h, w, 4) ndarray of uint8
        Straight (not premultiplied) RGBA; opaque where the image has no alpha.
    factor : int
        Preview pixel (r, c) is the mean of the image's ``factor`` x ``factor``
        block at (r * factor, c * factor); image point p is preview point p / factor.
    size : (int, int)
        The whole image's (width, height).
    """

    pixels: NDArray[np.uint8]
    factor: int
    size: tuple[int, int]

    @property
    def preview_size(self) -> tuple[int, int]:
        """The preview's (width, height)."""
        return int(self.pixels.shape[1]), int(self.pixels.shape[0])


def preview_image(image: RasterImage, side: int = PREVIEW_SIDE) -> PreviewImage:
    """Shrink an image by the smallest whole factor that brings its longest side to at most ``side``.

    Block means keep the preview a faithful picture of the image (no
    aliasing); a whole factor keeps the coordinates exact (image point p is
    preview point p / factor). The last ``width % factor`` columns and
    ``height % factor`` rows, less than a block, are left out.
    """
    px = convert_pixels(image.pixels, "float")
    h, w = px.shape[:2]
    factor = max(1, math.ceil(max(w, h) / side))
    ph, pw = max(1, h // factor), max(1, w // factor)
    if factor > 1:
        block = px[: ph * factor, : pw * factor]
        px = block.reshape(ph, factor, pw, factor, -1).mean(axis=(1, 3), dtype=np.float32)
    channels = px.shape[2]
    alpha = image.alpha_channel
    colour = [c for c in range(channels) if c != alpha][:3]
    rgb = px[:, :, colour]
    if rgb.shape[2] == 1:
        rgb = np.repeat(rgb, 3, axis=2)
    elif rgb.shape[2] == 2:
        rgb = np.concatenate([rgb, rgb[:, :, :1] * 0], axis=2)
    a = px[:, :, alpha : alpha + 1] if alpha is not None else np.ones((ph, pw, 1), np.float32)
    if alpha is not None and image.associated_alpha:  # the page draws straight colour
        with np.errstate(divide="ignore", invalid="ignore"):
            rgb = np.where(a > 0, rgb / np.where(a > 0, a, 1), 0)
    rgba = np.concatenate([rgb, a], axis=2)
    return PreviewImage(np.ascontiguousarray(convert_pixels(rgba.astype(np.float32), "uint8")), factor, (w, h))


def encode_png(rgba: NDArray[np.uint8]) -> bytes:
    """An 8-bit RGBA image as PNG bytes (the standard library's zlib; no filter).

    >>> encode_png(np.zeros((1, 1, 4), np.uint8))[:8]
    b'\\x89PNG\\r\\n\\x1a\\n'
    """
    h, w = rgba.shape[:2]
    raw = np.zeros((h, 1 + 4 * w), np.uint8)
    raw[:, 1:] = rgba.reshape(h, 4 * w)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw.tobytes(), 1)) + chunk(b"IEND", b"")


def preview_areas(src: Polygon, dst: Polygon, triangles: int = PREVIEW_TRIANGLES) -> tuple[float, float]:
    """The preview's ``max_area`` (source, target): each polygon's area over ``triangles``, at least 1 px²."""
    return tuple(max(1.0, abs(p.signed_area) / triangles) for p in (src, dst))  # type: ignore[return-value]


@dataclass(frozen=True)
class PreviewMesh:
    """The map's pull-back as a textured mesh of the target, in preview pixels.

    Attributes
    ----------
    positions : (N, 2) ndarray of float32
        Vertices of a triangle mesh of the target polygon.
    texcoords : (N, 2) ndarray of float32
        f^-1 of each vertex: the source point it shows.
    triangles : (M, 3) ndarray of uint32
    map : BijectiveMap
        The map they come from.
    max_area : (float, float)
        The density it was built at (`preview_areas`).
    rebuilt : tuple of str
        Which sides were built for it (``"source"``, ``"target"``); the others were reused.
    seconds : float
        Time spent building and evaluating.
    """

    positions: NDArray[np.float32]
    texcoords: NDArray[np.float32]
    triangles: NDArray[np.uint32]
    map: BijectiveMap | CageMap
    max_area: tuple[float, float]
    rebuilt: tuple[str, ...]
    seconds: float

    def to_bytes(self, header: dict) -> bytes:
        """``header`` (JSON, with the counts added) and the arrays, as the page reads them.

        Layout: uint32 length of the JSON header, the header padded with
        spaces to a multiple of 4 bytes, then float32 ``x, y, u, v`` per
        vertex and uint32 indices, little-endian.
        """
        doc = dict(header, vertices=len(self.positions), triangles=len(self.triangles))
        text = json.dumps(doc).encode()
        text += b" " * (-len(text) % 4)
        data = np.concatenate([self.positions, self.texcoords], axis=1).astype("<f4")
        return struct.pack("<I", len(text)) + text + data.tobytes() + self.triangles.astype("<u4").tobytes()


class PreviewMapper:
    """Builds the preview's maps the way `warpcli.maps.compose.build_map` does, keeping the side that did not move.

    `build_map` builds both harmonic maps every time. In a drag only one
    polygon moves, and with Theta unchanged (Theta ``regular`` depends on
    the vertex count alone) the other side's map is the same one: it is
    kept, keyed by everything it depends on (polygon, Theta, method,
    options, region). The map is then `BijectiveMap(phi0, phi1)`, certified
    as `build_map` certifies it: the same map, built by the same calls.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._kept: dict[str, tuple[tuple, ThetaMap]] = {}
        # The last cage map (its face maps are reused where a face did not move) and its faces' target meshes.
        self._cage: CageMap | None = None
        self._face_meshes: dict[int, tuple] = {}
        # The last within pair, with what it was made from: (key, pair, src, dst).
        self._within: tuple | None = None

    def build(self, src: Polygon, dst: Polygon, options: MapOptions, region: tuple[float, float, float, float]) -> PreviewMesh:
        """The map between ``src`` and ``dst`` at ``options``' density, and its mesh of the target.

        Raises
        ------
        InputError
            If the polygons do not correspond or the options are bad.
        FoldOverError
            If the map would fold.
        """
        t0 = time.perf_counter()
        with self._lock:
            check_pair(src, dst)
            theta = theta_for(src, dst, options)
            method = METHODS[options.method].load()
            rebuilt = []
            maps = []
            areas = options.areas()
            # Only the source's lookup tables are made (it is inverted); the
            # target is read at its own mesh's vertices, never on a pixel grid.
            for i, (polygon, role, side) in enumerate(((src, "source", "inverse"), (dst, "target", None))):
                # A side's map depends on the other side's max_area not at all.
                own = dataclasses.replace(options, max_area=areas[i])
                key = (polygon.points.tobytes(), polygon.name, theta.points.tobytes(), own, region)
                kept = self._kept.get(role)
                if kept is not None and kept[0] == key:
                    maps.append(kept[1])
                    continue
                phi = method.build(polygon, theta, options, role, region)
                if side is not None and hasattr(phi, "precompute"):
                    phi.precompute(side)
                self._kept[role] = (key, phi)
                maps.append(phi)
                rebuilt.append(role)
            fmap = BijectiveMap(*maps)
            if options.check:
                fmap.check_bijective()
            positions, triangles, tex = _target_mesh(*maps, dst, options.areas()[1], region)
        return PreviewMesh(
            positions.astype(np.float32), tex.astype(np.float32), np.asarray(triangles, np.uint32), fmap,
            options.areas(), tuple(rebuilt), time.perf_counter() - t0,
        )  # fmt: skip


    def build_cage(
        self, src: Partition, dst: Partition, options: MapOptions, region: tuple[float, float, float, float], factor: int = 1
    ) -> PreviewMesh:
        """The map between two cage meshes (`warpcli.maps.cage.build_cage_map`) at ``options``' density, and its mesh of the target.

        The meshes, ``options``' density and ``region`` are in the image's
        pixels; the mesh returned is in the preview's (divided by ``factor``).
        The map is the one made in the image's pixels (the export's cage mesh
        itself), which the preview's own scaled copy would only repeat at the
        cost of validating two more meshes.

        A face's map on a side is kept from the last call where that side of
        the face did not move (`build_cage_map`'s ``kept``): in a drag within
        an outline (`within_pair`) only the faces at the dragged vertex
        change, and the source side does not change at all.

        Raises
        ------
        PolygonError, InputError, FoldOverError
            As `build_cage_map`.
        """
        from ..maps.cage import build_cage_map

        t0 = time.perf_counter()
        with self._lock:
            before = self._cage
            fmap = build_cage_map(src, dst, options, regions=(region, region), kept=before)
            self._cage = fmap
            old = (set(), set()) if before is None else ({id(m.phi0) for m in before.face_maps}, {id(m.phi1) for m in before.face_maps})
            rebuilt = tuple(
                role for role, side, ids in (("source", "phi0", old[0]), ("target", "phi1", old[1]))
                if any(id(getattr(m, side)) not in ids for m in fmap.face_maps)
            )  # fmt: skip
            if options.check:
                fmap.check_bijective()
            parts, offset, meshes = [], 0, {}
            for face_map in fmap.face_maps:
                # A face whose two maps were both kept has the same mesh and texture as last time.
                key = (id(face_map.phi0), id(face_map.phi1), options.areas()[1], region)
                kept = self._face_meshes.get(key)
                if kept is None or kept[0] is not face_map.phi0 or kept[1] is not face_map.phi1:
                    kept = (face_map.phi0, face_map.phi1,
                            _target_mesh(face_map.phi0, face_map.phi1, face_map.dst, options.areas()[1], region))  # fmt: skip
                meshes[key] = kept
                positions, triangles, tex = kept[2]
                parts.append((positions, np.asarray(triangles) + offset, tex))
                offset += len(positions)
            self._face_meshes = meshes
            positions = np.concatenate([p[0] for p in parts])
            triangles = np.concatenate([p[1] for p in parts])
            tex = np.concatenate([p[2] for p in parts])
            if factor != 1:
                positions, tex = positions / factor, tex / factor
        return PreviewMesh(
            positions.astype(np.float32), tex.astype(np.float32), np.asarray(triangles, np.uint32), fmap,
            options.areas(), rebuilt, time.perf_counter() - t0,
        )  # fmt: skip

    def within_pair(
        self, src: Polygon, dst: Polygon, within: str, image_size: tuple[int, int], drag: str | None = None
    ) -> WithinPair:
        """`warpcli.within.within_pair` of two polygons; in a drag, the last call's cut of the ring kept where it still holds.

        While a side is dragged (``drag`` not None), the ring's cut of the
        last call (its faces, by vertex index) is kept when the outline is
        the same and the moved polygon's vertices, put in place of the old
        ones, still leave every face a valid partition on that side: checked
        exactly, by building the side's `Partition` as `within_pair` does
        (the same checks, so a cut that no longer holds is never shown). The
        preview then moves with the cut it had, as a drag moves the polygon:
        the map is the cage map of a valid cut of the ring. Otherwise, and
        always when no side is dragged (the pointer released, the export),
        the ring is cut anew by `within_pair`: the command line's own cut and
        errors.
        """
        from ..within import within_pair

        key = (within, image_size, src.name, dst.name, src.n, dst.n)
        with self._lock:
            last = self._within
        pair = None
        if drag is not None and last is not None and last[0] == key:
            pair = _moved_pair(last[1], last[2], last[3], src, dst, within, image_size)
        if pair is None:
            pair = within_pair(src, dst, within, image_size)
        with self._lock:
            self._within = (key, pair, src, dst)
        return pair


def _moved_pair(
    pair: WithinPair, old_src: Polygon, old_dst: Polygon, src: Polygon, dst: Polygon, within: str, image_size: tuple[int, int]
) -> WithinPair | None:
    """``pair`` (made for ``old_src``, ``old_dst``) with the cage's vertices moved to ``src``'s and ``dst``'s, the ring's
    faces kept; None unless the outline is the same and both sides are still valid partitions."""
    from ..polygon.outline import outline_polygon

    n = src.n
    if pair.cage_faces != 1 or pair.cage_loops[0] != tuple(range(n)):
        return None  # one polygon cage, its vertices first and in order: as within_pair makes it for one polygon
    outline = outline_polygon(within, image_size, [src.points, dst.points])
    stretched = None
    if not np.array_equal(outline, pair.outline):
        # A margin's box moved with an outermost vertex: its points (on the box's sides, the same on both
        # sides) go along with it, stretched as the box was; the corners exactly to the new box's.
        stretched = _stretched_outline(pair, outline)
        if stretched is None:
            return None
    sides = []
    for mesh, old, new in ((pair.src, old_src, src), (pair.dst, old_dst, dst)):
        if np.array_equal(old.points, new.points) and stretched is None:
            sides.append(mesh)
            continue
        vertices = np.array(mesh.vertices)
        vertices[:n] = new.points
        if stretched is not None:
            vertices[stretched[0]] = stretched[1]
        try:
            sides.append(mesh.moved(vertices))  # every check of a cage mesh, exactly
        except PolygonError:
            return None
    return dataclasses.replace(pair, src=sides[0], dst=sides[1], outline=outline)


def _stretched_outline(pair: WithinPair, outline: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.float64]] | None:
    """The outline's points of ``pair`` (vertex indices, new positions) moved from its box onto the box ``outline``,
    or None unless both are boxes (four corners, sides parallel to the axes) and the points are the same on both sides."""
    old = pair.outline
    loop = pair.src.loops[0]
    if len(old) != 4 or len(outline) != 4 or not np.array_equal(pair.src.vertices[loop], pair.dst.vertices[loop]):
        return None
    lo, hi, new_lo, new_hi = old.min(axis=0), old.max(axis=0), outline.min(axis=0), outline.max(axis=0)
    corners = {tuple(p) for p in old.tolist()}
    if corners != {(x, y) for x in (lo[0], hi[0]) for y in (lo[1], hi[1])} or not (hi > lo).all():
        return None
    points = pair.src.vertices[loop]
    moved = new_lo + (points - lo) * ((new_hi - new_lo) / (hi - lo))
    # On a side a coordinate is the box's own (lo or hi): it becomes the new box's exactly.
    for axis in (0, 1):
        for was, now in ((lo[axis], new_lo[axis]), (hi[axis], new_hi[axis])):
            moved[points[:, axis] == was, axis] = now
    return loop, moved


def _target_mesh(
    phi0: ThetaMap, phi1: ThetaMap, dst: Polygon, area: float | None, region: tuple[float, float, float, float]
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.float64]]:
    """A triangle mesh of the target ``dst`` and f^-1 = phi0^-1 o phi1 at its vertices: (positions, triangles, texcoords).

    FEM: phi1's own mesh (it takes its vertices to ``values`` by
    definition); the meshless methods: ``dst`` meshed at ``area`` (or
    `PREVIEW_TRIANGLES` of its area). A vertex whose pre-image could not be
    found (none expected) shows nothing: its triangles are left out.
    """
    mesh = getattr(phi1, "mesh", None)
    if mesh is not None and hasattr(phi1, "values"):
        positions, triangles, in_theta = mesh.vertices, mesh.triangles, phi1.values
    else:
        from ..maps.fem.mesh import mesh_polygon

        mesh = mesh_polygon(dst, area or max(1.0, abs(dst.signed_area) / PREVIEW_TRIANGLES), region=region)
        positions, triangles = mesh.vertices, mesh.triangles
        in_theta = phi1.evaluate(positions).points
    # In Z order, each point starts its search where the last one was
    # found (``coherent``): the same points, found ten times faster.
    order = z_order(in_theta)
    tex = np.empty_like(in_theta)
    tex[order] = phi0.inverse(in_theta[order], coherent=True).points
    bad = ~np.isfinite(tex).all(axis=1)
    if bad.any():
        keep = ~bad[triangles].any(axis=1)
        triangles = triangles[keep]
        tex = np.where(bad[:, None], 0.0, tex)
    return positions, triangles, tex


def z_order(points: NDArray[np.float64]) -> NDArray[np.intp]:
    """The order of ``points`` along a Z (Morton) curve: neighbours in it are mostly neighbours in the plane.

    >>> z_order(np.array([[1.0, 1.0], [0.0, 0.0], [1.0, 0.0]])).tolist()
    [1, 2, 0]
    """
    lo = points.min(axis=0)
    span = max(float(np.ptp(points, axis=0).max()), 1e-300)
    q = ((points - lo) / span * 65535).astype(np.uint64)

    def spread(v: NDArray[np.uint64]) -> NDArray[np.uint64]:
        for shift, mask in ((8, 0x00FF00FF), (4, 0x0F0F0F0F), (2, 0x33333333), (1, 0x55555555)):
            v = (v | (v << np.uint64(shift))) & np.uint64(mask)
        return v

    return np.argsort(spread(q[:, 0]) | (spread(q[:, 1]) << np.uint64(1)), kind="stable")


def with_preview_density(options: MapOptions, src: Polygon, dst: Polygon, drag: str | None = None) -> MapOptions:
    """``options`` at the preview's density: its ``max_area`` (`preview_areas`), meshes not graded.

    ``drag`` (``"src"`` or ``"dst"``): that side is being dragged, and gets
    `PREVIEW_DRAG_TRIANGLES` instead of `PREVIEW_TRIANGLES`; the other side
    keeps its density, so that its map (which the drag does not change) is
    kept (`PreviewMapper`).

    The FEM meshes' grading towards reflex vertices refines them down to a
    tenth of a pixel, for accuracy far below a preview's pixel, and takes
    most of their vertices (5 to 9 times as many): without it a drag's map is
    rebuilt several times faster. It is the same map, by the same code, at a
    coarser density: ``BijectiveMap.between(src, dst, with_preview_density(...))``.
    """
    areas = preview_areas(src, dst)
    if drag is not None:
        side = ("src", "dst").index(drag)
        coarse = preview_areas(src, dst, PREVIEW_DRAG_TRIANGLES)
        areas = tuple(coarse[i] if i == side else areas[i] for i in (0, 1))  # type: ignore[assignment]
    return dataclasses.replace(options, max_area=areas, grade=False)
