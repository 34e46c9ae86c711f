#!/usr/bin/env python
"""``warp`` (FEM, MFS, BEM) against its peers and an I/O floor, whole processes, per image size (issue 24).

    python bench/peers.py                            # 1, 4 and 12 MP, 3 runs each: ~10 minutes
    python bench/peers.py --sizes 1 --repeat 5       # 1 MP only
    python bench/peers.py --out bench/results/$(date +%F)-peers.md

Needs the ``bench`` extra (``pip install -e .[bench]``: scikit-image, opencv-contrib-python-headless;
the plain opencv-python-headless wheels have no thin-plate spline).

Every contender runs as its own process on the same files, in turns (one run of each, then
the next round), after one untimed round; the table shows medians of ``--repeat`` rounds,
each contender's ratio to the floor, and peak RSS (GNU ``/usr/bin/time -f %M``, or
``os.wait4`` in a launcher: see bench/run.py's ``Runner``). The inputs are bench/run.py's: an
8-bit RGB PNG of 5:4 aspect and its ``star12`` pair (a 6-point star onto a thinner, rotated
one). Contenders:

* ``warp fem`` / ``warp mfs`` / ``warp bem``: ``python -m warpcli -q IN --src A --dst B OUT
  [--method M]``, default options otherwise (this checkout's warpcli, bytecode compiled);
* ``skimage PAT``: scikit-image's ``PiecewiseAffineTransform`` estimated from the polygon
  vertices (target -> source), then ``skimage.transform.warp(order=1)``;
* ``skimage TPS``: scikit-image's ``ThinPlateSplineTransform`` on the same vertices, then
  ``warp(order=1)``;
* ``OpenCV TPS``: ``cv2.createThinPlateSplineShapeTransformer()`` on the same vertices and
  its ``warpImage`` (bilinear): a thin-plate spline folds and does not take edges onto
  edges, so this is a speed reference, not an equivalent;
* ``before fem`` (with ``--before DIR``), and ``before mfs`` / ``before bem`` where ``warp
  mfs`` / ``warp bem`` run: ``warp`` from another checkout (say the commit
  before issue 24, exported with ``git archive``), its defaults, in the same rounds;
* ``floor``: a process that imports numpy, OpenImageIO and cv2, reads the PNG, remaps it by
  ``cv2.remap`` (bilinear) with a map given as an ``.npy`` file (warp's own inverse map at
  this size, float32), and writes it: what any warp of this image must pay.

Then, in this process, **the editor's map rebuild** (``warp edit``'s preview, issue 22):
`warpcli.edit.preview.PreviewMapper.build` at the preview density
(`warpcli.edit.preview.with_preview_density`) for the same 12-vertex pair, per size: a
full rebuild (both maps, a new mapper) and a drag (one target vertex moved: only the
target's map is rebuilt), medians of ``--editor-repeat`` after one warm-up, for the
methods of ``--editor-methods`` (FEM by default; issue 24's goal: at most 50 ms).

Every peer and the floor read and write with OpenImageIO, the library ``warp`` uses, and
write PNG with warp's settings (``warpcli.raster.dtypes.PNG_COMPRESSION``, OpenImageIO's
``png:compressionLevel``, libpng's default adaptive filters), so the ratios compare the
warps and not PNG encoders. ``--compression N`` runs every contender at level N instead.
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, REPO)
import run as bench_run  # noqa: E402  bench/run.py: the images, the pairs, the Runner
import startup  # noqa: E402  bench/startup.py: compile_bytecode

PEER_SCRIPT = r'''
"""Peers of `warp` for bench/peers.py.

    python peer.py KIND LEVEL IN.png SRC.json DST.json OUT.png [MAP.npy]

KIND: pat, tps (scikit-image), cvtps (OpenCV), floor (cv2.remap with MAP.npy). Reads and
writes 8-bit PNG with OpenImageIO at png:compressionLevel LEVEL.
"""
import json
import sys

import numpy as np
import OpenImageIO as oiio

kind, level, inp, src_path, dst_path, out_path = sys.argv[1:7]


def polygon(path):
    with open(path) as fh:
        return np.asarray(json.load(fh), dtype=np.float64)


src = inp_in = None
ii = oiio.ImageInput.open(inp)
if ii is None:
    sys.exit(f"peer: cannot read {inp}: {oiio.geterror()}")
img = np.asarray(ii.read_image(oiio.UINT8))
ii.close()
h, w, c = img.shape
if kind == "floor":
    import cv2

    m = np.load(sys.argv[7])
    # warp's map holds continuous coordinates (pixel i centred at i + 0.5); remap's, indices.
    mx = np.ascontiguousarray(m[..., 0]) - np.float32(0.5)
    my = np.ascontiguousarray(m[..., 1]) - np.float32(0.5)
    out = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
elif kind == "cvtps":
    import cv2

    s = polygon(src_path).astype(np.float32).reshape(1, -1, 2)
    d = polygon(dst_path).astype(np.float32).reshape(1, -1, 2)
    tps = cv2.createThinPlateSplineShapeTransformer()
    matches = [cv2.DMatch(i, i, 0) for i in range(s.shape[1])]
    # warpImage pulls back through the transform estimated from the second shape to the first.
    tps.estimateTransformation(d, s, matches)
    out = tps.warpImage(img, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
else:
    from skimage.transform import PiecewiseAffineTransform, ThinPlateSplineTransform, warp

    s, d = polygon(src_path), polygon(dst_path)
    t = PiecewiseAffineTransform() if kind == "pat" else ThinPlateSplineTransform()
    if not t.estimate(d, s):  # skimage's warp takes the output-to-input map
        sys.exit("peer: estimate failed")
    out = warp(img, t, order=1, preserve_range=True).round().astype(np.uint8)
o = oiio.ImageOutput.create(out_path)
spec = oiio.ImageSpec(w, h, c, "uint8")
spec.attribute("png:compressionLevel", int(level))
if o is None or not o.open(out_path, spec) or not o.write_image(np.ascontiguousarray(out)):
    sys.exit(f"peer: cannot write {out_path}: {oiio.geterror()}")
o.close()
'''

CONTENDERS = ("warp fem", "warp mfs", "warp bem", "skimage PAT", "skimage TPS", "OpenCV TPS", "floor", "before fem",
              "before mfs", "before bem")
PEER_KIND = {"skimage PAT": "pat", "skimage TPS": "tps", "OpenCV TPS": "cvtps", "floor": "floor"}


def progress(msg: str) -> None:
    print(f"[peers {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="1,4,12", help="megapixels, comma-separated (default 1,4,12)")
    p.add_argument("--repeat", type=int, default=3, help="timed rounds (medians; default 3)")
    p.add_argument("--skip", default="", help="contenders to leave out, comma-separated (e.g. 'warp bem')")
    p.add_argument("--skip-above", default="warp bem=4,OpenCV TPS=4,skimage TPS=4",
                   help="contender=MP: leave it out above that size (default: BEM, both TPS above 4 MP)")
    p.add_argument("--compression", type=int, default=None,
                   help="PNG compression level for every contender (default: warp's default)")
    p.add_argument("--editor-methods", default="fem", help="methods of the editor rebuild table ('' for none)")
    p.add_argument("--editor-repeat", type=int, default=9, help="editor rebuilds per measurement (medians)")
    p.add_argument("--before", metavar="DIR", help="also run `warp` (FEM, and MFS and BEM where this checkout's "
                   "run) from the checkout in DIR, its defaults, as 'before fem' (mfs, bem) in the same rounds")
    p.add_argument("--ratio-to", default="floor", metavar="NAME",
                   help="the contender the ratios in brackets divide by (default: floor; e.g. 'skimage PAT')")
    p.add_argument("--keep", metavar="DIR", help="keep the inputs and outputs in DIR")
    p.add_argument("--out", metavar="FILE", help="also write the table as markdown to FILE")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    # The runs change directory (below): paths given relative to the caller's are resolved now,
    # and an --out that cannot be written is said now, not after ten minutes of runs.
    args.out = os.path.abspath(args.out) if args.out else None
    args.before = os.path.abspath(args.before) if args.before else None
    if args.out and not os.access(os.path.dirname(args.out), os.W_OK):
        sys.exit(f"peers: cannot write {args.out}: no such directory, or not writable")
    startup.compile_bytecode()
    from warpcli.pipeline import warp_image
    from warpcli.raster import dtypes

    # Before issue 24 warp wrote OpenImageIO's default, zlib level 6.
    level = getattr(dtypes, "PNG_COMPRESSION", 6) if args.compression is None else args.compression
    sizes = [float(s) for s in args.sizes.split(",") if s.strip()]
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    above = {}
    for item in (x for x in args.skip_above.split(",") if x.strip()):
        name, _, mp = item.rpartition("=")
        above[name.strip()] = float(mp)
    tmp = None if args.keep else tempfile.TemporaryDirectory(prefix="warppeers-")
    work = os.path.abspath(args.keep) if args.keep else tmp.name
    os.makedirs(work, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=REPO + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # Children run in the scratch directory: `python -m warpcli` puts its working
    # directory first on sys.path, which would shadow PYTHONPATH's checkout.
    os.chdir(work)
    runner = bench_run.Runner(work)
    before_env = None
    if args.before:
        before = os.path.abspath(args.before)
        before_env = dict(os.environ, PYTHONPATH=before + os.pathsep + os.environ.get("PYTHONPATH", ""))
        subprocess.run([sys.executable, "-m", "compileall", "-q", os.path.join(before, "warpcli")], check=False)
    for where, e in ((REPO, env), (args.before, before_env)):
        if e is not None:
            found = subprocess.run([sys.executable, "-c", "import warpcli; print(warpcli.__file__)"], env=e,
                                   capture_output=True, text=True).stdout.strip()
            if not found.startswith(os.path.abspath(where) + os.sep):
                sys.exit(f"peers: the children would import warpcli from {found}, not from {where}")
    peer = os.path.join(work, "peer.py")
    with open(peer, "w") as fh:
        fh.write(PEER_SCRIPT)
    head = [
        f"command: {shlex.join(['python', 'bench/peers.py', *(sys.argv[1:] if argv is None else argv)])}",
        f"machine: {os.cpu_count()} cores ({platform.processor() or platform.machine()}), "
        f"load at start {' '.join(f'{x:.2f}' for x in os.getloadavg())}; python {platform.python_version()}; "
        f"git {git_revision()}",
        f"PNG: OpenImageIO png:compressionLevel {level}, libpng's default filters, for every contender; "
        f"peak RSS by {runner.method}",
    ]
    rows = []
    loads = []  # the 1-minute load average at the start of every timed round
    for mp in sizes:
        w, h = bench_run.image_dims(mp)
        progress(f"{mp:g} MP ({w}x{h}): inputs")
        base = os.path.join(work, f"{mp:g}mp")
        img = bench_run.make_image(w, h)
        bench_run.write_png(base + ".png", img)
        pair = bench_run.make_pairs(w, h)[0]
        src, dst = base + "_src.json", base + "_dst.json"
        bench_run.write_polygon(src, pair.src)
        bench_run.write_polygon(dst, pair.dst)
        np.save(base + "_map.npy", warp_image(img, pair.src, pair.dst).inverse_map.astype(np.float32))
        cmds = {}
        for name in CONTENDERS:
            before = name.startswith("before")
            limit = above.get(name, above.get(name.replace("before", "warp"), float("inf")))
            if name in skip or mp > limit or (before and not args.before):
                continue
            if before and name != "before fem" and name.replace("before", "warp") in skip:
                continue  # the other checkout's MFS or BEM only beside this one's
            out = f"{base}_{name.replace(' ', '_')}.png"
            if name == "before fem":
                cmd = [sys.executable, "-m", "warpcli", "-q", base + ".png", "--src", src, "--dst", dst, out]
            elif before:
                cmd = [sys.executable, "-m", "warpcli", "-q", base + ".png", "--src", src, "--dst", dst, out,
                       "--method", name.split()[1]]
            elif name.startswith("warp"):
                cmd = [sys.executable, "-m", "warpcli", "-q", base + ".png", "--src", src, "--dst", dst, out,
                       "--method", name.split()[1]]
                if args.compression is not None:
                    cmd += ["--compression", str(level)]
            else:
                cmd = [sys.executable, peer, PEER_KIND[name], str(level), base + ".png", src, dst, out, base + "_map.npy"]
            cmds[name] = cmd
        res = {name: ([], []) for name in cmds}
        for rnd in range(args.repeat + 1):
            if rnd:
                loads.append(os.getloadavg()[0])
            for name, cmd in cmds.items():
                progress(f"{mp:g} MP round {rnd}/{args.repeat}: {name} (load {os.getloadavg()[0]:.2f})")
                wall, rss = run_child(runner, cmd, before_env if name.startswith("before") else env)
                if rnd:  # round 0 warms the page cache and any kernel cache
                    res[name][0].append(wall)
                    res[name][1].append(rss)
        rows.append((mp, w, h, res))
        print(table(rows, md=False, ref=args.ratio_to), flush=True)
    text = "\n".join(head) + "\n\n" + table(rows, md=True, ref=args.ratio_to) + "\n" + footer(rows, args.ratio_to) + "\n"
    if loads:
        text += f"1-minute load at the start of each timed round: {' '.join(f'{x:.2f}' for x in loads)}\n"
    methods = [m.strip() for m in args.editor_methods.split(",") if m.strip()]
    if methods:
        progress("editor rebuilds, in-process")
        text += "\n" + editor_table(sizes, methods, args.editor_repeat) + "\n"
    text += f"load at end {' '.join(f'{x:.2f}' for x in os.getloadavg())}\n"
    print("\n" + text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text)
    if tmp is not None:
        tmp.cleanup()
    return 0


def editor_table(sizes, methods, repeat: int) -> str:
    """``warp edit``'s map rebuild at preview density, in-process: full and drag, medians in ms."""
    from warpcli.edit.preview import PreviewMapper, with_preview_density
    from warpcli.options import MapOptions
    from warpcli.polygon import Polygon

    lines = [
        f"Editor: map rebuild at preview density, in-process, median of {repeat} (min-max), ms; "
        f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}",
        "",
        "| size | method | triangles (target) | full rebuild | drag (target only) |",
        "|---|---|---:|---:|---:|",
    ]
    for mp in sizes:
        w, h = bench_run.image_dims(mp)
        pair = bench_run.make_pairs(w, h)[0]
        src, dst = Polygon(pair.src), Polygon(pair.dst)
        region = (0.0, 0.0, float(w), float(h))
        for method in methods:
            opts = with_preview_density(MapOptions(method=method), src, dst)
            PreviewMapper().build(src, dst, opts, region)  # warm-up: kernels, caches
            full, drag = [], []
            for k in range(repeat):
                moved = pair.dst.copy()
                moved[len(moved) // 2] += (1.0 + 0.25 * k, 0.5)
                mapper = PreviewMapper()
                t0 = time.perf_counter()
                mesh = mapper.build(src, dst, opts, region)
                t1 = time.perf_counter()
                mapper.build(src, Polygon(moved), opts, region)
                t2 = time.perf_counter()
                full.append(1e3 * (t1 - t0))
                drag.append(1e3 * (t2 - t1))
            cell = lambda xs: f"{statistics.median(xs):.1f} ({min(xs):.1f}-{max(xs):.1f})"  # noqa: E731
            lines.append(f"| {mp:g} MP | {method} | {len(mesh.triangles):,} | {cell(full)} | {cell(drag)} |")
    return "\n".join(lines) + "\n"


def git_revision() -> str:
    r = subprocess.run(["git", "-C", REPO, "describe", "--always", "--dirty"], capture_output=True, text=True)
    return r.stdout.strip() or "?"


def run_child(runner, cmd, env):
    old = dict(os.environ)
    os.environ.clear()
    os.environ.update(env)
    try:
        return runner.run(cmd)
    finally:
        os.environ.clear()
        os.environ.update(old)


def table(rows, md: bool, ref: str = "floor") -> str:
    names = [n for n in CONTENDERS if any(n in r[3] for r in rows)]
    head = ["size"] + names
    lines = []
    for mp, w, h, res in rows:
        floor = statistics.median(res[ref][0]) if ref in res else None
        cells = [f"{mp:g} MP"]
        for n in names:
            if n not in res:
                cells.append("")
                continue
            t = statistics.median(res[n][0])
            ratio = f" (x{t / floor:.2f})" if floor and n != ref else ""
            cells.append(f"{t:.2f} s{ratio}")
        lines.append(cells)
        cells = ["  peak RSS"]
        for n in names:
            cells.append(f"{statistics.median(res[n][1]) / 1024:.0f} MB" if n in res else "")
        lines.append(cells)
    if md:
        out = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * len(names)]
        out += ["| " + " | ".join(c) + " |" for c in lines]
        return "\n".join(out) + "\n"
    widths = [max(len(x[i]) for x in [head] + lines) for i in range(len(head))]
    return "\n".join("  ".join(c.ljust(wd) for c, wd in zip(r, widths)) for r in [head] + lines) + "\n"


def footer(rows, ref: str = "floor") -> str:
    lines = ["Spread (min-max of the timed rounds):"]
    for mp, w, h, res in rows:
        spread = ", ".join(f"{n} {min(t):.2f}-{max(t):.2f}" for n, (t, _) in res.items())
        lines.append(f"- {mp:g} MP ({w}x{h}): {spread}")
    for mp, w, h, res in rows:
        if ref in res and len(res) > 1:
            # each round runs every contender once, one after the other: the ratio within a round
            # is less disturbed by a burst of load than the ratio of medians
            per = ", ".join(f"{n} x{statistics.median(a / b for a, b in zip(t, res[ref][0])):.2f}"
                            for n, (t, _) in res.items() if n != ref)
            lines.append(f"- {mp:g} MP, median of the rounds' ratios to {ref}: {per}")
    lines.append(f"Ratios in brackets: to the {ref} measured in the same rounds.")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
