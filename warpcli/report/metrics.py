"""Metrics: the report's distortion numbers over every output pixel, in bounded memory (the paper's §4.3 and Table 2).

The measures themselves (`Distortion`, `distortion`, `singular_values`) are
`warpcli.distortion`'s, shared with the volume report and Theta's
optimization; they are imported here, where the report has always found them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..distortion import Distortion, distortion, singular_values

__all__ = ["BLOCK", "Distortion", "distortion", "measure", "singular_values", "summarize"]


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
