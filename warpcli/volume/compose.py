"""Composition in 3D: maps of polyhedra onto Theta, f = phi1^-1 o phi0 between them, and its pull-back of voxel centres."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import mapping
from .._cached import cached_property
from ..errors import InputError
from ..mapping import Certificate, ComposedMap, Mapped
from ..simplicial import PiecewiseLinear
from . import _kernels
from .surface import Surface
from .tetmesh import TetMesh
from .theta import Theta

#: The pull-back works through the output grid in slabs of whole slices of
#: about this many voxels, so its temporary arrays stay small (about 100
#: bytes per voxel) whatever the volume's size.
SLAB_VOXELS = 1 << 21

#: A point of Theta this far outside a map's image (in barycentric terms) is
#: still snapped onto it: both maps' images are subdivisions of Theta's faces,
#: so only rounding separates them.
SNAP = 1e-6


@dataclass(eq=False)
class VolumeThetaMap(ABC):
    """A map phi of a polyhedron (a cage) onto Theta, with its inverse: the 3D `warpcli.maps.base.ThetaMap`.

    Attributes
    ----------
    surface : Surface
        The cage: the domain's boundary.
    theta : Theta
    timings : dict of str to float
    """

    surface: Surface
    theta: Theta
    timings: dict = field(default_factory=dict, kw_only=True)

    @abstractmethod
    def evaluate(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        """phi at points of the polyhedron (NaN outside it)."""

    @abstractmethod
    def inverse(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        """phi^-1 at points of Theta (NaN outside it)."""

    @abstractmethod
    def certify(self) -> Certificate:
        """Count the elements where the map flips."""

    def describe(self) -> dict:
        return {}


@dataclass(eq=False)
class IdentityMap(VolumeThetaMap):
    """phi when Theta is the cage itself: the identity, with no mesh."""

    def _inside(self, p: NDArray[np.float64]) -> NDArray[np.bool_]:
        w = _kernels.winding(p, self.surface.vertices, self.surface.triangles)
        return w > 0.5

    def evaluate(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        p = as_points(points)
        out = np.where(self._inside(p)[:, None], p, np.nan)
        return Mapped(out, _eye_where(out) if jacobian else None)

    def inverse(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        return self.evaluate(points, jacobian=jacobian)

    def certify(self) -> Certificate:
        return Certificate(0, 0, "tetrahedra")

    def describe(self) -> dict:
        return {"identity": True}


@dataclass(eq=False)
class TetMap(VolumeThetaMap):
    """phi as the piecewise-linear harmonic map on a tetrahedral mesh (§3.1.1 in 3D, §5.3).

    Attributes
    ----------
    mesh : TetMesh
        The mesh of the polyhedron.
    values : (N, 3) ndarray of float
        phi at its nodes: points of Theta.
    harmonic : (N, 3) ndarray of float or None
        The discrete harmonic map's values, when ``values`` are those
        untangled from it (`warpcli.volume.untangle`); else None.
    """

    mesh: TetMesh = field(default=None, kw_only=True)  # type: ignore[assignment]
    values: NDArray[np.float64] = field(default=None, kw_only=True)  # type: ignore[assignment]
    info: dict = field(default_factory=dict, kw_only=True)
    harmonic: NDArray[np.float64] | None = field(default=None, kw_only=True)

    @cached_property
    def domain_coefficients(self) -> NDArray[np.float64]:
        return tet_coefficients(self.mesh.vertices, self.mesh.tets)

    @cached_property
    def image_coefficients(self) -> NDArray[np.float64]:
        return tet_coefficients(self.values, self.mesh.tets)

    @cached_property
    def neighbours(self) -> NDArray[np.int64]:
        return tet_neighbours(self.mesh.tets)

    @cached_property
    def jacobians(self) -> NDArray[np.float64]:
        """(M, 3, 3): d phi / d x on each tetrahedron."""
        return tet_jacobians(self.mesh.vertices, self.values, self.mesh.tets)

    @cached_property
    def _domain_locator(self) -> TetLocator:
        return TetLocator(self.mesh.vertices, self.mesh.tets, 0.0, self.domain_coefficients)

    @cached_property
    def _image_locator(self) -> TetLocator:
        return TetLocator(self.values, self.mesh.tets, SNAP, self.image_coefficients)

    def flipped(self) -> NDArray[np.bool_]:
        """Tetrahedra whose image is inverted or flat, or of boundary nodes alone and flat up to the
        rounding of the boundary data (`warpcli.volume.spans.folded`: four images coplanar in exact
        arithmetic can come out positive).

        A flat one counts whatever makes it flat: a sliver collapsed onto a
        triangle is a map that is not one-to-one. The mesh is built so that
        no boundary nodes alone make one (`warpcli.volume.spans`).
        """
        from .spans import folded

        return folded(self.mesh, self.values)

    def moved(self) -> NDArray[np.int64]:
        """Nodes whose values differ from the harmonic map's (none unless untangled)."""
        if self.harmonic is None:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero((self.values != self.harmonic).any(axis=1))

    def certify(self) -> Certificate:
        return Certificate(int(self.flipped().sum()), self.mesh.n_tets, "tetrahedra")

    def describe(self) -> dict:
        return {
            "vertices": self.mesh.n_vertices, "tetrahedra": self.mesh.n_tets, **self.info,
        }  # fmt: skip

    def evaluate(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        p = as_points(points)
        out, where = PiecewiseLinear(self.values, self.mesh.tets, self._domain_locator).evaluate(p)
        jac = None
        if jacobian:
            jac = np.full((len(p), 3, 3), np.nan)
            ok = where >= 0
            jac[ok] = self.jacobians[where[ok]]
        return Mapped(out, jac)

    def inverse(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        p = as_points(points)
        out, where = PiecewiseLinear(self.mesh.vertices, self.mesh.tets, self._image_locator).evaluate(p)
        jac = None
        if jacobian:
            jac = np.full((len(p), 3, 3), np.nan)
            ok = where >= 0
            jac[ok] = safe_inverse(self.jacobians[where[ok]])
        return Mapped(out, jac)

    def locate_coherent(self, theta_points: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """phi^-1 at a coherent sequence of points of Theta: a walk, with the buckets for the rest."""
        k = len(theta_points)
        out = np.full((k, 3), np.nan)
        where = np.empty(k, dtype=np.int64)
        _kernels.walk(
            theta_points, self.mesh.tets, self.image_coefficients, self.neighbours, self.mesh.vertices, 64, out, where
        )
        lost = np.flatnonzero(where < 0)
        if lost.size:
            o, w = PiecewiseLinear(self.mesh.vertices, self.mesh.tets, self._image_locator).evaluate(theta_points[lost])
            out[lost] = o
            where[lost] = w
        return out, where


class TetLocator:
    """Point location in a tetrahedral mesh (a `warpcli.simplicial.Locator`): a grid of cells over
    its bounding box, each listing the tetrahedra overlapping it, searched by a compiled kernel.

    Parameters
    ----------
    vertices : (N, 3) ndarray of float
    tets : (M, 4) ndarray of int
    snap : float
        A point outside every tetrahedron by at most this much (in
        barycentric terms) is snapped onto the nearest one's boundary (see
        `warpcli.volume._kernels.bucket_locate`).
    coefficients : (M, 12) ndarray of float or None
        `tet_coefficients` of the mesh, if already at hand.
    """

    def __init__(
        self, vertices: NDArray[np.float64], tets: NDArray[np.int64], snap: float = 0.0,
        coefficients: NDArray[np.float64] | None = None,
    ) -> None:  # fmt: skip
        v = vertices
        lo = v.min(axis=0)
        extent = np.maximum(v.max(axis=0) - lo, 1e-300)
        # About one tetrahedron per cell.
        cell = float(np.cbrt(np.prod(extent) / max(len(tets), 1)))
        cell = max(cell, float(extent.max()) / 512.0)
        self.lo = lo
        self.cell = cell
        self.dims = np.maximum(np.ceil(extent / cell).astype(np.int64), 1)
        self.start, self.items = _kernels.build_buckets(v, tets, lo, cell, self.dims)
        self.snap = float(snap)
        self.coefficients = tet_coefficients(v, tets) if coefficients is None else coefficients

    def locate(self, points: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """The tetrahedron containing each point (-1 for none) and its barycentric coordinates (K, 4)."""
        p = as_points(points)
        where = np.empty(len(p), dtype=np.int64)
        bary = np.full((len(p), 4), np.nan)
        _kernels.bucket_locate(
            p, self.start, self.items, self.lo, self.cell, self.dims, self.coefficients, self.snap, where, bary
        )
        return where, bary


def as_points(points: ArrayLike) -> NDArray[np.float64]:
    """Points as a contiguous (K, 3) float array (for the kernels), or `InputError`."""
    return mapping.as_points(points, 3, contiguous=True)


def safe_inverse(m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverses of a stack of 3x3 matrices; NaN where one is singular or not finite."""
    out = np.full(m.shape, np.nan)
    with np.errstate(all="ignore"):
        det = np.linalg.det(m)
    good = np.isfinite(det) & (det != 0)
    out[good] = np.linalg.inv(m[good])
    return out


def _eye_where(p: NDArray[np.float64]) -> NDArray[np.float64]:
    jac = np.broadcast_to(np.eye(3), (len(p), 3, 3)).copy()
    jac[~np.isfinite(p[:, 0])] = np.nan
    return jac


def tet_coefficients(v: NDArray[np.float64], tets: NDArray[np.int64]) -> NDArray[np.float64]:
    """Per tetrahedron: vertex 0 and the inverse of [v1 - v0, v2 - v0, v3 - v0] (as rows of lambda_1..3), (M, 12).

    A flat tetrahedron gets infinite coefficients (no point is inside it).
    """
    a = v[tets[:, 0]]
    e = np.stack([v[tets[:, k]] - a for k in (1, 2, 3)], axis=2)  # columns: edges
    det = np.linalg.det(e)
    out = np.empty((len(tets), 12))
    out[:, :3] = a
    good = np.abs(det) > 0
    inv = np.full((len(tets), 3, 3), np.inf)
    inv[good] = np.linalg.inv(e[good])
    out[:, 3:] = inv.reshape(-1, 9)
    return np.ascontiguousarray(out)


def tet_neighbours(tets: NDArray[np.int64]) -> NDArray[np.int64]:
    """``nbr[t, m]``: the tetrahedron across the face of t opposite its vertex m, or -1."""
    m = len(tets)
    faces = np.concatenate([np.delete(tets, k, axis=1) for k in range(4)])  # face k of all, then k+1 ...
    key = np.sort(faces, axis=1)
    order = np.lexsort((key[:, 2], key[:, 1], key[:, 0]))
    ks = key[order]
    same = (ks[1:] == ks[:-1]).all(axis=1)
    nbr = np.full(4 * m, -1, dtype=np.int64)
    i = order[:-1][same]
    j = order[1:][same]
    nbr[i] = j % m
    nbr[j] = i % m
    return np.ascontiguousarray(nbr.reshape(4, m).T)


def tet_jacobians(x: NDArray[np.float64], y: NDArray[np.float64], tets: NDArray[np.int64]) -> NDArray[np.float64]:
    """Jacobians (M, 3, 3) of the piecewise-linear maps taking each tetrahedron at ``x`` to itself at ``y``."""
    ex = np.stack([x[tets[:, k]] - x[tets[:, 0]] for k in (1, 2, 3)], axis=2)
    ey = np.stack([y[tets[:, k]] - y[tets[:, 0]] for k in (1, 2, 3)], axis=2)
    with np.errstate(all="ignore"):
        return ey @ np.linalg.inv(ex)


def coherent_order(v: NDArray[np.float64], tets: NDArray[np.int64]) -> NDArray[np.int64]:
    """Tetrahedra in Morton (Z-curve) order of their centroids: consecutive ones are neighbours."""
    c = v[tets].mean(axis=1)
    lo = c.min(axis=0)
    span = max(float((c.max(axis=0) - lo).max()), 1e-300)
    q = np.minimum(((c - lo) / span * 1023.0).astype(np.int64), 1023)
    code = np.zeros(len(c), dtype=np.int64)
    for bit in range(10):
        for d in (2, 1, 0):
            code = (code << 1) | ((q[:, d] >> (9 - bit)) & 1)
    return np.argsort(code, kind="stable").astype(np.int64)


@dataclass(frozen=True)
class VoxelGrid:
    """A grid of voxel centres: ``shape`` (nx, ny, nz) and the affine taking index (i, j, k) to world (x, y, z).

    Voxel (i, j, k) is stored at ``array[k, j, i]`` of a C-ordered (nz, ny, nx) array.
    """

    shape: tuple[int, int, int]
    affine: NDArray[np.float64]

    @property
    def inverse_affine(self) -> NDArray[np.float64]:
        return np.linalg.inv(self.affine)

    def to_index(self, world: NDArray[np.float64]) -> NDArray[np.float64]:
        a = self.inverse_affine
        return world @ a[:3, :3].T + a[:3, 3]

    def to_world(self, index: NDArray[np.float64]) -> NDArray[np.float64]:
        return index @ self.affine[:3, :3].T + self.affine[:3, 3]

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The world box (lowest and highest corners) of the voxels, each a unit cube of index space about its centre."""
        corners = np.array(np.meshgrid(*[[-0.5, n - 0.5] for n in self.shape], indexing="ij")).reshape(3, -1).T
        world = self.to_world(corners)
        return world.min(axis=0), world.max(axis=0)

    def centres(self, flat: NDArray[np.int64]) -> NDArray[np.float64]:
        """World coordinates of the voxel centres with these flat indices."""
        nx, ny, _ = self.shape
        k, rest = np.divmod(flat, nx * ny)
        j, i = np.divmod(rest, nx)
        return self.to_world(np.column_stack([i, j, k]).astype(np.float64))


class VolumeMap(ComposedMap):
    """The map f between two polyhedra, as two maps onto one Theta (eq. (2) in 3D).

    ``forward`` takes source points to the target, ``inverse`` target points
    back: f = phi1^-1 o phi0 and f^-1 = phi0^-1 o phi1. Nothing guarantees
    that f is bijective in 3D (the paper's §5.3); `certificates` and
    `check_bijective` count the tetrahedra either map flips.

    Parameters
    ----------
    phi0, phi1 : VolumeThetaMap
        The source and the target cage onto the same Theta.
    """

    dim = 3

    def __init__(self, phi0: VolumeThetaMap, phi1: VolumeThetaMap) -> None:
        if not phi0.theta.same_as(phi1.theta):
            raise InputError("the two maps go onto different Thetas; f = phi1^-1 o phi0 needs one")
        super().__init__(phi0, phi1)

    @property
    def src(self) -> Surface:
        return self.phi0.surface

    @property
    def dst(self) -> Surface:
        return self.phi1.surface

    def fold_message(self, source: Certificate, target: Certificate) -> str:
        """What `check_bijective` says when either map flips a tetrahedron."""
        return (
            f"the maps flip {source.flipped} tetrahedra of {self.src.name} and {target.flipped} of {self.dst.name}; "
            "the warp would fold the volume over itself (--allow-folds writes it anyway)"
        )

    def untangling_displacement(self) -> float | None:
        """How far untangling moved the warp: the largest displacement at a moved node, in world units.

        At a target node whose image in Theta moved from y0 (harmonic) to
        y1, f^-1 moved from phi0^-1(y0) to phi0^-1(y1) in the source; at a
        source node, f from phi1^-1(y0) to phi1^-1(y1) in the target. Both
        maps being piecewise linear, the largest difference of the warps
        is at such nodes where the other map is affine around them. None
        when no node moved (or no moved node's images can be followed).
        """
        worst = None
        for mine, other in ((self.phi0, self.phi1), (self.phi1, self.phi0)):
            if not isinstance(mine, TetMap) or mine.harmonic is None:
                continue
            moved = mine.moved()
            if len(moved) == 0:
                continue
            a = other.inverse(mine.harmonic[moved]).points
            b = other.inverse(mine.values[moved]).points
            d = np.linalg.norm(a - b, axis=1)
            d = d[np.isfinite(d)]
            if len(d):
                worst = max(worst or 0.0, float(d.max()))
        return worst

    def pull_back_slabs(self, grid: VoxelGrid, slab_voxels: int = SLAB_VOXELS):
        """f^-1 at the voxel centres of an output grid inside the target, slab by slab.

        The target's mesh (or, when the target is Theta, the source map's
        image mesh) is scan-converted onto the grid, slice by slice; where
        both maps have meshes, the points of Theta found are then located in
        the source map's image by a walk. Only slices that the target crosses
        are visited.

        Yields
        ------
        voxels : (K,) ndarray of int64
            Flat indices (``(k * ny + j) * nx + i``) of the voxel centres inside.
        points : (K, 3) ndarray of float
            Their pre-images in the source's (world) coordinates; NaN for a
            centre whose point of Theta is outside the source map's image
            (only where a map folds).
        """
        nx, ny, nz = grid.shape
        p0, p1 = self.phi0, self.phi1
        if isinstance(p1, TetMap):
            mesh_v, tets, val = p1.mesh.vertices, p1.mesh.tets, p1.values
            second = p0 if isinstance(p0, TetMap) else None
        elif isinstance(p0, TetMap):  # the target is Theta: scan phi0's image, carrying its domain
            mesh_v, tets, val = p0.values, p0.mesh.tets, p0.mesh.vertices
            second = None
        else:  # both cages are Theta: the identity
            yield from _identity_slabs(self.dst, grid, slab_voxels)
            return
        v_index = np.ascontiguousarray(grid.to_index(mesh_v))
        coef = tet_coefficients(v_index, tets)
        order = coherent_order(v_index, tets)
        zs = v_index[tets, 2]
        zmin, zmax = zs.min(axis=1), zs.max(axis=1)
        k_first = max(int(math.ceil(float(zmin.min()) - 1e-7)), 0)
        k_last = min(int(math.floor(float(zmax.max()) + 1e-7)), nz - 1)
        per_slab = max(1, slab_voxels // (nx * ny))
        val = np.ascontiguousarray(val)
        for k0 in range(k_first, k_last + 1, per_slab):
            k1 = min(k0 + per_slab, k_last + 1)
            sel = order[(zmax[order] >= k0 - 1e-7) & (zmin[order] <= k1 - 1 + 1e-7)]
            nvox = (k1 - k0) * nx * ny
            claimed = np.zeros(nvox, dtype=np.uint8)
            voxels = np.empty(nvox, dtype=np.int64)
            values = np.empty((nvox, 3))
            where = np.empty(nvox, dtype=np.int64)
            n = _kernels.scan_slab(v_index, tets, coef, val, sel, nx, ny, k0, k1, claimed, voxels, values, where)
            voxels, values = voxels[:n], values[:n]
            if second is not None:
                values, _ = second.locate_coherent(values)
            yield voxels, values


def _identity_slabs(surface: Surface, grid: VoxelGrid, slab_voxels: int):
    nx, ny, nz = grid.shape
    per_slab = max(1, slab_voxels // (nx * ny))
    idx_v = grid.to_index(surface.vertices)
    k_first = max(int(math.ceil(idx_v[:, 2].min())), 0)
    k_last = min(int(math.floor(idx_v[:, 2].max())), nz - 1)
    for k0 in range(k_first, k_last + 1, per_slab):
        k1 = min(k0 + per_slab, k_last + 1)
        flat = np.arange(k0 * nx * ny, k1 * nx * ny, dtype=np.int64)
        world = grid.centres(flat)
        inside = _kernels.winding(world, surface.vertices, surface.triangles) > 0.5
        yield flat[inside], world[inside]
