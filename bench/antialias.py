"""Antialiasing where the map shrinks: a fine checkerboard squeezed into a third of its size.

    python bench/antialias.py

Compares warpcli's output, with and without antialiasing, against a 4x
supersampled reference (the same warp rendered at 4x the resolution with no
filtering, then averaged over 4x4 blocks), over the pixels inside the target
polygon away from its edge. Prints RMSE and the largest error, in 8-bit levels.
"""

from __future__ import annotations

import math
import time

import numpy as np

from warpcli import warp_image
from warpcli.raster.resample import edge_coverage


def checkerboard(size: int, square: int) -> np.ndarray:
    r, c = np.mgrid[0:size, 0:size]
    return (((r // square) + (c // square)) % 2 * 255).astype(np.float32)[:, :, None]


def hexagon(cx: float, cy: float, radius: float, phase: float) -> np.ndarray:
    a = phase + 2 * math.pi * np.arange(6) / 6
    return np.stack([cx + radius * np.cos(a), cy + radius * np.sin(a)], axis=1)


def measure(size: int = 300, square: int = 3, shrink: float = 3.0) -> dict:
    img = checkerboard(size, square)
    src = hexagon(size / 2, size / 2, 0.47 * size, 0.0)
    dst = hexagon(size / 2, size / 2, 0.47 * size / shrink, 0.2)
    t0 = time.perf_counter()
    plain = warp_image(img, src, dst, antialias=False).pixels[:, :, 0].astype(np.float64)
    t1 = time.perf_counter()
    smooth = warp_image(img, src, dst, antialias=True).pixels[:, :, 0].astype(np.float64)
    t2 = time.perf_counter()
    big = warp_image(img, src, dst * 4, size=(4 * size, 4 * size), antialias=False).pixels[:, :, 0]
    reference = big.astype(np.float64).reshape(size, 4, size, 4).mean(axis=(1, 3))
    centre_in = np.isfinite(warp_image(img, src, dst, antialias=False).inverse_map[..., 0])
    inside = centre_in.ravel()
    inside[edge_coverage(dst, centre_in).pixels] = False
    inside = inside.reshape(size, size)

    def errors(x):
        d = (x - reference)[inside]
        return float(np.sqrt((d * d).mean())), float(np.abs(d).max())

    return {
        "pixels": int(inside.sum()),
        "plain": errors(plain),
        "antialiased": errors(smooth),
        "seconds": (t1 - t0, t2 - t1),
    }


def main() -> None:
    r = measure()
    print("checkerboard 300 px, 3 px squares, into a hexagon 1/3 the size (8-bit levels vs 4x supersampled)")
    print(f"{'':14s} {'RMSE':>8s} {'max':>8s} {'seconds':>8s}")
    for key, sec in (("plain", r["seconds"][0]), ("antialiased", r["seconds"][1])):
        rmse, worst = r[key]
        print(f"{key:14s} {rmse:8.2f} {worst:8.1f} {sec:8.3f}")
    print(f"({r['pixels']} pixels inside the target, away from its edge)")


if __name__ == "__main__":
    main()
