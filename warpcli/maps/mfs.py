"""Method of fundamental solutions (MFS) for the harmonic map of a polygon (paper §3.1.3).

Each component of the map is approximated by

    phi_hat(x) = sum_i w_i log|x - s_i| + A(x),     A affine,

i.e. the paper's sum_i w_i G_{s_i} + A with the factor -1/(2 pi) of the
Green's function (5) absorbed into the weights.  The sites s_i lie outside the
polygon, so phi_hat is harmonic inside by construction; w and A are fitted to
the piecewise-linear boundary data b at k >> m boundary nodes by linear least
squares.

Site placement (a documented variant of Martin et al. 2008, who put the
sites on an outward offset of the boundary):

- ``m - r * n_c`` sites on an outward offset of the boundary: boundary nodes
  distributed by arclength (graded towards reflex vertices), each moved along
  the outward normal (the outward bisector at a vertex) by ``offset`` times
  the local node spacing;
- ``n_c`` sites on the outward bisector of each of the r reflex vertices, at
  distances clustered exponentially towards the vertex ("lightning"
  placement of Gopal & Trefethen 2019): the solution behaves like
  r^(pi/alpha) there, and a charge density on the exterior bisector
  reproduces exactly that singular function (its natural harmonic extension
  is continuous across the bisector), whereas a plain offset curve stays at a
  fixed distance from the corner and converges slowly;
- a site that falls inside the polygon, or closer to some other part of the
  boundary than half the intended distance (a concave polygon's offset can
  cross the polygon elsewhere), is pulled back towards its boundary node
  until it is not.

The defaults (offset 3 node spacings, n_c = sqrt(m) corner sites reaching
half the shorter edge with clustering sigma = 4, k = 4 m fitting nodes) were
chosen by measuring the boundary deviation and the interior error against a
converged BEM solution on L-, C- and star-shaped polygons and a convex
pentagon: a larger offset converges faster for smooth data (sites far from
the boundary) but the corner sites are what makes reflex corners converge.

All of this happens in the normalised frame of `warpcli.maps.closed_form.Frame`.
Evaluation is a compiled, vectorised sum over sites per point
(`warpcli.maps._smooth_kernels.mfs_evaluate`), called as cached machine code
without importing numba (`warpcli._native.Kernels`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._native import Kernels

from ..grid import inside_polygon
from .closed_form import (
    ClosedForm,
    Frame,
    boundary_nodes,
    caller_parameters,
    distance_to_boundary,
    interior_angles,
    local_edges,
    lstsq,
    node_data,
    on_edges,
    prepare_polygon,
)

__all__ = ["MFSSolution", "fit_mfs", "default_mfs_sites"]

#: The evaluation kernel, as cached machine code (numba only to compile it once).
_compiled = Kernels("warpcli.maps._smooth_kernels")

#: Clustering of the corner sites: d_j = D exp(-sigma (sqrt(n_c) - sqrt(j))).
_CORNER_SIGMA = 4.0
#: Farthest corner site, as a fraction of the shorter edge at the vertex.
_CORNER_REACH = 0.5
#: Grading strength (see `warpcli.maps.closed_form.boundary_nodes`) of the
#: offset sites and fitting nodes towards reflex vertices.
_GRADING = 0.5


@dataclass(frozen=True, eq=False)
class MFSSolution(ClosedForm):
    """A fitted MFS approximation of the harmonic map phi of a polygon (paper §3.1.3).

    Create with `fit_mfs`.  Arrays are in the local frame of ``frame``.

    Attributes
    ----------
    m : int
        Number of sites.
    k : int
        Number of boundary nodes the fit used.
    frame : Frame
        Normalisation of coordinates and data.
    sites : (m, 2) ndarray of float
        The sites s_i (local coordinates), all outside the polygon.
    weights : (m, 2) ndarray of float
        ``weights[i, a]``: weight of log|x - s_i| in component a (local data).
    affine : (3, 2) ndarray of float
        ``affine[:, a]`` = (c, a_x, a_y): the affine part c + a_x x + a_y y.
    residual : float
        Largest deviation from the (local) data at the fitting nodes, in
        units of the original targets (prescribed data only).
    trace : (edge, t, values) or None
        With natural boundary conditions: fitting nodes on the edges as
        (caller's edge, parameter) and the map's values there.
    """

    m: int
    k: int
    frame: Frame
    sites: NDArray[np.float64]
    weights: NDArray[np.float64]
    affine: NDArray[np.float64]
    residual: float
    trace: tuple | None = None

    def _local(self, p: NDArray[np.float64], want_val: bool, want_jac: bool, want_hess: bool):
        K = len(p)
        val = np.zeros((K if want_val else 0, 2))
        jac = np.zeros((K if want_jac else 0, 2, 2))
        hess = np.zeros((K if want_hess else 0, 2, 2, 2))
        if K:
            _compiled.mfs_evaluate(
                np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
                np.ascontiguousarray(self.sites[:, 0]), np.ascontiguousarray(self.sites[:, 1]),
                np.ascontiguousarray(self.weights[:, 0]), np.ascontiguousarray(self.weights[:, 1]),
                want_val, want_jac, want_hess, val, jac, hess,
            )  # fmt: skip
        if want_val:
            val += self.affine[0] + p @ self.affine[1:]
        if want_jac:
            jac += self.affine[1:].T
        return val, jac, hess


    def invert_newton(
        self,
        targets_xy: NDArray[np.float64],
        guess: NDArray[np.float64],
        polygon: NDArray[np.float64],
        thresh: float,
        noise: float,
        *,
        max_iter: int = 20,
        jacobian: bool = False,
        chain: NDArray[np.bool_] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64] | None]:
        """`warpcli.maps.newton.invert` of this map, compiled: the same damped iteration per point.

        One compiled loop per point (`warpcli.maps._smooth_kernels.mfs_invert`)
        instead of numpy passes over the points still iterating: an MFS point
        costs a few sums over the sites, and the passes around them (trial
        points in or out of the polygon, bookkeeping) cost as much.

        Parameters
        ----------
        targets_xy, guess : (K, 2) ndarray of float
            Points to invert (caller's coordinates of the image) and starts.
        polygon : (n, 2) ndarray of float
            The domain (caller's coordinates): starts outside fail, trial
            points outside get their step halved.
        thresh, noise : float
            Absolute residuals (`warpcli.maps.newton.thresholds`).
        max_iter : int
        jacobian : bool
            Also return phi's Jacobian at converged points (NaN elsewhere).
        chain : (K,) ndarray of bool, optional
            Points that start from the quadratic extrapolation of the three
            pre-images before them (when those converged) instead of ``guess``
            (which may then be NaN): runs of evenly spaced targets, such as
            consecutive pixels of a row (`warpcli.maps._smooth_kernels.mfs_invert`).
            A chained point whose three predecessors did not converge, with a
            NaN guess, is returned unconverged.

        Returns
        -------
        points : (K, 2) ndarray of float
        converged : (K,) ndarray of bool
        jacobians : (K, 2, 2) ndarray of float or None
        """
        from .newton import ARMIJO, MAX_HALVINGS

        q = np.ascontiguousarray(targets_xy, dtype=np.float64)
        g = np.ascontiguousarray(guess, dtype=np.float64)
        K = len(q)
        out = np.empty((K, 2))
        ok = np.zeros(K, dtype=np.uint8)
        jac = np.empty((K if jacobian else 0, 2, 2))
        f = self.frame
        frame = np.array([f.centre[0], f.centre[1], f.scale, f.tcentre[0], f.tcentre[1], f.tscale], dtype=np.float64)
        v = np.asarray(polygon, dtype=np.float64)
        links = np.zeros(K, dtype=np.uint8) if chain is None else np.ascontiguousarray(chain, dtype=np.uint8)
        if K:
            _compiled.mfs_invert(
                np.ascontiguousarray(q[:, 0]), np.ascontiguousarray(q[:, 1]),
                np.ascontiguousarray(g[:, 0]), np.ascontiguousarray(g[:, 1]), links,
                np.ascontiguousarray(self.sites[:, 0]), np.ascontiguousarray(self.sites[:, 1]),
                np.ascontiguousarray(self.weights[:, 0]), np.ascontiguousarray(self.weights[:, 1]),
                np.ascontiguousarray(self.affine, dtype=np.float64), frame,
                np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1]),
                float(thresh), float(noise), int(max_iter), int(MAX_HALVINGS), float(ARMIJO),
                bool(jacobian), out, ok, jac,
            )  # fmt: skip
        return out, ok.astype(bool), (jac if jacobian else None)

    def _local_bounds(self, p: NDArray[np.float64], reach: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.zeros((len(p), 3))
        if len(p):
            w = self.weights
            a = self.affine[1:]  # rows (x, y), columns (u, v): u_x = a[0, 0], u_y = a[1, 0], ...
            const = 0.5 * max(np.hypot(a[0, 0] + a[1, 1], a[0, 1] - a[1, 0]), np.hypot(a[0, 0] - a[1, 1], a[0, 1] + a[1, 0]))
            _compiled.mfs_bounds(
                np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), reach,
                np.ascontiguousarray(self.sites[:, 0]), np.ascontiguousarray(self.sites[:, 1]),
                0.5 * w[:, 0], 0.5 * w[:, 1], 0.5 * w[:, 0], -0.5 * w[:, 1],
                0.5 * np.hypot(w[:, 0], w[:, 1]), float(const), out,
            )  # fmt: skip
        return out


def default_mfs_sites(n_vertices: int) -> int:
    """Default number of MFS sites for a polygon with ``n_vertices`` vertices.

    Parameters
    ----------
    n_vertices : int

    Returns
    -------
    int
        ``max(256, 8 * n_vertices)``.
    """
    return max(256, 8 * n_vertices)


def _outward_normals(V: NDArray[np.float64], edge: NDArray[np.int64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Outward unit normals at boundary nodes (outward bisector at vertices); V counter-clockwise."""
    e = np.roll(V, -1, axis=0) - V
    ne = np.stack([e[:, 1], -e[:, 0]], axis=1)
    ne /= np.hypot(ne[:, 0], ne[:, 1])[:, None]
    nrm = ne[edge].copy()
    at_vertex = t == 0.0
    bis = ne[edge] + ne[(edge - 1) % len(V)]
    bis /= np.hypot(bis[:, 0], bis[:, 1])[:, None]
    nrm[at_vertex] = bis[at_vertex]
    return nrm


class SitePlacementError(ValueError):
    """MFS sites could not be placed outside the polygon and clear of its boundary (too many for its
    narrowest gaps: a site between two close edges is near both)."""

    def __init__(self, m: int) -> None:
        super().__init__("could not place MFS sites outside the polygon, clear of its boundary")
        self.m = m


def _pull_back(
    V: NDArray[np.float64],
    base: NDArray[np.float64],
    direction: NDArray[np.float64],
    dist: NDArray[np.float64],
    clearance: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Sites ``base + dist * direction``, pulled back until each is outside and clear of the boundary.

    A site is accepted when it is outside the polygon and at least half its
    intended clearance (``clearance * dist``) away from the boundary; otherwise
    its distance is halved (at most 40 times).
    """
    dist = dist.copy()
    for _ in range(40):  # bounded number of passes, vectorised over sites
        s = base + dist[:, None] * direction
        bad = inside_polygon(s, V) | (distance_to_boundary(s, V) < 0.5 * clearance * dist)
        if not bad.any():
            return s
        dist[bad] *= 0.5
    raise SitePlacementError(len(base))


def fit_mfs(
    vertices: ArrayLike,
    targets: ArrayLike,
    m: int | None = None,
    k: int | None = None,
    *,
    offset: float = 3.0,
    corner_sites: int | None = None,
    rcond: float = 1e-13,
    boundary: str = "linear",
    free: tuple[tuple[int, ...], tuple[int, ...]] = ((), ()),
) -> MFSSolution:
    """Fit the MFS approximation of the harmonic map with piecewise-linear boundary data.

    The weights minimise sum_j |phi_hat(x_j) - b(x_j)|^2 over k boundary nodes
    x_j (paper §3.1.3): nodes spaced by arclength (including the vertices,
    mildly graded towards reflex vertices), plus extra nodes clustered
    towards each reflex vertex like the corner sites.  The
    least-squares problem is solved with a truncated SVD (LAPACK gelsd) after
    scaling every column to unit norm.  Why: the MFS matrix is notoriously
    ill-conditioned -- neighbouring sites give nearly parallel columns, and
    the clustered corner sites nearly coincide with offset sites; measured
    condition numbers of the scaled matrix range from ~1e9 (star, m = 256) to
    1e16 (L shape, m = 256 and 1024: numerically rank deficient).  Normal equations would
    square that; an unpivoted QR has no answer for the rank deficiency and
    returns huge, alternating weights that cancel when summed (rounding noise
    in the evaluation).  The SVD with the cut-off ``rcond`` returns the
    minimum-norm weights among the fits that are optimal to that relative
    accuracy.  Column scaling makes the cut-off independent of how close a
    site is to the boundary (the columns' sizes differ by orders of
    magnitude otherwise).

    Parameters
    ----------
    vertices : (n, 2) array_like of float
        A simple polygon P, either orientation.
    targets : (n, 2) array_like of float
        ``targets[i]`` is the image of vertex i; the data are linear along edges.
    m : int, optional
        Number of sites; default `default_mfs_sites`.
    k : int, optional
        Number of boundary fitting nodes (k >= m + 3); default 4 m.
    offset : float, optional
        Distance of the offset-curve sites from the boundary, in units of the
        local spacing of their boundary nodes.
    corner_sites : int, optional
        Sites on the bisector of each reflex vertex; default ``round(sqrt(m))``
        (capped so that at least half the sites remain on the offset curve).
    rcond : float, optional
        Relative cut-off for small singular values of the column-scaled matrix.
    boundary : {"linear", "quadratic"}, optional
        The boundary behaviour along each edge (§5.2,
        `warpcli.boundary.to_theta_parameter`).
    free : pair of tuples of int, optional
        Natural boundary conditions (§5.2, experimental): component a of the
        map is fitted to a zero normal derivative, instead of data, at the
        nodes inside the edges ``free[a]`` (the caller's indices); each
        component is then fitted on its own.

    Returns
    -------
    MFSSolution
    """
    frame, V, T = prepare_polygon(vertices, targets)
    n = len(V)
    m = default_mfs_sites(n) if m is None else int(m)
    k = 4 * m if k is None else int(k)
    if m < n:
        raise ValueError(f"m must be at least the number of vertices ({n}), got {m}")
    if k < m + 3:
        raise ValueError(f"k must be at least m + 3 = {m + 3}, got {k}")

    angles = interior_angles(V)
    reflex = np.flatnonzero(angles > np.pi + 1e-9)
    e = np.roll(V, -1, axis=0) - V
    lengths = np.hypot(e[:, 0], e[:, 1])
    nc = int(round(np.sqrt(m))) if corner_sites is None else int(corner_sites)
    if len(reflex):
        nc = max(0, min(nc, (m - n) // (2 * len(reflex))))
    else:
        nc = 0
    m_off = m - nc * len(reflex)

    # Offset-curve sites (graded mildly towards reflex vertices).
    gamma = np.where(angles > np.pi + 1e-9, _GRADING, 0.0)
    edge, t = boundary_nodes(V, m_off, gamma)
    base = on_edges(V, edge, t)
    spacing = 0.5 * (
        np.hypot(*(np.roll(base, -1, axis=0) - base).T) + np.hypot(*(base - np.roll(base, 1, axis=0)).T)
    )
    normal = _outward_normals(V, edge, t)
    # clearance: how far from the boundary a site at distance d along `normal`
    # should be, in units of d: 1, but sin(half the exterior angle) on the
    # bisector of a reflex vertex
    ext_half = 0.5 * (2.0 * np.pi - angles)
    at_reflex = (t == 0.0) & (angles[edge] > np.pi + 1e-9)
    clear = np.where(at_reflex, np.sin(np.clip(ext_half[edge], 1e-3, None)), 1.0)
    sites = [_pull_back(V, base, normal, offset * spacing, clear)]

    # Corner sites: exponentially clustered on the exterior bisectors
    # (d_j = D exp(-sigma (sqrt(nc) - sqrt(j))), Gopal & Trefethen 2019).
    cx_list, cd_list = [], []
    if nc:
        j = np.arange(1, nc + 1)
        for v in reflex:  # loop over reflex vertices
            D = _CORNER_REACH * min(lengths[v], lengths[v - 1])
            d = D * np.exp(-_CORNER_SIGMA * (np.sqrt(nc) - np.sqrt(j)))
            nrm = _outward_normals(V, np.array([v]), np.array([0.0]))[0]
            clr = np.full(nc, min(1.0, np.sin(max(ext_half[v], 1e-3))))
            base_v = np.repeat(V[v][None, :], nc, axis=0)
            sites.append(_pull_back(V, base_v, np.repeat(nrm[None, :], nc, axis=0), d, clr))
            cx_list.append(v)
            cd_list.append(d)
    S = np.concatenate(sites)

    # Fitting nodes: k_main by arclength (mild grading) + clustered corner nodes.
    n_extra = 4 * nc * len(reflex)
    k_main = max(k - n_extra, m + 3)
    e_k, t_k = boundary_nodes(V, k_main, gamma)
    X = [on_edges(V, e_k, t_k)]
    x_edge, x_t = [e_k], [t_k]
    for v, d in zip(cx_list, cd_list):  # loop over reflex vertices
        for other, length in (((v + 1) % n, lengths[v]), ((v - 1) % n, lengths[v - 1])):  # its two edges
            for f in (0.5, 1.5):  # nodes between and beside the corner sites' distances
                r = np.minimum(f * d / length, 0.5)
                X.append(V[v] + r[:, None] * (V[other] - V[v]))
                # as (edge, parameter): edge v from V[v], or edge v - 1 towards V[v]
                x_edge.append(np.full(len(r), v if other == (v + 1) % n else (v - 1) % n))
                x_t.append(r if other == (v + 1) % n else 1.0 - r)
    X = np.concatenate(X)
    x_edge = np.concatenate(x_edge)
    x_t = np.concatenate(x_t)
    bdata = node_data(T, x_edge, x_t, boundary, frame.flipped)

    # Least squares with scaled columns: [log|x_j - s_i|, 1, x, y].
    dxs = X[:, None, :] - S[None, :, :]
    A = np.empty((len(X), len(S) + 3))
    A[:, : len(S)] = 0.5 * np.log(np.einsum("jik,jik->ji", dxs, dxs))
    A[:, len(S)] = 1.0
    A[:, len(S) + 1 :] = X
    if any(len(f) for f in free):
        coef, residual = _fit_natural(A, X, S, bdata, x_edge, x_t, V, free, rcond, frame)
        solution = _solution(S, X, coef, residual, frame)
        ce, ct = caller_parameters(e_k, t_k, n, frame.flipped)
        trace = (ce, ct, solution.value(frame.centre + frame.scale * X[: len(e_k)]))
        return dataclasses.replace(solution, trace=trace)
    cscale = np.linalg.norm(A, axis=0)
    # truncated-SVD least squares (LAPACK gelsd): minimum-norm solution of the
    # column-scaled problem, singular values below rcond * largest dropped
    coef = lstsq(A / cscale, bdata, cond=rcond) / cscale[:, None]
    residual = float(np.max(np.abs(A @ coef - bdata))) * frame.tscale
    return _solution(S, X, coef, residual, frame)


def _solution(S, X, coef, residual, frame) -> MFSSolution:
    return MFSSolution(
        m=len(S),
        k=len(X),
        frame=frame,
        sites=np.ascontiguousarray(S),
        weights=np.ascontiguousarray(coef[: len(S)]),
        affine=np.ascontiguousarray(coef[len(S) :]),
        residual=residual,
    )


def _fit_natural(A, X, S, bdata, x_edge, x_t, V, free, rcond, frame):
    """Per component: data rows where it is prescribed, zero-normal-derivative rows inside its free edges.

    Normal-derivative rows are taken as they are in the local frame (polygon
    size 1): a slope error counts like a data error over the polygon's size.
    Measured on a dart (a reflex vertex between a free and a prescribed edge)
    against BEM: weighting them by the node spacing instead leaves them so
    weak that the fit misses by 0.3 (and folds); weight 1 gives 3e-3 at
    m = 256 and 6e-4 at m = 1024, weight 10 about twice that.
    """
    n = len(V)
    e = np.roll(V, -1, axis=0) - V
    lengths = np.hypot(e[:, 0], e[:, 1])
    normal = np.stack([e[x_edge, 1], -e[x_edge, 0]], axis=1) / lengths[x_edge, None]  # outward (ccw)
    dxs = X[:, None, :] - S[None, :, :]
    r2 = np.einsum("jik,jik->ji", dxs, dxs)
    dn = np.empty_like(A)
    dn[:, : len(S)] = np.einsum("jik,jk->ji", dxs, normal) / r2
    dn[:, len(S)] = 0.0
    dn[:, len(S) + 1 :] = normal
    coef = np.empty((A.shape[1], 2))
    residual = 0.0
    for comp in range(2):  # the components have different conditions
        neumann = np.isin(x_edge, local_edges(free[comp], n, frame.flipped)) & (x_t > 0.0)
        M = np.where(neumann[:, None], dn, A)
        rhs = np.where(neumann, 0.0, bdata[:, comp])
        cscale = np.linalg.norm(M, axis=0)
        coef[:, comp] = lstsq(M / cscale, rhs, cond=rcond) / cscale
        dirichlet = ~neumann
        if dirichlet.any():
            residual = max(residual, float(np.max(np.abs(A[dirichlet] @ coef[:, comp] - rhs[dirichlet]))))
    return coef, residual * frame.tscale
