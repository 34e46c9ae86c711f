#!/usr/bin/env python
"""A warp of an image larger than memory: time and peak RSS against a 12 MP warp.

    python bench/gigapixel.py                        # 40000 x 25000 (1 GP), ~10 min
    python bench/gigapixel.py --width 10000 --height 6250 --repeat 3

Writes a W x H 8-bit RGB tiled TIFF (256 x 256 tiles, uncompressed, made
strip by strip so the benchmark itself stays small) and a 12-vertex polygon
pair covering most of it (an ellipse onto a star), then runs whole ``warp``
processes under GNU time:

- the 12 MP row: the same pair scaled to 4382 x 2739, warped in memory and
  with ``--tiled`` (the baseline the per-pixel cost is compared with);
- the big row: ``warp --tiled`` (a 1-gigapixel image would also switch to
  strips by itself on a machine where it does not fit).

Each row gives the median wall time of ``--repeat`` runs, the peak RSS, and
the nanoseconds per output pixel; the ratio column divides the per-pixel cost
by the 12 MP in-memory warp's. The targets (issue 13): at most 4 GB peak RSS
at 1 GP, and a time linear in the pixel count.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile

import numpy as np


def make_image(path: str, width: int, height: int) -> None:
    """A smooth colour ramp with a checkerboard, as a tiled TIFF written 256 rows at a time."""
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(path)
    spec = oiio.ImageSpec(width, height, 3, "uint8")
    spec.tile_width = spec.tile_height = 256
    spec.attribute("compression", "none")
    if not out.open(path, spec):
        raise SystemExit(out.geterror())
    x = np.arange(width)
    for y0 in range(0, height, 256):
        y = np.arange(y0, min(height, y0 + 256))[:, None]
        strip = np.empty((len(y), width, 3), dtype=np.uint8)
        strip[:, :, 0] = (x * 255 // max(width - 1, 1))[None, :]
        strip[:, :, 1] = (y * 255 // max(height - 1, 1))
        strip[:, :, 2] = ((x[None, :] // 64 + y // 64) % 2) * 255
        if not out.write_tiles(0, width, y0, y0 + len(y), 0, 1, strip):
            raise SystemExit(out.geterror())
    if not out.close():
        raise SystemExit(out.geterror())


def polygons(width: int, height: int) -> tuple[list, list]:
    """An ellipse of 12 vertices inset 2 % from the border, and a star: every other vertex 15 % inwards."""
    cx, cy = width / 2, height / 2
    rx, ry = 0.48 * width, 0.48 * height
    src, dst = [], []
    for k in range(12):
        a = 2 * math.pi * k / 12
        src.append([cx + rx * math.cos(a), cy + ry * math.sin(a)])
        s = 0.85 if k % 2 else 1.0
        dst.append([cx + s * rx * math.cos(a + 0.05), cy + s * ry * math.sin(a + 0.05)])
    return src, dst


def run(cmd: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one process, from GNU time."""
    done = subprocess.run(["/usr/bin/time", "-f", "%e %M", *cmd], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}): {done.stderr.strip()}")
    wall, kb = done.stderr.strip().splitlines()[-1].split()
    return float(wall), int(kb) / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--width", type=int, default=40000)
    ap.add_argument("--height", type=int, default=25000)
    ap.add_argument("--repeat", type=int, default=1, help="runs of the big row (the 12 MP rows run 3 times)")
    ap.add_argument("--dir", help="work folder (default: a temporary one, removed at the end)")
    args = ap.parse_args()
    warp = os.path.join(os.path.dirname(sys.executable), "warp")
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        rows = []
        for label, (w, h), modes, repeat in (
            ("12 MP", (4382, 2739), ("in memory", "--tiled"), 3),
            (f"{w_h(args)}", (args.width, args.height), ("--tiled",), args.repeat),
        ):
            image = os.path.join(tmp, f"in_{w}x{h}.tif")
            print(f"[gigapixel] writing a {w} x {h} tiled TIFF", file=sys.stderr, flush=True)
            make_image(image, w, h)
            src, dst = polygons(w, h)
            a, b = os.path.join(tmp, f"a_{w}.json"), os.path.join(tmp, f"b_{w}.json")
            for path, pts in ((a, src), (b, dst)):
                with open(path, "w") as fh:
                    json.dump(pts, fh)
            out = os.path.join(tmp, f"out_{w}x{h}.tif")
            for mode in modes:
                cmd = [warp, image, "--src", a, "--dst", b, out, "-q"] + ([mode] if mode.startswith("--") else [])
                times, peaks = [], []
                for k in range(repeat):
                    print(f"[gigapixel] {label} {mode} run {k + 1}/{repeat}", file=sys.stderr, flush=True)
                    t, m = run(cmd)
                    times.append(t)
                    peaks.append(m)
                    os.unlink(out)
                rows.append((label, mode, w * h, statistics.median(times), max(peaks)))
            os.unlink(image)
    base = rows[0][3] / rows[0][2]
    print("warp of an 8-bit RGB tiled TIFF, 12-vertex ellipse -> star covering most of it; medians, peak RSS max")
    print(f"{'image':<22} {'mode':<10} {'MP':>8} {'wall s':>9} {'peak RSS MB':>12} {'ns/pixel':>9} {'/ 12 MP':>8}")
    for label, mode, n, t, m in rows:
        print(f"{label:<22} {mode:<10} {n / 1e6:>8.1f} {t:>9.2f} {m:>12.0f} {t / n * 1e9:>9.1f} {t / n / base:>8.2f}")


def w_h(args) -> str:
    return f"{args.width} x {args.height}"


if __name__ == "__main__":
    main()
