#!/usr/bin/env python
"""The cost of deciding every fold exactly: FEM triangles at 1 MP and volume tetrahedra.

    python bench/exact_orient.py             # 4 pairs at 1 MP, 2 volume cases; 7 runs each (~1-2 min busy)
    python bench/exact_orient.py --repeat 3

Per map (both maps of the four pairs of bench/theta_table.py at 1 MP, FEM at
the default settings; the source and target tetrahedral maps of the two
cases of bench/volume.py at 128^3), medians of ``--repeat`` runs of:

- ``float ms``: the former test, the sign of each image triangle's area
  (tetrahedron's volume) in doubles (`triangle_areas`, `tet_volumes`);
- ``exact ms``: the exact test the certificate runs now
  (`warpcli.maps.fem.solve.flipped_triangles`,
  `warpcli.volume.untangle.inverted`: Shewchuk's filter, then exact
  arithmetic for what it cannot decide);
- ``unsure``: how many elements the filter passed to exact arithmetic;
- ``differ``: elements whose float sign differs from the exact one.

The machine is shared: the header gives the load average; quote it with the numbers.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

from methods_table import REGION, bench_pairs  # noqa: E402

from warpcli import MapOptions, build_map  # noqa: E402
from warpcli.maps.fem.mesh import triangle_areas  # noqa: E402
from warpcli.maps.fem.solve import flipped_triangles  # noqa: E402
from warpcli.polygon import signed_area  # noqa: E402
from warpcli.polygon.predicates import orient, orient3d_sign  # noqa: E402
from warpcli.volume.tetmesh import tet_volumes  # noqa: E402
from warpcli.volume.untangle import inverted, tet_signs  # noqa: E402


def median_ms(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def fem_rows(repeat: int) -> list[str]:
    rows = []
    for name, src, dst in bench_pairs(None):
        f = build_map(src, dst, MapOptions(), regions=(REGION, REGION))
        for side, phi in (("phi0", f.phi0), ("phi1", f.phi1)):
            mesh, values, theta = phi.mesh, phi.values, phi.theta.points
            sense = np.sign(signed_area(theta))
            t = mesh.triangles
            a, b, c = values[t[:, 0]], values[t[:, 1]], values[t[:, 2]]
            det, bound = orient(a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1])
            unsure = int((~(np.abs(det) > bound)).sum())
            float_flip = triangle_areas(values, t) * sense <= 0
            exact_flip = flipped_triangles(mesh, values, theta)
            old = median_ms(lambda: triangle_areas(values, t) * sense <= 0, repeat)
            new = median_ms(lambda: flipped_triangles(mesh, values, theta), repeat)
            rows.append(f"| {name} {side} | {len(t):,} triangles | {old:.1f} | {new:.1f} | {unsure} | "
                        f"{int((float_flip != exact_flip).sum())} |")  # fmt: skip
    return rows


def volume_rows(repeat: int) -> list[str]:
    from volume import cages

    from warpcli.volume import build_map as build_volume_map

    rows = []
    for case in ("cube->bent", "blob4->blob3"):
        a, b = cages(case, 128)
        vmap = build_volume_map(a, b)
        for side, phi in (("source", vmap.phi0), ("target", vmap.phi1)):
            if not hasattr(phi, "mesh"):
                continue  # a cage that is its own Theta: the identity, nothing to check
            values, tets = phi.values, phi.mesh.tets
            vol = tet_volumes(values, tets)
            corners = [values[tets[:, k]] for k in range(4)]
            sign = orient3d_sign(*corners)
            old = median_ms(lambda: tet_volumes(values, tets) <= 0, repeat)
            new = median_ms(lambda: inverted(values, tets), repeat)
            signs = median_ms(lambda: tet_signs(values, tets), repeat)
            # The filter alone: how many went to exact arithmetic (those whose sign the bound leaves open).
            from warpcli.polygon import predicates

            calls = []
            exact = predicates._orient3d_exact
            predicates._orient3d_exact = lambda *p: calls.append(1) or exact(*p)
            try:
                orient3d_sign(*corners)
            finally:
                predicates._orient3d_exact = exact
            rows.append(f"| {case} {side} | {len(tets):,} tetrahedra | {old:.1f} | {new:.1f} (signs {signs:.1f}) | "
                        f"{len(calls)} | {int((np.sign(vol) != sign).sum())} |")  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; medians of {args.repeat} runs\n")
    print("| map | elements | float ms | exact ms | unsure | differ |")
    print("|---|---|---|---|---|---|")
    for rows in (fem_rows, volume_rows):
        print("\n".join(rows(args.repeat)), flush=True)


if __name__ == "__main__":
    main()
