"""Untangling the discrete maps (warpcli.volume.untangle): stars put right by hand, and twisted cages that fold."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli.volume import build_map
from warpcli.volume.compose import TetMap
from warpcli.volume.examples import bend, box, twist
from warpcli.volume.surface import surface_from_arrays
from warpcli.volume.tetmesh import tet_volumes
from warpcli.volume.untangle import inverted, untangle


def octahedron_star():
    """Node 0 at the centre of a regular octahedron, eight positively oriented tetrahedra around it."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    tets = []
    for x in (1, 2):
        for y in (3, 4):
            for z in (5, 6):
                t = [0, x, y, z]
                if tet_volumes(v, np.array([t]))[0] < 0:
                    t = [0, x, z, y]
                tets.append(t)
    return v, np.array(tets, dtype=np.int64)


@pytest.mark.parametrize("where", [[1.6, 0.2, 0.1], [0.0, 0.0, 2.5], [-0.3, -1.2, 0.9]])
def test_a_node_outside_its_kernel_goes_back_in(where):
    v, tets = octahedron_star()
    fixed = np.arange(len(v)) > 0
    tangled = v.copy()
    tangled[0] = where
    assert inverted(tangled, tets).sum() > 0
    done = untangle(tangled, tets, fixed)
    assert done.inverted_before > 0 and done.inverted_after == 0
    assert tet_volumes(done.values, tets).min() > 0
    assert np.array_equal(done.values[1:], v[1:])  # the boundary does not move
    assert done.moved.tolist() == [0]
    # Nearest point of the kernel with a margin: inside the octahedron |x| + |y| + |z| < 1.
    assert np.abs(done.values[0]).sum() < 1
    again = untangle(tangled, tets, fixed)
    assert np.array_equal(again.values, done.values)


def test_a_map_with_nothing_inverted_is_left_alone():
    v, tets = octahedron_star()
    fixed = np.arange(len(v)) > 0
    y = v.copy()
    y[0] = [0.2, -0.1, 0.3]
    done = untangle(y, tets, fixed)
    assert done.inverted_before == done.inverted_after == 0 and len(done.moved) == 0 and done.programs == 0
    assert np.array_equal(done.values, y)


def test_every_tangled_star_is_put_right():
    # Two octahedral stars side by side, each centre pushed out through the other's side.
    v, tets = octahedron_star()
    w = v.copy()
    w[:, 0] += 2.0
    nodes = np.concatenate([v, w])
    second = tets + len(v)
    all_tets = np.concatenate([tets, second])
    fixed = np.ones(len(nodes), dtype=bool)
    fixed[[0, len(v)]] = False
    y = nodes.copy()
    y[0] = [3.0, 0.2, 0.0]
    y[len(v)] = [-1.5, 0.0, 0.3]
    done = untangle(y, all_tets, fixed)
    assert done.inverted_after == 0 and tet_volumes(done.values, all_tets).min() > 0
    assert done.moved.tolist() == [0, len(v)]


def test_flat_and_inverted_images_count_whatever_pins_them():
    # Four boundary nodes on one plane (a flat image, or flat but for rounding), a free node
    # lifting its own tetrahedron: the flat one sends a sliver onto a triangle, a map that is not
    # one-to-one, and counts as inverted however its nodes are pinned.
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1e-17], [0.3, 0.3, 1.0]])
    tets = np.array([[0, 1, 2, 3], [0, 1, 2, 4]])
    fixed = np.array([True, True, True, True, False])
    for z in (0.0, -1e-17, 1e-300):
        y = v.copy()
        y[3, 2] = z
        assert inverted(y, tets).tolist() == [z <= 0, False]
    y = v.copy()
    y[3, 2] = -0.1  # a real inversion of boundary nodes alone: nothing to move, still counted
    done = untangle(y, tets, fixed)
    assert done.inverted_before == done.inverted_after == 1 and len(done.moved) == 0


def twisted_pair(turns, angle):
    v, f = box(3)
    return surface_from_arrays(v, f, "cube.obj"), surface_from_arrays(bend(twist(v, turns), angle), f, "bent.obj")


@pytest.mark.parametrize(("turns", "angle"), [(0.25, 0.9), (0.2, 1.2)])
def test_twisted_bent_cages_fold_and_are_untangled(turns, angle):
    src, dst = twisted_pair(turns, angle)
    plain = build_map(src, dst, edge=0.1, untangle=False)
    vmap = build_map(src, dst, edge=0.1)
    assert isinstance(vmap.phi1, TetMap)
    # The same mesh: repairs (edges split where untangling alone could not mend) only add nodes.
    n = plain.phi1.mesh.n_vertices
    assert np.array_equal(vmap.phi1.mesh.vertices[:n], plain.phi1.mesh.vertices)
    info = vmap.phi1.info["untangle"]
    harmonic_flips = plain.phi1.certify().flipped
    assert harmonic_flips > 0 and vmap.phi1.certify().flipped == info["inverted_after"] == 0
    if info["repaired_edges"] == 0:
        assert info["inverted_before"] == harmonic_flips
        assert np.array_equal(vmap.phi1.mesh.tets, plain.phi1.mesh.tets)
    # Only nodes of the neighbourhood moved, by a fraction of a tetrahedron; away from them the
    # map is the discrete harmonic map of its mesh.
    moved = vmap.phi1.moved()
    assert 0 < len(moved) < 50
    harmonic = vmap.phi1.harmonic
    assert np.abs(vmap.phi1.values[moved] - harmonic[moved]).max() < 0.1
    assert np.array_equal(np.delete(vmap.phi1.values, moved, axis=0), np.delete(harmonic, moved, axis=0))
    assert 0 < vmap.untangling_displacement() < 0.1
    rng = np.random.default_rng(4)
    p = dst.vertices.mean(axis=0) + 0.2 * (rng.random((400, 3)) - 0.5)
    assert np.nanmax(np.abs(vmap.inverse(p) - plain.inverse(p))) < 0.1
