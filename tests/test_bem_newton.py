"""BEM's inverse: the proved second-order step (`warpcli.maps.meshless.taylor_step`) and the tables it evaluates with."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import random_star

from warpcli.maps.bem_eval import _GAUSS01, gauss01
from warpcli.maps.meshless import taylor_step
from warpcli.maps.newton import thresholds


def test_gauss_tables_are_numpys_leggauss_bit_for_bit():
    for n in _GAUSS01:
        x, w = np.polynomial.legendre.leggauss(n)
        t, wt = gauss01(n)
        assert np.array_equal(t, 0.5 * (x + 1.0)) and np.array_equal(wt, 0.5 * w)
    x, w = np.polynomial.legendre.leggauss(7)  # not tabled: numpy's
    assert np.array_equal(gauss01(7)[0], 0.5 * (x + 1.0))


def _bem_map(seed, check=False):
    from warpcli import MapOptions, Polygon
    from warpcli.maps.registry import METHODS
    from warpcli.maps.theta import regular

    rng = np.random.default_rng(seed)
    poly = Polygon(random_star(rng))
    opts = MapOptions(method="bem", nodes=96, check=check)
    return METHODS["bem"].load().build(poly, regular(poly, poly, opts), opts, "source")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_taylor_step_proves_only_residuals_within_the_tolerance(seed):
    """Starts at generated distances (1e-7 to 0.3 px) from pre-images of generated points: every point
    the step calls converged has phi(y) within Newton's tolerance of its target (phi evaluated
    directly), and its Jacobian is phi's there to ~(|d| / rho)^2; close starts are proved (the
    step is not vacuous), far ones are not claimed."""
    phi = _bem_map(seed)
    rng = np.random.default_rng(seed + 10)
    V = phi.polygon.points
    lo, hi = V.min(axis=0), V.max(axis=0)
    p = lo + rng.random((3000, 2)) * (hi - lo)
    p = p[phi._inside_polygon(p)][:400]
    q = phi.solution.value(p)
    scale = 10.0 ** rng.uniform(-7, -0.5, len(p))
    ang = rng.uniform(0, 2 * np.pi, len(p))
    y0 = p + scale[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    keep = phi._inside_polygon(y0)
    p, q, y0, scale = p[keep], q[keep], y0[keep], scale[keep]
    thresh, _ = thresholds(q, 1e-12, None)
    rho = phi._distance_below(y0)
    y, done, jac = taylor_step(phi.solution, q, y0, rho, phi._value_spread, thresh)
    assert done.any() and not done.all()
    got = phi.solution.value(y[done])
    assert np.hypot(*(q[done] - got).T).max() <= thresh
    ref = phi.solution.jacobian(y[done])
    assert np.abs(jac[done] - ref).max() <= 1e-8 * np.abs(ref).max()
    assert done[scale < 1e-5].mean() > 0.9
    assert not done[scale > 0.1].any()


def test_runs_are_evenly_spaced_pixels_of_one_row():
    """`_runs` on generated rows of pixel centres mapped by a smooth map, with pixels left out: in
    every run the row is one and the columns evenly spaced (the interpolation's index is the
    pixel's position), and a stretch of 3 or more consecutive pixels is one run but for its first
    (which may end the run before it, where the spacing changes)."""
    from warpcli.maps.meshless import _runs

    rng = np.random.default_rng(5)
    rows, cols = [], []
    for r in range(30):
        c = np.arange(int(rng.integers(1, 40)))
        c = c[rng.random(len(c)) > rng.choice([0.05, 0.3, 0.5])]  # pixels left out
        rows.append(np.full(len(c), r))
        cols.append(c)
    row, col = np.concatenate(rows), np.concatenate(cols)
    x, y = col + 0.5, row + 0.5
    q = np.stack([x + 0.01 * y**2 + 0.002 * x**2, y + 0.003 * x * y], axis=1)
    run, pos, last = _runs(q)
    for r in np.unique(run):
        k = np.flatnonzero(run == r)
        assert np.array_equal(k, np.arange(k[0], k[0] + len(k)))
        assert (pos[k] == np.arange(len(k))).all() and (last[k] == len(k) - 1).all()
        assert (row[k] == row[k[0]]).all() and len(set(np.diff(col[k]))) <= 1
    new = np.r_[True, (row[1:] != row[:-1]) | (col[1:] != col[:-1] + 1)]
    stretch = np.cumsum(new) - 1
    for s in np.flatnonzero(np.bincount(stretch) >= 3):
        k = np.flatnonzero(stretch == s)
        assert (run[k[1:]] == run[k[1]]).all()


@pytest.mark.parametrize("seed", [0, 3])
def test_coherent_starts_find_the_same_pre_images(seed):
    """BEM's inverse of a pixel grid's values with ``coherent=True`` (first guesses located for a
    quarter of each row, interpolated between) finds the same points as without, to Newton's
    tolerance, with the same NaNs and Jacobians to the proved step's accuracy."""
    phi = _bem_map(seed)
    V = phi.polygon.points
    lo, hi = np.floor(V.min(axis=0)), np.ceil(V.max(axis=0))
    X, Y = np.meshgrid(np.arange(lo[0], hi[0]) + 0.5, np.arange(lo[1], hi[1]) + 0.5)
    p = np.stack([X.ravel(), Y.ravel()], axis=1)
    p = p[phi._inside_polygon(p)]
    q = phi.evaluate(p).points
    a = phi.inverse(q, jacobian=True, coherent=True)
    b = phi.inverse(q, jacobian=True)
    fa, fb = np.isfinite(a.points).all(axis=1), np.isfinite(b.points).all(axis=1)
    assert np.array_equal(fa, fb) and fa.sum() > 0.9 * len(q)
    assert np.abs(a.points[fa] - b.points[fa]).max() < 1e-6
    assert np.abs(a.jacobian[fa] - b.jacobian[fa]).max() <= 1e-7 * np.abs(b.jacobian[fa]).max()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_value_spread_holds_inside_gamma(seed):
    """`taylor_step`'s bound D rests on the maximum principle inside Gamma: for a map the certificate
    accepts, the closed form's values at generated points farther from the boundary than the
    collar's band lie in Theta's bounding box (the spread's centre +- D, D with its margin removed),
    and `_distance_below` keeps every start's disc that far from the boundary."""
    from warpcli.maps.meshless import _nearest_within

    phi = _bem_map(seed, check=True)
    rng = np.random.default_rng(seed + 20)
    V = phi.polygon.points
    lo, hi = V.min(axis=0), V.max(axis=0)
    p = lo + rng.random((20000, 2)) * (hi - lo)
    p = p[phi._inside_polygon(p)]
    cand, _, _, dist = _nearest_within(p, V, phi._polygon_xy, np.inf)
    d = np.full(len(p), np.inf)
    d[cand] = dist
    inside_gamma = p[d > phi._band_width]
    u = phi.solution.value(inside_gamma)
    T = phi.theta.points
    centre, half = 0.5 * (T.min(axis=0) + T.max(axis=0)), 0.5 * np.ptp(T, axis=0)
    assert (np.abs(u - centre) <= half * (1 + 1e-9)).all()
    assert np.allclose(phi._value_spread, 1.1 * half)
    rho = phi._distance_below(p)
    assert (rho <= np.maximum(d - phi._band_width, 0.0)).all()
