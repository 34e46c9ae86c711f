"""Distortion measures of a map from its Jacobians, in any dimension (the paper's §4.3 and Table 2).

One set of formulas for maps of polygons (d = 2) and of polyhedra (d = 3),
from the singular values ``sigma_1 >= ... >= sigma_d`` of a Jacobian J:

- conformal distortion ``sum sigma_k^2 / |det J|^(2/d)``: d for a
  similarity (2 in the plane, where it is ``sigma_1/sigma_2 +
  sigma_2/sigma_1``; 3 in space, the MIPS energy);
- isometric distortion ``max(sigma_1, 1 / sigma_d)``: 1 for a rigid motion.

Both are invariant under inversion (the singular values of J^-1 are the
reciprocals of J's, in reverse order), so they can be measured on the
Jacobians of f^-1, which a warp knows exactly at every output pixel.
This module imports numpy only: `warpcli.report`, `warpcli.volume.report`
and `warpcli.maps.optimize` all measure with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


def singular_values(j: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """Singular values ``sigma_1 >= ... >= sigma_d >= 0`` of a stack of d x d matrices.

    Parameters
    ----------
    j : (..., d, d) ndarray of float
        Finite matrices.

    Returns
    -------
    tuple of d (...) ndarrays of float
        In decreasing order. For d = 2 in closed form, otherwise by SVD.

    Examples
    --------
    >>> s1, s2 = singular_values(np.array([[3.0, 0.0], [0.0, -2.0]]))
    >>> float(s1), float(s2)
    (3.0, 2.0)
    """
    if j.shape[-1] == 2:
        a, b, c, d = j[..., 0, 0], j[..., 0, 1], j[..., 1, 0], j[..., 1, 1]
        # sigma1,2 = (sqrt((a+d)^2 + (c-b)^2) +- sqrt((a-d)^2 + (b+c)^2)) / 2
        p = np.hypot(a + d, c - b)
        q = np.hypot(a - d, b + c)
        return 0.5 * (p + q), 0.5 * np.abs(p - q)
    s = np.linalg.svd(j, compute_uv=False)
    return tuple(s[..., k] for k in range(j.shape[-1]))


def conformal(s: tuple[NDArray[np.float64], ...], det: NDArray[np.float64]) -> NDArray[np.float64]:
    """Conformal distortion ``sum sigma_k^2 / |det|^(2/d)`` from singular values and the determinant.

    Parameters
    ----------
    s : tuple of d ndarrays of float
        `singular_values` of the Jacobians.
    det : ndarray of float
        Their determinants (``prod sigma_k`` up to sign).

    Returns
    -------
    ndarray of float
        d for a similarity; inf where a Jacobian is singular.

    Notes
    -----
    The same number is rounded as each dimension's report always has: for
    d = 2 as ``sigma_1/sigma_2 + sigma_2/sigma_1`` (``det`` is not needed),
    for d = 3 with a cube root.

    Examples
    --------
    >>> s = (np.array([2.0]), np.array([2.0]), np.array([2.0]))
    >>> conformal(s, np.array([8.0])).tolist()
    [3.0]
    """
    d = len(s)
    with np.errstate(all="ignore"):
        if d == 2:
            return s[0] / s[1] + s[1] / s[0]
        total = s[0] ** 2
        for k in range(1, d):
            total = total + s[k] ** 2
        if d == 3:
            return total / np.cbrt(np.abs(det)) ** 2
        return total / np.abs(det) ** (2.0 / d)


def isometric(s: tuple[NDArray[np.float64], ...]) -> NDArray[np.float64]:
    """Isometric distortion ``max(sigma_1, 1 / sigma_d)`` from decreasing singular values (1 for a rigid motion).

    Examples
    --------
    >>> isometric((np.array([2.0]), np.array([0.25]))).tolist()
    [4.0]
    """
    with np.errstate(all="ignore"):
        return np.maximum(s[0], 1.0 / s[-1])


def determinant(j: NDArray[np.float64]) -> NDArray[np.float64]:
    """Determinants of a stack of d x d matrices: for d = 2 written out, otherwise `numpy.linalg.det`."""
    if j.shape[-1] == 2:
        return j[..., 0, 0] * j[..., 1, 1] - j[..., 0, 1] * j[..., 1, 0]
    return np.linalg.det(j)


@dataclass(frozen=True)
class Distortion:
    """Distortion of f (source -> target) at sampled target points.

    Every array has one entry per sample, NaN where the sample has no
    Jacobian (outside the target).

    Attributes
    ----------
    conformal : ndarray
        `conformal` (d for a similarity: ``sigma1/sigma2 + sigma2/sigma1`` in 2D).
    isometric : ndarray
        ``max(sigma1, 1/sigma_d)`` (1 for a rigid motion).
    det : ndarray
        det of the Jacobian of f at the sample's source point (signed: a
        mirror map, between polygons of opposite orientations, has negative
        determinants throughout).
    weight : ndarray
        Source area (volume) the sample stands for, in source pixels (voxels).
    """

    conformal: NDArray[np.float64]
    isometric: NDArray[np.float64]
    det: NDArray[np.float64]
    weight: NDArray[np.float64]

    def summary(self) -> dict:
        """Area-weighted means over the source domain and maxima, the report's numbers."""
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

    Both measures are invariant under inversion, so they are computed from
    J_f^-1, which is known exactly at every output pixel; each sample
    stands for ``|det J_f^-1|`` source pixels (voxels), which weights the
    means so that they are means over the source domain.

    Parameters
    ----------
    inverse_jacobian : (..., d, d) array_like of float
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
    j = np.asarray(inverse_jacobian, dtype=np.float64)
    d = j.shape[-1]
    j = j.reshape(-1, d, d)
    keep = np.flatnonzero(np.isfinite(j).all(axis=(1, 2)))
    j_inv = j[keep]
    s = singular_values(j_inv)
    det_inv = determinant(j_inv)
    out = [np.full(len(j), np.nan) for _ in range(4)]
    out[0][keep] = conformal(s, det_inv)
    out[1][keep] = isometric(s)
    with np.errstate(divide="ignore", invalid="ignore"):
        out[2][keep] = 1.0 / det_inv
    out[3][keep] = np.abs(det_inv)
    return Distortion(*out)
