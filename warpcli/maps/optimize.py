"""Theta optimization (the paper's §5.1): the convex intermediate polygon that lowers distortion.

The map f = phi1^-1 o phi0 depends on Theta, and both discrete harmonic maps
are linear in Theta's vertices (`warpcli.maps.theta_energy`): on coarse FEM
meshes the basis functions are solved once per polygon, and the energy (the
source-side area-weighted mean of the conformal or isometric distortion of
f, or a smooth stand-in for its maximum) comes with its exact gradient with
respect to all of Theta's vertices. So all vertices move at once, by
L-BFGS-B, from the regular and from the cyclic Theta, over a parameterization
that keeps Theta strictly convex:

- the turning (exterior) angles are sigmoids between a floor and pi minus
  it, shifted together so that they sum to 2 pi;
- the edge lengths are exponentials, tilted by the one vector that closes
  the polygon (the minimum of a convex function: unique);
- the composed map does not change under an affine map of Theta, so
  position, size and rotation are fixed, and the guards below are measured
  after an affine normalization (Theta's vertices whitened), where an
  affine stretch cannot hide them.

**Guards.** A coarse energy can be gamed: driving some turning angles to
hundredths of a degree lowers it on coarse meshes while the full map
becomes extreme. A smooth penalty keeps every normalized turning angle above
`MIN_TURN` times the regular polygon's and every normalized edge above
`MIN_EDGE` times the mean. Then regular, cyclic and the optimized Theta are
measured again on finer FEM maps (`MEASURE_COARSENING` times the automatic
triangle area, about 20 times the coarse maps' triangles) and the best by
that measure is kept: never worse than ``regular`` or ``cyclic`` there.

The energy is measured on FEM maps whatever the method: the harmonic maps
are what every method approximates; the chosen Theta is then used by the
method at full accuracy. Deterministic: no randomness, fixed starts.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..polygon import Polygon
from .fem.mesh import auto_max_area, mesh_polygon
from .fem.solve import DirichletSolver
from .theta import TargetTheta, Theta, cyclic, regular
from .theta_energy import HarmonicBasis, ThetaEnergy

log = logging.getLogger("warpcli")

#: Coarse maps: FEM triangles this many times larger than the automatic density...
COARSENING = 8.0
#: ... and at least the polygon's area over this many (the energy's cost stays
#: bounded for large images; its value changes by a fraction of a percent).
COARSE_TRIANGLES = 1000
#: No turning angle below this fraction of the regular polygon's (2 pi / n), by construction.
FLOOR = 0.01
#: The keep-the-best measure: FEM triangles this many times larger than the automatic density
#: (or the user's), not graded (against the automatic density the energy moved by 0.01 % on
#: a 1 MP pair, for a third of the cost).
MEASURE_COARSENING = 2.0
#: Normalized turning angles below this fraction of the regular polygon's are penalized.
MIN_TURN = 0.1
#: Normalized edges shorter than this fraction of the mean are penalized.
MIN_EDGE = 0.1
#: Weight of the guards' penalty (per unit of squared log-ratio below the bound).
PENALTY = 1.0
#: L-BFGS-B iterations from each start before the better one goes on...
SCOUT = 8
#: ... for at most this many.
MAX_ITERATIONS = 60
#: Stop when an iteration lowers the objective by less than this (relative).
TOLERANCE = 1e-4
#: Step of the central differences of the (cheap, smooth) parameterization.
PARAM_STEP = 1e-6


def optimized(src: Polygon, dst: Polygon, options) -> Theta:
    """Strategy ``optimized``: all of Theta's vertices moved jointly to lower the energy.

    Parameters
    ----------
    src, dst : Polygon
    options : MapOptions
        ``energy`` (``"conformal"``, ``"isometric"``, ``"max-conformal"`` or
        ``"max-isometric"``), ``theta_start`` (which start is reported as
        ``before``; both are tried) and the FEM options (``max_area``,
        ``weights``, boundary behaviour, ``grade``).

    Returns
    -------
    Theta
        Named ``"optimized"``; its ``notes`` hold the energy on the finer maps
        before (the ``theta_start`` polygon) and after, which of ``regular``,
        ``cyclic`` and ``optimized`` was kept, the coarse energies and the
        energy evaluations.

    References
    ----------
    Schneider & Hormann, CAGD 2015, §5.1 and Table 2.
    """
    clock = time.perf_counter
    t0 = clock()
    starts = {"regular": regular(src, dst, options), "cyclic": cyclic(src, dst, options)}
    energy = coarse_energy(src, dst, options)
    run, best_start = joint(energy, {k: v.points for k, v in starts.items()})
    t1 = clock()
    candidates = {**{k: v.points for k, v in starts.items()}, "optimized": run.points}
    full = measure(src, dst, options, candidates, straight=True)
    order = ("optimized", "regular", "cyclic", "none")  # ties: the first (the optimized one)
    kept = min((k for k in order if k in full), key=lambda k: full[k])
    if kept == "none" and not straight_certified(src, dst, options):
        # Certified on the measure's maps but not on the run's (a finer mesh): dropped.
        full["none"] = None
        kept = min(order[:3], key=lambda k: full[k])
    log.info(
        "optimizing Theta: %s energy %.5g (regular) %.5g (cyclic) %.5g (optimized from %s) %s (none); kept %s",
        options.energy, full["regular"], full["cyclic"], full["optimized"], best_start,
        f"{full['none']:.5g}" if full.get("none") is not None else "dropped", kept,
    )  # fmt: skip
    notes = {
        "energy": options.energy, "start": options.theta_start,
        "before": full[options.theta_start], "after": full[kept], "kept": kept, "optimized_from": best_start,
        "coarse_before": run.before, "coarse_after": run.energy, "none": full.get("none"),
        "evaluations": energy.evaluations, "seconds": {"optimize": t1 - t0, "measure": clock() - t1},
    }  # fmt: skip
    if kept == "none":
        # The straight map, certified on the maps the run builds (see `straight_certified`);
        # the best convex Theta is kept beside it for a run whose mesh differs and folds.
        convex = min(("optimized", "regular", "cyclic"), key=lambda k: full[k])
        notes.update(fallback=candidates[convex].tolist(), fallback_name=convex, fallback_after=full[convex])
        return TargetTheta(dst.points, name="optimized", notes=notes)
    return Theta(candidates[kept], name="optimized", notes=notes)


def joint(energy: ThetaEnergy, starts: dict) -> tuple[Run, str]:
    """`optimize` from each start for SCOUT iterations, then the best one on to convergence.

    Returns the run (its ``before`` the energy of its start) and the name of that start.
    """
    runs = {name: optimize(energy, points, max_iterations=SCOUT) for name, points in starts.items()}
    best_start = min(runs, key=lambda k: runs[k].objective)
    run = optimize(energy, runs[best_start].points)
    if run.objective > runs[best_start].objective:
        run = runs[best_start]
    run.before = runs[best_start].before
    return run, best_start


def coarse_energy(src: Polygon, dst: Polygon, options) -> ThetaEnergy:
    """The energy on coarse FEM maps (COARSENING times the automatic or the user's triangle areas)."""
    areas = options.areas() if options.method == "fem" else (None, None)
    bases = [
        HarmonicBasis.solve(
            p, max(COARSENING * (auto_max_area(p) if a is None else a), abs(p.signed_area) / COARSE_TRIANGLES),
            weights=options.weights, boundary=b,
            grade=False,
        )
        for p, a, b in zip((src, dst), areas, (options.src_boundary, options.dst_boundary))
    ]  # fmt: skip
    return ThetaEnergy(bases[0], bases[1], options.energy, rule=CENTROID)


#: One sample per triangle, at its centroid.
CENTROID = np.full((1, 3), 1.0 / 3.0)


class _Solved:
    """A factorized Dirichlet problem as a basis-like object: values(theta) by one solve (no gradient)."""

    def __init__(self, polygon: Polygon, area: float, options, boundary: str) -> None:
        # Not graded towards reflex vertices: the energy is an area integral, and the
        # few square pixels grading refines hardly move it (the cost would double).
        self.mesh = mesh_polygon(polygon, area, boundary=boundary, grade=False)
        self._solver = DirichletSolver(self.mesh, options.weights)
        self._boundary = boundary
        self.n = polygon.n

    def values(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return self._solver.solve(theta, self._boundary)


def measure(src: Polygon, dst: Polygon, options, thetas: dict, *, straight: bool = False) -> dict:
    """The energy of each Theta on the finer FEM maps of the keep-the-best step.

    One mesh and factorization per polygon, one solve per Theta. With
    ``straight`` (FEM only), also ``"none"``: the plain harmonic map straight
    onto the target (`warpcli.maps.straight`) on the same source mesh, the
    target's map the identity, measured alike; left out where it folds
    (`optimized` also certifies it on the run's maps before keeping it).
    """
    areas = options.areas() if options.method == "fem" else (None, None)
    sides = [
        _Solved(p, MEASURE_COARSENING * (auto_max_area(p) if a is None else a), options, b)
        for p, a, b in zip((src, dst), areas, (options.src_boundary, options.dst_boundary))
    ]
    # One sample per triangle (its centroid): the full meshes are fine enough.
    energy = ThetaEnergy(sides[0], sides[1], options.energy, rule=CENTROID)  # type: ignore[arg-type]
    out = {name: energy(np.asarray(points), gradient=False)[0] for name, points in thetas.items()}
    if straight and options.method == "fem" and options.conditions == "dirichlet":
        value = _straight_energy(src, dst, options, sides[0])
        if value is not None:
            out["none"] = value
    return out


class _Fixed:
    """A basis-like object whose map is the same whatever Theta: the straight map's two sides."""

    def __init__(self, mesh, values: NDArray[np.float64]) -> None:
        self.mesh = mesh
        self._values = values
        self.n = 0

    def values(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return self._values


def _straight_energy(src: Polygon, dst: Polygon, options, source: _Solved) -> float | None:
    """The energy of the straight map on the keep-the-best step's source mesh, or None where it
    folds there or a boundary behaviour rules it out."""
    from .fem.solve import flipped_exactly
    from .straight import straight_boundary

    try:
        boundary = straight_boundary(options)
    except InputError:
        return None
    values = source._solver.solve(dst.points, boundary)
    if flipped_exactly(source.mesh, values, dst.points).any():
        return None
    # The target's map is the identity: its mesh is the target itself, meshed once (coarse: it only
    # locates the samples, and J = I on every triangle).
    target_mesh = mesh_polygon(dst, max(auto_max_area(dst), abs(dst.signed_area) / COARSE_TRIANGLES), grade=False)
    energy = ThetaEnergy(_Fixed(source.mesh, values), _Fixed(target_mesh, target_mesh.vertices),  # type: ignore[arg-type]
                         options.energy, rule=CENTROID)  # fmt: skip
    value = energy(np.zeros((0, 2)), gradient=False)[0]
    return value if math.isfinite(value) else None


def straight_certified(src: Polygon, dst: Polygon, options) -> bool:
    """Whether the straight map the run would build (FEM at the run's density, no region) flips no triangle."""
    import dataclasses

    from . import fem
    from .theta import TargetTheta

    phi = fem.build(src, TargetTheta(dst.points, name="none"), dataclasses.replace(options, check=False), "source")
    return not phi.flipped().any()


class Run:
    """One optimization's result: the points, the coarse energy before and after, the objective."""

    def __init__(self, points, before, energy, objective, evaluations) -> None:
        self.points = points
        self.before = before
        self.energy = energy
        self.objective = objective
        self.evaluations = evaluations


def optimize(energy: ThetaEnergy, start: NDArray[np.float64], *, max_iterations: int = MAX_ITERATIONS) -> Run:
    """L-BFGS-B over the convex parameterization from ``start``, on energy + guards.

    Returns
    -------
    Run
        The best point seen (the objective never rises above the start's).
    """
    from scipy.optimize import minimize

    shape = ConvexShape(start)
    n = len(start)
    x0 = shape.params
    best = {"x": x0, "objective": math.inf, "energy": math.inf}
    first = energy.evaluations

    def objective(x: NDArray[np.float64]):
        with np.errstate(all="ignore"):
            theta, jac = shape.points_and_jacobian(x)
            if not (np.isfinite(theta).all() and np.isfinite(jac).all()):
                return 1e30, np.zeros_like(x)  # a step too far: the line search comes back
            e, grad = energy(theta)
            pen, pen_grad = guard_penalty(theta)
        if not math.isfinite(e) or grad is None or not math.isfinite(pen):
            return 1e30, np.zeros_like(x)
        total = e + pen
        if total < best["objective"]:
            best.update(x=x.copy(), objective=total, energy=e)
        return total, jac.T @ (grad + pen_grad).ravel()

    before, _ = energy(shape.points(x0), gradient=False)
    try:
        minimize(
            objective, x0, jac=True, method="L-BFGS-B",
            options={"maxiter": max_iterations, "ftol": TOLERANCE, "gtol": 1e-7, "maxcor": min(2 * n, 20)},
        )  # fmt: skip
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as err:  # keep the best point seen
        log.debug("optimizing Theta stopped: %s", err)
    points = shape.points(best["x"])
    return Run(points, before, best["energy"], best["objective"], energy.evaluations - first)


class ConvexShape:
    """Strictly convex polygons of n vertices from 2n unconstrained parameters (see the module's notes).

    Parameters ``z`` (n) give the turning angles (`_turns`: each between a
    floor and pi minus it, summing to 2 pi); ``r`` (n) the log edge lengths
    before closing. Edge 0 keeps
    the start's direction, vertex 0 its place, the perimeter is 2 pi.
    """

    def __init__(self, start: NDArray[np.float64]) -> None:
        pts = np.asarray(start, dtype=np.float64)
        if _signed_area(pts) < 0:
            raise InputError("the optimization starts from a positively oriented Theta")
        self.n = n = len(pts)
        self.floor = FLOOR * 2.0 * math.pi / n
        e = np.roll(pts, -1, axis=0) - pts
        heading = np.arctan2(e[:, 1], e[:, 0])
        turn = np.mod(heading - np.roll(heading, 1) + math.pi, 2.0 * math.pi) - math.pi  # at vertex i
        self.cap = math.pi - self.floor
        share = np.clip((turn - self.floor) / (self.cap - self.floor), 1e-9, 1.0 - 1e-9)
        self.direction0 = float(heading[0])
        self.origin = pts[0].copy()
        self.scale = float(np.hypot(e[:, 0], e[:, 1]).sum()) / (2.0 * math.pi)
        self.params = np.concatenate([np.log(share / (1.0 - share)), np.log(np.hypot(e[:, 0], e[:, 1]) / self.scale)])

    def points(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """The polygon (n, 2) of parameters ``x``."""
        return self._batch(np.asarray(x, dtype=np.float64)[None])[0]

    def _batch(self, xs: NDArray[np.float64], tilt: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Polygons (m, n, 2) of parameter rows ``xs`` (m, 2n); ``tilt`` starts Newton's closing
        there (rows near one point: two or three steps) instead of from scratch."""
        n = self.n
        z, r = xs[:, :n], xs[:, n:]
        turn = self._turns(z)
        heading = self.direction0 + np.concatenate([np.zeros((len(xs), 1)), np.cumsum(turn[:, 1:], axis=1)], axis=1)
        u = np.stack([np.cos(heading), np.sin(heading)], axis=2)  # (m, n, 2)
        r = r - r.max(axis=1, keepdims=True)
        if tilt is None:
            t = np.stack([_closing(r[k], u[k]) for k in range(len(xs))])
        else:
            t = np.repeat(tilt[None], len(xs), axis=0)
            for _ in range(4):  # Newton from a nearby minimum: quadratic convergence
                w = np.exp(r + np.einsum("mnd,md->mn", u, t))
                g = np.einsum("mn,mnd->md", w, u)
                h = np.einsum("mn,mnd,mne->mde", w, u, u)
                t = t - np.linalg.solve(h, g[..., None])[..., 0]
        lengths = np.exp(r + np.einsum("mnd,md->mn", u, t))
        lengths *= 2.0 * math.pi / lengths.sum(axis=1, keepdims=True)
        steps = lengths[..., None] * u
        out = np.concatenate([np.zeros((len(xs), 1, 2)), np.cumsum(steps[:, :-1], axis=1)], axis=1)
        return self.origin + self.scale * out

    def points_and_jacobian(self, x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The polygon and d(points)/dx, (2n, 2n), by central differences (the map is smooth and cheap)."""
        n = self.n
        z, r = x[:n], x[n:]
        heading = self.direction0 + np.concatenate([[0.0], np.cumsum(self._turns(z)[1:])])
        u = np.stack([np.cos(heading), np.sin(heading)], axis=1)
        tilt = _closing(r - r.max(), u)
        rows = np.repeat(x[None], 2 * x.size + 1, axis=0)
        k = np.arange(x.size)
        rows[1 + k, k] += PARAM_STEP
        rows[1 + x.size + k, k] -= PARAM_STEP
        # The shift by max(r) is a constant of each row's closing: the base's tilt starts every row's Newton.
        pts = self._batch(rows, tilt)
        jac = (pts[1 : 1 + x.size] - pts[1 + x.size :]).reshape(x.size, -1).T / (2.0 * PARAM_STEP)
        return pts[0], jac

    def _turns(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """Turning angles ``floor + (cap - floor) sigmoid(z + c)``, c per row such that they sum to 2 pi.

        Each angle stays in (floor, cap), cap = pi - floor (a turn of pi or
        more could not close a convex polygon); the sum is increasing in c,
        so c is unique: bisection, then Newton to rounding error.
        """
        z2 = np.atleast_2d(z)
        span = self.cap - self.floor
        target = 2.0 * math.pi - self.n * self.floor
        lo = np.full((len(z2), 1), -60.0) - z2.max(axis=1, keepdims=True)
        hi = np.full((len(z2), 1), 60.0) - z2.min(axis=1, keepdims=True)

        def total(c):
            return span * _sigmoid(z2 + c).sum(axis=1, keepdims=True)

        for _ in range(24):
            mid = 0.5 * (lo + hi)
            low = total(mid) < target
            lo = np.where(low, mid, lo)
            hi = np.where(low, hi, mid)
        c = 0.5 * (lo + hi)
        for _ in range(5):
            sg = _sigmoid(z2 + c)
            c = c - (span * sg.sum(axis=1, keepdims=True) - target) / (span * (sg * (1.0 - sg)).sum(axis=1, keepdims=True))
        out = self.floor + span * _sigmoid(z2 + c)
        return out if np.ndim(z) == 2 else out[0]


def _sigmoid(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _closing(r: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """The tilt t minimizing F(t) = sum exp(r_i + t.u_i): there sum exp(r_i + t.u_i) u_i = 0, the polygon closes.

    F is strictly convex and grows in every direction when the edge
    directions turn by less than pi at a time (true of every convex
    polygon), so Newton's method with halving finds its unique minimum.
    """
    t = np.zeros(2)
    f = np.exp(r + u @ t).sum()
    for _ in range(200):
        w = np.exp(r + u @ t)
        g = w @ u
        step = np.linalg.solve((u * w[:, None]).T @ u, g)
        if float(np.hypot(*g)) <= 1e-3 * float(w.sum()):
            break  # near the minimum: plain Newton steps below
        lam = 1.0
        while lam > 1e-12:
            trial = t - lam * step
            ft = np.exp(r + u @ trial).sum()
            if ft < f:
                break
            lam *= 0.5
        t, f = trial, ft
    for _ in range(6):  # quadratic convergence to rounding error
        w = np.exp(r + u @ t)
        t = t - np.linalg.solve((u * w[:, None]).T @ u, w @ u)
    return t


def _signed_area(p: NDArray[np.float64]) -> float:
    q = np.roll(p, -1, axis=0)
    return 0.5 * float((p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]).sum())


def normalized(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """The polygon (or stack of polygons, (..., n, 2)) under the affine map that whitens its
    vertices (mean 0, covariance the identity).

    The composed map does not change under an affine map of Theta; the
    guards are measured in this frame, where a stretch cannot hide a flat corner.
    """
    c = points - points.mean(axis=-2, keepdims=True)
    cov = np.swapaxes(c, -1, -2) @ c / c.shape[-2]
    ev, vec = np.linalg.eigh(cov)
    return (c @ vec) / np.sqrt(ev)[..., None, :]


def guards(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Normalized turning angles over the regular polygon's, and normalized edge lengths over
    their mean (each (..., n) for points (..., n, 2))."""
    p = normalized(points)
    e = np.roll(p, -1, axis=-2) - p
    heading = np.arctan2(e[..., 1], e[..., 0])
    turn = np.abs(np.mod(heading - np.roll(heading, 1, axis=-1) + math.pi, 2.0 * math.pi) - math.pi)
    lengths = np.hypot(e[..., 0], e[..., 1])
    n = points.shape[-2]
    return turn / (2.0 * math.pi / n), lengths / lengths.mean(axis=-1, keepdims=True)


def guard_penalty(points: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
    """``PENALTY * sum(log(bound / x)^2)`` over the guards below their bounds, and its gradient
    with respect to the points (central differences, all at once: a function of n points)."""

    def value(p: NDArray[np.float64]) -> NDArray[np.float64]:
        with np.errstate(divide="ignore", invalid="ignore"):
            turn, edge = guards(p)
            low = np.concatenate(
                [np.log(np.maximum(MIN_TURN / turn, 1.0)), np.log(np.maximum(MIN_EDGE / edge, 1.0))], axis=-1
            )
        return PENALTY * (low * low).sum(axis=-1)

    v = float(value(points))
    if v == 0.0:
        return v, np.zeros_like(points)  # zero near the point too: the bounds are strict inequalities
    h = 1e-7 * float(np.abs(points).max())
    m = points.size
    probes = np.repeat(points[None], 2 * m, axis=0).reshape(2 * m, m)
    probes[np.arange(m), np.arange(m)] += h
    probes[m + np.arange(m), np.arange(m)] -= h
    values = value(probes.reshape(2 * m, *points.shape))
    return v, ((values[:m] - values[m:]) / (2.0 * h)).reshape(points.shape)
