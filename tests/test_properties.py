"""Property tests over random simple polygon pairs (hypothesis), and convergence."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import simple_polygons, star
from warpcli import BijectiveMap, Polygon


@st.composite
def pairs(draw):
    """Two valid polygons with the same vertex count, built valid (see helpers.simple_polygons)."""
    n = draw(st.integers(3, 60))
    return Polygon(draw(simple_polygons(n))), Polygon(draw(simple_polygons(n)))


# 15 pairs (derandomized): both kinds of polygon (star-shaped, notched bands), both orientations
# and 3 to 60 vertices are all drawn; the next 15 drew more of the same (0.3 s of CPU each).
@given(pairs())
@settings(max_examples=15)
def test_random_pairs_are_bijective_and_respect_the_boundary(pair):
    src, dst = pair
    f = BijectiveMap.between(src, dst)
    assert f.flipped_triangles() == 0
    # Vertices and edges: parameter t on source edge i goes to t on target edge i.
    # Every edge's points in one call each way (the same points and bounds as edge by edge).
    t = np.array([0.0, 0.3, 0.7])[None, :, None]
    p0, p1 = np.asarray(src.points, float), np.asarray(dst.points, float)
    on0 = (p0[:, None] + t * (np.roll(p0, -1, axis=0) - p0)[:, None]).reshape(-1, 2)
    on1 = (p1[:, None] + t * (np.roll(p1, -1, axis=0) - p1)[:, None]).reshape(-1, 2)
    np.testing.assert_allclose(f.forward(on0), on1, atol=1e-7)
    np.testing.assert_allclose(f.inverse(on1), on0, atol=1e-7)
    # Inside: forward(inverse(q)) == q, at pixel centres inside the target.
    from warpcli.grid import inside_polygon, pixel_centres

    q = pixel_centres(128, 128)
    q = q[inside_polygon(q, dst.points)][::7]
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
