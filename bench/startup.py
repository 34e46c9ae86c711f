#!/usr/bin/env python
"""What ``warp`` pays before the first pixel, against the floor of any warp.

    python bench/startup.py                      # 1 MP, 7 alternating runs: ~1 minute
    python bench/startup.py --repeat 11 --megapixels 4

Each row is a whole process, the median wall time of ``--repeat`` runs taken in
turns (row 1, row 2, ..., then again), so that a busy machine slows every row
alike; the ``min-max`` column shows how busy it was:

- ``python -c pass``: the interpreter alone;
- ``warp --help`` (the goal: under 0.2 s);
- ``warp``, bad input: a missing polygon file, exit status 2 (under 0.3 s);
- ``warp`` on a 1 x 1 image: the fixed cost of a warp, everything but the work
  that grows with the image;
- the floor: a process that imports numpy and OpenImageIO, reads the image,
  resamples it with a precomputed map (OpenImageIO's bilinear ``st_warp``, the
  map loaded from an ``.npy`` file) and writes it: what any warp must pay at
  this size;
- ``warp`` on the image (the 6-point star pair of ``bench/run.py``), and the
  PWA peer of ``bench/run.py`` on the same files.

warpcli's bytecode is compiled first, as ``pip install`` does (so a shell with
``PYTHONDONTWRITEBYTECODE`` does not make ``warp`` compile its modules on every
run), and every command runs once untimed (the first run on a machine compiles
the kernels). `bench/run.py` prints the same table in its header.
"""

from __future__ import annotations

import argparse
import compileall
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

FLOOR_SCRIPT = r'''
"""The floor of a warp: read, resample with a precomputed map, write (numpy and OpenImageIO only)."""
import sys

import numpy as np
import OpenImageIO as oiio

inp_path, map_path, out_path = sys.argv[1:4]
src = oiio.ImageBuf(inp_path)
xy = np.load(map_path)  # (H, W, 2): source point of each output pixel centre, NaN outside
h, w = xy.shape[:2]
st = np.empty((h, w, 2), dtype=np.float32)  # as an STMap: normalized, -1 outside
st[..., 0] = xy[..., 0] / src.spec().width
st[..., 1] = xy[..., 1] / src.spec().height
st[~np.isfinite(st)] = -1.0
stmap = oiio.ImageBuf(oiio.ImageSpec(w, h, 2, "float"))
stmap.set_pixels(oiio.ROI(), st)
out = oiio.ImageBufAlgo.st_warp(src, stmap, filtername="triangle")  # bilinear, in C++
if not out.write(out_path, "uint8"):
    sys.exit(f"floor: cannot write {out_path}: {out.geterror()}")
'''


def compile_bytecode() -> None:
    """Compile warpcli's modules, as an installation does."""
    import warpcli

    compileall.compile_dir(os.path.dirname(warpcli.__file__), quiet=1)


def prepare(work: str, megapixels: float) -> dict[str, str]:
    """Write the inputs: a 1 x 1 image and polygons, the test image, its star pair, the map, the scripts."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import run as bench  # bench/run.py: the same images and pairs

    from warpcli.pipeline import warp_image

    paths = {k: os.path.join(work, v) for k, v in {
        "one": "one.png", "one_src": "one_src.json", "one_dst": "one_dst.json", "image": "image.png",
        "src": "src.json", "dst": "dst.json", "map": "map.npy", "floor": "floor.py", "peer": "peer.py",
        "missing": "missing.json",
    }.items()}  # fmt: skip
    bench.write_png(paths["one"], np.zeros((1, 1, 3), dtype=np.uint8))
    bench.write_polygon(paths["one_src"], np.array([[0.1, 0.1], [0.9, 0.1], [0.5, 0.9]]))
    bench.write_polygon(paths["one_dst"], np.array([[0.1, 0.1], [0.9, 0.2], [0.4, 0.9]]))
    w, h = bench.image_dims(megapixels)
    img = bench.make_image(w, h)
    bench.write_png(paths["image"], img)
    pair = bench.make_pairs(w, h)[0]
    bench.write_polygon(paths["src"], pair.src)
    bench.write_polygon(paths["dst"], pair.dst)
    np.save(paths["map"], warp_image(img, pair.src, pair.dst).inverse_map.astype(np.float32))
    with open(paths["floor"], "w") as fh:
        fh.write(FLOOR_SCRIPT)
    with open(paths["peer"], "w") as fh:
        fh.write(bench.PEER_SCRIPT)
    return paths


def commands(paths: dict[str, str], warp: str) -> dict[str, tuple[list[str], int]]:
    """Each row's command and the exit status it must end with."""
    py = sys.executable
    out = lambda name: os.path.join(os.path.dirname(paths["one"]), name)  # noqa: E731
    return {
        "python -c pass": ([py, "-c", "pass"], 0),
        "warp --help": ([warp, "--help"], 0),
        "warp, bad input (missing polygon file)": (
            [warp, "-q", paths["one"], "--src", paths["missing"], "--dst", paths["one_dst"], out("never.png")], 2
        ),
        "warp on a 1 x 1 image (fixed cost)": (
            [warp, "-q", paths["one"], "--src", paths["one_src"], "--dst", paths["one_dst"], out("one_out.png")], 0
        ),
        "floor: numpy + OpenImageIO, read, resample with a map, write": (
            [py, paths["floor"], paths["image"], paths["map"], out("floor_out.png")], 0
        ),
        "warp on the image": (
            [warp, "-q", paths["image"], "--src", paths["src"], "--dst", paths["dst"], out("warp_out.png")], 0
        ),
        "PWA peer on the image": (
            [py, paths["peer"], "pwa", paths["image"], paths["src"], paths["dst"], out("pwa_out.png")], 0
        ),
    }


def measure(cmds: dict[str, tuple[list[str], int]], repeat: int, progress=None) -> dict[str, list[float]]:
    """Wall seconds of every command, ``repeat`` times in turns, after one untimed run each."""
    times: dict[str, list[float]] = {label: [] for label in cmds}
    for rep in range(repeat + 1):
        if progress is not None:
            progress(f"start-up run {rep}/{repeat}" + (" (untimed)" if rep == 0 else ""))
        for label, (cmd, status) in cmds.items():
            t0 = time.perf_counter()
            r = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            wall = time.perf_counter() - t0
            if r.returncode != status:
                tail = r.stderr.decode("utf-8", "replace")[-800:]
                raise RuntimeError(f"{label}: exit status {r.returncode}, expected {status}\n{tail}")
            if rep:
                times[label].append(wall)
    return times


def table(times: dict[str, list[float]], megapixels: float, md: bool = False) -> str:
    """The start-up table, with the gaps to the floor and the peer."""
    med = {k: statistics.median(v) for k, v in times.items()}
    floor = med["floor: numpy + OpenImageIO, read, resample with a map, write"]
    pwa = med["PWA peer on the image"]
    rows = []
    for label, xs in times.items():
        name = label.replace("the image", f"the {megapixels:g} MP image")
        m = med[label]
        rows.append([name, f"{m:.3f}", f"{min(xs):.3f}-{max(xs):.3f}", f"{m / floor:.2f}", f"{m / pwa:.2f}"])
    headers = ["process", "median s", "min-max", "/ floor", "/ PWA"]
    runs = len(next(iter(times.values())))
    title = f"Start-up and floor: whole processes, median wall seconds of {runs} alternating runs"
    if md:
        out = [f"### {title}", "", "| " + " | ".join(headers) + " |", "|---|" + "---:|" * (len(headers) - 1)]
        out += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(out) + "\n"
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]

    def line(cells):
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

    rule = "-" * len(line(headers))
    fixed = med["warp on a 1 x 1 image (fixed cost)"]
    note = (
        f"fixed cost {fixed:.3f} s, floor {floor:.3f} s, warp {med['warp on the image']:.3f} s = "
        f"{med['warp on the image'] / pwa:.2f} x PWA"
    )
    return "\n".join([title, rule, line(headers), rule, *(line(r) for r in rows), rule, note]) + "\n"


def run(repeat: int = 7, megapixels: float = 1.0, md: bool = False, progress=None) -> str:
    """Prepare, measure and render the table (for bench/run.py)."""
    warp = os.path.join(os.path.dirname(sys.executable), "warp")
    if not os.access(warp, os.X_OK):
        raise RuntimeError(f"no warp executable next to {sys.executable} (pip install -e .)")
    compile_bytecode()
    with tempfile.TemporaryDirectory(prefix="warpstart-") as work:
        paths = prepare(work, megapixels)
        times = measure(commands(paths, warp), repeat, progress)
    return table(times, megapixels, md)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=7, help="timed runs of each command [7]")
    p.add_argument("--megapixels", type=float, default=1.0, help="size of the test image [1]")
    args = p.parse_args(argv)
    print(run(args.repeat, args.megapixels, progress=lambda m: print(f"[startup] {m}", file=sys.stderr, flush=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
