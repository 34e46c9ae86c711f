"""The smooth maps' certificate (`warpcli.maps.certificate`) against an independent dense check on nasty polygons."""

from __future__ import annotations

import numpy as np
import pytest
from nasty import SHAPES, c_shape, dense_check, dense_samples, ring_gap

from warpcli import MapOptions, Polygon, build_map, warp_image
from warpcli.errors import FoldOverError
from warpcli.maps.certificate import cover
from warpcli.maps.meshless import BEM, MFS
from warpcli.maps.theta import regular
from warpcli.report import build_report, unknown_pixels

METHODS = {"bem": BEM, "mfs": MFS}


def _check(phi) -> dict:
    v = phi.polygon.points
    return dense_check(phi, dense_samples(v, grid=60_000, along=0.25, corner_rings=16))


@pytest.mark.parametrize("method", ["bem", "mfs"])
@pytest.mark.parametrize("low", [False, True], ids=["default", "low-nodes"])
@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_every_accepted_map_has_det_j_positive_at_dense_samples(shape, low, method):
    """Accepted (certificate ok) means no fold and no deep excursion out of Theta at ~10x more points."""
    v = SHAPES[shape](np.random.default_rng(11))
    poly = Polygon(v, name=shape)
    nodes = max(64, len(v) + 8) if low else None
    phi = METHODS[method].build(poly, regular(poly, poly), MapOptions(method=method, nodes=nodes, check=False))
    cert = phi.certify()
    if not cert.ok:
        return  # refused (or refitted by the build): nothing was promised
    d = _check(phi)
    assert d["folds"] == 0, (shape, method, nodes, d)
    assert d["deep"] == 0, (shape, method, nodes, d)


def test_ring_with_a_gap_onto_a_c_is_refused_with_few_nodes():
    """The issue's visible fold (BEM, 64 nodes: phi leaves Theta 1 px inside the arm ends)."""
    rg = ring_gap(np.random.default_rng(7), thick=40, k=16)
    c = c_shape(16, 16)
    src, dst = Polygon(rg, name="ring"), Polygon(c, name="C")
    for a, b in ((src, dst), (dst, src)):
        try:
            f = build_map(a, b, MapOptions(method="bem", nodes=64))
        except FoldOverError as err:
            assert "fold" in str(err)
            continue
        for phi in (f.phi0, f.phi1):  # accepted: then it must be clean
            d = _check(phi)
            assert d["folds"] == 0 and d["deep"] == 0, d


def test_cover_reaches_the_boundary_and_every_corner():
    """The starting cells come within the band floor of every edge and into every corner's wedge."""
    v = SHAPES["comb"](np.random.default_rng(3))
    c = cover(v, 1e-9 * 300)
    from warpcli.boundary import nearest_edge
    from warpcli.grid import inside_polygon

    assert inside_polygon(c.centres, v).all()
    edge, _, dist = nearest_edge(c.centres, v)
    assert dist.min() <= 0.0101
    assert set(np.unique(edge[dist < 0.02])) == set(range(len(v)))
    for p in v:  # samples within 0.02 of each vertex
        assert np.hypot(*(c.centres - p).T).min() < 0.02


def test_report_counts_pixels_without_a_jacobian():
    """A NaN Jacobian inside the target is counted as flipped, not skipped; pixels outside are not."""
    src = [[10.0, 10.0], [90.0, 12.0], [85.0, 88.0], [12.0, 80.0]]
    res = warp_image(np.zeros((100, 100), np.float32), src, src, size=(100, 100))
    assert unknown_pixels(res) == 0
    base = build_report(res)["flipped_triangles"]
    r0, c0 = res.pull.origin
    res.pull.jacobian[50 - r0, 50 - c0] = np.nan  # inside
    res.pull.points[40 - r0, 30 - c0] = np.nan  # inside
    res.pull.jacobian[1 - r0 if r0 <= 1 else 0, 0] = np.nan  # the window's corner: outside the target
    assert unknown_pixels(res) == 2
    assert build_report(res)["flipped_triangles"] == base + 2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mild_shapes_are_accepted_and_clean(seed):
    """Not every polygon is refused: star-shaped ones with reflex corners pass with BEM, and are clean."""
    v = SHAPES["star_like"](np.random.default_rng(seed))
    poly = Polygon(v, name="star")
    phi = BEM.build(poly, regular(poly, poly), MapOptions(method="bem", check=False))
    assert phi.certify().ok
    d = _check(phi)
    assert d["folds"] == 0 and d["deep"] == 0, d
