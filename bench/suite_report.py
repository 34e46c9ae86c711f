"""Tables of one or more runs of bench/suite_cold.sh: the whole run, the workers' start and tail, the compiles.

    python bench/suite_report.py OUT [OUT ...]
"""

from __future__ import annotations

import collections
import json
import os
import re
import sys


def _read(path: str) -> str:
    with open(path) as fh:
        return fh.read()


def _lines(path):
    return [json.loads(line) for line in _read(path).splitlines()] if os.path.exists(path) else []


def run_row(d: str) -> str:
    t0, t1 = float(_read(f"{d}/t0")), float(_read(f"{d}/t1"))
    time_v = _read(f"{d}/time.txt")
    user = float(re.search(r"User time \(seconds\): ([\d.]+)", time_v).group(1))
    system = float(re.search(r"System time \(seconds\): ([\d.]+)", time_v).group(1))
    load = [_read(f"{d}/uptime_{k}").split("load average:")[1].split(",")[0].strip() for k in ("before", "after")]
    tests = _lines(f"{d}/timeline.jsonl")
    ends, firsts = {}, {}
    for r in tests:
        if r["w"] != "main":
            ends[r["w"]] = max(ends.get(r["w"], 0.0), r["t1"] - t0)
            firsts[r["w"]] = min(firsts.get(r["w"], 1e9), r["t0"] - t0)
    summary = _read(f"{d}/out.txt").strip().splitlines()[-1].strip("= ")
    compiles = _lines(f"{d}/compile.jsonl")
    native = sum(r["cpu"] for r in compiles if r["kind"] == "native")
    numba_only = sum(r["cpu"] for r in compiles if r["kind"] == "njit" and r["depth"] == 0 and not r["cached"]
                     and r["name"].startswith("warpcli.") and not any(
                         n["kind"] == "native" and n["pid"] == r["pid"] and n["name"] == r["name"] for n in compiles))
    return (f"| {os.path.basename(d)} | {summary.split(' in ')[0]} | {t1 - t0:.0f} s | {user:.0f} + {system:.0f} = {user + system:.0f} s"
            f" | {max(firsts.values(), default=0):.1f} s | {abs(ends.get('gw0', 0) - ends.get('gw1', 0)):.1f} s"
            f" | {native + numba_only:.1f} s | {load[0]} / {load[1]} |")


def compile_table(d: str) -> None:
    rows = collections.defaultdict(lambda: {"native": 0, "njit": 0, "variants": set(), "njit_variants": set(), "cpu": 0.0, "njit_cpu": 0.0})
    nested = collections.defaultdict(lambda: [0, 0.0, set()])
    for r in _lines(f"{d}/compile.jsonl"):
        name = r["name"].replace("warpcli.", "")
        if r["kind"] == "native":
            x = rows[name]
            x["native"] += 1
            x["variants"].add(r["sig"])
            x["cpu"] += r["cpu"]
        elif r["kind"] == "njit" and not r["cached"] and r["name"].startswith("warpcli."):
            if r["depth"] == 0:
                x = rows[name]
                x["njit"] += 1
                x["njit_cpu"] += r["cpu"]
                x["njit_variants"].add(r["sig"])
            else:
                n = nested[name]
                n[0] += 1
                n[1] += r["cpu"]
                n[2].add(r["sig"])
    print(f"\n{os.path.basename(d)}: kernels compiled (thread CPU s; a native compile includes numba's compile of the kernel)\n")
    print("| kernel | route | compiles | argument-type variants | CPU s |")
    print("|---|---|---|---|---|")
    total = 0.0
    for name, x in sorted(rows.items(), key=lambda kv: -(kv[1]["cpu"] or kv[1]["njit_cpu"])):
        cpu = x["cpu"] if x["native"] else x["njit_cpu"]
        total += cpu
        route = "native" if x["native"] else "numba"
        variants = x["variants"] if x["native"] else x["njit_variants"]
        print(f"| {name} | {route} | {x['native'] or x['njit']} | {len(variants)} | {cpu:.1f} |")
    print(f"| all | | | | {total:.1f} |")
    twice = {k: v for k, v in nested.items() if len(v[2]) > 1}
    if twice:
        print("\nkernels called by kernels, compiled for more than one signature:")
        for name, (n, cpu, sigs) in sorted(twice.items(), key=lambda kv: -kv[1][1]):
            print(f"- {name}: {n} compiles, {len(sigs)} signatures ({sum('Literal' in s for s in sigs)} literal), {cpu:.2f} s")


if __name__ == "__main__":
    print("| run | tests | wall | CPU user + sys | first test at | workers' ends apart | compile CPU | load 1 min before / after |")
    print("|---|---|---|---|---|---|---|---|")
    for d in sys.argv[1:]:
        print(run_row(d))
    for d in sys.argv[1:]:
        compile_table(d)
