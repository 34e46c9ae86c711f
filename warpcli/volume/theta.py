"""Theta in 3D: the polyhedron both harmonic maps go onto, with the cages' connectivity, and the strategies that choose it."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from ..errors import MeshingError
from .surface import Surface, SurfaceError, check_pair, is_convex, read_surface

#: Named strategies; anything else is a path to a mesh file.
THETA_STRATEGIES = ("auto", "source", "target", "sphere")

#: Relaxation steps of the spherical parameterization (each kept only while it stays bijective).
SPHERE_STEPS = 300


@dataclass(frozen=True, eq=False)
class Theta:
    """The intermediate polyhedron: the cages' connectivity at other vertex positions.

    In 2D, Theta is convex so that the harmonic maps are bijective
    (Radó-Kneser-Choquet). In 3D that theorem fails (the paper's §5.3), so
    no Theta guarantees bijectivity; a convex one (a convex cage, a cube for
    hexahedral cages, or one the user gives) is still the best start, and
    where none is at hand the sphere strategy gives a polyhedron inscribed in
    the unit sphere, star-shaped about its centre, whose faces are the images
    of a bijective spherical parameterization.

    Parameters
    ----------
    vertices : (N, 3) array_like of float
        Vertex i corresponds to vertex i of both cages.
    name : str
        The strategy or file it came from.
    convex : bool
        Whether it is convex (checked by the strategies).
    cage : int or None
        0 or 1 when Theta is the source or target cage itself (that map is
        then the identity), else None.
    notes : dict
        What the strategy reports (for the sphere: its concave edges).
    """

    vertices: NDArray[np.float64]
    name: str = "theta"
    convex: bool = False
    cage: int | None = None
    notes: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = np.array(self.vertices, dtype=np.float64)
        v.setflags(write=False)
        object.__setattr__(self, "vertices", v)

    def same_as(self, other: Theta) -> bool:
        """Whether two Thetas are the same polyhedron, vertex for vertex (by value, as in 2D)."""
        return self.vertices.shape == other.vertices.shape and bool(np.array_equal(self.vertices, other.vertices))


def theta_for(src: Surface, dst: Surface, strategy: str | os.PathLike[str] = "auto") -> Theta:
    """Choose Theta for two corresponding cages.

    Parameters
    ----------
    src, dst : Surface
        Checked cages with the same connectivity.
    strategy : str or path-like
        ``"auto"``: the source cage if it is convex, else the target if it
        is, else ``"sphere"``. ``"source"`` / ``"target"``: that cage, which
        must be convex. ``"sphere"``: a polyhedron inscribed in the unit
        sphere through a bijective spherical parameterization
        (`sphere_embedding`). Otherwise a path to a mesh with the cages'
        connectivity, which must be convex (the paper's Fig. 17 uses a cube
        for hexahedral cages).

    Returns
    -------
    Theta

    Raises
    ------
    SurfaceError
        If the named cage or the given mesh is not convex, or the mesh does
        not have the cages' connectivity.
    MeshingError
        If no bijective spherical parameterization was found.
    """
    if isinstance(strategy, str) and strategy in THETA_STRATEGIES:
        if strategy == "auto":
            for k, cage in enumerate((src, dst)):
                if is_convex(cage):
                    return Theta(cage.vertices, f"{cage.name} (convex)", True, k)
            strategy = "sphere"
        if strategy in ("source", "target"):
            k = 0 if strategy == "source" else 1
            cage = (src, dst)[k]
            if not is_convex(cage):
                raise SurfaceError(f"{cage.name}: is not convex, so it cannot be Theta (--theta {strategy})")
            return Theta(cage.vertices, f"{cage.name} (convex)", True, k)
        x = sphere_embedding((src, dst))
        probe = src.with_vertices(x, "sphere")
        return Theta(x, "sphere", is_convex(probe, 1e-12), None, _concavity(probe))
    path = os.fspath(strategy)
    surface = read_surface(path)
    check_pair(src, surface)
    if not is_convex(surface):
        raise SurfaceError(f"{path}: Theta must be convex, and this polyhedron is not")
    return Theta(surface.vertices, path, True, None)


def _concavity(surface: Surface) -> dict:
    """How far a star-shaped Theta is from convex: its concave edges and the worst angle."""
    from .surface import reflex_edges

    edges = reflex_edges(surface, 0.0)
    if len(edges) == 0:
        return {"concave_edges": 0, "max_concave_angle_deg": 0.0}
    v, t = surface.vertices, surface.triangles
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n /= np.linalg.norm(n, axis=1)[:, None]
    # Angle between the two normals at each concave edge.
    code = {(int(a), int(b)): k for k, (a, b) in enumerate(np.stack([t, np.roll(t, -1, axis=1)], 2).reshape(-1, 2))}
    worst = 0.0
    for a, b in edges.tolist():
        i, j = code[(a, b)] // 3, code[(b, a)] // 3
        worst = max(worst, math.degrees(math.acos(min(1.0, max(-1.0, float(n[i] @ n[j]))))))
    return {"concave_edges": int(len(edges)), "max_concave_angle_deg": round(worst, 3)}


def sphere_embedding(cages: tuple[Surface, ...]) -> NDArray[np.float64]:
    """A bijective map of the cages' vertices onto the unit sphere (a spherical parameterization).

    Tries, in order: the radial projection of each cage from its centroid
    (bijective when the cage is star-shaped about it: the paper's blobs), and
    a Tutte embedding of the mesh less one triangle in the plane, lifted to
    the sphere by an inverse stereographic projection scaled so that every
    triangle keeps its orientation, then relaxed towards uniform edge
    weights. A candidate is taken only when it is certified bijective: every
    triangle positively oriented as seen from the centre and the solid
    angles summing to 4 pi (degree one).

    Returns
    -------
    (N, 3) ndarray of float
        Unit vectors.

    Raises
    ------
    MeshingError
        If no candidate is bijective.
    """
    t = cages[0].triangles
    for cage in cages:
        v = cage.vertices
        # Centre of the solid (not of the vertices, which cluster where the mesh is fine).
        c = _solid_centroid(v, t)
        x = v - c
        norms = np.linalg.norm(x, axis=1)
        if (norms > 1e-12 * cage.diameter).all():
            x = x / norms[:, None]
            if _bijective(x, t):
                return x
    for seed in _outer_triangles(cages[0]):
        x = _stereographic_tutte(t, cages[0].n_vertices, seed)
        if x is not None and _bijective(x, t):
            return _relax(x, t)
    raise MeshingError(
        f"{cages[0].name}: no bijective spherical parameterization found for Theta; give a convex Theta "
        "with the cages' connectivity (--theta FILE)"
    )


def _solid_centroid(v: NDArray[np.float64], t: NDArray[np.int64]) -> NDArray[np.float64]:
    o = v.mean(axis=0)
    a, b, c = v[t[:, 0]] - o, v[t[:, 1]] - o, v[t[:, 2]] - o
    vol = np.einsum("ij,ij->i", a, np.cross(b, c))
    return o + (vol[:, None] * (a + b + c)).sum(axis=0) / (4.0 * vol.sum())


def _bijective(x: NDArray[np.float64], t: NDArray[np.int64]) -> bool:
    a, b, c = x[t[:, 0]], x[t[:, 1]], x[t[:, 2]]
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    if not (det > 1e-15).all():
        return False
    # Van Oosterom & Strackee: tan(omega / 2) = det / (1 + a.b + b.c + c.a).
    denom = 1.0 + np.einsum("ij,ij->i", a, b) + np.einsum("ij,ij->i", b, c) + np.einsum("ij,ij->i", c, a)
    omega = 2.0 * np.arctan2(det, denom)
    return abs(omega.sum() - 4.0 * math.pi) < 1e-6


def _outer_triangles(cage: Surface, tries: int = 8) -> NDArray[np.int64]:
    """Triangles to leave out of the planar embedding: the largest ones, in a fixed order."""
    area = np.linalg.norm(
        np.cross(cage.vertices[cage.triangles[:, 1]] - cage.vertices[cage.triangles[:, 0]],
                 cage.vertices[cage.triangles[:, 2]] - cage.vertices[cage.triangles[:, 0]]), axis=1
    )  # fmt: skip
    return np.argsort(-area, kind="stable")[:tries]


def _uniform_laplacian(t: NDArray[np.int64], n: int) -> sp.csr_matrix:
    i = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
    j = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    adj = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)).tocsr()
    adj = ((adj + adj.T) > 0).astype(np.float64)
    return (sp.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj).tocsr()


def _stereographic_tutte(t: NDArray[np.int64], n: int, outer: int) -> NDArray[np.float64] | None:
    """Tutte's embedding of the mesh less triangle ``outer`` in a triangle, lifted to the sphere."""
    lap = _uniform_laplacian(t, n)
    b = t[outer]
    free = np.setdiff1d(np.arange(n), b)
    angles = 2.0 * math.pi * np.arange(3) / 3.0
    # The left-out triangle runs clockwise in the plane: seen from outside it
    # is the face at infinity.
    xb = np.stack([np.cos(angles), -np.sin(angles)], axis=1)
    p = np.empty((n, 2))
    p[b] = xb
    rhs = -(lap[free][:, b] @ xb)
    p[free] = np.column_stack([spla.spsolve(lap[free][:, free].tocsc(), rhs[:, k]) for k in range(2)])
    inner = np.delete(np.arange(len(t)), outer)
    # Orientation on the sphere of an inner triangle is orient2d * (1 + s^2 k) with k the power of
    # the origin with respect to its circumcircle; the outer one needs s > 1 (its circle has k = -1).
    q = p[t[inner]]
    a, bb, c = q[:, 0], q[:, 1], q[:, 2]
    d = 2.0 * (a[:, 0] * (bb[:, 1] - c[:, 1]) + bb[:, 0] * (c[:, 1] - a[:, 1]) + c[:, 0] * (a[:, 1] - bb[:, 1]))
    if (np.abs(d) < 1e-300).any():
        return None
    sq = (q**2).sum(axis=2)
    ux = (sq[:, 0] * (bb[:, 1] - c[:, 1]) + sq[:, 1] * (c[:, 1] - a[:, 1]) + sq[:, 2] * (a[:, 1] - bb[:, 1])) / d
    uy = (sq[:, 0] * (c[:, 0] - bb[:, 0]) + sq[:, 1] * (a[:, 0] - c[:, 0]) + sq[:, 2] * (bb[:, 0] - a[:, 0])) / d
    power = 2.0 * (ux * a[:, 0] + uy * a[:, 1]) - sq[:, 0]  # |centre|^2 - radius^2
    worst = float(max(-power.min(), 1e-12))
    if worst >= 1.0:
        return None
    s = worst ** -0.25  # between 1 and 1 / sqrt(worst)
    p *= s
    r2 = (p**2).sum(axis=1)
    x = np.column_stack([2 * p[:, 0], 2 * p[:, 1], r2 - 1.0]) / (r2 + 1.0)[:, None]
    a3, b3, c3 = x[t[:, 0]], x[t[:, 1]], x[t[:, 2]]
    if np.einsum("ij,ij->i", a3, np.cross(b3, c3)).sum() < 0:
        x[:, 2] *= -1.0
    return x


def _relax(x: NDArray[np.float64], t: NDArray[np.int64]) -> NDArray[np.float64]:
    """Move each vertex towards the mean of its neighbours on the sphere while the map stays bijective."""
    n = len(x)
    lap = _uniform_laplacian(t, n)
    deg = lap.diagonal()
    adj = sp.diags(deg) - lap
    best = x
    for _ in range(SPHERE_STEPS):
        y = (adj @ best) / deg[:, None]
        y -= y.mean(axis=0)
        y /= np.linalg.norm(y, axis=1)[:, None]
        if not _bijective(y, t):
            break
        step = float(np.abs(y - best).max())
        best = y
        if step < 1e-7:
            break
    return best
