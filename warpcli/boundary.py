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


@dataclass(frozen=True)
class BoundaryData:
    """Dirichlet boundary data onto Theta, edge by edge: g(i, t) = W_i + u(t) (W_{i+1} - W_i), u the behaviour.

    With its first derivative and a bound on its second, for the collar of a
    smooth map (`warpcli.maps.collar`) and its certificate.

    Parameters
    ----------
    theta : (n, 2) ndarray of float
        Theta's vertices W.
    behaviour : str
        ``"linear"`` (u = t) or ``"quadratic"`` (u = t^2), `to_theta_parameter`.

    Examples
    --------
    >>> g = BoundaryData(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]), "quadratic")
    >>> g.points([0], [0.5]).tolist(), g.tangent([0], [0.5]).tolist(), g.bend([0]).tolist()
    ([[1.0, 0.0]], [[4.0, 0.0]], [8.0])
    """

    theta: NDArray[np.float64]
    behaviour: str = "linear"

    def _edge(self, edge: ArrayLike) -> NDArray[np.float64]:
        e = np.asarray(edge, dtype=np.intp)
        return self.theta[(e + 1) % len(self.theta)] - self.theta[e]

    def points(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """g(edge, t), (K, 2): Theta's points (as `edge_points` of `to_theta_parameter`)."""
        return edge_points(self.theta, edge, to_theta_parameter(t, self.behaviour))

    def tangent(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """dg/dt, (K, 2)."""
        s = np.asarray(t, dtype=np.float64)
        slope = 2.0 * s if self.behaviour == "quadratic" else np.ones_like(s)
        return slope[:, None] * self._edge(edge)

    def bend(self, edge: ArrayLike) -> NDArray[np.float64]:
        """|d^2 g / dt^2| on the whole edge, (K,): 0 (linear) or 2 |W_{i+1} - W_i| (quadratic)."""
        k = 2.0 if self.behaviour == "quadratic" else 0.0
        return k * np.hypot(*self._edge(edge).T)

    def parameter(self, edge: ArrayLike, t_from: ArrayLike, t_to: ArrayLike, fraction: ArrayLike) -> NDArray[np.float64]:
        """The t between t_from and t_to whose point lies ``fraction`` of the way from g(t_from) to g(t_to)."""
        a = to_theta_parameter(t_from, self.behaviour)
        b = to_theta_parameter(t_to, self.behaviour)
        return from_theta_parameter(a + np.asarray(fraction, dtype=np.float64) * (b - a), self.behaviour)
