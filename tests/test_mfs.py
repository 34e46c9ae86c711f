"""The method of fundamental solutions (paper §3.1.3): `warpcli.maps.mfs`, and its agreement with BEM."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from warpcli.grid import inside_polygon as points_in_polygon
from warpcli.maps.bem import fit_bem
from warpcli.maps.closed_form import distance_to_boundary
from warpcli.maps.mfs import fit_mfs

from helpers import random_star, simple_polygons

# -- shapes -----------------------------------------------------------------


def lshape() -> np.ndarray:
    return np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]])


def star(n: int = 6) -> np.ndarray:
    th = np.pi / 2 + np.pi * np.arange(2 * n) / n
    r = np.where(np.arange(2 * n) % 2 == 0, 1.0, 0.45)
    return np.stack([r * np.cos(th), r * np.sin(th)], axis=1)


def cshape() -> np.ndarray:
    """A C with a narrow slot: outward offsets of the slot's walls cross the polygon."""
    return np.array([[0, 0], [3, 0], [3, 1.3], [0.8, 1.3], [0.8, 1.7], [3, 1.7], [3, 3], [0, 3.0]])


def shape(name: str, orientation: int, offset: float) -> np.ndarray:
    base = {"L": lshape, "star": star, "C": cshape}[name]()
    return base[::orientation] + offset


def orientation_of(vertices: np.ndarray) -> float:
    v = vertices - vertices.mean(axis=0)
    return float(np.sign(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])))


def ngon_targets(vertices: np.ndarray) -> np.ndarray:
    """Regular n-gon of circumradius 1 with the orientation of ``vertices``."""
    n = len(vertices)
    th = 2 * np.pi * np.arange(n) / n * orientation_of(vertices)
    return np.stack([np.cos(th), np.sin(th)], axis=1)


def grid_inside(vertices: np.ndarray, n: int, margin: float = 0.0) -> np.ndarray:
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    g = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(lo[0] + g * (hi[0] - lo[0]), lo[1] + g * (hi[1] - lo[1]))
    q = np.stack([X.ravel(), Y.ravel()], axis=1)
    q = q[points_in_polygon(q, vertices)]
    return q[distance_to_boundary(q, vertices) > max(margin, 1e-9) * np.max(hi - lo)]


def boundary_samples(vertices: np.ndarray, targets: np.ndarray, per_edge: int):
    """Points along every edge and the boundary data b there."""
    t = (np.arange(per_edge) + 0.5) / per_edge
    n = len(vertices)
    pts = np.concatenate([vertices[i] + t[:, None] * (vertices[(i + 1) % n] - vertices[i]) for i in range(n)])
    data = np.concatenate([(1 - t)[:, None] * targets[i] + t[:, None] * targets[(i + 1) % n] for i in range(n)])
    return pts, data


# -- exactness ----------------------------------------------------------------


@pytest.mark.parametrize("name", ["L", "star"])
@pytest.mark.parametrize("orientation", [1, -1])
@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_affine_data_give_the_affine_map(name, orientation, offset):
    P = shape(name, orientation, offset)
    A = np.array([[0.7, -1.3], [0.4, 2.1]])
    c = np.array([3.0, -5.0])
    T = P @ A.T + c
    sol = fit_mfs(P, T, m=96)
    size = np.ptp(P, axis=0).max()
    q = grid_inside(P, 25)
    v, J = sol.value_and_jacobian(q)
    tol = 1e-6 * np.abs(A).max() * size + 4 * np.finfo(float).eps * np.abs(T).max()
    assert np.abs(v - (q @ A.T + c)).max() <= tol
    assert np.abs(J - A).max() <= 1e-6 * np.abs(A).max()
    np.testing.assert_array_equal(sol.value(q), v)
    np.testing.assert_array_equal(sol.jacobian(q), J)


def test_triangle_map_is_affine():
    P = np.array([[0.0, 0.0], [3.0, 1.0], [1.0, 2.5]]) + 1e6
    T = np.array([[1.0, 0.0], [-0.5, 0.8], [-0.5, -0.8]])
    M = np.linalg.solve((P - P[0])[1:], (T - T[0])[1:]).T
    sol = fit_mfs(P, T, m=64)
    q = grid_inside(P, 20)
    assert np.abs(sol.value(q) - (T[0] + (q - P[0]) @ M.T)).max() < 1e-9
    assert np.abs(sol.jacobian(q) - M).max() < 1e-7
    assert sol.residual < 1e-9


@pytest.mark.parametrize("name", ["L", "star", "C"])
@pytest.mark.parametrize("orientation", [1, -1])
def test_sites_lie_outside_and_clear_of_the_polygon(name, orientation):
    P = shape(name, orientation, 1e6)
    sol = fit_mfs(P, ngon_targets(P), m=200)
    local = (P - sol.frame.centre) / sol.frame.scale
    assert sol.sites.shape == (200, 2) and sol.m == 200 and sol.k >= 4 * 200
    assert not points_in_polygon(sol.sites, local).any()
    assert distance_to_boundary(sol.sites, local).min() > 0


# -- agreement and accuracy ---------------------------------------------------


@pytest.mark.parametrize("name", ["L", "star"])
@pytest.mark.parametrize("orientation", [1, -1])
def test_bem_and_mfs_agree_away_from_the_boundary(name, orientation):
    P = shape(name, orientation, 1e6)
    T = ngon_targets(P)  # Theta: regular n-gon of circumradius 1
    q = grid_inside(P, 40, margin=0.05)
    bem = fit_bem(P, T, m=192)
    mfs = fit_mfs(P, T, m=192)
    vb, Jb = bem.value_and_jacobian(q)
    vm, Jm = mfs.value_and_jacobian(q)
    assert np.abs(vb - vm).max() < 1e-3  # brief: 1e-3 relative to Theta; measured ~1e-5
    assert np.abs(vb - vm).max() < 1e-4
    assert np.abs(Jb - Jm).max() < 1e-3 * np.abs(Jb).max()


@pytest.mark.parametrize("name", ["L", "star"])
@pytest.mark.parametrize("orientation", [1, -1])
def test_jacobian_determinant_is_positive(name, orientation):
    """Both maps are practically bijective (paper §3.1.4) onto a regular n-gon of matching orientation."""
    P = shape(name, orientation, 1e6)
    T = ngon_targets(P)
    q = grid_inside(P, 120)  # ~5-9k points, down to ~1e-4 of the size from the boundary
    for fit in (fit_bem, fit_mfs):
        J = fit(P, T, m=128).jacobian(q)
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        assert det.min() > 0, fit.__name__


def test_boundary_deviation_shrinks_as_m_grows():
    P = star() + 1e6
    T = ngon_targets(P)
    pts, data = boundary_samples(P, T, 60)
    dev = [np.abs(fit_mfs(P, T, m=m).value(pts) - data).max() for m in (96, 192, 384)]
    assert dev[0] > 2 * dev[1] > 4 * dev[2]
    assert dev[2] < 1e-3


def test_hessian_matches_finite_differences():
    P = star()[::-1]
    sol = fit_mfs(P, ngon_targets(P), m=128)
    q = grid_inside(P, 12, margin=0.05)
    H = sol.hessian(q)
    h = 1e-5
    fd = np.stack([(sol.jacobian(q + h * e) - sol.jacobian(q - h * e)) / (2 * h) for e in np.eye(2)], axis=-1)
    assert np.abs(H - fd).max() < 1e-5 * np.abs(H).max()
    assert np.abs(H[:, :, 0, 0] + H[:, :, 1, 1]).max() < 1e-10 * np.abs(H).max()
    fdj = np.stack([(sol.value(q + h * e) - sol.value(q - h * e)) / (2 * h) for e in np.eye(2)], axis=-1)
    J = sol.jacobian(q)
    assert np.abs(J - fdj).max() < 1e-6 * np.abs(J).max()
    moved = fit_mfs(P * 1e-3 + 1e6, ngon_targets(P), m=128)
    np.testing.assert_allclose(moved.hessian(q * 1e-3 + 1e6) * 1e-6, H, atol=1e-5 * np.abs(H).max())
    np.testing.assert_allclose(moved.jacobian(q * 1e-3 + 1e6) * 1e-3, J, atol=1e-6 * np.abs(J).max())


def test_deterministic_and_validated():
    P = lshape()
    T = ngon_targets(P)
    q = grid_inside(P, 10)
    a, b = fit_mfs(P, T, m=64), fit_mfs(P, T, m=64)
    np.testing.assert_array_equal(a.value(q), b.value(q))
    with pytest.raises(ValueError):
        fit_mfs(P, T, m=3)
    with pytest.raises(ValueError):
        fit_mfs(P, T, m=64, k=50)
    with pytest.raises(ValueError):
        fit_mfs(P, T[:-1])
    assert a.value(np.zeros((0, 2))).shape == (0, 2)
    assert a.hessian(np.array([0.5, 0.5])).shape == (1, 2, 2, 2)


def test_the_map_interface_gives_the_hessian_inside_and_nan_elsewhere():
    """SmoothMap.hessian: the closed form's second derivatives, equal to finite differences of
    the Jacobian that `evaluate` returns; NaN outside the polygon and on its boundary."""
    from warpcli import MapOptions, Polygon
    from warpcli.maps.registry import METHODS
    from warpcli.maps.theta import regular

    poly = Polygon(np.array([[0, 0], [100, 0], [100, 40], [40, 40], [40, 100], [0, 100]], float))
    opts = MapOptions(method="mfs")
    phi = METHODS["mfs"].load().build(poly, regular(poly, poly, opts), opts, "source")
    q = np.array([[20.0, 20.0], [70.0, 20.0], [20.0, 70.0]])
    H = phi.hessian(q)
    h = 1e-3
    for b in range(2):
        step = np.zeros(2)
        step[b] = h
        fd = (phi.evaluate(q + step, jacobian=True).jacobian - phi.evaluate(q - step, jacobian=True).jacobian) / (2 * h)
        np.testing.assert_allclose(H[:, :, :, b], fd, atol=1e-6 * np.abs(H).max() + 1e-9)
    np.testing.assert_allclose(np.trace(H, axis1=2, axis2=3), 0.0, atol=1e-9 * np.abs(H).max())  # harmonic
    assert np.isnan(phi.hessian([[70.0, 70.0], [50.0, 0.0], [np.nan, 1.0]])).all()


# -- the number of nodes: bounded below by the vertices, above by memory and time (issue 27) --


def _regular(n: int, r: float = 50.0) -> np.ndarray:
    t = 2 * np.pi * np.arange(n) / n
    return np.stack([60 + r * np.cos(t), 60 + r * np.sin(t)], axis=1)


@pytest.mark.parametrize("method", ["bem", "mfs"])
@pytest.mark.parametrize("n", [5, 17, 60, 301])
def test_nodes_below_the_vertex_count_are_one_line_exit_2(tmp_path, method, n):
    from helpers import run_cli, write_png, write_polygon

    img = write_png(tmp_path / "in.png", np.zeros((120, 120, 3), dtype=np.uint8))
    poly = write_polygon(tmp_path / "p.json", _regular(n))
    for nodes in sorted({3, n // 2 + 1, n - 1} - {n}):
        if nodes < 3:
            continue
        code, err = run_cli([img, tmp_path / "out.png", "--src", poly, "--dst", poly, "--method", method, "--nodes", str(nodes)])
        assert code == 2 and err.count("\n") == 1 and f"--nodes {nodes} is fewer than its {n} vertices" in err, err
        assert not (tmp_path / "out.png").exists()


@pytest.mark.parametrize("method", ["bem", "mfs"])
@pytest.mark.parametrize("budget", [10**6, 10**8, 10**10])
def test_nodes_beyond_memory_are_refused_before_fitting(monkeypatch, method, budget):
    from warpcli import MapOptions, Polygon
    from warpcli.errors import InputError
    from warpcli.maps import meshless

    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", str(budget))
    entry = meshless.BEM if method == "bem" else meshless.MFS
    most = entry.most_nodes()
    # the bound is the memory model's: the largest m with bytes(m) <= budget
    assert entry.fit_bytes(most) <= budget < entry.fit_bytes(most + 1)
    poly = Polygon(_regular(8))
    monkeypatch.setattr(entry, "_fit", lambda *a, **k: pytest.fail("fitted"))
    for nodes in (most + 1, 2 * most + 7, 100_000):
        with pytest.raises(InputError, match=rf"--nodes {nodes}: an? {method.upper()} fit .* more than"):
            entry.build(poly, None, MapOptions(method=method, nodes=nodes))
    if most >= 8:
        assert entry.nodes_for(poly, most) == most


@pytest.mark.parametrize("n", [3, 100, 256, 257, 600, 5000])
def test_the_default_nodes_are_capped(monkeypatch, caplog, n):
    from warpcli import Polygon
    from warpcli.maps import meshless

    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", str(10**12))
    poly = Polygon(_regular(n, 1000.0))
    m = meshless.MFS.nodes_for(poly, None)
    if 8 * n <= meshless.MAX_AUTO_NODES:
        assert m is None  # the fit's own default, max(256, 8 n)
    else:
        assert m == max(meshless.MAX_AUTO_NODES, n) and "--nodes chooses m" in caplog.text


def test_a_polygon_with_more_vertices_than_memory_allows_nodes_is_refused(monkeypatch):
    from warpcli import Polygon
    from warpcli.errors import InputError
    from warpcli.maps import meshless

    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", str(300 * 99**2))
    with pytest.raises(InputError, match="100 vertices need at least 100 MFS sites"):
        meshless.MFS.nodes_for(Polygon(_regular(100)), None)


@pytest.mark.parametrize("cap", [300, 512, 1000])
def test_refits_of_a_folding_map_stay_within_the_cap(monkeypatch, caplog, cap):
    # A certificate that always fails: the refits double m from the default
    # and stop before passing the cap; the map is then refused by the
    # certificate (in one line, elsewhere), never fitted beyond it.
    from warpcli import MapOptions, Polygon
    from warpcli.maps import meshless
    from warpcli.maps.base import Certificate
    from warpcli.maps.theta import regular

    monkeypatch.setattr(meshless, "MAX_AUTO_NODES", cap)
    fitted = []
    real = meshless._Method._fit

    def fit(self, polygon, theta, m, boundary, free):
        fitted.append(m)
        return real(self, polygon, theta, m, boundary, free)

    monkeypatch.setattr(meshless._Method, "_fit", fit)
    monkeypatch.setattr(meshless.SmoothMap, "certify", lambda self: Certificate(1, 10, "samples"))
    poly = Polygon(_regular(7))
    opts = MapOptions(method="mfs")
    phi = meshless.MFS.build(poly, regular(poly, poly, opts), opts)
    ms = [256 if m is None else m for m in fitted]
    assert ms == [256 * 2**k for k in range(len(ms))] and ms[-1] <= cap < 2 * ms[-1]
    assert phi.solution.m == ms[-1]


@pytest.mark.parametrize("method", ["mfs", "bem"])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_inverse_jacobian_is_the_maps_at_the_pre_images_found(method, seed):
    """`SmoothMap.inverse` takes phi's Jacobian from Newton's own evaluations (issue 24); the former
    route, a pass of `evaluate` at the pre-images, is the reference: same points, same NaNs, and
    the Jacobians of the inverse agree to rounding (MFS), or for BEM, whose Newton takes most points
    after one proved second-order step (`warpcli.maps.meshless.taylor_step`) with the Jacobian J + H d
    of that step's expansion, to its third-order term (|d| / rho)^2: 1e-8 here. Generated star-shaped
    polygons."""
    from warpcli import MapOptions, Polygon
    from warpcli.maps.base import inv2
    from warpcli.maps.registry import METHODS
    from warpcli.maps.theta import regular

    rng = np.random.default_rng(seed)
    poly = Polygon(random_star(rng))
    opts = MapOptions(method=method, nodes=96, check=False)
    phi = METHODS[method].load().build(poly, regular(poly, poly, opts), opts, "source")
    g = (np.arange(24) + 0.5) / 24
    X, Y = np.meshgrid(g, g)
    q = phi.theta.points.min(axis=0) + np.stack([X.ravel(), Y.ravel()], 1) * np.ptp(phi.theta.points, axis=0)
    q = np.concatenate([q, phi.theta.points[:2], [[np.nan, 0.0]]])  # vertices of Theta and a NaN too
    got = phi.inverse(q, jacobian=True)
    plain = phi.inverse(q)
    assert np.array_equal(got.points, plain.points, equal_nan=True)
    ref = np.full((len(q), 2, 2), np.nan)
    ok = np.isfinite(got.points).all(axis=1)
    ref[ok] = inv2(phi.evaluate(got.points[ok], jacobian=True).jacobian)
    assert np.array_equal(np.isnan(got.jacobian), np.isnan(ref))
    fin = np.isfinite(ref)
    assert fin.sum() > 100
    close = 1e-10 if method == "mfs" else 1e-8
    assert np.abs(got.jacobian[fin] - ref[fin]).max() <= close * np.abs(ref[fin]).max()


@pytest.mark.parametrize("seed", range(6))
def test_least_squares_are_scipys_bit_for_bit(seed):
    """`closed_form.lstsq` calls LAPACK's gelsd without importing scipy.linalg: the same bits as
    ``scipy.linalg.lstsq(..., lapack_driver="gelsd")``, tall and square, one or several right-hand
    sides, rank-deficient, with and without a cut-off; NaN refused as scipy refuses it."""
    import scipy.linalg

    from warpcli.maps.closed_form import lstsq

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    m = n + int(rng.integers(0, 60))
    A = rng.normal(size=(m, n)) * 10.0 ** rng.uniform(-3, 3, n)
    if seed % 2:
        A[:, -1] = A[:, 0]  # rank-deficient
    b = rng.normal(size=(m, 3)) if seed % 3 else rng.normal(size=m)
    for cond in (None, 1e-12, 1e-3):
        want = scipy.linalg.lstsq(A, b, cond=cond, lapack_driver="gelsd")[0]
        got = lstsq(A, b, cond)
        assert got.shape == want.shape and np.array_equal(got, want)
    A[0, 0] = np.nan
    with pytest.raises(ValueError):
        lstsq(A, b)


def test_a_meshless_fit_does_not_import_scipy_linalg():
    """scipy.linalg's import (numpy.testing, unittest, ...) is 0.17 s of a 1 MP MFS warp: a fit does without it."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "from warpcli.maps.mfs import fit_mfs\n"
        "sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])\n"
        "fit_mfs(sq, sq * 2.0, 16)\n"
        "print(sorted(m for m in sys.modules if m.startswith('scipy')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "'scipy.linalg'" not in out and "scipy.linalg._flapack" in out


def test_the_grid_path_of_a_smooth_map_is_the_default_one():
    """A smooth map's pixel-grid evaluation (its compiled even-odd test, `SmoothMap._inside_polygon`) gives
    what `ThetaMap.evaluate_grid` defines: phi at the centres `warpcli.grid.inside_polygon` keeps, with
    edges and vertices through pixel centres (where "inside" is decided by the test's arithmetic)."""
    from warpcli import MapOptions, Polygon
    from warpcli.grid import inside_polygon, pixel_centres
    from warpcli.maps.compose import theta_for
    from warpcli.maps.meshless import MFS

    v = np.array([[2.5, 2.5], [30.5, 2.5], [30.5, 14.5], [16.5, 16.5], [14.5, 29.5], [2.5, 29.5]])
    poly = Polygon(v, name="p")
    opts = MapOptions(method="mfs", nodes=32)
    phi = MFS.build(poly, theta_for(poly, poly, opts), opts)
    got = phi.evaluate_grid(33, 32)
    centres = pixel_centres(33, 32, (0, 32))
    keep = np.flatnonzero(inside_polygon(centres, v))
    want = phi.evaluate(centres[keep])
    ok = np.isfinite(want.points[:, 0])
    assert np.array_equal(got.pixels, keep[ok]) and got.values.tobytes() == want.points[ok].tobytes()


@settings(max_examples=15, deadline=None)
@given(simple_polygons(7), st.floats(1e-9, 3.0), st.integers(0, 2**31))
def test_the_pull_backs_nearest_edges_are_boundarys_bit_for_bit(poly, reach, seed):
    """The pull-back asks `boundary.nearest_edge` only of the points its compiled filter
    (`_smooth_kernels.near_boundary`) keeps (issue 24): those are a superset of the points within
    reach, and nearest_edge of them alone gives what it gives them among all points, so indices,
    edges, parameters and distances are nearest_edge's on every point, bit for bit. Generated
    polygons; points near and on the edges and vertices, far away, NaN."""
    from warpcli.boundary import nearest_edge, on_boundary
    from warpcli.maps.meshless import _columns, _nearest_within, _on_boundary

    rng = np.random.default_rng(seed)
    k = rng.integers(0, len(poly), 600)
    t = rng.random(600)
    t[::5] = 0.0  # vertices
    on = poly[k] + t[:, None] * (np.roll(poly, -1, axis=0)[k] - poly[k])
    step = rng.normal(size=(600, 2)) * reach * rng.choice([0.0, 0.5, 1.0, 1.000001, 2.0], (600, 1))
    p = np.concatenate([on + step, rng.uniform(-10.0, 140.0, (400, 2)), [[np.nan, 1.0], [1.0, np.nan]]])
    edge, par, dist = nearest_edge(p, poly)
    within = np.flatnonzero(dist <= reach)
    cand, e2, t2, d2 = _nearest_within(p, poly, _columns(poly), reach)
    assert set(within) <= set(cand)
    assert e2.tobytes() == edge[cand].tobytes() and t2.tobytes() == par[cand].tobytes()
    assert d2.tobytes() == dist[cand].tobytes()
    want = on_boundary(p, poly, reach)
    got = _on_boundary(p, poly, _columns(poly), reach)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(got, want))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_coherent_inverse_finds_the_plain_ones_pre_images(seed):
    """`SmoothMap.inverse(coherent=True)` of an MFS map starts Newton from the extrapolated pre-images
    of the points before (`_steady` runs: rows of a grid) rather than from the first guess (issue 24):
    every pre-image the plain inverse finds it finds too, to Newton's tolerance, with phi(y) = q
    checked by `evaluate`, and the same points without one; rows of different lengths, repeated
    points, jumps, points outside Theta. Generated star-shaped polygons."""
    from warpcli import MapOptions, Polygon
    from warpcli.maps.meshless import MFS
    from warpcli.maps.theta import regular

    rng = np.random.default_rng(seed)
    poly = Polygon(random_star(rng))
    opts = MapOptions(method="mfs", nodes=96, check=False)
    phi = MFS.build(poly, regular(poly, poly, opts), opts, "source")
    lo, span = phi.theta.points.min(axis=0), np.ptp(phi.theta.points, axis=0)
    rows = []
    for y in np.linspace(-0.05, 1.05, 23):  # rows running out of Theta at both ends
        x = np.linspace(-0.05, 1.05, int(rng.integers(20, 60)))
        rows.append(lo + np.stack([x, np.full_like(x, y)], axis=1) * span)
    q = np.concatenate(rows + [rows[3][:5], rows[3][:5], rows[7][::-1]])  # a repeat, a row backwards
    q[::41] = q[::41][::-1]  # jumps
    got = phi.inverse(q, jacobian=True, coherent=True)
    plain = phi.inverse(q, jacobian=True)
    ok = np.isfinite(plain.points).all(axis=1)
    assert ok.sum() > 300
    assert np.array_equal(np.isfinite(got.points).all(axis=1), ok)
    assert np.abs(got.points[ok] - plain.points[ok]).max() <= 1e-8 * phi._size
    inside = ok & (phi.collar.inside(np.where(ok[:, None], got.points, 0.0)) if phi.collar is not None else ok)
    back = phi.evaluate(got.points[inside]).points
    assert np.abs(back - q[inside]).max() <= 1e-9 * span.max()
    fin = np.isfinite(plain.jacobian)
    assert np.array_equal(fin, np.isfinite(got.jacobian))
    assert np.abs(got.jacobian[fin] - plain.jacobian[fin]).max() <= 1e-6 * np.abs(plain.jacobian[fin]).max()


def test_steady_runs_are_evenly_spaced_targets():
    """`_steady` keeps a point when the three steps before it are nearly equal (a row of pixels),
    and only then: a row's first three points, and three after a jump, start from the first guess."""
    from warpcli.maps.meshless import _steady

    row = np.stack([np.linspace(0.0, 1.0, 10), np.linspace(0.0, 0.2, 10) ** 2], axis=1)
    q = np.concatenate([row, row + [0.0, 1.0]])
    got = _steady(q)
    want = np.ones(len(q), dtype=bool)
    want[[0, 1, 2, 10, 11, 12]] = False
    assert np.array_equal(got, want)
    assert not _steady(q[:3]).any() and _steady(np.zeros((5, 2)))[3:].all()
