"""Report: measuring a map (certificates, Jacobians, distortion) and drawing it (grid, heatmap).

- `metrics`: distortion measures from Jacobians;
- `figures`: a grid carried through the map, distortion heatmaps;
- `seam`: the jump of neighbouring values across a polyline (a retouch's edge, a cut) against elsewhere.
"""

from __future__ import annotations

import time
from typing import Any, Protocol



class Measurable(Protocol):
    """What a report needs of a warp (`warpcli.pipeline.WarpResult` is one)."""

    map: Any  #: the `warpcli.maps.compose.BijectiveMap`
    pull: Any  #: the `warpcli.maps.compose.PullBack`, with Jacobians of f^-1 at output pixels
    timings: dict[str, float]


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
        ``flipped_triangles`` (elements where either map flips: 0 for a
        bijection); ``min_jacobian_det``; ``conformal`` and ``isometric``
        (``mean`` and ``max``); ``timings`` (seconds per stage).

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
    # A cage map (`warpcli.maps.cage.CageMap`) has a Theta per face, and a report per face.
    theta = {"theta": {"name": f.theta.name, **f.theta.notes}} if f.theta is not None and f.theta.notes else {}
    faces = _faces(f, result.pull, summarize) if hasattr(f, "face_maps") else {}
    return {
        "vertices": f.src.n,
        **theta,
        **f.describe(),
        "flipped_triangles": f.flipped_triangles(),
        "min_jacobian_det": summary["min_jacobian_det"],
        "conformal": summary["conformal"],
        "isometric": summary["isometric"],
        **faces,
        "timings": {k: round(v, 4) for k, v in timings.items()},
    }


def _faces(f: Any, pull: Any, summarize: Any) -> dict:
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
            entry.update(summarize(pull.jacobian[mine]) if mine.any() else {})
        per.append(entry)
    return {
        "certified": all(e["certified"] for e in per),
        "certificate": "every face map certified one-to-one; the target faces a partition with the source's "
        "faces and orientation (validated), so the whole map is one-to-one",
        "faces": per,
    }
