"""Numbers written into Triangle's switches: decimals its parser reads, never an exponent."""

from __future__ import annotations

import numpy as np


def decimal(value: float) -> str:
    """``value`` as Triangle's switch parser reads it: digits and a point, 17 significant digits.

    Triangle reads a switch's number as the run of digits and points after
    its letter: ``a5e-05`` is an area of 5 (the ``e`` ends it), so a small
    area given as Python's ``%g`` writes it asked for a mesh of two
    triangles where thousands were wanted. ``%.17g`` is kept where it has no
    exponent (the same text as before, the same meshes); elsewhere the value
    is written positionally, the same double.

    >>> decimal(123.5), decimal(5e-05), decimal(1e-4)
    ('123.5', '0.000050000000000000002', '0.0001')
    """
    text = f"{value:.17g}"
    if "e" not in text:
        return text
    return np.format_float_positional(value, precision=17, unique=False, fractional=False, trim="-")
