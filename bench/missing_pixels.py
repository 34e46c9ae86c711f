#!/usr/bin/env python
"""Output pixels inside the target that get no pre-image: the 4 bench pairs at 1 MP x BEM, MFS.

    python bench/missing_pixels.py                      # linear boundary data (~2-4 min busy)
    python bench/missing_pixels.py --behaviour quadratic

Per pair and method (bench/methods_table.py's pairs and 1118 x 894 grid, the
default m, refits as a user gets them): how many pixel centres strictly inside
the target polygon have no pull-back (NaN: they would come out as
background), how many have one outside the source polygon, the distances to
the target's boundary of the first few missing, and the pull-back's seconds
(one run; the machine is shared). Every count must be 0: an accepted map
samples every pixel inside its target.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from methods_table import HEIGHT, WIDTH, smooth_maps  # noqa: E402

from warpcli.boundary import nearest_edge  # noqa: E402
from warpcli.grid import inside_polygon, pixel_centres  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--behaviour", default="linear", choices=["linear", "quadratic"])
    args = ap.parse_args(argv)
    centres = pixel_centres(WIDTH, HEIGHT)
    print(f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} at start\n")
    print("| pair | method | missing | outside the source | distances px (first 5) | pull-back s |")
    print("|---|---|---:|---:|---|---:|")
    for name, method, src, dst, opts, fm in smooth_maps(args.behaviour):
        if isinstance(fm, Exception):
            print(f"| {name} | {method} | refused: {fm} |")
            continue
        t0 = time.perf_counter()
        pts = fm.inverse_grid(WIDTH, HEIGHT).reshape(-1, 2)
        seconds = time.perf_counter() - t0
        inside = inside_polygon(centres, dst.points)
        found = np.isfinite(pts).all(axis=1)
        missing = np.flatnonzero(inside & ~found)
        k = np.flatnonzero(inside & found)
        outside = int((~inside_polygon(pts[k], src.points)).sum())
        dist = nearest_edge(centres[missing[:5]], dst.points)[2] if missing.size else []
        print(f"| {name} | {method} | {missing.size} | {outside} | {', '.join(f'{d:.4f}' for d in dist)} | {seconds:.1f} |", flush=True)
    print(f"\nload {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
