"""Metrics: Jacobians of the composed map, distortion (the paper's Table 2), fold-over counts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .harmonic import HarmonicMap


def triangle_jacobians(phi: HarmonicMap, *, inverse: bool = False) -> NDArray[np.float64]:
    """(M, 2, 2): the constant Jacobian of the piecewise-linear map on each triangle.

    ``J = G @ inv(E)`` with ``E = [v_1 - v_0, v_2 - v_0]`` (mesh) and
    ``G = [theta_1 - theta_0, theta_2 - theta_0]`` (image) as columns; with
    ``inverse``, the Jacobian of the inverse map, ``E @ inv(G)``. NaN or inf
    for a degenerate triangle.
    """
    t = phi.mesh.triangles
    v = phi.mesh.vertices
    w = phi.values
    e = np.stack([v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]], axis=2)  # columns
    g = np.stack([w[t[:, 1]] - w[t[:, 0]], w[t[:, 2]] - w[t[:, 0]]], axis=2)
    if inverse:
        e, g = g, e
    return g @ _inv2(e)


def _inv2(m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverses of a stack of 2x2 matrices, in closed form."""
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack(
            [np.stack([m[:, 1, 1], -m[:, 0, 1]], axis=1), np.stack([-m[:, 1, 0], m[:, 0, 0]], axis=1)], axis=1
        ) / det[:, None, None]


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


def distortion_at_pixels(
    phi0: HarmonicMap, phi1: HarmonicMap, tri0: NDArray[np.integer], tri1: NDArray[np.integer]
) -> Distortion:
    """Distortion of f = phi1^-1 o phi0 at output pixels with known triangles.

    An output pixel y in target triangle T1, whose pre-image lies in source
    triangle T0, sees the inverse map with Jacobian
    ``J_inv = J_phi0(T0)^-1 @ J_phi1(T1)``. Both measures are invariant under
    inversion (the singular values of J_f are the reciprocals of those of
    J_inv, swapped), so they are computed from J_inv; each pixel stands for
    ``|det J_inv|`` square pixels of the source, which weights the means so
    that they are means over the source polygon.

    Parameters
    ----------
    tri0, tri1 : array_like of int
        Source and target triangle of each sampled output pixel (-1: no
        Jacobian, NaN results).
    """
    t0 = np.asarray(tri0).ravel()
    t1 = np.asarray(tri1).ravel()
    keep = np.flatnonzero((t0 >= 0) & (t1 >= 0))
    j_inv = np.linalg.solve(triangle_jacobians(phi0)[t0[keep]], triangle_jacobians(phi1)[t1[keep]])
    s1, s2 = singular_values(j_inv)
    det_inv = j_inv[:, 0, 0] * j_inv[:, 1, 1] - j_inv[:, 0, 1] * j_inv[:, 1, 0]
    out = [np.full(t0.shape, np.nan) for _ in range(4)]
    with np.errstate(divide="ignore", invalid="ignore"):
        out[0][keep] = s1 / s2 + s2 / s1
        out[1][keep] = np.maximum(s1, 1.0 / s2)
        out[2][keep] = 1.0 / det_inv
    out[3][keep] = np.abs(det_inv)
    return Distortion(*out)
