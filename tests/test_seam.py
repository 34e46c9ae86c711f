"""The seam measure (warpcli.report.seam): jumps of neighbouring values across a polyline, against elsewhere."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import simple_polygons
from warpcli.polygon.predicates import segments_touch
from warpcli.report.seam import crossing_pairs, seam_jump


def _brute_crossings(poly, width, height):
    """Each neighbour pair against each edge with the exact segment test; odd counts cross."""
    a, b = poly, np.roll(poly, -1, axis=0)
    out = []
    for shape, step in (((height, width - 1), (1, 0)), ((height - 1, width), (0, 1))):
        r, c = np.mgrid[0 : shape[0], 0 : shape[1]]
        p = np.stack([c.ravel() + 0.5, r.ravel() + 0.5], axis=1)
        q = p + step
        n, m = len(p), len(a)
        hit = segments_touch(np.repeat(p, m, 0), np.repeat(q, m, 0), np.tile(a, (n, 1)), np.tile(b, (n, 1)))
        out.append((hit.reshape(n, m).sum(axis=1) % 2 == 1).reshape(shape))
    return out


@settings(max_examples=15, deadline=None)
@given(st.integers(3, 12).flatmap(simple_polygons), st.floats(0.1, 0.4), st.floats(0.013, 0.917))
def test_crossing_pairs_agree_with_exact_segment_tests(poly, scale, offset):
    # Scaled and shifted off the pixel lattice, so that no vertex or edge passes through a pixel centre
    # (where the half-open rule and a closed segment test may count differently).
    v = np.asarray(poly) * scale + offset
    w, h = 40, 36
    got = crossing_pairs(v, w, h)
    want = _brute_crossings(v, w, h)
    for g, x in zip(got, want):
        np.testing.assert_array_equal(g, x)


def test_a_step_across_a_polygon_is_measured_against_the_ramp_elsewhere():
    y, x = np.mgrid[0:50, 0:60].astype(float)
    ramp = x + 0.5 * y
    square = np.array([[15.2, 10.3], [40.1, 10.3], [40.1, 35.7], [15.2, 35.7]])
    inside = (x + 0.5 > 15.2) & (x + 0.5 < 40.1) & (y + 0.5 > 10.3) & (y + 0.5 < 35.7)
    stepped = ramp + 20.0 * inside
    flat = seam_jump(ramp, square)
    seam = seam_jump(np.stack([stepped, ramp], axis=2), square)  # the largest channel's jump counts
    assert flat.across_max == 1.0 and flat.elsewhere_max == 1.0 and flat.ratio == 1.0
    assert seam.across_max == 21.0 and seam.elsewhere_max == 1.0 and seam.ratio == 21.0
    assert seam.across.size == 2 * 26 + 2 * 25  # 26 rows and 25 columns of centres inside: pairs straddling each side
    d = seam.as_dict()
    assert d["pairs_across"] == 102 and d["across_mean"] > 19


def test_non_finite_values_are_left_out():
    v = np.zeros((5, 6))
    v[2, 3] = np.nan
    s = seam_jump(v, [[0.0, 0.0], [0.0, 5.0]], closed=False)
    assert np.isfinite(s.elsewhere).all() and s.elsewhere.size == 5 * 5 + 4 * 6 - 4
