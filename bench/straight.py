"""``--theta none`` (the plain harmonic map straight onto the target) beside every registered Theta.

    python bench/straight.py                    # eight pairs, FEM, a markdown table (a minute or two)
    python bench/straight.py --pairs star,U

On the six concave pairs of bench/optimizer.py and the two of bench/theta_table.py that
are not among them, every Theta strategy of `warpcli.maps.registry.THETAS` is run
through `warp_image` (FEM, default density, a 512 px image) and measured by the report
(`build_report`: mean and maximum conformal and isometric distortion over the source).
Where the straight map folds, its row says at how many triangles (the run refuses it).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import optimizer
import theta_table

from warpcli import MapOptions, build_report, warp_image
from warpcli.errors import InputError
from warpcli.maps.registry import THETAS


def pairs():
    seen = set()
    for name, src, dst in optimizer.pairs():
        seen.add(name)
        yield name, src, dst
    for name, src, dst, _ in theta_table.pairs():
        if name not in seen:
            yield name, src, dst


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", default="", help="only pairs whose name starts with one of these (comma-separated)")
    args = parser.parse_args(argv)
    wanted = [w for w in args.pairs.split(",") if w]
    print("| pair | Theta | conformal mean | conformal max | isometric mean | isometric max | flipped | kept | seconds |")
    print("|---|---|---:|---:|---:|---:|---:|---|---:|")
    for name, src, dst in pairs():
        if wanted and not any(name.startswith(w) for w in wanted):
            continue
        size = int(np.ceil(max(src.bounds[2], src.bounds[3], dst.bounds[2], dst.bounds[3]))) + 1
        img = np.zeros((size, size, 1), dtype=np.float32)
        for theta in THETAS:
            t0 = time.perf_counter()
            try:
                res = warp_image(img, src, dst, map=MapOptions(theta=theta))
            except InputError as err:
                print(f"| {name} | {theta} | refused: {str(err).split('; ')[0].split(' folds ')[-1]} | | | | | | |", flush=True)
                continue
            rep = build_report(res)
            c, i = rep["conformal"], rep["isometric"]
            kept = rep.get("theta", {}).get("kept", "")
            print(
                f"| {name} | {theta} | {c['mean']:.4f} | {c['max']:.2f} | {i['mean']:.4f} | {i['max']:.2f} | "
                f"{rep['flipped_triangles']} | {kept} | {time.perf_counter() - t0:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
