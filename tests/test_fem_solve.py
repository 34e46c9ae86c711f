"""Tests of warpcli.maps.fem.solve: the cotangent Laplacian and the Dirichlet solve."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import comb, l_shape, regular, spiral, star
from warpcli.maps.fem import FEMMap
from warpcli.maps.fem.mesh import mesh_polygon
from warpcli.maps.fem.solve import boundary_values, cotan_laplacian, mean_value_laplacian, solve_dirichlet
from warpcli.maps.theta import Theta, regular_polygon
from warpcli.polygon import Polygon

SHAPES = {"star": star(), "L": l_shape(), "comb": comb(), "spiral": spiral()}


def solve_harmonic(poly, max_area, theta, weights="cotan"):
    """The FEM map of ``poly`` meshed at ``max_area`` onto ``theta`` (an (n, 2) array)."""
    mesh = mesh_polygon(poly, max_area)
    return FEMMap(poly, Theta(theta), mesh, solve_dirichlet(mesh, theta, weights), weights)


def test_laplacian_of_right_triangle_by_hand():
    # Right angle at vertex 0, 45 degrees at 1 and 2: cot 45 = 1, cot 90 = 0.
    v = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    k = cotan_laplacian(v, np.array([[0, 1, 2]])).toarray()
    expected = np.array([[1.0, -0.5, -0.5], [-0.5, 0.5, 0.0], [-0.5, 0.0, 0.5]])
    np.testing.assert_allclose(k, expected, atol=1e-15)


@pytest.mark.parametrize("name", SHAPES)
def test_laplacian_symmetric_zero_row_sums_nonnegative_interior_weights(name):
    mesh = mesh_polygon(Polygon(SHAPES[name]), 4.0)
    k = cotan_laplacian(mesh.vertices, mesh.triangles)
    assert abs(k - k.T).max() < 1e-12
    assert np.abs(np.asarray(k.sum(axis=1))).max() < 1e-10
    # Constrained Delaunay, no interior constraints: every edge with an
    # interior endpoint has cot a + cot b >= 0, i.e. K_ij <= 0.
    is_b = np.zeros(mesh.n_vertices, bool)
    is_b[mesh.boundary] = True
    coo = k.tocoo()
    off = coo.row != coo.col
    interior_edge = off & ~(is_b[coo.row] & is_b[coo.col])
    assert coo.data[interior_edge].max() <= 1e-12


@pytest.mark.parametrize("name", SHAPES)
def test_boundary_interpolated_and_no_flips(name):
    poly = Polygon(SHAPES[name])
    theta = regular_polygon(poly.n)
    phi = solve_harmonic(poly, 4.0, theta)
    np.testing.assert_allclose(phi.values[phi.mesh.boundary], boundary_values(phi.mesh, theta), atol=0)
    corners = phi.mesh.boundary[phi.mesh.boundary_t == 0]
    np.testing.assert_allclose(phi.values[corners], theta[phi.mesh.boundary_edge[phi.mesh.boundary_t == 0]], atol=1e-15)
    assert not phi.flipped().any()


def test_linear_functions_are_reproduced_exactly():
    """P1 FEM reproduces linear data: a triangle goes onto Theta affinely."""
    tri = Polygon([[10.0, 12.0], [90.0, 30.0], [40.0, 100.0]])
    theta = regular_polygon(3)
    phi = solve_harmonic(tri, 3.0, theta)
    # The affine map sending the polygon's vertices to Theta's.
    src = np.hstack([tri.points, np.ones((3, 1))])
    coef = np.linalg.solve(src, theta)
    expected = np.hstack([phi.mesh.vertices, np.ones((phi.mesh.n_vertices, 1))]) @ coef
    np.testing.assert_allclose(phi.values, expected, atol=1e-12)


def test_interior_values_are_discrete_harmonic():
    poly = Polygon(star())
    phi = solve_harmonic(poly, 4.0, regular_polygon(poly.n))
    k = cotan_laplacian(phi.mesh.vertices, phi.mesh.triangles)
    residual = k @ phi.values
    interior = np.setdiff1d(np.arange(phi.mesh.n_vertices), phi.mesh.boundary)
    assert np.abs(residual[interior]).max() < 1e-10


def test_mirrored_polygon_maps_without_flips():
    """A polygon oriented against Theta gives an orientation-reversing map, not a flip."""
    poly = Polygon(regular(7)[::-1])
    phi = solve_harmonic(poly, 4.0, regular_polygon(7))
    assert not phi.flipped().any()


def test_mean_value_weights_are_positive_and_reproduce_linear_functions():
    mesh = mesh_polygon(Polygon(star()), 6.0)
    k = mean_value_laplacian(mesh.vertices, mesh.triangles)
    coo = k.tocoo()
    off = coo.row != coo.col
    assert (coo.data[off] < 0).all()  # w_ij > 0 on every edge
    assert np.abs(np.asarray(k.sum(axis=1))).max() < 1e-10
    # Linear precision: sum_j w_ij (v_j - v_i) = 0 at interior vertices.
    interior = np.setdiff1d(np.arange(mesh.n_vertices), mesh.boundary)
    assert np.abs((k @ mesh.vertices)[interior]).max() < 1e-9


@pytest.mark.parametrize("name", SHAPES)
def test_positive_weights_never_flip_and_interpolate_the_boundary(name):
    poly = Polygon(SHAPES[name])
    theta = regular_polygon(poly.n)
    phi = solve_harmonic(poly, 4.0, theta, "positive")
    assert not phi.flipped().any()
    np.testing.assert_allclose(phi.values[phi.mesh.boundary], boundary_values(phi.mesh, theta), atol=0)


def test_positive_weights_map_a_triangle_affinely():
    tri = Polygon([[10.0, 12.0], [90.0, 30.0], [40.0, 100.0]])
    phi = solve_harmonic(tri, 3.0, regular_polygon(3), "positive")
    coef = np.linalg.solve(np.hstack([tri.points, np.ones((3, 1))]), regular_polygon(3))
    expected = np.hstack([phi.mesh.vertices, np.ones((phi.mesh.n_vertices, 1))]) @ coef
    np.testing.assert_allclose(phi.values, expected, atol=1e-12)
