"""Tests of warpcli.mesh: graded quality CDT meshes and boundary bookkeeping."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import comb, l_shape, spiral, star
from warpcli.errors import PolygonError
from warpcli.maps.fem.mesh import (
    AUTO_MAX_TRIANGLES,
    MAX_TRIANGLES,
    auto_max_area,
    centroids,
    mesh_polygon,
    triangle_areas,
)
from warpcli.polygon import Polygon
from warpcli.simplicial import corners

SHAPES = {"star": star(), "L": l_shape(), "comb": comb(), "spiral": spiral()}


@pytest.mark.parametrize("name", SHAPES)
@pytest.mark.parametrize("orient", [1, -1])
def test_mesh_covers_polygon_with_consistent_orientation(name, orient):
    poly = Polygon(SHAPES[name][::orient])
    mesh = mesh_polygon(poly, 2.0)
    areas = triangle_areas(mesh.vertices, mesh.triangles)
    assert np.all(np.sign(areas) == np.sign(poly.signed_area))
    assert abs(areas.sum() - poly.signed_area) < 1e-9 * abs(poly.signed_area)
    assert np.abs(areas).max() <= 2.0 * (1 + 1e-9)


@pytest.mark.parametrize("name", SHAPES)
def test_boundary_nodes_lie_on_their_edges_at_their_parameters(name):
    poly = Polygon(SHAPES[name])
    mesh = mesh_polygon(poly, 4.0)
    p = poly.points
    e = mesh.boundary_edge
    t = mesh.boundary_t[:, None]
    expected = (1 - t) * p[e] + t * p[(e + 1) % poly.n]
    np.testing.assert_allclose(mesh.vertices[mesh.boundary], expected, atol=1e-9)
    assert np.all((mesh.boundary_t >= 0) & (mesh.boundary_t < 1))
    # Every polygon vertex is a mesh node with t = 0 on its own edge.
    corners = mesh.boundary_t == 0
    assert sorted(e[corners].tolist()) == list(range(poly.n))


@pytest.mark.parametrize("name", SHAPES)
def test_boundary_of_mesh_is_the_boundary_nodes(name):
    poly = Polygon(SHAPES[name])
    mesh = mesh_polygon(poly, 4.0)
    edges = np.sort(np.concatenate([mesh.triangles[:, [0, 1]], mesh.triangles[:, [1, 2]], mesh.triangles[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    outline = np.unique(uniq[count == 1])
    assert np.array_equal(outline, np.sort(mesh.boundary))


def test_mesh_is_graded_towards_reflex_vertices():
    poly = Polygon(l_shape())
    (reflex,) = poly.reflex_vertices()
    mesh = mesh_polygon(poly, 16.0)
    tri = mesh.triangles
    centroid = mesh.vertices[tri].mean(axis=1)
    dist = np.hypot(*(centroid - poly.points[reflex]).T)
    area = np.abs(triangle_areas(mesh.vertices, tri))
    assert area[dist < 1.0].max() < area[dist > 20].mean() / 20


def test_meshing_is_deterministic():
    poly = Polygon(star())
    a = mesh_polygon(poly, 2.0)
    b = mesh_polygon(poly, 2.0)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.triangles, b.triangles)


def test_too_large_polygon_is_refused_before_meshing():
    big = Polygon([[0, 0], [1e7, 0], [1e7, 1e7], [0, 1e7]], name="big.json")
    with pytest.raises(PolygonError, match=r"big.json: .*more than the limit") as info:
        mesh_polygon(big, 1.0)
    assert f"{MAX_TRIANGLES:,}" in str(info.value)


def test_auto_area_is_at_least_one_pixel_and_fits_the_limit():
    small = Polygon(star(r_in=5, r_out=10))
    assert auto_max_area(small) == 1.0
    huge = Polygon([[0, 0], [1e6, 0], [1e6, 1e6], [0, 1e6]])
    a = auto_max_area(huge)
    assert 2.0 * abs(huge.signed_area) / a <= AUTO_MAX_TRIANGLES * (1 + 1e-12)


def test_auto_density_meshes_a_huge_polygon_quickly():
    huge = Polygon([[0, 0], [1e7, 0], [1e7, 1e7], [0, 1e7]])
    mesh = mesh_polygon(huge, auto_max_area(huge))
    assert mesh.n_triangles <= AUTO_MAX_TRIANGLES


@pytest.mark.parametrize("size", [1e4, 1e6, 1e8])
def test_a_polygon_far_larger_than_its_image_is_meshed_at_the_image(size):
    # Uniform at the automatic density, the 1e8 square would need 1M triangles
    # (the cap) of 8e10 px^2 each; graded from the image, the count grows
    # with the logarithm of the size.
    """Graded from the region of interest: the triangle count does not grow with the polygon,
    and triangles over the image keep the image's automatic density."""
    from warpcli.maps.fem.mesh import graded_from, triangle_areas

    poly = Polygon([[-size, -size], [size, -size], [size, size], [-size, size]])
    region = (0.0, 0.0, 64.0, 48.0)
    assert graded_from(poly, region)
    area = auto_max_area(poly, region)
    assert area == auto_max_area(Polygon([[0, 0], [64, 0], [64, 48], [0, 48]]))
    m = mesh_polygon(poly, area, region=region)
    assert m.n_triangles < 500_000
    c = m.vertices[m.triangles].mean(axis=1)
    over = (c[:, 0] > 0) & (c[:, 0] < 64) & (c[:, 1] > 0) & (c[:, 1] < 48)
    assert np.abs(triangle_areas(m.vertices, m.triangles))[over].max() <= area * (1 + 1e-9)


def _far_needles(count: int, seed: int):
    """Needles and thin strips from a 40 x 30 image out to 1e3-1e9 px, in random directions and widths."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        reach = 10.0 ** rng.uniform(3, 9)
        angle = rng.uniform(0, 2 * np.pi)
        width = 10.0 ** rng.uniform(1, 3.5)
        d, n = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
        base = np.array([20.0, 15.0])
        tip = np.clip(base + reach * d, -9e8, 9e8)
        if rng.random() < 0.5:  # a needle: a triangle with its tip far away
            pts = [base - width * n, tip, base + width * n]
        else:  # a strip of constant width
            pts = [base - width * n, tip - width * n, tip + width * n, base + width * n]
        try:
            yield Polygon(np.array(pts)), reach, width
        except PolygonError:  # thinner than the validator allows for its size: not a mesher's case
            continue


def test_far_thin_parts_are_meshed_or_refused_within_a_bounded_work(monkeypatch):
    # A part far beyond the image that is thin for its length needs triangles all along it (their
    # angles are bounded): a needle to x = 9e8 took 5 million triangles, 40 s and 2 GB for a 200 px
    # image. The mesher now stops at the budget's vertices, whatever the coordinates, and refuses.
    import triangle

    import warpcli.maps.fem.mesh as mesh_module

    monkeypatch.setattr(mesh_module, "AUTO_MAX_TRIANGLES", 20_000)  # the floor of the budget, small for the test
    made = []
    real = triangle.triangulate

    def counted(data, switches):
        out = real(data, switches)
        made.append(len(out["vertices"]))
        return out

    monkeypatch.setattr(triangle, "triangulate", counted)
    region = (0.0, 0.0, 40.0, 30.0)
    outcomes = {"meshed": 0, "refused": 0}
    for poly, reach, width in _far_needles(24, seed=5):
        area = auto_max_area(poly, region)
        most = max(20_000, round(mesh_module.GRADED_BUDGET * 2 * (40 + 40) * (30 + 40) / area))
        made.clear()
        try:
            m = mesh_polygon(poly, area, region=region)
        except PolygonError as err:
            assert "reaches far beyond the image" in str(err) and "too thin for its length" in str(err)
            outcomes["refused"] += 1
        else:
            assert m.n_triangles <= most
            outcomes["meshed"] += 1
        assert max(made) <= most, (reach, width)  # the work, refused or not
    assert outcomes["meshed"] and outcomes["refused"], outcomes  # both sides of the budget were generated


def test_far_reaching_wide_polygons_are_never_refused():
    # Squares and stars to the coordinates' limit round a tiny image: triangles growing with the
    # distance keep them far under the budget's floor (445,000-464,000 measured at 1e9).
    region = (0.0, 0.0, 10.0, 10.0)
    square = [Polygon([[-size, -size], [size, -size], [size, size], [-size, size]]) for size in (1e3, 9.9e8)]
    stars = [Polygon(star(6, 5.0, 5.0, 0.4 * size, size)) for size in (1e4, 1e7)]
    for poly in square + stars:
        m = mesh_polygon(poly, auto_max_area(poly, region), region=region)
        assert m.n_triangles < AUTO_MAX_TRIANGLES / 2


def test_a_polygon_near_its_image_is_meshed_as_without_a_region():
    from warpcli.maps.fem.mesh import graded_from

    poly = Polygon(star(cx=64, cy=64, r_in=20, r_out=70))  # reaches a little beyond a 128 px image
    region = (0.0, 0.0, 128.0, 128.0)
    assert not graded_from(poly, region)
    a = mesh_polygon(poly, auto_max_area(poly, region), region=region)
    b = mesh_polygon(poly, auto_max_area(poly))
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.triangles, b.triangles)


def test_corners_are_fancy_indexings_values_and_the_grading_centroids_are_means():
    rng = np.random.default_rng(24)
    specials = np.array([0.0, -0.0, 1.0, -2.5, np.inf, -np.inf, np.nan, 1e-310])
    v = np.concatenate([rng.normal(size=(300, 2)) * 10.0 ** rng.integers(-3, 4, size=(300, 1)),
                        np.array(np.meshgrid(specials, specials)).reshape(2, -1).T])  # fmt: skip
    t = rng.integers(0, len(v), size=(5000, 3)).astype(np.int32)
    t[:512] = np.array(np.meshgrid(*[np.arange(300, 308)] * 3)).reshape(3, -1).T  # every triple of the specials
    got = corners(v, t)
    for k in range(3):
        assert got[k].tobytes() == v[t[:, k]].tobytes()
    tets = rng.integers(0, len(v), size=(100, 4))  # any simplex: one array per corner
    assert [c.tobytes() for c in corners(v, tets)] == [v[tets[:, k]].tobytes() for k in range(4)]
    # mesh_polygon's size field: its centroids are the mean over each triangle's corners, bit for bit.
    with np.errstate(invalid="ignore"):  # inf - inf among the specials
        c = centroids(v, t)
        want = v[t].mean(axis=1)
    assert np.array_equal(np.isnan(c), np.isnan(want))
    assert c[~np.isnan(c)].tobytes() == want[~np.isnan(want)].tobytes()


@pytest.mark.parametrize("seed", range(4))
def test_meshes_scale_with_the_polygon_exactly_whatever_the_units(seed):
    # Triangle read a switch's area as its digits and point only: an area below 1e-4, written
    # as 5e-05, was an area of 5, and a polygon in small units (mm, or 0..1) got a mesh of two
    # triangles. Scaled by powers of two (exact in floating point, and Triangle's predicates
    # are exact), the polygon and its area bound give the same mesh, scaled.
    from nasty import star_like

    from warpcli.maps.fem.mesh import mesh_polygon

    points = star_like(np.random.default_rng(seed), 300.0)
    base = mesh_polygon(Polygon(points), 40.0, grade=False)
    assert base.n_triangles > 500
    for k in (-12, -10, -3, 4):  # areas from 2.4e-6 (below 1e-4: written with an exponent by %g) up
        s = 2.0**k
        mesh = mesh_polygon(Polygon(points * s), 40.0 * s * s, grade=False)
        assert np.array_equal(mesh.triangles, base.triangles), k
        assert np.array_equal(mesh.vertices, base.vertices * s), k


def test_the_switch_numbers_are_decimals_triangle_reads():
    from warpcli._switches import decimal

    rng = np.random.default_rng(1)
    for x in np.concatenate([10.0 ** rng.uniform(-40, 20, 200), [1e-4, 9.99e-5, 1.0, 0.1, 123.456]]):
        text = decimal(float(x))
        assert set(text) <= set("0123456789.") and float(text) == x, (x, text)
