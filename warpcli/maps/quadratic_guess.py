"""A quadratic first guess for Newton's inverse of a smooth map (paper §3.2): P2 triangles in Theta.

The first guess of `warpcli.maps.meshless` is the piecewise-linear inverse of
a triangulation of the polygon mapped into Theta. Its error is O(h^2) (median
0.025 px for the 1 MP star pair's 4000-triangle mesh), so nearly every point
needs two Newton steps, three evaluations of the map. With the map's values at
the triangulation's edge midpoints too, each triangle's image is a quadratic
(isoparametric P2) patch

    T(l1, l2) = sum_k N_k(l) phi(x_k),

x_k its three vertices and three midpoints, N_k the quadratic Lagrange
functions of the barycentric coordinates l = (1 - l1 - l2, l1, l2). A target q
in the triangle's image is solved for by Newton on T (two steps from the
linear barycentric coordinates), and its guess is the source point with
those coordinates: error O(h^3) (median 5e-4 px on that pair, measured), and
about two thirds of the points converge after one step (2.3 evaluations per
point instead of 2.9).

Only the starting point changes: Newton's tests (residual, line search,
domain) decide every pre-image as before, and a guess that would leave the
polygon (a curved patch next to the boundary) or is not finite keeps the
linear one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._arrays import first_and_inverse

__all__ = ["QuadraticGuess"]

#: Newton steps on the quadratic patch (the first already leaves the patch's own error, O(h^3), behind).
STEPS = 2


@dataclass(frozen=True, eq=False)
class QuadraticGuess:
    """The P2 patches of a triangulation's image, for first guesses of pre-images.

    Create with `of`.

    Attributes
    ----------
    vertices : (V, 2) ndarray of float
        The triangulation's vertices (in the polygon).
    triangles : (T, 3) ndarray of int
    coef_rows : (12, T) ndarray of float
        Per triangle, T(l1, l2) = A + B1 l1 + B2 l2 + C11 l1^2 + C12 l1 l2 +
        C22 l2^2: the rows are the x and y of A, B1, B2, C11, C12, C22.
    """

    vertices: NDArray[np.float64]
    triangles: NDArray[np.int64]
    coef_rows: NDArray[np.float64]

    @classmethod
    def of(
        cls,
        vertices: NDArray[np.float64],
        triangles: NDArray[np.int64],
        image: NDArray[np.float64],
        evaluate: Callable[[NDArray[np.float64]], NDArray[np.float64]],
        *,
        jacobian: NDArray[np.float64] | None = None,
    ) -> QuadraticGuess:
        """The patches of a triangulation whose vertices map to ``image``; ``evaluate`` maps the edge midpoints.

        With the map's ``jacobian`` at the vertices, an edge whose two ends have one takes the cubic
        Hermite value at its midpoint, (f_a + f_b) / 2 + (J_a - J_b)(b - a) / 8 (error of order h^4,
        one beyond the patch's own O(h^3)), and only the others are evaluated: at 1 MP, 22k midpoint
        evaluations of a BEM map (0.1 s of the source map's build, measured) become ~4k, those of
        edges with an end on the boundary, where the Jacobian is not defined.

        Parameters
        ----------
        vertices : (V, 2) ndarray of float
        triangles : (T, 3) ndarray of int
        image : (V, 2) ndarray of float
            The map at the vertices.
        evaluate : callable
            ``evaluate(points)`` (k, 2) -> (k, 2): the map (called once, at
            the midpoints of the triangulation's edges, those not given by
            ``jacobian``).
        jacobian : (V, 2, 2) ndarray of float or None
            The map's Jacobian at the vertices (NaN where it has none).

        Returns
        -------
        QuadraticGuess
        """
        tri = np.asarray(triangles, dtype=np.int64)
        ends = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        ends.sort(axis=1)
        # each edge once
        first, which = first_and_inverse(ends[:, 0] * len(vertices) + ends[:, 1])
        pairs = ends[first]
        centre = 0.5 * (vertices[pairs[:, 0]] + vertices[pairs[:, 1]])
        if jacobian is None:
            mid = evaluate(centre)
        else:
            ja, jb = jacobian[pairs[:, 0]], jacobian[pairs[:, 1]]
            h = vertices[pairs[:, 1]] - vertices[pairs[:, 0]]
            mid = 0.5 * (image[pairs[:, 0]] + image[pairs[:, 1]]) + 0.125 * np.einsum("kab,kb->ka", ja - jb, h)
            lack = np.flatnonzero(~np.isfinite(mid).all(axis=1))
            mid[lack] = evaluate(centre[lack])
        which = which.reshape(3, -1)
        p0, p1, p2 = image[tri[:, 0]], image[tri[:, 1]], image[tri[:, 2]]
        m01, m12, m20 = mid[which[0]], mid[which[1]], mid[which[2]]
        # N_0 = l0 (2 l0 - 1), N_1 = l1 (2 l1 - 1), N_2 = l2 (2 l2 - 1), N_01 = 4 l0 l1, N_12 = 4 l1 l2,
        # N_20 = 4 l2 l0 with l0 = 1 - l1 - l2, collected by monomials of (l1, l2)
        coef = np.concatenate(
            [
                p0,
                -3.0 * p0 - p1 + 4.0 * m01,
                -3.0 * p0 - p2 + 4.0 * m20,
                2.0 * p0 + 2.0 * p1 - 4.0 * m01,
                4.0 * (p0 - m01 + m12 - m20),
                2.0 * p0 + 2.0 * p2 - 4.0 * m20,
            ],
            axis=1,
        )
        return cls(np.asarray(vertices, dtype=np.float64), tri, np.ascontiguousarray(coef.T))

    def guess(
        self,
        q: NDArray[np.float64],
        tri: NDArray[np.intp],
        bary: NDArray[np.float64],
        linear: NDArray[np.float64],
        inside: Callable[[NDArray[np.float64]], NDArray[np.bool_]],
    ) -> NDArray[np.float64]:
        """First guesses of the pre-images of ``q``, each in the image of triangle ``tri`` (>= 0).

        Parameters
        ----------
        q : (K, 2) ndarray of float
            Targets.
        tri : (K,) ndarray of int
            The triangle whose (straight) image holds each target.
        bary : (K, 3) ndarray of float
            Its barycentric coordinates there.
        linear : (K, 2) ndarray of float
            The piecewise-linear guesses (kept where the quadratic one is
            not finite or not ``inside``).
        inside : callable
            ``inside(points)`` -> bool mask: the map's domain.

        Returns
        -------
        (K, 2) ndarray of float
        """
        # per point the rows of its patch's coefficients: ax, ay, b1x, b1y, ... (one gather)
        ax, ay, b1x, b1y, b2x, b2y, c11x, c11y, c12x, c12y, c22x, c22y = self.coef_rows[:, tri]
        qx = q[:, 0]
        qy = q[:, 1]
        l1 = bary[:, 1].copy()
        l2 = bary[:, 2].copy()
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for _ in range(STEPS):
                # the patch T and its derivatives along l1 (j1) and l2 (j2) at (l1, l2)
                j1x = b1x + c11x * l1
                j1y = b1y + c11y * l1
                j2x = b2x + c22x * l2
                j2y = b2y + c22y * l2
                rx = qx - (ax + l1 * (j1x + c12x * l2) + l2 * j2x)
                ry = qy - (ay + l1 * (j1y + c12y * l2) + l2 * j2y)
                j1x += c11x * l1 + c12x * l2
                j1y += c11y * l1 + c12y * l2
                j2x += c12x * l1 + c22x * l2
                j2y += c12y * l1 + c22y * l2
                det = j1x * j2y - j2x * j1y
                l1 += (rx * j2y - j2x * ry) / det
                l2 += (j1x * ry - rx * j1y) / det
            v = self.vertices[self.triangles[tri]]
            out = v[:, 0] + l1[:, None] * (v[:, 1] - v[:, 0]) + l2[:, None] * (v[:, 2] - v[:, 0])
        ok = np.isfinite(out).all(axis=1)
        ok[ok] = inside(out[ok])
        out[~ok] = linear[~ok]
        return out
