"""What each process of a warp does when: a light trace of a run's stages, and a timeline of them.

    python bench/shot_timeline.py -- IN.#.png OUT.#.png --frames 1-24 --src s.json --dst d.json --jobs 2 -q
    python bench/shot_timeline.py --shot animated --frames 24 --size 1280x720 --jobs 2   # bench/jobs.py's shot

Runs ``warp`` with the given arguments in a child interpreter that wraps the stages of a
sequence (the map workers' builds and plans, their copies into shared memory, the main
process's waits, reads, resampling and writes, the start-up) in timers, before any of them
runs; the forked workers inherit the wrapped functions. Each stage logs one line (start and
end on the monotonic clock, which all the processes share; the thread's CPU seconds; the
process's user and system seconds and minor page faults over the stage) to a file, and the
table printed after the run gives, per process, the seconds and CPU each stage took in all,
and when each process was first and last busy: the serial head (before the first plan
arrives) and tail (after the last build ends). ``--gantt`` draws one line per process, a
character per 50 ms. No change to the code it times; the wrappers cost a few microseconds a
stage.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import subprocess
import sys
import tempfile
import time

TRACE_ENV = "WARPCLI_BENCH_TRACE"
T0_ENV = "WARPCLI_BENCH_T0"


def _install(path: str) -> None:
    """In the traced interpreter: wrap the stages; each logs a line to ``path``."""
    import functools
    import resource
    import threading

    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    frame_re = re.compile(r"\.(-?\d+)\.[A-Za-z0-9]+$")

    def log(**event) -> None:
        # One write per line, shorter than PIPE_BUF: lines of several processes do not interleave.
        # ``process``: the process's CPU seconds so far (user and system), at the stage's end.
        r = resource.getrusage(resource.RUSAGE_SELF)
        os.write(fd, (json.dumps({**event, "process": r.ru_utime + r.ru_stime}) + "\n").encode())

    def now() -> tuple:
        r = resource.getrusage(resource.RUSAGE_SELF)
        return time.monotonic(), time.thread_time(), r.ru_utime, r.ru_stime, r.ru_minflt

    def mark(stage: str, **extra) -> None:
        log(stage=stage, pid=os.getpid(), thread=threading.current_thread().name, t0=time.monotonic(), t1=time.monotonic(), **extra)

    def wrap(owner, name: str, stage: str, label=None) -> None:
        fn = getattr(owner, name)

        @functools.wraps(fn)
        def timed(*args, **kwargs):
            a = now()
            try:
                return fn(*args, **kwargs)
            finally:
                b = now()
                log(stage=stage, pid=os.getpid(), thread=threading.current_thread().name, t0=a[0], t1=b[0],
                    cpu=b[1] - a[1], user=b[2] - a[2], sys=b[3] - a[3], faults=b[4] - a[4],
                    label=label(*args, **kwargs) if label else None)  # fmt: skip

        setattr(owner, name, timed)

    def frame_of(*args, **kwargs):
        for a in (*args, *kwargs.values()):
            if isinstance(a, str):
                m = frame_re.search(a)
                if m:
                    return int(m.group(1))
        return None

    mark("interpreter", t_launch=float(os.environ.get(T0_ENV, "nan")))
    import warpcli._fork as fork
    import warpcli.batch as batch
    import warpcli.plan as plan
    import warpcli.cli  # noqa: F401  (the import of the CLI is start-up)

    mark("imported")
    wrap(batch, "map_between", "map")
    wrap(batch, "plan_for", "plan")
    wrap(batch, "_plans_in_child", "build")
    wrap(batch, "read_image", "read", frame_of)
    wrap(batch, "write_like", "write", frame_of)
    wrap(batch, "warp_one", "frame", frame_of)
    wrap(batch, "warp_run", "run here")
    wrap(batch, "_plan_memory", "shared memory")
    wrap(batch, "_run_sizes", "headers")
    wrap(batch, "warp_sequence", "sequence")
    wrap(plan.SamplingPlan, "render", "render")
    wrap(fork, "_respond", "respond")
    wrap(fork, "_dumps", "pickle")
    wrap(fork, "_receive", "receive")
    wrap(fork.Worker, "__init__", "fork")
    wrap(fork.Worker, "submit", "submit")
    wrap(fork.Worker, "result", "wait")
    wrap(fork.Worker, "close", "close")
    from warpcli.maps import registry

    for method in registry.METHODS.values():
        try:
            module = method.load()
        except Exception:
            continue
        if callable(getattr(module, "prepare", None)):
            wrap(module, "prepare", "kernels")
    import atexit

    atexit.register(lambda: mark("exit"))
    from warpcli.cli import run

    sys.argv[0] = "warp"
    try:
        run()
    finally:
        mark("exit")


def _events(path: str) -> list[dict]:
    with open(path) as fh:
        return [json.loads(line) for line in fh if line.strip()]


def report(path: str, t_launch: float, t_end: float, gantt: bool, step: float = 0.05) -> None:
    events = _events(path)
    main = next(e["pid"] for e in events if e["stage"] == "interpreter")
    pids = [main] + sorted({e["pid"] for e in events} - {main})
    total = t_end - t_launch
    print(f"run: {total:.2f} s from launch to exit; the interpreter up at {events[0]['t0'] - t_launch:.3f} s, "
          f"warpcli's CLI imported at {next(e['t0'] for e in events if e['stage'] == 'imported') - t_launch:.3f} s")  # fmt: skip
    # Stages that hold others (sequence, frame, build, respond, run here, wait...) are listed too: the
    # leaves are read, render, write (main) and map, plan, pickle (workers).
    for pid in pids:
        mine = [e for e in events if e["pid"] == pid and "cpu" in e]
        if not mine:
            continue
        who = "main" if pid == main else f"worker {pid}"
        first, last = min(e["t0"] for e in mine) - t_launch, max(e["t1"] for e in mine) - t_launch
        print(f"\n{who}: stages from {first:.3f} s to {last:.3f} s")
        print("| stage | calls | seconds | thread CPU | process user | process system | page faults |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        by = collections.defaultdict(list)
        for e in mine:
            by[e["stage"]].append(e)
        for stage, es in by.items():
            print(f"| {stage} | {len(es)} | {sum(e['t1'] - e['t0'] for e in es):.3f} | {sum(e['cpu'] for e in es):.3f} | "
                  f"{sum(e['user'] for e in es):.3f} | {sum(e['sys'] for e in es):.3f} | {sum(e['faults'] for e in es)} |")  # fmt: skip
    waits = sorted((e for e in events if e["stage"] == "wait"), key=lambda e: e["t0"])
    frames = sorted((e for e in events if e["stage"] == "frame"), key=lambda e: e["t0"])
    builds = sorted((e for e in events if e["stage"] == "build"), key=lambda e: e["t0"])
    if waits and frames:
        print(f"\nmain: first wait for a plan {waits[0]['t0'] - t_launch:.3f}-{waits[0]['t1'] - t_launch:.3f} s; "
              f"waits in all {sum(e['t1'] - e['t0'] for e in waits):.3f} s ({len(waits)}); "
              f"first frame written at {frames[0]['t1'] - t_launch:.3f} s; last frame {frames[-1]['t0'] - t_launch:.3f}-{frames[-1]['t1'] - t_launch:.3f} s")  # fmt: skip
    forks = sorted((e for e in events if e["stage"] == "fork"), key=lambda e: e["t0"])
    if forks:
        print(f"main: the first worker forked at {forks[0]['t0'] - t_launch:.3f} s, after {forks[0]['process']:.3f} s of the main process's CPU "
              f"(launch to the interpreter: {events[0]['t0'] - t_launch:.3f} s more)")  # fmt: skip
    if builds:
        print(f"workers: first build {builds[0]['t0'] - t_launch:.3f}-{builds[0]['t1'] - t_launch:.3f} s, last build ends "
              f"{max(e['t1'] for e in builds) - t_launch:.3f} s; builds {sum(e['t1'] - e['t0'] for e in builds):.3f} s, "
              f"{sum(e['cpu'] for e in builds):.3f} s CPU")  # fmt: skip
    if gantt:
        # One character per step: the leaf stage running then (upper case: main process).
        letters = {"read": "R", "render": "S", "write": "W", "wait": ".", "kernels": "K", "headers": "H", "fork": "F",
                   "map": "m", "plan": "p", "pickle": "c", "respond": "o", "shared memory": "M"}  # fmt: skip
        n = int(total / step) + 1
        print(f"\none character per {step * 1000:.0f} ms from launch ({', '.join(f'{v}={k}' for k, v in letters.items())}, - other work)")
        for pid in pids:
            row = [" "] * n
            mine = [e for e in events if e["pid"] == pid and "cpu" in e]
            for e in sorted(mine, key=lambda e: -(e["t1"] - e["t0"])):  # short stages drawn over long ones
                c = letters.get(e["stage"], "-")
                for k in range(int((e["t0"] - t_launch) / step), min(n, int((e["t1"] - t_launch) / step) + 1)):
                    row[k] = c
            print(f"{'main' if pid == main else pid:>8} |{''.join(row)}|")


def main(argv: list[str] | None = None) -> None:
    if os.environ.get(TRACE_ENV) and argv is None and sys.argv[1:2] == ["--traced"]:
        sys.argv[1:] = sys.argv[2:]
        _install(os.environ[TRACE_ENV])
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gantt", action="store_true")
    parser.add_argument("--shot", choices=("animated",), help="make bench/jobs.py's animated shot and warp it")
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--jobs", default="2")
    parser.add_argument("--keep", metavar="FILE", help="keep the trace's lines in FILE")
    parser.add_argument("warp", nargs="*", help="warp's arguments (after --)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        warp_args = list(args.warp)
        if args.shot:
            sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
            import jobs as bench

            w, h = (int(v) for v in args.size.split("x"))
            bench.write_frames(tmp, args.frames, w, h, "png")
            s, n = min(w, h), args.frames
            src = {"frames": {"1": bench.star(w / 2, h / 2, 0.2 * s, 0.45 * s), str(n): bench.star(w / 2 + 0.04 * s, h / 2, 0.2 * s, 0.45 * s, 0.2)}}
            dst = {"frames": {"1": bench.star(w / 2, h / 2, 0.15 * s, 0.47 * s, 0.3), str(n): bench.star(w / 2, h / 2 + 0.03 * s, 0.15 * s, 0.47 * s, 0.5)}}
            for name, pts in (("src.json", src), ("dst.json", dst)):
                with open(os.path.join(tmp, name), "w") as fh:
                    json.dump(pts, fh)
            os.makedirs(os.path.join(tmp, "out"))
            warp_args = [os.path.join(tmp, "frame.#.png"), os.path.join(tmp, "out", "out.#.png"), "--frames", f"1-{n}",
                         "--src", os.path.join(tmp, "src.json"), "--dst", os.path.join(tmp, "dst.json"), "--jobs", args.jobs, "-q"]  # fmt: skip
        trace = args.keep or os.path.join(tmp, "trace.jsonl")
        if os.path.exists(trace):
            os.unlink(trace)
        t_launch = time.monotonic()
        env = {**os.environ, TRACE_ENV: trace, T0_ENV: repr(t_launch)}
        code = subprocess.run([sys.executable, os.path.abspath(__file__), "--traced", *warp_args], env=env).returncode
        t_end = time.monotonic()
        if code:
            sys.exit(f"warp ended with status {code}")
        report(trace, t_launch, t_end, args.gantt)


if __name__ == "__main__":
    main()
