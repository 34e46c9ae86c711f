"""The boundary certificate of a smooth map onto Theta (BEM, MFS): det J > 0 and one-to-one, proved on one curve.

Write the map as phi = u + i v (harmonic where the closed form is defined)
and let A = phi_z, B = conj(phi_zbar): both are analytic there and det J =
|A|^2 - |B|^2 (`warpcli.maps.certificate.lower_bound` uses the same
notation). Let Gamma be a closed polygonal curve, simple and
counter-clockwise, bounding a region R whose closure lies where A and B are
analytic (MFS: the polygon itself, its sites are outside; BEM: a curve
`offset` inside the polygon, `inner_offset`, its closed form being singular
at the boundary nodes). Write P for A and Q for B when the map should
preserve orientation (``sign`` +1), the other way round when it should
reverse it. If

1. |P| > |Q| at every point of Gamma, and
2. the winding number of P along Gamma is 0,

then P has no zero in R (argument principle: P is analytic, so the number
of its zeros inside is its winding number along Gamma), omega = Q / P is
analytic in R and continuous on its closure, |omega| < 1 on Gamma, hence
|omega| < 1 on all of R (maximum modulus principle) and sign * det J =
|P|^2 (1 - |omega|^2) > 0 on the closure of R. (Chen & Weber, "Bounded
distortion harmonic mappings in the plane", ACM Trans. Graph. 34(4), 2015,
build their injectivity criterion on the same argument: a harmonic map
whose f_z does not vanish and whose dilatation |f_zbar / f_z| is below 1 on
the boundary is locally injective inside.) If moreover

3. phi(Gamma) is a simple closed curve,

then phi is one-to-one on R: for y off phi(Gamma), the number of
pre-images of y in R, each counted with the sign of det J (+1 everywhere),
is the degree of phi on R at y, which is the winding number of phi(Gamma)
around y, 0 or +-1 for a simple curve, and never -1 since no pre-image
counts negatively (the degree argument of docs/proving.md, for a smooth
map). So phi maps R one-to-one onto the inside of phi(Gamma).

Each condition is proved piece by piece along Gamma, rigorously up to the
rounding bounds of `ClosedForm.derivative_bounds`. A piece is a segment of
Gamma of length 2 r, centre x0, unit direction e; at x0 the closed form
gives phi, J and the Hessian (A0, B0, A1 = A'(x0), B1), and
`ClosedForm.derivative_bounds` bounds the Taylor remainders rho_A, rho_B
over the disc of radius r and the evaluation error eta. On the piece:

- |P| >= |P0| - |P1| r - rho_P - eta and |Q| <= |Q0| + |Q1| r + rho_Q + eta:
  condition 1 holds where the first exceeds the second;
- P then stays in a disc around P0 that excludes 0, so its argument moves
  by less than pi / 2 from its value at x0, and the change between two
  consecutive centres is the principal value of arg(P0' / P0): their sum
  is the winding number (condition 2), exactly;
- the tangent of the image, D = dphi/ds = A e + conj(B e), stays within dD
  = (|A1| + |B1|) r + rho_A + rho_B + 2 eta of D0, so (with dD < |D0|) its
  direction within asin(dD / |D0|) of D0's, and phi(x0 + s e) within dD |s|
  of phi(x0) + s D0: the piece's image lies in a capsule (the segment
  phi(x0) +- r D0 thickened by dD r).

Condition 3 from the capsules: two pieces whose capsules do not meet have
disjoint images; two pieces whose capsules meet are joined along Gamma by a
chain of pieces (either way round); if the tangent directions of a chain's
pieces all lie in an open half-plane {D : u . D > 0}, then u . phi is
strictly increasing along the chain and the two pieces' images meet only
where the chain joins them (nowhere, unless they are neighbours). A pair
of pieces resolved neither way splits both (their capsules shrink); every
pair resolved proves phi(Gamma) simple. The capsules' candidate pairs come
from a sweep along one axis (`_pairs_within`); the chains' ranges of tangent
directions from sparse tables, O(1) per pair.

A piece that is not proved is split in two, down to pieces of `MIN_PIECE`
of the polygon's size; a piece not proved there fails: the certificate
proves the map or refuses it, nothing is left "unproved". A piece whose
centre has sign * det J <= 0 fails at once (a fold of the closed form, not
a weakness of the bound).

Values outside Theta (without the band's conditions below): phi maps R onto
the inside of phi(Gamma), so a value outside Theta comes from near Gamma;
at every piece's centre the cell certificate's measure (the distance to the polygon's boundary plus how
far, to first order, the point must move for its value to come back onto
Theta's edge line) must stay within the band (`BAND`): sampled, not
proved, as there.

The band between the polygon and Gamma (``offset`` > 0, with the boundary
data ``boundary`` given): there the map is the collar of
`warpcli.maps.collar`, (1 - t) g(F(s)) + t phi(G(s)) on the cells of
`offset_band`, and two more conditions on every piece make it one-to-one
from the band onto the ring between Theta's boundary and phi(Gamma):

4. the piece's capsule lies strictly inside every edge line of Theta (so
   phi(Gamma), and phi(R) inside it, are inside Theta: this replaces the
   sampled check of values outside Theta);
5. sign det(D, V) > 0 over the piece, V = phi - g(F) the collar's segment
   (`_collar` gives the bound): the segments cross phi(Gamma) the right
   way round.

The collar's Jacobian determinant is linear in t between det(g', V) (> 0 by
4) and det(D, V) (> 0 by 5), and the degree argument for the ring does the
rest (docs/proving.md). Without ``boundary`` the band is left to the
caller, as are vertices where the boundary data force det J -> 0
(`degenerate_vertices`): the caller keeps the cell certificate with its
left-out balls for those maps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .._arrays import sorted_unique
from ..boundary import nearest_edge
from ..grid import inside_polygon
from ..polygon.predicates import segments_touch, signed_area
from .certificate import BAND, BAND_RELATIVE, OUTSIDE

__all__ = ["MAX_PIECES", "MIN_PIECE", "BoundaryCertificate", "OffsetBand", "certify_boundary", "inner_offset", "offset_band"]

#: The polygonal arcs around reflex vertices (`inner_offset`) turn by at most this per chord (radians).
ARC_STEP = math.pi / 32
#: Starting pieces along Gamma are no longer than this fraction of the polygon's size.
START_PIECE = 1.0 / 256
#: Pieces are split down to this fraction of the polygon's size; one not proved there fails.
MIN_PIECE = 1e-9
#: Evaluations at most; beyond, the pieces still unproved fail.
MAX_PIECES = 2_000_000
#: Rounding of the value phi(x0) relative to Theta's size (sums of O(m) terms; the bounds' eta covers A, B).
VALUE_ERROR = 1e-11
#: Rounds of splitting by the bounds alone before an evaluation (`_graded`).
GRADING_ROUNDS = 30
#: Rounds of the simplicity test (each splits the pieces in pairs it could not resolve).
MAX_ROUNDS = 40


@dataclass(frozen=True)
class BoundaryCertificate:
    """What `certify_boundary` found.

    Attributes
    ----------
    failed : int
        0 when the map is proved one-to-one with det J > 0 on the region
        Gamma bounds. Otherwise at least 1: pieces of Gamma where condition
        1 fails at the centre or could not be proved at the smallest
        length, pieces in pairs whose images could not be told apart, or 1
        for a winding number of P that is not 0 (a zero of P inside).
    checked : int
        Evaluations of the closed form (pieces, all rounds).
    pieces : int
        Pieces of Gamma in the end (0 when a piece failed).
    winding : int or None
        The winding number of P along Gamma: its zeros inside (None when a
        piece failed: not computed).
    turns : int or None
        How many times phi(Gamma) goes around Theta's centre in the map's
        orientation (1 for a proved map; None when not computed, or when a
        piece's image comes near the centre). For the record: not needed
        by the proof.
    offset : float
        Gamma's distance inside the polygon (0: the boundary itself); the
        band between is not proved.
    folds : int
        Pieces whose centre has sign * det J <= 0 (among ``failed``).
    outside : int
        Pieces whose centre's value leaves Theta beyond the band (among
        ``failed``).
    tangled : int
        Pieces of the smallest length whose image could not be told apart
        from another's (among ``failed``).
    where : (float, float) or None
        A point of Gamma where a piece failed (the centre of the worst fold
        if any), in the polygon's coordinates.
    closer : int
        Failures of an attempt with Gamma closer to the boundary, when the
        caller moved it inwards (`SmoothMap.boundary_certificate` for MFS:
        the polygon itself first); 0 otherwise.
    band : bool
        Whether the band between the polygon and Gamma was proved too (the
        collar's conditions, 4 and 5 of the module's docstring): then the
        map with `warpcli.maps.collar.Collar` in the band is one-to-one on
        the whole polygon, onto Theta.
    crossed : int
        Pieces where the collar's condition 5 fails at the centre (among
        ``failed``).
    knots : (K, 7) ndarray of float or None
        The proved pieces, in Gamma's order: the edge, the centre's
        parameter along it, phi's value there (x, y), and the piece's
        capsule: its half-axis r D0 (x, y) and its thickness dD r + the
        rounding of the value (phi on the piece lies within the thickness of
        the segment w0 +- r D0); None unless ``band``.
        `warpcli.maps.collar.Collar.inverse` brackets with them.
    """

    failed: int
    checked: int
    pieces: int
    winding: int | None
    turns: int | None
    offset: float
    folds: int = 0
    outside: int = 0
    tangled: int = 0
    where: tuple[float, float] | None = None
    closer: int = 0
    band: bool = False
    crossed: int = 0
    knots: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        """True when the map is proved (``failed`` is 0)."""
        return self.failed == 0


def inner_offset(vertices: NDArray[np.float64], delta: float) -> NDArray[np.float64] | None:
    """The polygon moved ``delta`` inwards, counter-clockwise: mitred at convex corners, rounded at reflex ones; None if not simple.

    Each edge moves delta along its inward normal n. At a convex vertex the
    two moved edges meet at v + delta (n_prev + n) / (1 + n_prev . n); at a
    reflex vertex they are joined by a polygonal arc around v at radius
    delta (`ARC_STEP` radians per chord, so that Gamma turns there by small
    steps: a mitred reflex corner turns by up to pi at once, and a smooth
    map's image of it turns back by as much, which condition 3 of
    `certify_boundary` cannot accept). The result is checked: every moved
    edge keeps its direction and no two of its edges that do not share a
    vertex meet, so it is a simple polygon.

    Parameters
    ----------
    vertices : (n, 2) ndarray of float
        The polygon, either orientation.
    delta : float
        The distance; 0 returns the polygon counter-clockwise.

    Returns
    -------
    (k, 2) ndarray of float or None
    """
    band = offset_band(vertices, delta)
    return None if band is None else band.gamma


@dataclass(frozen=True)
class OffsetBand:
    """The band between a polygon and its `inner_offset` Gamma, cut into cells along the segments joining them.

    Cell c is the set of points (1 - t) F(s) + t G(s), s and t in [0, 1],
    with F(s) = F0 + s (F1 - F0) on the polygon's boundary (on one edge) and
    G(s) = G0 + s (G1 - G0) on Gamma, F1 - F0 and G1 - G0 parallel or one
    of them 0. Three kinds, in counter-clockwise order round the polygon: a
    strip along each moved edge (G1 - G0 = F1 - F0: a rectangle of width
    delta); a fan round each reflex vertex v per chord of its arc (F0 = F1
    = v); two trapezoids at each convex vertex v, where Gamma has its mitre
    point c and a point on each moved edge a little before and after it (F
    runs along the edge to v while G runs to c, then both on from there).
    Neighbouring cells share a segment from the polygon to Gamma; together
    they tile the band (the parametrisation has a positive Jacobian on every
    cell and runs once round both curves), and G moves in every cell.

    Attributes
    ----------
    gamma : (k, 2) ndarray of float
        Gamma, counter-clockwise.
    f0, f1, g0, g1 : (c, 2) ndarray of float
        The cells' ends on the polygon and on Gamma.
    edge : (c,) ndarray of int
        The polygon's edge holding F (in the polygon's own numbering and
        orientation, as given).
    t0, t1 : (c,) ndarray of float
        F0's and F1's parameters on that edge.
    of_gamma : (k,) ndarray of int
        The cell of each edge of Gamma (edge i runs from gamma[i] to
        gamma[i + 1]): cell i.
    """

    gamma: NDArray[np.float64]
    f0: NDArray[np.float64]
    f1: NDArray[np.float64]
    g0: NDArray[np.float64]
    g1: NDArray[np.float64]
    edge: NDArray[np.intp]
    t0: NDArray[np.float64]
    t1: NDArray[np.float64]
    of_gamma: NDArray[np.intp]


def offset_band(vertices: NDArray[np.float64], delta: float) -> OffsetBand | None:
    """Gamma (`inner_offset`) and the cells of the band between it and the polygon; None if Gamma is not simple.

    Parameters
    ----------
    vertices : (n, 2) ndarray of float
        The polygon, either orientation.
    delta : float
        Gamma's distance inside; 0 gives Gamma = the polygon (counter-clockwise) and no cells.

    Returns
    -------
    OffsetBand or None
    """
    v0 = np.asarray(vertices, dtype=np.float64)
    n = len(v0)
    flipped = signed_area(v0) < 0
    v = v0[::-1] if flipped else v0
    none = np.zeros((0, 2))
    if delta == 0:
        ints = np.zeros(0, dtype=np.intp)
        return OffsetBand(v.copy(), none, none, none, none, ints, np.zeros(0), np.zeros(0), ints)
    e = np.roll(v, -1, axis=0) - v
    e2 = (e * e).sum(axis=1)
    nrm = np.stack([-e[:, 1], e[:, 0]], axis=1) / np.sqrt(e2)[:, None]  # inward (left of a ccw edge)
    prev = np.roll(nrm, 1, axis=0)
    cos = (prev * nrm).sum(axis=1)
    turn = np.roll(e, 1, axis=0)[:, 0] * e[:, 1] - np.roll(e, 1, axis=0)[:, 1] * e[:, 0]  # < 0: reflex
    first, last = np.zeros((n, 2)), np.zeros((n, 2))
    mitre, arcs = {}, {}
    for i in range(n):  # loop over vertices: a mitre point (convex) or an arc (reflex)
        if turn[i] >= 0:
            if 1.0 + cos[i] < 1e-12:
                return None
            mitre[i] = first[i] = last[i] = v[i] + delta * (prev[i] + nrm[i]) / (1.0 + cos[i])
        else:
            a0 = math.atan2(prev[i, 1], prev[i, 0])
            sweep = math.atan2(prev[i, 0] * nrm[i, 1] - prev[i, 1] * nrm[i, 0], float(prev[i] @ nrm[i]))
            sweep = sweep if sweep < 0 else sweep - 2 * math.pi  # clockwise, from n_prev to n
            k = max(1, math.ceil(abs(sweep) / ARC_STEP))
            ang = a0 + sweep * np.arange(k + 1) / k
            arcs[i] = v[i] + delta * np.stack([np.cos(ang), np.sin(ang)], axis=1)
            first[i], last[i] = arcs[i][0], arcs[i][-1]
    # moved edge i runs from vertex i's last point to vertex i + 1's first
    moved = np.roll(first, -1, axis=0) - last
    along = (moved * e).sum(axis=1) / np.sqrt(e2)
    if (along <= 0).any():
        return None
    unit = e / np.sqrt(e2)[:, None]
    pts = []
    cells = []  # (f0, f1, g0, g1, ccw edge, t0, t1)

    def param(i, p):  # parameter of p's projection on ccw edge i
        return float((p - v[i]) @ e[i]) / float(e2[i])

    for i in range(n):  # loop over vertices, then the moved edge after each
        h = (i - 1) % n
        if i in mitre:
            # Gamma gets a point a little before and after the mitre point c on the moved edges, and
            # the corner two trapezoids: F runs along an edge to v while G runs to c (then from them),
            # so that G moves in every cell (with t^2 data g stands still at v: a cell with G fixed
            # would have det J = 0 along the whole segment from v to c)
            c = mitre[i]
            ch = c - min(delta, 0.25 * along[h]) * unit[h]
            ci = c + min(delta, 0.25 * along[i]) * unit[i]
            pts.append(np.stack([ch, c, ci]))
            first[i], last[i] = ch, ci
            fh, fi = ch - delta * nrm[h], ci - delta * nrm[i]
            cells.append((fh, v[i], ch, c, h, param(h, fh), 1.0))
            cells.append((v[i], fi, c, ci, i, 0.0, param(i, fi)))
        else:
            arc = arcs[i]
            pts.append(arc)
            cells.extend((v[i], v[i], arc[j], arc[j + 1], i, 0.0, 0.0) for j in range(len(arc) - 1))
        cells.append((i,))  # moved edge i (a strip), once every vertex's points are known
    for c, cell in enumerate(cells):
        if len(cell) == 1:
            i = cell[0]
            ga, gb = last[i], first[(i + 1) % n]
            fa, fb = ga - delta * nrm[i], gb - delta * nrm[i]
            cells[c] = (fa, fb, ga, gb, i, param(i, fa), param(i, fb))
    g = np.concatenate(pts)
    if _self_crossing(g) or _crossing(g, v) or not inside_polygon(g[:1], v)[0]:
        return None
    f0, f1, g0, g1 = (np.array([cell[k] for cell in cells], dtype=np.float64) for k in range(4))
    edge = np.array([cell[4] for cell in cells], dtype=np.intp)
    t0 = np.array([cell[5] for cell in cells])
    t1 = np.array([cell[6] for cell in cells])
    of_gamma = np.arange(len(cells))  # every cell has its edge of Gamma, in order
    if flipped:  # ccw edge i is edge n - 2 - i of the polygon as given, run backwards
        edge = (n - 2 - edge) % n
        t0, t1 = 1.0 - t0, 1.0 - t1
    return OffsetBand(g, f0, f1, g0, g1, edge, np.clip(t0, 0.0, 1.0), np.clip(t1, 0.0, 1.0), of_gamma)


def _crossing(g: NDArray[np.float64], v: NDArray[np.float64]) -> bool:
    """Whether an edge of the closed polyline g meets (or touches) an edge of the polygon v (exactly)."""
    a, b = g, np.roll(g, -1, axis=0)
    for p, q in zip(v, np.roll(v, -1, axis=0)):  # loop over the polygon's edges, vectorised over g's
        if segments_touch(a, b, np.broadcast_to(p, a.shape), np.broadcast_to(q, a.shape)).any():
            return True
    return False


def _self_crossing(g: NDArray[np.float64]) -> bool:
    """Whether two edges of the closed polyline g that do not share a vertex meet (exactly).

    Only pairs whose closed bounding boxes overlap can meet (a common point lies in both boxes,
    compared as the doubles they are): the exact test runs on those, found in blocks of edges
    against all later ones (O(n^2) comparisons of coordinates, few exact predicates).
    """
    n = len(g)
    a, b = g, np.roll(g, -1, axis=0)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    block = 256
    for s in range(0, n, block):  # blocks of edges, vectorised over the later edges
        i = np.arange(s, min(n, s + block))[:, None]
        j = np.arange(n)[None, :]
        # j shares no vertex with i: not i - 1, i, i + 1 (and edge n - 1 is edge 0's neighbour)
        later = (j >= i + 2) & ~((i == 0) & (j == n - 1))
        meet = later & (lo[i, 0] <= hi[j, 0]) & (lo[j, 0] <= hi[i, 0]) & (lo[i, 1] <= hi[j, 1]) & (lo[j, 1] <= hi[i, 1])
        ii, jj = np.nonzero(meet)
        if ii.size:
            ii += s
            if segments_touch(a[ii], b[ii], a[jj], b[jj]).any():
                return True
    return False


def certify_boundary(solution, vertices, theta, sign: float, offset: float = 0.0, boundary=None) -> BoundaryCertificate:
    """Prove det J > 0 and injectivity on the region bounded by a curve `offset` inside the polygon.

    See the module's docstring for what is proved and how.

    Parameters
    ----------
    solution : ClosedForm
        ``value_jacobian_hessian`` and ``derivative_bounds`` of the map;
        analytic on a neighbourhood of Gamma and of the region it bounds.
    vertices : (n, 2) ndarray of float
        The polygon.
    theta : Theta
        Where its values must lie (convex).
    sign : float
        +1 or -1: the sign det J has when the map preserves the orientation
        it should (Theta's orientation times the polygon's).
    offset : float
        Gamma's distance inside the polygon (`inner_offset`); 0: the
        polygon's boundary (MFS).
    boundary : BoundaryData or None
        The boundary data (Theta's point for the point at parameter t of
        the polygon's edge: linear, t^2 or a sliding table along each edge).
        Given with ``offset`` > 0, the band is proved too (``band``).

    Returns
    -------
    BoundaryCertificate
    """
    v = np.asarray(vertices, dtype=np.float64)
    size = float(np.ptp(v, axis=0).max())
    band = min(BAND, BAND_RELATIVE * size)
    cells = offset_band(v, offset)
    if cells is None:  # the offset curve is not simple: nothing proved
        return BoundaryCertificate(1, 0, 0, None, None, offset)
    gamma = cells.gamma
    collar = boundary is not None and offset > 0
    w = theta.points
    tsize = float(np.ptp(w, axis=0).max())
    centre = w.mean(axis=0)
    c0 = complex(centre[0], centre[1])
    # starting pieces: every edge of Gamma cut into equal pieces of at most START_PIECE * size;
    # a piece is (edge, t0, t1): the part of Gamma's edge between those parameters
    ge = np.roll(gamma, -1, axis=0) - gamma
    length = np.hypot(ge[:, 0], ge[:, 1])
    count = np.maximum(1, np.ceil(length / (START_PIECE * size))).astype(np.int64)
    edge = np.repeat(np.arange(len(gamma)), count)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    idx = np.arange(int(count.sum())) - np.repeat(first, count)
    t0 = idx / count[edge]
    t1 = (idx + 1) / count[edge]
    floor = MIN_PIECE * size
    nd = np.roll(w, -1, axis=0) - w
    nd = nd / np.hypot(nd[:, 0], nd[:, 1])[:, None]
    slack = OUTSIDE * tsize
    noise = VALUE_ERROR * tsize
    if collar:  # the cell of each Gamma edge (a strip or a reflex fan): its polygon edge and parameters
        cg = cells.of_gamma
        c_edge, c_t0, c_dt = cells.edge[cg], cells.t0[cg], cells.t1[cg] - cells.t0[cg]
    # the pieces kept so far (proved one by one), column-wise
    keep = {k: [] for k in ("edge", "t0", "t1", "p0", "w0", "d0", "dd", "r")}
    failed = folds = outside = checked = tangled = crossed = 0
    winding = where = None
    for _ in range(MAX_ROUNDS):
        while len(edge):  # condition 1 (and the tangent's direction), splitting what is not proved
            a = gamma[edge] + t0[:, None] * ge[edge]
            b = gamma[edge] + t1[:, None] * ge[edge]
            x0 = 0.5 * (a + b)
            r = 0.5 * (t1 - t0) * length[edge]
            val, j, h = solution.value_jacobian_hessian(x0)
            bound = solution.derivative_bounds(x0, r)
            checked += len(x0)
            eta, rho_a, rho_b = bound[:, 0], bound[:, 1], bound[:, 2]
            ux, uy, vx, vy = j[:, 0, 0], j[:, 0, 1], j[:, 1, 0], j[:, 1, 1]
            a0 = 0.5 * ((ux + vy) + 1j * (vx - uy))
            b0 = 0.5 * ((ux - vy) - 1j * (vx + uy))
            uxx, uxy, vxx, vxy = h[:, 0, 0, 0], h[:, 0, 0, 1], h[:, 1, 0, 0], h[:, 1, 0, 1]
            a1 = np.abs(0.5 * ((uxx + vxy) + 1j * (vxx - uxy)))
            b1 = np.abs(0.5 * ((uxx - vxy) - 1j * (vxx + uxy)))
            if sign > 0:
                p0, p1, rp, q0, q1, rq = a0, a1, rho_a, b0, b1, rho_b
            else:
                p0, p1, rp, q0, q1, rq = b0, b1, rho_b, a0, a1, rho_a
            e = (ge[edge, 0] + 1j * ge[edge, 1]) / length[edge]
            d0 = a0 * e + np.conj(b0 * e)
            with np.errstate(invalid="ignore", over="ignore"):
                low = np.abs(p0) - p1 * r - rp - eta
                high = np.abs(q0) + q1 * r + rq + eta
                dd = (a1 + b1) * r + rho_a + rho_b + 2.0 * eta
                proved = (low > high) & (dd < np.abs(d0))  # condition 1; the tangent's direction known
            fold = ~(np.abs(p0) > np.abs(q0))
            if collar:  # conditions 4 and 5: the band's collar
                # the data at the foot of x0 and their first and second derivatives along Gamma
                rate = c_dt[edge] / length[edge]
                ta, tb = c_t0[edge] + t0 * c_dt[edge], c_t0[edge] + t1 * c_dt[edge]
                tm = 0.5 * (ta + tb)
                gc = boundary.points(c_edge[edge], tm) @ np.array([1.0, 1j])
                gp = boundary.tangent(c_edge[edge], tm) @ np.array([1.0, 1j]) * rate
                stray = boundary.stray(c_edge[edge], ta, tb, 0.5 * (tb - ta))
                inset, transverse, far, cross = _collar(val, d0, dd, r, gc, gp, stray, w, nd, theta.orientation, sign, noise)
                proved &= (inset > 0) & (transverse > 0)
                crossed += int((cross & ~fold & ~far).sum())
            else:
                far = _outside(val, j, x0, v, w, nd, theta.orientation, slack, band)
                cross = np.zeros(len(x0), dtype=bool)
            bad = fold | far | cross
            proved &= ~bad
            lost = ~proved & ~bad & (2.0 * r <= floor)
            folds += int(fold.sum())
            outside += int((far & ~fold).sum())
            failed += int(bad.sum() + lost.sum())
            if failed:
                k = np.flatnonzero(bad | lost)
                worst = k[np.argmin((np.abs(p0) - np.abs(q0))[k])] if fold.any() else k[0]
                where = (float(x0[worst, 0]), float(x0[worst, 1]))
                break
            k = np.flatnonzero(proved)
            for name, col in (("edge", edge), ("t0", t0), ("t1", t1), ("p0", p0), ("d0", d0), ("dd", dd), ("r", r)):
                keep[name].append(col[k])
            keep["w0"].append(val[k, 0] + 1j * val[k, 1])
            split = np.flatnonzero(~proved)
            if checked + 2 * split.size > MAX_PIECES:
                failed += int(split.size)
                break
            edge, t0, t1 = _graded(
                solution, gamma, ge, length, floor, edge[split], t0[split], t1[split],
                (np.abs(p0) - np.abs(q0))[split], (p1 + q1)[split], np.abs(d0)[split], (a1 + b1)[split],
                MAX_PIECES - checked,
            )  # fmt: skip
        if failed:
            break
        col = {name: np.concatenate(parts) for name, parts in keep.items()}
        order = np.lexsort((col["t0"], col["edge"]))
        col = {name: c[order] for name, c in col.items()}
        keep = {name: [c] for name, c in col.items()}
        if winding is None:
            # condition 2, once every piece has condition 1 (later splits cannot change it):
            # consecutive centres, cyclically, whose principal increments add up to the exact change
            p = col["p0"]
            winding = int(round(float(np.angle(np.roll(p, -1) / p).sum()) / (2 * math.pi)))
            if winding != 0:  # P has a zero inside: det J <= 0 there
                failed += 1
                break
        # condition 3: pairs of pieces whose images' capsules meet, each resolved by a chain
        unresolved = _crossing_candidates(col, noise)
        if not unresolved.size:
            break
        small = 2.0 * col["r"][unresolved] <= floor
        if small.any() or checked + 2 * unresolved.size > MAX_PIECES:
            tangled = int(small.sum()) or int(unresolved.size)
            failed += tangled
            break
        rest = np.ones(len(col["r"]), dtype=bool)
        rest[unresolved] = False
        keep = {name: [c[rest]] for name, c in col.items()}
        edge, t0, t1 = _halves(col["edge"][unresolved], col["t0"][unresolved], col["t1"][unresolved])
    else:
        failed += 1  # MAX_ROUNDS of splitting did not tell the capsules apart
    if failed:
        return BoundaryCertificate(failed, checked, 0, winding, None, offset, folds, outside, tangled, where, crossed=crossed)
    wv = col["w0"] - c0
    reach = np.abs(col["d0"]) * col["r"] + col["dd"] * col["r"] + noise
    turns = None
    if (reach < np.abs(wv)).all():  # every piece's image keeps off Theta's centre: its turns, for the record
        turns = int(round(sign * float(np.angle(np.roll(wv, -1) / wv).sum()) / (2 * math.pi)))
    knots = None
    if collar:
        mid = 0.5 * (col["t0"] + col["t1"])
        axis = col["r"] * col["d0"]
        thick = col["dd"] * col["r"] + noise
        knots = np.stack([col["edge"].astype(np.float64), mid, col["w0"].real, col["w0"].imag, axis.real, axis.imag, thick], axis=1)
    return BoundaryCertificate(0, checked, len(wv), winding, turns, offset, 0, 0, 0, band=collar, knots=knots)


def _halves(edge, t0, t1):
    """Each piece (edge, t0, t1) split in two."""
    mid = 0.5 * (t0 + t1)
    return np.repeat(edge, 2), np.stack([t0, mid], axis=1).ravel(), np.stack([mid, t1], axis=1).ravel()


def _graded(solution, gamma, ge, length, floor, edge, t0, t1, margin, slope, tangent, bend, budget):
    """The pieces (edge, t0, t1) that were not proved, split where the remainder bounds alone say they must be.

    Evaluating the closed form costs BEM a pass of its treecode (~0.1 s for
    300 points next to the boundary), its bounds far less: each piece is
    split in two, then its parts again while `ClosedForm.derivative_bounds`
    says that, with the parent's margin |P0| - |Q0| and first derivatives,
    half that margin would not be enough (a prediction: what is proved is
    decided on evaluation). So a piece next to a node is cut down to the
    node's scale in one evaluation round instead of ten.

    At most ``budget`` pieces come out (the evaluations `MAX_PIECES` still
    allows; the caller has checked that halving every piece fits): a round
    that would split beyond it is not made, and the caller fails what it
    cannot then prove. Without the cap, pieces whose bound does not shrink
    with their length (BEM's evaluation error eta, when Gamma is so close to
    the boundary that it outweighs the margin) doubled every round, 2^30 of
    each (a 2e5 px square at 0.01 px: 15 million pieces and gigabytes after
    14 rounds, before a single evaluation).
    """
    edge, t0, t1 = _parts(edge, t0, t1, np.full(len(edge), 2))
    owner = np.repeat(np.arange(len(margin)), 2)
    done_e, done_0, done_1 = [], [], []
    for _ in range(GRADING_ROUNDS):  # each halves what the bounds alone cannot accept
        x0 = gamma[edge] + (0.5 * (t0 + t1))[:, None] * ge[edge]
        r = 0.5 * (t1 - t0) * length[edge]
        bound = solution.derivative_bounds(x0, r)
        with np.errstate(invalid="ignore", over="ignore"):
            loss = slope[owner] * r + bound[:, 1] + bound[:, 2] + 2.0 * bound[:, 0]
            ok = (loss < 0.5 * margin[owner]) & (bend[owner] * r + bound[:, 1] + bound[:, 2] < 0.5 * tangent[owner])
        ok |= ~(margin[owner] > 0) | (2.0 * r <= 2.0 * floor)  # a fold, or as small as pieces get: evaluate
        done_e.append(edge[ok])
        done_0.append(t0[ok])
        done_1.append(t1[ok])
        more = np.flatnonzero(~ok)
        if not more.size:
            break
        if sum(map(len, done_e)) + 2 * more.size > budget:  # evaluate these as they are
            done_e.append(edge[more])
            done_0.append(t0[more])
            done_1.append(t1[more])
            break
        edge, t0, t1 = _parts(edge[more], t0[more], t1[more], np.full(more.size, 2))
        owner = np.repeat(owner[more], 2)
    else:
        done_e.append(edge)
        done_0.append(t0)
        done_1.append(t1)
    return np.concatenate(done_e), np.concatenate(done_0), np.concatenate(done_1)


def _parts(edge, t0, t1, parts):
    """Piece k (edge, t0, t1) split into parts[k] equal pieces."""
    k = np.repeat(np.arange(len(edge)), parts)
    first = np.cumsum(parts) - parts
    i = np.arange(int(parts.sum())) - np.repeat(first, parts)
    span = (t1 - t0)[k] / parts[k]
    return edge[k], t0[k] + i * span, np.where(i + 1 == parts[k], t1[k], t0[k] + (i + 1) * span)


def _crossing_candidates(col, noise: float) -> NDArray[np.intp]:
    """The pieces (indices, in Gamma's order) in a pair whose capsules meet and that no chain resolves.

    Capsule k: the segment phi(x0) +- r D0 thickened by dD r (+ rounding).
    A pair is resolved when the chain of pieces between them, either way
    round Gamma, has all its tangent directions (arg D0 +- asin(dD / |D0|))
    within an arc shorter than pi.
    """
    n = len(col["r"])
    w0, d0, r, dd = col["w0"], col["d0"], col["r"], col["dd"]
    half = r * d0
    thick = dd * r + noise
    extent = np.abs(half) + thick
    # a meeting pair is within ext_i + ext_j <= 2 max(ext_i, ext_j): found from its larger capsule
    i, jj = _pairs_within(w0, 2.0 * extent * (1.0 + 1e-9) + 1e-300)
    pick = (jj != i) & ((extent[i] > extent[jj]) | ((extent[i] == extent[jj]) & (i < jj)))
    i, jj = i[pick], jj[pick]
    meet = _segment_distance(w0[i] - half[i], w0[i] + half[i], w0[jj] - half[jj], w0[jj] + half[jj]) <= thick[i] + thick[jj]
    i, jj = i[meet], jj[meet]
    if not i.size:
        return np.zeros(0, dtype=np.intp)
    lo_i, hi_i = np.minimum(i, jj), np.maximum(i, jj)
    # tangent directions unwrapped along Gamma (principal steps: exact wherever a chain's
    # directions fit in a half-circle, the only case the test accepts), twice round
    step = np.angle(np.roll(d0, -1) / d0)
    phi = np.concatenate([[0.0], np.cumsum(step)])  # phi[k] for k = 0..n (phi[n]: once round)
    total = phi[n]
    ang = np.concatenate([phi[:n], phi[:n] + total])
    eps = np.arcsin(np.minimum(1.0, dd / np.abs(d0)))
    eps = np.concatenate([eps, eps])
    top, bottom = _SparseTable(ang + eps, np.maximum), _SparseTable(ang - eps, np.minimum)
    forward = top.query(lo_i, hi_i) - bottom.query(lo_i, hi_i) < math.pi
    backward = top.query(hi_i, lo_i + n) - bottom.query(hi_i, lo_i + n) < math.pi
    bad = ~(forward | backward)
    return sorted_unique(np.concatenate([lo_i[bad], hi_i[bad]]))


def _pairs_within(w: NDArray[np.complex128], radius: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Every pair (i, j), i == j included, with |w_j - w_i| <= radius_i, as two index arrays.

    A sweep along one axis per point, the one where fewer points lie within
    its radius (the points follow a curve: along a stretch parallel to one
    axis the other sorts them apart), then the exact distance. Replaces a
    k-d tree (`scipy.spatial.cKDTree`, whose import cost a 1 MP warp 0.09 s):
    the callers keep only pairs whose capsules meet, all well within the
    radius, so the same pairs come out whichever superset is searched.
    """
    sweeps = []
    for coord in (w.real, w.imag):
        order = np.argsort(coord, kind="stable")
        ranked = coord[order]
        lo = np.searchsorted(ranked, coord - radius, side="left")
        hi = np.searchsorted(ranked, coord + radius, side="right")
        sweeps.append((order, lo, hi - lo))
    along_y = sweeps[1][2] < sweeps[0][2]
    firsts, seconds = [], []
    for (order, lo, count), which in zip(sweeps, (~along_y, along_y)):
        k = np.flatnonzero(which)
        cnt = count[k]
        start = np.cumsum(cnt) - cnt
        pos = np.arange(int(cnt.sum())) - np.repeat(start - lo[k], cnt)
        firsts.append(np.repeat(k, cnt))
        seconds.append(order[pos])
    i, j = np.concatenate(firsts), np.concatenate(seconds)
    close = np.abs(w[j] - w[i]) <= radius[i]
    return i[close].astype(np.intp), j[close].astype(np.intp)


class _SparseTable:
    """Range maxima (or minima) of a fixed array in O(1) per query, vectorised."""

    def __init__(self, values: NDArray[np.float64], op) -> None:
        self.op = op
        self.levels = [values]
        k = 1
        while 2 * k <= len(values):
            prev = self.levels[-1]
            self.levels.append(op(prev[:-k], prev[k:]))
            k *= 2

    def query(self, lo: NDArray[np.intp], hi: NDArray[np.intp]) -> NDArray[np.float64]:
        """op over values[lo..hi] (inclusive, lo <= hi)."""
        span = hi - lo + 1
        level = np.floor(np.log2(span)).astype(np.int64)
        out = np.empty(len(lo))
        for lv in sorted_unique(level):  # loop over the (few) levels present
            k = level == lv
            table = self.levels[lv]
            out[k] = self.op(table[lo[k]], table[hi[k] - (1 << lv) + 1])
        return out


def _segment_distance(a, b, c, d) -> NDArray[np.float64]:
    """Distances between the segments [a, b] and [c, d] (complex endpoints, vectorised)."""

    def cross(u, v):
        return (np.conj(u) * v).imag

    def to_segment(p, s, t):
        e = t - s
        den = np.abs(e) ** 2
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.where(den > 0, ((np.conj(e) * (p - s)).real) / den, 0.0)
        return np.abs(p - (s + np.clip(u, 0.0, 1.0) * e))

    d1, d2 = cross(b - a, c - a), cross(b - a, d - a)
    d3, d4 = cross(d - c, a - c), cross(d - c, b - c)
    crossing = (d1 * d2 < 0) & (d3 * d4 < 0)
    near = np.minimum(np.minimum(to_segment(a, c, d), to_segment(b, c, d)), np.minimum(to_segment(c, a, b), to_segment(d, a, b)))
    return np.where(crossing, 0.0, near)


def _collar(val, d0, dd, r, gc, gp, stray, w, nd, orientation, sign, noise):
    """Conditions 4 and 5 on each piece: margins (> 0: proved on the whole piece) and failures at its centre.

    Piece: centre value w0 = phi(x0), tangent D0 of phi along Gamma (per unit
    length), dD, half-length r; gc and gp the boundary data at the foot of
    x0 and their derivative along the piece (0 on a reflex fan), stray a
    bound on how far they leave their tangent over the piece
    (`BoundaryData.stray`). On the piece phi = w0 + s D0 + E1 with |E1| <=
    dD |s|, D = D0 + E2 with |E2| <= dD, g = gc + s gp + Eg with |Eg| <=
    stray, and V = phi - g = V0 + s (D0 - gp) + E1 - Eg, so

        sign det(D, V) >= sign det(D0, V0) - r |det(D0, gp)| - |D0| dD r
                          - dD (|V0| + r |D0 - gp| + dD r + stray)
                          - |D0| stray - (|D0| + dD) noise

    (condition 5), and phi stays in the capsule w0 +- r D0 thickened by dD r
    + noise, strictly inside every edge line of Theta (condition 4).

    Returns
    -------
    inset, transverse : (K,) ndarray of float
        The margins of conditions 4 and 5 over the piece.
    outside, crossed : (K,) ndarray of bool
        The centre's value on or beyond an edge line of Theta; sign
        det(D0, V0) <= 0 at the centre: failures no split can mend.
    """
    w0 = val[:, 0] + 1j * val[:, 1]
    inset = np.full(len(w0), np.inf)
    depth = np.full(len(w0), np.inf)
    for i in range(len(w)):  # loop over Theta's edges (convex: inside every edge line)
        u = nd[i, 0] + 1j * nd[i, 1]
        inner = (np.conj(u) * (w0 - complex(w[i, 0], w[i, 1]))).imag * orientation  # distance inside edge line i
        depth = np.minimum(depth, inner)
        reach = r * np.abs((np.conj(u) * d0).imag) + dd * r + noise
        inset = np.minimum(inset, inner - reach)
    v0 = w0 - gc
    det0 = sign * (np.conj(d0) * v0).imag
    loss = r * np.abs((np.conj(d0) * gp).imag) + np.abs(d0) * dd * r
    loss = loss + dd * (np.abs(v0) + r * np.abs(d0 - gp) + dd * r + stray) + np.abs(d0) * stray + (np.abs(d0) + dd) * noise
    with np.errstate(invalid="ignore"):
        return inset, det0 - loss, ~(depth > noise), ~(det0 > 0)


def _outside(val, j, x0, v, w, nd, orientation, slack, band) -> NDArray[np.bool_]:
    """Centres whose value lies outside Theta so far that the boundary, seen through phi, moves in by more than the band.

    The cell certificate's measure (`warpcli.maps.certificate.certify_cells`):
    the distance of x0 to the polygon's boundary plus max_i e_i / |J^T n_i|
    (e_i: how far phi(x0) lies beyond Theta's edge line i, n_i its normal).
    """
    beyond = np.zeros(len(val))
    shift = np.zeros(len(val))
    for i in range(len(w)):  # loop over Theta's edges (convex Theta: the farthest edge line)
        cross = nd[i, 0] * (val[:, 1] - w[i, 1]) - nd[i, 1] * (val[:, 0] - w[i, 0])
        ei = -cross * orientation
        beyond = np.maximum(beyond, ei)
        normal = np.array([nd[i, 1], -nd[i, 0]]) * orientation  # outward
        across = np.hypot(*(np.einsum("kab,a->kb", j, normal)).T)  # |J^T n_i|
        with np.errstate(divide="ignore", invalid="ignore"):
            shift = np.where(ei > slack, np.fmax(shift, np.where(across > 0, ei / across, np.inf)), shift)
    out = beyond > slack
    if out.any():
        k = np.flatnonzero(out)
        delta = nearest_edge(x0[k], v)[2]
        out[k] = ~(delta + shift[k] <= band)
    return out
