"""The paper's §6: maps of successive steps compose to the map of the whole step, and moving
the vertices back restores the image (what animated polygons and --inverse rely on)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import built_map, l_shape, similarity, star
from warpcli import BijectiveMap, MapOptions, Polygon
from warpcli.grid import inside_polygon

PAIRS = {
    "star": (star(), star(r_in=18, phase=0.25), star(r_in=30, r_out=50, phase=-0.2)),
    "L": (l_shape(), similarity(l_shape(), 0.9, 0.3), l_shape(x0=14, size=100, notch=0.4)),
}


def _samples(poly, n=4000, seed=1):
    p = np.random.default_rng(seed).uniform(poly.min(axis=0), poly.max(axis=0), (n, 2))
    return p[inside_polygon(p, poly)]


@pytest.mark.parametrize("name", sorted(PAIRS))
@pytest.mark.parametrize("method", ["fem", "mfs"])
def test_steps_compose_to_the_whole_step(name, method):
    """f(B->C) o f(A->B) = f(A->C) for the exact maps (phi_C^-1 phi_B phi_B^-1 phi_A), and
    discretely too when the steps share Theta (here the regular n-gon): B is meshed and solved
    the same way in both steps, so phi_B^-1 phi_B cancels to the inverse's rounding (measured:
    below 1e-9 px). A Theta that depends on the pair (cyclic, optimized) breaks this."""
    a, b, c = (Polygon(p) for p in PAIRS[name])
    opts = MapOptions(method=method)
    # A -> B is also the first map of the next test: built once per test process (helpers.built_map).
    ab, bc, ac = built_map(a.points, b.points, opts), BijectiveMap.between(b, c, opts), BijectiveMap.between(a, c, opts)
    p = _samples(a.points)
    composed = bc.forward(ab.forward(p))
    direct = ac.forward(p)
    ok = np.isfinite(composed[:, 0])
    assert ok.mean() > 0.999
    assert np.abs(composed[ok] - direct[ok]).max() < 1e-6


@pytest.mark.parametrize("name", sorted(PAIRS))
@pytest.mark.parametrize("method", ["fem", "bem", "mfs"])
def test_moving_the_vertices_back_restores_every_point(name, method):
    """f(B->A) o f(A->B) = identity: with the same Theta both are built from the same two maps
    (measured: below 1e-9 px for FEM, BEM and MFS)."""
    a, b, _ = (Polygon(p) for p in PAIRS[name])
    opts = MapOptions(method=method)
    ab, ba = built_map(a.points, b.points, opts), BijectiveMap.between(b, a, opts)
    p = _samples(a.points, 1500)
    back = ba.forward(ab.forward(p))
    ok = np.isfinite(back[:, 0])
    assert ok.mean() > 0.999
    assert np.abs(back[ok] - p[ok]).max() < 1e-6


def test_warp_inverse_undoes_a_warp_from_the_cli(tmp_path):
    """warp A->B then warp --inverse with the same files: the image comes back inside A, to
    resampling accuracy (two bilinear passes on a smooth image)."""
    import contextlib
    import io

    from helpers import read_pixels, write_png, write_polygon
    from warpcli.cli import main

    y, x = np.mgrid[0:128, 0:128] / 127.0
    smooth = np.round(np.stack([200 * x + 20, 160 * y + 40, 100 + 80 * x * y], axis=2)).astype(np.uint8)
    img = write_png(tmp_path / "in.png", smooth)
    a, b, _ = PAIRS["star"]
    sa, sb = write_polygon(tmp_path / "a.json", a), write_polygon(tmp_path / "b.json", b)
    with contextlib.redirect_stderr(io.StringIO()):
        assert main([img, str(tmp_path / "fwd.png"), "--src", sa, "--dst", sb]) == 0
        assert main([str(tmp_path / "fwd.png"), str(tmp_path / "back.png"), "--src", sa, "--dst", sb, "--inverse"]) == 0
    back = read_pixels(tmp_path / "back.png").astype(int)
    core = _samples(a, 20000, seed=3)
    # pixels well inside A (2 px from its edge, where the forward warp had no antialiased edge)
    from warpcli.boundary import nearest_edge

    _, _, dist = nearest_edge(core, a)
    core = core[dist > 3]
    r, c = core[:, 1].astype(int), core[:, 0].astype(int)
    assert np.abs(back[r, c] - smooth[r, c].astype(int)).max() <= 3
