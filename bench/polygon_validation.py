"""Polygon validation time against the vertex count: a wavy star r(a) = R (1 + 0.3 sin 17a).

    python bench/polygon_validation.py [--sizes 1e3,1e4,1e5,1e6] [--repeat 3] [--radius 10000] [--no-read]

For each n, builds the star with n vertices at equal angles (R = 10 000 px by
default, so edges are 0.2 px long even at a million vertices) and prints the
median wall time of ``repeat`` runs of

- ``Polygon(points)``: validation of an (n, 2) array (repeats, area,
  simplicity, clearance), with the pairs of edges tested;
- ``read_polygon(path)``: the same polygon read from a JSON file (parsing and
  checking the parsed lists as well), unless ``--no-read``.

Progress goes to stderr, the table (markdown) to stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time

import numpy as np

from warpcli.polygon import Polygon, read_polygon
from warpcli.polygon.validate import check_edges


def wavy_star(n: int, radius: float) -> np.ndarray:
    a = 2 * np.pi * np.arange(n) / n
    r = radius * (1 + 0.3 * np.sin(17 * a))
    return np.stack([2 * radius + r * np.cos(a), 2 * radius + r * np.sin(a)], axis=1)


def median_time(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e3,1e4,1e5,1e6", help="vertex counts, comma-separated")
    ap.add_argument("--repeat", type=int, default=3, help="runs per measurement (the median is shown)")
    ap.add_argument("--radius", type=float, default=1e4, help="R, in pixels")
    ap.add_argument("--no-read", dest="read", action="store_false", help="skip the read_polygon column")
    args = ap.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]

    print(
        f"Polygon validation, wavy star r(a) = R (1 + 0.3 sin 17a), R = {args.radius:g} px; "
        f"median of {args.repeat} runs; Python {platform.python_version()}, numpy {np.__version__}, "
        f"{os.cpu_count()} CPUs ({platform.machine()})\n"
    )
    head = "| n | Polygon(points) | per vertex | pairs tested |" + (" read_polygon(file) | file size |" if args.read else "")
    print(head)
    print("|" + "---:|" * (head.count("|") - 1))
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            print(f"n = {n:,} ...", file=sys.stderr, flush=True)
            pts = wavy_star(n, args.radius)
            t_val = median_time(lambda: Polygon(pts, name="star"), args.repeat)
            pairs = check_edges(pts, "star", clearance=True)
            row = f"| {n:,} | {t_val:.3f} s | {t_val / n * 1e6:.2f} us | {pairs:,} |"
            if args.read:
                path = os.path.join(tmp, f"star{n}.json")
                with open(path, "w") as fh:
                    json.dump(pts.tolist(), fh)
                t_read = median_time(lambda: read_polygon(path), args.repeat)
                size = os.path.getsize(path)
                row += f" {t_read:.3f} s | {size / 1e6:.3g} MB |"
            print(row, flush=True)


if __name__ == "__main__":
    main()
