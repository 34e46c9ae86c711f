"""Report: measuring a map (certificates, Jacobians, distortion) and drawing it (grid, heatmap).

- `metrics`: distortion measures from Jacobians;
- `figures`: a grid carried through the map, distortion heatmaps.
"""

from __future__ import annotations

import time
from typing import Any, Protocol



class Measurable(Protocol):
    """What a report needs of a warp (`warpcli.pipeline.WarpResult` is one)."""

    map: Any  #: the `warpcli.maps.compose.BijectiveMap`
    pull: Any  #: the `warpcli.maps.compose.PullBack`, with Jacobians of f^-1 at output pixels
    timings: dict[str, float]


#: Pixel centres this close to the target's boundary (times its size) take the exact boundary map, without a Jacobian.
ON_BOUNDARY = 1e-9


def unknown_pixels(result: Measurable) -> int:
    """Output pixels strictly inside the target whose pull-back or its Jacobian is NaN.

    A bijection has a source point and a Jacobian at every such pixel. A
    smooth map whose value leaves Theta is clamped onto Theta's boundary
    there, and an inverse that does not converge gives NaN: those pixels
    used to be skipped by the metrics, they are counted here. Pixel
    centres on the boundary (to `ON_BOUNDARY`) have no Jacobian by design.

    Parameters
    ----------
    result : Measurable
        A warp that kept its Jacobians.

    Returns
    -------
    int
    """
    import numpy as np

    from ..boundary import on_boundary
    from ..grid import inside_polygon

    pull = result.pull
    dst = result.map.dst.points
    size = float(np.ptp(dst, axis=0).max())
    h, w = pull.points.shape[:2]
    r0, c0 = pull.origin
    xs = c0 + np.arange(w) + 0.5
    count = 0
    band = max(1, (1 << 18) // max(w, 1))
    for s in range(0, h, band):  # bands of rows: bounded memory
        ys = r0 + np.arange(s, min(s + band, h)) + 0.5
        centres = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
        pts = pull.points[s : s + band].reshape(-1, 2)
        jac = pull.jacobian[s : s + band].reshape(-1, 4)
        lost = ~(np.isfinite(pts).all(axis=1) & np.isfinite(jac).all(axis=1))
        idx = np.flatnonzero(lost)
        if not idx.size:
            continue
        idx = idx[inside_polygon(centres[idx], dst)]
        near = on_boundary(centres[idx], dst, ON_BOUNDARY * size)[0]
        count += int(idx.size - near.size)
    return count


def build_report(result: Measurable) -> dict:
    """The map's certificates, Jacobian and distortion (the paper's Table 2) as a JSON-able dict.

    Distortion is sampled at the output pixels: each stands for the source
    area it pulls back (see `warpcli.report.metrics.distortion`), so the means
    are area-weighted means over the source polygon, and the maxima and
    ``min_jacobian_det`` are taken over the sampled points.

    Parameters
    ----------
    result : WarpResult
        A warp that kept its Jacobians (any object with ``map``, ``pull`` and
        ``timings``).

    Returns
    -------
    dict
        ``vertices``; what the method adds (FEM: ``source_mesh`` and
        ``target_mesh`` with their vertex and triangle counts);
        ``flipped_triangles`` (elements where either map flips, plus the
        output pixels inside the target whose pull-back or Jacobian is
        unknown, see `unknown_pixels`: 0 for a bijection);
        ``min_jacobian_det``; ``conformal`` and ``isometric`` (``mean`` and
        ``max``); ``timings`` (seconds per stage).

    Raises
    ------
    ValueError
        If the result kept no Jacobians.

    References
    ----------
    Schneider & Hormann, CAGD 2015, §4.3 and Table 2.
    """
    from .metrics import summarize

    if result.pull.jacobian is None:
        raise ValueError("this result kept no Jacobians to measure")
    t0 = time.perf_counter()
    summary = summarize(result.pull.jacobian)
    f = result.map
    result.timings["metrics"] = time.perf_counter() - t0
    timings = dict(result.timings)
    theta = {"theta": {"name": f.theta.name, **f.theta.notes}} if f.theta.notes else {}
    return {
        "vertices": f.src.n,
        **theta,
        **f.describe(),
        "flipped_triangles": f.flipped_triangles() + unknown_pixels(result),
        "min_jacobian_det": summary["min_jacobian_det"],
        "conformal": summary["conformal"],
        "isometric": summary["isometric"],
        "timings": {k: round(v, 4) for k, v in timings.items()},
    }
