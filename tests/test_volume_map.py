"""The 3D map (warpcli.volume theta/tetmesh/fem/compose): exact mathematics on small meshes."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli.volume import build_map
from warpcli.volume.compose import IdentityMap, TetMap, VoxelGrid
from warpcli.volume.examples import bend, box, icosphere, rotation, star, tetrahedron, twist
from warpcli.volume.fem import laplacian, solve_dirichlet
from warpcli.volume.surface import surface_from_arrays
from warpcli.volume.tetmesh import mesh_polyhedron, tet_volumes
from warpcli.volume.theta import _bijective, _relax, _stereographic_tutte, sphere_embedding, theta_for


def blob(level=2, lobes=3, depth=0.35, scale=1.0):
    v, f = icosphere(level)
    return surface_from_arrays(scale * star(v, lobes, depth), f, "blob.obj")


def inside_points(surface, n, seed=0):
    """Points inside a cage (rejection sampling with a fixed seed)."""
    from warpcli.volume._kernels import winding

    rng = np.random.default_rng(seed)
    lo, hi = surface.bounds
    p = lo + (hi - lo) * rng.random((8 * n, 3))
    return p[winding(p, surface.vertices, surface.triangles) > 0.5][:n]


def test_laplacian_symmetric_zero_rows_and_linear_precision():
    mesh = mesh_polyhedron(blob(1), 0.4)
    k = laplacian(mesh.vertices, mesh.tets)
    assert abs(k - k.T).max() < 1e-12
    assert np.abs(np.asarray(k.sum(axis=1))).max() < 1e-12
    assert (tet_volumes(mesh.vertices, mesh.tets) > 0).all()
    linear = mesh.vertices @ np.array([0.3, -1.0, 2.0]) + 0.5
    interior = np.setdiff1d(np.arange(mesh.n_vertices), mesh.boundary)
    assert np.abs((k @ linear)[interior]).max() < 1e-10


@pytest.mark.parametrize("solver", ["direct", "amg", "jacobi"])
def test_solvers_reproduce_linear_data(solver):
    if solver == "amg":
        pytest.importorskip("pyamg", reason="the amg solver is optional (pip install pyamg)")
    cage = blob(1)
    mesh = mesh_polyhedron(cage, 0.25)
    a = np.array([[1.0, 0.2, 0.0], [0.1, 0.9, 0.3], [0.0, -0.2, 1.1]])
    values, info = solve_dirichlet(mesh, mesh.vertices[mesh.boundary] @ a.T, solver)
    assert info["solver"] == solver
    assert np.abs(values - mesh.vertices @ a.T).max() < 1e-7


def test_tetrahedron_onto_tetrahedron_is_exactly_affine():
    v, f = tetrahedron()
    a = np.array([[2.0, 0.5, 0.1], [-0.3, 1.5, 0.2], [0.4, 0.1, 0.8]])
    shift = np.array([10.0, -3.0, 4.0])
    src = surface_from_arrays(v, f, "a.obj")
    dst = surface_from_arrays(v @ a.T + shift, f, "b.obj")
    vmap = build_map(src, dst, "sphere", edge=0.1)
    assert isinstance(vmap.phi0, TetMap) and isinstance(vmap.phi1, TetMap)
    p = inside_points(src, 300)
    assert np.abs(vmap.forward(p) - (p @ a.T + shift)).max() < 1e-8
    q = p @ a.T + shift
    back, jac = vmap.inverse_mapped(q)
    assert np.abs(back - p).max() < 1e-8
    assert np.abs(jac - np.linalg.inv(a)).max() < 1e-7
    assert all(c.ok for c in vmap.certificates())


@pytest.mark.parametrize("theta", ["auto", "sphere"])
def test_identity_cages_give_the_identity(theta):
    cage = blob(2)
    vmap = build_map(cage, cage.with_vertices(cage.vertices, "copy.obj"), theta, edge=0.3)
    p = inside_points(cage, 400)
    assert np.abs(vmap.inverse(p) - p).max() < 1e-9
    assert np.abs(vmap.forward(p) - p).max() < 1e-9


def test_identity_of_a_convex_cage_needs_no_mesh():
    v, f = box(2)
    cage = surface_from_arrays(v, f, "cube.obj")
    vmap = build_map(cage, cage.with_vertices(v, "cube2.obj"))
    assert isinstance(vmap.phi0, IdentityMap) and isinstance(vmap.phi1, IdentityMap)
    grid = VoxelGrid((4, 4, 4), np.array([[0.25, 0, 0, 0.125], [0, 0.25, 0, 0.125], [0, 0, 0.25, 0.125], [0, 0, 0, 1]]))
    voxels, points = next(vmap.pull_back_slabs(grid))
    assert len(voxels) == 64
    assert np.abs(points - grid.centres(voxels)).max() < 1e-12


def test_similar_cages_give_the_similarity_to_fem_accuracy():
    src = blob(2)
    r = rotation([1.0, 2.0, 0.5], 0.7)
    s, shift = 1.7, np.array([3.0, -1.0, 2.0])
    dst = src.with_vertices(s * src.vertices @ r.T + shift, "similar.obj")
    vmap = build_map(src, dst, "auto", edge=0.12)
    assert vmap.theta.name == "sphere"
    p = inside_points(src, 500)
    err = np.linalg.norm(vmap.forward(p) - (s * p @ r.T + shift), axis=1) / s
    # Errors relative to the blob's size (about 2): FEM accuracy, not rounding.
    assert np.nanmax(err) < 0.02
    assert np.nanmean(err) < 0.005


def test_boundary_faces_go_onto_the_corresponding_faces():
    v, f = box(3)
    src = surface_from_arrays(v, f, "cube.obj")
    dst = surface_from_arrays(bend(twist(v, 0.1), 0.8), f, "bent.obj")
    vmap = build_map(src, dst, "auto", edge=0.2)
    assert isinstance(vmap.phi0, IdentityMap)
    rng = np.random.default_rng(1)
    lam = rng.dirichlet(np.ones(3), size=len(dst.triangles))
    on_dst = np.einsum("tk,tkd->td", lam, dst.vertices[dst.triangles])
    on_src = np.einsum("tk,tkd->td", lam, src.vertices[src.triangles])
    # Pulled back a hair inside the target, points land a hair inside the source face.
    centre = dst.vertices.mean(axis=0)
    back = vmap.inverse(on_dst + 1e-9 * (centre - on_dst))
    assert np.abs(back - on_src).max() < 1e-6
    fwd = vmap.phi1.values[vmap.phi1.mesh.boundary]
    expected = vmap.phi1.mesh.boundary_values(src.vertices, src.triangles)
    assert np.abs(fwd - expected).max() < 1e-12


def test_theta_strategies():
    v, f = box(2)
    cube = surface_from_arrays(v, f, "cube.obj")
    bent = surface_from_arrays(bend(v, 1.0), f, "bent.obj")
    assert theta_for(bent, cube).cage == 1
    assert theta_for(cube, bent).cage == 0
    t = theta_for(bent, bent.with_vertices(bent.vertices * 2), "sphere")
    assert np.allclose(np.linalg.norm(t.vertices, axis=1), 1.0)
    with pytest.raises(ValueError, match="not convex"):
        theta_for(cube, bent, "target")


def test_theta_from_file_must_be_convex(tmp_path):
    from test_volume_surface import write_obj

    v, f = box(2)
    bent = surface_from_arrays(bend(v, 1.0), f, "bent.obj")
    other = surface_from_arrays(bend(v, -0.8, towards=1), f, "other.obj")
    good = write_obj(tmp_path / "theta.obj", 3 * v, f)
    assert theta_for(bent, other, good).convex
    bad = write_obj(tmp_path / "bad.obj", bend(v, 0.5), f)
    with pytest.raises(ValueError, match="bad.obj: Theta must be convex"):
        theta_for(bent, other, bad)


def test_tutte_spherical_parameterization_is_bijective():
    v, f = box(4)
    cage = surface_from_arrays(bend(twist(v, 0.1), 1.5), f, "bent.obj")
    for outer in range(3):
        x = _stereographic_tutte(cage.triangles, cage.n_vertices, outer)
        if x is not None:
            break
    assert x is not None and _bijective(x, cage.triangles)
    assert _bijective(_relax(x, cage.triangles), cage.triangles)
    y = sphere_embedding((cage,))
    assert _bijective(y, cage.triangles)


def test_a_cage_touching_itself_where_the_checks_cannot_tell_is_refused_not_a_crash(tmp_path, monkeypatch):
    # A top vertex of a box pushed straight down through the bottom face, exactly through one of its
    # vertices or edges: the surface checks' floating-point tests see no strict crossing, and TetGen
    # aborted the process (SIGABRT) leaving tetgen-tmpfile_* in the working directory. Every case is
    # now an error, from the checks or from TetGen's child, and nothing is left behind.
    from warpcli.errors import WarpError

    monkeypatch.chdir(tmp_path)
    v, f = box(3, (4.0, 4.0, 4.0), (28.0, 28.0, 28.0))
    top = [k for k in range(len(v)) if v[k, 2] == 28.0 and 4.0 < v[k, 0] < 28.0 and 4.0 < v[k, 1] < 28.0]
    refused = 0
    for k in top[:2]:
        for x, y in ((12.0, 12.0), (12.0, 16.0), (16.0, 12.0), (20.0, 16.0)):
            u = v.copy()
            u[k] = [x, y, 2.0]
            try:
                mesh_polyhedron(surface_from_arrays(u, f, "pushed"), 4.0)
            except WarpError as err:
                assert "pushed" in str(err) and "\n" not in str(err)
                refused += 1
    assert refused == 2 * 4
    assert list(tmp_path.iterdir()) == []
