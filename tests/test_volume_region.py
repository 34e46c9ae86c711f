"""Cages far larger than the volume: meshes graded from the volume's box, so the work follows the volume, not the cage."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli.volume import build_map
from warpcli.volume.examples import bend, box, twist
from warpcli.volume.surface import surface_from_arrays
from warpcli.volume.tetmesh import REGION_REACH, auto_edge, graded_from, mesh_polyhedron
from warpcli.volume.volio import tiff_grid

pytest.importorskip("tetgen")

GRID = tiff_grid((32, 32, 32))
REGION = GRID.bounds()


def scaled_pair(scale: float, offset: float = 0.0):
    """The docs' sample pair (a box from 4 to 28 onto it twisted and bent), scaled about the volume's centre."""
    v, f = box(3, (4.0, 4.0, 4.0), (28.0, 28.0, 28.0))
    c = 16.0
    src = surface_from_arrays((v - c) * scale + c + offset, f, f"cube x{scale:g}")
    dst = surface_from_arrays((bend(twist(v, 0.2), 0.5) - c) * scale + c + offset, f, f"bent x{scale:g}")
    return src, dst


def test_the_grid_bounds_are_the_voxels_box():
    lo, hi = REGION
    assert np.array_equal(lo, [0, 0, 0]) and np.array_equal(hi, [32, 32, 32])  # TIFF: voxel i spans [i, i + 1]


@pytest.mark.parametrize(("scale", "graded"), [(1.0, False), (2.0, False), (3.0, True), (50.0, True)])
def test_graded_from_needs_a_reach_beyond_the_region(scale, graded):
    src, _ = scaled_pair(scale)
    assert graded_from(src, REGION) is graded
    assert graded_from(src, None) is False
    # Reaching out on one side alone is enough.
    lo, hi = REGION
    v = src.vertices.copy()
    reach = REGION_REACH * 32
    assert graded_from(src.with_vertices(v + [hi[0] + reach + 1 - v[:, 0].max(), 0, 0]), REGION)


def test_the_default_edge_follows_the_region_not_the_cage():
    small, _ = scaled_pair(1.0)
    for scale in (5.0, 50.0, 5000.0):
        src, _ = scaled_pair(scale)
        assert auto_edge(src, 1.0, REGION) == pytest.approx(0.6 * np.sqrt(32.0))
        assert auto_edge(src, 1.0) > auto_edge(src, 1.0, REGION)
    assert auto_edge(small, 1.0, REGION) == auto_edge(small, 1.0)


def test_mesh_size_grows_with_the_log_of_the_cage_not_its_volume():
    # A uniform mesh of the cage 20x the volume took 456k tetrahedra and 14 s; 100x would pass the
    # 6M limit. Graded from the volume's box, 20x to 10,000x stay within a few times 1x's count.
    counts = {}
    for scale in (20.0, 10_000.0):
        _, dst = scaled_pair(scale)
        mesh = mesh_polyhedron(dst, auto_edge(dst, 1.0, REGION), region=REGION)
        counts[scale] = mesh.n_tets
    assert counts[10_000.0] < 1.3 * counts[20.0] < 200_000


def test_the_volume_is_meshed_at_the_nominal_edge():
    _, dst = scaled_pair(20.0)
    edge = auto_edge(dst, 1.0, REGION)
    mesh = mesh_polyhedron(dst, edge, region=REGION)
    lo, hi = REGION
    centre = mesh.vertices[mesh.tets].mean(axis=1)
    inside = ((centre > lo) & (centre < hi)).all(axis=1)
    e = np.linalg.norm(mesh.vertices[mesh.tets[:, 0]] - mesh.vertices[mesh.tets[:, 1]], axis=1)
    assert inside.sum() > 1000
    assert 0.6 * edge < np.median(e[inside]) < 1.4 * edge
    assert np.median(e[~inside]) > 2 * edge  # and coarser away from it


@pytest.mark.parametrize("scale", [3.0, 8.0])
def test_graded_maps_agree_with_uniform_ones_in_the_volume(scale):
    # Where a uniform mesh of the whole cage is still affordable, the graded map is as good a
    # harmonic map in the volume: they agree to a tenth of a voxel on average (the uniform one is
    # no reference either: bench/volume_region.py measures both against a finer graded mesh).
    src, dst = scaled_pair(scale)
    graded = build_map(src, dst, region=REGION)
    uniform = build_map(src, dst)
    assert graded.phi1.describe()["graded_from_region"] and not uniform.phi1.describe()["graded_from_region"]
    assert [c.flipped for c in graded.certificates()] == [0, 0]
    rng = np.random.default_rng(5)
    p = 0.5 + 31 * rng.random((3000, 3))
    a, b = graded.inverse(p), uniform.inverse(p)
    ok = np.isfinite(a[:, 0]) & np.isfinite(b[:, 0])
    assert ok.sum() > 2000
    d = np.linalg.norm(a[ok] - b[ok], axis=1)
    assert d.mean() < 0.1 and d.max() < 0.5


def test_a_cage_far_from_the_volume_costs_almost_nothing():
    # Cages 20x the volume, 10 km away: no voxel is inside, and the map is a coarse one.
    src, dst = scaled_pair(20.0, offset=1e4)
    vmap = build_map(src, dst, region=REGION)
    assert vmap.phi1.mesh.n_tets < 2000 and [c.flipped for c in vmap.certificates()] == [0, 0]


def test_warp_volume_grades_from_its_volume(tmp_path):
    # The command passes the volume's box: a cage 20x the volume is meshed graded from it.
    tifffile = pytest.importorskip("tifffile")
    import json

    from helpers import run_cli
    from test_volume_surface import write_obj

    data = np.random.default_rng(8).integers(0, 255, (32, 32, 32), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    src, dst = scaled_pair(20.0)
    write_obj(tmp_path / "a.obj", src.vertices, src.triangles)
    write_obj(tmp_path / "b.obj", dst.vertices, dst.triangles)
    code, err = run_cli(["volume", tmp_path / "in.tif", tmp_path / "out.tif", "--src", tmp_path / "a.obj", "--dst", tmp_path / "b.obj", "--report", tmp_path / "r.json"])
    assert code == 0, err
    target = json.loads((tmp_path / "r.json").read_text())["maps"]["target"]
    assert target["graded_from_region"] and target["tetrahedra"] < 150_000
