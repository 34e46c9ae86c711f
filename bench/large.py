"""A warp wider than 32767 px (OpenCV's remap limit): time and peak memory.

    python bench/large.py [--width 40000] [--height 500]

Writes a W x H 8-bit RGB PNG and two 8-vertex polygons spanning it into a
temporary folder, runs the ``warp`` command once under GNU time, and prints
the wall time, peak RSS and the stage timings (-v).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=int, default=40000)
    ap.add_argument("--height", type=int, default=500)
    args = ap.parse_args()
    w, h = args.width, args.height
    with tempfile.TemporaryDirectory() as tmp:
        x = np.arange(w)[None, :]
        y = np.arange(h)[:, None]
        px = np.stack(
            [np.broadcast_to((x * 7) % 256, (h, w)), np.broadcast_to((y * 3) % 256, (h, w)), ((x // 16 + y // 16) % 2) * 255],
            axis=2,
        ).astype(np.uint8)
        import OpenImageIO as oiio

        inp = os.path.join(tmp, "wide.png")
        out = oiio.ImageOutput.create(inp)
        out.open(inp, oiio.ImageSpec(w, h, 3, "uint8"))
        out.write_image(np.ascontiguousarray(px))
        out.close()
        xs = np.linspace(0, w, 4)
        src = [[float(v), 0.0] for v in xs] + [[float(v), float(h)] for v in xs[::-1]]
        dst = [[float(v), 0.15 * h * (i % 2)] for i, v in enumerate(xs)] + [
            [float(v), h - 0.15 * h * (i % 2)] for i, v in enumerate(xs[::-1])
        ]
        for name, pts in (("src.json", src), ("dst.json", dst)):
            with open(os.path.join(tmp, name), "w") as fh:
                json.dump(pts, fh)
        warp = os.path.join(os.path.dirname(sys.executable), "warp")
        cmd = ["/usr/bin/time", "-f", "%e s wall, %M KB peak RSS", warp, inp, os.path.join(tmp, "out.png"),
               "--src", os.path.join(tmp, "src.json"), "--dst", os.path.join(tmp, "dst.json"), "-v"]
        done = subprocess.run(cmd, capture_output=True, text=True)
        print(f"warp of a {w} x {h} RGB 8-bit PNG ({w * h / 1e6:.1f} MP), exit {done.returncode}")
        print(done.stderr.strip())


if __name__ == "__main__":
    main()
