"""--jobs N, the cores a run may keep busy: batches, animated shots and single images against one core.

    python bench/jobs.py                      # 50 frames of 1600x1250 PNG, 3 rounds: ~3 minutes
    python bench/jobs.py --frames 20 --format exr --jobs 1,2,4
    python bench/jobs.py --shot animated --frames 24 --size 1280x720 --rounds 3 --one-core
    python bench/jobs.py --shot single --frames 6 --checkout /path/to/old/clone

``--shot batch`` (the default) warps the frames with ``--out-dir``, one map for all of them.
``--shot animated`` warps them as a sequence (``frame.#.png --frames 1-N``) whose polygons are
keyframed (the star turns and moves from the first frame to the last), so every frame has a map
of its own: the case that only processes make parallel (with --jobs N, N forked workers build
the next frames' maps while the main process warps the frames whose maps have arrived).
``--shot single`` runs ``warp IN OUT`` once per frame, one image each: the single-image run.

warpcli's bytecode (and the other checkout's) is compiled first, as ``pip install`` does: in a
shell with ``PYTHONDONTWRITEBYTECODE`` every run would compile its modules again (0.26 s, serial,
in every row alike), which is no cost of an installed ``warp``.

Each round runs `warp` as a subprocess once per row, in alternating order (after one untimed
warm-up run of each row on the first frames), on the same generated frames (a colour ramp and
a checker, different per frame; a 12-vertex star onto a rotated one). The rows are ``--jobs``
values (``--jobs 1`` is one core: no threads, no child processes) and ``default`` (no
``--jobs``: every core the process may use). Prints the median wall time per row, the speed-up
against the first row measured in the same rounds, the CPU seconds (user and system of the
whole process tree: the figure to read on a loaded machine, where wall times follow the other
work), of which system seconds, the cores kept busy (CPU / wall), the CPU against the first
row's, and whether every output file is byte-identical to the first row's. Each round's line
(on stderr) gives the load average next to its times.

Two more rows put the speed-up in context, measured in the same rounds:

``--one-core`` runs ``--jobs 1`` pinned to one CPU (``sched_setaffinity``, as ``taskset``
does): an independent check that ``--jobs 1`` is the serial cost of the shot (the two rows
should agree). ``--checkout DIR`` runs another checkout's ``warpcli`` (e.g. the release an
issue was measured on, or the code before a change) with its default ``--jobs``.
``--pair`` runs two ``--jobs 1`` shots at once, each pinned to a CPU of its own, and gives
each shot half the wall time and half the CPU: what two independent serial processes get out
of the machine, the ceiling of any process-level parallelism on it. Its CPU against ``--jobs 1``
is what the machine charges for running two at once (shared caches and memory bandwidth, and
on a virtual machine the host's sharing of its cores), which no code of ours causes.
"""

from __future__ import annotations

import argparse
import compileall
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


def _children_cpu() -> tuple[float, float]:
    """User and system seconds of the finished child processes (and theirs) so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime, usage.ru_stime


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument("--size", default="1600x1250")
    parser.add_argument("--format", default="png")
    parser.add_argument("--jobs", default="1,2,default", help="rows: --jobs values, 'default' for none [1,2,default]")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--shot", choices=("batch", "animated", "single"), default="batch")
    parser.add_argument("--one-core", action="store_true", help="add --jobs 1 pinned to one CPU")
    parser.add_argument("--checkout", metavar="DIR", help="add a row running DIR's warpcli with its default --jobs")
    parser.add_argument("--pair", action="store_true", help="add two --jobs 1 shots at once, each pinned to a CPU (per shot)")
    args = parser.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    jobs = [None if j == "default" else int(j) for j in args.jobs.split(",")]
    # Rows: (label, jobs value or None for the default, extra environment, CPUs to pin the process
    # to; for the pair, one set of CPUs per shot).
    rows = [(f"{j or 'default'}", j, {}, None) for j in jobs]
    cpus = sorted(os.sched_getaffinity(0))
    if args.pair and len(cpus) >= 2:
        rows.append(("1, two shots at once", 1, {}, ({cpus[0]}, {cpus[1]})))
    if args.one_core:
        rows.append(("1, taskset one core", 1, {}, {min(os.sched_getaffinity(0))}))
    if args.checkout:
        rows.append((f"default, {os.path.basename(os.path.abspath(args.checkout))}", None, {"PYTHONPATH": os.path.abspath(args.checkout)}, None))
    warp = os.path.join(os.path.dirname(sys.executable), "warp")
    import warpcli

    for package in (os.path.dirname(warpcli.__file__), *((os.path.join(args.checkout, "warpcli"),) if args.checkout else ())):
        compileall.compile_dir(package, quiet=1)  # as an installation does (see above)
    load_before = os.getloadavg()[0]
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
        sys_cpu: dict[str, list[float]] = {row[0]: [] for row in rows}  # of which the kernel's (page faults, pipes)
        loads: list[float] = []
        hashes: dict[str, dict[str, str]] = {}
        polys = ["--src", os.path.join(tmp, "src.json"), "--dst", os.path.join(tmp, "dst.json")]

        def commands(out: str, j: int | None, count: int) -> list[list[str]]:
            flag = [] if j is None else ["--jobs", str(j)]
            if args.shot == "animated":
                ins = os.path.join(tmp, f"frame.#.{args.format}")
                return [[warp, ins, os.path.join(out, f"out.#.{args.format}"), "--frames", f"1-{count}", *polys, *flag, "-q"]]
            if args.shot == "single":
                return [[warp, f, os.path.join(out, os.path.basename(f)), *polys, *flag, "-q"] for f in frames[:count]]
            return [[warp, *frames[:count], *polys, "--out-dir", out, *flag, "-q"]]

        def run(label: str, j: int | None, env: dict, pin, out: str, count: int) -> None:
            if isinstance(pin, tuple):  # the pair: both shots at once, each in a directory and on a CPU of its own
                os.makedirs(out, exist_ok=True)
                procs = []
                for k, one in enumerate(pin):
                    os.makedirs(os.path.join(out, f"shot{k}"), exist_ok=True)
                    procs += [subprocess.Popen(cmd, env={**os.environ, **env}, preexec_fn=lambda one=one: os.sched_setaffinity(0, one))
                              for cmd in commands(os.path.join(out, f"shot{k}"), j, count)]  # fmt: skip
                if any(p.wait() for p in procs):
                    raise subprocess.CalledProcessError(1, "warp")
                return
            os.makedirs(out, exist_ok=True)
            for cmd in commands(out, j, count):
                if env.get("PYTHONPATH"):  # another checkout's code, through the same interpreter
                    cmd = [sys.executable, "-m", "warpcli", *cmd[1:]]
                # -m puts the working directory first on sys.path: run another checkout's code from there.
                cwd = env.get("PYTHONPATH")
                subprocess.run(cmd, check=True, cwd=cwd, env={**os.environ, **env}, preexec_fn=(lambda pin=pin: os.sched_setaffinity(0, pin)) if pin else None)

        for label, j, env, pin in rows:  # warm-up: compiled kernels loaded (or compiled) once, files cached
            run(label, j, env, pin, os.path.join(tmp, "warm"), min(2, args.frames))
        for r in range(args.rounds):
            for label, j, env, pin in (rows if r % 2 == 0 else rows[::-1]):
                out = os.path.join(tmp, f"out{[row[0] for row in rows].index(label)}")
                t0, (u0, s0) = time.perf_counter(), _children_cpu()
                run(label, j, env, pin, out, args.frames)
                shots = len(pin) if isinstance(pin, tuple) else 1  # the pair's figures are per shot
                times[label].append((time.perf_counter() - t0) / shots)
                u1, s1 = _children_cpu()
                cpu[label].append((u1 - u0 + s1 - s0) / shots)
                sys_cpu[label].append((s1 - s0) / shots)
                loads.append(os.getloadavg()[0])
                hashes[label] = digest(os.path.join(out, "shot1") if shots > 1 else out)
                print(f"round {r + 1} jobs {label}: {times[label][-1]:.2f} s, {cpu[label][-1]:.2f} s of CPU ({sys_cpu[label][-1]:.2f} system), "
                      f"load {loads[-1]:.2f}", file=sys.stderr, flush=True)  # fmt: skip
    first = rows[0][0]
    base = statistics.median(times[first])
    print(f"{args.shot}: {args.frames} frames of {w}x{h} {args.format.upper()}, {os.cpu_count()} cores, load {load_before:.2f} before, "
          f"{os.getloadavg()[0]:.2f} after, {statistics.median(loads):.2f} median after each run; median of {args.rounds}")  # fmt: skip
    # Cores busy = CPU / wall: jobs 1 keeps one core busy, so on 2 cores the speed-up of
    # jobs 2 is at most about 2, less the serial start-up and what other processes take.
    # CPU seconds are user + system of the whole process tree (the workers too): on a loaded
    # machine they are the steadier figure; system seconds show page faults and pipe copies.
    print(f"| jobs | seconds (median) | per frame | CPU seconds (median) | of which system | cores busy | speed-up vs jobs {first} | CPU vs jobs {first} | outputs identical to jobs {first} |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
    base_cpu = statistics.median(cpu[first])
    for label, *_ in rows:
        m = statistics.median(times[label])
        c = statistics.median(cpu[label])
        busy = statistics.median(cj / tj for cj, tj in zip(cpu[label], times[label]))
        print(f"| {label} | {m:.2f} | {m / args.frames:.3f} | {c:.2f} | {statistics.median(sys_cpu[label]):.2f} | {busy:.2f} | {base / m:.2f} | "
              f"{c / base_cpu:.3f} | {'yes' if hashes[label] == hashes[first] else 'NO'} |")  # fmt: skip
    best = min(statistics.median(times[f"{j or 'default'}"]) for j in jobs)
    others = ", ".join(f"x{statistics.median(times[label]) / best:.2f} over jobs {label}" for label, *_ in rows if statistics.median(times[label]) > best)
    if others:
        print(f"\nThe fastest jobs row: {others}.")


if __name__ == "__main__":
    main()
