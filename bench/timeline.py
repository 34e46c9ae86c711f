#!/usr/bin/env python
"""Timeline of one ``warp`` run: which stage runs when, on which thread and process (issue 24).

    LAUNCH_T=$(date +%s.%N) python bench/timeline.py LOG -- -q IN.png --src A.json --dst B.json OUT.png
    sort -t$'\t' -k5 -n LOG | column -t -s$'\t'

Runs ``python -m warpcli`` with its arguments in this process, appending one line per event
to LOG: pid, thread, kind, name, start and end in ms since LAUNCH_T (the shell's clock
before the interpreter started; now if unset) and the process's CPU ms so far. Events:
imports taking over 3 ms (nesting depth in the kind: import0 is top level) and calls of
the stages wrapped below (`WRAP`). Forked children write to the same file (appends of one
line are atomic), so both maps' builds show beside the parent's work. The wrappers add a
few microseconds per call; the import hook a little more per import.
"""
import functools
import importlib.abc
import importlib.machinery
import os
import sys
import threading
import time

T0 = float(os.environ.get("LAUNCH_T", time.time()))
LOG = sys.argv[1]
fd = os.open(LOG, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
depth = threading.local()


def emit(kind, name, t0, t1):
    os.write(fd, f"{os.getpid()}\t{threading.current_thread().name}\t{kind}\t{name}\t{(t0 - T0) * 1e3:.1f}\t{(t1 - T0) * 1e3:.1f}\t{time.process_time()*1e3:.0f}\n".encode())


emit("start", "python", T0, time.time())

WRAP = {
    "warpcli.raster.imageio": ["read_image", "read_header", "_write", "write_image"],
    "warpcli.maps.fem.mesh": ["mesh_polygon"],
    "warpcli.maps.fem.solve": ["DirichletSolver.__init__", "DirichletSolver.solve"],
    "warpcli.maps.fem": ["FEMMap.precompute", "prepare", "build", "_Forked.result", "_Forked.__init__", "repaired"],
    "warpcli.maps.compose": ["BijectiveMap.check_bijective", "build_map", "theta_for", "BijectiveMap.pull_back"],
    "warpcli.plan": ["plan_for", "SamplingPlan.render", "SamplingPlan.from_map", "_coverage"],
    "warpcli.pipeline": ["warp_file", "write_like", "_warp", "_RowsMade._make"],
    "warpcli._native": [],
    "warpcli._fork": ["_respond", "_receive", "Forked._reap"],
    "warpcli.maps.fem.locate": [],
    "warpcli.maps.fem.sparse": ["splu", "load_superlu", "cotan_stiffness"],
    "warpcli.cli.warp": [],
    "warpcli.outputs": ["PendingOutputs.__exit__"],
}


def wrap(mod, dotted):
    owner = mod
    parts = dotted.split(".")
    for p in parts[:-1]:
        owner = getattr(owner, p)
    fn = getattr(owner, parts[-1])
    label = mod.__name__.split(".")[-1] + "." + dotted

    @functools.wraps(fn)
    def w(*a, **k):
        t0 = time.time()
        try:
            return fn(*a, **k)
        finally:
            emit("call", label, t0, time.time())

    setattr(owner, parts[-1], w)


class Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if getattr(depth, "busy", False):
            return None
        depth.busy = True
        try:
            spec = importlib.machinery.PathFinder.find_spec(name, path, target)
            if spec is None:
                for f in sys.meta_path:
                    if f is self or not hasattr(f, "find_spec"):
                        continue
                    spec = f.find_spec(name, path, target)
                    if spec is not None:
                        break
        finally:
            depth.busy = False
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        loader = spec.loader
        orig = loader.exec_module

        def exec_module(module, orig=orig):
            d = getattr(depth, "d", 0)
            depth.d = d + 1
            t0 = time.time()
            try:
                orig(module)
            finally:
                depth.d = d
                t1 = time.time()
                if t1 - t0 > 0.003 and d < 3:
                    emit(f"import{d}", name, t0, t1)
            if name in WRAP:
                for dotted in WRAP[name]:
                    try:
                        wrap(module, dotted)
                    except AttributeError:  # renamed: logged, the run goes on
                        emit("wraperr", f"{name}.{dotted}", t0, t0)

        try:
            loader.exec_module = exec_module
        except AttributeError:  # a loader that takes no attributes: its module is not timed
            pass
        return spec


sys.meta_path.insert(0, Finder())
sys.argv = [sys.argv[0]] + sys.argv[3:]
import runpy

try:
    runpy.run_module("warpcli", run_name="__main__", alter_sys=True)
finally:
    emit("end", "main", time.time(), time.time())
