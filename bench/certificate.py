#!/usr/bin/env python
"""The BEM/MFS certificate's cost at the default settings: the former 40,000-sample check against the cells.

    python bench/certificate.py            # 4 pairs x BEM, MFS x linear, quadratic DST; 3 runs (~10-15 min busy)
    python bench/certificate.py --quick    # linear only, 1 run (~3 min)

Inputs: the four pairs of bench/theta_table.py at 1 MP (scaled as in
bench/methods_table.py: each polygon fills 90 % of a 1118 x 894 image), the
regular Theta, the default m. Per pair, method and DST boundary behaviour,
medians of ``--repeat`` runs in this process (kernels warmed up first):

- ``fit s``: both maps fitted, no certificate (``check=False``);
- ``40k s``: the former certificate on both maps (det J at a 40,000-point
  grid, what main ran until this branch; reproduced here as it was);
- ``cells s``: `SmoothMap.cell_certificate` on both maps (its cache cleared
  each run), with its verdict, samples and the balls it left out;
- ``warp s``: `warp_image` on the 1 MP image with the certificate on, as a
  user runs it (a refit after a failed certificate included; "refused" if
  the map still folds with 2048 nodes);
- ``before s``: the same warp with the former certificate: the warp without
  any certificate (``check=False``, measured) plus ``40k s`` (where the
  former check accepted both maps at the default m, as it did on these
  pairs), and the ratio ``warp s / before s``.

The table goes to stdout (markdown), progress to stderr; the header names
the machine, its load average and the git revision (the machine is shared:
quote the load with the numbers).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
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
from warpcli.boundary import on_boundary  # noqa: E402
from warpcli.errors import FoldOverError  # noqa: E402
from warpcli.grid import inside_polygon  # noqa: E402


def former_certificate(phi) -> tuple[int, int]:
    """main's certificate before the cells (commit 8eca283, `SmoothMap.certify`): det J at 40,000 grid samples."""
    xmin, ymin, xmax, ymax = phi.polygon.bounds
    step = math.sqrt(abs(phi.polygon.signed_area) / 40_000)
    xs = np.arange(xmin + step / 2, xmax, step)
    ys = np.arange(ymin + step / 2, ymax, step)
    pts = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    pts = pts[inside_polygon(pts, phi.polygon.points)]
    near, _, _ = on_boundary(pts, phi.polygon.points, 1e-9 * max(xmax - xmin, ymax - ymin))
    pts = np.delete(pts, near, axis=0)
    j = phi.solution.jacobian(pts)
    det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]
    bad = ~(det * phi.theta.orientation * np.sign(phi.polygon.signed_area) > 0)
    return int(bad.sum()), len(pts)


def timed(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="linear boundaries only, one run")
    ap.add_argument("--behaviours", default="linear,quadratic", help="DST boundary behaviours, comma-separated")
    args = ap.parse_args(argv)
    repeat = 1 if args.quick else args.repeat
    behaviours = ("linear",) if args.quick else tuple(args.behaviours.split(","))
    rev = subprocess.run(["git", "-C", HERE, "describe", "--always", "--dirty"], capture_output=True, text=True).stdout.strip()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start; warpcli {rev}; "
          f"medians of {repeat} run(s)\n")  # fmt: skip
    warm_up()
    img = test_image()
    print("| pair | method | DST boundary | fit s | 40k s | 40k verdict | cells s | cells verdict (samples) | balls left out | warp s | before s | after / before |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, src, dst in bench_pairs(None):
        for method in ("bem", "mfs"):
            for behaviour in behaviours:
                print(f"{name} {method} {behaviour}", file=sys.stderr, flush=True)
                opts = MapOptions(method=method, check=False, dst_boundary=behaviour)
                fit, f = timed(lambda opts=opts: build_map(src, dst, opts), repeat)
                maps = (f.phi0, f.phi1)
                old_s, old = timed(lambda maps=maps: [former_certificate(p) for p in maps], repeat)

                def cells(maps=maps):
                    for p in maps:
                        p.__dict__.pop("cell_certificate", None)
                    return [p.cell_certificate for p in maps]

                new_s, new = timed(cells, repeat)
                try:
                    warp_s, _ = timed(lambda opts=opts: warp_image(img, src, dst, map=dataclasses.replace(opts, check=True)), repeat)
                except FoldOverError:  # refused after the refits: the time is not a warp's
                    warp_s = math.nan
                bare, _ = timed(lambda opts=opts: warp_image(img, src, dst, map=opts), repeat)
                before = bare + old_s
                verdict_old = "ok" if all(o[0] == 0 for o in old) else f"{sum(o[0] for o in old)} fail"
                failed = sum(c.failed for c in new)
                verdict_new = ("ok" if not failed else f"{failed} fail (refit)") + f" ({sum(c.checked for c in new):,})"
                balls = sum(len(c.excluded) for c in new)
                radius = max((r for c in new for _, r in c.excluded), default=0.0)
                ball = f"{balls}, r <= {radius:.2f} px" if balls else "0"
                warp = "refused" if math.isnan(warp_s) else f"{warp_s:.2f}"
                ratio = "-" if math.isnan(warp_s) else f"{warp_s / before:.2f}"
                print(f"| {name} | {method} | {behaviour} | {fit:.2f} | {old_s:.2f} | {verdict_old} | {new_s:.2f} | {verdict_new} | "
                      f"{ball} | {warp} | {before:.2f} | {ratio} |", flush=True)  # fmt: skip
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
