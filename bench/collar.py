#!/usr/bin/env python
"""The collar (`warpcli.maps.collar`): how wide the proved band is, how many pixels it touches, what it costs.

    python bench/collar.py                  # the 4 bench pairs at 1 MP x BEM, MFS; medians of 3 (~3-5 min busy)
    python bench/collar.py --repeat 1 --behaviour quadratic

Inputs: the four pairs of bench/theta_table.py at 1 MP (bench/methods_table.py's
scaling), the regular Theta, the default m (refits as a user gets them).
Per pair and method: each map's band (Gamma's distance inside, px; the
first of `meshless.BAND_STEPS` x `band_floor` that proves the map), the
boundary certificate's seconds and evaluations (median), then over the
1 MP test image's output pixels: how many have their centre in the
target's band or their pull-back in the source's (the pixels whose
sampling point the collar decides), how far the collar moves those points
from where the closed form alone puts them (px, in the source; NaN where
the closed form's Newton finds no pre-image), and the whole warp's seconds
(median, `warp_image`).

Run it in another checkout (``PYTHONPATH=/path/to/other python bench/collar.py``)
for the same table before the collar: the warp's seconds compare across runs
of one session only (the machine is shared: the load is printed).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from methods_table import smooth_maps, test_image, warm_up  # noqa: E402

from warpcli import warp_image  # noqa: E402
from warpcli.grid import inside_polygon  # noqa: E402
from warpcli.maps.newton import invert  # noqa: E402


def band_pixels(fm, size):
    """Output pixel centres in the target's band, or whose pull-back lies in the source's; and how far the
    collar moves their pull-back from the closed form's own (max px)."""
    w, h = size
    yy, xx = np.mgrid[0:h, 0:w]
    y = np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5], 1)
    y = y[inside_polygon(y, fm.phi1.polygon.points)]
    c1, c0 = getattr(fm.phi1, "collar", None), getattr(fm.phi0, "collar", None)  # None before the collar
    if c1 is None and c0 is None:
        return 0, 0.0
    x = fm.phi0.inverse(fm.phi1.evaluate(y).points).points
    touched = np.zeros(len(y), dtype=bool)
    if c1 is not None:
        touched |= ~c1.inside(y)
    if c0 is not None:
        ok = np.isfinite(x).all(axis=1)
        touched[np.flatnonzero(ok)[~c0.inside(x[ok])]] = True
    k = np.flatnonzero(touched)
    if not k.size:
        return 0, 0.0
    # the closed form alone: phi1's value, then Newton on phi0's closed form from the collar's answer
    s0, s1 = fm.phi0.solution, fm.phi1.solution
    val = s1.value(y[k])
    start = np.where(np.isfinite(x[k]), x[k], fm.phi0.polygon.points.mean(axis=0))
    raw, ok = invert(s0.value, s0.jacobian, val, start, tol=1e-12)[:2]
    raw[~ok] = np.nan
    moved = np.hypot(*(raw - x[k]).T)
    return int(k.size), float(np.nanmax(moved)) if np.isfinite(moved).any() else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--behaviour", default="linear", choices=["linear", "quadratic"])
    args = ap.parse_args(argv)
    import warpcli

    print(f"warpcli from {os.path.dirname(warpcli.__file__)}; {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} at start\n")
    image = test_image()
    size = (image.shape[1], image.shape[0])
    warm_up()
    print("| pair | method | m | band phi0 px | band phi1 px | certificate s | evaluations | band pixels | moved px | warp s |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, method, src, dst, opts, fm in smooth_maps(args.behaviour):
        if isinstance(fm, Exception):
            print(f"| {name} | {method} | | refused: {fm} |")
            continue
        cert_s, evals = [], 0
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            proofs = [phi.certify_boundary_at(phi.boundary_certificate.offset) for phi in (fm.phi0, fm.phi1)]
            cert_s.append(time.perf_counter() - t0)
            evals = sum(p.checked for p in proofs)
        band = [p.offset if getattr(p, "band", False) else float("nan") for p in (fm.phi0.boundary_certificate, fm.phi1.boundary_certificate)]
        count, moved = band_pixels(fm, size)
        warps = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            warp_image(image, src, dst, map=opts)
            warps.append(time.perf_counter() - t0)
        m = fm.phi0.solution.m
        print(f"| {name} | {method} | {m} | {band[0]:.3f} | {band[1]:.3f} | {statistics.median(cert_s):.2f} | {evals} | "
              f"{count} | {moved:.2e} | {statistics.median(warps):.2f} |", flush=True)  # fmt: skip
    print(f"\nload {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
