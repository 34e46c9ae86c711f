"""Tests of warpcli.locate: bucket-grid point location and scan conversion."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import comb, star
from warpcli.locate import TriangleLocator, barycentric_combine, scan_convert
from warpcli.mesh import mesh_polygon
from warpcli.pipeline import pixel_centres
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


@pytest.mark.parametrize("shape", [star(), comb()])
def test_scan_conversion_equals_point_location_at_pixel_centres(shape):
    mesh = mesh_polygon(Polygon(shape), 3.0)
    tri_s, bary_s = scan_convert(mesh.vertices, mesh.triangles, 130, 125)
    tri_l, bary_l = TriangleLocator(mesh.vertices, mesh.triangles).locate(pixel_centres(130, 125))
    assert np.array_equal(tri_s, tri_l)
    np.testing.assert_array_equal(bary_s, bary_l)


def test_pixel_centre_on_a_shared_edge_goes_to_the_smaller_index():
    # Two triangles sharing the diagonal x = y; pixel (1, 1) has its centre on it.
    v = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    for tris in (np.array([[0, 1, 2], [0, 2, 3]]), np.array([[0, 2, 3], [0, 1, 2]])):
        tri, _ = scan_convert(v, tris, 4, 4)
        assert tri.reshape(4, 4)[1, 1] == 0
        assert (tri >= 0).all()
