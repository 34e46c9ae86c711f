"""The CLI end to end on the shipped sample images and polygon pairs."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import read_pixels
from warpcli import BijectiveMap, read_polygon

SAMPLES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "sample_images")
PAIRS = [("grid.png", "grid_L.json", "grid_hexagon.json"), ("chelsea.png", "chelsea_ring.json", "chelsea_star.json")]


@pytest.mark.parametrize("image,src,dst", PAIRS)
def test_sample_warp_end_to_end(image, src, dst, tmp_path):
    inp = os.path.join(SAMPLES, image)
    src_p, dst_p = (os.path.join(SAMPLES, n) for n in (src, dst))
    outs = []
    for k in range(2):
        out = tmp_path / f"out{k}.png"
        done = subprocess.run(
            [sys.executable, "-m", "warpcli", inp, "--src", src_p, "--dst", dst_p, str(out)],
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr
        assert done.stdout == "" and done.stderr == ""
        outs.append(out)
    assert outs[0].read_bytes() == outs[1].read_bytes()  # byte-identical, run after run
    before = read_pixels(inp)
    after = read_pixels(outs[0])
    assert after.shape == before.shape and after.dtype == before.dtype
    # Outside the target polygon, away from its antialiased edge: the default background, 0.
    from warpcli.raster.resample import edge_coverage

    f = BijectiveMap.between(read_polygon(src_p), read_polygon(dst_p))
    h, w = before.shape[:2]
    centre_in = np.isfinite(f.inverse_grid(w, h)[..., 0])
    inside = centre_in.ravel()
    inside[edge_coverage(f.dst.points, centre_in).pixels] = True
    assert (after.reshape(h * w, -1)[~inside] == 0).all()
    # Just inside each target vertex, the output shows what the input has just
    # inside the corresponding source vertex (the vertices correspond).
    s = np.array(json.load(open(src_p))["points"])
    d = np.array(json.load(open(dst_p))["points"])
    for k in range(len(s)):
        toward = lambda p, i: p[i] + 0.02 * (p.mean(axis=0) - p[i])  # noqa: E731
        q = toward(d, k)
        x = f.inverse(q[None])[0]
        assert np.isfinite(x).all()
        assert np.hypot(*(x - toward(s, k))) < 0.1 * np.hypot(*np.ptp(s, axis=0))
