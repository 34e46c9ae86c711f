"""CPU of compiling kernels from an empty cache: BEM's evaluation alone, or a first warp of each method.

    python bench/compile_cold.py evaluate     # numba's compile of bem_evaluate for the suite's types
    python bench/compile_cold.py workload     # BEM, FEM and MFS warps of a sample in process, and a
                                              # refinement of read-only cage triangles

Each run uses a fresh cache directory (``NUMBA_CACHE_DIR``, which `warpcli._native` also uses)
and prints the CPU seconds of the process. Compare two source trees by running this from each
in turns (``PYTHONPATH=TREE``), several times: on a shared machine one run says little.
"""

from __future__ import annotations

import os
import resource
import sys
import tempfile
import time

os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="compile-cold-")
os.environ["WARPCLI_FORK"] = "0"  # everything in this process, counted by RUSAGE_SELF


def evaluate() -> None:
    from numba import types as T

    from warpcli.maps import _bem_kernels

    f8, i8, b1 = T.float64, T.int64, T.boolean

    def a(dtype, ndim):
        return T.Array(dtype, ndim, "C")

    sig = (
        a(f8, 1), a(f8, 1), a(i8, 1), a(i8, 1), a(f8, 1), a(f8, 1), a(f8, 1),
        a(f8, 1), a(f8, 1), a(f8, 1), a(f8, 1), a(f8, 1), a(f8, 1), a(f8, 1), a(f8, 3), a(f8, 3),
        a(i8, 1), a(i8, 1), a(f8, 2), a(f8, 2), a(f8, 3), a(f8, 3), a(f8, 3),
        f8, f8, b1, b1, b1, a(f8, 2), a(f8, 3), a(f8, 4),
        a(f8, 2), a(f8, 2), a(i8, 1), a(f8, 2), a(i8, 1), a(i8, 2), a(f8, 2),
    )  # fmt: skip
    _bem_kernels.bem_evaluate.compile(sig)


def workload() -> None:
    import numpy as np

    from warpcli.cli import main
    from warpcli.volume.tetmesh import refine_surface

    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "sample_images")
    out = tempfile.mkdtemp(prefix="compile-cold-out-")
    for method in ("bem", "fem", "mfs"):
        args = [os.path.join(here, "grid.png"), "--src", os.path.join(here, "grid_L.json"),
                "--dst", os.path.join(here, "grid_hexagon.json"), os.path.join(out, f"{method}.png"),
                "--method", method, "-q"]  # fmt: skip
        assert main(args) == 0, method
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    t = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    t.setflags(write=False)
    refine_surface(v, t, lambda p: np.full(len(p), 0.3))


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "evaluate"
    t0 = time.perf_counter()
    {"evaluate": evaluate, "workload": workload}[what]()
    ru = resource.getrusage(resource.RUSAGE_SELF)
    print(f"{what}: {ru.ru_utime + ru.ru_stime:.2f} s CPU, {time.perf_counter() - t0:.2f} s wall, load {os.getloadavg()[0]:.1f}")
