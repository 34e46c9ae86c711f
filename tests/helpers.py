"""Test geometry built in code: named polygons and small utilities."""

from __future__ import annotations

import json
import math

import numpy as np


def star(n: int = 6, cx: float = 64.0, cy: float = 64.0, r_in: float = 25.0, r_out: float = 58.0, phase: float = 0.0):
    """A 2n-vertex star (concave): outer points at even indices."""
    k = np.arange(2 * n)
    r = np.where(k % 2 == 0, r_out, r_in)
    a = phase + np.pi * k / n
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)


def regular(n: int, cx: float = 64.0, cy: float = 64.0, r: float = 58.0, phase: float = 0.0):
    a = phase + 2 * np.pi * np.arange(n) / n
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)


def l_shape(x0: float = 8.0, y0: float = 8.0, size: float = 112.0, notch: float = 0.5):
    """An L: a square with its top-right quadrant removed (one reflex vertex)."""
    s, m = size, size * notch
    return np.array(
        [[x0, y0], [x0 + m, y0], [x0 + m, y0 + m], [x0 + s, y0 + m], [x0 + s, y0 + s], [x0, y0 + s]],
        dtype=float,
    )


def comb(teeth: int = 4, x0: float = 8.0, y0: float = 8.0, width: float = 112.0, height: float = 112.0, depth: float = 0.6):
    """A comb: a bar along the bottom with ``teeth`` teeth pointing up."""
    pts = []
    tw = width / (2 * teeth - 1)
    top = y0
    base = y0 + height * depth
    for k in range(teeth):
        xa = x0 + 2 * k * tw
        pts += [[xa, top], [xa + tw, top], [xa + tw, base]]
        if k < teeth - 1:
            pts += [[xa + 2 * tw, base]]
    pts += [[x0 + width, y0 + height], [x0, y0 + height]]
    return np.array(pts, dtype=float)


def spiral(turns: float = 1.5, cx: float = 64.0, cy: float = 64.0, r0: float = 10.0, r1: float = 58.0, width: float = 10.0, samples: int = 40):
    """A thick spiral arm: outer curve out, inner curve back (strongly non-star-shaped)."""
    t = np.linspace(0.0, 1.0, samples)
    ang = 2 * math.pi * turns * t
    r = r0 + (r1 - r0) * t
    outer = np.stack([cx + (r + width / 2) * np.cos(ang), cy + (r + width / 2) * np.sin(ang)], axis=1)
    inner = np.stack([cx + (r - width / 2) * np.cos(ang), cy + (r - width / 2) * np.sin(ang)], axis=1)
    return np.concatenate([outer, inner[::-1]])


def similarity(points, scale: float = 1.0, angle: float = 0.0, shift=(0.0, 0.0), center=(64.0, 64.0)):
    """Apply x -> s R (x - c) + c + shift."""
    c = np.asarray(center, dtype=float)
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return (np.asarray(points, dtype=float) - c) @ rot.T * scale + c + np.asarray(shift, dtype=float)


def write_polygon(path, points) -> str:
    with open(path, "w") as fh:
        json.dump(np.asarray(points, dtype=float).tolist(), fh)
    return str(path)


def write_png(path, pixels) -> str:
    import OpenImageIO as oiio

    px = np.ascontiguousarray(pixels)
    if px.ndim == 2:
        px = px[:, :, None]
    h, w, c = px.shape
    types = {
        np.dtype(np.uint8): "uint8", np.dtype(np.uint16): "uint16", np.dtype(np.float32): "float", np.dtype(np.float16): "half",
        np.dtype(np.uint32): "uint",  # OpenImageIO's name: "uint32" is none of its names
    }  # fmt: skip
    out = oiio.ImageOutput.create(str(path))
    assert out is not None, oiio.geterror()
    assert out.open(str(path), oiio.ImageSpec(w, h, c, types[px.dtype]))
    assert out.write_image(px)
    out.close()
    return str(path)


def read_pixels(path):
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    px = inp.read_image(oiio.UNKNOWN)
    inp.close()
    return px if px.ndim == 3 else px[:, :, None]


def random_star(rng, cx: float = 60.0, cy: float = 60.0):
    """A generated star-shaped polygon's vertices, drawn from ``rng`` (a numpy Generator): 5 to 8 at
    sorted random angles, radii 20-45 px around (cx, cy)."""
    n = int(rng.integers(5, 9))
    th = np.sort(rng.uniform(0, 2 * np.pi, n))
    r = rng.uniform(20.0, 45.0, n)
    return np.stack([cx + r * np.cos(th), cy + r * np.sin(th)], axis=1)


def star_shaped(angles_gaps, radii, cx: float = 64.0, cy: float = 64.0, scale: float = 56.0):
    """A star-shaped polygon: vertex k at angle (cumulative gaps) and radius radii[k].

    Simple by construction: the angles increase strictly around the centre.
    """
    gaps = np.asarray(angles_gaps, dtype=float)
    a = np.cumsum(gaps) / gaps.sum() * 2 * math.pi
    r = np.asarray(radii, dtype=float)
    return np.stack([cx + scale * r * np.cos(a), cy + scale * r * np.sin(a)], axis=1)


def monotone_band(xs_top, ys_top, xs_bottom, ys_bottom, x0: float = 8.0, y0: float = 8.0, size: float = 112.0):
    """An x-monotone polygon: a top chain left to right over a bottom chain right to left.

    Simple by construction: both chains are x-monotone, share their end
    points' x, and the top chain's y (screen: smaller) stays above a line the
    bottom chain stays below. With deep notches from both sides it is not
    star-shaped. Arguments are in [0, 1]: x positions of the inner vertices
    of each chain (sorted here) and their heights (top in [0, 0.45], bottom in
    [0.55, 1] of ``size``).
    """
    xt = np.sort(np.asarray(xs_top, dtype=float))
    xb = np.sort(np.asarray(xs_bottom, dtype=float))[::-1]
    top = np.stack([xt, 0.45 * np.asarray(ys_top, dtype=float)], axis=1)
    bottom = np.stack([xb, 0.55 + 0.45 * np.asarray(ys_bottom, dtype=float)], axis=1)
    ends_top = np.array([[0.0, 0.45 * 0.5], [1.0, 0.45 * 0.5]])
    ends_bottom = np.array([[1.0, 0.55 + 0.45 * 0.5], [0.0, 0.55 + 0.45 * 0.5]])
    pts = np.concatenate([ends_top[:1], top, ends_top[1:], ends_bottom[:1], bottom, ends_bottom[1:]])
    return np.array([x0, y0]) + size * pts


def simple_polygons(n: int):
    """A hypothesis strategy of valid simple polygons with n >= 4 (or 3) vertices, built valid.

    Star-shaped ones (random angles and radii) and x-monotone bands with
    notches from both sides (generally not star-shaped), either orientation;
    no draw is rejected.
    """
    from hypothesis import strategies as st

    unit = st.floats(0.0, 1.0)

    def build(kind, gaps, radii, xs, ys, reverse):
        if kind == "star" or n < 4:
            pts = star_shaped(gaps, radii)
        else:
            k_top = (n - 4) // 2
            k_bot = n - 4 - k_top
            # Distinct x positions: a strictly increasing sequence from the draws.
            x = 0.02 + 0.96 * np.cumsum(np.asarray(xs) + 0.05)[: n - 4] / np.sum(np.asarray(xs) + 0.05)
            pts = monotone_band(x[:k_top], ys[:k_top], x[k_top:], ys[k_top : k_top + k_bot])
        return pts[::-1].copy() if reverse else pts

    return st.builds(
        build,
        st.sampled_from(["star", "band"]),
        st.lists(st.floats(0.2, 1.0), min_size=n, max_size=n),
        st.lists(st.floats(0.3, 1.0), min_size=n, max_size=n),
        st.lists(unit, min_size=n, max_size=n),
        st.lists(unit, min_size=n, max_size=n),
        st.booleans(),
    )


def run_cli(args):
    """Run the ``warp`` command in-process: (exit status, what it wrote on stderr)."""
    import contextlib
    import io

    from warpcli.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, err.getvalue()


_MAPS: dict = {}


def built_map(src, dst, options=None):
    """``BijectiveMap.between(Polygon(src), Polygon(dst), options)``, built once per test process.

    Many contract tests ask for the same pair with the same options (a pair's
    map, its identity, its symmetry); a map is a value that tests only
    evaluate, so each worker builds each one once. Keyed on the exact
    coordinates (bytes) and the options (a frozen dataclass); the 64 most
    recent are kept.
    """
    from warpcli import BijectiveMap, MapOptions, Polygon

    src, dst = np.ascontiguousarray(src, dtype=float), np.ascontiguousarray(dst, dtype=float)
    options = options or MapOptions()
    key = (src.shape, src.tobytes(), dst.shape, dst.tobytes(), options)
    if key not in _MAPS:
        if len(_MAPS) >= 64:
            _MAPS.pop(next(iter(_MAPS)))
        _MAPS[key] = BijectiveMap.between(Polygon(src), Polygon(dst), options)
    return _MAPS[key]
