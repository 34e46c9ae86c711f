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
Evaluation is a compiled, vectorised sum over sites per point (`_evaluate`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from .._jit import njit
from numpy.typing import ArrayLike, NDArray

from ..grid import inside_polygon
from .closed_form import (
    ClosedForm,
    Frame,
    boundary_nodes,
    caller_parameters,
    distance_to_boundary,
    fast_log,
    interior_angles,
    local_edges,
    lstsq,
    node_data,
    on_edges,
    prepare_polygon,
)

__all__ = ["MFSSolution", "fit_mfs", "default_mfs_sites"]

#: Clustering of the corner sites: d_j = D exp(-sigma (sqrt(n_c) - sqrt(j))).
_CORNER_SIGMA = 4.0
#: Farthest corner site, as a fraction of the shorter edge at the vertex.
_CORNER_REACH = 0.5
#: Grading strength (see `warpcli.maps.closed_form.boundary_nodes`) of the
#: offset sites and fitting nodes towards reflex vertices.
_GRADING = 0.5


#: Floating-point flags of the evaluation kernel: reassociation lets LLVM
#: vectorise the sums over sites (the order of the additions then depends on
#: the SIMD width of the machine: results are deterministic on a machine, and
#: agree across machines to rounding); contraction allows fused multiply-adds.
_FASTMATH = {"reassoc", "contract"}


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def _evaluate(px, py, sx, sy, w0, w1, want_val, want_jac, want_hess, val, jac, hess):
    """Sum w_i log|z - s_i| and its derivatives over the sites, for every point.

    One loop over points, and inside it a branch-free loop over sites per
    requested quantity, which LLVM vectorises (the log is `fast_log` for
    that reason).  With F(z) = sum_i w_i log(z - s_i): value = Re F,
    gradient = (Re F', -Im F') with F' = sum w_i / (z - s_i), and
    phi_xx = -phi_yy = Re F'', phi_xy = -Im F'' with F'' = -sum w_i / (z - s_i)^2.
    """
    K = px.shape[0]
    m = sx.shape[0]
    for k in range(K):
        x = px[k]
        y = py[k]
        if want_val and want_jac:
            v0 = 0.0
            v1 = 0.0
            a00 = 0.0
            a01 = 0.0
            a10 = 0.0
            a11 = 0.0
            for i in range(m):
                dx = x - sx[i]
                dy = y - sy[i]
                r2 = dx * dx + dy * dy
                lg = fast_log(r2)
                inv = 1.0 / r2
                gx = dx * inv
                gy = dy * inv
                v0 += w0[i] * lg
                v1 += w1[i] * lg
                a00 += w0[i] * gx
                a01 += w0[i] * gy
                a10 += w1[i] * gx
                a11 += w1[i] * gy
            val[k, 0] = 0.5 * v0
            val[k, 1] = 0.5 * v1
            jac[k, 0, 0] = a00
            jac[k, 0, 1] = a01
            jac[k, 1, 0] = a10
            jac[k, 1, 1] = a11
        elif want_val:
            v0 = 0.0
            v1 = 0.0
            for i in range(m):
                dx = x - sx[i]
                dy = y - sy[i]
                lg = fast_log(dx * dx + dy * dy)
                v0 += w0[i] * lg
                v1 += w1[i] * lg
            val[k, 0] = 0.5 * v0
            val[k, 1] = 0.5 * v1
        elif want_jac:
            a00 = 0.0
            a01 = 0.0
            a10 = 0.0
            a11 = 0.0
            for i in range(m):
                dx = x - sx[i]
                dy = y - sy[i]
                inv = 1.0 / (dx * dx + dy * dy)
                gx = dx * inv
                gy = dy * inv
                a00 += w0[i] * gx
                a01 += w0[i] * gy
                a10 += w1[i] * gx
                a11 += w1[i] * gy
            jac[k, 0, 0] = a00
            jac[k, 0, 1] = a01
            jac[k, 1, 0] = a10
            jac[k, 1, 1] = a11
        if want_hess:
            h0r = 0.0
            h0i = 0.0
            h1r = 0.0
            h1i = 0.0
            for i in range(m):
                dx = x - sx[i]
                dy = y - sy[i]
                inv = 1.0 / (dx * dx + dy * dy)
                ur = dx * inv  # u = 1/(z - s)
                ui = -dy * inv
                u2r = ur * ur - ui * ui
                u2i = 2.0 * ur * ui
                h0r -= w0[i] * u2r
                h0i -= w0[i] * u2i
                h1r -= w1[i] * u2r
                h1i -= w1[i] * u2i
            hess[k, 0, 0, 0] = h0r
            hess[k, 0, 0, 1] = -h0i
            hess[k, 0, 1, 0] = -h0i
            hess[k, 0, 1, 1] = -h0r
            hess[k, 1, 0, 0] = h1r
            hess[k, 1, 0, 1] = -h1i
            hess[k, 1, 1, 0] = -h1i
            hess[k, 1, 1, 1] = -h1r


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def _bounds(px, py, reach, sx, sy, ar, ai, br, bi, rho, const, out):
    """Per disc (centre p, radius r): the evaluation error of A and B at p and bounds of their Taylor remainders.

    A(z) = sum_i alpha_i / (z - s_i) + a0, B the same with beta_i (|alpha_i| =
    |beta_i| = ``rho[i]``), so A^(k)(z) = (-1)^k k! sum_i alpha_i / (z -
    s_i)^(k+1). Over the disc (|z - s_i| >= d_i - r, d_i = |p - s_i|):

        |A(p + h) - A(p) - A'(p) h| <= |A''(p)| r^2 / 2 + |A^(3)(p)| r^3 / 6
                                       + sum_i rho_i r^4 / (d_i - r)^5,

    the last the Lagrange remainder of order 4 (4! / 4! sum rho_i / (d_i -
    r)^5). A''(p) and A^(3)(p) are summed exactly: the weights cancel (their
    absolute sums are 1e3-1e4 times the derivatives, measured), so the sum
    of absolute values enters only at order 4, where r / (d_i - r) is small.
    Rounding: (m + 1) eps times 2 the absolute sums, at every order.
    """
    K = px.shape[0]
    m = sx.shape[0]
    eps = 2.220446049250313e-16
    for k in range(K):
        r = reach[k]
        t0 = const
        t2 = 0.0
        t3 = 0.0
        t4 = 0.0
        a2r = 0.0
        a2i = 0.0
        a3r = 0.0
        a3i = 0.0
        b2r = 0.0
        b2i = 0.0
        b3r = 0.0
        b3i = 0.0
        for i in range(m):
            dx = px[k] - sx[i]
            dy = py[k] - sy[i]
            d2 = dx * dx + dy * dy
            d = np.sqrt(d2)
            inv = 1.0 / d2
            ur = dx * inv  # u = 1 / (z - s)
            ui = -dy * inv
            u2r = ur * ur - ui * ui
            u2i = 2.0 * ur * ui
            u3r = u2r * ur - u2i * ui
            u3i = u2r * ui + u2i * ur
            u4r = u3r * ur - u3i * ui
            u4i = u3r * ui + u3i * ur
            # A'' = 2 sum alpha u^3, A^(3) = -6 sum alpha u^4 (moduli below)
            a2r += ar[i] * u3r - ai[i] * u3i
            a2i += ar[i] * u3i + ai[i] * u3r
            a3r += ar[i] * u4r - ai[i] * u4i
            a3i += ar[i] * u4i + ai[i] * u4r
            b2r += br[i] * u3r - bi[i] * u3i
            b2i += br[i] * u3i + bi[i] * u3r
            b3r += br[i] * u4r - bi[i] * u4i
            b3i += br[i] * u4i + bi[i] * u4r
            t0 += rho[i] * inv * d
            t2 += rho[i] * inv * inv * d
            t3 += rho[i] * inv * inv
            # branch-free (the loop vectorises): a disc reaching the site gives 1/0 = inf
            g = max(d - r, 0.0)
            g2 = g * g
            t4 += rho[i] / (g2 * g2 * g)
        rnd = 2.0 * (m + 1) * eps
        r2 = r * r
        r3 = r2 * r
        # |A''| r^2 / 2 = |sum alpha u^3| r^2, |A^(3)| r^3 / 6 = |sum alpha u^4| r^3
        common = rnd * (t2 * r2 + t3 * r3) + t4 * r2 * r2
        out[k, 0] = rnd * t0
        out[k, 1] = np.hypot(a2r, a2i) * r2 + np.hypot(a3r, a3i) * r3 + common
        out[k, 2] = np.hypot(b2r, b2i) * r2 + np.hypot(b3r, b3i) * r3 + common


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
            _evaluate(
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


    def _local_bounds(self, p: NDArray[np.float64], reach: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.zeros((len(p), 3))
        if len(p):
            w = self.weights
            a = self.affine[1:]  # rows (x, y), columns (u, v): u_x = a[0, 0], u_y = a[1, 0], ...
            const = 0.5 * max(np.hypot(a[0, 0] + a[1, 1], a[0, 1] - a[1, 0]), np.hypot(a[0, 0] - a[1, 1], a[0, 1] + a[1, 0]))
            _bounds(
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
