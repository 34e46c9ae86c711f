"""Tests of warpcli.locate: bucket-grid point location and scan conversion."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import comb, star
from warpcli.maps.fem.locate import TriangleLocator, barycentric_combine, triangle_neighbours
from warpcli.maps.fem.mesh import mesh_polygon
from warpcli.polygon import Polygon


def brute_force(vertices, triangles, points, tol=1e-10):
    """Smallest index of a triangle containing each point, by testing all of them."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))

    def cross(u, w):
        return u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0]

    out = np.full(len(points), -1)
    for i, p in enumerate(points):
        d2 = cross(b - a, p - a) / cross(b - a, c - a)
        d1 = cross(p - a, c - a) / cross(b - a, c - a)
        l0 = 1 - d1 - d2
        inside = np.flatnonzero((d1 >= -tol) & (d2 >= -tol) & (l0 >= -tol))
        out[i] = inside[0] if inside.size else -1
    return out


@pytest.mark.parametrize("shape", [star(), comb()])
def test_locator_agrees_with_brute_force(shape):
    mesh = mesh_polygon(Polygon(shape), 40.0)
    rng = np.random.default_rng(8)
    pts = np.concatenate([rng.uniform(-5, 133, (400, 2)), mesh.vertices[:50]])
    tri, bary = TriangleLocator(mesh.vertices, mesh.triangles).locate(pts)
    expected = brute_force(mesh.vertices, mesh.triangles, pts)
    assert np.array_equal(tri >= 0, expected >= 0)
    # Same triangle, or (on a shared edge or vertex) one whose interpolation agrees.
    back = barycentric_combine(mesh.vertices, mesh.triangles, tri, bary)
    np.testing.assert_allclose(back[tri >= 0], pts[tri >= 0], atol=1e-9)
    assert np.isnan(bary[tri < 0]).all()


def test_neighbours_are_mutual_and_share_the_opposite_edge():
    mesh = mesh_polygon(Polygon(comb()), 20.0)
    nbr = triangle_neighbours(mesh.triangles)
    t = mesh.triangles
    for i in range(len(t)):
        for k in range(3):
            j = nbr[i, k]
            edge = {t[i, (k + 1) % 3], t[i, (k + 2) % 3]}
            if j < 0:
                continue
            assert i in nbr[j]
            assert edge <= set(t[j])
