"""Theta optimization (the paper's §5.1): the convex intermediate polygon that lowers distortion.

The map f = phi1^-1 o phi0 depends on Theta. Starting from the regular (or
cyclic) polygon, each vertex of Theta in turn moves along a finite-difference
gradient of the chosen energy (the area-weighted mean conformal or isometric
distortion of f, the report's number), the step halved until Theta stays
strictly convex and the energy goes down. The energy is measured on coarse
FEM maps at fixed sample points of the target, whatever the method: each
evaluation re-solves two factorized systems (only the boundary data
changes), where BEM and MFS would fit anew. The energy is a property of the
harmonic maps, which every method approximates; the optimized Theta is then
used by the chosen method at full accuracy. Deterministic: no randomness, a
fixed visiting order.
"""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
from numpy.typing import NDArray

from ..distortion import distortion
from ..errors import InputError
from ..grid import inside_polygon
from ..mapping import matmul2
from ..polygon import Polygon
from . import fem
from .base import ThetaMap
from .fem.mesh import auto_max_area
from .theta import Theta, cyclic, regular

log = logging.getLogger("warpcli")

#: Finite-difference step, in units of Theta's circumradius (1).
FD_STEP = 1e-3
#: The first move of a vertex, the same units.
FIRST_STEP = 0.05
#: Stop when a sweep over all vertices lowers the energy by less than this (relative).
TOLERANCE = 1e-3
#: At most this many sweeps.
MAX_SWEEPS = 8
#: Target points at which the energy is measured.
SAMPLES = 2048
#: Coarse maps: FEM triangles this many times larger than the automatic density.
COARSENING = 8.0


def optimized(src: Polygon, dst: Polygon, options) -> Theta:
    """Strategy ``optimized``: Theta moved, one vertex at a time, to lower the energy.

    Parameters
    ----------
    src, dst : Polygon
    options : MapOptions
        ``energy`` (``"conformal"`` or ``"isometric"``), ``theta_start``
        (``"regular"`` or ``"cyclic"``) and the method's options.

    Returns
    -------
    Theta
        Named ``"optimized"``; its ``notes`` hold the energy before and after,
        the sweeps and the energy evaluations.

    References
    ----------
    Schneider & Hormann, CAGD 2015, §5.1 and Table 2.
    """
    start = (cyclic if options.theta_start == "cyclic" else regular)(src, dst, options)
    method = fem  # whatever the method: the energy is measured on coarse FEM maps
    coarse = dataclasses.replace(
        options, method="fem", theta="regular", max_area=_coarse_areas(src, dst, options), check=False
    )
    phi0 = method.build(src, start, coarse, "source")
    phi1 = method.build(dst, start, coarse, "target")
    samples = _samples(dst)
    evaluations = 0

    def energy(points: NDArray[np.float64]) -> float:
        nonlocal evaluations
        try:
            theta = Theta(points, name="candidate")
        except InputError:
            return math.inf  # not strictly convex
        evaluations += 1
        a = _onto(phi1, theta, method, dst, coarse, "target")
        b = _onto(phi0, theta, method, src, coarse, "source")
        m1 = a.evaluate(samples, jacobian=True)
        m0 = b.inverse(m1.points, jacobian=True, coherent=True)  # samples in grid order: walk, no locator
        # The report's number (`warpcli.report.metrics.summarize`, which is this for so few samples).
        value = distortion(matmul2(m0.jacobian, m1.jacobian)).summary()[options.energy]["mean"]
        return math.inf if value is None else value

    w = start.points.copy()
    before = current = energy(w)
    steps = np.full(len(w), FIRST_STEP)
    sweeps = 0
    for sweeps in range(1, MAX_SWEEPS + 1):
        at_start = current
        for i in range(len(w)):
            grad = np.zeros(2)
            for k in range(2):
                probe = w.copy()
                probe[i, k] += FD_STEP
                grad[k] = (energy(probe) - current) / FD_STEP
            norm = float(np.hypot(*grad))
            if not (norm > 0 and math.isfinite(norm)):
                continue
            step = steps[i]
            while step > 1e-3 * FIRST_STEP:
                trial = w.copy()
                trial[i] -= step * grad / norm
                e = energy(trial)
                if e < current:
                    w, current = trial, e
                    steps[i] = min(2.0 * step, FIRST_STEP * 4)
                    break
                step *= 0.5  # halve until Theta is strictly convex and the energy falls
            else:
                steps[i] = step
        log.info("optimizing Theta: sweep %d, %s energy %.5g", sweeps, options.energy, current)
        if at_start - current <= TOLERANCE * abs(at_start):
            break
    notes = {
        "energy": options.energy, "start": start.name, "before": before, "after": current,
        "sweeps": sweeps, "evaluations": evaluations,
    }  # fmt: skip
    return Theta(w, name="optimized", notes=notes)


def _onto(phi: ThetaMap, theta: Theta, method, polygon: Polygon, options, role: str) -> ThetaMap:
    """phi's polygon onto another Theta: the method's cheap re-solve, or a new build."""
    return phi.retarget(theta) or method.build(polygon, theta, options, role)


def _coarse_areas(src: Polygon, dst: Polygon, options):
    """FEM triangle areas COARSENING times the automatic ones (or the user's, for FEM)."""
    areas = options.areas() if options.method == "fem" else (None, None)
    return tuple(
        COARSENING * (auto_max_area(p) if a is None else a) for p, a in zip((src, dst), areas)
    )


def _samples(dst: Polygon) -> NDArray[np.float64]:
    """About SAMPLES points on a regular grid inside the target (deterministic)."""
    xmin, ymin, xmax, ymax = dst.bounds
    step = math.sqrt(abs(dst.signed_area) / SAMPLES)
    xs = np.arange(xmin + step / 2, xmax, step)
    ys = np.arange(ymin + step / 2, ymax, step)
    pts = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    return pts[inside_polygon(pts, dst.points)]
