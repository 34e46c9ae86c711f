"""Cage meshes: one bijective map per face of a planar partition, glued along the shared edges.

Each face of the source mesh goes onto the same face of the target mesh by
the map `build_map` makes for one polygon, with any method and Theta. That
map takes every edge of the face onto the same edge of the target linearly
(the point at parameter t to the point at parameter t: f = phi1^-1 o phi0
and both maps send the edge to Theta's edge with one boundary behaviour), so
the two faces of an interior edge agree on it and the whole map is
continuous: exactly for FEM (its boundary values are exact), to the
accuracy of the boundary fit for BEM and MFS. It is one-to-one when every face
map is and the target faces form a partition with the same combinatorics and
orientation as the source's (`warpcli.polygon.partition.validate_pair`): the
whole map is certified when every face map is.

A `CageMap` has what `warpcli.plan.SamplingPlan.from_map` needs
(``pull_back``, ``inverse_boundary``, ``dst``, ``src``), so every output kind
takes it as it takes a `BijectiveMap`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import FoldOverError, InputError
from ..grid import inside_polygon, window
from ..mapping import Certificate, Mapped, as_points
from ..options import MapOptions, check_size
from ..polygon import Polygon
from ..polygon.partition import Partition, check_shapes, validate_pair
from .compose import BijectiveMap, PullBack, Region, build_map

__all__ = ["CageMap", "CagePullBack", "build_cage_map", "face_labels", "map_between"]


@dataclass(frozen=True)
class CagePullBack(PullBack):
    """A `PullBack` of a cage mesh, with the face each pixel centre of the window lies in.

    Attributes
    ----------
    faces : (h, w) ndarray of int32 or None
        Face index per pixel centre of the window (`face_labels`); -1 outside
        the mesh.
    """

    faces: NDArray[np.int32] | None = None


def _first_centre(x: NDArray[np.float64]) -> NDArray[np.int64]:
    """The least integer c with c + 0.5 >= x, exactly (x finite)."""
    c = np.ceil(x - 0.5)
    c = np.where(c - 0.5 >= x, c - 1.0, c)
    c = np.where(c + 0.5 < x, c + 1.0, c)
    return c.astype(np.int64)


def face_labels(
    side: Partition, width: int, height: int, rows: tuple[int, int], cols: tuple[int, int]
) -> NDArray[np.int32]:
    """Which face each pixel centre of a window of a ``width`` x ``height`` grid lies in.

    The even-odd rule of `warpcli.grid.inside_polygon` (a centre is inside
    when an odd number of edges cross its row to its right, each edge's
    crossing taken half-open in y), by scan conversion, with each edge's
    crossing computed once from its endpoints in a fixed order (lower vertex
    index first): the two faces of an edge then see the same crossing, bit
    for bit, and a centre exactly on it goes to the face on its right (the
    span ``[left, right)`` of a row). So the faces' centres do not overlap
    and leave no gap; should rounding ever give a centre to two faces, the
    lower index keeps it. The work is the crossings of the edges with the
    rows plus the pixels of each face's bounding box.

    Parameters
    ----------
    side : Partition
        The mesh, in the grid's coordinates.
    width, height : int
        The grid's size.
    rows, cols : (int, int)
        The window: rows ``r0 <= r < r1``, columns ``c0 <= c < c1``.

    Returns
    -------
    (r1 - r0, c1 - c0) ndarray of int32
        Face index per pixel centre; -1 outside every face.
    """
    r0, r1 = rows
    c0, c1 = cols
    labels = np.full((r1 - r0, c1 - c0), -1, dtype=np.int32)
    if r1 <= r0 or c1 <= c0:
        return labels
    v = side.vertices
    crossings: dict[tuple[int, int], tuple[NDArray[np.int64], NDArray[np.float64]]] = {}
    for k, face in enumerate(side.faces):
        rr, xx = [], []
        for j in range(len(face)):
            a, b = face[j], face[(j + 1) % len(face)]
            key = (min(a, b), max(a, b))
            hit = crossings.get(key)
            if hit is None:
                (px, py), (qx, qy) = v[key[0]], v[key[1]]
                lo, hi = _first_centre(np.array([min(py, qy), max(py, qy)]))
                r = np.arange(max(lo, r0), min(hi, r1), dtype=np.int64)
                y = r + 0.5
                # The formula of grid.inside_polygon, from the lower index's end.
                xc = px + (y - py) * (qx - px) / (qy - py) if r.size else np.zeros(0)
                hit = crossings[key] = (r, xc)
            rr.append(hit[0])
            xx.append(hit[1])
        r = np.concatenate(rr)
        if not r.size:
            continue
        x = np.concatenate(xx)
        order = np.lexsort((x, r))
        r, x = r[order], x[order]
        # Every row holds an even number of crossings (a closed loop crosses
        # each line an even number of times, half-open in y): pairs in order.
        left, right, row = x[0::2], x[1::2], r[0::2]
        lo = np.clip(_first_centre(left), c0, c1)
        hi = np.clip(_first_centre(right), c0, c1)
        keep = hi > lo
        if not keep.any():
            continue
        row, lo, hi = row[keep] - r0, lo[keep] - c0, hi[keep] - c0
        fr0, fr1 = int(row.min()), int(row.max()) + 1
        fc0, fc1 = int(lo.min()), int(hi.max())
        diff = np.zeros((fr1 - fr0, fc1 - fc0 + 1), dtype=np.int32)
        np.add.at(diff, (row - fr0, lo - fc0), 1)
        np.add.at(diff, (row - fr0, hi - fc0), -1)
        inside = np.cumsum(diff, axis=1)[:, :-1] > 0
        part = labels[fr0:fr1, fc0:fc1]
        part[inside & (part < 0)] = k
    return labels


class CageMap:
    """The map between two cage meshes: a `BijectiveMap` per face, continuous across shared edges.

    Build one with `build_cage_map`. ``pull_back``, ``inverse_boundary``,
    ``src`` and ``dst`` are what `warpcli.plan.SamplingPlan.from_map` needs;
    ``src`` and ``dst`` are the meshes' outlines (Polygons), the meshes are
    ``src_mesh`` and ``dst_mesh``.

    Parameters
    ----------
    src_mesh, dst_mesh : Partition
        Corresponding cage meshes (checked by `validate_pair`).
    face_maps : sequence of BijectiveMap
        The map of each face, in the meshes' face order.
    """

    def __init__(self, src_mesh: Partition, dst_mesh: Partition, face_maps: list[BijectiveMap]) -> None:
        validate_pair(src_mesh, dst_mesh)
        if len(face_maps) != src_mesh.n_faces:
            raise InputError(f"{dst_mesh.name}: {len(face_maps)} face maps for {src_mesh.n_faces} faces")
        self.src_mesh = src_mesh
        self.dst_mesh = dst_mesh
        self.face_maps = tuple(face_maps)
        # (options, regions) when made by build_cage_map: which of its face maps a later build may reuse.
        self.built_with: tuple | None = None
        self.timings: dict[str, float] = {}
        for fmap in self.face_maps:
            for stage, seconds in fmap.timings.items():
                self.timings[stage] = self.timings.get(stage, 0.0) + seconds
        self._reverse: tuple[BijectiveMap, ...] | None = None

    @property
    def faces(self) -> tuple[tuple[int, ...], ...]:
        """The faces, as vertex indices (the same on both sides)."""
        return self.src_mesh.faces

    @property
    def src(self) -> Polygon:
        """The source mesh's outline."""
        return self.src_mesh.outline

    @property
    def dst(self) -> Polygon:
        """The target mesh's outline."""
        return self.dst_mesh.outline

    @property
    def theta(self) -> None:
        """None: every face has a Theta of its own (``face_maps[k].theta``)."""
        return None

    @property
    def orientation_preserving(self) -> bool:
        """False when the meshes run in opposite directions: the map is then a mirror image."""
        return (self.src.signed_area > 0) == (self.dst.signed_area > 0)

    # ------------------------------------------------------------ certificates

    def certificates(self) -> tuple[Certificate, Certificate]:
        """The faces' certificates summed, (source, target)."""
        pairs = [fmap.certificates() for fmap in self.face_maps]
        kinds = {c.kind for pair in pairs for c in pair}
        kind = kinds.pop() if len(kinds) == 1 else "samples"
        return tuple(  # type: ignore[return-value]
            Certificate(sum(p[i].flipped for p in pairs), sum(p[i].checked for p in pairs), kind) for i in (0, 1)
        )

    def flipped_triangles(self) -> int:
        """Elements where any face map flips: 0 for a bijection."""
        return sum(fmap.flipped_triangles() for fmap in self.face_maps)

    def check_bijective(self) -> None:
        """Raise `FoldOverError` unless every face map is certified one-to-one (naming the face)."""
        for fmap in self.face_maps:
            c0, c1 = fmap.certificates()
            if not (c0.ok and c1.ok):
                raise FoldOverError(fmap.fold_message(c0, c1))

    @property
    def certified(self) -> bool:
        """Whether every face map is certified one-to-one: then so is the whole map (the meshes are
        validated partitions with the same faces, so the faces' images do not overlap)."""
        return all(c.ok for fmap in self.face_maps for c in fmap.certificates())

    def describe(self) -> dict:
        """What the report adds: the counts of faces and vertices."""
        return {"cage_faces": self.src_mesh.n_faces, "cage_vertices": self.src_mesh.n}

    # ------------------------------------------------------------ pixel grids

    def pull_back(
        self, width: int, height: int, *, jacobian: bool = True, rows: tuple[int, int] | None = None
    ) -> CagePullBack:
        """f^-1 (and its Jacobian) at the pixel centres of a ``width`` x ``height`` output grid.

        Each centre takes the value of the face it lies in (`face_labels`);
        where that face's map has no value (a centre on its edge, which the
        method counts outside), a neighbour's, which agrees there. Arguments
        and result as `BijectiveMap.pull_back`, plus the face per pixel.
        """
        width, height = check_size((width, height))
        return _gather(self.face_maps, self.dst_mesh, width, height, jacobian, rows)

    def inverse_grid(self, width: int, height: int) -> NDArray[np.float64]:
        """`inverse` at every pixel centre of a ``width`` x ``height`` output image: (H, W, 2), NaN outside."""
        return self.pull_back(width, height, jacobian=False).full_points()

    def forward_grid(self, width: int, height: int) -> NDArray[np.float64]:
        """`forward` at every pixel centre of a ``width`` x ``height`` source image: (H, W, 2), NaN outside."""
        width, height = check_size((width, height))
        return _gather(self._reversed(), self.src_mesh, width, height, False, None).full_points()

    def _reversed(self) -> tuple[BijectiveMap, ...]:
        if self._reverse is None:
            self._reverse = tuple(BijectiveMap(fmap.phi1, fmap.phi0) for fmap in self.face_maps)
        return self._reverse

    def inverse_boundary(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """The source point of parameter t on edge i of the target's outline (the face's boundary map)."""
        e = np.asarray(edge, dtype=np.intp)
        tt = np.broadcast_to(np.asarray(t, dtype=np.float64), e.shape)
        face, local = self.dst_mesh.outline_edges
        out = np.empty(e.shape + (2,))
        fk = face[e]
        for k in np.unique(fk):
            on = fk == k
            out[on] = self.face_maps[int(k)].inverse_boundary(local[e[on]], tt[on])
        return out

    # ------------------------------------------------------------ points

    def _through_faces(self, points: ArrayLike, side: Partition, maps, how: str) -> Mapped:
        p = as_points(points)
        out = np.full((len(p), 2), np.nan)
        jac = np.full((len(p), 2, 2), np.nan)
        todo = np.ones(len(p), dtype=bool)
        for k, fmap in enumerate(maps):
            if not todo.any():
                break
            # Only points in the face's bounding box are tested against its edges.
            face = side.face_points(k)
            lo, hi = face.min(axis=0), face.max(axis=0)
            idx = np.flatnonzero(todo & (p >= lo).all(axis=1) & (p <= hi).all(axis=1))
            inside = idx[inside_polygon(p[idx], face)]
            if inside.size:
                m = getattr(fmap, how)(p[inside])
                ok = np.isfinite(m.points[:, 0])
                out[inside[ok]] = m.points[ok]
                jac[inside[ok]] = m.jacobian[ok]
                todo[inside[ok]] = False
        # Points on an edge that the even-odd test gave no face: whichever face maps them.
        for fmap in maps:
            idx = np.flatnonzero(todo)
            if not idx.size:
                break
            m = getattr(fmap, how)(p[idx])
            ok = np.isfinite(m.points[:, 0])
            out[idx[ok]] = m.points[ok]
            jac[idx[ok]] = m.jacobian[ok]
            todo[idx[ok]] = False
        return Mapped(out, jac)

    def forward_mapped(self, points: ArrayLike) -> Mapped:
        """f and its Jacobian at source points (NaN outside the source mesh)."""
        return self._through_faces(points, self.src_mesh, self.face_maps, "forward_mapped")

    def inverse_mapped(self, points: ArrayLike) -> Mapped:
        """f^-1 and its Jacobian at target points (NaN outside the target mesh)."""
        return self._through_faces(points, self.dst_mesh, self.face_maps, "inverse_mapped")

    def forward(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map source points to the target; NaN outside the source mesh."""
        return self.forward_mapped(points).points

    def inverse(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map target points back to the source; NaN outside the target mesh."""
        return self.inverse_mapped(points).points

    def forward_jacobian(self, points: ArrayLike) -> NDArray[np.float64]:
        """Jacobian of f at source points."""
        return self.forward_mapped(points).jacobian

    def inverse_jacobian(self, points: ArrayLike) -> NDArray[np.float64]:
        """Jacobian of f^-1 at target points."""
        return self.inverse_mapped(points).jacobian


def _gather(
    maps, side: Partition, width: int, height: int, jacobian: bool, rows: tuple[int, int] | None
) -> CagePullBack:
    """The face maps' pull-backs on the grid of ``side``, each pixel from its face."""
    w0, w1, c0, c1 = window(side.outline.bounds, width, height)
    r0, r1 = w0, w1
    if rows is not None:
        r0 = min(max(rows[0], w0), w1)
        r1 = max(min(rows[1], w1), r0)
    h, w = r1 - r0, c1 - c0
    labels = face_labels(side, width, height, (r0, r1), (c0, c1))
    points = np.full((h, w, 2), np.nan)
    jac = np.full((h, w, 2, 2), np.nan) if jacobian else None
    owned = np.zeros((h, w), dtype=bool)
    pulls = []
    for k, fmap in enumerate(maps):
        pb = fmap.pull_back(width, height, jacobian=jacobian, rows=rows)
        ph, pw = pb.points.shape[:2]
        if ph == 0 or pw == 0:
            continue
        a, b = pb.origin[0] - r0, pb.origin[1] - c0
        sub = (slice(a, a + ph), slice(b, b + pw))
        pulls.append((k, pb, sub))
        finite = np.isfinite(pb.points[..., 0])
        if jac is not None:  # a meshless face map has a value on its edge but no Jacobian there
            finite &= np.isfinite(pb.jacobian[..., 0, 0])
        mine = finite & (labels[sub] == k)
        # A face's own pixels are its; a pixel its face leaves without a value
        # (on the edge, outside by the method's count) takes the first other's.
        take = mine | (finite & ~owned[sub] & ~np.isfinite(points[sub][..., 0]))
        points[sub][take] = pb.points[take]
        if jac is not None:
            jac[sub][take] = pb.jacobian[take]
        owned[sub] |= mine
    if jac is not None:
        # A centre exactly on an edge where no face's method gives a Jacobian (BEM and MFS have
        # none on their boundary): its own face's value, and the Jacobian a hair inside the face
        # (the face map is smooth up to its edge; the nearest of a few nudges that has one: the
        # Jacobian changes by about 1e-4 over 0.01 px).
        for k, pb, sub in pulls:
            take = np.isfinite(pb.points[..., 0]) & ~np.isfinite(points[sub][..., 0]) & (labels[sub] == k)
            if not take.any():
                continue
            points[sub][take] = pb.points[take]
            rr, cc = np.nonzero(take)
            centres = np.stack([cc + pb.origin[1] + 0.5, rr + pb.origin[0] + 0.5], axis=1)
            found = np.full((len(centres), 2, 2), np.nan)
            for d in _NUDGES:
                todo = ~np.isfinite(found[:, 0, 0])
                if not todo.any():
                    break
                found[todo] = maps[k].inverse_mapped(centres[todo] + d).jacobian
            jac[sub][take] = found
    return CagePullBack(points, jac, (r0, c0), (width, height), labels)


#: Offsets (px) at which the Jacobian of a pixel centre on a face's edge is taken, nearest first
#: (the meshless methods give none within about 1e-4 px of their boundary).
_NUDGES = np.concatenate([
    np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, 1], [1, -1], [-1, -1]], dtype=np.float64) * scale
    for scale in (1e-6, 1e-3, 1e-2)
])  # fmt: skip


def build_cage_map(
    src: Partition,
    dst: Partition,
    options: MapOptions | None = None,
    *,
    regions: tuple[Region | None, Region | None] = (None, None),
    kept: CageMap | None = None,
) -> CageMap:
    """Build the map between two cage meshes: `build_map` for every face.

    Parameters
    ----------
    src, dst : Partition
        Corresponding cage meshes: the same faces, vertex i of ``src`` onto
        vertex i of ``dst``.
    options : MapOptions or None
        As for `build_map` (any method and Theta), for every face; FEM's
        automatic ``max_area`` is the whole outline's (one density for all
        faces, as for one polygon of that outline). Mixed
        boundary conditions and different boundary behaviours on the two
        sides are refused: the faces of an edge would not meet on it.
    regions : (region, region)
        Where the source and the target map will be evaluated (see `build_map`).
    kept : CageMap or None
        A map built before by this function (the editor's last preview): a
        side's map of a face (phi0 of the source face, phi1 of the target's)
        is taken from it instead of being built again where it was built
        from the same polygon (points and name), Theta, options (with that
        side's ``max_area``) and region, as building it again would make the
        same map. Only meshes of more
        than `CONCURRENT_FACES` faces reuse (the others go through
        `build_map`).

    Returns
    -------
    CageMap
        Its ``timings`` sum the faces'; ``built_with`` holds the options and
        regions it was built at.

    Raises
    ------
    PolygonError
        If the meshes do not correspond (`validate_pair`): one line naming the face.
    InputError
        For options a cage mesh cannot take.
    FoldOverError
        With ``options.check``, if a face map is not certified one-to-one
        (naming the face).
    """
    opts = options or MapOptions()
    validate_pair(src, dst)
    if opts.conditions == "mixed":
        raise InputError(
            f"{dst.name}: a cage mesh cannot take mixed boundary conditions: their edges slide, so neighbouring "
            "faces would not meet on their shared edge"
        )
    if opts.src_boundary != opts.dst_boundary:
        raise InputError(
            f"{dst.name}: a cage mesh needs the same boundary behaviour on both sides (got {opts.src_boundary} for the "
            f"source, {opts.dst_boundary} for the target; --boundary sets the target's only, --src-boundary the "
            "source's): otherwise neighbouring faces would not meet on their shared edge"
        )
    if opts.method == "fem" and opts.max_area is None:
        # The automatic density of the whole outline, not of each face: a
        # face's own (sqrt(area) / 35) would mesh k faces sqrt(k) times as
        # finely in all, for the same accuracy per square pixel.
        from .fem.mesh import auto_max_area

        opts = dataclasses.replace(
            opts, max_area=(auto_max_area(src.outline, regions[0]), auto_max_area(dst.outline, regions[1]))
        )
    pairs = list(zip(src.face_polygons(), dst.face_polygons()))
    if len(pairs) <= CONCURRENT_FACES:
        maps = [build_map(a, b, opts, regions=regions) for a, b in pairs]
    else:
        sides = _kept_sides(kept)
        maps = [_face_map(a, b, opts, regions, sides) for a, b in pairs]
    result = CageMap(src, dst, maps)
    result.built_with = (opts, regions)
    return result


def _side_key(role: str, polygon: Polygon, theta, opts: MapOptions, regions) -> tuple:
    """What a side's map of a face is built from: its role, polygon, Theta, its own options and region.

    A side's map depends on the other side's ``max_area`` not at all (the
    methods take their role's): the key holds the side's alone, so that the
    source's maps are kept when a drag meshes the target more coarsely.
    """
    i = 0 if role == "source" else 1
    own = dataclasses.replace(opts, max_area=opts.areas()[i])
    return (role, polygon.points.tobytes(), polygon.name, theta.points.tobytes(), theta.name, own, regions[i])


def _kept_sides(kept: CageMap | None) -> dict[tuple, object]:
    """The side maps of ``kept`` by `_side_key`."""
    if kept is None or kept.built_with is None:
        return {}
    opts, regions = kept.built_with
    sides: dict[tuple, object] = {}
    for fmap in kept.face_maps:
        for role, phi in (("source", fmap.phi0), ("target", fmap.phi1)):
            sides[_side_key(role, phi.polygon, phi.theta, opts, regions)] = phi
    return sides


#: Meshes of at most this many faces build each face with `build_map`, its two
#: maps at once (a child process and a thread); more faces are built one map
#: after the other on this thread: on small faces starting the child and the
#: threads cost more than the maps (measured on a busy machine: 0.08 s against
#: 0.013 s for a triangle of 1700 px^2; 128 triangles took 16 s instead of 2.2,
#: and 16 faces built this way took less than 4 built concurrently; see
#: bench/cage.py). The maps are the same either way (each is independent of
#: the scheduling).
CONCURRENT_FACES = 2


def _face_map(
    src: Polygon, dst: Polygon, opts: MapOptions, regions: tuple[Region | None, Region | None], kept: dict | None = None
) -> BijectiveMap:
    """`build_map`'s policy for one face, both maps built on this thread (or taken from ``kept``, `_kept_sides`)."""
    from .compose import theta_for
    from .registry import METHODS

    theta = theta_for(src, dst, opts)
    method = METHODS[opts.method].load()
    maps = []
    for polygon, role, region, side in ((src, "source", regions[0], "inverse"), (dst, "target", regions[1], "grid")):
        phi = kept.get(_side_key(role, polygon, theta, opts, regions)) if kept else None
        if phi is not None:
            maps.append(phi)  # built from the same polygon, Theta, options and region: the same map
            continue
        phi = method.build(polygon, theta, opts, role, region)
        if region is not None and hasattr(phi, "precompute"):
            phi.precompute(side)
        maps.append(phi)
    result = BijectiveMap(*maps)
    for phi in maps:
        for stage, seconds in phi.timings.items():
            result.timings[stage] = result.timings.get(stage, 0.0) + seconds
    if opts.check:
        result.check_bijective()
    return result


def map_between(
    src: Polygon | Partition,
    dst: Polygon | Partition,
    options: MapOptions | None = None,
    *,
    regions: tuple[Region | None, Region | None] = (None, None),
) -> BijectiveMap | CageMap:
    """The map between two polygons (`BijectiveMap.between`) or two cage meshes (`build_cage_map`).

    Raises
    ------
    PolygonError
        For a polygon facing a cage mesh, or shapes that do not correspond.
    """
    check_shapes(src, dst)
    if isinstance(src, Partition):
        return build_cage_map(src, dst, options, regions=regions)  # type: ignore[arg-type]
    return BijectiveMap.between(src, dst, options, regions=regions)  # type: ignore[arg-type]
