"""Volume maps of cages much larger than the volume: meshed graded from the volume's box, against uniform meshes.

    python bench/volume_region.py [--size 32] [--scales 1 2 5 20] [--json out.json]

The docs' sample pair (a 3 x 3-quad box from 4 to 28 voxels onto the same box
twisted a fifth of a turn and bent by 0.5 rad) scaled by s about the volume's
centre, over a size^3 volume (TIFF convention). For each scale, in child
processes (peak RSS each its own): the default map (graded from the volume's
box once the cage reaches past it by half the box's size), and the uniform
mesh the cage's own size asks for (the behaviour before); each timed and its
accuracy measured at output voxel centres against a finer graded reference
(edges / 4^(1/3), slope halved): |f^-1 - f^-1_ref| in voxels.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np


def pair(scale: float, n: int):
    from warpcli.volume.examples import bend, box, twist
    from warpcli.volume.surface import surface_from_arrays

    v, f = box(3, (4.0, 4.0, 4.0), (28.0, 28.0, 28.0))
    v = v * n / 32.0
    c = n / 2.0
    src = surface_from_arrays((v - c) * scale + c, f, "cube")
    dst = surface_from_arrays((bend(twist(v, 0.2), 0.5) - c) * scale + c, f, "bent")
    return src, dst


def run(scale: float, n: int, mode: str) -> dict:
    from warpcli.volume import build_map, tetmesh
    from warpcli.volume.report import sample_voxels
    from warpcli.volume.volio import tiff_grid

    src, dst = pair(scale, n)
    grid = tiff_grid((n, n, n))
    region = grid.bounds()
    t0 = time.perf_counter()
    vmap = build_map(src, dst, region=region if mode == "graded" else None)
    build = time.perf_counter() - t0
    info = vmap.phi1.describe()
    out = {"scale": scale, "mode": mode, "build_s": round(build, 2), "tets": info.get("tetrahedra", 0),
           "edge": round(info.get("edge", 0.0), 3), "flipped": [c.flipped for c in vmap.certificates()],
           "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)}  # fmt: skip
    ref_path = f"/tmp/volume_region_ref_{scale:g}_{n}.npy"
    if mode == "graded":  # the reference: edges / 4^(1/3) at the region, growing at half the slope
        slope = tetmesh.REGION_SLOPE
        tetmesh.REGION_SLOPE = slope / 2
        try:
            ref = build_map(src, dst, edge=info["edge"] / 4 ** (1 / 3), region=region)
        finally:
            tetmesh.REGION_SLOPE = slope
        p = sample_voxels(grid, ref, 50_000)
        np.save(ref_path, np.concatenate([p, ref.inverse(p)], axis=1))
    ref = np.load(ref_path)
    d = np.linalg.norm(vmap.inverse(ref[:, :3]) - ref[:, 3:], axis=1)
    d = d[np.isfinite(d)]
    out["accuracy_vox"] = {"mean": round(float(d.mean()), 4) if d.size else None,
                           "p99": round(float(np.percentile(d, 99)), 4) if d.size else None, "samples": int(d.size)}  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 2.0, 5.0, 20.0])
    ap.add_argument("--uniform-up-to", type=float, default=20.0, help="skip the uniform mesh above this scale")
    ap.add_argument("--json")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        scale, mode = float(args.child[0]), args.child[1]
        print(json.dumps(run(scale, args.size, mode)))
        return
    rows = []
    print("| scale | mesh | edge | tetrahedra | build s | peak RSS MB | flipped | mean / p99 vs reference (vox) |")
    print("|---:|---|---:|---:|---:|---:|---|---|")
    for scale in args.scales:
        for mode in ("graded", "uniform"):
            if mode == "uniform" and scale > args.uniform_up_to:
                continue
            cmd = [sys.executable, __file__, "--size", str(args.size), "--child", str(scale), mode]
            done = subprocess.run(cmd, capture_output=True, text=True, check=True)
            res = json.loads(done.stdout.strip().splitlines()[-1])
            rows.append(res)
            acc = res["accuracy_vox"]
            print(f"| {scale:g} | {mode} | {res['edge']} | {res['tets']:,} | {res['build_s']} | {res['peak_rss_mb']} | "
                  f"{res['flipped']} | {acc['mean']} / {acc['p99']} |", flush=True)  # fmt: skip
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
