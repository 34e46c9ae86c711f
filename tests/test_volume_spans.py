"""No interior point onto Theta's boundary (warpcli.volume.spans): generated bent and twisted boxes, and the splits' meshes."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli.polygon.predicates import orient3d_sign
from warpcli.volume import build_map
from warpcli.volume.compose import TetMap
from warpcli.volume.examples import bend, box, twist
from warpcli.volume.spans import face_planes, flat_spans, node_planes, split_simplices
from warpcli.volume.surface import surface_from_arrays
from warpcli.volume.tetmesh import boundary_faces, mesh_polyhedron, tet_volumes

pytest.importorskip("tetgen")


def bent_pairs(count: int, seed: int):
    """Boxes (a unit cube of n x n quadrilaterals a side) onto the same box twisted and bent by seeded amounts."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        n = int(rng.integers(2, 4))
        turns, angle = float(rng.uniform(0.0, 0.22)), float(rng.uniform(0.3, 1.1))
        v, f = box(n)
        try:
            dst = surface_from_arrays(bend(twist(v, turns), angle), f, f"bent n={n} t={turns:.3f} a={angle:.3f}")
        except ValueError:  # the bend made the surface cross itself: not a cage
            continue
        out.append((surface_from_arrays(v, f, "cube"), dst))
    return out


PAIRS = bent_pairs(12, 11)


def inside_theta(points, theta_vertices):
    """Signed distance of points inside the unit cube (Theta here) to its boundary: positive inside."""
    lo, hi = theta_vertices.min(axis=0), theta_vertices.max(axis=0)
    return np.minimum(points - lo, hi - points).min(axis=1)


@pytest.mark.parametrize("pair", PAIRS, ids=[p[1].name for p in PAIRS])
def test_interior_points_go_strictly_inside_theta(pair):
    # A homeomorphism takes interior to interior. Each tetrahedron's centroid is an interior
    # point of the solid: the map must put it inside Theta, not on a face of the cube. Before the
    # flat spans were split, the tetrahedra whose four boundary nodes went onto one face of the
    # cube sent their centroids onto it (and the certificate let them pass as "flattened").
    src, dst = pair
    vmap = build_map(src, dst, edge=0.12)
    phi = vmap.phi1
    assert isinstance(phi, TetMap) and phi.theta.cage == 0  # the source cube is Theta
    assert vmap.certificates()[1].flipped == 0
    centroids = phi.values[phi.mesh.tets].mean(axis=1)
    size = np.ptp(phi.theta.vertices, axis=0).max()
    assert inside_theta(centroids, phi.theta.vertices).min() > 1e-9 * size
    # Every image tetrahedron keeps its orientation, by the float volume too (an independent test).
    assert tet_volumes(phi.values, phi.mesh.tets).min() > 0
    # And the map is one-to-one where it is sampled: round trips through both directions.
    rng = np.random.default_rng(3)
    lo, hi = dst.vertices.min(axis=0), dst.vertices.max(axis=0)
    p = lo + (hi - lo) * rng.random((4000, 3))
    pre = vmap.inverse(p)
    ok = np.isfinite(pre[:, 0])
    assert ok.sum() > 500
    assert np.abs(vmap.forward(pre[ok]) - p[ok]).max() < 1e-9


@pytest.mark.parametrize("pair", PAIRS[:3], ids=[p[1].name for p in PAIRS[:3]])
def test_no_flat_span_is_left_and_tetgens_meshes_have_them(pair):
    src, dst = pair
    theta = src.vertices
    mesh = mesh_polyhedron(dst, 0.12)
    nodes, planes = node_planes(mesh, theta, dst.triangles)
    edges, faces = flat_spans(mesh, nodes, planes)
    # The bend puts boundary nodes of two sides of the box on one face of the cube: TetGen joins
    # some of them through the solid (what this module exists for), at least on most pairs.
    vmap = build_map(src, dst, edge=0.12)
    fixed_mesh = vmap.phi1.mesh
    after = flat_spans(fixed_mesh, *node_planes(fixed_mesh, theta, dst.triangles))
    assert len(after[0]) == 0 and len(after[1]) == 0
    assert vmap.phi1.info["split_edges"] == len(edges)
    # Each split edge's two nodes do share a face of the cube, and the edge crosses the solid.
    y = mesh.boundary_values(theta, dst.triangles)
    at = np.full(mesh.n_vertices, -1)
    at[mesh.boundary] = np.arange(len(mesh.boundary))
    for a, b in edges[:50]:
        ya, yb = y[at[a]], y[at[b]]
        assert ((np.abs(ya - yb) < 1e-12) & ((np.abs(ya) < 1e-12) | (np.abs(ya - 1) < 1e-12))).any()


def test_face_planes_are_the_cubes_six_sides():
    v, f = box(3)
    cube = surface_from_arrays(v, f, "cube")
    groups = face_planes(cube.vertices, cube.triangles)
    assert len(np.unique(groups)) == 6
    centre = cube.vertices[cube.triangles].mean(axis=1)
    for g in np.unique(groups):
        c = centre[groups == g]
        assert (np.ptp(c, axis=0) < 1e-12).sum() == 1  # one coordinate constant on each side
    # A sphere-like polyhedron: no two triangles coplanar.
    from warpcli.volume.examples import icosphere

    s, t = icosphere(1)
    assert len(np.unique(face_planes(s, t))) == len(t)


@pytest.mark.parametrize("seed", range(4))
def test_splitting_keeps_the_mesh_a_conforming_positive_mesh_of_the_solid(seed):
    # Random interior edges and faces (of any nodes, not only flat spans), split in sequence,
    # some sharing tetrahedra: the result must still be a mesh of the same solid.
    rng = np.random.default_rng(seed)
    v, f = box(2)
    mesh = mesh_polyhedron(surface_from_arrays(bend(v, 0.6), f, "bent"), 0.3)
    tets = mesh.tets
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]])
    key, counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    interior_faces = key[counts == 2]
    edges = np.unique(np.sort(np.concatenate([tets[:, [i, j]] for i, j in ((0, 1), (0, 2), (1, 3), (2, 3))]), axis=1), axis=0)
    skin = boundary_faces(tets)
    skin_edges = {tuple(sorted(e)) for t in skin.tolist() for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    edges = np.array([e for e in edges.tolist() if tuple(e) not in skin_edges])
    picks = [edges[i] for i in rng.choice(len(edges), 12, replace=False)]
    picks += [interior_faces[i] for i in rng.choice(len(interior_faces), 8, replace=False)]
    order = rng.permutation(len(picks))
    out = split_simplices(mesh, [picks[i] for i in order])
    assert out.n_vertices == mesh.n_vertices + len(picks)
    sign = orient3d_sign(*(out.vertices[out.tets[:, k]] for k in range(4)))
    assert (sign > 0).all()
    assert abs(tet_volumes(out.vertices, out.tets).sum() - tet_volumes(mesh.vertices, mesh.tets).sum()) < 1e-12
    f2 = np.concatenate([out.tets[:, [1, 2, 3]], out.tets[:, [0, 2, 3]], out.tets[:, [0, 1, 3]], out.tets[:, [0, 1, 2]]])
    _, c2 = np.unique(np.sort(f2, axis=1), axis=0, return_counts=True)
    assert c2.max() == 2  # every face shared by at most two tetrahedra
    # The surface is the same triangles: only interior simplices were split.
    before = {tuple(sorted(x)) for x in boundary_faces(mesh.tets).tolist()}
    assert before == {tuple(sorted(x)) for x in boundary_faces(out.tets).tolist()}
    # Each new node is the barycentre of its simplex.
    for k, i in enumerate(order):
        assert np.allclose(out.vertices[mesh.n_vertices + k], mesh.vertices[picks[i]].mean(axis=0), rtol=0, atol=1e-15)


@pytest.mark.parametrize(("n", "k"), [(7, 2), (50, 3), (3_000_000, 3), (2**40, 2)])
def test_unique_rows_is_numpys_unique(n, k):
    from warpcli.volume.spans import _unique_rows

    rng = np.random.default_rng(n % 97)
    rows = rng.integers(0, n, (500, k), dtype=np.int64)
    rows = np.concatenate([rows, rows[:100]])  # repeats
    want, counts = np.unique(rows, axis=0, return_counts=True)
    got, got_counts = _unique_rows(rows, n, counts=True)
    assert np.array_equal(got, want) and np.array_equal(got_counts, counts)
    assert np.array_equal(_unique_rows(rows, n), want)
    assert _unique_rows(rows[:0], n).shape == (0, k)


def test_a_split_whose_rounded_midpoint_would_flatten_a_sliver_is_left_out():
    # A thin bent plate died with numpy's 'Singular matrix' in the FEM assembly: the midpoint of an
    # edge of a sliver, rounded, left a piece flat. Such a split is now left out, and said so.
    from warpcli.polygon.predicates import orient3d_sign
    from warpcli.volume.tetmesh import TetMesh

    rng = np.random.default_rng(0)
    kept = skipped = 0
    for _ in range(400):
        a, b, c = rng.random((3, 3))
        u, v = rng.random(2)
        d = a + u * (b - a) + v * (c - a) + np.cross(b - a, c - a) * rng.choice([1e-16, 3e-17, 1e-15, 1e-3])
        p = np.array([a, b, c, d])
        if orient3d_sign(*(p[[k]] for k in range(4)))[0] < 0:
            p = p[[0, 2, 1, 3]]
        if not orient3d_sign(*(p[[k]] for k in range(4)))[0] > 0:
            continue
        mesh = TetMesh(p, np.array([[0, 1, 2, 3]]), np.arange(4), np.zeros(4, dtype=np.int64), np.eye(3)[[0, 1, 2, 0]])
        applied: list[bool] = []
        out = split_simplices(mesh, [np.array([0, 3]), np.array([1, 2])], applied)
        sign = orient3d_sign(*(out.vertices[out.tets[:, k]] for k in range(4)))
        assert (sign > 0).all() and out.n_vertices == 4 + sum(applied) and out.n_tets == 1 + 1 * applied[0] + (1 + applied[0]) * applied[1]
        kept += sum(applied)
        skipped += len(applied) - sum(applied)
    assert kept > 100 and skipped > 5, (kept, skipped)


def test_a_tetrahedron_of_boundary_nodes_flat_up_to_rounding_counts_as_folded():
    # Four images coplanar in exact arithmetic, rounded off their plane (as barycentric combinations
    # of Theta's vertices are) so that the exact sign says positive: the certificate took it.
    from warpcli.volume.spans import pinned_flat_or_inverted
    from warpcli.volume.tetmesh import TetMesh
    from warpcli.volume.untangle import inverted

    p = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 1.0]])
    mesh = TetMesh(p, np.array([[0, 1, 2, 3]]), np.arange(4), np.zeros(4, dtype=np.int64), np.eye(3)[[0, 1, 2, 0]])
    for z in (1e-17, 0.0, -1e-17, 1e-300):
        images = np.array([[26.0, 28, 6], [26, 26, 4], [28, 24, 4], [28, 26, 6]])
        images[3, 2] += z
        assert pinned_flat_or_inverted(mesh, images).tolist() == [True], z
    assert not inverted(np.array([[26.0, 28, 6], [26, 26, 4], [28, 24, 4], [28, 26, 6 + 1e-15]]), mesh.tets).any()
    assert pinned_flat_or_inverted(mesh, p).tolist() == [False]  # a real tetrahedron is not
    # With a free node it is the solve's to lift, and the exact sign decides.
    free = TetMesh(p, mesh.tets, np.arange(3), np.zeros(3, dtype=np.int64), np.eye(3))
    assert pinned_flat_or_inverted(free, np.array([[26.0, 28, 6], [26, 26, 4], [28, 24, 4], [28, 26, 6]])).tolist() == [False]


def test_graded_meshing_falls_back_to_the_cages_own_mesh_when_tetgen_fails(monkeypatch):
    from warpcli.volume import tetmesh

    v, f = box(3, (4.0, 4.0, 4.0), (28.0, 28.0, 28.0))
    cage = surface_from_arrays((bend(twist(v, 0.2), 0.5) - 16) * 20 + 16, f, "big")
    region = (np.zeros(3), np.full(3, 32.0))
    real = tetmesh._tetgen

    def failing(v, tri, max_volume, name, inner=None):
        if inner is not None:
            raise tetmesh.MeshingError(f"{name}: TetGen failed (as it did on 12 of 864 graded cages)")
        return real(v, tri, max_volume, name, inner)

    monkeypatch.setattr(tetmesh, "_tetgen", failing)
    mesh = tetmesh.mesh_polyhedron(cage, 40.0, region=region)
    assert mesh.n_tets > 1000
    for edge in (1e-300, 1e300):
        with pytest.raises(tetmesh.InputError, match="out of all proportion"):
            tetmesh.mesh_polyhedron(cage, edge)
