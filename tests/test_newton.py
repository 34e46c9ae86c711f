"""Pointwise inversion by damped Newton (paper §3.2): `warpcli.maps.newton`."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli.grid import inside_polygon as points_in_polygon
from warpcli.maps.closed_form import distance_to_boundary
from warpcli.maps.mfs import fit_mfs
from warpcli.maps.newton import invert


def star(n: int = 6) -> np.ndarray:
    th = np.pi / 2 + np.pi * np.arange(2 * n) / n
    r = np.where(np.arange(2 * n) % 2 == 0, 1.0, 0.45)
    return np.stack([r * np.cos(th), r * np.sin(th)], axis=1)


def test_inverse_of_forward_is_identity_for_the_mfs_map_on_a_star():
    P = star() * 50.0 + 1e6
    n = len(P)
    th = 2 * np.pi * np.arange(n) / n
    sol = fit_mfs(P, np.stack([np.cos(th), np.sin(th)], axis=1), m=128)
    size = np.ptp(P, axis=0).max()
    lo, hi = P.min(axis=0), P.max(axis=0)
    g = (np.arange(40) + 0.5) / 40
    X, Y = np.meshgrid(lo[0] + g * (hi[0] - lo[0]), lo[1] + g * (hi[1] - lo[1]))
    p = np.stack([X.ravel(), Y.ravel()], axis=1)
    p = p[points_in_polygon(p, P) & (distance_to_boundary(p, P) > 0.02 * size)]
    x = sol.value(p)
    # first guesses: the points moved by up to 2% of the size, kept inside
    shift = 0.02 * size * np.stack([np.cos(7.0 * np.arange(len(p))), np.sin(7.0 * np.arange(len(p)))], axis=1)
    guess = np.where(points_in_polygon(p + shift, P)[:, None], p + shift, p)
    inside = lambda y: points_in_polygon(y, P)  # noqa: E731
    y, ok = invert(sol.value, sol.jacobian, x, guess, inside=inside)
    assert ok.all()
    assert np.abs(y - p).max() < 1e-8 * size
    assert inside(y).all()


def bulge(y):
    """A smooth bijection of the unit disc onto itself (radial profile r -> r (1 + r^2) / 2).

    Convex profile: a full Newton step from near the centre towards a target
    near the rim overshoots the disc, so the damping has to act.
    """
    r2 = np.sum(y * y, axis=1, keepdims=True)
    return y * 0.5 * (1.0 + r2)


def bulge_jac(y):
    r2 = np.sum(y * y, axis=1)
    return (0.5 * (1.0 + r2))[:, None, None] * np.eye(2) + y[:, :, None] * y[:, None, :]


def in_disc(y):
    return np.sum(y * y, axis=1) < 1.0


def test_damping_keeps_iterates_in_the_domain_and_converges():
    ang = np.linspace(0.0, 2 * np.pi, 50, endpoint=False)
    y_true = 0.97 * np.stack([np.cos(ang), np.sin(ang)], axis=1)  # close to the boundary
    x = bulge(y_true)
    guess = -0.1 * y_true  # far away, on the other side

    def guarded(y):  # "undefined" outside the domain: never evaluated there
        assert in_disc(y).all()
        return bulge(y)

    rejected = []

    def inside(y):
        mask = in_disc(y)
        rejected.append(int((~mask).sum()))
        return mask

    y, ok = invert(guarded, bulge_jac, x, guess, inside=inside, max_iter=50)
    assert ok.all()
    assert np.abs(y - y_true).max() < 1e-10
    assert sum(rejected) > 0  # the damping did act


def test_unreachable_targets_are_reported_not_converged():
    x = np.array([[2.0, 0.0], [0.3, 0.2]])  # the first is outside the image (the unit disc)
    y, ok = invert(bulge, bulge_jac, x, np.zeros((2, 2)) + 0.1, inside=in_disc)
    assert not ok[0] and ok[1]
    assert in_disc(y).all()
    np.testing.assert_allclose(bulge(y[1:]), x[1:], atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_hopeless_points_stop_and_the_others_iterate_bit_for_bit(seed):
    # generated targets in and out of the bulge's image (the unit disc), some hopeless by the
    # caller's word: those stop after `hopeless_after` iterations, not converged; every other
    # point's iterates, flag and Jacobian are those of the run without `hopeless`
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1.6, 1.6, size=(40, 2))
    guess = rng.uniform(-0.5, 0.5, size=(40, 2))
    far = np.hypot(*x.T) > 1.05  # no pre-image: these would run all their iterations
    asked = []

    def hopeless(t):
        asked.append(len(t))
        return np.hypot(*t.T) > 1.05

    fj = lambda y: (bulge(y), bulge_jac(y))  # noqa: E731
    y0, ok0, j0 = invert(bulge, bulge_jac, x, guess, inside=in_disc, fun_jac=fj, jacobian=True)
    y1, ok1, j1 = invert(bulge, bulge_jac, x, guess, inside=in_disc, fun_jac=fj, jacobian=True, hopeless=hopeless)
    assert len(asked) == 1 and asked[0] >= far.sum()  # asked once, about the points still iterating
    assert not ok0[far].any() and not ok1[far].any()
    np.testing.assert_array_equal(ok1, ok0)
    np.testing.assert_array_equal(y1[~far], y0[~far])
    np.testing.assert_array_equal(j1[~far], j0[~far])


def test_starting_outside_fails_and_exact_guesses_return_at_once():
    y0 = np.array([[0.2, 0.1], [1.5, 0.0]])
    calls = []

    def fun(y):
        calls.append(len(y))
        return bulge(y)

    y, ok = invert(fun, bulge_jac, bulge(y0[:1]).repeat(2, axis=0), y0, inside=in_disc)
    assert ok.tolist() == [True, False]
    np.testing.assert_array_equal(y, y0)
    assert calls == [1]  # one evaluation, at the one inside start
    y, ok = invert(bulge, bulge_jac, np.zeros((0, 2)), np.zeros((0, 2)))
    assert y.shape == (0, 2) and ok.shape == (0,)


def test_a_point_stuck_at_the_noise_floor_converges_within_the_floor_only():
    """A map evaluated with rounding noise above tol (a sum of large terms) cannot meet tol;
    with ``floor`` above the noise the stuck points converge, and only those within it."""
    from warpcli.maps.newton import invert

    rng = np.random.default_rng(0)
    A = np.array([[2.0, 0.3], [-0.4, 1.5]])

    def noisy(y):
        return y @ A.T + rng.uniform(-1e-10, 1e-10, y.shape)  # seeded noise, 100x tol

    x = rng.uniform(-1, 1, (200, 2))
    guess = x @ np.linalg.inv(A).T + 0.01
    _, ok = invert(noisy, lambda y: np.broadcast_to(A, (len(y), 2, 2)), x, guess, tol=1e-12)
    assert not ok.all()
    y, ok = invert(noisy, lambda y: np.broadcast_to(A, (len(y), 2, 2)), x, guess, tol=1e-12, floor=1e-9)
    assert ok.all()
    np.testing.assert_allclose(y, x @ np.linalg.inv(A).T, atol=1e-9)


def test_fused_evaluations_and_the_returned_jacobian_agree_with_separate_passes():
    # generated targets in the disc, starts scattered around them (the damping acts near the rim)
    rng = np.random.default_rng(11)
    y_true = rng.uniform(-0.7, 0.7, (300, 2))
    y_true = y_true[in_disc(y_true / 0.99)]
    x = bulge(y_true)
    guess = np.clip(y_true + rng.normal(0.0, 0.05, y_true.shape), -0.69, 0.69)
    calls = {"fun": 0, "jac": 0}

    def fun(y):
        calls["fun"] += 1
        return bulge(y)

    def jac(y):
        calls["jac"] += 1
        return bulge_jac(y)

    y0, ok0 = invert(fun, jac, x, guess, inside=in_disc)
    y1, ok1, j1 = invert(fun, jac, x, guess, inside=in_disc, jacobian=True)
    used = dict(calls)
    y2, ok2, j2 = invert(fun, jac, x, guess, inside=in_disc, fun_jac=lambda y: (bulge(y), bulge_jac(y)), jacobian=True)
    assert calls == used  # fused: neither fun nor jac called on their own
    assert ok0.all() and ok1.all() and ok2.all()
    assert np.array_equal(y0, y1)  # the Jacobian at the end does not change the iterates
    assert np.abs(y2 - y_true).max() < 1e-10 and np.abs(y1 - y_true).max() < 1e-10
    # the Jacobian returned is the map's at the last iterate (closed form, independent of invert)
    assert np.array_equal(j1, bulge_jac(y1))
    assert np.array_equal(j2, bulge_jac(y2))


def test_points_that_do_not_converge_get_no_jacobian():
    x = np.array([[0.2, 0.1], [5.0, 5.0]])  # the second has no pre-image in the disc
    y, ok, j = invert(bulge, bulge_jac, x, np.zeros((2, 2)), inside=in_disc, jacobian=True, max_iter=30)
    assert ok.tolist() == [True, False]
    assert np.isfinite(j[0]).all() and np.isnan(j[1]).all()
    _, _, j0 = invert(bulge, bulge_jac, np.zeros((0, 2)), np.zeros((0, 2)), jacobian=True)
    assert j0.shape == (0, 2, 2)


def test_compiled_mfs_newton_agrees_with_invert_on_generated_polygons():
    """`MFSSolution.invert_newton` (compiled, per point) against `invert` (numpy) as the reference:
    the same converged points to well below 1e-6 px, and phi's own Jacobian at them."""
    from warpcli.maps.newton import thresholds

    rng = np.random.default_rng(5)
    for _ in range(3):
        n = int(rng.integers(5, 10))
        th = np.sort(rng.uniform(0, 2 * np.pi, n))
        P = np.stack(np.array([np.cos(th), np.sin(th)]) * rng.uniform(30.0, 60.0, n), axis=1) + rng.uniform(0, 500, 2)
        tt = 2 * np.pi * np.arange(n) / n
        sol = fit_mfs(P, np.stack([np.cos(tt), np.sin(tt)], axis=1), m=64)
        lo, hi = P.min(axis=0), P.max(axis=0)
        p = lo + rng.random((400, 2)) * (hi - lo)
        p = p[points_in_polygon(p, P) & (distance_to_boundary(p, P) > 1.0)]
        x = sol.value(p)
        guess = np.where(points_in_polygon(p + 2.0, P)[:, None], p + 2.0, p)
        guess[0] = hi + 10.0  # a start outside the polygon fails in both
        inside = lambda y: points_in_polygon(y, P)  # noqa: E731
        y_ref, ok_ref = invert(sol.value, sol.jacobian, x, guess, inside=inside, floor=1e-9)
        thresh, noise = thresholds(x, 1e-12, 1e-9)
        y, ok, J = sol.invert_newton(x, guess, P, thresh, noise, jacobian=True)
        assert np.array_equal(ok, ok_ref) and not ok[0] and ok[1:].all()
        assert np.abs(y[ok] - y_ref[ok]).max() < 1e-7
        assert np.abs(y[ok] - p[ok]).max() < 1e-7
        assert np.isnan(J[~ok]).all()
        assert np.allclose(J[ok], sol.jacobian(y[ok]), rtol=1e-12, atol=1e-14)


def _seeded_star(rng, n, rmin, rmax, c=(300.0, 300.0)):
    ang = np.sort(np.sort(rng.uniform(0, 2 * np.pi, n)) + np.linspace(0, 1e-3, n))
    r = rng.uniform(rmin, rmax, n)
    return np.stack([c[0] + r * np.cos(ang), c[1] + r * np.sin(ang)], 1)


def test_every_point_of_theta_is_inverted_even_where_the_first_guess_fails():
    # An outside review's seeded MFS star pair: Newton did not converge from the first guess at 9 of
    # the 74,170 pre-images of the output's pixels, up to 91 px inside the source, and `forward`
    # gave NaN there (`warp_points` called them outside). Every point of Theta has a pre-image; now
    # every one is found (`SmoothMap._second_starts`), and goes back to its pixel centre.
    from warpcli import BijectiveMap, Polygon

    rng = np.random.default_rng(1)
    n = int(rng.integers(5, 30))
    src = _seeded_star(rng, n, rng.uniform(5, 120), 280)
    dst = _seeded_star(rng, n, rng.uniform(5, 120), 280)
    f = BijectiveMap.between(Polygon(src), Polygon(dst), method="mfs")
    x = f.inverse_grid(600, 600)
    inside = np.isfinite(x[..., 0])
    rows, cols = np.nonzero(inside)
    back = f.forward(x[inside])
    assert np.isfinite(back).all()
    np.testing.assert_allclose(back, np.stack([cols + 0.5, rows + 0.5], axis=1), atol=1e-6)
