"""Property tests over random simple polygon pairs (hypothesis), and convergence."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from helpers import star
from warpcli import BijectiveMap, Polygon, PolygonError


@st.composite
def polygons(draw, n: int):
    """A random simple polygon with n vertices in a 128 px square: star-shaped,
    or a star-shaped one swirled (x -> rotation by an angle growing with the
    radius), which is generally not star-shaped; either orientation."""
    gaps = np.array(draw(st.lists(st.floats(0.2, 1.0), min_size=n, max_size=n)))
    angles = np.cumsum(gaps) / gaps.sum() * 2 * math.pi
    radii = np.array(draw(st.lists(st.floats(0.3, 1.0), min_size=n, max_size=n)))
    swirl = draw(st.sampled_from([0.0, 0.0, 1.5, 3.0]))
    a = angles + swirl * radii**2
    pts = np.stack([64 + 56 * radii * np.cos(a), 64 + 56 * radii * np.sin(a)], axis=1)
    if draw(st.booleans()):
        pts = pts[::-1]
    try:
        return Polygon(pts)
    except PolygonError:
        assume(False)


@st.composite
def pairs(draw):
    n = draw(st.integers(3, 60))
    return draw(polygons(n)), draw(polygons(n))


@given(pairs())
@settings(max_examples=30)
def test_random_pairs_are_bijective_and_respect_the_boundary(pair):
    src, dst = pair
    f = BijectiveMap.between(src, dst)
    assert f.flipped_triangles() == 0
    n = src.n
    # Vertices and edges: parameter t on source edge i goes to t on target edge i.
    t = np.array([0.0, 0.3, 0.7])
    for i in range(n):
        a0, b0 = src.points[i], src.points[(i + 1) % n]
        a1, b1 = dst.points[i], dst.points[(i + 1) % n]
        on0 = a0 + t[:, None] * (b0 - a0)
        on1 = a1 + t[:, None] * (b1 - a1)
        np.testing.assert_allclose(f.forward(on0), on1, atol=1e-7)
        np.testing.assert_allclose(f.inverse(on1), on0, atol=1e-7)
    # Inside: forward(inverse(q)) == q, at the centroids of the target mesh.
    mesh = f.phi1.mesh
    q = mesh.vertices[mesh.triangles].mean(axis=1)[:: max(1, mesh.n_triangles // 500)]
    back = f.forward(f.inverse(q))
    np.testing.assert_allclose(back, q, atol=1e-7)


def _error_against(f: BijectiveMap, ref: BijectiveMap, size: int = 128) -> float:
    a = f.inverse_grid(size, size)
    b = ref.inverse_grid(size, size)
    ok = np.isfinite(a[..., 0]) & np.isfinite(b[..., 0])
    return float(np.hypot(*(a[ok] - b[ok]).T).mean())


def test_map_converges_as_the_mesh_refines():
    """Mean error against a 1/16 px^2 reference falls like the area bound (rate -> 1)."""
    src = Polygon(star(r_in=25, r_out=58))
    dst = Polygon(star(r_in=18, r_out=57, phase=0.3))
    ref = BijectiveMap.between(src, dst, max_area=0.0625)
    areas = (4.0, 1.0, 0.25)
    errors = [_error_against(BijectiveMap.between(src, dst, max_area=a), ref) for a in areas]
    assert errors[0] > errors[1] > errors[2]
    rates = [math.log(errors[k] / errors[k + 1]) / math.log(areas[k] / areas[k + 1]) for k in range(2)]
    # P1 FEM converges like h^2, i.e. like the area bound (rate 1); measured
    # here 0.67 then 0.83, approaching 1 as the mesh refines.
    assert rates[0] > 0.5 and rates[1] > 0.7 and rates[1] > rates[0], rates


@pytest.mark.parametrize("weights", ["cotan", "positive"])
def test_swirled_non_star_shaped_pair(weights):
    k = np.arange(60)
    r = np.where(k % 2 == 0, 1.0, 0.5)
    a = 2 * math.pi * k / 60 + 1.2 * r**2
    swirl = Polygon(np.stack([64 + 56 * r * np.cos(a), 64 + 56 * r * np.sin(a)], axis=1))
    plain = Polygon(star(n=30, r_in=30, r_out=56))
    f = BijectiveMap.between(swirl, plain, weights=weights)
    assert f.flipped_triangles() == 0
