"""The distortion of f = phi1^-1 o phi0 as a function of Theta, with its exact gradient (§5.1).

A discrete harmonic map is linear in Theta's vertices: the boundary data put
the node at parameter s of edge i at ``(1 - s) w_i + s w_(i+1)`` and the
interior solves a linear system, so the image of every mesh vertex is
``V = W @ Theta`` with an (N, n) matrix W of basis functions fixed by the
mesh, the weights and the boundary behaviour. `HarmonicBasis` solves W once
per polygon (one factorization, n right-hand sides); every Theta's map is
then a matrix product.

`ThetaEnergy` measures the distortion of f on the source side: at fixed
points of the source mesh's triangles (three per triangle, each standing for
a third of its area), J_f = J_phi1^-1 J_phi0, where J_phi0 is constant on the
sample's source triangle and J_phi1^-1 = E1 G1^-1 on the triangle of phi1's
image mesh that contains the sample's image (E1 its edges in the target, G1
in Theta). While no sample changes triangle, the energy is a smooth function
of Theta and its gradient is exact: the chain rule through G0 (linear in
Theta) and through the inverse G1^-1 (``d(G^-1) = -G^-1 dG G^-1``), then
back through V = W @ Theta. The weights are source areas, which do not
depend on Theta: the mean is a mean over the source, not over the target
(where a map that squeezes much source into little target hides it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..boundary import to_theta_parameter
from ..polygon import Polygon
from .base import inv2
from .fem.locate import TriangleLocator, triangle_neighbours
from .fem.mesh import TriMesh, mesh_polygon, triangle_areas
from .fem.solve import DirichletSolver

#: Energies: the area-weighted mean over the source of a distortion measure,
#: or a smooth stand-in for its maximum (the mean of its POWER-th power, to the 1 / POWER).
ENERGIES = ("conformal", "isometric", "max-conformal", "max-isometric")
#: Steps of the walk from each sample's previous triangle before a bucket search.
WALK_STEPS = 8
#: The power of the smooth maximum.
POWER = 8.0
#: Barycentric coordinates of the samples in each source triangle (the
#: three-point rule exact for quadratics: the energy of a map whose distortion
#: varies smoothly within a source triangle is integrated well).
RULE = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])


@dataclass(frozen=True, eq=False)
class HarmonicBasis:
    """The discrete harmonic maps of one mesh onto every Theta: ``values = W @ theta``.

    Parameters
    ----------
    mesh : TriMesh
    basis : (N, n) ndarray of float
        Column k: the harmonic function that is 1 at polygon vertex k, falls
        along its two edges as the boundary behaviour says and is 0 on the
        other edges. Rows sum to 1 (constants are harmonic), so the map is
        affinely covariant in Theta.
    """

    mesh: TriMesh
    basis: NDArray[np.float64]

    @classmethod
    def solve(cls, polygon: Polygon, max_area: float, *, weights: str = "cotan", boundary: str = "linear",
              grade: bool = True) -> HarmonicBasis:  # fmt: skip
        """Mesh ``polygon`` and solve its n basis functions (one factorization, n/2 back-substitutions)."""
        mesh = mesh_polygon(polygon, max_area, boundary=boundary, grade=grade)
        return cls.from_solver(DirichletSolver(mesh, weights), polygon.n, boundary)

    @classmethod
    def from_solver(cls, solver: DirichletSolver, n: int, boundary: str = "linear") -> HarmonicBasis:
        """The basis of a factorized Dirichlet problem: two basis functions per solve (x and y)."""
        w = np.empty((solver.mesh.n_vertices, n))
        for k in range(0, n, 2):
            unit = np.zeros((n, 2))  # any data: the solve is linear in it, convex or not
            unit[k, 0] = 1.0
            if k + 1 < n:
                unit[k + 1, 1] = 1.0
            values = solver.solve(unit, boundary)
            w[:, k] = values[:, 0]
            if k + 1 < n:
                w[:, k + 1] = values[:, 1]
        return cls(solver.mesh, w)

    @property
    def n(self) -> int:
        """Theta's vertex count."""
        return self.basis.shape[1]

    def values(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """The image in Theta of every mesh vertex, (N, 2)."""
        return self.basis @ theta


def boundary_matrix(mesh: TriMesh, n: int, boundary: str = "linear") -> NDArray[np.float64]:
    """(B, n): the boundary nodes' data as a linear function of Theta's vertices (for tests)."""
    s = to_theta_parameter(mesh.boundary_t, boundary)
    out = np.zeros((len(mesh.boundary), n))
    rows = np.arange(len(mesh.boundary))
    np.add.at(out, (rows, mesh.boundary_edge), 1.0 - s)
    np.add.at(out, (rows, (mesh.boundary_edge + 1) % n), s)
    return out


@dataclass(eq=False)
class ThetaEnergy:
    """The source-side distortion of f = phi1^-1 o phi0 as a function of Theta, with its gradient.

    Parameters
    ----------
    source, target : HarmonicBasis
        phi0's and phi1's bases (the same n).
    kind : str
        One of `ENERGIES`.

    Attributes
    ----------
    evaluations : int
        Calls so far (each gives the value and the gradient).
    """

    source: HarmonicBasis
    target: HarmonicBasis
    kind: str = "conformal"
    rule: NDArray[np.float64] = field(default_factory=lambda: RULE)
    evaluations: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        if self.kind not in ENERGIES:
            raise ValueError(f"unknown energy {self.kind!r}; choose one of {', '.join(ENERGIES)}")
        m0 = self.source.mesh
        t0 = m0.triangles.astype(np.int64)
        self._t0 = t0
        self._t1 = self.target.mesh.triangles.astype(np.int64)
        area = np.abs(triangle_areas(m0.vertices, m0.triangles))
        rule = np.atleast_2d(self.rule)
        self._sample_tri = np.repeat(np.arange(len(t0)), len(rule))
        self._weight = np.repeat(area / len(rule), len(rule))
        self._weight = self._weight / self._weight.sum()
        # The samples' images are a fixed linear combination of the basis rows.
        self._corners = t0[self._sample_tri]
        self._bary = np.tile(rule, (len(t0), 1))
        self._last = np.zeros(len(self._sample_tri), dtype=np.int64)  # each sample's last triangle
        self._neighbours = triangle_neighbours(self._t1)
        self._e0_inv = inv2(_edges(m0.vertices, t0))  # E0^-1 per source triangle
        self._e1 = _edges(self.target.mesh.vertices, self._t1)  # E1 per target triangle

    @property
    def n(self) -> int:
        return self.source.n

    def __call__(self, theta: NDArray[np.float64], *, gradient: bool = True):
        """The energy at ``theta`` (n, 2) and its gradient (n, 2) (None without ``gradient``).

        Returns ``(inf, None)`` where a sample's image lies in no triangle of
        phi1's image mesh or a Jacobian is singular (a degenerate Theta).
        """
        self.evaluations += 1
        theta = np.asarray(theta, dtype=np.float64).reshape(self.n, 2)
        v0 = self.source.values(theta)
        v1 = self.target.values(theta)
        g0 = _edges(v0, self._t0)
        g1 = _edges(v1, self._t1)
        q = g0 @ self._e0_inv  # J_phi0 per source triangle
        g1_inv = inv2(g1)
        p = self._e1 @ g1_inv  # J_phi1^-1 per target triangle
        tri1 = self._locate(v1, self._images(v0))
        if (tri1 < 0).any() or not (np.isfinite(q).all() and np.isfinite(p).all()):
            return math.inf, None
        qs = q[self._sample_tri]
        ps = p[tri1]
        j = ps @ qs
        value, dj = _measure(j, self._weight, self.kind, gradient)
        if not gradient:
            return value, None
        if not math.isfinite(value):
            return math.inf, None
        # dE/dQ = P^T M summed per source triangle, dE/dG0 = dE/dQ E0^-T;
        # dE/dP = M Q^T summed per target triangle, dE/dG1 = -P^T dE/dP G1^-T.
        d_q = _sum_per(np.swapaxes(ps, 1, 2) @ dj, self._sample_tri, len(self._t0))
        d_g0 = d_q @ np.swapaxes(self._e0_inv, 1, 2)
        d_p = _sum_per(dj @ np.swapaxes(qs, 1, 2), tri1, len(self._t1))
        d_g1 = -(np.swapaxes(p, 1, 2) @ d_p @ np.swapaxes(g1_inv, 1, 2))
        grad = self.source.basis.T @ _to_vertices(d_g0, self._t0, len(v0))
        grad += self.target.basis.T @ _to_vertices(d_g1, self._t1, len(v1))
        return value, grad

    def at_samples(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """J_f at every sample, (S, 2, 2) (NaN where a sample's image is in no triangle)."""
        theta = np.asarray(theta, dtype=np.float64)
        v1 = self.target.values(theta)
        q = _edges(self.source.values(theta), self._t0) @ self._e0_inv
        p = self._e1 @ inv2(_edges(v1, self._t1))
        tri1, _ = TriangleLocator(v1, self._t1).locate(self._images(self.source.values(theta)))
        j = p[np.maximum(tri1, 0)] @ q[self._sample_tri]
        j[tri1 < 0] = np.nan
        return j

    def triangles_of_samples(self, theta: NDArray[np.float64]) -> NDArray[np.int64]:
        """The triangle of phi1's image mesh holding each sample's image (for tests of the gradient)."""
        theta = np.asarray(theta, dtype=np.float64)
        v1 = self.target.values(theta)
        return TriangleLocator(v1, self._t1).locate(self._images(self.source.values(theta)))[0]

    def _locate(self, v1: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.int64]:
        """The triangle of phi1's image mesh holding each point: a walk from where it was last
        time (Theta moves little between evaluations), a bucket search for the few it misses."""
        tri = self._last.copy()
        todo = np.arange(len(y))
        for _ in range(WALK_STEPS):
            t = self._t1[tri[todo]]
            a, b, c = v1[t[:, 0]], v1[t[:, 1]], v1[t[:, 2]]
            p = y[todo]
            det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
            with np.errstate(all="ignore"):
                l1 = ((p[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (p[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])) / det
                l2 = ((b[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (p[:, 0] - a[:, 0])) / det
            bary = np.stack([1.0 - l1 - l2, l1, l2], axis=1)
            # Strictly inside (a margin): a point on an edge goes on to the bucket search, whose ties are fixed.
            inside = (bary > 1e-9).all(axis=1)
            todo = todo[~inside]
            if not todo.size:
                break
            worst = np.argmin(bary[~inside], axis=1)  # across the edge opposite the most negative corner
            step = self._neighbours[tri[todo], worst]
            onward = step >= 0
            tri[todo[onward]] = step[onward]
            todo = np.concatenate([todo[onward], todo[~onward]])
            if not onward.all():
                break
        if todo.size:
            tri[todo] = TriangleLocator(v1, self._t1).locate(y[todo])[0]
        self._last = np.where(tri >= 0, tri, self._last)
        return tri

    def _images(self, v0: NDArray[np.float64]) -> NDArray[np.float64]:
        """The samples' images in Theta, from phi0's vertex images."""
        c = self._corners
        return np.einsum("sk,skd->sd", self._bary, v0[c])


def _edges(v: NDArray[np.float64], t: NDArray[np.int64]) -> NDArray[np.float64]:
    """(M, 2, 2): each triangle's edges ``v1 - v0`` and ``v2 - v0`` as columns."""
    return np.stack([v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]], axis=2)


def _sum_per(x: NDArray[np.float64], index: NDArray[np.int64], size: int) -> NDArray[np.float64]:
    """(size, 2, 2): the 2x2 matrices ``x`` summed by ``index``."""
    flat = x.reshape(len(x), 4)
    out = np.stack([np.bincount(index, weights=flat[:, k], minlength=size) for k in range(4)], axis=1)
    return out.reshape(size, 2, 2)


def _to_vertices(d_g: NDArray[np.float64], t: NDArray[np.int64], size: int) -> NDArray[np.float64]:
    """dE/dV (size, 2) from dE/dG per triangle, G = [v1 - v0, v2 - v0]."""
    out = np.zeros((size, 2))
    for c in range(2):
        a, b = d_g[:, c, 0], d_g[:, c, 1]  # component c of the two edges
        out[:, c] = (
            np.bincount(t[:, 1], weights=a, minlength=size)
            + np.bincount(t[:, 2], weights=b, minlength=size)
            - np.bincount(t[:, 0], weights=a + b, minlength=size)
        )
    return out


def _measure(j: NDArray[np.float64], w: NDArray[np.float64], kind: str, gradient: bool):
    """The energy of Jacobians ``j`` (S, 2, 2) with weights ``w`` (summing to 1), and dE/dJ per sample."""
    a, b, c, d = j[:, 0, 0], j[:, 0, 1], j[:, 1, 0], j[:, 1, 1]
    det = a * d - b * c
    with np.errstate(all="ignore"):
        if kind.endswith("conformal"):
            frob = a * a + b * b + c * c + d * d
            x = frob / np.abs(det)
        else:
            p = np.hypot(a + d, c - b)
            q = np.hypot(a - d, b + c)
            s1, s2 = 0.5 * (p + q), 0.5 * np.abs(p - q)
            x = np.maximum(s1, 1.0 / s2)
    if not np.isfinite(x).all():
        return math.inf, None
    if kind.startswith("max-"):
        scale = float(x.max())
        mean_p = float((w * (x / scale) ** POWER).sum())
        value = scale * mean_p ** (1.0 / POWER)
        outer = w * value / mean_p * (x / scale) ** (POWER - 1.0) / scale  # d value / d x per sample
    else:
        value = float((w * x).sum())
        outer = w
    if not gradient:
        return value, None
    cof = np.stack([np.stack([d, -c], -1), np.stack([-b, a], -1)], -2)  # d det / dJ
    with np.errstate(all="ignore"):
        if kind.endswith("conformal"):
            dx = (2.0 * j - (x * np.sign(det))[:, None, None] * cof) / np.abs(det)[:, None, None]
        else:
            q_safe = np.where(q > 0, q, np.inf)  # q = 0: s1 = s2, a kink; take a one-sided derivative
            dp = np.stack([np.stack([a + d, b - c], -1), np.stack([c - b, a + d], -1)], -2) / p[:, None, None]
            dq = np.stack([np.stack([a - d, b + c], -1), np.stack([b + c, d - a], -1)], -2) / q_safe[:, None, None]
            ds1 = 0.5 * (dp + dq)
            ds2 = 0.5 * np.sign(p - q)[:, None, None] * (dp - dq)
            top = s1 >= 1.0 / s2
            dx = np.where(top[:, None, None], ds1, -ds2 / (s2 * s2)[:, None, None])
    return value, outer[:, None, None] * dx
