"""Volume warps at 256^3: time, peak memory, accuracy against a 4x finer mesh, inversions before and after untangling (issue 14).

Each case runs in a child process, so that its peak RSS is its own:

    python bench/volume.py [--size 256] [--no-accuracy] [--json out.json]

Cases (cages in voxel coordinates of a TIFF-convention volume):
  cube->bent   a 5x5-per-side cube (152 vertices) onto the same box twisted a
               quarter turn and bent by 1.2 rad (Theta = the cube: one mesh);
  blob->blob   a star-shaped blob with 4 lobes onto one with 3 (642 vertices,
               Theta = the sphere strategy: two meshes, a walk between them).
Accuracy: |f^-1(p) - f^-1_fine(p)| in voxels over output voxel centres inside
the target (a regular subsample), with f_fine built on meshes of 4x as many
tetrahedra (edge lengths / 4^(1/3)).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np


def cages(case: str, n: int):
    from warpcli.volume.examples import bend, box, icosphere, star, twist
    from warpcli.volume.surface import surface_from_arrays

    s = n / 256.0
    if case == "cube->bent":
        v, f = box(5, (28 * s,) * 3, (228 * s,) * 3)
        return surface_from_arrays(v, f, "cube"), surface_from_arrays(bend(twist(v, 0.25), 1.2), f, "bent")
    v, f = icosphere(3)
    c = n / 2.0
    return (surface_from_arrays(c + 0.36 * n * star(v, 4, 0.3), f, "blob4"),
            surface_from_arrays(c + 0.36 * n * star(v, 3, 0.3, 0.5), f, "blob3"))  # fmt: skip


def volume(n: int):
    from warpcli.volume.volio import Volume, tiff_grid

    x = np.arange(n, dtype=np.float32)
    data = (127.5 + 60 * np.sin(x / 9.0)[None, None, :] + 60 * np.cos(x / 13.0)[None, :, None]
            * np.sin(x / 7.0)[:, None, None]).astype(np.uint8)  # fmt: skip
    return Volume(data[..., None], tiff_grid((n, n, n)), "tiff")


def run_case(case: str, n: int, accuracy: bool) -> dict:
    from warpcli.volume import build_map, warp_volume
    from warpcli.volume.report import build_report, sample_voxels

    a, b = cages(case, n)
    vol = volume(n)
    t0 = time.perf_counter()
    vmap = build_map(a, b)
    t1 = time.perf_counter()
    result = warp_volume(vol, vmap)
    t2 = time.perf_counter()
    out = {
        "case": case, "size": n, "build_s": round(t1 - t0, 2), "warp_s": round(t2 - t1, 2),
        "total_s": round(t2 - t0, 2), "timings": {k: round(v, 2) for k, v in vmap.timings.items()},
        "maps": {"source": vmap.phi0.describe(), "target": vmap.phi1.describe()},
        "theta": vmap.theta.name, "voxels_inside": result.inside,
    }  # fmt: skip
    out["peak_rss_mb_warp"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    rep = build_report(result)
    out["flipped_tetrahedra"] = rep["flipped_tetrahedra"]
    out["untangling"] = rep["untangling"]
    out["distortion"] = rep["distortion"]
    if accuracy:
        edges = [m.describe().get("edge") for m in (vmap.phi0, vmap.phi1)]
        edge = min(e for e in edges if e) / 4 ** (1 / 3)
        t3 = time.perf_counter()
        fine = build_map(a, b, edge=edge)
        out["fine_build_s"] = round(time.perf_counter() - t3, 2)
        out["fine_maps"] = {"source": fine.phi0.describe(), "target": fine.phi1.describe()}
        p = sample_voxels(vol.grid, vmap, 100_000)
        d = np.linalg.norm(vmap.inverse(p) - fine.inverse(p), axis=1)
        d = d[np.isfinite(d)]
        out["accuracy_vox"] = {"mean": round(float(d.mean()), 4), "p99": round(float(np.percentile(d, 99)), 4),
                               "max": round(float(d.max()), 4), "samples": int(d.size)}  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--case", choices=["cube->bent", "blob->blob"], action="append")
    ap.add_argument("--no-accuracy", action="store_true")
    ap.add_argument("--json")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    cases = args.case or ["cube->bent", "blob->blob"]
    if args.child:
        print(json.dumps(run_case(cases[0], args.size, not args.no_accuracy)))
        return
    results = []
    for case in cases:
        cmd = [sys.executable, __file__, "--child", "--size", str(args.size), "--case", case]
        if args.no_accuracy:
            cmd.append("--no-accuracy")
        done = subprocess.run(cmd, capture_output=True, text=True, check=True)
        res = json.loads(done.stdout.strip().splitlines()[-1])
        results.append(res)
        acc = res.get("accuracy_vox", {})
        unt = res["untangling"]
        inv = ", ".join(
            f"{side} {unt[side]['inverted_before']} -> {unt[side]['inverted_after']}" for side in ("source", "target") if unt[side]
        ) or "no meshes"
        print(f"{case:11s} {args.size}^3: build {res['build_s']} s + warp {res['warp_s']} s = {res['total_s']} s, "
              f"peak RSS {res['peak_rss_mb_warp']} MB; tets {res['maps']['source'].get('tetrahedra', 0)} + "
              f"{res['maps']['target'].get('tetrahedra', 0)}; inverted (harmonic -> untangled) {inv}, moved by at most "
              f"{unt['max_displacement_voxels']} voxel; "
              f"min det J {res['distortion'].get('min_jacobian_det')}; accuracy {acc}", flush=True)  # fmt: skip
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)


if __name__ == "__main__":
    main()
