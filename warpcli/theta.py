"""Theta stage: the convex intermediate polygon both harmonic maps go onto."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def regular_polygon(n: int) -> NDArray[np.float64]:
    """The regular n-gon inscribed in the unit circle, positive shoelace area.

    Vertex 0 is at angle 0 and the angles increase, so with y down the
    vertices run clockwise on screen, like `Polygon.signed_area` > 0.

    >>> regular_polygon(4).round(12).tolist()
    [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [-0.0, -1.0]]
    """
    if n < 3:
        raise ValueError(f"Theta needs at least 3 vertices, got {n}")
    angle = 2.0 * np.pi * np.arange(n) / n
    return np.stack([np.cos(angle), np.sin(angle)], axis=1)
