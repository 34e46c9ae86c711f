"""The Theta optimizer against a generic joint optimizer and today's vertex-by-vertex descent (§5.1).

    python bench/optimizer.py                       # conformal energy, six concave pairs (a few minutes)
    python bench/optimizer.py --energy isometric --pairs star,zigzag

On six concave pairs (a star, an L onto a U, a horseshoe onto a ring sector,
a zigzag onto a flat star, and the two sample pairs), every optimizer works
on the same coarse energy (`warpcli.maps.optimize.coarse_energy`: the
source-side mean distortion on FEM meshes 8 times coarser than the default,
with its exact gradient) and under the same guards (normalized turning
angles and edges, `warpcli.maps.optimize.guards`):

- ``joint L-BFGS-B``: `warpcli.maps.optimize.joint`, as ``--theta
  optimized`` runs it: a few L-BFGS-B iterations from the regular and from
  the cyclic Theta, then the better one on to convergence; the guards as a
  penalty;
- ``SLSQP``: scipy's SLSQP over all 2n coordinates from the same two starts,
  with the exact gradient, convexity (every turn positive) and the guards as
  inequality constraints;
- ``vertex by vertex``: the previous algorithm (one vertex at a time along a
  forward-difference gradient of step 1e-3, steps halved until Theta stays
  convex and the energy falls; 8 sweeps at most), on this energy;
- ``regular`` and ``cyclic``: no optimization.

Columns: the coarse energy, the energy of the same Theta on the finer
FEM maps (`warpcli.maps.optimize.measure`), the energy evaluations (each
gives value and gradient, except for the vertex-by-vertex method's, which
are values only), after how many of its own evaluations the joint optimizer
first reached that row's final coarse energy (the joint run's trace: the
regular start first, then the cyclic one), and the seconds (median of --repeat runs; the machine is
shared, so times are indicative). ``--theta optimized`` keeps the best of
regular, cyclic and the joint result by the full energy: the last row.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))

from warpcli import MapOptions, Polygon, read_polygon  # noqa: E402
from warpcli.errors import InputError  # noqa: E402
from warpcli.maps import optimize as opt  # noqa: E402
from warpcli.maps.theta import Theta, cyclic, regular  # noqa: E402

SAMPLES = os.path.join(HERE, "..", "sample_images")


def arc(cx, cy, r, a0, a1, k):
    a = np.linspace(a0, a1, k)
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)


def pairs():
    """(name, source, target): six concave pairs."""
    k = np.arange(12)
    a = 2 * np.pi * k / 12
    star = np.stack([256 + np.where(k % 2 == 0, 230.0, 95.0) * np.cos(a), 256 + np.where(k % 2 == 0, 230.0, 95.0) * np.sin(a)], axis=1)
    blob = np.stack([256 + np.where(k % 2 == 0, 200.0, 150.0) * np.cos(a + 0.3), 256 + 0.7 * np.where(k % 2 == 0, 200.0, 150.0) * np.sin(a + 0.3)], axis=1)
    yield "star -> squashed blob", Polygon(star, name="star"), Polygon(blob, name="blob")
    ell = [[40, 40], [180, 40], [180, 330], [470, 330], [470, 470], [300, 470], [150, 470], [40, 470]]
    u = [[40, 40], [180, 40], [180, 330], [330, 330], [330, 40], [470, 40], [470, 470], [40, 470]]
    yield "L -> U", Polygon(ell, name="L"), Polygon(u, name="U")
    # A horseshoe (outer arc, inner arc back) onto a quarter ring sector.
    horse = np.concatenate([arc(256, 256, 220, np.pi * 0.9, np.pi * 2.1, 9), arc(256, 256, 110, np.pi * 2.1, np.pi * 0.9, 9)])
    sector = np.concatenate([arc(60, 470, 420, -np.pi / 2, 0, 9), arc(60, 470, 150, 0, -np.pi / 2, 9)])
    yield "horseshoe -> ring sector", Polygon(horse, name="horseshoe"), Polygon(sector, name="sector")
    k = np.arange(10)
    a = 2 * np.pi * k / 10
    r = np.where(k % 2 == 0, 220.0, 90.0)
    flat = np.stack([256 + r * np.cos(a), 256 + 0.6 * r * np.sin(a)], axis=1)
    zig = np.array([[40, 80], [120, 300], [200, 80], [280, 300], [360, 80], [470, 300], [470, 460], [300, 420], [200, 460], [40, 460]], float)
    yield "zigzag -> flat star", Polygon(zig, name="zigzag"), Polygon(flat, name="flat star")
    yield "grid: L -> hexagon", read_polygon(os.path.join(SAMPLES, "grid_L.json")), read_polygon(os.path.join(SAMPLES, "grid_hexagon.json"))
    yield "chelsea: ring -> star", read_polygon(os.path.join(SAMPLES, "chelsea_ring.json")), read_polygon(os.path.join(SAMPLES, "chelsea_star.json"))


def vertex_by_vertex(energy, start, fd_step=1e-3, first_step=0.05, tolerance=1e-3, max_sweeps=8):
    """The previous `--theta optimized` (coordinate descent along forward differences), on ``energy``."""

    def value(points):
        try:
            Theta(points)
        except InputError:
            return math.inf
        return energy(points, gradient=False)[0]

    w = start.copy()
    current = value(w)
    steps = np.full(len(w), first_step)
    for _ in range(max_sweeps):
        at_start = current
        for i in range(len(w)):
            grad = np.zeros(2)
            for k in range(2):
                probe = w.copy()
                probe[i, k] += fd_step
                grad[k] = (value(probe) - current) / fd_step
            norm = float(np.hypot(*grad))
            if not (norm > 0 and math.isfinite(norm)):
                continue
            step = steps[i]
            while step > 1e-3 * first_step:
                trial = w.copy()
                trial[i] -= step * grad / norm
                e = value(trial)
                if e < current:
                    w, current = trial, e
                    steps[i] = min(2.0 * step, first_step * 4)
                    break
                step *= 0.5
            else:
                steps[i] = step
        if at_start - current <= tolerance * abs(at_start):
            break
    return w


def slsqp(energy, start, max_iterations=200):
    """scipy's SLSQP over all vertices: exact gradient; convexity and the guards as constraints."""
    from scipy.optimize import minimize

    n = len(start)
    scale = float(np.abs(start).max())

    def f(x):
        e, g = energy(x.reshape(n, 2))
        if not math.isfinite(e):
            return 1e30, np.zeros_like(x)
        return e, g.ravel()

    def constraints(x):
        p = x.reshape(n, 2)
        a = p - np.roll(p, 1, axis=0)
        b = np.roll(p, -1, axis=0) - p
        turn = (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) / scale**2
        t, e = opt.guards(p)
        return np.concatenate([turn - 1e-9, np.log(t / opt.MIN_TURN), np.log(e / opt.MIN_EDGE)])

    def fan(x):  # the fan from vertex 0 turns one way: with every turn positive, the polygon winds once
        p = x.reshape(n, 2)
        a = p[1:-1] - p[0]
        b = p[2:] - p[0]
        return (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) / scale**2 - 1e-9

    def constraints_jac(x):
        c = constraints(x)
        jac = np.empty((len(c), len(x)))
        for k in range(len(x)):
            a = x.copy()
            a[k] += 1e-7
            b = x.copy()
            b[k] -= 1e-7
            jac[:, k] = (constraints(a) - constraints(b)) / 2e-7
        return jac

    res = minimize(f, start.ravel(), jac=True, method="SLSQP", constraints=[{"type": "ineq", "fun": constraints, "jac": constraints_jac}, {"type": "ineq", "fun": fan, "jac": lambda x: _fd(fan, x)}], options={"maxiter": max_iterations, "ftol": 1e-9})
    return res.x.reshape(n, 2)


class Recorded:
    """An energy that records the value of every evaluation (``trace``), for "passes it after"."""

    def __init__(self, inner):
        self.inner = inner
        self.trace = []

    @property
    def evaluations(self):
        return self.inner.evaluations

    def __call__(self, theta, gradient=True):
        out = self.inner(theta, gradient=gradient)
        self.trace.append(out[0])
        return out


def _fd(fn, x, h=1e-7):
    jac = np.empty((len(fn(x)), len(x)))
    for k in range(len(x)):
        a = x.copy()
        a[k] += h
        b = x.copy()
        b[k] -= h
        jac[:, k] = (fn(a) - fn(b)) / (2 * h)
    return jac


def valid(points):
    """Whether the points are a strictly convex polygon turning once around (a Theta)."""
    try:
        Theta(points)
        return True
    except InputError:
        return False


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--energy", default="conformal", choices=("conformal", "isometric", "max-conformal", "max-isometric"))
    parser.add_argument("--pairs", default="", help="only pairs whose name starts with one of these (comma-separated)")
    parser.add_argument("--repeat", type=int, default=1, help="runs per timing (the median is shown)")
    parser.add_argument("--table2", action="store_true", help="the eight pairs of bench/table2.py instead of these six")
    args = parser.parse_args(argv)
    wanted = [w for w in args.pairs.split(",") if w]
    options = MapOptions(theta="optimized", energy=args.energy)
    print(f"| pair | Theta | coarse {args.energy} | full {args.energy} | evaluations | joint passes it after | seconds |")
    print("|---|---|---:|---:|---:|---:|---:|")
    if args.table2:
        sys.path.insert(0, HERE)
        import table2

        chosen = [(name, src, dst) for name, src, dst, _ in table2.pairs()]
    else:
        chosen = list(pairs())
    for name, src, dst in chosen:
        if wanted and not any(name.startswith(w) for w in wanted):
            continue
        starts = {"regular": regular(src, dst).points, "cyclic": cyclic(src, dst).points}
        energy = Recorded(opt.coarse_energy(src, dst, options))
        rows = {}

        def timed(label, fn):
            times = []
            for _ in range(args.repeat):
                energy.trace.clear()
                before = energy.evaluations
                t0 = time.perf_counter()
                out = fn()
                times.append(time.perf_counter() - t0)
                evals = energy.evaluations - before
            rows[label] = (out, evals, statistics.median(times), list(energy.trace))

        for label, pts in starts.items():
            rows[label] = (pts, 0, 0.0, [])

        def joint():
            return opt.joint(energy, starts)[0].points

        def best_of(fn):
            cands = [fn(energy, p) for p in starts.values()]
            return min(cands, key=lambda p: energy(p, gradient=False)[0] if valid(p) else math.inf)

        timed("joint L-BFGS-B", joint)
        timed("SLSQP", lambda: best_of(slsqp))
        timed("vertex by vertex", lambda: best_of(vertex_by_vertex))
        full = opt.measure(src, dst, options, {k: v[0] for k, v in rows.items()})
        kept = min(("joint L-BFGS-B", "regular", "cyclic"), key=lambda k: full[k])
        final = {label: energy.inner(v[0], gradient=False)[0] for label, v in rows.items()}
        trace = np.array(rows["joint L-BFGS-B"][3])
        for label, (pts, evals, secs, _) in rows.items():
            coarse = final[label]
            if label in ("SLSQP", "vertex by vertex"):
                hit = np.flatnonzero(trace <= coarse * (1 + 1e-9))
                reach = str(int(hit[0]) + 1) if hit.size else "never"
            else:
                reach = ""
            t, e = opt.guards(pts)
            flag = "" if t.min() >= opt.MIN_TURN * 0.99 and e.min() >= opt.MIN_EDGE * 0.99 else f" (guards crossed: {min(t.min() / opt.MIN_TURN, e.min() / opt.MIN_EDGE):.2f})"
            if not valid(pts):
                flag = " (not a convex polygon)"
            print(f"| {name} | {label}{flag} | {coarse:.4f} | {full[label]:.4f} | {evals} | {reach} | {secs:.2f} |", flush=True)
        print(f"| {name} | **--theta optimized** (keeps {kept}) | | **{full[kept]:.4f}** | | | |", flush=True)


if __name__ == "__main__":
    main()
