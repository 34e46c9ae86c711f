"""The seam of a retouch (--outside input) with and without --feather, and the cost of cutting a ring.

    python bench/seam.py

Part 1: Chelsea's eye widened (sample_images/chelsea_eye*.json) and the same cage
on a smooth ramp, pasted over the input with feathers of 0 to 12 px: the
largest and mean jump between neighbouring pixels across the target's edge
(`warpcli.report.seam.seam_jump`), against the largest and 99th percentile
jump elsewhere, in 8-bit levels (ramp: in ramp steps).

Part 2: `warpcli.polygon.outline.cut_ring` on the eye cage within the image,
the cage's box grown by 20 px, and two cages (both eyes, the second a copy
moved right): faces, points, and the median time of 5 runs (the machine is
shared: times are indicative).
"""

from __future__ import annotations

import os
import time

import numpy as np

from warpcli import warp_image
from warpcli.polygon import read_polygon
from warpcli.polygon.outline import cut_ring, outline_polygon
from warpcli.raster.imageio import read_image
from warpcli.report.seam import seam_jump

HERE = os.path.dirname(os.path.abspath(__file__))
SAMPLES = os.path.join(HERE, "..", "sample_images")


def main() -> None:
    image = read_image(os.path.join(SAMPLES, "chelsea.png")).pixels
    src = read_polygon(os.path.join(SAMPLES, "chelsea_eye.json")).points
    dst = read_polygon(os.path.join(SAMPLES, "chelsea_eye_wide.json")).points
    h, w = image.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    ramp = np.round((x + y) * 255.0 / (w + h)).astype(np.uint8)[:, :, None]  # one level per ~3 px
    print("seam across the target's edge (8-bit levels)")
    print(f"{'image':8} {'feather':>7} {'across max':>10} {'across mean':>11} {'else max':>8} {'else p99':>8}")
    for name, img in (("chelsea", image), ("ramp", ramp)):
        for feather in (0, 2, 4, 8, 12):
            out = warp_image(img, src, dst, outside="input", feather=feather).pixels
            s = seam_jump(out.astype(np.float64), dst)
            print(f"{name:8} {feather:7d} {s.across_max:10.0f} {s.across_mean:11.2f} {s.elsewhere_max:8.0f} "
                  f"{s.elsewhere_p99:8.1f}")  # fmt: skip
    print()
    print("cut_ring: the ring between an outline and the cages")
    print(f"{'case':24} {'faces':>5} {'points':>6} {'median s':>8}")
    twin_src = src + [165.0, 0.0]
    twin_dst = dst + [166.0, 2.0]
    cases = {
        "eye within image": (outline_polygon("image", (w, h), [src, dst]), [src], [dst]),
        "eye within 20 px": (outline_polygon("20", (w, h), [src, dst]), [src], [dst]),
        "two eyes within image": (outline_polygon("image", (w, h), []), [src, twin_src], [dst, twin_dst]),
    }
    for name, (outline, s_cages, d_cages) in cases.items():
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            sv, _, faces = cut_ring(outline, s_cages, d_cages)
            times.append(time.perf_counter() - t0)
        print(f"{name:24} {len(faces):5d} {len(sv):6d} {float(np.median(times)):8.3f}")


if __name__ == "__main__":
    main()
