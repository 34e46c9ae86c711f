#!/usr/bin/env python
"""What a cage mesh costs against one polygon with the same outline, and against scikit-image.

    python bench/cage.py                   # 512 x 512, grids of 1 to 8 x 8 faces, 3 runs each: ~1 minute
    python bench/cage.py --size 1024 --repeat 5

Every row maps the same square region (most of the image) cut into a k x k grid
of faces with its interior vertices jittered (a seeded random cage), with FEM and
the default mesh density: ``build`` is `build_cage_map` (one `build_map` per
face), ``pull-back`` the inverse map at every output pixel with Jacobians
(`CageMap.pull_back`, which locates each pixel's face by scan conversion and
takes the face maps' own pull-backs), ``labels`` that location alone. The
``1 x 1`` row is a cage mesh of one face, the ``polygon`` row the same square as
a `Polygon`. The last rows are k x k meshes of triangles (each square cut in
two) against scikit-image's ``PiecewiseAffineTransform`` on the same triangles
(estimate, then its inverse at every pixel centre), which is the same map.

Medians of ``--repeat`` runs, taken in turns so that a busy machine slows every
row alike; the ``spread`` column is (max - min) / median of the totals.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def grid(k: int, size: int, seed: int = 0, triangles: bool = False):
    from warpcli.polygon.partition import Partition

    lo, hi = 0.1 * size, 0.9 * size
    xs = np.linspace(lo, hi, k + 1)
    verts = np.array([[x, y] for y in xs for x in xs])
    faces = []
    for r in range(k):
        for c in range(k):
            a, b, d, e = r * (k + 1) + c, r * (k + 1) + c + 1, (r + 1) * (k + 1) + c + 1, (r + 1) * (k + 1) + c
            faces += [(a, b, d), (a, d, e)] if triangles else [(a, b, d, e)]
    rng = np.random.default_rng(seed)
    moved = verts.copy()
    inner = [i for i in range(len(verts)) if 0 < i % (k + 1) < k and 0 < i // (k + 1) < k]
    cell = (hi - lo) / k
    moved[inner] += rng.uniform(-0.25, 0.25, (len(inner), 2)) * cell
    return Partition(verts, faces, "src"), Partition(moved, faces, "dst")


def one_run(kind: str, k: int, size: int) -> dict:
    from warpcli.maps.cage import build_cage_map, face_labels
    from warpcli.maps.compose import build_map

    clock = time.perf_counter
    if kind == "polygon":
        src, dst = grid(1, size)
        t0 = clock()
        fmap = build_map(src.outline, dst.outline)
        t1 = clock()
        fmap.pull_back(size, size, jacobian=True)
        return {"build": t1 - t0, "pull-back": clock() - t1, "labels": 0.0}
    if kind == "skimage":
        from skimage.transform import PiecewiseAffineTransform

        from warpcli.grid import pixel_centres

        src, dst = grid(k, size, triangles=True)
        t0 = clock()
        make = getattr(PiecewiseAffineTransform, "from_estimate", None)  # scikit-image 0.26 on
        if make is not None:
            tform = make(dst.vertices, src.vertices)
        else:
            tform = PiecewiseAffineTransform()
            tform.estimate(dst.vertices, src.vertices)
        t1 = clock()
        tform(pixel_centres(size, size))
        return {"build": t1 - t0, "pull-back": clock() - t1, "labels": 0.0}
    src, dst = grid(k, size, triangles=kind == "triangles")
    t0 = clock()
    fmap = build_cage_map(src, dst)
    t1 = clock()
    fmap.pull_back(size, size, jacobian=True)
    t2 = clock()
    face_labels(dst, size, size, (0, size), (0, size))
    return {"build": t1 - t0, "pull-back": t2 - t1, "labels": clock() - t2}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rows = [("polygon", 1), ("quads", 1), ("quads", 2), ("quads", 4), ("quads", 8),
            ("triangles", 4), ("skimage", 4), ("triangles", 8), ("skimage", 8)]  # fmt: skip
    for kind, k in rows:  # once untimed: kernels load, caches warm
        one_run(kind, k, 64)
    runs: dict = {row: [] for row in rows}
    for _ in range(args.repeat):
        for row in rows:
            runs[row].append(one_run(*row, args.size))
    print(f"{args.size} x {args.size} output, medians of {args.repeat} runs (a shared, busy machine: compare rows)")
    print(f"{'what':<24} {'faces':>5} {'build s':>8} {'pull-back s':>11} {'labels s':>8} {'spread':>6}")
    for (kind, k), got in runs.items():
        med = {key: statistics.median(r[key] for r in got) for key in got[0]}
        totals = [r["build"] + r["pull-back"] for r in got]
        spread = (max(totals) - min(totals)) / statistics.median(totals)
        faces = 1 if kind == "polygon" else (2 * k * k if kind in ("triangles", "skimage") else k * k)
        name = {"polygon": "polygon (BijectiveMap)", "quads": f"cage mesh {k} x {k}",
                "triangles": f"triangle mesh {k} x {k} x 2", "skimage": "skimage PiecewiseAffine"}[kind]  # fmt: skip
        print(f"{name:<24} {faces:>5} {med['build']:>8.3f} {med['pull-back']:>11.3f} {med['labels']:>8.3f} {spread:>6.0%}")


if __name__ == "__main__":
    main()
