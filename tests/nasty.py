"""Nasty polygons for the smooth maps' certificate, and an independent dense check of det J.

The shapes are the classes where BEM and MFS approximations fold: thin
spikes, slots, rings with a gap, combs, wavy many-gons, zigzags. Each
generator takes a seeded ``numpy.random.Generator`` so a test can draw
several of a class. `dense_check` samples a map far more densely than its
certificate, where folds live (a uniform grid, bands 0.01-3 px inside every
edge, polar grids around every vertex), with its own code: only the closed
form's public ``value_and_jacobian`` is shared with the certificate.
"""

from __future__ import annotations

import numpy as np

from warpcli.grid import inside_polygon


def _circle(r, th, centre=(0.0, 0.0)):
    return np.stack([centre[0] + r * np.cos(th), centre[1] + r * np.sin(th)], axis=1)


def spikes(rng: np.random.Generator, size: float = 300.0) -> np.ndarray:
    """A star with k thin spikes: tips at R, valleys at r, each spike a few degrees wide."""
    k = int(rng.integers(5, 10))
    R, r = size / 2, size / 2 * rng.uniform(0.2, 0.35)
    half = rng.uniform(0.015, 0.04)  # the spike's half-width at its base, radians
    out = []
    for i in range(k):
        a = 2 * np.pi * i / k
        out += [(r, a - half), (R, a), (r, a + half)]
    rr, th = np.array(out).T
    return _circle(rr, th)


def slot(rng: np.random.Generator, size: float = 300.0) -> np.ndarray:
    """A square with a 2-4 px wide slot cut from one side to past the middle."""
    g = rng.uniform(2.0, 4.0)
    depth = size * rng.uniform(0.55, 0.8)
    y = size * rng.uniform(0.35, 0.65)
    return np.array(
        [[0, 0], [size, 0], [size, y - g / 2], [size - depth, y - g / 2], [size - depth, y + g / 2],
         [size, y + g / 2], [size, size], [0, size]], dtype=float,
    )  # fmt: skip


def ring_gap(rng: np.random.Generator, size: float = 300.0, thick: float | None = None, k: int | None = None) -> np.ndarray:
    """A ring cut open by a 2-3 px gap (a C whose ends nearly touch)."""
    R = size / 2
    r = R - (thick if thick is not None else R * rng.uniform(0.25, 0.45))
    g = rng.uniform(2.0, 3.0)
    k = int(rng.integers(12, 24)) if k is None else k
    a_out, a_in = np.arcsin(g / 2 / R), np.arcsin(g / 2 / r)
    outer = _circle(R, np.linspace(a_out, 2 * np.pi - a_out, k))
    inner = _circle(r, np.linspace(2 * np.pi - a_in, a_in, k))
    return np.concatenate([outer, inner])


def c_shape(n_outer: int, n_inner: int, size: float = 300.0) -> np.ndarray:
    """A thick C (an open ring with a wide mouth), n_outer + n_inner vertices: a ring's partner."""
    R, r = size / 2, size / 4
    outer = _circle(R, np.linspace(0.5, 2 * np.pi - 0.5, n_outer))
    inner = _circle(r, np.linspace(2 * np.pi - 0.8, 0.8, n_inner))
    return np.concatenate([outer, inner])


def comb(rng: np.random.Generator, size: float = 300.0) -> np.ndarray:
    """A comb: a spine and k teeth 3-8 px wide with 2-5 px gaps."""
    k = int(rng.integers(5, 9))
    w, g = rng.uniform(3.0, 8.0), rng.uniform(2.0, 5.0)
    h = size * rng.uniform(0.5, 0.8)
    spine = size * 0.2
    pts = [[0.0, 0.0]]
    x = 0.0
    for i in range(k):
        pts += [[x, -h], [x + w, -h], [x + w, 0.0]]
        x += w
        if i < k - 1:
            pts.append([x + g, 0.0])
            x += g
    pts += [[x, spine], [0.0, spine]]
    p = np.array(pts[1:])  # the first tooth starts at the origin
    return p


def wavy(rng: np.random.Generator, size: float = 300.0) -> np.ndarray:
    """A wavy many-gon: r = R (1 + a sin(k theta)) with 120-240 vertices."""
    n = int(rng.integers(120, 241))
    k = int(rng.integers(8, 20))
    a = rng.uniform(0.08, 0.2)
    th = 2 * np.pi * np.arange(n) / n
    return _circle(size / 2 * (1 + a * np.sin(k * th)), th)


def zigzag(rng: np.random.Generator, size: float = 300.0) -> np.ndarray:
    """A zigzag band: k sharp teeth above and below."""
    k = int(rng.integers(4, 8))
    amp = size * rng.uniform(0.2, 0.4)
    thick = size * rng.uniform(0.05, 0.12)
    x = np.linspace(0.0, size, 2 * k + 1)
    y = np.where(np.arange(2 * k + 1) % 2 == 0, 0.0, amp)
    return np.concatenate([np.stack([x, y], 1), np.stack([x[::-1], y[::-1] + thick], 1)])


def star_like(rng: np.random.Generator, size: float = 300.0) -> np.ndarray:
    """A milder case: a star-shaped polygon of 6-14 vertices, radii 0.45-1 of R (reflex corners, no slivers)."""
    n = int(rng.integers(6, 15))
    th = 2 * np.pi * (np.arange(n) + 0.5 * rng.uniform(-0.6, 0.6, n)) / n
    return _circle(size / 2 * rng.uniform(0.45, 1.0, n), th)


SHAPES = {
    "spikes": spikes, "slot": slot, "ring_gap": ring_gap, "comb": comb, "wavy": wavy, "zigzag": zigzag, "star_like": star_like,
}


def _segments(v: np.ndarray):
    a = v
    b = np.roll(v, -1, axis=0)
    e = b - a
    length = np.hypot(*e.T)
    inward = np.stack([-e[:, 1], e[:, 0]], 1) / length[:, None]
    area2 = np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
    return a, e, length, inward * np.sign(area2)


def dense_samples(v: np.ndarray, grid: int = 300_000, along: float = 0.1, corner_rings: int = 24) -> np.ndarray:
    """Points inside polygon v: a uniform grid of about ``grid`` points, bands at 16 distances
    0.01-3 px inside every edge every ``along`` px, and polar grids (``corner_rings`` radii
    0.01-5 px, 96 angles) around every vertex."""
    lo, hi = v.min(0), v.max(0)
    area = abs(0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
    h = np.sqrt(area / grid)
    xs, ys = np.arange(lo[0] + h / 3, hi[0], h), np.arange(lo[1] + h / 3, hi[1], h)
    parts = [np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)]
    a, e, length, inward = _segments(v)
    dist = np.geomspace(0.01, 3.0, 16)
    for i in range(len(v)):  # loop over edges
        t = (np.arange(max(2, int(length[i] / along))) + 0.5) / max(2, int(length[i] / along))
        base = a[i] + t[:, None] * e[i]
        parts.append((base[:, None, :] + dist[None, :, None] * inward[i]).reshape(-1, 2))
    rad = np.geomspace(0.01, 5.0, corner_rings)
    ang = 2 * np.pi * (np.arange(96) + 0.5) / 96
    ring = (rad[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], -1)[None]).reshape(-1, 2)
    parts += [p + ring for p in v]
    pts = np.concatenate(parts)
    return pts[inside_polygon(pts, v)]


def dense_check(phi, samples: np.ndarray | None = None) -> dict:
    """Where a smooth map onto Theta folds or leaves Theta, at `dense_samples` of its polygon.

    Parameters
    ----------
    phi : warpcli.maps.meshless.SmoothMap
        Its values and Jacobians as accepted: the collar's in its band.
    samples : (K, 2) ndarray, optional
        The points (default `dense_samples`).

    Returns
    -------
    dict
        ``samples``, ``folds`` (det J <= 0 relative to the orientation, or not
        finite), ``outside`` (the value outside Theta by more than 1e-9 of its
        size), ``worst`` (the point of the smallest oriented det J).
    """
    v = phi.polygon.points
    p = dense_samples(v) if samples is None else samples
    size = float(np.ptp(v, axis=0).max())
    # the closed form is the map only strictly inside (to rounding): what evaluate does
    from warpcli.boundary import nearest_edge

    p, dist = p[nearest_edge(p, v)[2] > 1e-9 * size], nearest_edge(p, v)[2]
    dist = dist[dist > 1e-9 * size]
    # the map as accepted: the closed form, and the collar in its band (`SmoothMap.collar`); the
    # values unclamped (evaluate clamps onto Theta), to see any excursion
    j = phi.evaluate(p, jacobian=True).jacobian
    val = phi.solution.value(p)
    collar = phi.collar
    if collar is not None:
        band = np.flatnonzero(dist <= collar.band_width)
        band = band[~collar.inside(p[band])]
        val[band] = collar.evaluate(p[band])[0]
    sign = phi.theta.orientation * np.sign(phi.polygon.signed_area)
    det = sign * (j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0])
    folds = ~(det > 0)
    w = phi.theta.points
    d = np.roll(w, -1, axis=0) - w
    tscale = float(np.ptp(w, axis=0).max())
    outside = np.zeros(len(p), bool)
    for i in range(len(w)):  # convex Theta: outside iff beyond some edge
        cross = (d[i, 0] * (val[:, 1] - w[i, 1]) - d[i, 1] * (val[:, 0] - w[i, 0])) / np.hypot(*d[i])
        outside |= cross * phi.theta.orientation < -1e-9 * tscale
    k_out = np.flatnonzero(outside)
    deep = 0
    if k_out.size:
        # how far the point must move for its value to come back onto each
        # crossed edge line: the excursion over the gradient of n . phi
        shift = np.zeros(k_out.size)
        for i in range(len(w)):
            n = np.array([d[i, 1], -d[i, 0]]) / np.hypot(*d[i]) * phi.theta.orientation
            e = ((val[k_out] - w[i]) @ n)
            g = np.hypot(*(j[k_out, 0, :] * n[0] + j[k_out, 1, :] * n[1]).T)
            with np.errstate(divide="ignore", invalid="ignore"):
                shift = np.where(e > 1e-9 * tscale, np.fmax(shift, e / g), shift)
        shift = nearest_edge(p[k_out], v)[2] + shift
        deep = int((~(shift <= min(1.0, 4e-3 * size))).sum())
    k = int(np.nanargmin(np.where(np.isfinite(det), det, -np.inf)))
    return {
        "samples": len(p), "folds": int(folds.sum()), "outside": int(outside.sum()), "deep": deep,
        "worst": p[k], "min_det": float(det[k]),
    }  # fmt: skip
