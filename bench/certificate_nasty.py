#!/usr/bin/env python
"""The boundary certificate and the cell certificate against an independent dense check, on generated nasty polygons.

    python bench/certificate_nasty.py              # 6 classes x seeds 11, 5 x BEM, MFS x default m, 128, 64 (~10 min busy)
    python bench/certificate_nasty.py --seeds 3

Inputs: the classes of tests/nasty.py but the wavy 240-gon (minutes per fit
at its default m), 300 px, the regular Theta, linear boundaries, the source
map only (phi0), at the default m (no refit), 128 and 64 nodes (when at
least the vertices + 8). Per map: the cell certificate as the former
defaults ran it (MFS: the rigorous bound; BEM: the first-order test) and
the boundary certificate as the map runs it (`SmoothMap.boundary_certificate`:
MFS on its polygon, else, like BEM, Gamma the first distance inside that
proves the map with its band, the collar), verdict, Gamma's distance,
whether the band is proved, seconds; then the dense check of
tests/nasty.py on the map as accepted (the collar in its band: a
60,000-point grid, bands 0.01-3 px inside every edge every 0.25 px, polar
grids of 16 radii at every vertex) plus samples 1e-6..0.01 px inside every
edge every 0.25 px and around every vertex: folds (det J <= 0) and deep
excursions out of Theta at the samples deeper than Gamma, and within the
band. The table goes to stdout (markdown).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from nasty import SHAPES, dense_check, dense_samples  # noqa: E402

from warpcli import MapOptions, Polygon  # noqa: E402
from warpcli.boundary import nearest_edge  # noqa: E402
from warpcli.grid import inside_polygon  # noqa: E402
from warpcli.maps.meshless import BEM, MFS  # noqa: E402
from warpcli.maps.theta import regular as regular_theta  # noqa: E402


def near_boundary(v: np.ndarray) -> np.ndarray:
    """Samples 1e-6..0.01 px inside every edge (every 0.25 px) and around every vertex."""
    e = np.roll(v, -1, axis=0) - v
    length = np.hypot(*e.T)
    area2 = np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
    inward = np.stack([-e[:, 1], e[:, 0]], 1) / length[:, None] * np.sign(area2)
    dist = np.geomspace(1e-6, 0.01, 9)
    parts = []
    for i in range(len(v)):  # loop over edges
        k = max(2, int(length[i] / 0.25))
        base = v[i] + ((np.arange(k) + 0.5) / k)[:, None] * e[i]
        parts.append((base[:, None, :] + dist[None, :, None] * inward[i]).reshape(-1, 2))
    ang = 2 * np.pi * (np.arange(96) + 0.5) / 96
    ring = (np.geomspace(1e-6, 0.01, 12)[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], -1)[None]).reshape(-1, 2)
    parts += [p + ring for p in v]
    p = np.concatenate(parts)
    return p[inside_polygon(p, v)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="11,5", help="comma-separated seeds of the generators")
    args = ap.parse_args(argv)
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start\n")
    print("| shape | seed | method | m | cells ok | cells s | boundary ok | Gamma px | band proved | boundary s | "
          "boundary evaluations | folds deeper than Gamma | deep deeper than Gamma | folds in the band | deep in the band |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for shape in sorted(SHAPES):
        if shape == "wavy":
            continue
        for seed in (int(s) for s in args.seeds.split(",")):
            v = SHAPES[shape](np.random.default_rng(seed))
            for method in ("mfs", "bem"):
                for nodes in (None, 128, 64):
                    if nodes is not None and nodes < len(v) + 8:
                        continue
                    poly = Polygon(v, name=shape)
                    opts = MapOptions(method=method, nodes=nodes, check=False)
                    phi = {"bem": BEM, "mfs": MFS}[method].build(poly, regular_theta(poly, poly, opts), opts)
                    t0 = time.perf_counter()
                    cells = phi.certify_cells_with(rigorous=method == "mfs")  # linear data: no ball
                    t1 = time.perf_counter()
                    proof = phi.boundary_certificate  # the default: MFS's fallback, the first band that holds
                    t2 = time.perf_counter()
                    p = np.concatenate([dense_samples(v, grid=60_000, along=0.25, corner_rings=16), near_boundary(v)])
                    deeper = nearest_edge(p, v)[2] > proof.offset
                    d = dense_check(phi, p[deeper])
                    b = dense_check(phi, p[~deeper]) if (~deeper).any() else {"folds": 0, "deep": 0}
                    print(f"| {shape} | {seed} | {method} | {phi.solution.m} | {cells.failed == 0} | {t1 - t0:.2f} | "
                          f"{proof.failed == 0} | {proof.offset:.4f} | {proof.band} | {t2 - t1:.2f} | {proof.checked} | "
                          f"{d['folds']} | {d['deep']} | "
                          f"{b['folds']} | {b['deep']} |", flush=True)  # fmt: skip
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
