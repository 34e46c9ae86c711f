"""The Theta optimizer (§5.1): linear bases, the exact gradient, the convex parameterization, keep-the-best."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import l_shape, star
from warpcli import MapOptions, Polygon, build_report, warp_image
from warpcli.maps import optimize as opt
from warpcli.maps.fem.solve import DirichletSolver
from warpcli.maps.theta import Theta, cyclic_polygon, regular_polygon
from warpcli.maps.theta_energy import ENERGIES, HarmonicBasis, ThetaEnergy, boundary_matrix

HEXAGON = np.array([[10, 20], [40, 10], [120, 30], [110, 110], [60, 118], [15, 90]], dtype=float)


@pytest.fixture(scope="module")
def l_pair():
    """An L onto a hexagon on coarse meshes (a few hundred triangles)."""
    src, dst = Polygon(l_shape()), Polygon(HEXAGON)
    return src, dst, HarmonicBasis.solve(src, 60.0, grade=False), HarmonicBasis.solve(dst, 60.0, grade=False)


def convex_thetas(n: int):
    """Strictly convex n-gons: cyclic polygons of random edge lengths, stretched and sheared."""
    return st.tuples(
        st.lists(st.floats(0.3, 1.0), min_size=n, max_size=n),
        st.floats(0.5, 2.0), st.floats(-0.5, 0.5),
    ).map(lambda a: cyclic_polygon(a[0]) @ np.array([[a[1], a[2]], [0.0, 1.0]]).T)  # fmt: skip


@settings(max_examples=10, deadline=None)
@given(theta=convex_thetas(6))
def test_the_basis_gives_every_thetas_map(l_pair, theta):
    """values = W @ theta is the Dirichlet solve for that Theta; on the boundary, the hat functions."""
    src, _, basis, _ = l_pair
    solved = DirichletSolver(basis.mesh).solve(theta)
    np.testing.assert_allclose(basis.values(theta), solved, atol=1e-12)
    np.testing.assert_allclose(basis.basis.sum(axis=1), 1.0, atol=1e-12)  # constants are harmonic
    m = basis.mesh
    np.testing.assert_allclose(basis.values(theta)[m.boundary], boundary_matrix(m, 6) @ theta, atol=1e-12)


@pytest.mark.parametrize("kind", ENERGIES)
def test_the_gradient_is_exact_where_no_sample_changes_triangle(l_pair, kind):
    _, _, b0, b1 = l_pair
    energy = ThetaEnergy(b0, b1, kind)
    rng = np.random.default_rng(ENERGIES.index(kind))
    checked = 0
    for _ in range(1):
        theta = regular_polygon(6) + rng.normal(0.0, 0.04, (6, 2))
        value, grad = energy(theta)
        where = energy.triangles_of_samples(theta)
        h = 1e-6
        for i in range(6):
            for k in range(2):
                a, b = theta.copy(), theta.copy()
                a[i, k] += h
                b[i, k] -= h
                if not (np.array_equal(energy.triangles_of_samples(a), where)
                        and np.array_equal(energy.triangles_of_samples(b), where)):  # fmt: skip
                    continue  # a sample jumps triangle: the energy is not smooth there
                fd = (energy(a, gradient=False)[0] - energy(b, gradient=False)[0]) / (2 * h)
                assert fd == pytest.approx(grad[i, k], abs=1e-6 * max(1.0, abs(value)), rel=1e-5)
                checked += 1
    assert checked >= 8


def test_an_affine_pair_has_its_exact_distortion_for_every_theta():
    """Triangles: both maps are affine, so f is the affine map, whatever Theta."""
    src = np.array([[5.0, 5.0], [120.0, 15.0], [20.0, 110.0]])
    dst = np.array([[10.0, 20.0], [100.0, 5.0], [70.0, 120.0]])
    a = np.linalg.solve(np.hstack([src, np.ones((3, 1))]), dst)[:2].T
    s = np.linalg.svd(a, compute_uv=False)
    b0 = HarmonicBasis.solve(Polygon(src), 200.0)
    b1 = HarmonicBasis.solve(Polygon(dst), 200.0)
    for kind, exact in [("conformal", s[0] / s[1] + s[1] / s[0]), ("isometric", max(s[0], 1 / s[1]))]:
        energy = ThetaEnergy(b0, b1, kind)
        for theta in (regular_polygon(3), np.array([[0.0, 0.0], [3.0, 0.2], [0.5, 1.0]])):
            value, grad = energy(theta)
            assert value == pytest.approx(exact, rel=1e-9)
            assert np.abs(grad).max() < 1e-8  # flat: Theta does not change the map


@settings(max_examples=12, deadline=None)
@given(n=st.integers(3, 12), seed=st.integers(0, 10_000), spread=st.floats(0.0, 4.0))
def test_every_parameter_gives_a_strictly_convex_theta(n, seed, spread):
    rng = np.random.default_rng(seed)
    start = cyclic_polygon(rng.uniform(0.6, 1.0, n))
    shape = opt.ConvexShape(start)
    np.testing.assert_allclose(shape.points(shape.params), start, atol=1e-12)  # the start is a parameter
    x = shape.params + rng.normal(0.0, spread, shape.params.size)
    points, jac = shape.points_and_jacobian(x)
    Theta(points)  # strictly convex and turning once, or this raises
    e = np.roll(points, -1, axis=0) - points
    turn = np.arctan2(np.roll(e, 1, axis=0)[:, 0] * e[:, 1] - np.roll(e, 1, axis=0)[:, 1] * e[:, 0],
                      (np.roll(e, 1, axis=0) * e).sum(axis=1))  # fmt: skip
    assert turn.min() >= shape.floor * (1 - 1e-9) and turn.max() <= math.pi - shape.floor * (1 - 1e-9)
    assert turn.sum() == pytest.approx(2 * math.pi)
    k = seed % x.size  # one column of the Jacobian against central differences from scratch
    a, b = x.copy(), x.copy()
    a[k] += 1e-6
    b[k] -= 1e-6
    np.testing.assert_allclose(jac[:, k], (shape.points(a) - shape.points(b)).ravel() / 2e-6, atol=1e-5)


def test_the_guards_are_affine_invariant_and_catch_flat_corners():
    p = cyclic_polygon([1.0, 1.0, 0.7, 1.2, 0.9])
    a = np.array([[3.0, 1.0], [0.2, 0.5]])
    for x, y in zip(opt.guards(p), opt.guards(p @ a.T + [4.0, -2.0])):
        np.testing.assert_allclose(x, y, atol=1e-9)
    assert opt.guard_penalty(regular_polygon(7))[0] == 0.0
    flat = regular_polygon(8)
    flat[2] = 0.5 * (flat[1] + flat[3]) * 1.0005  # almost no turn at vertex 2
    pen, grad = opt.guard_penalty(flat)
    assert pen > 1.0 and np.abs(grad).max() > 0


@pytest.mark.parametrize("energy", ["conformal", "isometric"])
def test_optimized_theta_is_never_worse_than_regular_or_cyclic(energy):
    """Measured independently, by the report (a 1-px grid over the source, f's own Jacobians)."""
    img = np.zeros((96, 96, 1), dtype=np.float32)
    src, dst = star(5, 48, 48, 16.0, 44.0), star(5, 48, 48, 26.0, 44.0, phase=0.3) * [1.0, 0.6] + [0.0, 19.0]
    reps, thetas = {}, {}
    for theta in ("regular", "cyclic", "optimized"):
        res = warp_image(img, src, dst, map=MapOptions(energy=energy, max_area=10.0, theta=theta))
        reps[theta], thetas[theta] = build_report(res), res.map.theta
    best = min(reps["regular"][energy]["mean"], reps["cyclic"][energy]["mean"])
    assert reps["optimized"][energy]["mean"] <= best * (1 + 1e-3)
    notes = reps["optimized"]["theta"]
    assert notes["after"] <= notes["before"] and notes["kept"] in ("regular", "cyclic", "optimized", "none")
    if notes["kept"] == "none":  # the straight map (tests/test_straight.py): no Theta to guard
        assert reps["optimized"]["flipped_triangles"] == 0 and notes["none"] == notes["after"]
        return
    t, e = opt.guards(thetas["optimized"].points)
    assert t.min() >= 0.9 * opt.MIN_TURN and e.min() >= 0.9 * opt.MIN_EDGE


def test_the_joint_optimizer_lowers_the_coarse_energy_far_and_in_few_evaluations(l_pair):
    _, _, b0, b1 = l_pair
    energy = ThetaEnergy(b0, b1, "conformal")
    start = regular_polygon(6)
    run = opt.optimize(energy, start)
    assert run.energy < run.before * 0.97
    assert run.evaluations < 120  # SLSQP on the same energy: hundreds (bench/optimizer.py)
    Theta(run.points)
