"""The mesher is a C library that one bad input can crash (a segfault ends the process with no
message). Validation must keep every such input out: near-degenerate shapes on both sides of
the clearance floor go through validation and meshing in a child process, which must finish.

Each case is either refused by `Polygon` (an InputError) or meshed; a crash of the child shows
as a negative exit status. CI runs a fixed grid of cases; WARPCLI_FUZZ=long runs a denser one.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

CHILD = r"""
import json, sys
import numpy as np
from warpcli import InputError, Polygon
from warpcli.maps.fem.mesh import auto_max_area, mesh_polygon

counts = {"refused": 0, "meshed": 0}
for pts in json.load(sys.stdin):
    try:
        poly = Polygon(np.array(pts, dtype=float))
    except InputError:
        counts["refused"] += 1
        continue
    # coarse inside (the danger is at the small features, which triangle refines anyway)
    mesh = mesh_polygon(poly, max(auto_max_area(poly), abs(poly.signed_area) / 500))
    assert mesh.n_triangles > 0
    counts["meshed"] += 1
print(json.dumps(counts))
"""


def _cases(density: int) -> list[list[list[float]]]:
    """V-slits, needles, near-touching arms and spikes, with their critical width swept through
    and around the clearance floor (1e-3 px, or 1e-6 of the diagonal) at several sizes and offsets."""
    widths = np.logspace(-15, 0, density)
    cases = []
    for size in (10.0, 1e3, 1e5):
        for off in (0.0, 1e6):
            for w in widths * size / 10:
                # a square with a V-shaped slit from the top edge whose mouth is w wide
                s = size
                cases.append([[off, off], [off + s / 2 - w / 2, off], [off + s / 2, off + 0.8 * s],
                              [off + s / 2 + w / 2, off], [off + s, off], [off + s, off + s], [off, off + s]])
                # a needle: a triangle w high
                cases.append([[off, off], [off + s, off], [off + s / 3, off + w]])
                # two arms w apart
                cases.append([[off, off], [off + s, off], [off + s, off + s / 3], [off + s / 5, off + s / 3],
                              [off + s / 5, off + s / 3 + w], [off + s, off + s / 3 + w], [off + s, off + s],
                              [off, off + s]])
                # a spike w wide at its base
                cases.append([[off, off], [off + s / 2 - w / 2, off], [off + s / 2, off - 2 * s],
                              [off + s / 2 + w / 2, off], [off + s, off], [off + s / 2, off + s]])
    return [[list(map(float, p)) for p in c] for c in cases]


def test_near_degenerate_shapes_never_crash_the_mesher():
    density = 250 if os.environ.get("WARPCLI_FUZZ") == "long" else 16
    cases = _cases(density)
    proc = subprocess.run(
        [sys.executable, "-c", CHILD], input=json.dumps(cases), capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    counts = json.loads(proc.stdout)
    assert counts["refused"] + counts["meshed"] == len(cases)
    # both sides of the floor were exercised
    assert counts["refused"] > len(cases) // 4 and counts["meshed"] > len(cases) // 4, counts
