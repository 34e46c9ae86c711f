"""Rewrite the stored outputs in this folder (what this version of warpcli writes) from their committed inputs.

    python tests/golden/rewrite_stored.py

These images are warpcli's own output, so they record change, not correctness
(tests/test_output_stability.py compares against them; tests/test_golden.py
checks pixels against independent computations). Run it only when a change of
output is intended (say why in the commit), and look at the new images before
committing them. The inputs are drawn here (grid.png, 128x128, the sample grid
pattern at a quarter of its size) and the polygons are written here.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "sample_images"))

from make_samples import grid_image, write_png  # noqa: E402

#: name -> (src polygon, dst polygon, extra CLI options)
CASES = {
    "L_to_hexagon": (
        [[10.5, 10.5], [75.5, 10.5], [75.5, 65.5], [117.5, 65.5], [117.5, 117.5], [10.5, 117.5]],
        [[round(64 + 57 * math.cos(-2 * math.pi / 3 + 2 * math.pi * k / 6), 3), round(64 + 57 * math.sin(-2 * math.pi / 3 + 2 * math.pi * k / 6), 3)] for k in range(6)],
        ["--interp", "linear"],
    ),
    "square_to_star": (
        [[8.0, 8.0], [64.0, 4.0], [120.0, 8.0], [124.0, 64.0], [120.0, 120.0], [64.0, 124.0], [8.0, 120.0], [4.0, 64.0]],
        [[round(64 + (60 if k % 2 == 0 else 26) * math.cos(-3 * math.pi / 4 + math.pi * k / 4), 3), round(64 + (60 if k % 2 == 0 else 26) * math.sin(-3 * math.pi / 4 + math.pi * k / 4), 3)] for k in range(8)],
        ["--interp", "cubic", "--background", "1,1,1"],
    ),
}


def write_inputs(folder: str) -> None:
    """Write grid.png and every case's polygons into ``folder``."""

    px = grid_image(128, 8)
    out = os.path.join(folder, "grid.png")
    write_png(out, px)
    for name, (src, dst, _) in CASES.items():
        for suffix, pts in (("src", src), ("dst", dst)):
            with open(os.path.join(folder, f"{name}.{suffix}.json"), "w") as fh:
                json.dump(pts, fh)


def warp_command(folder: str, name: str, output: str) -> list[str]:
    opts = CASES[name][2]
    return [
        sys.executable, "-m", "warpcli", os.path.join(folder, "grid.png"),
        "--src", os.path.join(folder, f"{name}.src.json"),
        "--dst", os.path.join(folder, f"{name}.dst.json"),
        *opts, "-q", output,
    ]


def main() -> None:
    write_inputs(HERE)
    for name in CASES:
        subprocess.run(warp_command(HERE, name, os.path.join(HERE, f"{name}.png")), check=True)
        print("wrote", name)


if __name__ == "__main__":
    main()
