"""Metrics: distortion of a map from its Jacobians (the paper's §4.3 and Table 2)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


def singular_values(j: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Singular values ``sigma1 >= sigma2 >= 0`` of a stack of 2x2 matrices, in closed form."""
    a, b, c, d = j[..., 0, 0], j[..., 0, 1], j[..., 1, 0], j[..., 1, 1]
    # sigma1,2 = (sqrt((a+d)^2 + (c-b)^2) +- sqrt((a-d)^2 + (b+c)^2)) / 2
    p = np.hypot(a + d, c - b)
    q = np.hypot(a - d, b + c)
    return 0.5 * (p + q), 0.5 * np.abs(p - q)


@dataclass(frozen=True)
class Distortion:
    """Distortion of f (source -> target) at sampled output pixels.

    Every array has one entry per sample, NaN where the sample has no
    Jacobian (outside the target).

    Attributes
    ----------
    conformal : ndarray
        ``sigma1/sigma2 + sigma2/sigma1`` (2 for a similarity).
    isometric : ndarray
        ``max(sigma1, 1/sigma2)`` (1 for a rigid motion).
    det : ndarray
        det of the Jacobian of f at the sample's source point (signed: a
        mirror map, between polygons of opposite orientations, has negative
        determinants throughout).
    weight : ndarray
        Source area the sample stands for, in square source pixels.
    """

    conformal: NDArray[np.float64]
    isometric: NDArray[np.float64]
    det: NDArray[np.float64]
    weight: NDArray[np.float64]

    def summary(self) -> dict:
        """Area-weighted means over the source polygon and maxima, the report's numbers."""
        ok = np.isfinite(self.conformal) & np.isfinite(self.isometric) & np.isfinite(self.weight)
        w = self.weight[ok]
        total = float(w.sum())

        def mean(x):
            return float((x[ok] * w).sum() / total) if total > 0 else None

        def peak(x):
            return float(x[ok].max()) if ok.any() else None

        return {
            "min_jacobian_det": float(self.det[ok].min()) if ok.any() else None,
            "conformal": {"mean": mean(self.conformal), "max": peak(self.conformal)},
            "isometric": {"mean": mean(self.isometric), "max": peak(self.isometric)},
        }


def distortion(inverse_jacobian: ArrayLike) -> Distortion:
    """Distortion of f (source -> target) from Jacobians of f^-1 at sampled target points.

    Both measures are invariant under inversion (the singular values of J_f
    are the reciprocals of those of J_f^-1, swapped), so they are computed
    from J_f^-1, which is known exactly at every output pixel; each sample
    stands for ``|det J_f^-1|`` square pixels of the source, which weights the
    means so that they are means over the source polygon.

    Parameters
    ----------
    inverse_jacobian : (..., 2, 2) array_like of float
        d source / d target at each sample; NaN where unknown (outside the
        target: NaN results).

    Returns
    -------
    Distortion
        One entry per sample, flattened.

    References
    ----------
    Schneider & Hormann, CAGD 2015, §4.3 (conformal and isometric distortion)
    and Table 2.
    """
    j = np.asarray(inverse_jacobian, dtype=np.float64).reshape(-1, 2, 2)
    keep = np.flatnonzero(np.isfinite(j).all(axis=(1, 2)))
    j_inv = j[keep]
    s1, s2 = singular_values(j_inv)
    det_inv = j_inv[:, 0, 0] * j_inv[:, 1, 1] - j_inv[:, 0, 1] * j_inv[:, 1, 0]
    out = [np.full(len(j), np.nan) for _ in range(4)]
    with np.errstate(divide="ignore", invalid="ignore"):
        out[0][keep] = s1 / s2 + s2 / s1
        out[1][keep] = np.maximum(s1, 1.0 / s2)
        out[2][keep] = 1.0 / det_inv
    out[3][keep] = np.abs(det_inv)
    return Distortion(*out)


#: Metrics work through Jacobians in blocks of this many, so that their
#: temporaries stay small whatever the image size.
BLOCK = 1 << 20


def summarize(inverse_jacobian: ArrayLike, block: int = BLOCK) -> dict:
    """`Distortion.summary` of `distortion`, computed block by block in bounded memory.

    Parameters
    ----------
    inverse_jacobian : (..., 2, 2) array_like of float
        Jacobians of f^-1 at sampled target points (NaN where unknown).
    block : int
        Samples per block (the same numbers as one block, up to the order
        of the sums).

    Returns
    -------
    dict
        ``min_jacobian_det``, ``conformal`` and ``isometric`` (``mean``, ``max``).
    """
    j = np.asarray(inverse_jacobian, dtype=np.float64).reshape(-1, 2, 2)
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
    flat = j.reshape(-1, 2, 2)
    out = np.empty(len(flat))
    for s in range(0, len(flat), block):
        out[s : s + block] = getattr(distortion(flat[s : s + block]), name)
    return out.reshape(shape)
