"""Compiled (numba) kernels of the closed-form methods: the branch-free log, MFS's sum over sites.

Called through `warpcli._native.Kernels` (cached machine code, numba never
imported in a process that finds them compiled): importing numba and
loading its cached functions cost about 1 s of CPU in every MFS warp (measured
at 80 x 64 pixels: 1.2 s against FEM's 0.45 s), more than evaluating the map
at a megapixel. Kept apart from `warpcli.maps.mfs` and
`warpcli.maps.closed_form`, which import no numba.
"""

from __future__ import annotations

import numpy as np
from numba import types
from numba.extending import intrinsic

from .._jit import njit

__all__ = ["fast_log", "inside_points", "mfs_bounds", "mfs_evaluate", "near_boundary"]


@intrinsic
def _f64_as_i64(typingctx, x):  # noqa: ARG001 - numba intrinsic signature
    """Reinterpret the bits of a float64 as int64 (numba intrinsic)."""
    sig = types.int64(types.float64)

    def codegen(context, builder, signature, args):  # noqa: ARG001
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return sig, codegen


@intrinsic
def _i64_as_f64(typingctx, x):  # noqa: ARG001
    """Reinterpret the bits of an int64 as float64 (numba intrinsic)."""
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):  # noqa: ARG001
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return sig, codegen


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def fast_log(q):
    """Natural log of a positive, normal float64, branch-free so that loops vectorise.

    q = 2^e f with f in [sqrt(1/2), sqrt(2)); log f = 2 atanh(s), s = (f-1)/(f+1),
    |s| < 0.172, summed to s^19: relative error < 3e-16 (numba has no
    vectorised log without Intel SVML; this one is ~4x faster in SIMD loops).
    Compiled (numba) and inlined into the compiled evaluation loops of BEM
    and MFS.

    Parameters
    ----------
    q : float
        Positive and normal.

    Returns
    -------
    float
    """
    bits = _f64_as_i64(q)
    e = np.float64((bits >> 52) - 1023)
    f = _i64_as_f64((bits & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000)
    big = f > 1.4142135623730951
    f = 0.5 * f if big else f
    e = e + 1.0 if big else e
    s = (f - 1.0) / (f + 1.0)
    s2 = s * s
    p = 1.0 / 19.0
    p = p * s2 + 1.0 / 17.0
    p = p * s2 + 1.0 / 15.0
    p = p * s2 + 1.0 / 13.0
    p = p * s2 + 1.0 / 11.0
    p = p * s2 + 1.0 / 9.0
    p = p * s2 + 1.0 / 7.0
    p = p * s2 + 1.0 / 5.0
    p = p * s2 + 1.0 / 3.0
    p = p * s2 + 1.0
    return e * 0.6931471805599453 + 2.0 * s * p



#: Floating-point flags of the evaluation kernel: reassociation lets LLVM
#: vectorise the sums over sites (the order of the additions then depends on
#: the SIMD width of the machine: results are deterministic on a machine, and
#: agree across machines to rounding); contraction allows fused multiply-adds.
_FASTMATH = {"reassoc", "contract"}


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def mfs_evaluate(px, py, sx, sy, w0, w1, want_val, want_jac, want_hess, val, jac, hess):
    """Sum w_i log|z - s_i| and its derivatives over the sites, for every point.

    One loop over points, and inside it a branch-free loop over sites per
    requested quantity, which LLVM vectorises (the log is `fast_log` for
    that reason).  With F(z) = sum_i w_i log(z - s_i): value = Re F,
    gradient = (Re F', -Im F') with F' = sum w_i / (z - s_i), and
    phi_xx = -phi_yy = Re F'', phi_xy = -Im F'' with F'' = -sum w_i / (z - s_i)^2.
    """
    K = px.shape[0]
    m = sx.shape[0]
    for k in range(K):
        x = px[k]
        y = py[k]
        if want_val and want_jac:
            v0 = 0.0
            v1 = 0.0
            a00 = 0.0
            a01 = 0.0
            a10 = 0.0
            a11 = 0.0
            for i in range(m):
                dx = x - sx[i]
                dy = y - sy[i]
                r2 = dx * dx + dy * dy
                lg = fast_log(r2)
                inv = 1.0 / r2
                gx = dx * inv
                gy = dy * inv
                v0 += w0[i] * lg
                v1 += w1[i] * lg
                a00 += w0[i] * gx
                a01 += w0[i] * gy
                a10 += w1[i] * gx
                a11 += w1[i] * gy
            val[k, 0] = 0.5 * v0
            val[k, 1] = 0.5 * v1
            jac[k, 0, 0] = a00
            jac[k, 0, 1] = a01
            jac[k, 1, 0] = a10
            jac[k, 1, 1] = a11
        elif want_val:
            v0 = 0.0
            v1 = 0.0
            for i in range(m):
                dx = x - sx[i]
                dy = y - sy[i]
                lg = fast_log(dx * dx + dy * dy)
                v0 += w0[i] * lg
                v1 += w1[i] * lg
            val[k, 0] = 0.5 * v0
            val[k, 1] = 0.5 * v1
        elif want_jac:
            a00 = 0.0
            a01 = 0.0
            a10 = 0.0
            a11 = 0.0
            for i in range(m):
                dx = x - sx[i]
                dy = y - sy[i]
                inv = 1.0 / (dx * dx + dy * dy)
                gx = dx * inv
                gy = dy * inv
                a00 += w0[i] * gx
                a01 += w0[i] * gy
                a10 += w1[i] * gx
                a11 += w1[i] * gy
            jac[k, 0, 0] = a00
            jac[k, 0, 1] = a01
            jac[k, 1, 0] = a10
            jac[k, 1, 1] = a11
        if want_hess:
            h0r = 0.0
            h0i = 0.0
            h1r = 0.0
            h1i = 0.0
            for i in range(m):
                dx = x - sx[i]
                dy = y - sy[i]
                inv = 1.0 / (dx * dx + dy * dy)
                ur = dx * inv  # u = 1/(z - s)
                ui = -dy * inv
                u2r = ur * ur - ui * ui
                u2i = 2.0 * ur * ui
                h0r -= w0[i] * u2r
                h0i -= w0[i] * u2i
                h1r -= w1[i] * u2r
                h1i -= w1[i] * u2i
            hess[k, 0, 0, 0] = h0r
            hess[k, 0, 0, 1] = -h0i
            hess[k, 0, 1, 0] = -h0i
            hess[k, 0, 1, 1] = -h0r
            hess[k, 1, 0, 0] = h1r
            hess[k, 1, 0, 1] = -h1i
            hess[k, 1, 1, 0] = -h1i
            hess[k, 1, 1, 1] = -h1r


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def mfs_bounds(px, py, reach, sx, sy, ar, ai, br, bi, rho, const, out):
    """Per disc (centre p, radius r): the evaluation error of A and B at p and bounds of their Taylor remainders.

    A(z) = sum_i alpha_i / (z - s_i) + a0, B the same with beta_i (|alpha_i| =
    |beta_i| = ``rho[i]``), so A^(k)(z) = (-1)^k k! sum_i alpha_i / (z -
    s_i)^(k+1). Over the disc (|z - s_i| >= d_i - r, d_i = |p - s_i|):

        |A(p + h) - A(p) - A'(p) h| <= |A''(p)| r^2 / 2 + |A^(3)(p)| r^3 / 6
                                       + sum_i rho_i r^4 / (d_i - r)^5,

    the last the Lagrange remainder of order 4 (4! / 4! sum rho_i / (d_i -
    r)^5). A''(p) and A^(3)(p) are summed exactly: the weights cancel (their
    absolute sums are 1e3-1e4 times the derivatives, measured), so the sum
    of absolute values enters only at order 4, where r / (d_i - r) is small.
    Rounding: (m + 1) eps times 2 the absolute sums, at every order.
    """
    K = px.shape[0]
    m = sx.shape[0]
    eps = 2.220446049250313e-16
    for k in range(K):
        r = reach[k]
        t0 = const
        t2 = 0.0
        t3 = 0.0
        t4 = 0.0
        a2r = 0.0
        a2i = 0.0
        a3r = 0.0
        a3i = 0.0
        b2r = 0.0
        b2i = 0.0
        b3r = 0.0
        b3i = 0.0
        for i in range(m):
            dx = px[k] - sx[i]
            dy = py[k] - sy[i]
            d2 = dx * dx + dy * dy
            d = np.sqrt(d2)
            inv = 1.0 / d2
            ur = dx * inv  # u = 1 / (z - s)
            ui = -dy * inv
            u2r = ur * ur - ui * ui
            u2i = 2.0 * ur * ui
            u3r = u2r * ur - u2i * ui
            u3i = u2r * ui + u2i * ur
            u4r = u3r * ur - u3i * ui
            u4i = u3r * ui + u3i * ur
            # A'' = 2 sum alpha u^3, A^(3) = -6 sum alpha u^4 (moduli below)
            a2r += ar[i] * u3r - ai[i] * u3i
            a2i += ar[i] * u3i + ai[i] * u3r
            a3r += ar[i] * u4r - ai[i] * u4i
            a3i += ar[i] * u4i + ai[i] * u4r
            b2r += br[i] * u3r - bi[i] * u3i
            b2i += br[i] * u3i + bi[i] * u3r
            b3r += br[i] * u4r - bi[i] * u4i
            b3i += br[i] * u4i + bi[i] * u4r
            t0 += rho[i] * inv * d
            t2 += rho[i] * inv * inv * d
            t3 += rho[i] * inv * inv
            # branch-free (the loop vectorises): a disc reaching the site gives 1/0 = inf
            g = max(d - r, 0.0)
            g2 = g * g
            t4 += rho[i] / (g2 * g2 * g)
        rnd = 2.0 * (m + 1) * eps
        r2 = r * r
        r3 = r2 * r
        # |A''| r^2 / 2 = |sum alpha u^3| r^2, |A^(3)| r^3 / 6 = |sum alpha u^4| r^3
        common = rnd * (t2 * r2 + t3 * r3) + t4 * r2 * r2
        out[k, 0] = rnd * t0
        out[k, 1] = np.hypot(a2r, a2i) * r2 + np.hypot(a3r, a3i) * r3 + common
        out[k, 2] = np.hypot(b2r, b2i) * r2 + np.hypot(b3r, b3i) * r3 + common


@njit(cache=True, nogil=True, error_model="numpy")
def _inside(x, y, vx, vy):
    """Even-odd test of one point against a polygon: `warpcli.grid.inside_polygon`'s arithmetic."""
    n = vx.shape[0]
    inside = False
    for i in range(n):
        x0 = vx[i]
        y0 = vy[i]
        x1 = vx[(i + 1) % n]
        y1 = vy[(i + 1) % n]
        if (y0 > y) != (y1 > y):
            xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
            if x < xc:
                inside = not inside
    return inside


@njit(cache=True, nogil=True, error_model="numpy")
def inside_points(px, py, vx, vy, out):
    """`_inside` for every point: `warpcli.grid.inside_polygon`'s booleans, without its numpy pass per edge.

    For the few points of a line search against a polygon of many edges (the
    collar's Gamma: about 100), where numpy's passes cost ~1.8 ms a call
    whatever the number of points.
    """
    for k in range(px.shape[0]):
        out[k] = _inside(px[k], py[k], vx, vy)


@njit(cache=True, nogil=True, error_model="numpy")
def near_boundary(px, py, vx, vy, reach, out):
    """``out[k]`` = 1 where point k may lie within ``reach`` of the polygon's boundary (vx, vy), else 0.

    A superset of `warpcli.boundary.nearest_edge`'s ``distance <= reach``:
    the same distance (clamped projection onto each edge, then the
    hypotenuse), with a margin of 1e-12 times the coordinates' size for its
    rounding (numpy's dot product may fuse a multiply-add this one does not).
    The pull-back asks it of every pixel and pre-image, where only a thin band
    along the boundary can qualify: `nearest_edge` then runs on those few
    (one pass here instead of numpy's passes per edge over every point).
    NaN points are never flagged.
    """
    n = vx.shape[0]
    size = 0.0
    for i in range(n):
        size = max(size, abs(vx[i]) + abs(vy[i]))
    for k in range(px.shape[0]):
        x = px[k]
        y = py[k]
        lim = reach + 1e-12 * (size + abs(x) + abs(y)) + 1e-12 * reach
        lim2 = lim * lim
        hit = 0
        for i in range(n):
            ax = vx[i]
            ay = vy[i]
            dx = vx[(i + 1) % n] - ax
            dy = vy[(i + 1) % n] - ay
            rx = x - ax
            ry = y - ay
            dd = dx * dx + dy * dy
            t = (rx * dx + ry * dy) / dd if dd > 0.0 else 0.0
            t = min(max(t, 0.0), 1.0)
            ex = rx - t * dx
            ey = ry - t * dy
            if ex * ex + ey * ey <= lim2:
                hit = 1
                break
        out[k] = hit


# Not inlined at numba's level: an inlined body would take the caller's flags,
# without fastmath's reassociation its sums would not vectorise (measured: the
# compiled Newton ran slower than numpy's passes).
@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FASTMATH)
def _mfs_value_gradient(x, y, sx, sy, w0, w1):
    """0.5 sum_i w_i log|z - s_i|^2 and sum_i w_i (z - s_i)/|z - s_i|^2 at one local point, both
    components, in one pass over the sites (`mfs_evaluate`'s value and Jacobian loop): Newton's
    points, whose gradient is the next step's or the last Jacobian once a step is accepted (nearly
    every step from a close start); one pass shares the differences and squared distances."""
    v0 = 0.0
    v1 = 0.0
    a00 = 0.0
    a01 = 0.0
    a10 = 0.0
    a11 = 0.0
    for i in range(sx.shape[0]):
        dx = x - sx[i]
        dy = y - sy[i]
        r2 = dx * dx + dy * dy
        lg = fast_log(r2)
        inv = 1.0 / r2
        gx = dx * inv
        gy = dy * inv
        v0 += w0[i] * lg
        v1 += w1[i] * lg
        a00 += w0[i] * gx
        a01 += w0[i] * gy
        a10 += w1[i] * gx
        a11 += w1[i] * gy
    return 0.5 * v0, 0.5 * v1, a00, a01, a10, a11


@njit(cache=True, nogil=True, error_model="numpy")
def mfs_invert(
    qx, qy, gx, gy, chain, sx, sy, w0, w1, aff, frame, vx, vy, thresh, noise, max_iter, halvings, armijo,
    want_jac, out, ok, jac,
):  # fmt: skip
    """Damped Newton for phi(y) = q, one point at a time: `warpcli.maps.newton.invert` for an MFS map, compiled.

    The same iteration per point as ``invert`` (a point's steps never depend
    on the others'): full Newton step, halved until the trial lies in the
    polygon (vx, vy) and the squared residual decreases by the Armijo factor
    or meets ``thresh``; a point whose step cannot be accepted is converged
    if within ``noise``, and so is one out of iterations. phi in the
    caller's coordinates: local p = (y - centre) / scale, phi = tcentre +
    tscale (value + affine), J = tscale / scale (gradient + affine), with
    ``frame`` = (centre x, centre y, scale, tcentre x, tcentre y, tscale)
    (`warpcli.maps.closed_form.Frame`). ``out`` gets the last iterate, ``ok``
    1 where converged, ``jac`` (if ``want_jac``) phi's Jacobian there (NaN
    elsewhere).

    The start of point k is (gx, gy)[k], or where ``chain[k]`` is 1, the
    quadratic extrapolation 3 y[k-1] - 3 y[k-2] + y[k-3] of the three points
    before it (a run of evenly spaced targets: consecutive pixels of a row),
    when all three converged; a point with neither (a NaN start) is left
    unconverged for the caller to start again. Measured on the 1 MP bench pair:
    the extrapolation is 6e-5 px from the pre-image (median; the linear first
    guess of a 4000-triangle mesh 0.025 px), so 86 % of the points converge
    after one step instead of two. Every point gets its value and gradient in
    one pass (`_mfs_value_gradient`): the gradient of an accepted point is the
    next step's or the last Jacobian (nearly every step is accepted from a
    close start), and the path, so the bits, do not depend on ``want_jac``.
    """
    cx = frame[0]
    cy = frame[1]
    sc = frame[2]
    tcx = frame[3]
    tcy = frame[4]
    ts = frame[5]
    jf = ts / sc
    for k in range(qx.shape[0]):
        x0 = qx[k]
        x1 = qy[k]
        if chain[k] and k >= 3 and ok[k - 1] and ok[k - 2] and ok[k - 3]:
            y0 = 3.0 * (out[k - 1, 0] - out[k - 2, 0]) + out[k - 3, 0]
            y1 = 3.0 * (out[k - 1, 1] - out[k - 2, 1]) + out[k - 3, 1]
        else:
            y0 = gx[k]
            y1 = gy[k]
        ok[k] = 0
        out[k, 0] = y0
        out[k, 1] = y1
        if want_jac:
            for a in range(2):
                for b in range(2):
                    jac[k, a, b] = np.nan
        if not (np.isfinite(y0) and np.isfinite(y1)) or not _inside(y0, y1, vx, vy):
            continue
        px = (y0 - cx) / sc
        py = (y1 - cy) / sc
        u0, u1, g00, g01, g10, g11 = _mfs_value_gradient(px, py, sx, sy, w0, w1)
        r0 = x0 - (tcx + ts * (u0 + (aff[0, 0] + (px * aff[1, 0] + py * aff[2, 0]))))
        r1 = x1 - (tcy + ts * (u1 + (aff[0, 1] + (px * aff[1, 1] + py * aff[2, 1]))))
        f = r0 * r0 + r1 * r1
        done = np.sqrt(f) <= thresh
        it = 0
        while not done and it < max_iter:
            it += 1
            j00 = (g00 + aff[1, 0]) * jf
            j01 = (g01 + aff[2, 0]) * jf
            j10 = (g10 + aff[1, 1]) * jf
            j11 = (g11 + aff[2, 1]) * jf
            det = j00 * j11 - j01 * j10
            d0 = (j11 * r0 - j01 * r1) / det
            d1 = (j00 * r1 - j10 * r0) / det
            if not (np.isfinite(d0) and np.isfinite(d1)):
                break  # singular: dropped, not converged
            step = 1.0
            accepted = False
            for _ in range(halvings):
                t0 = y0 + step * d0
                t1 = y1 + step * d1
                if _inside(t0, t1, vx, vy):
                    tpx = (t0 - cx) / sc
                    tpy = (t1 - cy) / sc
                    v0, v1, h00, h01, h10, h11 = _mfs_value_gradient(tpx, tpy, sx, sy, w0, w1)
                    s0 = x0 - (tcx + ts * (v0 + (aff[0, 0] + (tpx * aff[1, 0] + tpy * aff[2, 0]))))
                    s1 = x1 - (tcy + ts * (v1 + (aff[0, 1] + (tpx * aff[1, 1] + tpy * aff[2, 1]))))
                    ft = s0 * s0 + s1 * s1
                    if ft <= (1.0 - 2.0 * armijo * step) * f or (np.isfinite(ft) and np.sqrt(ft) <= thresh):
                        y0 = t0
                        y1 = t1
                        px = tpx
                        py = tpy
                        r0 = s0
                        r1 = s1
                        f = ft
                        g00 = h00
                        g01 = h01
                        g10 = h10
                        g11 = h11
                        accepted = True
                        break
                step *= 0.5
            if not accepted:
                if np.sqrt(f) <= noise:
                    ok[k] = 1
                break
            if np.sqrt(f) <= thresh:
                done = True
        if done or (it >= max_iter and np.sqrt(f) <= noise):
            ok[k] = 1
        out[k, 0] = y0
        out[k, 1] = y1
        if ok[k] and want_jac:
            jac[k, 0, 0] = (g00 + aff[1, 0]) * jf
            jac[k, 0, 1] = (g01 + aff[2, 0]) * jf
            jac[k, 1, 0] = (g10 + aff[1, 1]) * jf
            jac[k, 1, 1] = (g11 + aff[2, 1]) * jf
