"""Metrics: the report's distortion numbers over every output pixel, in bounded memory (the paper's §4.3 and Table 2).

The measures themselves (`Distortion`, `distortion`, `singular_values`) are
`warpcli.distortion`'s, shared with the volume report and Theta's
optimization; they are imported here, where the report has always found them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..distortion import Distortion, distortion, singular_values

__all__ = [
    "BLOCK", "MAX_SOURCE_SAMPLES", "Distortion", "distortion", "measure", "singular_values", "source_grid", "summarize",
    "summarize_forward",
]


#: Metrics work through Jacobians in blocks of this many, so that their
#: temporaries stay small whatever the image size.
BLOCK = 1 << 20


def summarize(inverse_jacobian: ArrayLike, block: int = BLOCK) -> dict:
    """`Distortion.summary` of `distortion`, computed block by block in bounded memory.

    Parameters
    ----------
    inverse_jacobian : (..., d, d) array_like of float
        Jacobians of f^-1 at sampled target points (NaN where unknown).
    block : int
        Samples per block (the same numbers as one block, up to the order
        of the sums).

    Returns
    -------
    dict
        ``min_jacobian_det``, ``conformal`` and ``isometric`` (``mean``, ``max``).
    """
    j = np.asarray(inverse_jacobian, dtype=np.float64)
    j = j.reshape(-1, *j.shape[-2:])
    if len(j) <= block:
        return distortion(j).summary()
    total = 0.0
    sums = {"conformal": 0.0, "isometric": 0.0}
    peaks = {"conformal": -np.inf, "isometric": -np.inf}
    low = np.inf
    for s in range(0, len(j), block):
        d = distortion(j[s : s + block])
        ok = np.isfinite(d.conformal) & np.isfinite(d.isometric) & np.isfinite(d.weight)
        if not ok.any():
            continue
        w = d.weight[ok]
        total += float(w.sum())
        for name in sums:
            x = getattr(d, name)[ok]
            sums[name] += float((x * w).sum())
            peaks[name] = max(peaks[name], float(x.max()))
        low = min(low, float(d.det[ok].min()))
    if not np.isfinite(low):
        return {"min_jacobian_det": None, **{k: {"mean": None, "max": None} for k in sums}}
    return {
        "min_jacobian_det": low,
        **{k: {"mean": sums[k] / total if total > 0 else None, "max": peaks[k]} for k in sums},
    }


def measure(inverse_jacobian: ArrayLike, name: str, block: int = BLOCK) -> NDArray[np.float64]:
    """One distortion measure (``conformal``, ``isometric``, ``det`` or ``weight``) per sample.

    The same values as ``getattr(distortion(j), name)``, block by block.

    Returns
    -------
    ndarray of float
        The shape of ``inverse_jacobian`` without its last two axes.
    """
    j = np.asarray(inverse_jacobian, dtype=np.float64)
    shape = j.shape[:-2]
    flat = j.reshape(-1, *j.shape[-2:])
    out = np.empty(len(flat))
    for s in range(0, len(flat), block):
        out[s : s + block] = getattr(distortion(flat[s : s + block]), name)
    return out.reshape(shape)


#: At most this many source samples for the report: a 1-px grid over the
#: source up to this many pixels, a coarser regular grid beyond.
MAX_SOURCE_SAMPLES = 1 << 20


def source_grid(vertices: ArrayLike, max_samples: int = MAX_SOURCE_SAMPLES) -> NDArray[np.float64]:
    """Points of a regular grid over a polygon, inside it: pixel centres, or a coarser grid if too many.

    The spacing is 1 px while the polygon covers at most ``max_samples``
    pixels, else ``sqrt(area / max_samples)``; the grid is aligned with the
    pixel centres (x + 0.5) at 1 px. Every point stands for the same source
    area, so plain means over them are means over the source domain.

    Parameters
    ----------
    vertices : (n, 2) array_like of float
    max_samples : int

    Returns
    -------
    (K, 2) ndarray of float
        Row by row (a coherent order for walks through a mesh).
    """
    from ..grid import inside_polygon

    v = np.asarray(vertices, dtype=np.float64)
    x0, y0 = v.min(axis=0)
    x1, y1 = v.max(axis=0)
    q = np.roll(v, -1, axis=0)
    area = abs(0.5 * float((v[:, 0] * q[:, 1] - q[:, 0] * v[:, 1]).sum()))
    step = max(1.0, float(np.sqrt(area / max_samples)))
    xs = np.arange(np.floor(x0 / step), np.ceil(x1 / step) + 1) * step + 0.5 * step
    xs = xs[(xs > x0) & (xs < x1)]
    out = []
    for y in np.arange(np.floor(y0 / step), np.ceil(y1 / step) + 1) * step + 0.5 * step:
        if not y0 < y < y1:
            continue
        row = np.stack([xs, np.full(len(xs), y)], axis=1)
        out.append(row[inside_polygon(row, v)])
    return np.concatenate(out) if out else np.empty((0, 2))


def summarize_forward(forward_jacobian: ArrayLike) -> dict:
    """The report's numbers from Jacobians of f at points spread evenly over the source.

    Each point stands for the same source area, so the means are plain
    means: means over the source domain, however f squeezes or stretches
    it (the means of `summarize`, over target pixels weighted by |det J^-1|,
    are the same integral sampled in the target, where a region of the
    source squeezed into a few target pixels is sampled by few).

    Parameters
    ----------
    forward_jacobian : (..., 2, 2) array_like of float
        d target / d source; NaN rows are left out.

    Returns
    -------
    dict
        ``min_jacobian_det`` (of f), ``conformal`` and ``isometric`` (``mean``, ``max``).
    """
    j = np.asarray(forward_jacobian, dtype=np.float64)
    j = j.reshape(-1, *j.shape[-2:])
    ok = np.isfinite(j).all(axis=(1, 2))
    j = j[ok]
    # Both measures are invariant under inversion, and `distortion` reads
    # Jacobians of f^-1; here its det is 1 / det J_f, its weight |det J_f|.
    total = 0
    sums = {"conformal": 0.0, "isometric": 0.0}
    peaks = {"conformal": -np.inf, "isometric": -np.inf}
    low = np.inf
    for s in range(0, len(j), BLOCK):
        d = distortion(j[s : s + BLOCK])
        keep = np.isfinite(d.conformal) & np.isfinite(d.isometric) & np.isfinite(d.det)
        if not keep.any():
            continue
        total += int(keep.sum())
        for name in sums:
            x = getattr(d, name)[keep]
            sums[name] += float(x.sum())
            peaks[name] = max(peaks[name], float(x.max()))
        low = min(low, float((1.0 / d.det[keep]).min()))
    if total == 0:
        return {"min_jacobian_det": None, **{k: {"mean": None, "max": None} for k in sums}}
    return {"min_jacobian_det": low, **{k: {"mean": sums[k] / total, "max": peaks[k]} for k in sums}}
