"""Tests of warpcli.maps.compose (with FEM): the composed map and its inverse, against exact mathematics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import comb, l_shape, regular, similarity, spiral, star
from warpcli.maps.compose import BijectiveMap
from warpcli.polygon import Polygon

SHAPES = {"star": star(), "L": l_shape(), "comb": comb(), "spiral": spiral()}
RNG_SEED = 20261120



def _contains(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule point-in-polygon test, vectorized over points."""
    x, y = points[:, 0:1], points[:, 1:2]
    a = poly
    b = np.roll(poly, -1, axis=0)
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (crosses & (x < xint)).sum(axis=1) % 2 == 1


def inside_points(poly: Polygon, count: int, seed: int = RNG_SEED) -> np.ndarray:
    """Random points strictly inside ``poly`` (rejection sampling, seeded)."""
    rng = np.random.default_rng(seed)
    lo = poly.points.min(axis=0)
    hi = poly.points.max(axis=0)
    out = []
    while sum(len(o) for o in out) < count:
        p = rng.uniform(lo, hi, size=(4 * count, 2))
        out.append(p[_contains(p, poly.points)])
    return np.concatenate(out)[:count]


def assert_same_points(a: np.ndarray, b: np.ndarray) -> None:
    """Same NaN pattern, and equal (up to rounding on shared edges) elsewhere."""
    assert np.array_equal(np.isnan(a), np.isnan(b))
    np.testing.assert_allclose(a, b, atol=1e-9, rtol=0)


def affine_from(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The 3x2 matrix M with [p, 1] @ M = affine image of p, from 3 point pairs."""
    return np.linalg.solve(np.hstack([src, np.ones((3, 1))]), dst)


def test_triangle_to_triangle_is_exactly_affine():
    src = Polygon([[5.0, 7.0], [120.0, 20.0], [30.0, 110.0]])
    dst = Polygon([[60.0, 2.0], [118.0, 90.0], [4.0, 60.0]])
    f = BijectiveMap.between(src, dst)
    m = affine_from(src.points, dst.points)
    p = inside_points(src, 2000)
    fwd = f.forward(p)
    np.testing.assert_allclose(fwd, np.hstack([p, np.ones((len(p), 1))]) @ m, atol=1e-6)
    q = inside_points(dst, 2000)
    minv = affine_from(dst.points, src.points)
    np.testing.assert_allclose(f.inverse(q), np.hstack([q, np.ones((len(q), 1))]) @ minv, atol=1e-6)


@pytest.mark.parametrize("name", SHAPES)
def test_identical_polygons_give_the_identity(name):
    poly = Polygon(SHAPES[name])
    f = BijectiveMap.between(poly, poly)
    p = inside_points(poly, 3000)
    np.testing.assert_allclose(f.inverse(p), p, atol=1e-9)
    np.testing.assert_allclose(f.forward(p), p, atol=1e-9)


@pytest.mark.parametrize("name", ["star", "L", "comb"])
@pytest.mark.parametrize(
    "scale,angle,shift", [(1.0, 0.7, (3.0, -2.0)), (0.6, -0.4, (10.0, 5.0)), (1.5, 2.0, (-20.0, 8.0))]
)
def test_similar_polygons_give_the_similarity(name, scale, angle, shift):
    src = Polygon(SHAPES[name])
    dst = Polygon(similarity(src.points, scale, angle, shift))
    f = BijectiveMap.between(src, dst, max_area=2.0)
    p = inside_points(src, 3000)
    err = np.hypot(*(f.forward(p) - similarity(p, scale, angle, shift)).T)
    # FEM accuracy: the two meshes are not similar, so the two discrete maps
    # differ by their discretization error (largest at reflex corners).
    assert np.mean(err) < 0.02
    assert np.max(err) < 0.3


def test_default_density_is_within_the_documented_accuracy():
    """auto density: mean error against a 4x finer mesh at most 0.05 px (README)."""
    from warpcli.maps.fem.mesh import auto_max_area

    src = Polygon(star(cx=128, cy=128, r_in=60, r_out=124))
    dst = Polygon(star(cx=128, cy=128, r_in=45, r_out=120, phase=0.3))
    coarse = BijectiveMap.between(src, dst)
    fine = BijectiveMap.between(src, dst, max_area=(auto_max_area(src) / 4, auto_max_area(dst) / 4))
    a = coarse.inverse_grid(256, 256)
    b = fine.inverse_grid(256, 256)
    ok = np.isfinite(a[..., 0]) & np.isfinite(b[..., 0])
    err = np.hypot(*(a[ok] - b[ok]).T)
    assert err.mean() < 0.05
    assert err.max() < 1.0


def test_mirrored_target_gives_the_reflection():
    src = Polygon(star())
    mirrored = src.points * [-1.0, 1.0] + [128.0, 0.0]  # x -> 128 - x
    dst = Polygon(mirrored)
    assert np.sign(dst.signed_area) != np.sign(src.signed_area)
    f = BijectiveMap.between(src, dst)
    assert not f.orientation_preserving
    assert f.flipped_triangles() == 0
    p = inside_points(src, 3000)
    err = np.hypot(*(f.forward(p) - (p * [-1.0, 1.0] + [128.0, 0.0])).T)
    assert err.mean() < 0.02 and err.max() < 0.3


@pytest.mark.parametrize("name", SHAPES)
def test_target_edges_are_pulled_back_onto_source_edges(name):
    src = Polygon(SHAPES[name])
    dst = Polygon(star(n=len(src.points) // 2) if len(src.points) % 2 == 0 else regular(len(src.points)))
    f = BijectiveMap.between(src, dst)
    n = src.n
    t = np.linspace(0.0, 1.0, 37)[:-1]
    for i in range(n):
        a1, b1 = dst.points[i], dst.points[(i + 1) % n]
        a0, b0 = src.points[i], src.points[(i + 1) % n]
        on_dst = (1 - t)[:, None] * a1 + t[:, None] * b1
        on_src = (1 - t)[:, None] * a0 + t[:, None] * b0
        # The boundary map is linear per edge on both sides: parameter t on
        # target edge i comes from parameter t on source edge i.
        np.testing.assert_allclose(f.inverse(on_dst), on_src, atol=1e-7)
        np.testing.assert_allclose(f.forward(on_src), on_dst, atol=1e-7)


@pytest.mark.parametrize("name", SHAPES)
def test_no_flips_and_round_trips_on_concave_shapes(name):
    src = Polygon(SHAPES[name])
    n = src.n
    dst = Polygon(regular(n, r=50.0, phase=0.3))
    f = BijectiveMap.between(src, dst)
    assert f.flipped_triangles() == 0
    g = BijectiveMap.between(dst, src)
    assert g.flipped_triangles() == 0
    p = inside_points(src, 3000)
    np.testing.assert_allclose(f.inverse(f.forward(p)), p, atol=1e-8)
    q = inside_points(dst, 3000)
    np.testing.assert_allclose(f.forward(f.inverse(q)), q, atol=1e-8)


def test_points_outside_are_nan():
    src = Polygon(l_shape())
    f = BijectiveMap.between(src, src)
    out = f.inverse(np.array([[100.0, 20.0], [-5.0, -5.0], [60.0, 60.0]]))
    assert np.isnan(out[0]).all() and np.isnan(out[1]).all()
    assert np.isfinite(out[2]).all()


def test_composed_map_keeps_orientation_everywhere():
    """The Jacobian of f^-1 has the expected sign at random points.

    The tiny triangle (h = 1e-6 px) lies inside one linear piece of both
    piecewise-linear maps, so the orientation of its vertices' images is the
    sign of the composed map's Jacobian there (a larger triangle straddling a
    crease of a PL homeomorphism may legitimately come out reversed).
    """
    src = Polygon(star())
    dst = Polygon(spiral(samples=6))
    f = BijectiveMap.between(src, dst)
    # Small triangles around random points: the map must keep their orientation.
    q = inside_points(dst, 2000)
    h = 1e-6
    tri = np.stack([q, q + [h, 0.0], q + [0.0, h]], axis=1)
    ok = _contains(tri.reshape(-1, 2), dst.points).reshape(-1, 3).all(axis=1)
    pre = f.inverse(tri[ok].reshape(-1, 2)).reshape(-1, 3, 2)
    d1 = pre[:, 1] - pre[:, 0]
    d2 = pre[:, 2] - pre[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    expected = math.copysign(1.0, src.signed_area * dst.signed_area)
    assert np.all(det * expected > 0)


@pytest.mark.parametrize("name", ["star", "comb"])
def test_inverse_grid_equals_inverse_at_pixel_centres(name):
    from warpcli.grid import pixel_centres

    src = Polygon(SHAPES[name])
    dst = Polygon(regular(src.n, r=60.0, phase=0.1))
    f = BijectiveMap.between(src, dst)
    grid = f.inverse_grid(130, 120)
    assert_same_points(grid, f.inverse(pixel_centres(130, 120)).reshape(120, 130, 2))


def test_inverse_grid_on_a_square_split_along_pixel_centres():
    """Pixel centres exactly on shared edges and on the boundary are inside, once."""
    sq = Polygon([[0.5, 0.5], [6.5, 0.5], [6.5, 6.5], [0.5, 6.5]])
    f = BijectiveMap.between(sq, sq)
    grid = f.inverse_grid(8, 8)
    from warpcli.grid import pixel_centres

    centres = pixel_centres(8, 8).reshape(8, 8, 2)
    inside = np.zeros((8, 8), bool)
    inside[0:7, 0:7] = True  # centres 0.5 .. 6.5 lie on or inside the square
    assert np.array_equal(np.isfinite(grid[..., 0]), inside)
    np.testing.assert_allclose(grid[inside], centres[inside], atol=1e-9)


def _with_a_flip(phi):
    """The same map with two neighbouring interior nodes' images swapped: folded."""
    import dataclasses

    values = phi.values.copy()
    interior = np.setdiff1d(np.arange(phi.mesh.n_vertices), phi.mesh.boundary)
    t = phi.mesh.triangles
    for tri in t:
        inner = [v for v in tri if v in set(interior.tolist())]
        if len(inner) >= 2:
            a, b = inner[:2]
            values[[a, b]] = values[[b, a]]
            break
    return dataclasses.replace(phi, values=values)


def test_a_folded_map_is_detected_and_refused():
    from warpcli.errors import FoldOverError

    src = Polygon(star())
    f = BijectiveMap.between(src, src)
    bad = BijectiveMap(_with_a_flip(f.phi0), f.phi1)
    assert bad.flipped_triangles() > 0
    with pytest.raises(FoldOverError, match="flip"):
        bad.check_bijective()


def test_a_folded_cotan_map_is_repaired_with_positive_weights(caplog):
    from warpcli.maps.fem import repaired

    poly = Polygon(star())
    f = BijectiveMap.between(poly, poly)
    folded = _with_a_flip(f.phi0)
    assert folded.flipped().any()
    with caplog.at_level("WARNING", logger="warpcli"):
        fixed = repaired(folded)
    assert fixed.weights == "positive" and not fixed.flipped().any()
    assert "positive" in caplog.text


def test_positive_weights_give_a_bijective_map_close_to_the_harmonic_one():
    src = Polygon(star())
    dst = Polygon(regular(12, r=55.0, phase=0.2))
    f = BijectiveMap.between(src, dst, weights="positive")
    g = BijectiveMap.between(src, dst)
    assert f.flipped_triangles() == 0
    p = inside_points(src, 2000)
    np.testing.assert_allclose(f.inverse(f.forward(p)), p, atol=1e-8)
    # Not harmonic, but the same kind of map: within a few pixels everywhere.
    assert np.nanmax(np.hypot(*(f.forward(p) - g.forward(p)).T)) < 8.0


def test_forward_grid_equals_forward_at_pixel_centres_and_inverts():
    from warpcli.grid import pixel_centres

    src = Polygon(comb())
    dst = Polygon(regular(src.n, r=60.0, phase=0.1))
    f = BijectiveMap.between(src, dst)
    grid = f.forward_grid(128, 128)
    assert_same_points(grid, f.forward(pixel_centres(128, 128)).reshape(128, 128, 2))
    ok = np.isfinite(grid[..., 0])
    np.testing.assert_allclose(f.inverse(grid[ok]), pixel_centres(128, 128).reshape(128, 128, 2)[ok], atol=1e-7)


def test_theta_points_a_rounding_error_outside_go_through_the_boundary_map():
    """The fallback shared by inverse() and the grid pass: exact on the boundary, no Jacobian."""
    src = Polygon(star())
    f = BijectiveMap.between(src, src)
    w = f.theta.points
    mid = 0.5 * (w + np.roll(w, -1, axis=0))
    outward = mid * (1 + 1e-9)  # Theta is centred at the origin; beyond BARY_TOL
    expected = 0.5 * (src.points + np.roll(src.points, -1, axis=0))
    for coherent in (False, True):
        m = f.phi0.inverse(outward, jacobian=True, coherent=coherent)
        np.testing.assert_allclose(m.points, expected, atol=1e-9)
        assert np.isnan(m.jacobian).all()


@pytest.mark.parametrize("rows", [None, (30, 95)])
def test_pull_back_jacobians_are_the_products_of_both_maps_jacobians(rows):
    """The pull-back's Jacobian at each pixel centre is J(phi0^-1) @ J(phi1), each map's own
    (`evaluate_grid` and `inverse`, in numpy), where FEM scatters products of per-triangle tables
    (`FEMMap.grid_cells`, `inverse_cells`, `jacobian_table`); NaN where either is unknown."""
    f = BijectiveMap.between(Polygon(star()), Polygon(star(phase=0.3)))
    pull = f.pull_back(128, 128, rows=rows)
    g = f.phi1.evaluate_grid(128, 128, jacobian=True)
    m = f.phi0.inverse(g.values, jacobian=True, coherent=True)
    a, b = m.jacobian, g.jacobian
    prod = np.stack(
        [np.stack([a[:, r, 0] * b[:, 0, c] + a[:, r, 1] * b[:, 1, c] for c in range(2)], axis=-1) for r in range(2)],
        axis=-2,
    )  # fmt: skip
    want = np.full((128 * 128, 2, 2), np.nan)
    want[g.pixels] = prod
    points = np.full((128 * 128, 2), np.nan)
    points[g.pixels] = m.points
    (r0, c0), (h, w) = pull.origin, pull.points.shape[:2]
    want = want.reshape(128, 128, 2, 2)[r0 : r0 + h, c0 : c0 + w]
    np.testing.assert_array_equal(pull.jacobian, want)
    np.testing.assert_array_equal(pull.points, points.reshape(128, 128, 2)[r0 : r0 + h, c0 : c0 + w])
    assert (np.isfinite(pull.jacobian[..., 0, 0]) == np.isfinite(pull.points[..., 0])).mean() > 0.99


def test_a_pull_back_makes_each_map_only_the_jacobian_table_it_reads():
    """The target's map is scanned on the grid and the source's inverted: a pull-back reads the
    target's "grid" table and the source's "inverse" one, made with the maps (in the children that
    built them, where they fork), and makes neither map's other table (a table of both sides made
    the unread one's Jacobians in the parent, once per thread of the pull-back)."""
    f = BijectiveMap.between(Polygon(star()), Polygon(star(phase=0.3)))
    f.pull_back(128, 128)
    assert "_grid_table" in vars(f.phi1) and "_inverse_table" not in vars(f.phi1)
    assert "_inverse_table" in vars(f.phi0) and "_grid_table" not in vars(f.phi0)
    for phi, side in ((f.phi1, "grid"), (f.phi0, "inverse")):
        table = phi.jacobian_table(side)
        assert table.shape == (phi.mesh.n_triangles + 1, 2, 2) and np.isnan(table[-1]).all()
    with pytest.raises(ValueError, match="side"):
        f.phi0.jacobian_table("forward")


@pytest.mark.parametrize("name", SHAPES)
def test_the_triangles_a_band_of_rows_scans_are_every_triangle_that_can_reach_it_in_coherent_order(name):
    """`FEMMap._order_within` (from `_row_index`) against a brute force over every triangle: those
    whose corners' y span reaches within a pixel of rows r0 <= r < r1, in `_coherent_order`."""
    poly = Polygon(SHAPES[name])
    phi = BijectiveMap.between(poly, poly).phi1
    y = phi.mesh.vertices[:, 1]
    tri = phi.mesh.triangles
    low = np.array([min(y[a], y[b], y[c]) for a, b, c in tri])
    high = np.array([max(y[a], y[b], y[c]) for a, b, c in tri])
    ymin_sorted, ymax, by_ymin, rank, tallest = phi._row_index
    assert np.array_equal(ymax, high) and np.array_equal(ymin_sorted, np.sort(low))
    assert np.array_equal(by_ymin, np.argsort(low, kind="stable")) and tallest == (high - low).max()
    assert np.array_equal(phi._coherent_order[rank], np.arange(len(tri)))
    order = list(phi._coherent_order)
    top, bottom = int(np.floor(y.min())), int(np.ceil(y.max()))
    for r0 in range(top - 2, bottom + 2, 7):
        for r1 in (r0 + 1, r0 + 5, r0 + 40):
            reach = {t for t in range(len(tri)) if high[t] >= r0 - 1.0 and low[t] <= r1 + 1.0}
            assert list(phi._order_within(r0, r1)) == [t for t in order if t in reach]
