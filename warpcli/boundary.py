"""Boundary correspondence: points at a parameter along polygon edges, and back.

The boundary data of every map is defined edge by edge (the paper's §2): the
point at parameter t along edge i of a polygon (from vertex i to vertex i + 1,
mod n) corresponds to the point at parameter t along edge i of Theta. These
are the one place that computes it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


def edge_points(vertices: ArrayLike, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """``(1 - t) v[edge] + t v[edge + 1]``: points at parameter t along polygon edges.

    Parameters
    ----------
    vertices : (n, 2) array_like of float
        The polygon, closed implicitly (edge n - 1 runs back to vertex 0).
    edge : (K,) array_like of int
    t : (K,) array_like of float

    Returns
    -------
    (K, 2) ndarray of float

    Examples
    --------
    >>> edge_points([[0, 0], [4, 0], [4, 2]], [0, 2], [0.25, 0.5]).tolist()
    [[1.0, 0.0], [2.0, 1.0]]
    """
    v = np.asarray(vertices, dtype=np.float64)
    e = np.asarray(edge, dtype=np.intp)
    s = np.asarray(t, dtype=np.float64)[:, None]
    return (1.0 - s) * v[e] + s * v[(e + 1) % len(v)]


def nearest_edge(
    points: ArrayLike, vertices: ArrayLike
) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """The nearest point of a polygon's boundary to each point: edge, parameter, distance.

    A loop over the edges, vectorized over the points: memory O(K) however
    many vertices, and time K x n.

    Parameters
    ----------
    points : (K, 2) array_like of float
    vertices : (n, 2) array_like of float

    Returns
    -------
    edge : (K,) ndarray of int
        The first nearest edge.
    t : (K,) ndarray of float in [0, 1]
    distance : (K,) ndarray of float
    """
    q = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    v = np.asarray(vertices, dtype=np.float64)
    best = np.full(len(q), np.inf)
    edge = np.zeros(len(q), dtype=np.intp)
    param = np.zeros(len(q))
    for i in range(len(v)):
        a = v[i]
        d = v[(i + 1) % len(v)] - a
        rel = q - a
        t = np.clip((rel @ d) / (d @ d), 0.0, 1.0)
        dist = np.hypot(rel[:, 0] - t * d[0], rel[:, 1] - t * d[1])
        closer = dist < best
        best[closer] = dist[closer]
        edge[closer] = i
        param[closer] = t[closer]
    return edge, param, best


def to_theta_parameter(t: ArrayLike, behaviour: str = "linear") -> NDArray[np.float64]:
    """The boundary behaviour (the paper's §2 and §5.2): the parameter along Theta's edge
    of parameter t along the polygon's edge: t (linear) or t^2 (quadratic).

    >>> to_theta_parameter([0.5], "quadratic").tolist()
    [0.25]
    """
    s = np.asarray(t, dtype=np.float64)
    return s * s if behaviour == "quadratic" else s


def from_theta_parameter(s: ArrayLike, behaviour: str = "linear") -> NDArray[np.float64]:
    """The inverse of `to_theta_parameter`.

    >>> from_theta_parameter([0.25], "quadratic").tolist()
    [0.5]
    """
    u = np.asarray(s, dtype=np.float64)
    return np.sqrt(np.clip(u, 0.0, 1.0)) if behaviour == "quadratic" else u


def on_boundary(
    points: ArrayLike, vertices: ArrayLike, tolerance: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """The points within ``tolerance`` of a polygon's boundary, with their nearest edge and parameter.

    Returns
    -------
    index : (J,) ndarray of int
        Which points are that close.
    edge : (J,) ndarray of int
    t : (J,) ndarray of float in [0, 1]

    Examples
    --------
    >>> on_boundary([[1.0, 0.0], [1.0, 0.5]], [[0, 0], [2, 0], [0, 2]], 1e-9)
    (array([0]), array([0]), array([0.5]))
    """
    edge, t, dist = nearest_edge(points, vertices)
    index = np.flatnonzero(dist <= tolerance)
    return index, edge[index], t[index]


def slide(tables: list, edge: ArrayLike, u: ArrayLike, *, forward: bool) -> NDArray[np.float64]:
    """Parameters along Theta's edges of polygon parameters (forward), or the reverse, by the tables `warpcli.maps.base.sliding_tables` makes.

    Parameters
    ----------
    tables : list of (t, s) pairs
    edge : array_like of int
        Edge of each parameter.
    u : array_like of float
        Parameters along the polygon's edges (forward) or Theta's (not forward).
    forward : bool

    Returns
    -------
    ndarray of float
        The other side's parameters, linear between table entries.
    """
    e = np.broadcast_to(np.asarray(edge, dtype=np.intp), np.shape(u))
    u = np.asarray(u, dtype=np.float64)
    out = np.empty(u.shape)
    for i, (t_nodes, s_nodes) in enumerate(tables):  # loop over edges
        on = e == i
        if on.any():
            out[on] = np.interp(u[on], t_nodes, s_nodes) if forward else np.interp(u[on], s_nodes, t_nodes)
    return out


@dataclass(frozen=True)
class BoundaryData:
    """Boundary data onto Theta, edge by edge: g(i, t) = W_i + u_i(t) (W_{i+1} - W_i), u the behaviour.

    u is t (linear), t^2 (quadratic), or, for a boundary that slides along
    Theta's edges (natural conditions), a non-decreasing piecewise-linear
    table per edge (``tables``: (t, u) node arrays, as `warpcli.maps.base.slide`
    reads them). With its derivative and a bound on how far it strays from
    its tangent, for the collar of a smooth map (`warpcli.maps.collar`) and
    its certificate.

    Parameters
    ----------
    theta : (n, 2) ndarray of float
        Theta's vertices W.
    behaviour : str
        ``"linear"`` or ``"quadratic"`` (`to_theta_parameter`); ignored with ``tables``.
    tables : list of (t, u) pairs of 1-D arrays, or None
        The sliding correspondence, one table per edge.

    Examples
    --------
    >>> g = BoundaryData(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]), "quadratic")
    >>> g.points([0], [0.5]).tolist(), g.tangent([0], [0.5]).tolist()
    ([[1.0, 0.0]], [[4.0, 0.0]])
    >>> g.stray([0], [0.4], [0.6], [0.1]).round(12).tolist()  # |g''| / 2 * 0.1^2 = 4 * 0.01
    [0.04]
    """

    theta: NDArray[np.float64]
    behaviour: str = "linear"
    tables: list | None = None

    def _edge(self, edge: ArrayLike) -> NDArray[np.float64]:
        e = np.asarray(edge, dtype=np.intp)
        return self.theta[(e + 1) % len(self.theta)] - self.theta[e]

    def _u(self, edge: NDArray[np.intp], t: NDArray[np.float64]) -> NDArray[np.float64]:
        if self.tables is None:
            return to_theta_parameter(t, self.behaviour)
        return slide(self.tables, edge, t, forward=True)

    def _slopes(self, edge: NDArray[np.intp], t_lo: NDArray[np.float64], t_hi: NDArray[np.float64]):
        """The least and greatest du/dt over [t_lo, t_hi] on each edge."""
        if self.tables is None:
            if self.behaviour == "quadratic":
                return 2.0 * t_lo, 2.0 * t_hi
            return np.ones_like(t_lo), np.ones_like(t_lo)
        lo, hi = np.empty(t_lo.shape), np.empty(t_lo.shape)
        for i in np.unique(edge):  # loop over the edges present, vectorised over their pieces
            on = np.flatnonzero(edge == i)
            tn, un = (np.asarray(a, dtype=np.float64) for a in self.tables[i])
            with np.errstate(divide="ignore", invalid="ignore"):
                slope = np.where(np.diff(tn) > 0, np.diff(un) / np.diff(tn), 0.0)
            # the table's segments meeting [t_lo, t_hi]
            a = np.clip(np.searchsorted(tn, t_lo[on], side="right") - 1, 0, len(slope) - 1)
            b = np.clip(np.searchsorted(tn, t_hi[on], side="left") - 1, 0, len(slope) - 1)
            for k, (x, y) in enumerate(zip(a, np.maximum(a, b))):  # loop over pieces (each spans few segments)
                lo[on[k]], hi[on[k]] = slope[x : y + 1].min(), slope[x : y + 1].max()
        return lo, hi

    def points(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """g(edge, t), (K, 2): Theta's points."""
        e = np.asarray(edge, dtype=np.intp)
        return edge_points(self.theta, e, self._u(e, np.asarray(t, dtype=np.float64)))

    def tangent(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """dg/dt, (K, 2) (a table's: the slope of the segment holding t, the later one at a node)."""
        e = np.asarray(edge, dtype=np.intp)
        s = np.asarray(t, dtype=np.float64)
        return self._slopes(e, s, s)[0][:, None] * self._edge(e)

    def stray(self, edge: ArrayLike, t_lo: ArrayLike, t_hi: ArrayLike, half: ArrayLike) -> NDArray[np.float64]:
        """A bound on |g(t) - g(tm) - (t - tm) dg/dt(tm)| over [t_lo, t_hi], tm its middle, half = (t_hi - t_lo) / 2.

        Smooth u: |u''| half^2 / 2 (0 linear, half^2 quadratic); a table:
        (greatest - least slope over the range) times half. Times |W_{i+1} - W_i|.
        """
        e = np.asarray(edge, dtype=np.intp)
        lo_t, hi_t = np.asarray(t_lo, dtype=np.float64), np.asarray(t_hi, dtype=np.float64)
        h = np.abs(np.asarray(half, dtype=np.float64))
        if self.tables is None:
            k = h * h if self.behaviour == "quadratic" else np.zeros_like(h)
        else:
            lo, hi = self._slopes(e, np.minimum(lo_t, hi_t), np.maximum(lo_t, hi_t))
            k = (hi - lo) * h
        return k * np.hypot(*self._edge(e).T)
