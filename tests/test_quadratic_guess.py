"""The quadratic (P2) first guess of the smooth maps' inverse: `warpcli.maps.quadratic_guess`."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli.maps.quadratic_guess import QuadraticGuess


def square_mesh(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit square cut into n x n cells of two triangles each (counter-clockwise)."""
    t = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(t, t)
    v = np.stack([x.ravel(), y.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    a = (j * (n + 1) + i).ravel()
    b, c, d = a + 1, a + n + 2, a + n + 1
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def locate(image: np.ndarray, tri: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangle of the (straight) image holding each target and its barycentric coordinates (brute force)."""
    p0, p1, p2 = image[tri[:, 0]], image[tri[:, 1]], image[tri[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    d = q[:, None, :] - p0[None]
    l1 = (d[..., 0] * e2[:, 1] - d[..., 1] * e2[:, 0]) / det
    l2 = (e1[:, 0] * d[..., 1] - e1[:, 1] * d[..., 0]) / det
    ok = (l1 >= -1e-12) & (l2 >= -1e-12) & (l1 + l2 <= 1 + 1e-12)
    k = ok.argmax(axis=1)
    rows = np.arange(len(q))
    b = np.stack([1 - l1[rows, k] - l2[rows, k], l1[rows, k], l2[rows, k]], axis=1)
    return np.where(ok.any(axis=1), k, -1), b


def guesses(fun, inverse, n, seed=0):
    """PL and P2 guesses for targets fun(x) with x random in the square, and their errors against inverse."""
    v, tri = square_mesh(n)
    image = fun(v)
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.05, 0.95, (400, 2))
    q = fun(x)
    t, b = locate(image, tri, q)
    assert (t >= 0).all()
    linear = np.einsum("kj,kja->ka", b, v[tri[t]])
    g = QuadraticGuess.of(v, tri, image, fun).guess(q, t, b, linear, lambda p: np.ones(len(p), dtype=bool))
    exact = inverse(q)
    return np.abs(linear - exact).max(), np.abs(g - exact).max()


@pytest.mark.parametrize("a, b", [(0.3, -0.2), (-0.15, 0.25), (0.05, 0.1)])
def test_a_quadratic_map_is_a_p2_patch_so_its_guess_is_its_inverse(a, b):
    """phi(x, y) = (x + a y^2, y + b x^2) is reproduced exactly by every P2 patch: the guess is
    the exact pre-image up to Newton's convergence on the patch (two steps from the linear one)."""

    def fun(p):
        return np.stack([p[:, 0] + a * p[:, 1] ** 2, p[:, 1] + b * p[:, 0] ** 2], axis=1)

    def inverse(q):  # fixed point of x = u - a y^2, y = v - b x^2 (contracting here), to rounding
        x = q.copy()
        for _ in range(200):
            x = np.stack([q[:, 0] - a * x[:, 1] ** 2, q[:, 1] - b * x[:, 0] ** 2], axis=1)
        return x

    lin, quad = guesses(fun, inverse, 8)
    assert lin > 1e-4
    assert quad < 1e-9


def test_the_guess_error_is_third_order_in_the_mesh_size():
    """For a smooth non-polynomial map the P2 guess's error falls ~8x when the mesh is halved
    (the linear one's ~4x)."""

    def fun(p):
        return np.stack([p[:, 0] + 0.1 * np.sin(2.0 * p[:, 1]), p[:, 1] + 0.1 * np.sin(1.5 * p[:, 0])], axis=1)

    def inverse(q):
        x = q.copy()
        for _ in range(200):
            x = np.stack([q[:, 0] - 0.1 * np.sin(2.0 * x[:, 1]), q[:, 1] - 0.1 * np.sin(1.5 * x[:, 0])], axis=1)
        return x

    (l1, q1), (l2, q2) = guesses(fun, inverse, 6), guesses(fun, inverse, 12)
    assert 3.0 < l1 / l2 < 5.0
    assert q1 / q2 > 6.0
    assert q2 < l2 / 20.0


def test_guesses_outside_the_domain_keep_the_linear_one():
    v, tri = square_mesh(4)

    def fun(p):
        return np.stack([p[:, 0] + 0.3 * p[:, 1] ** 2, p[:, 1]], axis=1)

    q = fun(np.array([[0.5, 0.5], [0.01, 0.9], [0.9, 0.1]]))
    t, b = locate(fun(v), tri, q)
    linear = np.einsum("kj,kja->ka", b, v[tri[t]])
    g = QuadraticGuess.of(v, tri, fun(v), fun)
    nowhere = g.guess(q, t, b, linear, lambda p: np.zeros(len(p), dtype=bool))
    assert nowhere.tobytes() == linear.tobytes()
    everywhere = g.guess(q, t, b, linear, lambda p: np.ones(len(p), dtype=bool))
    assert (everywhere != linear).any(axis=1).all()  # the quadratic guesses differ from the linear ones
    left = g.guess(q, t, b, linear, lambda p: p[:, 0] < 0.5)
    kept = (left == linear).all(axis=1)
    assert ((left[:, 0] < 0.5) | kept).all()  # each is in the domain, or the linear one
    assert (left[~kept] == everywhere[~kept]).all()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hermite_midpoints_are_the_maps_for_a_cubic_and_only_edges_without_jacobians_are_evaluated(seed):
    """With the map's Jacobian at the vertices, the midpoints are cubic Hermite values: exact for a
    generated cubic map (the patches equal those of evaluated midpoints to rounding); ``evaluate`` is
    called only at the midpoints of edges with an end whose Jacobian is NaN, and its values used there."""
    rng = np.random.default_rng(seed)
    c = rng.normal(0.0, 0.1, (2, 10))

    def fun(p):
        x, y = p[:, 0], p[:, 1]
        mono = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y, x**3, x * x * y, x * y * y, y**3])
        return p + (c @ mono).T

    def jac(p):
        x, y = p[:, 0], p[:, 1]
        one, zero = np.ones_like(x), np.zeros_like(x)
        dx = np.stack([zero, one, zero, 2 * x, y, zero, 3 * x * x, 2 * x * y, y * y, zero])
        dy = np.stack([zero, zero, one, zero, x, 2 * y, zero, x * x, 2 * x * y, 3 * y * y])
        return np.eye(2)[None] + np.stack([(c @ dx).T, (c @ dy).T], axis=2)

    v, tri = square_mesh(5)
    j = jac(v)
    blank = rng.random(len(v)) < 0.2
    j[blank] = np.nan
    asked = []

    def counted(p):
        asked.append(p.copy())
        return fun(p) + 1.0  # marked: these values must be the ones used at those edges

    ref = QuadraticGuess.of(v, tri, fun(v), fun)
    got = QuadraticGuess.of(v, tri, fun(v), counted, jacobian=j)
    asked = np.concatenate(asked)
    ends = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    ends = np.unique(ends, axis=0)
    lacking = ends[blank[ends[:, 0]] | blank[ends[:, 1]]]
    expect = 0.5 * (v[lacking[:, 0]] + v[lacking[:, 1]])
    assert len(asked) == len(expect)
    assert np.array_equal(np.unique(asked, axis=0), np.unique(expect, axis=0))
    # patches whose three edges have Jacobians at both ends are the evaluated midpoints' patches
    full = ~blank[tri].any(axis=1)
    assert full.any()
    assert np.allclose(got.coef_rows[:, full], ref.coef_rows[:, full], rtol=0, atol=1e-13)
    assert (np.abs(got.coef_rows[:, ~full] - ref.coef_rows[:, ~full]).max(axis=0) > 0.5).all()  # the marked values
