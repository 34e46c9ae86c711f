"""The smooth maps' certificate (`warpcli.maps.certificate`) against an independent dense check on nasty polygons.

The default run checks every generated class at few nodes (cheap fits) and
a few at the default m, with a dense check about twice the certificate's
density near edges and corners; WARPCLI_HEAVY=1 adds the default m on every
class and the full density (``FULL``), about 4 CPU minutes.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from helpers import regular, star
from nasty import SHAPES, c_shape, dense_check, dense_samples, ring_gap

from warpcli import MapOptions, Polygon, build_map, warp_image
from warpcli.errors import FoldOverError
from warpcli.maps.certificate import BAND, BAND_RELATIVE, cover, degenerate_vertices
from warpcli.maps.meshless import BEM, MFS
from warpcli.maps.theta import regular as regular_theta
from warpcli.report import build_report, unknown_pixels

METHODS = {"bem": BEM, "mfs": MFS}
HEAVY = os.environ.get("WARPCLI_HEAVY") == "1"
#: The dense check's density: (grid points, px between band samples along an edge, radii around a vertex).
FULL = (60_000, 0.25, 16)
LIGHT = (20_000, 0.5, 8)
DART = np.array([[10, 10], [120, 20], [60, 50], [20, 110]], dtype=float)
SQUARE = np.array([[8.0, 8.0], [120.0, 8.0], [120.0, 120.0], [8.0, 120.0]])


def _samples(v: np.ndarray) -> np.ndarray:
    grid, along, rings = FULL if HEAVY else LIGHT
    return dense_samples(v, grid=grid, along=along, corner_rings=rings)


def _outside_balls(phi, p: np.ndarray) -> np.ndarray:
    """The points outside the balls the certificate left out (where it promises nothing)."""
    keep = np.ones(len(p), dtype=bool)
    if phi.boundary_certificate is not None:  # proved from one curve: no ball left out
        return p
    for i, r in phi.cell_certificate.excluded:
        keep &= np.hypot(*(p - phi.polygon.points[i]).T) > r
    return p[keep]


def _check(phi) -> dict:
    return dense_check(phi, _outside_balls(phi, _samples(phi.polygon.points)))


def _build(shape: str, method: str, nodes: int | None, boundary: str = "linear", seed: int = 11):
    v = SHAPES[shape](np.random.default_rng(seed))
    poly = Polygon(v, name=shape)
    opts = MapOptions(method=method, nodes=nodes, check=False, src_boundary=boundary)
    return METHODS[method].build(poly, regular_theta(poly, poly, opts), opts)


# The default m refits (and fits many-gons) slowly, the wavy many-gon has ~10x the corners:
# heavy, except where it is cheap and accepted (BEM on spikes at the default m).
def _light(shape: str, low: bool) -> bool:
    return shape != "wavy" and (low or shape in ("spikes", "star_like"))


CASES = [
    pytest.param(shape, low, method, marks=() if _light(shape, low) else pytest.mark.heavy)
    for shape in sorted(SHAPES)
    for low in (False, True)
    for method in ("bem", "mfs")
]


@pytest.mark.parametrize("shape, low, method", CASES)
def test_every_accepted_map_has_det_j_positive_at_dense_samples(shape, low, method):
    """Accepted (certificate ok) means no fold and no deep excursion out of Theta at denser points."""
    v = SHAPES[shape](np.random.default_rng(11))
    nodes = max(64, len(v) + 8) if low else None
    phi = _build(shape, method, nodes)
    if not phi.certify().ok:
        return  # refused (or refitted by the build): nothing was promised
    assert phi.boundary_certificate is not None  # linear Dirichlet data: no vertex is degenerate
    d = _check(phi)
    assert d["folds"] == 0, (shape, method, nodes, d)
    assert d["deep"] == 0, (shape, method, nodes, d)


@pytest.mark.parametrize("shape", ["spikes", "zigzag", "star_like", "slot"])
@pytest.mark.parametrize("method", ["bem", "mfs"])
def test_quadratic_boundaries_accepted_maps_are_clean_everywhere(shape, method):
    """t^2 boundary data: every vertex is degenerate (det J -> 0 there); what is accepted is proved with the
    collar's band round them, no ball left out, and folds nowhere at dense samples of the map as accepted."""
    v = SHAPES[shape](np.random.default_rng(5))
    phi = _build(shape, method, max(64, len(v) + 8), "quadratic", seed=5)
    assert phi._degenerate.all()
    if not phi.certify().ok:
        return
    assert phi.boundary_certificate.band and phi.collar is not None
    d = _check(phi)
    assert d["folds"] == 0 and d["deep"] == 0, (shape, method, d)


@pytest.mark.parametrize(
    "src, dst, opts, which",
    [
        (DART, SQUARE, MapOptions(method="mfs", conditions="mixed"), 0),  # r^4.5 at the tip
        (DART, SQUARE, MapOptions(method="bem", conditions="mixed"), 0),
    ],
    ids=["mixed-dart-mfs", "mixed-dart-bem"],
)
def test_mixed_conditions_are_proved_whole_where_the_cells_left_balls_out(src, dst, opts, which):
    """The cases the cell certificate accepted with a ball left out round the dart's tip (and cells on their
    samples): proved now on the whole polygon, the tip in the collar's band; clean at dense samples."""
    f = build_map(Polygon(src), Polygon(dst), opts)  # raises FoldOverError if refused
    phi = (f.phi0, f.phi1)[which]
    assert phi.cell_certificate.excluded, "the case has a degenerate vertex with a fold of the closed form"
    assert phi.boundary_certificate.ok and phi.boundary_certificate.band
    d = _check(phi)
    assert d["folds"] == 0 and d["deep"] == 0, d


def test_t2_data_on_a_12_gon_are_proved_with_the_band_round_their_vertices():
    """The case the cells accepted with balls left out round its 12 degenerate vertices: now proved whole."""
    f = build_map(Polygon(star()), Polygon(regular(12, r=55.0, phase=0.2)), MapOptions(method="bem", dst_boundary="quadratic"))
    phi = f.phi1
    assert phi._degenerate.all() and phi.boundary_certificate.ok and phi.boundary_certificate.band
    d = _check(phi)
    assert d["folds"] == 0 and d["deep"] == 0, d


def test_folds_of_the_closed_form_next_to_degenerate_vertices_lie_in_the_proved_band():
    """MFS at m = 256 with t^2 data on a regular 12-gon folds up to 0.8 px from its vertices (det J <= 0 at dense
    points there, a 108 px polygon; the cells refused it): every such point lies in the band the certificate
    proved with the collar, and the map as accepted has det J > 0 at all the dense points."""
    from warpcli.boundary import nearest_edge

    poly = Polygon(regular(12, r=55.0, phase=0.2), name="12-gon")
    v = poly.points
    size = float(np.ptp(v, axis=0).max())
    opts = MapOptions(method="mfs", nodes=256, check=False, src_boundary="quadratic")
    phi = MFS.build(poly, regular_theta(poly, poly, opts), opts)
    p = dense_samples(v, grid=2_000, along=0.5, corner_rings=24)
    p = p[nearest_edge(p, v)[2] > 1e-9 * size]
    j = phi.solution.jacobian(p)
    det = phi.theta.orientation * np.sign(poly.signed_area) * (j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0])
    folds = p[~(det > 0)]
    from_vertex = np.hypot(*(folds[:, None] - v[None]).transpose(2, 0, 1)).min(axis=1)
    assert folds.size and from_vertex.max() > min(BAND, BAND_RELATIVE * size), from_vertex
    assert phi.certify().ok and phi.boundary_certificate.band
    assert not phi.collar.inside(folds).any()  # all in the band
    d = dense_check(phi, p)
    assert d["folds"] == 0 and d["deep"] == 0, d
    build_map(poly, Polygon(star()), MapOptions(method="mfs", nodes=256, src_boundary="quadratic"))  # accepted


def _theta_map(points):
    """A boundary map onto the unit square's corners per edge (a stand-in for a map's data)."""
    w = np.asarray(points, dtype=float)
    n = len(w)

    def to(edge, t, power):
        edge, t = np.asarray(edge), np.asarray(t, dtype=float)
        s = t ** power[edge]
        return w[edge] + s[:, None] * (w[(edge + 1) % n] - w[edge])

    return to


def test_degenerate_vertices_from_the_boundary_data():
    """Exactly the vertices where a one-sided slope of the data vanishes, or mixed conditions meet off a right angle."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    poly = np.array([[0.0, 0.0], [100.0, 0.0], [110.0, 90.0], [-5.0, 80.0]])
    to = _theta_map(square)
    linear = np.ones(4)
    assert not degenerate_vertices(poly, square, lambda e, t: to(e, t, linear)).any()
    # t^2 on every edge: every vertex starts an edge with no slope
    assert degenerate_vertices(poly, square, lambda e, t: to(e, t, 2 * linear)).all()
    # t^3 on edge 2 only: its start vertex 2; sqrt(t) on edge 0 is infinitely steep, not degenerate
    powers = np.array([0.5, 1.0, 3.0, 1.0])
    assert degenerate_vertices(poly, square, lambda e, t: to(e, t, powers)).tolist() == [False, False, True, False]
    # 1 - (1 - t)^2 on edge 3: no slope at its end, vertex 0
    def ease(e, t):
        e, t = np.asarray(e), np.asarray(t, dtype=float)
        out = to(e, t, linear)
        k = e == 3
        s = 1 - (1 - t[k]) ** 2
        out[k] = square[3] + s[:, None] * (square[0] - square[3])
        return out

    assert degenerate_vertices(poly, square, ease).tolist() == [True, False, False, False]
    # mixed conditions: a rectangle has right angles only; the dart's corners are not
    rect = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 1.0], [0.0, 1.0]])
    assert not degenerate_vertices(rect, square, lambda e, t: to(e, t, linear), mixed=True).any()
    assert degenerate_vertices(DART, square, lambda e, t: to(e, t, linear), mixed=True).all()
    assert degenerate_vertices(DART[::-1], square, lambda e, t: to(e, t, linear), mixed=True).all()
    skew = np.array([[5, 5], [120, 5], [120, 40], [5, 120]], dtype=float)  # right angles at 0 and 1
    assert degenerate_vertices(skew, square, lambda e, t: to(e, t, linear), mixed=True).tolist() == [False, False, True, True]
    assert degenerate_vertices(skew[::-1], square, lambda e, t: to(e, t, linear), mixed=True).tolist() == [True, True, False, False]


def test_a_point_like_edge_image_makes_both_its_vertices_degenerate():
    """An edge whose image is (nearly) a point: no slope at either end."""
    w = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [1.0 - 1e-12, 1.0], [0.0, 1.0]])
    poly = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [50.0, 120.0], [0.0, 100.0]])
    to = _theta_map(w)
    assert degenerate_vertices(poly, w, lambda e, t: to(e, t, np.ones(5))).tolist() == [False, False, True, True, False]


def test_ring_with_a_gap_onto_a_c_is_refused_with_few_nodes():
    """The issue's visible fold (BEM, 64 nodes: phi leaves Theta 1 px inside the arm ends)."""
    rg = ring_gap(np.random.default_rng(7), thick=40, k=16)
    c = c_shape(16, 16)
    src, dst = Polygon(rg, name="ring"), Polygon(c, name="C")
    with pytest.raises(FoldOverError, match="fold"):
        build_map(src, dst, MapOptions(method="bem", nodes=64))


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


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.heavy), pytest.param(2, marks=pytest.mark.heavy)])
def test_mild_shapes_are_accepted_and_clean(seed):
    """Not every polygon is refused: star-shaped ones with reflex corners pass with BEM, and are clean."""
    v = SHAPES["star_like"](np.random.default_rng(seed))
    poly = Polygon(v, name="star")
    phi = BEM.build(poly, regular_theta(poly, poly), MapOptions(method="bem", check=False))
    assert phi.certify().ok
    d = _check(phi)
    assert d["folds"] == 0 and d["deep"] == 0, d
