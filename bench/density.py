#!/usr/bin/env python
"""Mesh density against accuracy: could a graded size field give the default accuracy with fewer triangles? (issue 24)

    python bench/density.py                     # 1 MP, star12 and wavy48: about 30 s
    python bench/density.py --megapixels 4 --pairs star12

The default FEM mesh has one largest area for the whole polygon (`auto_max_area`), graded
only towards reflex vertices. Harmonic maps are smooth inside, so a mesh that grows away from
the boundary might reach the same accuracy with fewer triangles, and a map with fewer
triangles builds faster. This measures it: for each pair of `bench/run.py`, the FEM map on

- the default meshes (as `warp` builds them),
- uniform meshes of twice and half the default area,
- meshes whose edge length grows with the distance d from the polygon's boundary,
  ``min(cap * h, h + slope * d)`` (h: the default's edge length at the boundary, so the
  boundary keeps its points; reflex vertices graded as by default), at the default area
  and at half of it,

each against a reference on meshes of a sixteenth of the default area, at every third pixel
centre of the output grid: triangles of both meshes, mean, 99th percentile and maximum of
the distance in pixels. A size field that wins gives a lower mean at the same triangle count.
"""

from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import run as bench  # bench/run.py: the image sizes and polygon pairs

from warpcli.grid import pixel_centres
from warpcli.maps.compose import BijectiveMap
from warpcli.maps.fem import FEMMap
from warpcli.maps.fem import mesh as M
from warpcli.maps.fem.solve import DirichletSolver
from warpcli.polygon import Polygon

#: (slope, cap) of the size fields tried.
FIELDS = ((0.02, 2.0), (0.05, 2.0), (0.05, 3.0), (0.1, 3.0), (0.2, 4.0))


def boundary_distance(points: np.ndarray, polygon: Polygon) -> np.ndarray:
    """Distance from each point to the polygon's boundary."""
    p = polygon.points
    out = np.full(len(points), np.inf)
    for a, b in zip(p, np.roll(p, -1, axis=0)):
        ab = b - a
        t = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
        out = np.minimum(out, np.hypot(*(points - (a + t[:, None] * ab)).T))
    return out


def graded_mesh(polygon: Polygon, max_area: float, slope: float, cap: float) -> M.TriMesh:
    """A mesh of ``polygon`` with the size field above, refined in passes from a coarse one."""
    import triangle as tr

    out = tr.triangulate(M.triangle_input(polygon, max_area), f"pq{M.MIN_ANGLE:g}a{max_area * cap * cap:.17g}Q")
    h = math.sqrt(4.0 * max_area / math.sqrt(3.0))
    reflex = polygon.points[polygon.reflex_vertices()]
    for _ in range(40):
        c = M.centroids(out["vertices"], out["triangles"])
        edge = np.minimum(cap * h, h + slope * boundary_distance(c, polygon))
        if len(reflex):
            edge = np.minimum(edge, np.maximum(M._GRADE_SLOPE * M._nearest_distance(c, reflex), M._GRADE_MIN))
        target = math.sqrt(3.0) / 4.0 * edge * edge
        area = np.abs(M.triangle_areas(out["vertices"], out["triangles"]))
        big = area > target
        if not big.any():
            break
        out["triangle_max_area"] = np.where(big, np.maximum(target, area / 4.0), -1.0).reshape(-1, 1)
        out = tr.triangulate(out, f"rpq{M.MIN_ANGLE:g}aQ")
    return M.mesh_from_triangle(polygon, out)


def fem_on(polygon: Polygon, theta, mesh: M.TriMesh) -> FEMMap:
    """The FEM map of ``polygon`` onto ``theta`` on a given mesh (cotangent weights, linear boundary)."""
    return FEMMap(polygon, theta, mesh, DirichletSolver(mesh).solve(theta.points))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--megapixels", type=float, default=1.0)
    p.add_argument("--pairs", default="star12,wavy48")
    args = p.parse_args(argv)
    w, h = bench.image_dims(args.megapixels)
    pairs = {pair.name: pair for pair in bench.make_pairs(w, h)}
    pts = pixel_centres(w, h)[::3]
    print(f"{w} x {h}, every third pixel centre against meshes of 1/16 the default area\n")
    print("| pair | meshes | triangles | mean px | p99 px | max px |")
    print("|---|---|---:|---:|---:|---:|")
    for name in args.pairs.split(","):
        pair = pairs[name]
        src, dst = Polygon(pair.src, name="src"), Polygon(pair.dst, name="dst")
        a0, a1 = M.auto_max_area(src), M.auto_max_area(dst)
        default = BijectiveMap.between(src, dst)
        theta = default.theta
        ref = BijectiveMap.between(src, dst, max_area=(a0 / 16, a1 / 16)).inverse(pts)

        def row(label: str, fmap: BijectiveMap) -> None:
            got = fmap.inverse(pts)
            ok = np.isfinite(got).all(axis=1) & np.isfinite(ref).all(axis=1)
            d = np.hypot(*(got[ok] - ref[ok]).T)
            tri = len(fmap.phi0.mesh.triangles) + len(fmap.phi1.mesh.triangles)
            print(f"| {name} | {label} | {tri:,} | {d.mean():.4f} | {np.percentile(d, 99):.4f} | {d.max():.3f} |", flush=True)

        row("default", default)
        for k in (2.0, 0.5):
            row(f"uniform, area x{k:g}", BijectiveMap.between(src, dst, max_area=(a0 * k, a1 * k)))
        for scale in (1.0, 0.5):
            for slope, cap in FIELDS:
                phis = [fem_on(poly, theta, graded_mesh(poly, a * scale, slope, cap)) for poly, a in ((src, a0), (dst, a1))]
                row(f"graded, area x{scale:g}, slope {slope:g}, cap {cap:g}", BijectiveMap(*phis))
    return 0


if __name__ == "__main__":
    sys.exit(main())
