"""Tests of warpcli.report (and its metrics): closed forms and an independent computation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import l_shape, similarity, star
from warpcli import Polygon, warp_image
from warpcli.report.metrics import singular_values
from warpcli.report import build_report


def test_singular_values_closed_form_matches_svd():
    rng = np.random.default_rng(10)
    m = rng.normal(size=(500, 2, 2))
    s1, s2 = singular_values(m)
    ref = np.linalg.svd(m, compute_uv=False)
    np.testing.assert_allclose(s1, ref[:, 0], rtol=1e-12)
    np.testing.assert_allclose(s2, ref[:, 1], rtol=1e-9, atol=1e-12)


def _warp(src, dst, size=(128, 128)):
    img = np.zeros((size[1], size[0], 1), dtype=np.float32)
    return warp_image(img, src, dst, size=size)


def test_identity_reports_conformal_2_isometric_1_det_1():
    poly = star()
    rep = build_report(_warp(poly, poly))
    assert rep["flipped_triangles"] == 0
    assert rep["conformal"]["mean"] == pytest.approx(2.0, abs=1e-9)
    assert rep["conformal"]["max"] == pytest.approx(2.0, abs=1e-6)
    assert rep["isometric"]["mean"] == pytest.approx(1.0, abs=1e-9)
    assert rep["min_jacobian_det"] == pytest.approx(1.0, abs=1e-6)


def _similarity_case(scale: float, size: int, max_area):
    k = size / 128
    src = Polygon(star(cx=64 * k, cy=64 * k, r_in=25 * k, r_out=58 * k))
    dst = Polygon(similarity(src.points, scale, 0.6, (5.0 * k, -4.0 * k), center=(64 * k, 64 * k)))
    img = np.zeros((size, size, 1), dtype=np.float32)
    return warp_image(img, src, dst, max_area=max_area)


@pytest.mark.parametrize("scale", [0.5, 1.6])
def test_similarity_reports_conformal_2_and_isometric_max_s_inverse_s(scale):
    res = _similarity_case(scale, 256, 1.0)
    rep = build_report(res)
    # Derivatives of a piecewise-linear FEM map are piecewise constant with
    # O(h) errors, and both measures are minimal at a similarity, so noise
    # only raises them: the means sit slightly above the closed forms.
    assert 2.0 <= rep["conformal"]["mean"] < 2.0 * 1.005
    assert max(scale, 1 / scale) <= rep["isometric"]["mean"] < max(scale, 1 / scale) * 1.03
    d = res.distortion()
    assert np.nanmedian(d.det) == pytest.approx(scale * scale, rel=0.005)


def test_distortion_converges_to_the_closed_form_as_the_mesh_refines():
    excess = []
    for area in (4.0, 1.0, 0.25):
        rep = build_report(_similarity_case(0.5, 256, area))
        excess.append(rep["isometric"]["mean"] - 2.0)
    assert excess[0] > excess[1] > excess[2] > 0
    assert excess[2] < 0.025


def test_affine_triangle_map_reports_its_exact_singular_values():
    src = np.array([[5.0, 5.0], [120.0, 15.0], [20.0, 110.0]])
    dst = np.array([[10.0, 20.0], [100.0, 5.0], [70.0, 120.0]])
    a = np.linalg.solve(np.hstack([src, np.ones((3, 1))]), dst)[:2].T  # dst = a @ src + b
    s = np.linalg.svd(a, compute_uv=False)
    rep = build_report(_warp(src, dst))
    assert rep["conformal"]["mean"] == pytest.approx(s[0] / s[1] + s[1] / s[0], rel=1e-9)
    assert rep["conformal"]["max"] == pytest.approx(s[0] / s[1] + s[1] / s[0], rel=1e-9)
    assert rep["isometric"]["mean"] == pytest.approx(max(s[0], 1 / s[1]), rel=1e-9)
    assert rep["min_jacobian_det"] == pytest.approx(np.linalg.det(a), rel=1e-9)


def test_report_agrees_with_finite_differences_of_the_warped_coordinates():
    """An independent computation: differentiate the pulled-back pixel coordinates."""
    src = Polygon(l_shape(size=100))
    dst = Polygon(star(3, 64, 64, 30, 60, 0.2))
    res = _warp(src, dst)
    x = res.inverse_map
    # Central differences of x(y) over the pixel grid: J of f^-1 at interior pixels.
    dx = (x[1:-1, 2:] - x[1:-1, :-2]) / 2.0
    dy = (x[2:, 1:-1] - x[:-2, 1:-1]) / 2.0
    j = np.stack([dx, dy], axis=-1)  # columns: d/dx, d/dy
    ok = np.isfinite(j).all(axis=(-1, -2))
    j = j[ok]
    s1, s2 = singular_values(j)
    area = np.abs(j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0])
    conformal = float(((s1 / s2 + s2 / s1) * area).sum() / area.sum())
    isometric = float((np.maximum(s1, 1 / s2) * area).sum() / area.sum())
    rep = build_report(res)
    assert rep["conformal"]["mean"] == pytest.approx(conformal, rel=0.03)
    assert rep["isometric"]["mean"] == pytest.approx(isometric, rel=0.03)


def test_mirror_map_has_negative_determinants_and_no_flips():
    src = Polygon(star())
    dst = Polygon(src.points * [-1.0, 1.0] + [128.0, 0.0])
    res = _warp(src, dst)
    rep = build_report(res)
    assert rep["flipped_triangles"] == 0
    d = res.distortion()
    ok = np.isfinite(d.det)
    assert (d.det[ok] < 0).all()  # orientation-reversing everywhere, never folded
    assert np.median(d.det[ok]) == pytest.approx(-1.0, rel=0.005)
    assert rep["min_jacobian_det"] < 0
    assert rep["conformal"]["mean"] == pytest.approx(2.0, rel=0.01)


def test_triangle_jacobians_of_an_affine_map():
    from warpcli.maps.fem import triangle_jacobians
    from warpcli.maps.fem.mesh import mesh_polygon
    from warpcli.maps.fem.solve import solve_dirichlet
    from warpcli.maps.theta import regular_polygon

    tri = Polygon([[0.0, 0.0], [40.0, 0.0], [0.0, 30.0]])
    mesh = mesh_polygon(tri, 20.0)
    values = solve_dirichlet(mesh, regular_polygon(3))
    j = triangle_jacobians(mesh.vertices, values, mesh.triangles)
    a = np.linalg.solve(np.hstack([tri.points, np.ones((3, 1))]), regular_polygon(3))[:2].T
    np.testing.assert_allclose(j, np.broadcast_to(a, j.shape), atol=1e-12)
    assert math.isfinite(j.sum())
    inv = triangle_jacobians(values, mesh.vertices, mesh.triangles)
    np.testing.assert_allclose(inv @ j, np.broadcast_to(np.eye(2), j.shape), atol=1e-12)


def test_blockwise_summary_and_measure_equal_the_whole_computation():
    from warpcli.report.metrics import distortion, measure, summarize

    res = _warp(Polygon(l_shape(size=100)), Polygon(star(3, 64, 64, 30, 60, 0.2)))
    j = res.pull.jacobian
    whole = distortion(j).summary()
    parts = summarize(j, block=997)
    assert parts["min_jacobian_det"] == whole["min_jacobian_det"]
    for name in ("conformal", "isometric"):
        assert parts[name]["max"] == whole[name]["max"]
        assert parts[name]["mean"] == pytest.approx(whole[name]["mean"], rel=1e-12)
    np.testing.assert_array_equal(measure(j, "isometric", block=997).ravel(), distortion(j).isometric)
    assert res.measure("conformal").shape == (128, 128)


def test_figures_scale_with_the_picture():
    from warpcli.report.figures import _legend, grid_figure, stroke

    assert stroke(300, 500) == 1 and stroke(3000, 4000) == 2
    assert _legend(500, "t", 2.0, 10.0, (2, 10)).shape[1] == 150
    assert _legend(3000, "t", 2.0, 10.0, (2, 10)).shape[1] == 450
    img = np.zeros((2400, 2400, 3), dtype=np.uint8)
    sq = Polygon([[100.0, 100.0], [2300.0, 100.0], [2300.0, 2300.0], [100.0, 2300.0]])
    inv = np.full((2400, 2400, 2), np.nan)
    fig = grid_figure(img, inv, sq, sq)
    # Grid lines two pixels wide: rows 75 and 76 are light, 77 is not (step 150).
    assert fig[75, 10, 0] > 150 and fig[76, 10, 0] > 150 and fig[77, 10, 0] == 0


def test_a_parallelogram_pair_reports_the_affine_maps_exact_distortion():
    """Both polygons affine images of one square: each harmonic map is affine (FEM reproduces
    linear functions), so f is the affine map between them, and every source point says so."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    a0, a1 = np.array([[90.0, 20.0], [10.0, 60.0]]), np.array([[40.0, -30.0], [25.0, 100.0]])
    src, dst = square @ a0.T + [10.0, 20.0], square @ a1.T + [40.0, 10.0]
    a = a1 @ np.linalg.inv(a0)
    s = np.linalg.svd(a, compute_uv=False)
    rep = build_report(_warp(src, dst, size=(140, 140)))
    for key in ("mean", "max"):
        assert rep["conformal"][key] == pytest.approx(s[0] / s[1] + s[1] / s[0], rel=1e-9)
        assert rep["isometric"][key] == pytest.approx(max(s[0], 1 / s[1]), rel=1e-9)
    assert rep["min_jacobian_det"] == pytest.approx(np.linalg.det(a), rel=1e-9)


def test_the_report_measures_over_the_source_as_differences_of_f_do():
    """An independent measurement: central differences of f's points on a 1-px source grid (not
    its Jacobians), plain means over the grid; on a map that squeezes parts of the source."""
    from warpcli.grid import inside_polygon

    src = Polygon(l_shape(size=100))
    dst = Polygon(star(3, 64, 64, 18, 60, 0.2))
    res = _warp(src, dst)
    f = res.map
    x, y = np.meshgrid(np.arange(8.5, 109.0), np.arange(8.5, 109.0))
    p = np.stack([x, y], axis=-1)
    h = 0.25
    dfx = (f.forward((p + [h, 0]).reshape(-1, 2)) - f.forward((p - [h, 0]).reshape(-1, 2))) / (2 * h)
    dfy = (f.forward((p + [0, h]).reshape(-1, 2)) - f.forward((p - [0, h]).reshape(-1, 2))) / (2 * h)
    j = np.stack([dfx, dfy], axis=-1)  # columns: d/dx, d/dy
    inside = inside_polygon(p.reshape(-1, 2), src.points) & np.isfinite(j).all(axis=(1, 2))
    s1, s2 = singular_values(j[inside])
    rep = build_report(res)
    assert rep["conformal"]["mean"] == pytest.approx(float(np.mean(s1 / s2 + s2 / s1)), rel=0.02)
    assert rep["isometric"]["mean"] == pytest.approx(float(np.mean(np.maximum(s1, 1 / s2))), rel=0.02)
