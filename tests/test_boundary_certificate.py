"""The boundary certificate (`warpcli.maps.boundary_certificate`) against exact maths and an independent dense check.

- Exactly known harmonic maps phi = g(z) + conj(h(z)) (polynomials g, h: A =
  g', B = h', det J = |g'|^2 - |h'|^2 in closed form, Taylor remainders
  exact): affine maps and z + c conj(z)^2 / 2 on a square are accepted
  exactly when det J > 0 on the closed polygon (and the map is one-to-one,
  by the inequality in `test_quadratic_shear_on_the_square`), refused
  otherwise; a map whose A has a zero inside while |B| < |A| on the
  boundary is refused by the winding number alone.
- Generated nasty polygons (`tests/nasty.py`), BEM and MFS at few nodes:
  every map it accepts has det J > 0 and no deep excursion out of Theta at
  dense samples down to 1e-6 px from the boundary (MFS; BEM: deeper than
  its offset curve), and its boundary image has no self-crossing at dense
  points.
- The sample pairs are accepted; an MFS fold it finds on the boundary is a
  fold (det J <= 0 there by the map's own Jacobian).
- Bounded work: generated BEM maps of polygons 1e5-3e6 px across prove as
  a 2,000 px one does, with a small multiple of its evaluations and bounds;
  a closed form whose error bound never lets a piece be proved fails within
  `MAX_PIECES`, its pieces never split beyond that.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from nasty import SHAPES, dense_check, dense_samples

from warpcli import MapOptions, Polygon, build_map
from warpcli.boundary import nearest_edge
from warpcli.grid import inside_polygon
from warpcli.maps import boundary_certificate
from warpcli.maps.boundary_certificate import _pairs_within, certify_boundary, inner_offset
from warpcli.maps.meshless import BAND_STEPS, BEM, MFS
from warpcli.maps.theta import Theta
from warpcli.maps.theta import regular as regular_theta
from warpcli.polygon.formats import read_polygon

HERE = os.path.dirname(os.path.abspath(__file__))
SAMPLES = os.path.join(HERE, "..", "sample_images")
SQUARE = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
BIG = Theta(np.array([[-50.0, -50.0], [50.0, -50.0], [50.0, 50.0], [-50.0, 50.0]]))


class Harmonic:
    """phi = g(z) + conj(h(z)) with polynomial g, h (coefficients, highest degree first): a closed form, exactly."""

    def __init__(self, g, h) -> None:
        self.g = np.poly1d(np.asarray(g, dtype=complex))
        self.h = np.poly1d(np.asarray(h, dtype=complex))

    def value_jacobian_hessian(self, points):
        p = np.asarray(points, dtype=float)
        z = p[:, 0] + 1j * p[:, 1]
        a, b = self.g.deriv()(z), self.h.deriv()(z)
        a1, b1 = self.g.deriv(2)(z), self.h.deriv(2)(z)
        phi = self.g(z) + np.conj(self.h(z))
        fx, fy = a + np.conj(b), 1j * (a - np.conj(b))  # phi_x, phi_y
        fxx, fxy, fyy = a1 + np.conj(b1), 1j * (a1 - np.conj(b1)), -(a1 + np.conj(b1))
        val = np.stack([phi.real, phi.imag], axis=1)
        jac = np.stack([np.stack([fx.real, fy.real], -1), np.stack([fx.imag, fy.imag], -1)], axis=1)
        hx = np.stack([np.stack([fxx, fxy], -1), np.stack([fxy, fyy], -1)], axis=1)  # [k, b, c]
        hess = np.stack([hx.real, hx.imag], axis=1)
        return val, jac, hess

    def derivative_bounds(self, points, reach):
        """The Taylor remainders of A and B beyond first order: finite sums, bounded term by term."""
        p = np.asarray(points, dtype=float)
        z = p[:, 0] + 1j * p[:, 1]
        r = np.asarray(reach, dtype=float)
        out = np.zeros((len(p), 3))
        for col, f in ((1, self.g.deriv()), (2, self.h.deriv())):
            for k in range(2, max(f.order, 1) + 1):
                out[:, col] += np.abs(f.deriv(k)(z)) * r**k / math.factorial(k)
        out[:, 0] = 1e-13 * (1.0 + np.abs(self.g.deriv()(z)) + np.abs(self.h.deriv()(z)))
        return out


@pytest.mark.parametrize("seed", range(6))
def test_affine_maps_are_accepted_exactly_when_they_keep_the_orientation(seed):
    """phi = a z + conj(b z): det J = |a|^2 - |b|^2 everywhere; one-to-one when it is not 0."""
    rng = np.random.default_rng(seed)
    v = SHAPES[["star_like", "zigzag", "slot"][seed % 3]](rng) / 150.0 - 1.0
    a, b = (rng.normal(size=2) @ [1, 1j]) * rng.uniform(0.5, 2), rng.normal(size=2) @ [1, 1j]
    keep = abs(a) > abs(b)
    if abs(abs(a) - abs(b)) < 0.05:  # not at the threshold
        b *= 0.5
        keep = abs(a) > abs(b)
    phi = Harmonic([a, 0], [b, 0])
    sign = float(np.sign(0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])))
    same = certify_boundary(phi, v, BIG, sign)
    other = certify_boundary(phi, v, BIG, -sign)
    assert (same.failed == 0) == keep, (a, b, same)
    assert (other.failed == 0) == (not keep), (a, b, other)


@pytest.mark.parametrize("c", [0.2, 0.45j, 0.6 * np.exp(1j), -0.68, 0.74j, 0.9, 1.3 * np.exp(2j)])
def test_quadratic_shear_on_the_square(c):
    """phi = z + c conj(z)^2 / 2 on [-1, 1]^2: det J = 1 - |c|^2 |z|^2 > 0 on the closed square iff |c| sqrt 2 < 1.

    Then it is also one-to-one: |phi(z1) - phi(z2) - (z1 - z2)| = |c| / 2 |z1 + z2| |z1 - z2| <= |c| sqrt 2 |z1 - z2|.
    """
    phi = Harmonic([1, 0], [c / 2, 0, 0])
    cert = certify_boundary(phi, SQUARE, BIG, 1.0)
    assert (cert.failed == 0) == (abs(c) * math.sqrt(2) < 1), (c, cert)
    if cert.failed:
        assert cert.folds, cert  # the corners fold: det J < 0 there
        x, y = cert.where
        assert 1 - abs(c) ** 2 * (x * x + y * y) <= 0


def test_a_zero_of_a_inside_is_caught_by_the_winding_number():
    """A = z - z0 vanishes at z0 inside, |B| = 0.1 < |A| all along the boundary: det J = -0.01 at z0."""
    z0 = 0.2 + 0.1j
    phi = Harmonic([0.5, -z0, 0], [0.1, 0])  # g = z^2 / 2 - z0 z: g' = z - z0
    assert np.abs(np.abs([complex(*p) - z0 for p in SQUARE]) > 0.1).all()
    cert = certify_boundary(phi, SQUARE, BIG, 1.0)
    assert cert.failed and cert.winding == 1 and cert.folds == 0, cert
    _, j, _ = phi.value_jacobian_hessian(np.array([[z0.real, z0.imag]]))
    assert np.linalg.det(j[0]) < 0  # the fold the winding number found
    # with the zero moved outside, the same map is accepted on the square
    assert certify_boundary(Harmonic([0.5, -3.0, 0], [0.1, 0]), SQUARE, BIG, 1.0).failed == 0


def test_inner_offset_is_the_polygon_moved_inwards():
    """Every point of the offset curve lies inside, at least delta (to the arcs' chords) from the boundary and at
    most delta from an edge's line; reflex corners are rounded; too large a delta gives None."""
    v = SHAPES["zigzag"](np.random.default_rng(3))
    for delta in (0.01, 0.5, 3.0):
        g = inner_offset(v, delta)
        ge = np.roll(g, -1, axis=0) - g
        pts = (g[:, None, :] + np.linspace(0, 1, 7)[None, :, None] * ge[:, None, :]).reshape(-1, 2)
        assert inside_polygon(pts, v).all()
        d = nearest_edge(pts, v)[2]
        assert d.min() >= delta * math.cos(math.pi / 64) * (1 - 1e-9), (delta, d.min())
        area = 0.5 * np.sum(g[:, 0] * np.roll(g[:, 1], -1) - np.roll(g[:, 0], -1) * g[:, 1])
        assert area > 0  # counter-clockwise
    bar = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 2.0], [0.0, 2.0]])  # 2 wide: its sides' offsets cross past 1
    assert inner_offset(bar, 0.9) is not None
    assert inner_offset(bar, 1.2) is None
    assert np.allclose(inner_offset(SQUARE[::-1], 0.0), SQUARE)


def _near_boundary(v: np.ndarray, floor: float) -> np.ndarray:
    """Samples floor..0.01 px inside every edge (every 0.25 px) and around every vertex: the band the cells never saw."""
    e = np.roll(v, -1, axis=0) - v
    length = np.hypot(*e.T)
    area2 = np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
    inward = np.stack([-e[:, 1], e[:, 0]], 1) / length[:, None] * np.sign(area2)
    dist = np.geomspace(floor, 0.01, 7)
    parts = []
    for i in range(len(v)):  # loop over edges
        k = max(2, int(length[i] / 0.25))
        base = v[i] + ((np.arange(k) + 0.5) / k)[:, None] * e[i]
        parts.append((base[:, None, :] + dist[None, :, None] * inward[i]).reshape(-1, 2))
    ang = 2 * np.pi * (np.arange(96) + 0.5) / 96
    ring = (np.geomspace(floor, 0.01, 8)[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], -1)[None]).reshape(-1, 2)
    parts += [p + ring for p in v]
    p = np.concatenate(parts)
    return p[inside_polygon(p, v)]


def _image_of_gamma_is_simple(phi, offset: float, k: int = 2000) -> bool:
    """Whether phi at k points spread along Gamma (densest at the corners) is a polyline without self-crossing."""
    g = inner_offset(phi.polygon.points, offset)
    ge = np.roll(g, -1, axis=0) - g
    share = np.maximum(8, np.round(k * np.hypot(*ge.T) / np.hypot(*ge.T).sum())).astype(int)
    t = [0.5 - 0.5 * np.cos(np.pi * np.arange(s) / s) for s in share]  # Chebyshev-like: dense at both ends
    pts = np.concatenate([g[i] + t[i][:, None] * ge[i] for i in range(len(g))])
    w = phi.solution.value(pts)
    z = w[:, 0] + 1j * w[:, 1]
    a, b = z, np.roll(z, -1)
    n = len(z)
    for s in range(0, n, 400):  # blocks of edges against all later edges
        i = np.arange(s, min(n, s + 400))[:, None]
        j = np.arange(n)[None, :]
        ok = (j > i + 1) & ~((i == 0) & (j == n - 1))
        ai, bi, aj, bj = a[i], b[i], a[j], b[j]

        def cross(u, v):
            return (np.conj(u) * v).imag

        hit = (cross(bi - ai, aj - ai) * cross(bi - ai, bj - ai) < 0) & (cross(bj - aj, ai - aj) * cross(bj - aj, bi - aj) < 0)
        if (hit & ok).any():
            return False
    return True


# at these few nodes most nasty maps fold (and are refused); the seeds include ones accepted
CASES = [(shape, method, 11) for shape in sorted(SHAPES) if shape != "wavy" for method in ("mfs", "bem")]
CASES += [("ring_gap", "bem", 5)]
CASES += [pytest.param(*case, marks=pytest.mark.heavy) for case in [("star_like", "mfs", 5), ("star_like", "bem", 3)]]
CASES += [
    pytest.param(shape, method, seed, marks=pytest.mark.heavy)
    for shape in sorted(SHAPES)
    for method in ("mfs", "bem")
    for seed in (5, 3)
    if (shape, method, seed) not in [("ring_gap", "bem", 5), ("star_like", "mfs", 5), ("star_like", "bem", 3)]
]


@pytest.mark.parametrize("shape, method, seed", CASES)
def test_every_map_it_accepts_is_clean_at_dense_samples(shape, method, seed):
    """Accepted means: no fold, no deep excursion at dense samples down to 1e-6 px from the boundary (the
    collar in the band), and phi(Gamma) without self-crossing at dense points."""
    v = SHAPES[shape](np.random.default_rng(seed))
    poly = Polygon(v, name=shape)
    opts = MapOptions(method=method, nodes=max(64, len(v) + 8), check=False)
    phi = {"bem": BEM, "mfs": MFS}[method].build(poly, regular_theta(poly, poly, opts), opts)
    cert = phi.boundary_certificate
    if cert.failed:
        if cert.folds:  # a fold it names is a fold
            j = phi.solution.jacobian(np.array([cert.where]))
            sign = phi.theta.orientation * np.sign(poly.signed_area)
            assert sign * np.linalg.det(j[0]) <= 0
        return
    size = float(np.ptp(v, axis=0).max())
    p = np.concatenate([dense_samples(v, grid=10_000, along=0.5, corner_rings=8), _near_boundary(v, 1e-6 * size / 300)])
    d = dense_check(phi, p)  # the whole polygon: the closed form inside Gamma, the collar in the band
    assert d["folds"] == 0 and d["deep"] == 0, (shape, method, d)
    assert _image_of_gamma_is_simple(phi, cert.offset)


@pytest.mark.parametrize(
    "src, dst",
    [("grid_L.json", "grid_hexagon.json"), ("chelsea_ring.json", "chelsea_star.json")],
)
@pytest.mark.parametrize("method", ["mfs", "bem"])
def test_the_sample_pairs_are_accepted(src, dst, method):
    opts = MapOptions(method=method, check=False)
    f = build_map(read_polygon(os.path.join(SAMPLES, src)), read_polygon(os.path.join(SAMPLES, dst)), opts)
    for phi in (f.phi0, f.phi1):
        cert = phi.boundary_certificate
        assert cert.failed == 0 and cert.winding == 0 and cert.turns == 1 and cert.band, cert
        assert cert.offset in [min(0.01, 1e-5 * phi._size) * k for k in BAND_STEPS]


def test_degenerate_vertices_lie_in_the_proved_band():
    """t^2 data and mixed conditions (a boundary that slides along Theta's edges) force det J -> 0 at vertices, where
    no curve through them can be proved: the map is proved on Gamma inside and the collar covers the vertices,
    with the data as they are (t^2; mixed: the sliding correspondence the solution settles on)."""
    dart = Polygon(np.array([[10, 10], [120, 20], [60, 50], [20, 110]], dtype=float), name="dart")
    square = Polygon(np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]]), name="square")
    f = build_map(dart, square, MapOptions(method="mfs", conditions="mixed"))  # refitted once (512 sites)
    opts = MapOptions(method="mfs", src_boundary="quadratic")
    g = build_map(read_polygon(os.path.join(SAMPLES, "grid_L.json")), read_polygon(os.path.join(SAMPLES, "grid_hexagon.json")), opts)
    for phi in (f.phi0, g.phi0):
        assert phi._degenerate.any()
        cert = phi.boundary_certificate
        assert cert.ok and cert.band and phi.certify().checked == cert.checked
        d = dense_check(phi, dense_samples(phi.polygon.points, grid=10_000, along=0.5, corner_rings=12))
        assert d["folds"] == 0 and d["deep"] == 0, d


def test_an_mfs_fold_on_the_polygon_itself_is_real_and_the_map_is_proved_inside_instead():
    """A generated zigzag at the default 256 sites folds on its boundary next to a reflex vertex (under 0.001 px
    from it, where the cells never looked): the certificate on the polygon names a point with det J <= 0 by the
    map's own Jacobian, and the default proves the map inside instead, with the collar in the band."""
    from warpcli.maps.certificate import band_floor

    v = SHAPES["zigzag"](np.random.default_rng(11))
    poly = Polygon(v, name="zigzag")
    opts = MapOptions(method="mfs", check=False)
    phi = MFS.build(poly, regular_theta(poly, poly, opts), opts)
    sign = phi.theta.orientation * np.sign(poly.signed_area)
    whole = certify_boundary(phi.solution, v, phi.theta, sign, 0.0)
    assert whole.folds and not whole.ok
    j = phi.solution.jacobian(np.array([whole.where]))
    assert sign * np.linalg.det(j[0]) <= 0
    edge, _, dist = nearest_edge(np.array([whole.where]), v)
    assert dist[0] < 1e-9 * 300 and np.hypot(*(v - whole.where).T).min() < 0.05  # on an edge, next to a vertex
    cert = phi.boundary_certificate
    steps = [band_floor(phi._size) * k for k in BAND_STEPS]
    assert cert.ok and cert.band and cert.offset in steps
    # proved at the first distance that holds: every nearer one fails, the first one's failures counted
    nearer = [phi.certify_boundary_at(d) for d in steps[: steps.index(cert.offset)]]
    assert not any(c.ok for c in nearer)
    assert cert.closer == (nearer[0].failed if nearer else 0)
    assert phi.certify().ok


@pytest.mark.parametrize("kind", ["curve", "cloud", "axis", "ties"])
@pytest.mark.parametrize("seed", range(4))
def test_pairs_within_finds_exactly_the_pairs_a_dense_search_finds(kind, seed):
    """The capsules' candidate pairs (`_pairs_within`): every (i, j) with |w_j - w_i| <= radius_i, against
    all n^2 distances: points along a closed curve (as capsules' centres lie), a cloud, points on
    lines parallel to the axes (a sweep's worst case), repeated points; radii over decades."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    if kind == "curve":
        t = np.sort(rng.uniform(0, 2 * np.pi, n))
        w = (1 + 0.3 * np.cos(5 * t)) * np.exp(1j * t)
    elif kind == "cloud":
        w = rng.normal(size=n) + 1j * rng.normal(size=n)
    elif kind == "axis":
        w = np.where(rng.random(n) < 0.5, rng.integers(0, 3, n) + 1j * rng.uniform(0, 3, n),
                     rng.uniform(0, 3, n) + 1j * rng.integers(0, 3, n))
    else:
        w = rng.integers(0, 4, n) + 1j * rng.integers(0, 4, n) + 0.0
    radius = 10.0 ** rng.uniform(-4, 0.5, n)
    i, j = _pairs_within(w, radius)
    got = set(zip(i.tolist(), j.tolist()))
    dense = np.abs(w[None, :] - w[:, None]) <= radius[:, None]
    assert got == set(zip(*(x.tolist() for x in np.nonzero(dense))))
    assert len(got) == len(i)  # no pair twice


class Counted:
    """A closed form whose evaluations and bounds are counted (in points), failing the test past ``limit``."""

    def __init__(self, solution, limit: float = math.inf) -> None:
        self.solution, self.limit, self.points = solution, limit, 0

    def __getattr__(self, name):
        return getattr(self.solution, name)

    def _count(self, points) -> None:
        self.points += len(points)
        assert self.points <= self.limit, f"more than {self.limit:.0f} points evaluated or bounded"

    def value_jacobian_hessian(self, points):
        self._count(points)
        return self.solution.value_jacobian_hessian(points)

    def derivative_bounds(self, points, reach):
        self._count(points)
        return self.solution.derivative_bounds(points, reach)


def far_polygon(rng: np.random.Generator, kind: str) -> np.ndarray:
    """A polygon of unit size that BEM proves at its default nodes: an ellipse's inscribed polygon, a mild star,
    a rotated rectangle."""
    if kind == "ellipse":
        t = np.sort(rng.uniform(0, 2 * np.pi, int(rng.integers(5, 12))))
        v = np.stack([np.cos(t), rng.uniform(0.3, 1.0) * np.sin(t)], axis=1)
    elif kind == "star":
        k = int(rng.integers(5, 10))
        t = 2 * np.pi * (np.arange(k) + rng.uniform(-0.2, 0.2, k)) / k
        v = rng.uniform(0.6, 1.0, k)[:, None] * np.stack([np.cos(t), np.sin(t)], axis=1)
    else:
        a, th = rng.uniform(1.0, 4.0), rng.uniform(0, np.pi)
        rot = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
        v = np.array([[-a, -1.0], [a, -1.0], [a, 1.0], [-a, 1.0]]) @ rot
    return v / np.ptp(v, axis=0).max()


def _bem_certificate_work(v: np.ndarray, limit: float = math.inf):
    """The BEM map of polygon v (onto its regular Theta), its boundary certificate and the points it evaluated or bounded."""
    poly = Polygon(v, name="far")
    opts = MapOptions(method="bem", check=False)
    phi = BEM.build(poly, regular_theta(poly, poly, opts), opts)
    phi.solution = counted = Counted(phi.solution, limit)
    return phi.boundary_certificate, counted.points


@pytest.mark.parametrize("seed", range(6))
def test_bem_certificate_work_does_not_grow_with_the_polygons_scale(seed):
    """A polygon 1e5-3e6 px across (a target far larger than the image) is proved as at 2,000 px, with at most a
    small multiple of the evaluations and bounds. Gamma 0.01 px inside a 2e5 px square (5e-8 of its size) put
    BEM's evaluation error bound at 0.3 |A|: the pieces split without end (tens of millions, gigabytes)."""
    rng = np.random.default_rng(seed)
    v = far_polygon(rng, ["ellipse", "star", "rect"][seed % 3])
    near, work = _bem_certificate_work(2000.0 * v + 100.0)
    assert near.ok, near
    far, far_work = _bem_certificate_work(10 ** rng.uniform(5.0, 6.5) * v + 100.0, limit=4 * work)
    assert far.ok and far.band, far
    assert far_work <= 4 * work


def test_pieces_never_split_beyond_the_budget(monkeypatch):
    """A closed form whose evaluation error bound (eta = 0.6 |A|) is too large for any piece to be proved: the
    certificate fails within `MAX_PIECES` evaluations, and its splitting by the bounds alone (`_graded`) stays
    within a few times that (it doubled every piece 30 times, 2^30 each)."""
    monkeypatch.setattr(boundary_certificate, "MAX_PIECES", 20_000)

    class Blurred(Harmonic):
        def derivative_bounds(self, points, reach):
            out = super().derivative_bounds(points, reach)
            p = np.asarray(points, dtype=float)
            out[:, 0] = 0.6 * np.abs(self.g.deriv()(p[:, 0] + 1j * p[:, 1]))
            return out

    rng = np.random.default_rng(7)
    for kind in ("ellipse", "star", "rect"):
        v = 60.0 * far_polygon(rng, kind)  # inside Theta (BIG), where phi = z + conj(z) / 10 keeps it
        phi = Counted(Blurred([1.0, 0], [0.1, 0]), limit=5 * boundary_certificate.MAX_PIECES)
        cert = certify_boundary(phi, v, BIG, float(np.sign(Polygon(v, name=kind).signed_area)))
        assert cert.failed and not cert.folds, cert
        assert cert.checked <= boundary_certificate.MAX_PIECES
