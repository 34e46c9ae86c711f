#!/usr/bin/env python
"""The boundary certificate (`warpcli.maps.boundary_certificate`) against the cell certificates, per map and per warp.

    python bench/certificate_boundary.py             # 4 pairs x BEM, MFS; medians of 3 runs (~5-8 min busy)
    python bench/certificate_boundary.py --repeat 1 --no-warp

Inputs: the four pairs of bench/theta_table.py at 1 MP (bench/methods_table.py's
scaling), the regular Theta, the default m, linear boundaries.

First table, per pair, method and map (phi0: source onto Theta, phi1: target
onto Theta): seconds (median) of the cell certificate with the first-order
test (``first s``: BEM's default before this bench), with the rigorous cell
bound (``rigorous s``: MFS's default before), and of the boundary
certificate (``boundary s``, Gamma the polygon for MFS, 0.01 px inside for
BEM), the ratio of the last to the former default of the method, the
boundary certificate's evaluations, and the verdicts (``ok`` or the
number of failures; ``fold`` when the closed form's det J <= 0 at a point
of Gamma).

Second table (skipped with ``--no-warp``), per pair and method: a whole
default warp of the 1 MP test image as a user runs it (`warp_image`, a
refit with twice the nodes when the certificate fails), with the cell
certificate (the former default) and with the boundary certificate:
seconds (median), and the final m or "refused". (A third column, MFS
proved on its polygon only, went with that policy: since the collar every
map is proved with its band.)

The tables go to stdout (markdown); the header names the machine's load
(it is shared: quote the load with the numbers).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

from methods_table import bench_pairs, test_image, warm_up  # noqa: E402

from warpcli import MapOptions, build_map, warp_image  # noqa: E402
from warpcli.errors import FoldOverError  # noqa: E402
from warpcli.maps import meshless  # noqa: E402
from warpcli.maps.certificate import band_floor  # noqa: E402


def cells(phi, rigorous: bool):
    """`SmoothMap.cell_certificate`'s call (linear data: no ball), with the chosen cell test."""
    return phi.certify_cells_with(rigorous)


def boundary(phi):
    """`SmoothMap.boundary_certificate`'s first call (MFS on its polygon, BEM 0.01 px inside)."""
    size = float(np.ptp(phi.polygon.points, axis=0).max())
    return phi.certify_boundary_at(0.0 if phi.method == "mfs" else band_floor(size))


def timed(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def verdict(c) -> str:
    if not c.failed:
        return "ok"
    return f"{c.failed} (fold)" if getattr(c, "folds", 0) else str(c.failed)


def warp(src, dst, method: str, which: frozenset, image) -> str:
    """A default warp with the certificate chosen by `meshless.BOUNDARY_CERTIFIED`: the final m of both maps, or "refused"."""
    saved = meshless.BOUNDARY_CERTIFIED
    meshless.BOUNDARY_CERTIFIED = which
    try:
        try:
            res = warp_image(image, src, dst, map=MapOptions(method=method))
        except FoldOverError:
            return "refused"
        f = res.map
        return f"{f.phi0.solution.m}/{f.phi1.solution.m}"
    finally:
        meshless.BOUNDARY_CERTIFIED = saved


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-warp", action="store_true", help="skip the whole warps")
    args = ap.parse_args(argv)
    rev = subprocess.run(["git", "-C", HERE, "describe", "--always", "--dirty"], capture_output=True, text=True).stdout.strip()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start; warpcli {rev}; "
          f"medians of {args.repeat} run(s)\n")  # fmt: skip
    print("| pair | method | map | first s | rigorous s | boundary s | boundary / former default | boundary evaluations | "
          "first | rigorous | boundary |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    warm = True
    pairs = bench_pairs(None)
    for name, src, dst in pairs:
        for method in ("bem", "mfs"):
            f = build_map(src, dst, MapOptions(method=method, check=False))
            for k, phi in enumerate((f.phi0, f.phi1)):
                if warm:  # compile the kernels outside the timings
                    cells(phi, True)
                    boundary(phi)
                    warm = False
                t1, c1 = timed(lambda phi=phi: cells(phi, False), args.repeat)
                t2, c2 = timed(lambda phi=phi: cells(phi, True), args.repeat)
                t3, c3 = timed(lambda phi=phi: boundary(phi), args.repeat)
                former = t1 if method == "bem" else t2
                print(f"| {name} | {method} | phi{k} | {t1:.2f} | {t2:.2f} | {t3:.2f} | {t3 / former:.2f} | {c3.checked:,} | "
                      f"{verdict(c1)} | {verdict(c2)} | {verdict(c3)} |", flush=True)  # fmt: skip
    if not args.no_warp:
        image = test_image()
        warm_up()
        print("\n| pair | method | cells warp s | cells m | boundary warp s | boundary m | ratio |")
        print("|---|---|---|---|---|---|---|")
        for name, src, dst in pairs:
            for method in ("bem", "mfs"):
                ta, ma = timed(lambda: warp(src, dst, method, frozenset(), image), args.repeat)
                tb, mb = timed(lambda: warp(src, dst, method, frozenset({method}), image), args.repeat)
                print(f"| {name} | {method} | {ta:.2f} | {ma} | {tb:.2f} | {mb} | {tb / ta:.2f} |", flush=True)
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
