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


def _generated_mesh(k, seed=2026_11_25):
    """The mesh of a random simple polygon (star-shaped, 5-40 vertices; integer corners for every
    third, axis-aligned edges and cotangents of exactly 0) at a random density."""
    rng = np.random.default_rng([seed, k])
    n = int(rng.integers(5, 41))
    angles = np.sort(rng.uniform(0, 2 * np.pi, n))
    radii = rng.uniform(20, 60, n)
    pts = np.stack([64 + radii * np.cos(angles), 64 + radii * np.sin(angles)], axis=1)
    if k % 3 == 0:
        pts = np.round(pts)
    return mesh_polygon(Polygon(pts), float(rng.uniform(0.5, 12.0)))


def _brute_force_edges(tri):
    """{(lo, hi): sorted half-edges} by a dictionary over every half-edge h = k * M + t."""
    m = len(tri)
    edges = {}
    for k in range(3):
        for t in range(m):
            a, b = int(tri[t, (k + 1) % 3]), int(tri[t, (k + 2) % 3])
            edges.setdefault((min(a, b), max(a, b)), []).append(k * m + t)
    return edges


@pytest.mark.parametrize("seed", range(12))
def test_edges_and_system_of_generated_meshes(seed):
    mesh = _generated_mesh(seed)
    e = topology.mesh_edges(mesh.triangles, mesh.n_vertices)
    expected = _brute_force_edges(mesh.triangles)
    assert list(zip(e.lo.tolist(), e.hi.tolist())) == sorted(expected)
    for lo, hi, first, second in zip(e.lo, e.hi, e.first, e.second):
        halves = expected[(lo, hi)]
        assert [first] + ([second] if second >= 0 else []) == halves and (second < 0) == (len(halves) == 1)
    # The system, bit for bit scipy's (as above, on shapes drawn at random).
    k_ref = solve.cotan_laplacian(mesh.vertices, mesh.triangles)
    k_ref.sort_indices()
    k = sparse.cotan_stiffness(mesh.vertices, mesh.triangles, e)
    assert np.array_equal(k.indptr, k_ref.indptr) and np.array_equal(k.indices, k_ref.indices)
    assert _bits(k.data) == _bits(k_ref.data)
    rng = np.random.default_rng(seed)
    for _ in range(3):
        rows = np.flatnonzero(rng.random(mesh.n_vertices) < rng.uniform(0.1, 0.9))
        cols = np.flatnonzero(rng.random(mesh.n_vertices) < rng.uniform(0.1, 0.9))
        ref = k_ref[rows][:, cols]
        ref.sort_indices()
        mine = sparse.submatrix(k, rows, cols)
        assert np.array_equal(mine.indptr, ref.indptr) and np.array_equal(mine.indices, ref.indices)
        assert _bits(mine.data) == _bits(ref.data)


def test_edges_or_a_matrix_that_cannot_be_the_meshs_are_refused_before_the_compiled_passes():
    small, large = mesh_polygon(Polygon(star()), 12.0), mesh_polygon(Polygon(star()), 2.0)
    with pytest.raises(ValueError, match="not those of a mesh"):
        sparse.cotan_stiffness(small.vertices, small.triangles, large.edges)  # another mesh's edges
    k = sparse.cotan_stiffness(small.vertices, small.triangles, small.edges)
    rows = np.arange(small.n_vertices)
    bad = [
        sparse.CSR(k.indptr, k.indices + 1, k.data, k.shape),  # a column past the last
        sparse.CSR(k.indptr[:-1], k.indices, k.data, k.shape),  # a row short
        sparse.CSR(k.indptr * 2, k.indices, k.data, k.shape),  # rows ending past the entries
    ]
    for m in bad:
        with pytest.raises(ValueError, match="not a CSR matrix"):
            sparse.submatrix(m, rows, rows)
    with pytest.raises(ValueError, match=r"\(M, 3\)"):
        topology.mesh_edges(small.triangles[:, :2], small.n_vertices)


def test_a_triangle_with_a_repeated_or_missing_vertex_is_refused():
    t = np.array([[0, 1, 2], [2, 1, 1]])
    with pytest.raises(topology.NotManifold, match="repeated vertex"):
        topology.mesh_edges(t, 3)
    for bad in ([[0, 1, 3]], [[0, -1, 2]]):
        with pytest.raises(ValueError, match="outside the mesh"):
            topology.mesh_edges(np.array(bad), 3)
