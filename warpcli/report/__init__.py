"""Report: measuring a map (certificates, Jacobians, distortion) and drawing it (grid, heatmap).

- `metrics`: distortion measures from Jacobians;
- `figures`: a grid carried through the map, distortion heatmaps;
- `seam`: the jump of neighbouring values across a polyline (a retouch's edge, a cut) against elsewhere.
"""

from __future__ import annotations

import time
from typing import Any, Protocol



#: Source points measured at once (bounded temporaries).
SOURCE_BLOCK = 1 << 18


def measure_source(f: Any, parts: list | None = None) -> dict:
    """The report's distortion numbers of a map f, measured over its source polygon.

    A cage map (`warpcli.maps.cage.CageMap`) is measured face by face: its
    faces tile the source, so the points of all faces are the source's.

    Parameters
    ----------
    f : ComposedMap or CageMap
        Anything with ``src.points`` (the source polygon's vertices) and
        ``phi0``, ``phi1`` (``evaluate``, ``evaluate_grid`` and a coherent
        ``inverse``, with Jacobians), or with ``face_maps`` of those.
    parts : list of ndarray or None
        The Jacobians of `source_jacobians` per map (per face), if at hand.

    Returns
    -------
    dict
        `warpcli.report.metrics.summarize_forward` of the Jacobians of f at
        the points of `warpcli.report.metrics.source_grid`: at a 1-px grid,
        phi0 by its pixel-grid fast path; then phi1^-1 walked in row order.
    """
    import numpy as np

    from .metrics import summarize_forward

    if parts is None:
        parts = [source_jacobians(m) for m in (f.face_maps if hasattr(f, "face_maps") else (f,))]
    return summarize_forward(np.concatenate(parts) if parts else np.empty((0, 2, 2)))


def source_jacobians(f: Any) -> Any:
    """(N, 2, 2): the Jacobians of a map f (with ``src``, ``phi0``, ``phi1``) at the points of
    its source polygon that `measure_source` measures."""
    import math

    import numpy as np

    from .metrics import MAX_SOURCE_SAMPLES, source_grid

    phi0, phi1 = f.phi0, f.phi1
    v = np.asarray(f.src.points, dtype=np.float64)
    x0, y0 = v.min(axis=0)
    x1, y1 = v.max(axis=0)
    q = np.roll(v, -1, axis=0)
    area = abs(0.5 * float((v[:, 0] * q[:, 1] - q[:, 0] * v[:, 1]).sum()))
    parts = []
    if area <= MAX_SOURCE_SAMPLES and x0 >= 0.0 and y0 >= 0.0:
        # The pixel centres of a grid from the origin: phi0's fast path, band by band.
        width, height = math.ceil(x1) + 1, math.ceil(y1) + 1
        # In one pass when the grid is small (no per-band tables), else in bands of rows.
        band = height if width * height <= 4 * MAX_SOURCE_SAMPLES else max(1, SOURCE_BLOCK // width)
        for r0 in range(0 if band == height else int(y0), height, band):
            rows = None if band == height else (r0, min(r0 + band, height))
            g = phi0.evaluate_grid(width, height, rows, jacobian=True)
            b = phi1.inverse(g.values, jacobian=True, coherent=True)
            parts.append(b.jacobian @ g.jacobian)
    else:
        points = source_grid(v)
        for s in range(0, len(points), SOURCE_BLOCK):
            a = phi0.evaluate(points[s : s + SOURCE_BLOCK], jacobian=True)
            b = phi1.inverse(a.points, jacobian=True, coherent=True)
            parts.append(b.jacobian @ a.jacobian)
    return np.concatenate(parts) if parts else np.empty((0, 2, 2))


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

    Distortion is measured where it lives, over the source: on a 1-px grid
    of the source polygon (a coarser regular grid beyond
    `warpcli.report.metrics.MAX_SOURCE_SAMPLES` pixels), with the Jacobian of
    f at each point (`warpcli.report.metrics.summarize_forward`). The means
    are plain means over those points, means over the source domain; the
    maxima and ``min_jacobian_det`` are taken over them. (Earlier versions
    took the means over the output pixels, each weighted by the source area
    it pulls back: the same integral sampled in the target, which
    undersamples a region the map squeezes, biased low on extreme maps.)

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
    if result.pull.jacobian is None:
        raise ValueError("this result kept no Jacobians to measure")
    t0 = time.perf_counter()
    f = result.map
    parts = [source_jacobians(m) for m in (f.face_maps if hasattr(f, "face_maps") else (f,))]
    summary = measure_source(f, parts)
    result.timings["metrics"] = time.perf_counter() - t0
    timings = dict(result.timings)
    # A cage map (`warpcli.maps.cage.CageMap`) has a Theta per face, and a report per face.
    theta = {"theta": {"name": f.theta.name, **f.theta.notes}} if f.theta is not None and f.theta.notes else {}
    faces = _faces(f, result.pull, parts) if hasattr(f, "face_maps") else {}
    return {
        "vertices": f.src.n,
        **theta,
        **f.describe(),
        "flipped_triangles": f.flipped_triangles() + unknown_pixels(result),
        "min_jacobian_det": summary["min_jacobian_det"],
        "conformal": summary["conformal"],
        "isometric": summary["isometric"],
        **faces,
        "timings": {k: round(v, 4) for k, v in timings.items()},
    }


def _faces(f: Any, pull: Any, parts: list) -> dict:
    """A cage map's certificate and each face's: its map's certificates, mesh and distortion.

    The whole map is certified when every face map is: the meshes were
    validated as partitions with the same faces and orientation, so the
    faces' images tile the target without overlap.
    """
    labels = getattr(pull, "faces", None)
    per = []
    for k, fmap in enumerate(f.face_maps):
        c0, c1 = fmap.certificates()
        entry: dict[str, Any] = {
            "face": k, "vertices": fmap.src.n, **fmap.describe(), "certified": c0.ok and c1.ok,
            "flipped_triangles": fmap.flipped_triangles(),
        }  # fmt: skip
        if labels is not None:
            mine = labels == k
            entry["pixels"] = int(mine.sum())
        entry.update(measure_source(fmap, parts[k : k + 1]))
        per.append(entry)
    return {
        "certified": all(e["certified"] for e in per),
        "certificate": "every face map certified one-to-one; the target faces a partition with the source's "
        "faces and orientation (validated), so the whole map is one-to-one",
        "faces": per,
    }
