"""The certificate's rigorous cell bound (`lower_bound`, `ClosedForm.derivative_bounds`) against the maps themselves.

The bounds claim, for every disc (centre p, radius r) they are asked about:
|A(p + h) - A(p) - A'(p) h| <= rho_A for |h| <= r (A = f_z, B = conj(f_zbar)
of the map f = u + i v) and sign det J >= lower_bound over the disc. Both
are checked at random points of random discs on generated polygons (nasty
ones included), with the maps' own Jacobians there (the evaluation, not the
bound's code); BEM's node-pole form of A'' against central differences of
its Hessian checks the closed-form integration by parts.
"""

from __future__ import annotations

import numpy as np
import pytest
from nasty import SHAPES

from warpcli.grid import inside_polygon
from warpcli.maps import bem
from warpcli.maps.bem import fit_bem
from warpcli.maps.certificate import certify_cells, lower_bound
from warpcli.maps.closed_form import distance_to_boundary
from warpcli.maps.mfs import fit_mfs
from warpcli.maps.theta import Theta


def _ab(j):
    ux, uy, vx, vy = j[:, 0, 0], j[:, 0, 1], j[:, 1, 0], j[:, 1, 1]
    return 0.5 * ((ux + vy) + 1j * (vx - uy)), 0.5 * ((ux - vy) - 1j * (vx + uy))


def _ab1(h):
    uxx, uxy, vxx, vxy = h[:, 0, 0, 0], h[:, 0, 0, 1], h[:, 1, 0, 0], h[:, 1, 0, 1]
    return 0.5 * ((uxx + vxy) + 1j * (vxx - uxy)), 0.5 * ((uxx - vxy) - 1j * (vxx + uxy))


def _case(shape: str, seed: int):
    """A generated polygon, targets a smooth distortion of it (a map that does not fold), and random discs."""
    rng = np.random.default_rng(seed)
    v = SHAPES[shape](rng)
    t = v + 0.15 * np.stack([np.sin(v[:, 1] / 60.0), np.cos(v[:, 0] / 70.0)], axis=1) * np.ptp(v, axis=0).max() / 4
    lo, hi = v.min(axis=0), v.max(axis=0)
    c = rng.uniform(lo, hi, (1500, 2))
    c = c[inside_polygon(c, v)][:400]
    d = distance_to_boundary(c, v)
    r = rng.uniform(0.0, 2.0, len(c)) * d  # half of them cross the boundary
    return v, t, c, r, rng


@pytest.mark.parametrize("method", ["mfs", "bem"])
@pytest.mark.parametrize("shape,seed", [("zigzag", 1), ("star_like", 2), ("slot", 3)])
def test_remainder_and_lower_bound_hold(method, shape, seed):
    v, t, c, r, rng = _case(shape, seed)
    sol = (fit_mfs if method == "mfs" else fit_bem)(v, t, 96)
    bound = sol.derivative_bounds(c, r)
    _, j, h = sol.value_jacobian_hessian(c)
    a0, b0 = _ab(j)
    a1, b1 = _ab1(h)
    low = lower_bound(sol, c, r, j, h, 1.0)
    finite = np.isfinite(bound[:, 1])
    assert finite.sum() > len(c) // 4  # the bounds say something
    scale = np.abs(a0) + np.abs(b0)
    for _ in range(12):  # random points of every disc (BEM: only those in the polygon)
        hh = r * np.sqrt(rng.uniform(0, 1, len(c))) * np.exp(1j * rng.uniform(0, 2 * np.pi, len(c)))
        x = c + np.stack([hh.real, hh.imag], axis=1)
        inside = inside_polygon(x, v) & (distance_to_boundary(x, v) > 1e-6)
        x, hh = np.where(inside[:, None], x, c), np.where(inside, hh, 0.0)
        jx = sol.jacobian(x)
        a, b = _ab(jx)
        slack = 1e-12 * scale  # the evaluation's own rounding at x
        assert np.all(np.abs(a - a0 - a1 * hh) <= bound[:, 1] + slack)
        assert np.all(np.abs(b - b0 - b1 * hh) <= bound[:, 2] + slack)
        det = jx[:, 0, 0] * jx[:, 1, 1] - jx[:, 0, 1] * jx[:, 1, 0]
        assert np.all(low <= det + 1e-11 * scale**2)


@pytest.mark.parametrize("shape,seed", [("zigzag", 4), ("comb", 5)])
def test_bem_node_poles_are_the_second_derivative(shape, seed):
    v, t, c, _, _ = _case(shape, seed)
    sol = fit_bem(v, t, 96)
    ga, gb = sol._poles  # local frame: A'' = sum_n sum_k g_nk / (z - y_n)^k
    p = sol.frame.to_local(c)
    z = p[:, 0] + 1j * p[:, 1]
    y = sol.nodes[:, 0] + 1j * sol.nodes[:, 1]
    u = 1.0 / (z[:, None] - y[None, :])
    a2 = sum((ga[None, :, k] * u ** (k + 1)).sum(axis=1) for k in range(3))
    b2 = sum((gb[None, :, k] * u ** (k + 1)).sum(axis=1) for k in range(3))
    # central differences of A' = f_z' (from the Hessian) along x, in local units
    eps = 1e-4 * sol.frame.scale * np.minimum(distance_to_boundary(c, v) / sol.frame.scale, 1e-2)
    hp = sol.hessian(c + np.stack([eps, 0 * eps], axis=1))
    hm = sol.hessian(c - np.stack([eps, 0 * eps], axis=1))
    k = (sol.frame.tscale / sol.frame.scale**3)
    fa = (_ab1(hp)[0] - _ab1(hm)[0]) / (2 * eps) / k
    fb = (_ab1(hp)[1] - _ab1(hm)[1]) / (2 * eps) / k
    assert np.allclose(a2, fa, rtol=1e-4, atol=1e-6 * np.abs(a2).max())
    assert np.allclose(b2, fb, rtol=1e-4, atol=1e-6 * np.abs(b2).max())


def test_bem_star_shaped_discs():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    p = np.array([[0.5, 0.5], [0.5, 0.05], [0.05, 0.05], [0.5, 0.05]])
    r = np.array([0.4, 0.1, 0.1, 0.6])
    # inside; one edge, no vertex; two edges and a vertex; reaching three edges
    assert bem._star_shaped(p, r, square).tolist() == [True, True, False, False]


@pytest.mark.parametrize("method", ["mfs", "bem"])
def test_rigorous_certificate_verdicts(method):
    """A map onto a convex quadrilateral is proved (no failure); boundary data that cross themselves fail."""
    sq = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]])
    quad = np.array([[5.0, 0.0], [100.0, 5.0], [95.0, 100.0], [0.0, 95.0]])
    fit = fit_mfs if method == "mfs" else fit_bem
    good = certify_cells(fit(sq, quad, 64), sq, Theta(quad), 1.0, 1e-7, rigorous=True)
    assert good.failed == 0 and good.checked > 0
    bowtie = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    bad = certify_cells(fit(sq, bowtie, 64), sq, Theta(sq), 1.0, 1e-7, rigorous=True)
    assert bad.failed > 0
