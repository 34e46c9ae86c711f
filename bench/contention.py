"""What this machine charges for two busy CPUs: the CPU seconds of a fixed piece of work alone on
CPU 0, and with a copy of it on CPU 1 at the same time (medians of N rounds, default 3).

    python bench/contention.py [N]

Three pieces of work: ``alu`` (a Python loop: registers and the first-level cache), ``memory``
(copies of 320 MB arrays: memory bandwidth) and ``cache2M`` (copies of 2 MB arrays: the
second-level cache). On a machine whose CPUs are cores of their own each runs as fast beside the
other as alone (x1.00); on the virtual machine of `bench/results/2026-11-24-shots-3.md` even the
loop slowed by a quarter. Read it on a quiet machine (the load is printed).
"""
import os
import resource
import statistics
import subprocess
import sys

WORK = {
    "alu": "s = 0\nfor i in range(12_000_000): s += i * i",
    "memory": "import numpy as np\na = np.ones(40_000_000)\nb = np.empty_like(a)\nfor _ in range(12): np.copyto(b, a)",
    "cache2M": "import numpy as np\na = np.ones(250_000)\nb = np.empty_like(a)\nfor _ in range(6000): np.copyto(b, a)",
}


def run(code: str, cpus: list[int]) -> float:
    """CPU seconds per process of ``code`` run once on each of ``cpus`` at the same time."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    procs = [subprocess.Popen([sys.executable, "-c", code], preexec_fn=lambda c=c: os.sched_setaffinity(0, {c})) for c in cpus]
    for p in procs:
        p.wait()
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime) / len(cpus)


def main() -> None:
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    cpus = sorted(os.sched_getaffinity(0))[:2]
    if len(cpus) < 2:
        sys.exit("two CPUs are needed")
    for name, code in WORK.items():
        alone, pair = [], []
        for _ in range(rounds):
            alone.append(run(code, cpus[:1]))
            pair.append(run(code, cpus))
        a, b = statistics.median(alone), statistics.median(pair)
        print(f"{name}: CPU alone {a:.2f} s, two at once {b:.2f} s each: x{b / a:.3f}  load {os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
