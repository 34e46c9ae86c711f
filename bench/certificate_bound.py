#!/usr/bin/env python
"""The certificate's first-order cell test against the rigorous bound (`warpcli.maps.certificate.lower_bound`).

    python bench/certificate_bound.py            # 4 pairs x BEM, MFS, both maps; medians of 3 runs (~3-5 min busy)
    python bench/certificate_bound.py --repeat 1

Inputs: the four pairs of bench/theta_table.py at 1 MP (bench/methods_table.py's
scaling), the regular Theta, the default m, linear boundaries. Per pair,
method and map (phi0: source onto Theta, phi1: target onto Theta), the cell
certificate (`certify_cells`, the arguments `SmoothMap.cell_certificate`
passes) with the first-order test (``first s``, today's default) and with the
rigorous bound (``rigorous s``): seconds (median), samples (cells
evaluated), failures and cells left unproved at the smallest size (their
samples passed; ``unproved``, for both tests). The table goes to stdout (markdown); the header names the
machine's load (it is shared: quote the load with the numbers).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time


HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

from methods_table import bench_pairs  # noqa: E402

from warpcli import MapOptions, build_map  # noqa: E402


def certify(phi, rigorous: bool):
    """`SmoothMap.cell_certificate`'s call, with the chosen cell test."""
    return phi.certify_cells_with(rigorous)


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
    args = ap.parse_args(argv)
    rev = subprocess.run(["git", "-C", HERE, "describe", "--always", "--dirty"], capture_output=True, text=True).stdout.strip()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start; warpcli {rev}; "
          f"medians of {args.repeat} run(s)\n")  # fmt: skip
    print("| pair | method | map | first s | first samples | first unproved | rigorous s | rigorous samples | ratio s | "
          "rigorous failed | rigorous unproved |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    warm = True
    for name, src, dst in bench_pairs(None):
        for method in ("bem", "mfs"):
            f = build_map(src, dst, MapOptions(method=method, check=False))
            for k, phi in enumerate((f.phi0, f.phi1)):
                if warm:  # compile the kernels outside the timings
                    certify(phi, True)
                    warm = False
                t1, c1 = timed(lambda phi=phi: certify(phi, False), args.repeat)
                t2, c2 = timed(lambda phi=phi: certify(phi, True), args.repeat)
                print(f"| {name} | {method} | phi{k} | {t1:.2f} | {c1.checked:,} | {c1.unproved} | {t2:.2f} | {c2.checked:,} | {t2 / t1:.1f} | "
                      f"{c2.failed} | {c2.unproved} |", flush=True)  # fmt: skip
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
