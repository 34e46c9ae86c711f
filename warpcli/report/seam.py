"""Seams: how much neighbouring pixel values jump across a polyline, against the same measure elsewhere.

A retouch pasted over its image (``--outside input``) leaves a seam where the
target's edge crosses detail: the map jumps there, so neighbouring output
pixels come from far-apart input points. `seam_jump` measures it the plain
way: for every pair of 4-neighbouring pixels, the largest difference of their
values over the channels; the pairs whose centres lie on either side of the
polyline (the segment between the two centres crosses it) are *across*, the
others *elsewhere*. On a smooth ramp the jump elsewhere is one ramp step, and
a seam shows as an across maximum of many steps. Any per-pixel quantity can be
measured, not only colour: the entries of the map's Jacobian give the jump of
the Jacobian across a cage edge or a cut.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["SeamJump", "crossing_pairs", "seam_jump"]


@dataclass(frozen=True)
class SeamJump:
    """The jumps of neighbouring values across a polyline and elsewhere.

    Attributes
    ----------
    across : ndarray of float
        For each pair of 4-neighbours on either side of the polyline, the
        largest absolute difference of their values over the channels.
    elsewhere : ndarray of float
        The same for every other pair (both values finite).
    """

    across: NDArray[np.float64]
    elsewhere: NDArray[np.float64]

    @property
    def across_max(self) -> float:
        """The largest jump across (0 if no pair crosses)."""
        return float(self.across.max()) if self.across.size else 0.0

    @property
    def across_mean(self) -> float:
        """The mean jump across (0 if no pair crosses)."""
        return float(self.across.mean()) if self.across.size else 0.0

    @property
    def elsewhere_max(self) -> float:
        """The largest jump elsewhere."""
        return float(self.elsewhere.max()) if self.elsewhere.size else 0.0

    @property
    def elsewhere_p99(self) -> float:
        """The 99th percentile of the jumps elsewhere: the image's own sharpest ordinary steps."""
        return float(np.percentile(self.elsewhere, 99)) if self.elsewhere.size else 0.0

    @property
    def ratio(self) -> float:
        """``across_max / elsewhere_max``: 1 or less where the polyline leaves no seam (inf if nothing jumps elsewhere)."""
        top = self.elsewhere_max
        if top == 0:
            return 0.0 if self.across_max == 0 else float("inf")
        return self.across_max / top

    def as_dict(self) -> dict[str, float]:
        """The summary numbers, for a report."""
        return {
            "across_max": self.across_max, "across_mean": self.across_mean, "elsewhere_max": self.elsewhere_max,
            "elsewhere_p99": self.elsewhere_p99, "ratio": self.ratio, "pairs_across": int(self.across.size),
        }  # fmt: skip


def crossing_pairs(
    polyline: ArrayLike, width: int, height: int, *, closed: bool = True
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Which pairs of 4-neighbouring pixel centres lie on either side of a polyline.

    The segment between the centres of pixels (r, c) and (r, c + 1) crosses a
    polyline segment when that segment meets the row's centre line
    ``y = r + 0.5`` (half-open in y, so a vertex on it counts once) at
    ``c + 0.5 <= x < c + 1.5``; likewise for vertical pairs with columns.

    Parameters
    ----------
    polyline : (n, 2) array_like of float
        Vertices in the image's continuous coordinates.
    width, height : int
    closed : bool
        Whether the last vertex joins the first (a polygon's edge).

    Returns
    -------
    horizontal : (height, width - 1) ndarray of bool
        Pair (r, c)-(r, c + 1) crosses (an odd number of times: a polyline
        passing between two centres twice leaves them on one side).
    vertical : (height - 1, width) ndarray of bool
        Pair (r, c)-(r + 1, c) crosses.

    Examples
    --------
    >>> h, v = crossing_pairs([[1.7, 0.0], [1.7, 3.0]], 4, 3, closed=False)
    >>> h.astype(int).tolist(), bool(v.any())
    ([[0, 1, 0], [0, 1, 0], [0, 1, 0]], False)
    """
    p = np.asarray(polyline, dtype=np.float64).reshape(-1, 2)
    a = p if closed else p[:-1]
    b = np.roll(p, -1, axis=0) if closed else p[1:]
    horizontal = _crossings(a, b, height, width - 1)
    vertical = _crossings(a[:, ::-1], b[:, ::-1], width, height - 1).T
    return horizontal, vertical


def _crossings(a: NDArray, b: NDArray, lines: int, pairs: int) -> NDArray[np.bool_]:
    """(lines, pairs): segments ab crossing the centre line y = i + 0.5 between x = j + 0.5 and j + 1.5 (odd count)."""
    out = np.zeros((lines, max(pairs, 0)), dtype=np.int64)
    if pairs <= 0 or lines <= 0 or not len(a):
        return out.astype(bool)
    ylo, yhi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    first = np.clip(np.ceil(ylo - 0.5).astype(np.int64), 0, lines)
    last = np.clip(np.ceil(yhi - 0.5).astype(np.int64), 0, lines)
    count = np.maximum(last - first, 0)
    seg = np.repeat(np.arange(len(a)), count)
    line = np.repeat(first, count) + np.arange(seg.size) - np.repeat(np.cumsum(count) - count, count)
    y = line + 0.5
    t = (y - a[seg, 1]) / (b[seg, 1] - a[seg, 1])
    x = a[seg, 0] + t * (b[seg, 0] - a[seg, 0])
    j = np.floor(x - 0.5).astype(np.int64)
    ok = (j >= 0) & (j < pairs)
    np.add.at(out, (line[ok], j[ok]), 1)
    return (out & 1).astype(bool)


def seam_jump(values: ArrayLike, polyline: ArrayLike, *, closed: bool = True) -> SeamJump:
    """The jumps of neighbouring values across a polyline, against the same measure elsewhere.

    Parameters
    ----------
    values : (H, W) or (H, W, C) array_like of float
        An image, or any per-pixel quantity (the entries of a Jacobian);
        pairs with a non-finite value are left out.
    polyline : (n, 2) array_like of float
        The seam's course: the target polygon of a retouch, a cage edge, a cut.
    closed : bool
        Whether the last vertex joins the first.

    Returns
    -------
    SeamJump

    Examples
    --------
    >>> ramp = np.tile(np.arange(6.0), (4, 1))
    >>> ramp[:, 3:] += 10  # a step between columns 2 and 3
    >>> s = seam_jump(ramp, [[3.0, 0.0], [3.0, 4.0]], closed=False)
    >>> s.across_max, s.elsewhere_max
    (11.0, 1.0)
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 2:
        v = v[:, :, None]
    if v.ndim != 3:
        raise ValueError(f"values must be an (H, W) or (H, W, C) array, got shape {v.shape}")
    h, w = v.shape[:2]
    horizontal, vertical = crossing_pairs(polyline, w, h, closed=closed)
    across, elsewhere = [], []
    for diff, crosses in ((v[:, 1:] - v[:, :-1], horizontal), (v[1:] - v[:-1], vertical)):
        jump = np.abs(diff).max(axis=2)
        finite = np.isfinite(jump)
        across.append(jump[crosses & finite])
        elsewhere.append(jump[~crosses & finite])
    return SeamJump(np.concatenate(across), np.concatenate(elsewhere))
