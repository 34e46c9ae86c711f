#!/usr/bin/env python
"""The FEM map's sparse solve, SuperLU as warpcli calls it against the other direct solvers.

    python bench/solvers.py                       # sizes 1,4,12 MP, medians of 5
    python bench/solvers.py --sizes 1 --repeat 9

For each size, the two systems (K_UU, the cotangent Laplacian's unknown block) of a default
``warp`` of bench/run.py's image and ``star12`` pair are taken from the map being built, then
each is factorized and solved for both coordinates, in this process, in turns:

* ``SuperLU MMD`` (warpcli's call: ``splu(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0,
  SymmetricMode)``);
* ``SuperLU COLAMD`` (scipy's default ordering);
* ``cholespy`` (CHOLMOD's supernodal Cholesky; the matrix is symmetric positive definite once
  negated), when ``cholespy`` is importable (``pip install cholespy``: it is not a dependency).

Issue 24 names the supernodal Cholesky as a route to a faster FEM build; this is its
measurement. Any solver other than warpcli's changes the maps' last bits (the largest difference
to SuperLU's solution is printed) and so output bytes.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import run as bench_run  # noqa: E402  bench/run.py: the image and the pair


def systems(mp: float):
    """The K_UU of both meshes of a default FEM warp at ``mp`` megapixels."""
    os.environ["WARPCLI_FORK"] = "0"  # build in this process, where the solver can be watched
    from warpcli.maps.fem import solve
    from warpcli.pipeline import warp_image

    meshes = []
    init = solve.DirichletSolver.__init__

    def watch(self, mesh, *args, **kwargs):
        meshes.append(mesh)
        init(self, mesh, *args, **kwargs)

    solve.DirichletSolver.__init__ = watch
    try:
        w, h = bench_run.image_dims(mp)
        pair = bench_run.make_pairs(w, h)[0]
        warp_image(bench_run.make_image(w, h), pair.src, pair.dst)
    finally:
        solve.DirichletSolver.__init__ = init
    out = []
    for mesh in meshes:
        fixed = np.zeros(mesh.n_vertices, dtype=bool)
        fixed[mesh.boundary] = True
        unknown = np.flatnonzero(~fixed)
        k = solve.cotan_laplacian(mesh.vertices, mesh.triangles)
        out.append(k[unknown][:, unknown].tocsc())
    return out


def solvers():
    from scipy.sparse.linalg import splu

    found = {
        "SuperLU MMD": lambda a, b: splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                         options={"SymmetricMode": True}).solve(b),  # fmt: skip
        "SuperLU COLAMD": lambda a, b: splu(a).solve(b),
    }
    try:
        import cholespy
    except ImportError:
        return found

    def cholesky(a, b):
        sign = 1.0 if a.diagonal().mean() > 0 else -1.0  # the Laplacian's sign convention
        m = (sign * a).tocsc()
        s = cholespy.CholeskySolverD(m.shape[0], m.indptr.astype(np.int32), m.indices.astype(np.int32), m.data,
                                     cholespy.MatrixType.CSC)  # fmt: skip
        x = np.zeros_like(b)
        s.solve(np.ascontiguousarray(b), x)
        return sign * x

    found["cholespy"] = cholesky
    return found


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1,4,12")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    found = solvers()
    print(f"load at start {os.getloadavg()[0]:.2f}; medians of {args.repeat}, factorize + solve both coordinates")
    print("| size | unknowns | " + " | ".join(found) + " | largest difference to SuperLU MMD |")
    print("|---|---:|" + "---:|" * len(found) + "---:|")
    for mp in (float(s) for s in args.sizes.split(",")):
        for a in systems(mp):
            b = np.random.default_rng(0).random((a.shape[0], 2))
            times = {name: [] for name in found}
            for _ in range(args.repeat):
                for name, f in found.items():  # in turns
                    t = time.perf_counter()
                    f(a, b)
                    times[name].append(time.perf_counter() - t)
            ref = found["SuperLU MMD"](a, b)
            diff = max(float(np.abs(f(a, b) - ref).max()) for f in found.values())
            cells = " | ".join(f"{statistics.median(t) * 1e3:.0f} ms" for t in times.values())
            print(f"| {mp:g} MP | {a.shape[0]} | {cells} | {diff:.1e} |", flush=True)
    print(f"load at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
