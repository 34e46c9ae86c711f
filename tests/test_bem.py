"""The boundary element method (paper §3.1.2): `warpcli.maps.bem`."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg
from scipy.spatial import Delaunay

from warpcli.grid import inside_polygon as points_in_polygon
from warpcli.maps._bem_kernels import _gauss_order_index, bem_assemble, near_integrals
from warpcli.maps.bem import fit_bem
from warpcli.maps.bem_eval import _GAUSS_ORDERS, NEAR, gauss01
from warpcli.maps.closed_form import distance_to_boundary, interior_angles
from warpcli.maps.mfs import fit_mfs

# -- shapes -----------------------------------------------------------------


def lshape() -> np.ndarray:
    return np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]])


def star(n: int = 6) -> np.ndarray:
    th = np.pi / 2 + np.pi * np.arange(2 * n) / n
    r = np.where(np.arange(2 * n) % 2 == 0, 1.0, 0.45)
    return np.stack([r * np.cos(th), r * np.sin(th)], axis=1)


def pentagon() -> np.ndarray:
    return np.array([[0.0, 0.0], [2.0, 0.3], [2.5, 1.8], [1.0, 2.6], [-0.4, 1.5]])


def orientation(vertices: np.ndarray) -> float:
    """+1 for counter-clockwise, -1 for clockwise (centred first: coordinates may be ~1e6)."""
    v = vertices - vertices.mean(axis=0)
    return float(np.sign(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])))


def ngon_targets(vertices: np.ndarray) -> np.ndarray:
    """Regular n-gon of circumradius 1 with the orientation of ``vertices``."""
    n = len(vertices)
    th = 2 * np.pi * np.arange(n) / n * orientation(vertices)
    return np.stack([np.cos(th), np.sin(th)], axis=1)


def grid_inside(vertices: np.ndarray, n: int, margin: float = 0.0) -> np.ndarray:
    """Grid points inside the polygon at least ``margin`` (fraction of the bbox) from its boundary."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    g = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(lo[0] + g * (hi[0] - lo[0]), lo[1] + g * (hi[1] - lo[1]))
    q = np.stack([X.ravel(), Y.ravel()], axis=1)
    q = q[points_in_polygon(q, vertices)]
    size = np.max(hi - lo)
    return q[distance_to_boundary(q, vertices) > max(margin, 1e-9) * size]


def near_boundary_points(vertices: np.ndarray, dists: np.ndarray, per_edge: int = 7) -> np.ndarray:
    """Points at the given distances inside every edge (edge parameters in (0, 1))."""
    t = (np.arange(per_edge) + 0.5) / per_edge
    out = []
    for i in range(len(vertices)):
        a, b = vertices[i], vertices[(i + 1) % len(vertices)]
        e = b - a
        inward = np.array([-e[1], e[0]]) / np.hypot(*e) * orientation(vertices)
        for d in dists:
            out.append(a + t[:, None] * e + d * inward)
    return np.concatenate(out)


def affine_case(vertices: np.ndarray):
    A = np.array([[0.7, -1.3], [0.4, 2.1]])
    c = np.array([3.0, -5.0])
    return A, c, vertices @ A.T + c


# -- exactness ----------------------------------------------------------------


@pytest.mark.parametrize("shape", ["L", "star"])
@pytest.mark.parametrize("orientation", [1, -1])
@pytest.mark.parametrize("offset, scale", [(0.0, 1.0), (1e6, 1.0), (-3e5, 1e-3)])
def test_affine_data_give_the_affine_map(shape, orientation, offset, scale):
    base = lshape() if shape == "L" else star()
    P = base[::orientation] * scale + offset
    A, c, T = affine_case(P)
    sol = fit_bem(P, T, m=96)
    size = np.ptp(P, axis=0).max()
    q = np.concatenate([grid_inside(P, 25), near_boundary_points(P, np.array([1e-3, 1e-6]) * size)])
    v, J = sol.value_and_jacobian(q)
    norm_a = np.abs(A).max()
    # relative to the polygon size, plus the rounding of values as large as the targets
    assert np.abs(v - (q @ A.T + c)).max() <= 1e-8 * norm_a * size + 4 * np.finfo(float).eps * np.abs(T).max()
    assert np.abs(J - A).max() <= 1e-6 * norm_a
    # value() and jacobian() agree with the combined call
    np.testing.assert_array_equal(sol.value(q), v)
    np.testing.assert_array_equal(sol.jacobian(q), J)


def test_triangle_map_is_affine():
    P = np.array([[0.0, 0.0], [3.0, 1.0], [1.0, 2.5]]) + 1e6
    T = np.array([[1.0, 0.0], [-0.5, 0.8], [-0.5, -0.8]])
    # the affine map interpolating the vertex targets
    M = np.linalg.solve(np.c_[P - P[0]][1:], (T - T[0])[1:]).T
    sol = fit_bem(P, T, m=64)
    q = grid_inside(P, 20)
    assert np.abs(sol.value(q) - (T[0] + (q - P[0]) @ M.T)).max() < 1e-9
    assert np.abs(sol.jacobian(q) - M).max() < 1e-7


@pytest.mark.parametrize("angle", [0.0, 0.5])
def test_double_flux_nodes_reproduce_xy_on_a_rectilinear_polygon(angle):
    """u = x*y is linear along axis-parallel edges and its flux is linear per edge,
    jumping at corners: the double-node BEM must reproduce it to rounding error."""
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    P = lshape() @ R.T + 1e6

    def exact(p):
        u = (p - 1e6) @ R  # coordinates in the axis-parallel frame
        return np.stack([u[:, 0] * u[:, 1], u[:, 0] - 0.3 * u[:, 1]], axis=1)

    sol = fit_bem(P, exact(P), m=80)
    q = np.concatenate([grid_inside(P, 20), near_boundary_points(P, np.array([1e-4]))])
    assert np.abs(sol.value(q) - exact(q)).max() < 1e-10
    # the flux of the paper's continuous hat functions cannot jump at corners
    cont = fit_bem(P, exact(P), m=80, flux="continuous")
    assert np.abs(cont.value(q) - exact(q)).max() > 1e-5


def test_omega_is_the_interior_angle():
    """omega(x_j) = PV -int dG/dn at a vertex is interior angle / 2 pi (not exterior)."""
    P = np.array([[0.0, 0.0], [1.0, 0.0], [0.3, 0.4], [0.2, 1.2], [-0.5, 0.2]])  # convex + reflex vertices
    area2 = np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
    assert area2 > 0
    alpha = interior_angles(P)
    assert np.any(alpha > np.pi) and np.any(alpha < np.pi / 2)
    np.testing.assert_allclose(interior_angles(P[::-1]), alpha[::-1])
    # elements: each edge split in 3; collocation at the vertices
    ts = np.array([0.0, 1 / 3, 2 / 3])
    a = np.concatenate([P[i] + ts[:, None] * (P[(i + 1) % 5] - P[i]) for i in range(5)])
    b = np.roll(a, -1, axis=0)
    E = len(a)
    vert = np.arange(0, E, 3)
    inc_e = np.stack([(vert - 1) % E, vert], axis=1)
    inc_t = np.tile([1.0, 0.0], (5, 1))
    g = gauss01(16)
    S, D = np.empty((len(P), E, 2)), np.empty((len(P), E, 2))
    bem_assemble(P[:, 0].copy(), P[:, 1].copy(), inc_e, inc_t, a[:, 0].copy(), a[:, 1].copy(),
                 b[:, 0].copy(), b[:, 1].copy(), *g, NEAR, S, D)  # fmt: skip
    np.testing.assert_allclose(D.sum(axis=(1, 2)), alpha / (2 * np.pi), atol=1e-13)
    # ... so the paper's continuous-flux scheme, which collocates at vertices, reproduces constants
    sol = fit_bem(P, np.tile([2.0, -1.0], (5, 1)), m=40, flux="continuous")
    assert np.abs(sol.value(grid_inside(P, 15)) - [2.0, -1.0]).max() < 1e-12


def graded_quadrature(f, zeta: complex) -> complex:
    """int_0^1 f(t) dt for f nearly singular at t = zeta: Gauss on intervals graded towards Re zeta."""
    s = min(max(zeta.real, 0.0), 1.0)
    h = max(abs(zeta.imag), 1e-12)
    cuts = {0.0, 1.0, s}
    for k in range(80):
        for c in (s - h * 2.0**k, s + h * 2.0**k):
            if 0.0 < c < 1.0:
                cuts.add(c)
    cuts = np.array(sorted(cuts))
    x, w = np.polynomial.legendre.leggauss(20)
    a, b = cuts[:-1, None], cuts[1:, None]
    t = 0.5 * (a + b) + 0.5 * (b - a) * x
    return complex(np.sum(0.5 * (b - a) * w * f(t)))


def test_near_integrals_closed_forms():
    """The closed forms against graded quadrature, including points very close to the element."""
    kernels = [
        (lambda z, t: np.log(np.abs(z - t)), 0, 1),
        (lambda z, t: 1 / (z - t), 2, 3),
        (lambda z, t: (z - t) ** -2, 4, 5),
        (lambda z, t: (z - t) ** -3, 6, 7),
    ]
    for zeta in [0.3 + 1e-3j, 0.999 - 2e-4j, -0.01 + 0.02j, 1.5 - 0.7j, 0.5 + 1.9j, -1.2 + 0.1j, 2.0 + 0.0j]:
        got = near_integrals(zeta, zeta - 1)
        for f, i0, i1 in kernels:
            for i, hat in ((i0, lambda t: 1 - t), (i1, lambda t: t)):
                ref = graded_quadrature(lambda t: hat(t) * f(zeta, t), zeta)
                if i < 2:
                    ref = ref.real
                # relative to int |integrand| (~1/d^2 for k = 3 at distance d, whereas the
                # integral itself stays O(1): the reference quadrature cancels that much)
                size = graded_quadrature(lambda t: np.abs(hat(t) * f(zeta, t)), zeta).real
                assert abs(got[i] - ref) <= 1e-13 * max(1.0, size)


def test_gauss_rules_are_accurate_where_used():
    """The Gauss rule chosen for a point at R = 2|zeta - 1/2| >= 4 matches a 40-point rule."""
    tr, wr = gauss01(40)
    for R in [4.0, 5.0, 7.0, 12.0, 30.0, 90.0, 400.0, 3000.0]:
        n = int(_GAUSS_ORDERS[_gauss_order_index(R, _GAUSS_ORDERS)])
        t, w = gauss01(n)
        for th in np.linspace(0.0, 2 * np.pi, 13):
            zeta = 0.5 + 0.5 * R * np.exp(1j * th)
            for k in (1, 2, 3):
                scale = abs(zeta - 0.5) ** -k
                for hat in (lambda t: 1 - t, lambda t: t):
                    ref = np.sum(wr * hat(tr) * (zeta - tr) ** -k)
                    assert abs(np.sum(w * hat(t) * (zeta - t) ** -k) - ref) < 1e-13 * scale
            for hat in (lambda t: 1 - t, lambda t: t):
                ref = np.sum(wr * hat(tr) * np.log(np.abs(zeta - tr)))
                assert abs(np.sum(w * hat(t) * np.log(np.abs(zeta - t))) - ref) < 1e-13 * max(1.0, abs(ref))


# -- accuracy -----------------------------------------------------------------


def p1_fem(P: np.ndarray, T: np.ndarray, n: int):
    """Tiny independent P1 FEM reference on a convex polygon (cotangent Laplacian)."""
    size = np.ptp(P, axis=0).max()
    h = size / n
    bnd, bval = [], []
    for i in range(len(P)):
        a, b = P[i], P[(i + 1) % len(P)]
        k = max(1, int(np.ceil(np.hypot(*(b - a)) / h)))
        t = np.arange(k) / k
        bnd.append(a + t[:, None] * (b - a))
        bval.append((1 - t)[:, None] * T[i] + t[:, None] * T[(i + 1) % len(P)])
    bnd, bval = np.concatenate(bnd), np.concatenate(bval)
    inner = grid_inside(P, n, margin=0.5 / n)
    pts = np.concatenate([bnd, inner])
    tri = Delaunay(pts)
    assert len(tri.coplanar) == 0
    S = tri.simplices
    x = pts[S]
    e0, e1, e2 = x[:, 2] - x[:, 1], x[:, 0] - x[:, 2], x[:, 1] - x[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    edges = [e0, e1, e2]
    rows, cols, vals = [], [], []
    for i in range(3):
        for j in range(3):
            rows.append(S[:, i])
            cols.append(S[:, j])
            vals.append(np.sum(edges[i] * edges[j], axis=1) / (4 * area))
    K = scipy.sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                shape=(len(pts), len(pts)))  # fmt: skip
    nb = len(bnd)
    u = np.zeros((len(pts), 2))
    u[:nb] = bval
    Kii = K[nb:, nb:].tocsc()
    u[nb:] = scipy.sparse.linalg.spsolve(Kii, -K[nb:, :nb] @ bval)
    return inner, u[nb:]


def test_against_an_independent_fem_reference():
    P = pentagon()
    T = ngon_targets(P)
    nodes, ref = p1_fem(P, T, 120)
    size = np.ptp(P, axis=0).max()
    far = distance_to_boundary(nodes, P) > 0.05 * size
    sol = fit_bem(P, T, m=128)
    err = np.abs(sol.value(nodes[far]) - ref[far]).max()
    assert err < 2e-4  # the FEM's own error, O(h^2)
    coarse_nodes, coarse = p1_fem(P, T, 60)
    far_c = distance_to_boundary(coarse_nodes, P) > 0.05 * size
    assert np.abs(sol.value(coarse_nodes[far_c]) - coarse[far_c]).max() > 2 * err  # and it is the FEM's


def test_error_decreases_as_m_grows():
    P = star() + 1e6
    T = ngon_targets(P)
    q = grid_inside(P, 30, margin=0.02)
    ref = fit_mfs(P, T, m=512).value(q)  # the other method, converged to ~1e-7 here
    errs = [np.abs(fit_bem(P, T, m=m).value(q) - ref).max() for m in (48, 96, 192)]
    assert errs[0] > 2 * errs[1] > 4 * errs[2]
    assert errs[2] < 1e-4


def test_values_near_the_boundary_are_accurate():
    """Closed-form near integrals: accurate down to 1e-3 element lengths (and far below)."""
    P = lshape()
    A, c, T = affine_case(P)
    sol = fit_bem(P, T, m=64)
    L = 6.0 / 64  # typical element length
    for d in [1e-1 * L, 1e-3 * L, 1e-7 * L]:
        q = near_boundary_points(P, np.array([d]), per_edge=31)  # some right above nodes
        assert np.abs(sol.value(q) - (q @ A.T + c)).max() < 1e-12
        # rounding in the cancelling O(1/d) terms
        assert np.abs(sol.jacobian(q) - A).max() < 1e-11 * max(1.0, 1e-3 * L / d)
    # right next to the reflex vertex (1, 1)
    q = np.array([1.0, 1.0]) + np.array([[-1.0, -1.0], [-1.0, 0.2], [0.2, -1.0]]) * 1e-6
    assert np.abs(sol.value(q) - (q @ A.T + c)).max() < 1e-9


# -- derivatives --------------------------------------------------------------


def test_hessian_matches_finite_differences():
    P = star()[::-1]
    sol = fit_bem(P, ngon_targets(P), m=96)
    q = grid_inside(P, 12, margin=0.05)
    H = sol.hessian(q)
    h = 1e-5
    fd = np.stack(
        [(sol.jacobian(q + h * e) - sol.jacobian(q - h * e)) / (2 * h) for e in np.eye(2)], axis=-1
    )
    assert np.abs(H - fd).max() < 1e-5 * np.abs(H).max()
    # harmonic: trace-free in the derivative indices; symmetric
    assert np.abs(H[:, :, 0, 0] + H[:, :, 1, 1]).max() < 1e-9 * np.abs(H).max()
    np.testing.assert_array_equal(H[:, :, 0, 1], H[:, :, 1, 0])
    # Jacobian against finite differences of the value
    J = sol.jacobian(q)
    fdj = np.stack([(sol.value(q + h * e) - sol.value(q - h * e)) / (2 * h) for e in np.eye(2)], axis=-1)
    assert np.abs(J - fdj).max() < 1e-6 * np.abs(J).max()
    # far from the origin: derivatives scale back correctly
    moved = fit_bem(P * 1e-3 + 1e6, ngon_targets(P), m=96)
    np.testing.assert_allclose(moved.hessian(q * 1e-3 + 1e6) * 1e-6, H, atol=1e-5 * np.abs(H).max())


def test_block_local_expansions_agree_with_direct_sums():
    """Dense point sets go through per-block local expansions of the far field;
    single points through the direct sums: both must agree."""
    P = lshape()
    sol = fit_bem(P, ngon_targets(P), m=128)
    dense = grid_inside(P, 160)  # blocks of 256 nearby points
    v, J = sol.value_and_jacobian(dense)
    H = sol.hessian(dense)
    pick = np.linspace(0, len(dense) - 1, 40).astype(int)
    for i in pick:
        p = dense[i : i + 1]
        assert np.abs(sol.value(p) - v[i]).max() < 1e-13
        assert np.abs(sol.jacobian(p) - J[i]).max() < 1e-12 * np.abs(J).max()
        assert np.abs(sol.hessian(p) - H[i]).max() < 1e-10 * np.abs(H[i]).max()


# -- invariances and API ------------------------------------------------------


def test_position_scale_and_orientation_do_not_matter():
    P = star()
    T = ngon_targets(P)
    q = grid_inside(P, 15)
    base = fit_bem(P, T, m=100)
    v, J = base.value_and_jacobian(q)
    # (the vertices far from the origin are rounded to ~1e-8 of the size: that
    # must not change the discretisation, e.g. how nodes are shared among edges)
    moved = fit_bem(P * 1e-3 + 1e6, T, m=100)
    v2, J2 = moved.value_and_jacobian(q * 1e-3 + 1e6)
    assert np.abs(v2 - v).max() < 1e-6
    assert np.abs(J2 * 1e-3 - J).max() < 1e-5 * np.abs(J).max()
    # reversing the vertex order (with the targets) is the same problem
    rev = fit_bem(P[::-1], T[::-1], m=100)
    assert np.abs(rev.value(q) - v).max() < 1e-12
    # deterministic, and the nodes include the vertices
    np.testing.assert_array_equal(fit_bem(P, T, m=100).value(q), v)
    assert base.m == 100 and base.nodes.shape == (100, 2)
    local = (P - base.frame.centre) / base.frame.scale
    assert all(np.min(np.hypot(*(base.nodes - p).T)) < 1e-15 for p in local)


def test_bad_input_is_rejected():
    P = lshape()
    with pytest.raises(ValueError):
        fit_bem(P, P[:-1])
    with pytest.raises(ValueError):
        fit_bem(P[:2], P[:2])
    with pytest.raises(ValueError):
        fit_bem(P, P, m=3)
    with pytest.raises(ValueError):
        fit_bem(np.repeat(P, 2, axis=0), np.repeat(P, 2, axis=0))
    with pytest.raises(ValueError):
        fit_bem(P, P, flux="magic")
    sol = fit_bem(P, P, m=32)
    assert sol.value(np.zeros((0, 2))).shape == (0, 2)
    assert sol.hessian(np.array([0.5, 0.5])).shape == (1, 2, 2, 2)


def test_certify_skips_samples_on_the_boundary():
    """The certificate's sample grid can put a point on an edge to rounding, where BEM's closed
    form is singular (det J ~ +-1e-15 there): such samples are not evidence of a fold."""
    from warpcli import MapOptions, Polygon
    from warpcli.maps.registry import METHODS
    from warpcli.maps.theta import regular

    poly = Polygon(np.array([[15, 5], [105, 20], [95, 60], [90, 95], [20, 80]], float))
    opts = MapOptions(method="bem", check=False)
    phi = METHODS["bem"].load().build(poly, regular(poly, poly, opts), opts, "source")
    assert phi.certify().ok
