"""Compiled (numba) inner loops of the resample stage: samplers and the final rounding.

Each kernel is the per-pixel loop that numpy could only express as many
full-image passes. They are called through `warpcli._native.Kernels`, which
compiles each once per argument types and then loads its machine code without
importing numba; numba's own cache (``cache=True``) serves the compilations.

Results never depend on the number of threads: every output pixel is
computed independently.
"""

from __future__ import annotations

import math

import numpy as np
from .._jit import njit


@njit(cache=True, nogil=True)
def _background_if_outside(x, y, w, h, background, out, n):
    """Write the background into out[n] if (x, y) is outside [0, w] x [0, h] (or NaN)."""
    if x >= 0.0 and x <= w and y >= 0.0 and y <= h:
        return False
    for ch in range(out.shape[1]):
        out[n, ch] = background[ch]
    return True


@njit(cache=True, nogil=True)
def sample_linear(img, x0, y0, w, h, xy, background, out):
    """Bilinear samples of a W x H image at continuous points ``xy`` (N, 2).

    ``img`` (rows, columns, C) holds the part of the image whose top-left
    pixel is column ``x0``, row ``y0`` (all of it: 0, 0, W, H); a part must
    hold every pixel the points reach (a pixel beyond it is read as the
    nearest one it holds, never outside the array). Pixel i has its centre at
    i + 0.5; beyond the outermost centres the edge pixels extend (like
    scipy.ndimage.map_coordinates with mode='nearest'). Points outside
    [0, W] x [0, H], or NaN, get ``background``.
    """
    nc = img.shape[2]
    for n in range(xy.shape[0]):
        x = xy[n, 0]
        y = xy[n, 1]
        if _background_if_outside(x, y, w, h, background, out, n):
            continue
        for ch in range(nc):
            out[n, ch] = _bilinear(img, x0, y0, w, h, x, y, ch)


@njit(cache=True, nogil=True)
def _held(img, x0, y0, i, j, ch):
    """Pixel (column i, row j) of the image from its part ``img`` at (x0, y0), clamped into the part."""
    return img[min(max(j - y0, 0), img.shape[0] - 1), min(max(i - x0, 0), img.shape[1] - 1), ch]


@njit(cache=True, nogil=True)
def _bilinear(img, x0, y0, w, h, x, y, ch):
    """Bilinear sample of channel ch at continuous (x, y); the edge pixels extend."""
    u = min(max(x - 0.5, 0.0), w - 1.0)
    v = min(max(y - 0.5, 0.0), h - 1.0)
    i0 = int(u)
    j0 = int(v)
    i1 = min(i0 + 1, w - 1)
    j1 = min(j0 + 1, h - 1)
    tu = u - i0
    tv = v - j0
    top = _held(img, x0, y0, i0, j0, ch) * (1.0 - tu) + _held(img, x0, y0, i1, j0, ch) * tu
    bottom = _held(img, x0, y0, i0, j1, ch) * (1.0 - tu) + _held(img, x0, y0, i1, j1, ch) * tu
    return top * (1.0 - tv) + bottom * tv


@njit(cache=True, nogil=True)
def sample_linear_aa(img, x0, y0, w, h, xy, jac, kmax, background, out, acc):  # noqa: C901
    """Bilinear samples averaged over each output pixel's footprint in the source.

    The footprint of output pixel n is the parallelogram ``J [-1/2, 1/2]^2``
    around its source point, J = ``jac[n]`` the Jacobian of the inverse map
    there (NaN: unknown, one sample). It is covered by a k_u x k_v grid of
    samples, k_u = ceil(|J e_u| - 0.3) (so samples are at most ~1.15 px
    apart, and a map that barely shrinks keeps one sharp sample), capped at
    ``kmax``; where the map magnifies, k = 1: plain bilinear. Points, and
    samples, outside the input's area take ``background``. A symmetric
    average of a linear function is its value at the centre: linear data is
    still reproduced exactly. ``acc`` is float64 scratch space of one value
    per channel (the kernels allocate nothing: see `warpcli._native`).
    ``img``, ``x0``, ``y0``, ``w``, ``h``: the image, or the part of it the
    samples reach, as in `sample_linear`.
    """
    nc = img.shape[2]
    for n in range(xy.shape[0]):
        x = xy[n, 0]
        y = xy[n, 1]
        if _background_if_outside(x, y, w, h, background, out, n):
            continue
        a = jac[n, 0, 0]
        b = jac[n, 0, 1]
        c = jac[n, 1, 0]
        d = jac[n, 1, 1]
        ku = 1
        kv = 1
        # |column| <= 1.3 (most pixels): one sample, no square root needed.
        # An unknown (NaN) Jacobian compares false: one sample.
        nu = a * a + c * c
        nv = b * b + d * d
        if nu > 1.69:
            ku = min(kmax, int(math.ceil(math.sqrt(nu) - 0.3)))
        if nv > 1.69:
            kv = min(kmax, int(math.ceil(math.sqrt(nv) - 0.3)))
        if ku == 1 and kv == 1:
            # One sample (most pixels): bilinear at the centre, straight into out.
            for ch in range(nc):
                out[n, ch] = _bilinear(img, x0, y0, w, h, x, y, ch)
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
                        acc[ch] += weight * _bilinear(img, x0, y0, w, h, sx, sy, ch)
                else:
                    for ch in range(nc):
                        acc[ch] += weight * background[ch]
        for ch in range(nc):
            out[n, ch] = acc[ch]


@njit(cache=True, nogil=True)
def sample_nearest(img, x0, y0, w, h, xy, background, out):
    """The pixel each point ``xy`` (N, 2) falls in (the border belongs to the edge
    pixels); ``background`` outside [0, W] x [0, H]. ``img``, ``x0``, ``y0``,
    ``w``, ``h``: the image, or the part of it the points reach, as in
    `sample_linear`."""
    nc = img.shape[2]
    for n in range(xy.shape[0]):
        x = xy[n, 0]
        y = xy[n, 1]
        if _background_if_outside(x, y, w, h, background, out, n):
            continue
        i = min(int(x), w - 1)
        j = min(int(y), h - 1)
        for ch in range(nc):
            out[n, ch] = _held(img, x0, y0, i, j, ch)



@njit(cache=True, nogil=True)
def near_border(xy, w, h, out):
    """Indices of the points ``xy`` (N, 2) within one unit of the border of [0, w] x [0, h].

    Those where ``min(x, w - x, y, h - y) < 1``, NaN never (NumPy's ``minimum``
    would carry it through), written to ``out`` in ascending order.

    Returns
    -------
    int
        How many were written.
    """
    count = 0
    for n in range(xy.shape[0]):
        x = xy[n, 0]
        y = xy[n, 1]
        if x != x or y != y:
            continue
        if x < 1.0 or w - x < 1.0 or y < 1.0 or h - y < 1.0:
            out[count] = n
            count += 1
    return count


@njit(cache=True, nogil=True)
def footprint_bounds(xy, jac, with_jac, out):
    """The least and greatest x and y that the footprints of samples at ``xy`` (N, 2) reach.

    A sample at a finite point (x, y) with Jacobian ``jac[n]`` (N, 2, 2;
    unread unless ``with_jac``) reaches x -+ ex and y -+ ey, where
    ex = (|J00| + |J01|) / 2 and ey = (|J10| + |J11|) / 2 (a NaN half-extent
    counts as 0, an infinite one stays infinite). Points with a NaN or
    infinite coordinate reach nothing. Writes ``out[:4]`` = (least x,
    greatest x, least y, greatest y) over the points that reach something,
    each bound clipped to ``[out[4], out[5]]`` for x and ``[out[6], out[7]]``
    for y as given on entry.

    Returns
    -------
    int
        How many points reach something (0: ``out[:4]`` unchanged).
    """
    xlo, xhi, ylo, yhi = out[4], out[5], out[6], out[7]
    count = 0
    min_x = max_x = min_y = max_y = 0.0
    for n in range(xy.shape[0]):
        x = xy[n, 0]
        y = xy[n, 1]
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ex = 0.0
        ey = 0.0
        if with_jac:
            ex = 0.5 * (abs(jac[n, 0, 0]) + abs(jac[n, 0, 1]))
            ey = 0.5 * (abs(jac[n, 1, 0]) + abs(jac[n, 1, 1]))
            if ex != ex:
                ex = 0.0
            if ey != ey:
                ey = 0.0
        lo_x = x - ex
        hi_x = x + ex
        lo_y = y - ey
        hi_y = y + ey
        if count == 0:
            min_x, max_x, min_y, max_y = lo_x, hi_x, lo_y, hi_y
        else:
            min_x = min(min_x, lo_x)
            max_x = max(max_x, hi_x)
            min_y = min(min_y, lo_y)
            max_y = max(max_y, hi_y)
        count += 1
    if count:
        out[0] = min(max(min_x, xlo), xhi)
        out[1] = min(max(max_x, xlo), xhi)
        out[2] = min(max(min_y, ylo), yhi)
        out[3] = min(max(max_y, ylo), yhi)
    return count


@njit(cache=True, nogil=True)
def store(values, out, lo, hi, integer):
    """out = values (both flat), rounded half to even and clipped to [lo, hi] when ``integer``."""
    for i in range(values.shape[0]):
        v = values[i]
        if integer:
            v = np.rint(v)
            if v < lo:
                v = lo
            elif v > hi:
                v = hi
        out[i] = v
