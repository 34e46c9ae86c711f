"""Batch and sequence speed-up with --jobs: N frames through one map, or a shot with a map per frame.

    python bench/jobs.py                      # 50 frames of 1600x1250 PNG, 3 rounds: ~3 minutes
    python bench/jobs.py --frames 20 --format exr --jobs 1,2,4
    python bench/jobs.py --shot animated --frames 24 --size 1280x720 --rounds 5

``--shot batch`` (the default) warps the frames with ``--out-dir``, one map for all of them.
``--shot animated`` warps them as a sequence (``frame.#.png --frames 1-N``) whose polygons are
keyframed (the star turns and moves from the first frame to the last), so every frame has a map
of its own: the case that only processes make parallel (with --jobs N, N forked workers build
the next frames' maps while the main process warps the frames whose maps have arrived).

Each round runs `warp --out-dir` as a subprocess once per jobs value, in alternating order, on
the same generated frames (a colour ramp and a checker, different per frame; a 12-vertex star
onto a rotated one). Prints the median wall time per jobs value, the speed-up against jobs 1
measured in the same rounds, and whether every output file is byte-identical to jobs 1's.

Two more rows put the speed-up in context, measured in the same rounds:

    python bench/jobs.py --shot animated --frames 24 --size 1280x720 --one-core --checkout /path/to/old/clone

``--one-core`` runs ``--jobs 1`` pinned to one CPU (``sched_setaffinity``), the serial cost of
the shot (``--jobs 1`` itself is not serial: a forked child builds one of each frame's two maps
and kernels run on threads); ``--checkout DIR`` runs ``--jobs 1`` with another checkout's
``warpcli`` first on ``PYTHONPATH`` (e.g. the release an issue was measured on).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def write_frames(directory: str, count: int, w: int, h: int, ext: str) -> list[str]:
    import OpenImageIO as oiio

    y, x = np.mgrid[0:h, 0:w]
    paths = []
    for k in range(count):
        px = np.stack([(x * 255 // w + 3 * k) % 256, (y * 255 // h) % 256, ((x // 16 + y // 16 + k) % 2) * 200], axis=2).astype(np.uint8)
        path = os.path.join(directory, f"frame.{k + 1:04d}.{ext}")
        out = oiio.ImageOutput.create(path)
        out.open(path, oiio.ImageSpec(w, h, 3, "uint8"))
        out.write_image(px)
        out.close()
        paths.append(path)
    return paths


def star(cx, cy, r_in, r_out, phase=0.0, n=6):
    k = np.arange(2 * n)
    r = np.where(k % 2 == 0, r_out, r_in)
    a = phase + math.pi * k / n
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1).tolist()


def digest(directory: str) -> dict[str, str]:
    return {name: hashlib.sha256(open(os.path.join(directory, name), "rb").read()).hexdigest() for name in sorted(os.listdir(directory))}


def _children_cpu() -> float:
    """User and system seconds of the finished child processes (and theirs) so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument("--size", default="1600x1250")
    parser.add_argument("--format", default="png")
    parser.add_argument("--jobs", default="1,2")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--shot", choices=("batch", "animated"), default="batch")
    parser.add_argument("--one-core", action="store_true", help="add --jobs 1 pinned to one CPU")
    parser.add_argument("--checkout", metavar="DIR", help="add --jobs 1 run with DIR's warpcli")
    args = parser.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    jobs = [int(j) for j in args.jobs.split(",")]
    # Rows: (label, jobs value, extra environment, CPUs to pin the process to).
    rows = [(f"{j}", j, {}, None) for j in jobs]
    if args.one_core:
        rows.append(("1, one core", 1, {}, {min(os.sched_getaffinity(0))}))
    if args.checkout:
        rows.append((f"1, {os.path.basename(os.path.abspath(args.checkout))}", 1, {"PYTHONPATH": os.path.abspath(args.checkout)}, None))
    warp = os.path.join(os.path.dirname(sys.executable), "warp")
    with tempfile.TemporaryDirectory() as tmp:
        frames = write_frames(tmp, args.frames, w, h, args.format)
        s = min(w, h)
        src, dst = star(w / 2, h / 2, 0.2 * s, 0.45 * s), star(w / 2, h / 2, 0.15 * s, 0.47 * s, 0.3)
        if args.shot == "animated":  # keyframes at the first and last frame: a new pair on every frame
            n = args.frames
            src = {"frames": {"1": src, str(n): star(w / 2 + 0.04 * s, h / 2, 0.2 * s, 0.45 * s, 0.2)}}
            dst = {"frames": {"1": dst, str(n): star(w / 2, h / 2 + 0.03 * s, 0.15 * s, 0.47 * s, 0.5)}}
        for name, pts in (("src.json", src), ("dst.json", dst)):
            with open(os.path.join(tmp, name), "w") as fh:
                json.dump(pts, fh)
        times: dict[str, list[float]] = {row[0]: [] for row in rows}
        cpu: dict[str, list[float]] = {row[0]: [] for row in rows}
        hashes: dict[str, dict[str, str]] = {}
        for r in range(args.rounds):
            for label, j, env, pin in (rows if r % 2 == 0 else rows[::-1]):
                out = os.path.join(tmp, f"out{[row[0] for row in rows].index(label)}")
                os.makedirs(out, exist_ok=True)
                polys = ["--src", os.path.join(tmp, "src.json"), "--dst", os.path.join(tmp, "dst.json")]
                if args.shot == "animated":
                    ins = os.path.join(tmp, f"frame.#.{args.format}")
                    cmd = [warp, ins, os.path.join(out, f"out.#.{args.format}"), "--frames", f"1-{args.frames}", *polys, "--jobs", str(j), "-q"]
                else:
                    cmd = [warp, *frames, *polys, "--out-dir", out, "--jobs", str(j), "-q"]
                if env.get("PYTHONPATH"):  # another checkout's code, through the same interpreter
                    cmd = [sys.executable, "-m", "warpcli", *cmd[1:]]
                t0, c0 = time.perf_counter(), _children_cpu()
                # -m puts the working directory first on sys.path: run another checkout's code from there.
                cwd = env.get("PYTHONPATH")
                subprocess.run(cmd, check=True, cwd=cwd, env={**os.environ, **env}, preexec_fn=(lambda pin=pin: os.sched_setaffinity(0, pin)) if pin else None)
                times[label].append(time.perf_counter() - t0)
                cpu[label].append(_children_cpu() - c0)
                hashes[label] = digest(out)
                print(f"round {r + 1} jobs {label}: {times[label][-1]:.2f} s, {cpu[label][-1]:.2f} s of CPU", file=sys.stderr, flush=True)
    first = rows[0][0]
    base = statistics.median(times[first])
    print(f"{args.shot}: {args.frames} frames of {w}x{h} {args.format.upper()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; median of {args.rounds}")
    # Cores busy = CPU / wall: jobs 1 is not one core's worth (a forked child builds one of each
    # frame's two maps, kernels run on threads), so on 2 cores the speed-up of jobs 2 is at most
    # about 2 / (jobs 1's cores busy), less the serial start-up.
    print(f"| jobs | seconds (median) | per frame | CPU seconds (median) | cores busy | speed-up vs jobs {first} | outputs identical to jobs {first} |")
    print("|---|---:|---:|---:|---:|---:|---|")
    for label, *_ in rows:
        m = statistics.median(times[label])
        c = statistics.median(cpu[label])
        busy = statistics.median(cj / tj for cj, tj in zip(cpu[label], times[label]))
        print(f"| {label} | {m:.2f} | {m / args.frames:.3f} | {c:.2f} | {busy:.2f} | {base / m:.2f} | {'yes' if hashes[label] == hashes[first] else 'NO'} |")
    best = min(statistics.median(times[f"{j}"]) for j in jobs)
    others = ", ".join(f"x{statistics.median(times[label]) / best:.2f} over jobs {label}" for label, *_ in rows if statistics.median(times[label]) > best)
    if others:
        print(f"\nThe fastest jobs value: {others}.")


if __name__ == "__main__":
    main()
