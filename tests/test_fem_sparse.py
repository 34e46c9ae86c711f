"""Tests of warpcli.maps.fem.sparse: the Dirichlet system in numpy, bit for bit scipy.sparse's."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as sla

from helpers import comb, l_shape, regular, spiral, star
from warpcli.maps.fem import solve, sparse, topology
from warpcli.maps.fem.locate import triangle_neighbours
from warpcli.maps.fem.mesh import TriMesh, mesh_polygon
from warpcli.maps.theta import regular_polygon
from warpcli.polygon import Polygon

# Axis-aligned shapes give right angles: cotangents of exactly 0 and entries that cancel.
SHAPES = {"star": star(), "L": l_shape(), "comb": comb(), "spiral": spiral(), "square": regular(4, phase=np.pi / 4)}


def _bits(a) -> bytes:
    return np.ascontiguousarray(a).view(np.uint8).tobytes()


def _meshes():
    for name, pts in SHAPES.items():
        for area in (0.8, 6.0):
            yield f"{name}-{area}", mesh_polygon(Polygon(pts), area)


@pytest.mark.parametrize("name, mesh", list(_meshes()))
def test_the_system_is_scipys_bit_for_bit(name, mesh):
    k_ref = solve.cotan_laplacian(mesh.vertices, mesh.triangles)
    k_ref.sort_indices()
    k = sparse.cotan_stiffness(mesh.vertices, mesh.triangles, mesh.edges)
    assert np.array_equal(k.indptr, k_ref.indptr) and np.array_equal(k.indices, k_ref.indices)
    assert _bits(k.data) == _bits(k_ref.data)
    fixed = np.zeros(mesh.n_vertices, dtype=bool)
    fixed[mesh.boundary] = True
    unknown, known = np.flatnonzero(~fixed), mesh.boundary
    k_u = k_ref[unknown]
    k_uu, k_uk = k_u[:, unknown].tocsc(), k_u[:, known]
    mine_uu, mine_uk = sparse.submatrix(k, unknown, unknown), sparse.submatrix(k, unknown, known)
    indptr, indices, data = sparse.to_csc(mine_uu)
    assert np.array_equal(indptr, k_uu.indptr) and np.array_equal(indices, k_uu.indices)
    assert _bits(data) == _bits(k_uu.data)
    # Symmetric: the rows serve as the columns.
    assert np.array_equal(mine_uu.indptr, indptr) and _bits(mine_uu.data) == _bits(data)
    values = np.zeros((mesh.n_vertices, 2))
    values[known] = solve.boundary_values(mesh, regular_polygon(len(np.unique(mesh.boundary_edge))))
    rhs_ref = -(k_uk @ values[known])
    rhs = -(mine_uk @ values[known])
    assert _bits(rhs) == _bits(rhs_ref)
    assert _bits(mine_uk @ values[known][:, 0]) == _bits(k_uk @ values[known][:, 0])
    ref = sla.splu(k_uu, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    lu = sparse.splu(mine_uu, symmetric=True)
    assert _bits(lu.solve(np.ascontiguousarray(rhs))) == _bits(ref.solve(np.ascontiguousarray(rhs_ref)))


def test_the_solver_gives_the_scipy_routes_values(monkeypatch):
    mesh = mesh_polygon(Polygon(star()), 2.0)
    theta = regular_polygon(12)
    fast = solve.DirichletSolver(mesh).solve(theta)

    def refuse(*args):
        raise sparse.Unsupported("the scipy route, for the test")

    monkeypatch.setattr(solve, "_cotan_system", refuse)
    assert _bits(solve.DirichletSolver(mesh).solve(theta)) == _bits(fast)


def test_neighbours_from_the_edges_are_triangle_neighbours():
    for _, mesh in _meshes():
        got = topology.neighbours(mesh.edges, mesh.n_triangles)
        assert np.array_equal(got, triangle_neighbours(mesh.triangles))


def test_a_mesh_with_an_edge_of_three_triangles_takes_the_scipy_route():
    # Three triangles on the edge 0-1 (not a mesh triangle makes, but a TriMesh can hold it).
    v = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 1.0], [0.5, -1.0], [0.6, 2.0], [2.0, 2.0]])
    t = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [2, 4, 5]], dtype=np.int32)
    mesh = TriMesh(v, t, np.array([0, 1, 3, 4, 5]), np.array([0, 1, 2, 3, 4]), np.zeros(5))
    with pytest.raises(topology.NotManifold, match="more than two"):
        topology.mesh_edges(t, len(v))
    with pytest.raises(topology.NotManifold):
        mesh.edges
    values = solve.DirichletSolver(mesh).solve(regular_polygon(5))  # through scipy.sparse
    assert np.isfinite(values).all()


def test_superlu_is_loaded_on_its_own():
    module = sparse._superlu()
    assert module.__name__ == "scipy.sparse.linalg._dsolve._superlu"
    from scipy.sparse.linalg._dsolve import _superlu

    assert _superlu is module  # a later import of scipy.sparse.linalg finds the same module
