"""``--theta none``: the plain harmonic map straight onto the target, certified or refused (issue 25)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import comb, l_shape, read_pixels, run_cli, star, write_png, write_polygon
from hypothesis import given, settings
from hypothesis import strategies as st

from warpcli import MapOptions, Polygon, build_report, warp_image
from warpcli.errors import InputError
from warpcli.maps.compose import BijectiveMap

#: Coarse meshes: these tests are about the construction, not the accuracy.
AREA = 24.0


def straight(src, dst, **changes) -> BijectiveMap:
    return BijectiveMap.between(Polygon(src, name="src"), Polygon(dst, name="dst"), MapOptions(theta="none", max_area=AREA, **changes))


@settings(max_examples=8, deadline=None)
@given(
    shape=st.sampled_from(["L", "comb", "star"]),
    a=st.lists(st.floats(-0.6, 0.6), min_size=4, max_size=4),
    shift=st.lists(st.floats(-10.0, 10.0), min_size=2, max_size=2),
    mirror=st.booleans(),
)
def test_an_affine_pair_gives_exactly_the_affine_map(shape, a, shift, mirror):
    """The linear function is harmonic (and discretely so: P1 reproduces it), so boundary data
    that are an affine map give that affine map inside, at every point, to rounding."""
    src = {"L": l_shape(), "comb": comb(), "star": star(5, r_in=30.0)}[shape]
    m = np.array([[1.0 + a[0], a[1]], [a[2], 1.0 + a[3]]])
    if mirror:
        m = m @ np.diag([-1.0, 1.0])
    if abs(np.linalg.det(m)) < 0.2:
        m = m + 0.6 * np.eye(2) * np.sign(np.linalg.det(m) or 1.0)
    centre = src.mean(axis=0)
    dst = (src - centre) @ m.T + centre + shift
    f = straight(src, dst)
    assert f.flipped_triangles() == 0
    # The map's vertex images are the affine images of the mesh's vertices.
    phi = f.phi0
    np.testing.assert_allclose(phi.values, (phi.mesh.vertices - centre) @ m.T + centre + shift, atol=1e-9)
    # And f, f^-1 and f's Jacobian at points inside (the triangles' centroids).
    x = phi.mesh.vertices[phi.mesh.triangles].mean(axis=1)
    y = (x - centre) @ m.T + centre + shift
    np.testing.assert_allclose(f.forward(x), y, atol=1e-9)
    np.testing.assert_allclose(f.inverse(y), x, atol=1e-9)
    np.testing.assert_allclose(f.forward_jacobian(x), np.broadcast_to(m, (len(x), 2, 2)), atol=1e-9)


@pytest.mark.parametrize("src", [l_shape(), comb(3), star(4, r_in=30.0)], ids=["L", "comb", "star"])
def test_a_convex_target_gives_the_map_through_the_target_as_theta(src, tmp_path):
    """Onto a convex target T, the map through Theta = T is the straight map: phi1 (T onto
    itself, linear boundary data) is the identity, so f = phi0. The two constructions share
    nothing else (a Theta file, the target's own mesh and solve), so their images agree to rounding."""
    n = len(src)
    rng = np.random.default_rng(n)
    # Points of an ellipse in angular order are in strictly convex position.
    angles = 2 * np.pi * np.arange(n) / n + rng.uniform(-0.3, 0.3, n) * np.pi / n
    dst = np.stack([64 + 50 * np.cos(angles), 64 + 40 * np.sin(angles)], axis=1)
    theta = tmp_path / "theta.json"
    theta.write_text(json.dumps(dst.tolist()))
    img = np.random.default_rng(1).random((128, 128, 1)).astype(np.float32)
    a = warp_image(img, Polygon(src), Polygon(dst), map=MapOptions(theta="none", max_area=AREA))
    b = warp_image(img, Polygon(src), Polygon(dst), map=MapOptions(theta=str(theta), max_area=AREA))
    pa, pb = a.pull.full_points(), b.pull.full_points()
    assert np.array_equal(np.isnan(pa), np.isnan(pb))
    np.testing.assert_allclose(pa[~np.isnan(pa)], pb[~np.isnan(pb)], atol=1e-7)
    np.testing.assert_allclose(a.pixels, b.pixels, atol=1e-5)


@pytest.mark.parametrize("n", [4, 5, 6, 8])
@pytest.mark.parametrize("r_in", [8.0, 20.0])
def test_a_sharp_star_target_where_the_plain_map_folds_is_refused(n, r_in):
    with pytest.raises(InputError, match=r"folds at \d+ triangles?; use a convex Theta"):
        straight(star(n, r_in=50.0), star(n, r_in=r_in))


def test_the_refusal_is_one_line_exit_2_and_no_output(tmp_path):
    src = write_polygon(tmp_path / "src.json", star(5, r_in=50.0))
    dst = write_polygon(tmp_path / "dst.json", star(5, r_in=10.0))
    inp = write_png(tmp_path / "in.png", np.zeros((64, 64, 3), dtype=np.uint8))
    out = tmp_path / "out.png"
    code, err = run_cli([inp, "--src", src, "--dst", dst, out, "--theta", "none"])
    assert code == 2 and not out.exists()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "plain harmonic map" in lines[0] and "Traceback" not in err
    for method in ("bem", "mfs"):
        code, err = run_cli([inp, "--src", src, "--dst", dst, out, "--theta", "none", "--method", method])
        assert code == 2 and len(err.strip().splitlines()) == 1 and "--method fem" in err and not out.exists()


def test_a_certified_straight_map_is_one_to_one_by_brute_force():
    """The degree argument, checked independently: every sample point of the target lies in
    exactly one image triangle (barycentric tests against every triangle), none outside."""
    src, dst = l_shape(), l_shape() + [4.0, 6.0]
    dst[4] += [6.0, 6.0]  # not affine
    f = straight(src, dst)
    phi = f.phi0
    tri = phi.values[phi.mesh.triangles]  # (M, 3, 2)
    rng = np.random.default_rng(0)
    lo, hi = dst.min(axis=0), dst.max(axis=0)
    q = rng.uniform(lo, hi, (400, 2))
    from skimage.measure import points_in_poly  # an independent inside test

    inside = points_in_poly(q, dst)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    d = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    rel = q[:, None, :] - a[None]
    l1 = (rel[..., 0] * (c[:, 1] - a[:, 1]) - rel[..., 1] * (c[:, 0] - a[:, 0])) / d
    l2 = ((b[:, 0] - a[:, 0]) * rel[..., 1] - (b[:, 1] - a[:, 1]) * rel[..., 0]) / d
    count = ((l1 > 1e-12) & (l2 > 1e-12) & (1 - l1 - l2 > 1e-12)).sum(axis=1)
    assert (count[~inside] == 0).all()
    assert (count[inside] <= 1).all() and (count[inside] == 1).mean() > 0.97  # the rest lie on edges


def test_the_straight_map_takes_the_whole_pipeline(tmp_path):
    """Report, grid, heatmap and STMaps take it as any map; f^-1 of the boundary is the source's."""
    src = write_polygon(tmp_path / "src.json", l_shape())
    dst = write_polygon(tmp_path / "dst.json", l_shape(notch=0.45) + [3.0, -2.0])
    inp = write_png(tmp_path / "in.png", (np.random.default_rng(0).random((128, 128, 3)) * 255).astype(np.uint8))
    out, rep = tmp_path / "out.png", tmp_path / "r.json"
    extra = ["--grid", tmp_path / "g.png", "--heatmap", tmp_path / "h.png", "--save-map", tmp_path / "m.exr"]
    code, err = run_cli([inp, "--src", src, "--dst", dst, out, "--theta", "none", "--report", rep, *extra])
    assert code == 0, err
    doc = json.loads(rep.read_text())
    assert doc["flipped_triangles"] == 0 and doc["target_map"] == "identity" and doc["conformal"]["mean"] >= 2.0
    assert read_pixels(out).shape[:2] == (128, 128) and all(p.exists() for p in extra[1::2])
    code, err = run_cli([inp, "--src", src, "--dst", dst, tmp_path / "o2.png", "--theta", "none", "--save-theta", tmp_path / "t.json"])
    assert code == 2 and "--save-theta" in err and not (tmp_path / "t.json").exists()


def test_optimized_keeps_the_straight_map_where_it_is_best_and_drops_it_where_it_folds():
    img = np.zeros((128, 128, 1), dtype=np.float32)
    # A slightly moved L: the straight map is nearly conformal, no convex Theta comes close.
    src, dst = Polygon(l_shape()), Polygon(l_shape(notch=0.45) + [2.0, 1.0])
    res = warp_image(img, src, dst, map=MapOptions(theta="optimized", max_area=AREA))
    notes = build_report(res)["theta"]
    assert notes["kept"] == "none" and res.map.flipped_triangles() == 0
    plain = warp_image(img, src, dst, map=MapOptions(theta="none", max_area=AREA))
    np.testing.assert_array_equal(res.pull.full_points(), plain.pull.full_points())
    assert notes["none"] <= min(notes["before"], notes["after"])
    # A sharp star: the straight map folds, the candidate is dropped, the result is certified.
    src, dst = Polygon(star(5, r_in=50.0)), Polygon(star(5, r_in=12.0))
    res = warp_image(img, src, dst, map=MapOptions(theta="optimized", max_area=AREA))
    notes = build_report(res)["theta"]
    assert notes["none"] is None and notes["kept"] != "none" and res.map.flipped_triangles() == 0


def test_a_kept_straight_map_that_folds_on_the_run_s_mesh_falls_back_to_the_convex_theta(monkeypatch):
    """The optimizer certifies the straight map at the run's density without a region; should the
    run's mesh differ (graded from a far smaller image) and fold it, `build_map` takes the best
    convex candidate the optimizer kept beside it."""
    from warpcli.maps import compose
    from warpcli.maps.theta import TargetTheta, regular_polygon

    src, dst = Polygon(star(5, r_in=50.0)), Polygon(star(5, r_in=12.0))  # the straight map folds here
    notes = {"kept": "none", "fallback": regular_polygon(10).tolist(), "fallback_name": "regular", "fallback_after": 3.0}
    monkeypatch.setattr(compose, "theta_for", lambda s, d, o: TargetTheta(d.points, name="optimized", notes=notes))
    f = compose.build_map(src, dst, MapOptions(theta="optimized", max_area=AREA))
    assert not isinstance(f.theta, TargetTheta) and f.theta.same_as(compose.Theta(regular_polygon(10)))
    assert f.theta.notes["kept"] == "regular" and f.flipped_triangles() == 0
