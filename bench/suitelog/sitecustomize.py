"""A compile log for every Python process of a test run: ``SUITELOG_COMPILES=path`` (with this folder on PYTHONPATH).

Each process (pytest, its xdist workers, every CLI subprocess) appends one JSON
line per compile: ``kind`` "native" (`warpcli._native._compile`: numba's
compile of the kernel plus the C wrapper and its machine code) or "njit"
(numba's ``Dispatcher.compile`` that made a new overload: ``depth`` 0 for a
kernel called from Python, more for the kernels it calls; ``cached`` when it
came from numba's cache), the function, its argument types, wall and thread
CPU seconds. Nothing is patched unless the variable is set.
"""
import os
import sys

if os.environ.get("SUITELOG_COMPILES"):
    import importlib.abc
    import importlib.util
    import json
    import threading
    import time

    _depth = threading.local()

    def _log(rec):
        rec.update(pid=os.getpid(), worker=os.environ.get("PYTEST_XDIST_WORKER", ""), t=time.time(),
                   argv=" ".join(sys.argv[:2])[-60:])
        with open(os.environ["SUITELOG_COMPILES"], "a") as fh:
            fh.write(json.dumps(rec) + "\n")

    def _patch_native(m):
        orig = m._compile
        def _compile(module, name, variant, symbol, jit):
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                return orig(module, name, variant, symbol, jit)
            finally:
                _log({"kind": "native", "name": f"{module}.{name}", "sig": str(variant),
                      "wall": time.perf_counter() - t0, "cpu": time.thread_time() - c0})
        m._compile = _compile

    def _patch_dispatcher(m):
        D = m.Dispatcher
        orig = D.compile
        def compile(self, sig):
            d = getattr(_depth, "d", 0)
            _depth.d = d + 1
            t0, c0 = time.perf_counter(), time.thread_time()
            hits0 = sum(self._cache_hits.values()); n0 = len(self.overloads)
            try:
                return orig(self, sig)
            finally:
                _depth.d = d
                dt = time.perf_counter() - t0
                if len(self.overloads) != n0:
                    _log({"kind": "njit", "name": f"{self.py_func.__module__}.{self.py_func.__name__}",
                          "sig": str(sig), "wall": dt, "cpu": time.thread_time() - c0, "depth": d,
                          "cached": sum(self._cache_hits.values()) > hits0})
        D.compile = compile

    _HOOKS = {"warpcli._native": _patch_native, "numba.core.dispatcher": _patch_dispatcher}

    class _Finder(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name not in _HOOKS:
                return None
            sys.meta_path.remove(self)
            try:
                spec = importlib.util.find_spec(name)
            finally:
                sys.meta_path.insert(0, self)
            if spec is None:
                return None
            orig = spec.loader.exec_module
            def exec_module(module, orig=orig, hook=_HOOKS[name]):
                orig(module)
                hook(module)
            spec.loader.exec_module = exec_module
            return spec

    sys.meta_path.insert(0, _Finder())
