"""Compiled (numba) inner loops of the compose and resample stages.

Each kernel is the per-pixel loop that numpy could only express as dozens of
full-image passes: at 4 MP the composed inverse map takes 0.18 s here against
3.1 s vectorized (bench/). The kernels are cached on disk (``cache=True``:
beside this file, or in numba's user-wide cache directory when that is not
writable; ``NUMBA_CACHE_DIR`` overrides both), so only the first run compiles.

Results never depend on the number of threads: the compose kernel is serial,
and the resampling kernels compute every output pixel independently.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .locate import BARY_TOL

# Numba freezes module globals at compile time: the one tolerance, shared with
# the vectorized locator.
_TOL = BARY_TOL

#: ``status`` values written by `compose_grid`: outside the grid's mesh, found,
#: and walk abandoned (the point is handed back for a bucket search).
OUTSIDE, FOUND, LOST = 0, 1, 2


@njit(cache=True, nogil=True)
def _bary(coef, t, px, py):
    dx = px - coef[t, 0]
    dy = py - coef[t, 1]
    l1 = dx * coef[t, 2] + dy * coef[t, 3]
    l2 = dx * coef[t, 4] + dy * coef[t, 5]
    return 1.0 - l1 - l2, l1, l2


@njit(cache=True, nogil=True)
def compose_grid(
    v1, tri1, coef1, val1, order,
    tri0, coef0, nbr0, v0,
    max_steps, width, height, out, status, where0, where1,
):  # fmt: skip
    """Pull every pixel centre of the output grid back through phi0^-1 o phi1.

    Target triangles are scan-converted in the given ``order`` (spatially
    coherent, so that consecutive pixels are neighbours), a pixel centre on a
    shared edge going to the first triangle in that order. Its image
    theta = phi1(y) is then located in phi0's image mesh by a walk from the
    previous pixel's triangle, and x = phi0^-1(theta) is interpolated in the
    source mesh. The walk is Devillers' remembering stochastic walk: it
    crosses a randomly chosen edge that the point lies beyond, which cannot
    cycle even in a non-Delaunay mesh; the choices come from a fixed
    pseudo-random sequence, so results are deterministic.

    Writes ``out[p]`` = x and ``status[p]`` = FOUND; for a pixel outside the
    target, status OUTSIDE (out untouched); for a walk that leaves the mesh
    (theta a rounding error outside it) or exceeds ``max_steps`` (a rare
    cycle in a non-Delaunay mesh), status LOST and ``out[p]`` = theta, for
    the caller's bucket search.
    ``where1[p]`` and ``where0[p]`` receive the target and source triangles
    (the latter -1 when LOST), for the Jacobians of the map.
    """
    hint = 0
    rng = np.uint32(2463534242)
    for ii in range(order.shape[0]):
        i = order[ii]
        a = tri1[i, 0]
        b = tri1[i, 1]
        c = tri1[i, 2]
        xmin = min(v1[a, 0], v1[b, 0], v1[c, 0])
        xmax = max(v1[a, 0], v1[b, 0], v1[c, 0])
        ymin = min(v1[a, 1], v1[b, 1], v1[c, 1])
        ymax = max(v1[a, 1], v1[b, 1], v1[c, 1])
        pad = 1e-9 * max(width, height)
        c0 = max(int(math.ceil(xmin - 0.5 - pad)), 0)
        c1 = min(int(math.floor(xmax - 0.5 + pad)), width - 1)
        r0 = max(int(math.ceil(ymin - 0.5 - pad)), 0)
        r1 = min(int(math.floor(ymax - 0.5 + pad)), height - 1)
        for r in range(r0, r1 + 1):
            for col in range(c0, c1 + 1):
                pix = r * width + col
                if status[pix] != OUTSIDE:
                    continue
                l0, l1, l2 = _bary(coef1, i, col + 0.5, r + 0.5)
                if l0 < -_TOL or l1 < -_TOL or l2 < -_TOL:
                    continue
                where1[pix] = i
                thx = l0 * val1[a, 0] + l1 * val1[b, 0] + l2 * val1[c, 0]
                thy = l0 * val1[a, 1] + l1 * val1[b, 1] + l2 * val1[c, 1]
                t = hint
                found = -1
                for _ in range(max_steps):
                    m0, m1, m2 = _bary(coef0, t, thx, thy)
                    if m0 >= -_TOL and m1 >= -_TOL and m2 >= -_TOL:
                        found = t
                        break
                    # Edges the point lies beyond (negative coordinate); pick
                    # one of them with a xorshift draw.
                    rng ^= rng << np.uint32(13)
                    rng ^= rng >> np.uint32(17)
                    rng ^= rng << np.uint32(5)
                    first = int(rng % np.uint32(3))
                    k = -1
                    for j in range(3):
                        kk = (first + j) % 3
                        mk = m0 if kk == 0 else (m1 if kk == 1 else m2)
                        if mk < -_TOL:
                            k = kk
                            break
                    t = nbr0[t, k]
                    if t < 0:
                        break
                if found < 0:
                    status[pix] = LOST
                    out[pix, 0] = thx
                    out[pix, 1] = thy
                    continue
                hint = found
                where0[pix] = found
                m0, m1, m2 = _bary(coef0, found, thx, thy)
                p0 = tri0[found, 0]
                p1 = tri0[found, 1]
                p2 = tri0[found, 2]
                out[pix, 0] = m0 * v0[p0, 0] + m1 * v0[p1, 0] + m2 * v0[p2, 0]
                out[pix, 1] = m0 * v0[p0, 1] + m1 * v0[p1, 1] + m2 * v0[p2, 1]
                status[pix] = FOUND


@njit(cache=True, nogil=True)
def _background_if_outside(x, y, w, h, background, out, n):
    """Write the background into out[n] if (x, y) is outside [0, w] x [0, h] (or NaN)."""
    if x >= 0.0 and x <= w and y >= 0.0 and y <= h:
        return False
    for ch in range(out.shape[1]):
        out[n, ch] = background[ch]
    return True


@njit(cache=True, nogil=True)
def sample_linear(img, xy, background, out):
    """Bilinear samples of ``img`` (H, W, C) at continuous points ``xy`` (N, 2).

    Pixel i has its centre at i + 0.5; beyond the outermost centres the edge
    pixels extend (like scipy.ndimage.map_coordinates with mode='nearest').
    Points outside [0, W] x [0, H], or NaN, get ``background``.
    """
    h, w, nc = img.shape
    for n in range(xy.shape[0]):
        x = xy[n, 0]
        y = xy[n, 1]
        if _background_if_outside(x, y, w, h, background, out, n):
            continue
        for ch in range(nc):
            out[n, ch] = _bilinear(img, x, y, ch)


@njit(cache=True, nogil=True)
def _bilinear(img, x, y, ch):
    """Bilinear sample of channel ch at continuous (x, y); the edge pixels extend."""
    h, w, _ = img.shape
    u = min(max(x - 0.5, 0.0), w - 1.0)
    v = min(max(y - 0.5, 0.0), h - 1.0)
    i0 = int(u)
    j0 = int(v)
    i1 = min(i0 + 1, w - 1)
    j1 = min(j0 + 1, h - 1)
    tu = u - i0
    tv = v - j0
    top = img[j0, i0, ch] * (1.0 - tu) + img[j0, i1, ch] * tu
    bottom = img[j1, i0, ch] * (1.0 - tu) + img[j1, i1, ch] * tu
    return top * (1.0 - tv) + bottom * tv


@njit(cache=True, nogil=True)
def sample_linear_aa(img, xy, where0, where1, j0inv, j1, kmax, background, out):  # noqa: C901
    """Bilinear samples averaged over each output pixel's footprint in the source.

    The footprint of output pixel n is the parallelogram ``J [-1/2, 1/2]^2``
    around its source point, J = j0inv[where0[n]] @ j1[where1[n]] the
    Jacobian of the inverse map there. It is covered by a k_u x k_v grid of
    samples, k_u = ceil(|J e_u| - 0.3) (so samples are at most ~1.15 px
    apart, and a map that barely shrinks keeps one sharp sample), capped at
    ``kmax``; where the map magnifies, k = 1: plain bilinear. Points, and
    samples, outside the input's area take ``background``. A symmetric
    average of a linear function is its value at the centre: linear data is
    still reproduced exactly.
    """
    h, w, nc = img.shape
    acc = np.zeros(nc)
    for n in range(xy.shape[0]):
        x = xy[n, 0]
        y = xy[n, 1]
        if _background_if_outside(x, y, w, h, background, out, n):
            continue
        t0 = where0[n]
        t1 = where1[n]
        a = 0.0
        b = 0.0
        c = 0.0
        d = 0.0
        ku = 1
        kv = 1
        if t0 >= 0 and t1 >= 0:
            a = j0inv[t0, 0, 0] * j1[t1, 0, 0] + j0inv[t0, 0, 1] * j1[t1, 1, 0]
            b = j0inv[t0, 0, 0] * j1[t1, 0, 1] + j0inv[t0, 0, 1] * j1[t1, 1, 1]
            c = j0inv[t0, 1, 0] * j1[t1, 0, 0] + j0inv[t0, 1, 1] * j1[t1, 1, 0]
            d = j0inv[t0, 1, 0] * j1[t1, 0, 1] + j0inv[t0, 1, 1] * j1[t1, 1, 1]
            # |column| <= 1.3 (most pixels): one sample, no square root needed.
            nu = a * a + c * c
            nv = b * b + d * d
            if nu > 1.69:
                ku = min(kmax, int(math.ceil(math.sqrt(nu) - 0.3)))
            if nv > 1.69:
                kv = min(kmax, int(math.ceil(math.sqrt(nv) - 0.3)))
        if ku == 1 and kv == 1:
            # One sample (most pixels): bilinear at the centre, straight into out.
            for ch in range(nc):
                out[n, ch] = _bilinear(img, x, y, ch)
            continue
        for ch in range(nc):
            acc[ch] = 0.0
        weight = 1.0 / (ku * kv)
        for i in range(ku):
            su = (i + 0.5) / ku - 0.5
            for j in range(kv):
                sv = (j + 0.5) / kv - 0.5
                sx = x + a * su + b * sv
                sy = y + c * su + d * sv
                if sx >= 0.0 and sx <= w and sy >= 0.0 and sy <= h:
                    for ch in range(nc):
                        acc[ch] += weight * _bilinear(img, sx, sy, ch)
                else:
                    for ch in range(nc):
                        acc[ch] += weight * background[ch]
        for ch in range(nc):
            out[n, ch] = acc[ch]


@njit(cache=True, nogil=True)
def sample_nearest(img, xy, background, out):
    """The pixel each point ``xy`` (N, 2) falls in (the border belongs to the edge
    pixels); ``background`` outside [0, W] x [0, H]."""
    h, w, nc = img.shape
    for n in range(xy.shape[0]):
        x = xy[n, 0]
        y = xy[n, 1]
        if _background_if_outside(x, y, w, h, background, out, n):
            continue
        i = min(int(x), w - 1)
        j = min(int(y), h - 1)
        for ch in range(nc):
            out[n, ch] = img[j, i, ch]



@njit(cache=True, nogil=True)
def store(values, out, lo, hi, integer):
    """out = values, rounded half to even and clipped to [lo, hi] when ``integer``."""
    flat_in = values.reshape(-1)
    flat_out = out.reshape(-1)
    for i in range(flat_in.shape[0]):
        v = flat_in[i]
        if integer:
            v = np.rint(v)
            if v < lo:
                v = lo
            elif v > hi:
                v = hi
        flat_out[i] = v


def warm_up() -> None:
    """Load (or compile) the compose kernel on tiny inputs.

    The first call of a numba function in a process costs ~0.3 s even from the
    cache (numba loads its typing registries); BijectiveMap.between runs this
    while SuperLU, which releases the GIL, solves the two maps: 1 MP warp
    median 1.21 s vs 1.33 s without (10 interleaved runs). The samplers then
    load in a few milliseconds each, for whatever image type comes.
    """
    v = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])
    tri = np.array([[0, 1, 2]], dtype=np.int64)
    coef = np.array([[0.0, 0.0, 0.5, 0.0, 0.0, 0.5]])
    nbr = np.full((1, 3), -1, dtype=np.int64)
    where = np.full(4, -1, dtype=np.int32)
    order = np.zeros(1, dtype=np.int64)
    compose_grid(
        v, tri, coef, v, order, tri, coef, nbr, v, 8, 2, 2, np.empty((4, 2)), np.zeros(4, dtype=np.int8),
        where, where.copy(),
    )  # fmt: skip
