#!/usr/bin/env python
"""``warp texture``'s cost: a texture and vertex colours moved between two generated charts.

    python bench/texture.py                      # 1024 and 2048 px, fem and mfs, 3 runs each
    python bench/texture.py --sizes 1024 --methods fem --repeat 5

SRC is a 61 x 61 grid whose chart is a disk with a wavy rim (240 boundary
vertices), DST a 41 x 81 grid on an arch (240 boundary vertices, spaced
otherwise), four corners named on each, so the polygons hold the vertices of
both sides (the arclength merge). Each row is the median wall time of
``--repeat`` runs in this process (after one untimed run that loads the
kernels): the map built and the texture resampled into DST's layout with the
default filter, antialiasing and padding; and SRC's vertex colours carried
onto DST's 3321 vertices (map included). The machine's load changes the
numbers: say how busy it was next to them.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from warpcli.surface import UVMesh, transfer_attributes, transfer_texture


def grid_mesh(nu: int, nv: int, uv_of, reverse: bool = False) -> UVMesh:
    s, t = np.meshgrid(np.linspace(0, 1, nu), np.linspace(0, 1, nv))
    unit = np.stack([s.ravel(), t.ravel()], axis=1)
    r, c = np.mgrid[0 : nv - 1, 0 : nu - 1]
    a = (r * nu + c).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + nu + 1], 1), np.stack([a, a + nu + 1, a + nu], 1)])
    if reverse:  # faces counter-clockwise in UV space whichever way the layout turns the grid
        tris = tris[:, ::-1]
    uv = uv_of(unit)
    colours = {"red": 255 * unit[:, 0], "green": 255 * unit[:, 1], "blue": 255 * (1 - unit[:, 0])}
    return UVMesh(np.column_stack([unit, np.zeros(len(unit))]), uv, tris, tris, colours, dict.fromkeys(colours, "uchar"))


def wavy_disk(unit):
    """The unit square onto a disk with a wavy rim (square-to-disk by radial scaling)."""
    p = 2 * unit - 1
    a = np.arctan2(p[:, 1], p[:, 0])
    m = np.maximum(np.abs(p[:, 0]), np.abs(p[:, 1]))
    radius = m * (0.4 + 0.03 * np.sin(6 * a))
    return 0.5 + radius[:, None] * np.stack([np.cos(a), np.sin(a)], axis=1)


def arch(unit):
    angle = np.radians(20 + 140 * unit[:, 0])
    radius = 0.2 + 0.28 * unit[:, 1]
    return np.stack([0.5 + radius * np.cos(angle), 0.12 + radius * np.sin(angle)], axis=1)


def timed(fn, repeat: int) -> float:
    fn()
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        runs.append(time.perf_counter() - t0)
    return statistics.median(runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1024,2048")
    parser.add_argument("--methods", default="fem,mfs")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    src = grid_mesh(61, 61, wavy_disk)
    dst = grid_mesh(81, 41, arch, reverse=True)
    # Corners in loop order: the disk's bottom-left, bottom-right, top-right, top-left
    # onto the arch's inner-left, inner-right, outer-right, outer-left ends.
    corners = dict(src_corners=[0, 60, 3720, 3660], dst_corners=[80, 0, 3240, 3320])
    rng = np.random.default_rng(0)
    print("| method | texture | texture moved (s) | colours moved (s) |")
    print("|---|---|---|---|")
    for method in args.methods.split(","):
        for size in (int(s) for s in args.sizes.split(",")):
            tex = (rng.random((size, size, 3)) * 255).astype(np.uint8)
            t_tex = timed(lambda: transfer_texture(tex, src, dst, method=method, **corners), args.repeat)
            t_att = timed(
                lambda: transfer_attributes(src, dst, options=None if method == "fem" else _opts(method), **corners),
                args.repeat,
            )
            print(f"| {method} | {size} x {size} | {t_tex:.2f} | {t_att:.2f} |", flush=True)


def _opts(method: str):
    from warpcli import MapOptions

    return MapOptions(method=method)


if __name__ == "__main__":
    main()
