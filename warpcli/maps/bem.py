"""Boundary element method (BEM) for the harmonic map of a polygon (paper §3.1.2).

The harmonic map phi: P -> R^2 with phi = b on the boundary is found one
component at a time (two right-hand sides of one linear system).  On the
boundary, phi is the piecewise-linear data b itself and its normal derivative
q = d phi / dn is piecewise linear too (hat functions B_i on boundary nodes,
paper §3.1.2); q is found by collocating the boundary integral equation (6).
Inside, phi is evaluated by the representation formula

    phi(x) = sum_i (d_i int B_i G_x - c_i int dG_x/dn B_i),
    G_x(y) = -1/(2 pi) log|x - y|.

Conventions and choices (each is justified where it is implemented):

- Everything runs in normalised coordinates: the bounding box of P is
  centred at the origin and its longer side scaled to 1
  (`warpcli.maps.closed_form.Frame`).  This
  also keeps the logarithmic capacity of the boundary in [1/4, 0.6], away
  from the "degenerate scale" 1 at which the single-layer operator is singular.
- The polygon is made counter-clockwise, so the outward normal of an edge
  with unit tangent tau (as a complex number) is n = -i tau.
- omega(x) in (6) is the *interior* angle at x over 2 pi (1/2 on edges).  The
  paper says "exterior angle"; with G_x = -1/(2 pi) log|x - y| and the outward
  normal, the constant function forces omega = -PV int dG_x/dn = (angle of P
  seen from x) / (2 pi) = interior angle / (2 pi).  `tests/test_bem.py`
  checks this against the double-layer row sums.
- The flux q is discontinuous at corners: every polygon vertex carries two
  flux values, one per side ("double node").  Collocation is at the ordinary
  nodes and, instead of at a vertex, at two points a fraction `offset` of an
  element length inside the two elements that meet there (smooth boundary
  points, omega = 1/2, and exactly as many as flux unknowns), plus at every
  element midpoint; the overdetermined system is solved by least squares
  (the midpoints cut the interior error ~10x, measured).  Affine data and
  anything whose flux is piecewise linear per edge (e.g. x*y on an
  axis-aligned polygon) are reproduced to rounding error; a continuous flux
  cannot represent the jump of q = grad(phi).n at a corner (measured: 10-100x
  larger boundary deviation with the paper's continuous hats).
- Integrals of log|x - y| and of its derivatives against linear functions on
  a straight element have closed forms (`warpcli.maps._bem_kernels.near_integrals`);
  they are used for the singular integrals of the collocation system and,
  in evaluation, for every (point, element) pair closer than two element
  lengths, so values and derivatives stay accurate arbitrarily close to the
  boundary.

This module fits the solution; `warpcli.maps.bem_eval` evaluates it (Gauss
rules, closed forms near the boundary, a one-level treecode for the far field).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._native import Kernels
from .bem_eval import NEAR, ElementSources, evaluate, gauss01, gauss_sources
from .closed_form import (
    TWO_PI,
    ClosedForm,
    Frame,
    boundary_nodes,
    caller_parameters,
    interior_angles,
    local_edges,
    lstsq,
    node_data,
    on_edges,
    prepare_polygon,
)

__all__ = ["BEMSolution", "default_bem_nodes", "fit_bem"]

#: The compiled kernels: the collocation's integrals (`warpcli.maps._bem_kernels.bem_assemble`) and the
#: certificate's bounds (`warpcli.maps._bem_kernels.bem_bounds`).
_compiled = Kernels("warpcli.maps._bem_kernels", depends=("_smooth_kernels.py",))


# --------------------------------------------------------------------------
# Bounds of the derivatives over discs (the certificate's)
# --------------------------------------------------------------------------


def _node_poles(nodes, flux, data):
    """A'' and B'' of the representation formula as rational functions with poles at the nodes.

    With A = (U_0' + i U_1') / 2 (phi_a = Re U_a), element e from a to b (unit
    tangent tau) contributes -1/(2 pi tau) I1[q] - i/(2 pi) I2[c] to A, where
    I1[q] = int_a^b q(y) / (z - y) dy and I2[c] = int_a^b c(y) / (y - z)^2 dy
    with the complex densities q = (q_0 + i q_1) / 2, c = (c_0 + i c_1) / 2
    (B: -i), linear along the element (slopes q', c' per unit of y). In
    closed form (integrating the linear densities):

        I1'' = q' (1/(z-a) - 1/(z-b)) - q_a/(z-a)^2 + q_b/(z-b)^2,
        I2'' = c' (1/(z-a)^2 - 1/(z-b)^2) - 2 c_a/(z-a)^3 + 2 c_b/(z-b)^3,

    rational with poles at the element's ends only: A'' and B'' inside the
    polygon are sums over the nodes of gamma_k / (z - y_n)^k, k = 1, 2, 3
    (at a node inside an edge the q and c terms of its two elements cancel;
    the slopes' jumps remain). Returns the nodes' coefficients (m, 3)
    complex for A and for B.
    """
    m = len(nodes)
    z = nodes[:, 0] + 1j * nodes[:, 1]
    nxt = (np.arange(m) + 1) % m
    delta = z[nxt] - z
    tau = delta / np.abs(delta)
    out = []
    for s in (1.0, -1.0):  # A, then B
        q = 0.5 * (flux[:, :, 0] + s * 1j * flux[:, :, 1])  # (m, 2 ends)
        c = 0.5 * (data[:, :, 0] + s * 1j * data[:, :, 1])
        dq = (q[:, 1] - q[:, 0]) / delta
        dc = (c[:, 1] - c[:, 0]) / delta
        ks = -1.0 / (TWO_PI * tau)  # the single layer's factor
        kd = -1j / TWO_PI  # the double layer's
        g = np.zeros((m, 3), dtype=np.complex128)
        np.add.at(g, (np.arange(m), 0), ks * dq)
        np.add.at(g, (nxt, 0), -ks * dq)
        np.add.at(g, (np.arange(m), 1), -ks * q[:, 0] + kd * dc)
        np.add.at(g, (nxt, 1), ks * q[:, 1] - kd * dc)
        np.add.at(g, (np.arange(m), 2), -2.0 * kd * c[:, 0])
        np.add.at(g, (nxt, 2), 2.0 * kd * c[:, 1])
        out.append(g)
    return out[0], out[1]


def _star_shaped(p, r, V):
    """Whether the disc B(p, r) meets the polygon V in a set star-shaped from p.

    Sufficient conditions: the disc lies inside (farther than r from every
    edge), or it meets exactly one edge and holds no vertex (the disc cut
    by one edge's line: convex).
    """
    n = len(V)
    meets = np.zeros(len(p), dtype=np.int64)
    vertex = np.zeros(len(p), dtype=bool)
    for i in range(n):  # loop over the polygon's edges, vectorised over discs
        a = V[i]
        e = V[(i + 1) % n] - a
        t = np.clip(((p - a) @ e) / (e @ e), 0.0, 1.0)
        q = p - (a + t[:, None] * e)
        meets += np.hypot(q[:, 0], q[:, 1]) <= r
        vertex |= np.hypot(p[:, 0] - a[0], p[:, 1] - a[1]) <= r
    return (meets == 0) | ((meets == 1) & ~vertex)


# --------------------------------------------------------------------------
# The method
# --------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class BEMSolution(ClosedForm):
    """A fitted BEM approximation of the harmonic map phi of a polygon (paper §3.1.2).

    Create with `fit_bem`.  All arrays are in the local frame of ``frame``.

    Attributes
    ----------
    m : int
        Number of boundary nodes (including the polygon's vertices).
    frame : Frame
        Normalisation of coordinates and data.
    nodes : (m, 2) ndarray of float
        Boundary nodes (local coordinates, counter-clockwise).
    flux : (m, 2, 2) ndarray of float
        ``flux[e, s, a]``: normal derivative of component a of the local map
        at the start (s = 0) or end (s = 1) of element e (from node e to node
        e+1); differs on both sides of a vertex.
    data : (m, 2, 2) ndarray of float
        The same for the (local) boundary data.
    trace : (edge, t, values) or None
        With natural boundary conditions: the boundary nodes as (caller's
        edge, parameter) and the map's solved values there (caller's
        coordinates).
    """

    m: int
    frame: Frame
    nodes: NDArray[np.float64]
    flux: NDArray[np.float64]
    data: NDArray[np.float64]
    _sources: ElementSources | tuple = ()
    trace: tuple | None = None
    #: The polygon's local vertices and `_node_poles` (the certificate's bounds).
    _polygon: NDArray[np.float64] | tuple = ()
    _poles: tuple = ()

    # -- evaluation ---------------------------------------------------------

    def _local(self, p: NDArray[np.float64], want_val: bool, want_jac: bool, want_hess: bool):
        return evaluate(p, self._sources, self.flux, self.data, want_val, want_jac, want_hess)

    def _local_bounds(self, p: NDArray[np.float64], reach: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.zeros((len(p), 3))
        if len(p):
            ga, gb = self._poles
            g = np.concatenate([ga.T, gb.T])  # (6, m)
            w = np.array([[2.0], [6.0], [12.0]]) * np.maximum(np.abs(ga), np.abs(gb)).T
            a = self.nodes
            b = np.roll(a, -1, axis=0)
            size = np.hypot(*(b - a).T) * (
                np.hypot(self.flux[:, 0, 0], self.flux[:, 0, 1]) + np.hypot(self.flux[:, 1, 0], self.flux[:, 1, 1])
                + np.hypot(self.data[:, 0, 0], self.data[:, 0, 1]) + np.hypot(self.data[:, 1, 0], self.data[:, 1, 1])
            ) / TWO_PI  # fmt: skip
            _compiled.bem_bounds(
                np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), reach,
                np.ascontiguousarray(a[:, 0]), np.ascontiguousarray(a[:, 1]),
                np.ascontiguousarray(g.real), np.ascontiguousarray(g.imag), np.ascontiguousarray(w),
                np.ascontiguousarray(b[:, 0] - a[:, 0]), np.ascontiguousarray(b[:, 1] - a[:, 1]),
                1.0 / ((b - a) ** 2).sum(axis=1), size, out,
            )  # fmt: skip
            # the remainder holds along segments inside the polygon: where the
            # disc meets it in a set not star-shaped from p, nothing is proved
            out[~_star_shaped(p, reach, self._polygon), 1:] = np.inf
        return out


def default_bem_nodes(n_vertices: int) -> int:
    """Default number of BEM nodes for a polygon with ``n_vertices`` vertices.

    Parameters
    ----------
    n_vertices : int

    Returns
    -------
    int
        ``max(256, 8 * n_vertices)`` (see the measurements in the module's
        tests and the accompanying report; paper §3.1.4: m < 1000 suffices).
    """
    return max(256, 8 * n_vertices)


def fit_bem(
    vertices: ArrayLike,
    targets: ArrayLike,
    m: int | None = None,
    *,
    flux: str = "double",
    grading: float = 2.0 / 3.0,
    offset: float = 0.25,
    boundary: str = "linear",
    free: tuple[tuple[int, ...], tuple[int, ...]] = ((), ()),
) -> BEMSolution:
    """Fit the BEM approximation of the harmonic map with piecewise-linear boundary data.

    The boundary integral equation (6) is collocated at the nodes (at two
    points next to each vertex instead of the vertex itself, for the "double"
    flux) and at every element's midpoint, and the overdetermined system for
    the flux values is solved by least squares (LAPACK gelsd).  Regular
    integrals use 16-point Gauss rules, the ones on or near the collocation
    point's own elements closed forms.

    Parameters
    ----------
    vertices : (n, 2) array_like of float
        A simple polygon P, either orientation.
    targets : (n, 2) array_like of float
        ``targets[i]`` is the image of vertex i; the boundary data are linear
        along each edge.
    m : int, optional
        Number of boundary nodes, vertices included (at least n); default
        `default_bem_nodes`.
    flux : {"double", "continuous"}, optional
        "double" (default): two flux values at each vertex (see the module
        docstring).  "continuous": one flux value per node, as in the paper,
        collocated at the nodes themselves (omega = interior angle / 2 pi at
        vertices); kept for comparison -- it cannot follow the jump of the
        flux at corners (10-100x larger boundary deviation, measured).
    grading : float, optional
        Grading strength gamma in [0, 1) at reflex vertices (half of it at
        convex ones): element sizes grow like r^gamma with the distance r to
        the vertex, i.e. algebraic grading with exponent 1 / (1 - gamma) = 3
        by default.
    offset : float, optional
        Where, as a fraction of the element length from the vertex, the two
        collocation points next to a vertex lie ("double" only).
    boundary : {"linear", "quadratic"}, optional
        The boundary behaviour along each edge (§5.2,
        `warpcli.boundary.to_theta_parameter`); the data stay linear between
        nodes.
    free : pair of tuples of int, optional
        Natural boundary conditions (§5.2, experimental): component a of the
        map has zero normal derivative on the edges ``free[a]`` (the caller's
        indices; edge i runs from vertex i to i + 1), where its boundary
        values become unknowns of the system, and is prescribed elsewhere
        (the vertices stay prescribed). Needs the "double" flux.

    Returns
    -------
    BEMSolution
        With natural conditions, ``trace`` holds the solved boundary values.
    """
    frame, V, T = prepare_polygon(vertices, targets)
    n = len(V)
    if m is None:
        m = default_bem_nodes(n)
    m = int(m)
    if m < n:
        raise ValueError(f"m must be at least the number of vertices ({n}), got {m}")
    if flux not in ("double", "continuous"):
        raise ValueError(f"flux must be 'double' or 'continuous', got {flux!r}")
    if not 0.0 <= grading < 1.0:
        raise ValueError("grading must be in [0, 1)")
    if not 0.0 < offset < 0.5:
        raise ValueError("offset must be in (0, 1/2)")
    natural = any(len(f) for f in free)
    if natural and flux != "double":
        raise ValueError("natural boundary conditions need the 'double' flux")

    angles = interior_angles(V)
    # grade towards reflex vertices (singular flux) and, half as strongly,
    # towards convex ones (flux jump and r^(pi/alpha) terms)
    gamma = np.where(angles > np.pi + 1e-9, grading, 0.5 * grading)
    edge, t = boundary_nodes(V, m, gamma)
    nodes = on_edges(V, edge, t)
    is_vertex = t == 0.0
    data_nodes = node_data(T, edge, t, boundary, frame.flipped)

    nxt = np.roll(np.arange(m), -1)
    a = nodes
    d = nodes[nxt] - nodes
    cdata = np.stack([data_nodes, data_nodes[nxt]], axis=1)  # (m, 2 ends, 2 comps)

    # Collocation points, their weight omega, data value, and incidence.
    # The data at a collocation point is (1 - w) c[node] + w c[nxt[node]] (``cat``).
    cpts, omega, cval, inc_e, inc_t, cat = [], [], [], [], [], []
    for k in range(m):  # loop over boundary nodes (setup only)
        prev = (k - 1) % m
        if is_vertex[k] and flux == "double":
            for e_, tt in ((prev, 1.0 - offset), (k, offset)):
                cpts.append(a[e_] + tt * d[e_])
                omega.append(0.5)
                cval.append((1 - tt) * cdata[e_, 0] + tt * cdata[e_, 1])
                inc_e.append((e_, -1))
                inc_t.append((tt, -1.0))
                cat.append((e_, tt))
        else:
            cpts.append(a[k])
            # omega = interior angle / (2 pi) at a vertex, 1/2 on an edge
            omega.append(angles[edge[k]] / TWO_PI if is_vertex[k] else 0.5)
            cval.append(data_nodes[k])
            inc_e.append((prev, k))
            inc_t.append((1.0, 0.0))
            cat.append((k, 0.0))
    # Collocate at every element's midpoint too, and solve in the least-squares
    # sense: measured on L, C, star and convex shapes, this gives ~10x smaller
    # interior errors and ~2x smaller boundary deviations than the square
    # (nodes only) system, for both flux models.
    for e_ in range(m):  # loop over elements (setup only)
        cpts.append(a[e_] + 0.5 * d[e_])
        omega.append(0.5)
        cval.append(0.5 * (cdata[e_, 0] + cdata[e_, 1]))
        inc_e.append((e_, -1))
        inc_t.append((0.5, -1.0))
        cat.append((e_, 0.5))
    cpts = np.array(cpts)
    omega = np.array(omega)
    cval = np.array(cval)
    inc_e = np.array(inc_e, dtype=np.int64)
    inc_t = np.array(inc_t, dtype=np.float64)

    gt, gw = gauss01(16)
    S = np.empty((len(cpts), m, 2))
    D = np.empty((len(cpts), m, 2))
    _compiled.bem_assemble(
        np.ascontiguousarray(cpts[:, 0]), np.ascontiguousarray(cpts[:, 1]), inc_e, inc_t,
        np.ascontiguousarray(a[:, 0]), np.ascontiguousarray(a[:, 1]),
        np.ascontiguousarray(a[nxt, 0]), np.ascontiguousarray(a[nxt, 1]), gt, gw, NEAR, S, D,
    )  # fmt: skip

    # Unknown flux values: uidx[e, s] for the start (s=0) / end (s=1) of element e.
    if flux == "double":
        right = np.cumsum(np.where(is_vertex, 2, 1)) - 1  # unknown just after node k
        left = np.where(is_vertex, right - 1, right)  # unknown just before node k
        uidx = np.stack([right, left[nxt]], axis=1)
        nunk = int(right[-1] + 1)
    else:
        uidx = np.stack([np.arange(m), nxt], axis=1)
        nunk = m
    A = np.zeros((len(cpts), nunk))
    for s in range(2):  # scatter-add the two hat halves of each element
        np.add.at(A.T, uidx[:, s], S[:, :, s].T)
    trace = None
    if natural:
        cat_node = np.array([c[0] for c in cat], dtype=np.int64)
        cat_w = np.array([c[1] for c in cat])
        qflux, cdata = _solve_natural(
            A, S, D, omega, cat_node, cat_w, uidx, nxt, edge, is_vertex, data_nodes,
            tuple(local_edges(f, n, frame.flipped) for f in free),
        )  # fmt: skip
        ce, ct = caller_parameters(edge, t, n, frame.flipped)
        trace = (ce, ct, frame.tcentre + frame.tscale * cdata[:, 0, :])
    else:
        # (6) at x_p: sum S q = omega c(x_p) - sum D c   (D = -int c dG/dn, PV)
        rhs = omega[:, None] * cval - np.einsum("pes,esa->pa", D, cdata)
        sol = lstsq(A, rhs)
        qflux = np.ascontiguousarray(sol[uidx])  # (m, 2, 2)

    sources = gauss_sources(a, a[nxt], qflux, cdata)
    return BEMSolution(
        m=m, frame=frame, nodes=nodes, flux=qflux, data=np.ascontiguousarray(cdata), _sources=sources,
        trace=trace, _polygon=V, _poles=_node_poles(nodes, qflux, cdata),
    )  # fmt: skip


def _solve_natural(A, S, D, omega, cat_node, cat_w, uidx, nxt, edge, is_vertex, data_nodes, free):
    """The collocated system (6) with natural conditions on some edges, one component at a time.

    (6) reads S q = (omega P - Dn) c, with P interpolating the nodes' data at
    the collocation points and Dn the double-layer integrals gathered per
    node. For component a, q is zero on the elements of the edges
    ``free[a]`` and unknown elsewhere; c is unknown at the nodes inside those
    edges and known elsewhere (vertices included). The unknowns of both kinds
    go to the left, and the least-squares system is solved with unit-norm
    columns (flux and data unknowns differ in scale).
    """
    p, m = len(omega), len(edge)
    M = np.zeros((p, m))
    rows = np.arange(p)
    np.add.at(M, (rows, cat_node), omega * (1.0 - cat_w))
    np.add.at(M, (rows, nxt[cat_node]), omega * cat_w)
    np.add.at(M.T, np.arange(m), -D[:, :, 0].T)
    np.add.at(M.T, nxt, -D[:, :, 1].T)
    qflux = np.zeros((m, 2, 2))
    cdata = np.zeros((m, 2, 2))
    for comp in range(2):  # the two components have different conditions
        on_free = np.isin(edge, free[comp])
        unknown_c = np.flatnonzero(on_free & ~is_vertex)
        known_c = np.flatnonzero(~(on_free & ~is_vertex))
        unknown_q = np.unique(uidx[~on_free].ravel())
        lhs = np.concatenate([A[:, unknown_q], -M[:, unknown_c]], axis=1)
        rhs = M[:, known_c] @ data_nodes[known_c, comp]
        scale = np.linalg.norm(lhs, axis=0)
        scale[scale == 0] = 1.0
        sol = lstsq(lhs / scale, rhs) / scale
        q = np.zeros(A.shape[1])
        q[unknown_q] = sol[: len(unknown_q)]
        c = data_nodes[:, comp].copy()
        c[unknown_c] = sol[len(unknown_q) :]
        qflux[:, :, comp] = q[uidx]
        cdata[:, 0, comp] = c
        cdata[:, 1, comp] = c[nxt]
    return np.ascontiguousarray(qflux), np.ascontiguousarray(cdata)
