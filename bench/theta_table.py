"""Distortion by choice of Theta and boundary behaviour, in the style of the paper's Table 2.

    python bench/theta_table.py                     # FEM: a markdown table (about 2 minutes)
    python bench/theta_table.py --method mfs --pairs U  # another method, some pairs

For each polygon pair (the two sample pairs and two concave pairs drawn
here), the area-weighted mean and the maximum conformal and isometric
distortion of the FEM map, measured like the report (at every output pixel
of a 512 px image, weighted by the source area it stands for), for the
regular, cyclic and optimized Theta (optimized for each energy) and for
quadratic target boundaries; and the seconds each took.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))

from warpcli import MapOptions, Polygon, build_report, read_polygon, warp_image  # noqa: E402

SAMPLES = os.path.join(HERE, "..", "sample_images")


def pairs():
    yield "grid: L -> hexagon", read_polygon(os.path.join(SAMPLES, "grid_L.json")), read_polygon(os.path.join(SAMPLES, "grid_hexagon.json")), (512, 512)
    yield "chelsea: ring -> star", read_polygon(os.path.join(SAMPLES, "chelsea_ring.json")), read_polygon(os.path.join(SAMPLES, "chelsea_star.json")), (451, 300)
    # A U onto an irregular convex octagon with very uneven edges: far from regular.
    u = [[60, 60], [200, 60], [200, 380], [320, 380], [320, 60], [460, 60], [460, 460], [60, 460]]
    octagon = [[40, 250], [70, 90], [250, 40], [420, 60], [480, 200], [470, 300], [400, 470], [100, 450]]
    yield "U -> uneven octagon", Polygon(u, name="U"), Polygon(octagon, name="octagon"), (512, 512)
    # A 10-point comb-like zigzag onto a thin star.
    k = np.arange(10)
    a = 2 * np.pi * k / 10
    r = np.where(k % 2 == 0, 220.0, 90.0)
    star = np.stack([256 + r * np.cos(a), 256 + 0.6 * r * np.sin(a)], axis=1)
    zig = np.array([[40, 80], [120, 300], [200, 80], [280, 300], [360, 80], [470, 300], [470, 460], [300, 420], [200, 460], [40, 460]], float)
    yield "zigzag -> flat star", Polygon(zig, name="zigzag"), Polygon(star, name="star"), (512, 512)


VARIANTS = [
    ("regular", MapOptions()),
    ("cyclic", MapOptions(theta="cyclic")),
    ("optimized (conformal)", MapOptions(theta="optimized", energy="conformal")),
    ("optimized (isometric)", MapOptions(theta="optimized", energy="isometric")),
    ("quadratic DST boundary", MapOptions(dst_boundary="quadratic")),
]


def main(argv: list[str] | None = None) -> None:
    import argparse
    import dataclasses

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="fem", choices=("fem", "bem", "mfs"))
    parser.add_argument("--pairs", default="", help="only pairs whose name starts with one of these (comma-separated)")
    args = parser.parse_args(argv)
    wanted = [w for w in args.pairs.split(",") if w]
    rows = []
    for name, src, dst, size in pairs():
        if wanted and not any(name.startswith(w) for w in wanted):
            continue
        img = np.zeros((size[1], size[0], 1), dtype=np.float32)
        for label, opts in VARIANTS:
            opts = dataclasses.replace(opts, method=args.method)
            t0 = time.perf_counter()
            res = warp_image(img, src, dst, map=opts)
            seconds = time.perf_counter() - t0
            rep = build_report(res)
            rows.append((f"{name} ({args.method})" if args.method != "fem" else name, label, rep["conformal"]["mean"], rep["conformal"]["max"], rep["isometric"]["mean"], rep["isometric"]["max"], seconds, rep["flipped_triangles"]))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    print("| pair | Theta / boundary | conformal mean | conformal max | isometric mean | isometric max | seconds | flipped |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]:.3f} | {r[3]:.2f} | {r[4]:.3f} | {r[5]:.2f} | {r[6]:.1f} | {r[7]} |")


if __name__ == "__main__":
    main()
