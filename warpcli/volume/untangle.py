"""Untangling: moving the images of interior nodes into the kernels of their stars, so that no tetrahedron of a discrete map is inverted.

In 3D the P1 harmonic map can invert tetrahedra (cotangent weights can be
negative, and Radó-Kneser-Choquet has no 3D analogue). A piecewise-linear map
is locally injective when every tetrahedron keeps its orientation; moving the
image of one interior node changes only the tetrahedra around it, and they
are all positively oriented exactly when the node lies inside the kernel of
its star: the intersection of the half-spaces on the inner side of the
opposite faces' planes, a convex polytope. Each node of an inverted
tetrahedron is moved, in a fixed order, to the point of its kernel nearest
its harmonic position with a margin from the kernel's boundary, found by
linear programming (the local untangling of Freitag and Plassmann, 2000,
with the Chebyshev centre's distance to the faces as the measure). Where a
kernel is empty, the node goes to the point that makes its worst tetrahedron
least inverted, and the neighbourhood grows ring by ring until its nodes can
make room. Boundary nodes never move: the map still takes the cage's faces
onto Theta's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..polygon.predicates import orient3d_sign

#: A moved node keeps at least this fraction of the largest distance to the
#: faces of its star that the star allows (the Chebyshev radius of its kernel):
#: 0 would leave a tetrahedron flat, 1 moves the node to the kernel's centre.
MARGIN = 0.25

#: Where a node's kernel is empty, it goes where the distances to the faces
#: fall short of this (in units of its star's size) by the least in sum.
EMPTY_MARGIN = 0.02

#: Rounds of moves before giving up.
ROUNDS = 30

#: Untangling is a local repair: a map with more inverted tetrahedra than
#: this is left as it is (it folds at large, and no local move will do), and
#: the moves stop after this many linear programs (a few milliseconds each).
MAX_INVERTED = 1000
MAX_PROGRAMS = 10_000

#: Rings of neighbours the moved set may grow by where a kernel is empty.
MAX_RINGS = 4

#: A face of a star whose area is below this times the square of the star's
#: size is flat (three nodes on one line of Theta): it puts no bound on where
#: the star's node may go.
FLAT = 1e-9

#: Oriented faces opposite each corner of a tetrahedron (a, b, c, d): the
#: signed volume is ``n . (x - f0) / 6`` in the corner's position x, with
#: ``n = (f1 - f0) x (f2 - f0)``.
_OPPOSITE = np.array([[1, 3, 2], [0, 2, 3], [0, 3, 1], [0, 1, 2]])


@dataclass(frozen=True)
class Untangled:
    """What `untangle` did.

    Attributes
    ----------
    values : (N, 3) ndarray of float
        The map at the nodes, with moved interior nodes.
    inverted_before, inverted_after : int
        Inverted tetrahedra (see `inverted`) before and after.
    moved : (K,) ndarray of int64
        The nodes moved, ascending.
    rounds : int
        Rounds of moves made.
    programs : int
        Linear programs solved.
    """

    values: NDArray[np.float64]
    inverted_before: int
    inverted_after: int
    moved: NDArray[np.int64]
    rounds: int
    programs: int

    def describe(self) -> dict:
        return {
            "inverted_before": self.inverted_before, "inverted_after": self.inverted_after,
            "moved_nodes": int(len(self.moved)), "rounds": self.rounds, "programs": self.programs,
        }  # fmt: skip


def inverted(values: NDArray[np.float64], tets: NDArray[np.integer]) -> NDArray[np.bool_]:
    """Tetrahedra whose image is inverted or flat: every one that does not keep its orientation.

    Orientation is decided exactly (`warpcli.polygon.predicates.orient3d_sign`):
    a float volume can have the wrong sign on a near-flat tetrahedron, and a
    certificate that can miss an inversion is no certificate. A flat image
    counts, whatever makes it flat (its fixed nodes alone, on one face or
    edge of Theta, included): it sends a solid sliver onto a triangle, so the
    map is not one-to-one there. A corner that is not finite counts as
    inverted.
    """
    return ~(tet_signs(values, tets) > 0)


def tet_signs(values: NDArray[np.float64], tets: NDArray[np.integer]) -> NDArray[np.float64]:
    """The exact orientation (1, 0, -1; NaN for a corner not finite) of each tetrahedron's image,
    with the sign of `warpcli.volume.tetmesh.tet_volumes`."""
    return orient3d_sign(*(values[tets[:, k]] for k in range(4)))


def untangle(
    values: NDArray[np.float64],
    tets: NDArray[np.integer],
    fixed: NDArray[np.bool_],
    *,
    margin: float = MARGIN,
    rounds: int = ROUNDS,
) -> Untangled:
    """Move the images of free nodes so that no tetrahedron's image is inverted, where that can be done.

    Only the nodes of inverted tetrahedra move (and, where their kernels are
    empty, rings of their neighbours): the cost is a few small linear
    programs per inverted tetrahedron, whatever the mesh's size. The result
    does not depend on thread counts (nodes in ascending order, HiGHS's
    dual simplex).

    Parameters
    ----------
    values : (N, 3) array of float
        The map at the nodes (positively oriented tetrahedra must keep a
        positive signed volume).
    tets : (M, 4) array of int
        Positively oriented in the domain.
    fixed : (N,) array of bool
        Nodes that must not move (the boundary).
    margin : float
        See `MARGIN`.
    rounds : int
        See `ROUNDS`.

    Returns
    -------
    Untangled
        ``inverted_after`` is 0 unless a tetrahedron has no free node, a
        face of boundary nodes pins one (an interior face whose nodes all go
        into one face of Theta: one of its two tetrahedra must then invert),
        the map has more than `MAX_INVERTED` inverted tetrahedra, or the
        rounds or `MAX_PROGRAMS` ran out.
    """
    x = np.array(values, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    fixed = np.asarray(fixed, dtype=bool)
    bad = np.flatnonzero(inverted(x, tets))
    before = len(bad)
    start, incident = _incidence(tets, len(x))
    moved: set[int] = set()
    programs = 0
    ring = stalled = done = 0
    if before > MAX_INVERTED:
        return Untangled(x, before, before, np.zeros(0, dtype=np.int64), 0, 0)
    while done < rounds and stalled <= MAX_RINGS and programs < MAX_PROGRAMS and not fixed[tets[bad]].all():
        done += 1
        active = _free_nodes(tets[bad], fixed)
        for _ in range(ring):
            around = np.unique(np.concatenate([incident[start[v] : start[v + 1]] // 4 for v in active]))
            active = _free_nodes(tets[around], fixed)
        for v in active.tolist():
            tv = incident[start[v] : start[v + 1]]
            new, solved = _best_position(x, tets[tv // 4], tv % 4, x[v], margin)
            programs += solved
            if new is not None:
                x[v] = new
                moved.add(v)
        now = np.flatnonzero(inverted(x, tets))
        if len(now) < len(bad):
            ring = stalled = 0
        else:
            ring = min(ring + 1, MAX_RINGS)
            stalled += 1
        bad = now
    moved_nodes = np.array(sorted(v for v in moved if not np.array_equal(x[v], values[v])), dtype=np.int64)
    return Untangled(x, before, len(bad), moved_nodes, done, programs)


def _incidence(tets: NDArray[np.int64], n: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """For node v, ``incident[start[v]:start[v + 1]]`` are ``4 * tet + corner`` of the tetrahedra around it."""
    flat = tets.ravel()
    order = np.argsort(flat, kind="stable")
    start = np.searchsorted(flat[order], np.arange(n + 1))
    return start, order.astype(np.int64)


def _free_nodes(tets: NDArray[np.int64], fixed: NDArray[np.bool_]) -> NDArray[np.int64]:
    nodes = np.unique(tets)
    return nodes[~fixed[nodes]]


def _best_position(x, star, corner, x0, margin):
    """The position of a node that un-inverts its star (None: stay), and how many programs that took.

    The distances to the faces' planes are linear in the position: the
    largest smallest distance r* (the Chebyshev centre of the kernel) is one
    linear program; if r* > 0, a second finds the point nearest ``x0``
    (max-norm) at distance at least ``margin * r*`` from every face.
    """
    from scipy.optimize import linprog

    faces = x[np.take_along_axis(star, _OPPOSITE[corner], axis=1)]  # (S, 3, 3)
    f0 = faces[:, 0]
    n = np.cross(faces[:, 1] - f0, faces[:, 2] - f0)
    norm = np.linalg.norm(n, axis=1)
    ring = faces.reshape(-1, 3)
    scale = float(np.abs(ring - x0).max())
    # A flat opposite face (three boundary nodes on one line of Theta) leaves its tetrahedron
    # flat wherever the node goes: no constraint.
    keep = norm > FLAT * scale * scale
    if scale == 0 or not keep.any():
        return None, 0
    f0, u = f0[keep], n[keep] / norm[keep, None]
    # Work about x0, in units of the star's size: the solver's tolerances are absolute.
    c0 = ((f0 - x0) * u).sum(axis=1) / scale  # distance of y = (x - x0) / scale to face: u.y - c0
    heights = -c0
    lo = (ring - x0).min(axis=0) / scale
    hi = (ring - x0).max(axis=0) / scale
    # Maximize r subject to u.y - r >= c0, y in the star's bounding box.
    a_ub = np.column_stack([-u, np.ones(len(u))])
    res = linprog(
        np.array([0.0, 0.0, 0.0, -1.0]), A_ub=a_ub, b_ub=-c0,
        bounds=[(lo[0], hi[0]), (lo[1], hi[1]), (lo[2], hi[2]), (None, 2.0)], method="highs-ds",
    )  # fmt: skip
    if res.status != 0:
        return None, 1
    y, r = res.x[:3], float(res.x[3])
    if r <= 0:
        # Empty kernel: the position that makes the fewest faces' distances short of a margin,
        # in the L1 sense (sum of shortfalls), if it is better than where the node is.
        want = EMPTY_MARGIN
        k = len(u)
        a_ub = np.column_stack([-u, -np.eye(k)])
        res = linprog(
            np.concatenate([np.zeros(3), np.ones(k)]), A_ub=a_ub, b_ub=-(c0 + want),
            bounds=[(lo[0], hi[0]), (lo[1], hi[1]), (lo[2], hi[2])] + [(0.0, None)] * k, method="highs-ds",
        )  # fmt: skip
        if res.status == 0:
            y = res.x[:3]
            if (u @ y - c0 <= 0).sum() < (heights <= 0).sum():
                return x0 + scale * y, 2
        return None, 2
    # Nearest to x0 (in the max norm t) with distance margin * r from every face.
    want = margin * r
    a_ub = np.vstack([
        np.column_stack([-u, np.zeros(len(u))]),
        np.column_stack([np.eye(3), -np.ones(3)]),
        np.column_stack([-np.eye(3), -np.ones(3)]),
    ])  # fmt: skip
    b_ub = np.concatenate([-(c0 + want), np.zeros(6)])
    near = linprog(
        np.array([0.0, 0.0, 0.0, 1.0]), A_ub=a_ub, b_ub=b_ub,
        bounds=[(lo[0], hi[0]), (lo[1], hi[1]), (lo[2], hi[2]), (0.0, None)], method="highs-ds",
    )  # fmt: skip
    if near.status == 0 and (u @ near.x[:3] - c0).min() > 0.5 * want:
        y = near.x[:3]
    return x0 + scale * y, 2
