"""``--theta none``: the plain harmonic map of the source straight onto the target, where it does not fold.

Issue 25 (Table 2 against peers): a discrete harmonic map of the source's
FEM mesh straight onto the target polygon (boundary data: each source edge
linearly onto the target edge, as everywhere) is often less distorted than
the composition through a convex Theta. Nothing guarantees that it is
one-to-one (the target is not convex), but for a piecewise-linear map there
is an exact certificate: if every image triangle is oriented like the target
(exact orientation tests) and the boundary goes onto the simple target
polygon once, the degree argument makes the map one-to-one onto the target
(docs/proving.md). So it is offered where that certificate holds and refused
where it does not.

It takes the seam of every other map unchanged: Theta is the target polygon
itself (`warpcli.maps.theta.TargetTheta`), phi0 is FEM's map of the source
onto it and phi1 is the identity on the target (`IdentityMap`), so
f = phi1^-1 o phi0 = phi0 and the sampling plan, reports, pictures and
STMaps see a `warpcli.maps.compose.BijectiveMap` like any other.

What it gives up: f is only piecewise linear (its gradient jumps across the
source mesh's edges, and nothing is smooth below the triangles' scale); it
is not symmetric (f^-1 is not the same construction from the target); it
exists only where the straight map does not fold (never for a target whose
reflex corners the map cuts across); and it is FEM's alone: BEM and MFS
have no exact certificate for a map onto a non-convex polygon.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..boundary import nearest_edge
from ..errors import InputError
from ..grid import inside_polygon
from ..polygon import Polygon
from .base import Certificate, Mapped, ThetaMap, as_points
from .theta import TargetTheta

#: Points this close to the target's boundary (relative to its size) count as inside it.
BOUNDARY_TOLERANCE = 1e-12


def none(src: Polygon, dst: Polygon, options: object = None) -> TargetTheta:
    """Strategy ``none``: no Theta; the target polygon in its place (FEM only).

    Parameters
    ----------
    src, dst : Polygon
    options : MapOptions or None
        ``method`` must be ``"fem"``; the boundary behaviours are checked
        (`straight_boundary`).

    Returns
    -------
    TargetTheta
        The target's vertices, named ``"none"``.

    Raises
    ------
    InputError
        For BEM or MFS (no exact certificate of a map onto a non-convex
        polygon), or boundary behaviours the straight map cannot compose.
    """
    method = getattr(options, "method", "fem")
    if method != "fem":
        raise InputError(
            f"--theta none needs --method fem: only a piecewise-linear map has an exact certificate that the map "
            f"straight onto {dst.name} does not fold ({method} has none)"
        )
    straight_boundary(options)
    return TargetTheta(dst.points, name="none", notes={"map": "the harmonic map straight onto the target"})


def straight_boundary(options: object) -> str:
    """The boundary behaviour of the map straight onto the target.

    Through Theta, the point at parameter t of a source edge goes to
    parameter ``from(to(t, src), dst)`` of the target edge (`warpcli.boundary`):
    t when both sides behave alike, t^2 for a quadratic source and a linear
    target. The straight map takes that correspondence as its own boundary
    data; the remaining case (sqrt(t)) has no behaviour of its own and is refused.

    Raises
    ------
    InputError
        For a linear source with a quadratic target.
    """
    src_b = getattr(options, "src_boundary", "linear")
    dst_b = getattr(options, "dst_boundary", "linear")
    if src_b == dst_b:
        return "linear"
    if src_b == "quadratic":
        return "quadratic"
    raise InputError(
        "--theta none maps source edges straight onto target edges: a quadratic target boundary with a linear "
        "source (t goes to sqrt t) is not offered; use --src-boundary quadratic too, or a convex Theta"
    )


def fold_message(src: Polygon, dst: Polygon, flipped: int) -> str:
    """The one line that refuses a straight map that folds."""
    return (
        f"{dst.name}: the plain harmonic map of {src.name} straight onto {dst.name} folds at {flipped} triangle"
        f"{'s' if flipped != 1 else ''}; use a convex Theta (--theta regular, cyclic or optimized)"
    )


@dataclass(eq=False)
class IdentityMap(ThetaMap):
    """The target polygon onto itself: phi1 of ``--theta none`` (exactly the identity).

    Parameters
    ----------
    polygon : Polygon
        The target.
    theta : TargetTheta
        Its vertices.
    """

    method = "identity"

    def __post_init__(self) -> None:
        if not np.array_equal(self.polygon.points, self.theta.points):
            raise ValueError(f"{self.polygon.name}: the identity map goes onto its own polygon")
        size = float(np.ptp(self.polygon.points, axis=0).max())
        self._tolerance = BOUNDARY_TOLERANCE * max(size, 1.0)

    def _inside(self, q: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Points in the polygon or on its boundary (within rounding)."""
        finite = np.isfinite(q).all(axis=1)
        inside = np.zeros(len(q), dtype=bool)
        inside[finite] = inside_polygon(q[finite], self.polygon.points)
        rest = np.flatnonzero(finite & ~inside)
        if rest.size:
            _, _, dist = nearest_edge(q[rest], self.polygon.points)
            inside[rest[dist <= self._tolerance]] = True
        return inside

    def _identity(self, points: ArrayLike, jacobian: bool) -> Mapped:
        q = as_points(points)
        inside = self._inside(q)
        out = np.where(inside[:, None], q, np.nan)
        jac = None
        if jacobian:
            jac = np.zeros((len(q), 2, 2))
            jac[:, 0, 0] = jac[:, 1, 1] = 1.0
            jac[~inside] = np.nan
        return Mapped(out, jac)

    def evaluate(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        return self._identity(points, jacobian)

    def inverse(self, points: ArrayLike, *, jacobian: bool = False, coherent: bool = False) -> Mapped:
        return self._identity(points, jacobian)

    def certify(self) -> Certificate:
        """Nothing can flip: the identity is one-to-one."""
        return Certificate(0, 0, "triangles")

    def describe(self) -> dict:
        return {"map": "identity"}
