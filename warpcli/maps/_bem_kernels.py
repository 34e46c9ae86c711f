"""Compiled (numba) kernels of BEM: the collocation integrals, the evaluation's sums, the certificate's bounds.

Called through `warpcli._native.Kernels` (cached machine code, numba never
imported in a process that finds them compiled), by `warpcli.maps.bem`
(`bem_assemble`, `bem_bounds`) and `warpcli.maps.bem_eval` (`bem_evaluate`),
which import no numba: importing numba and loading its cached functions cost
about a fifth of an in-process BEM warp at 1 MP. The kernels allocate
nothing (the native route cannot): their outputs and work arrays come from
the callers. The maths is documented where the callers use it; the closed
forms on one element (`near_integrals`) are shared by the collocation and
the evaluation.
"""

from __future__ import annotations

import numpy as np

from .._jit import njit
from ._smooth_kernels import fast_log

__all__ = ["bem_assemble", "bem_bounds", "bem_evaluate", "crecip", "local_pair", "near_integrals"]

TWO_PI = 2.0 * np.pi
#: The representation formula is evaluated with closed forms, Gauss rules and a treecode whose errors
#: are ~1e-14 of the terms' sizes (`warpcli.maps.bem_eval`); the certificate's slack is this times their sum.
_EVAL_ERROR = 1e-13
#: Rows of a block's accumulators in `bem_evaluate` (``acc``): value, Phi' and
#: Phi'' of the two components, complex ones as real and imaginary parts.
_V0, _V1, _F0R, _F0I, _F1R, _F1I, _H0R, _H0I, _H1R, _H1I = range(10)
#: Rows of a block's far Gauss nodes in `bem_evaluate` (``far``): 1/D (complex),
#: log|D|, the charges and the dipoles (complex) of the two components.
_GTR, _GTI, _GLG, _GA0, _GA1, _GB0R, _GB0I, _GB1R, _GB1I = range(9)


# --------------------------------------------------------------------------
# Closed forms on one element (the collocation's and the evaluation's)
# --------------------------------------------------------------------------


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def crecip(z):
    """1/z without numba's ZeroDivisionError (inf/nan at z = 0, as numpy would give).

    Compiled (numba), inlined where it is called.

    Parameters
    ----------
    z : complex

    Returns
    -------
    complex
    """
    d = z.real * z.real + z.imag * z.imag
    return complex(z.real / d, -z.imag / d)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def local_pair(zx, zy, ax, ay, bx, by, idelta):
    """zeta = (z - a)/(b - a) and zeta - 1 = (z - b)/(b - a), accurately and consistently.

    Each is computed from its own end point (so that it keeps its relative
    accuracy next to that end); their common imaginary part (the signed
    distance to the element's line over its length) is taken from the nearer
    end, so that both lie on the same side of the real axis -- the principal
    logs in `near_integrals` rely on that for points on the line.

    Compiled (numba), inlined where it is called.

    Parameters
    ----------
    zx, zy : float
        The point z.
    ax, ay, bx, by : float
        The element's start a and end b.
    idelta : complex
        1 / (b - a).

    Returns
    -------
    zeta, zm : complex
        zeta and zeta - 1.
    """
    zeta = complex(zx - ax, zy - ay) * idelta
    zm = complex(zx - bx, zy - by) * idelta
    if abs(zm) < abs(zeta):
        y = zm.imag
    else:
        y = zeta.imag
    return complex(zeta.real, y), complex(zm.real, y)


@njit(cache=True, nogil=True, error_model="numpy")
def near_integrals(zeta, zm):
    """Closed-form integrals over the unit element t in [0, 1] for a point zeta off it.

    With hats phi_0 = 1 - t and phi_1 = t (paper §3.1.2's B_i restricted to
    one element) and the element mapped to [0, 1] (zeta = (z - a) / (b - a)):

        Lam_s = Re int phi_s(t) log(zeta - t) dt
        I_k,s = int phi_s(t) (zeta - t)^-k dt,   k = 1, 2, 3.

    Uses M_k = int (zeta - t)^-k, N_k = int t (zeta - t)^-k = zeta M_k - M_{k-1}
    and the antiderivatives of log.  Principal logs are consistent along the
    path zeta - t, t in [0, 1], unless zeta lies on the element itself
    (handled by the caller).  Meant for |zeta - 1/2| < 2 (no cancellation).
    ``zm`` is zeta - 1, computed by the caller from the element's end point:
    subtracting 1 from zeta would lose the relative accuracy of zeta - 1 that
    the singular terms 1/(zeta - 1)^k need next to the end node.
    Compiled (numba).

    Parameters
    ----------
    zeta, zm : complex
        The point in the element's coordinates, and zeta - 1 (`local_pair`).

    Returns
    -------
    tuple
        (Lam_0, Lam_1, I1_0, I1_1, I2_0, I2_1, I3_0, I3_1); Lam real, I complex.
    """
    lz = np.log(zeta)
    lzm = np.log(zm)
    m1 = lz - lzm
    iz = crecip(zeta)
    izm = crecip(zm)
    m2 = izm - iz
    m3 = 0.5 * (izm * izm - iz * iz)
    n1 = zeta * m1 - 1.0
    n2 = zeta * m2 - m1
    n3 = zeta * m3 - m2
    l0 = zeta * lz - zm * lzm - 1.0
    l1 = zeta * l0 - (0.5 * zeta * zeta * lz - 0.5 * zm * zm * lzm - 0.25 * (2.0 * zeta - 1.0))
    return (
        (l0 - l1).real,
        l1.real,
        m1 - n1,
        n1,
        m2 - n2,
        n2,
        m3 - n3,
        n3,
    )

# --------------------------------------------------------------------------
# The collocation system (`warpcli.maps.bem.fit_bem`)
# --------------------------------------------------------------------------


@njit(cache=True, nogil=True, error_model="numpy")
def _xlogx(x):
    """x log|x| with the limit 0 at x = 0."""
    if x == 0.0:
        return 0.0
    return x * np.log(abs(x))


@njit(cache=True, nogil=True, error_model="numpy")
def _on_element_log(r):
    """(int (1-t) log|r - t| dt, int t log|r - t| dt) over [0, 1] for r in [0, 1] (weak singularity)."""
    l0 = _xlogx(r) - _xlogx(r - 1.0) - 1.0
    l1 = r * l0 - (0.5 * r * _xlogx(r) - 0.5 * (r - 1.0) * _xlogx(r - 1.0) - 0.25 * (2.0 * r - 1.0))
    return l0 - l1, l1


@njit(cache=True, nogil=True, error_model="numpy")
def bem_assemble(cx, cy, inc_e, inc_t, ax, ay, bx, by, gt, gw, near, S, D):
    """Single- and double-layer integrals of each hat half at each collocation point.

    Parameters
    ----------
    cx, cy : (P,) float arrays
        Collocation points (local coordinates).
    inc_e, inc_t : (P, 2) int / float arrays
        Elements that contain each point (-1 if none) and the point's
        parameter on them.
    ax, ay, bx, by : (E,) float arrays
        Element start and end points.
    gt, gw : (G,) float arrays
        Gauss rule on [0, 1] for the regular integrals.

    near : float
        A (point, element) pair is integrated in closed form when the point
        lies within ``near / 2`` element lengths of the element's midpoint
        (`warpcli.maps.bem_eval.NEAR`).
    S : (P, E, 2) float array, written
        S[p, e, s] = int_e phi_s G_{x_p} ds, G_x(y) = -1/(2 pi) log|x - y|.
    D : (P, E, 2) float array, written
        D[p, e, s] = -int_e phi_s dG_{x_p}/dn_y ds (principal value; 0 on
        the element itself, where the kernel vanishes on a straight segment).
    """
    P = cx.shape[0]
    E = ax.shape[0]
    for p in range(P):
        for e in range(E):
            delta = complex(bx[e] - ax[e], by[e] - ay[e])
            L = abs(delta)
            logL = np.log(L)
            own = -1.0
            if inc_e[p, 0] == e:
                own = inc_t[p, 0]
            elif inc_e[p, 1] == e:
                own = inc_t[p, 1]
            if own >= 0.0:
                l0, l1 = _on_element_log(own)
                S[p, e, 0] = -L / TWO_PI * (0.5 * logL + l0)
                S[p, e, 1] = -L / TWO_PI * (0.5 * logL + l1)
                D[p, e, 0] = 0.0
                D[p, e, 1] = 0.0
                continue
            idelta = crecip(delta)
            zeta, zm = local_pair(cx[p], cy[p], ax[e], ay[e], bx[e], by[e], idelta)
            if abs(2.0 * zeta - 1.0) < near:
                l0, l1, a0, a1, _b0, _b1, _c0, _c1 = near_integrals(zeta, zm)
            else:
                l0 = 0.0
                l1 = 0.0
                a0 = 0.0j
                a1 = 0.0j
                for j in range(gt.shape[0]):
                    w = zeta - gt[j]
                    lg = 0.5 * np.log(w.real * w.real + w.imag * w.imag)
                    iw = crecip(w)
                    l0 += gw[j] * (1.0 - gt[j]) * lg
                    l1 += gw[j] * gt[j] * lg
                    a0 += gw[j] * (1.0 - gt[j]) * iw
                    a1 += gw[j] * gt[j] * iw
            S[p, e, 0] = -L / TWO_PI * (0.5 * logL + l0)
            S[p, e, 1] = -L / TWO_PI * (0.5 * logL + l1)
            D[p, e, 0] = -a0.imag / TWO_PI
            D[p, e, 1] = -a1.imag / TWO_PI

# --------------------------------------------------------------------------
# Bounds of the derivatives over discs (the certificate's: `warpcli.maps.bem`)
# --------------------------------------------------------------------------


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})
def bem_bounds(px, py, reach, yx, yy, gr, gi, w, ex, ey, il2, size, out):
    """Per disc (centre p, radius r): the evaluation error of A and B at p and bounds of their Taylor remainders.

    A'' = sum_n sum_k gamma_nk / (z - y_n)^k (`_node_poles`; ``gr``, ``gi``
    (6, m): real and imaginary parts, rows k = 1, 2, 3 of A then of B), so
    A''(p) and A^(3)(p) are summed exactly, and over the disc

        |A^(4)| = |sum_n sum_k k (k+1) gamma_nk / (z - y_n)^(k+2)| <= sum_n sum_k w_nk / (d_n - r)^(k+2)

    (d_n = |p - y_n|; ``w`` (3, m): k (k+1) max(|gamma_nk| of A, of B)), whence

        |A(p + h) - A(p) - A'(p) h| <= |A''(p)| r^2 / 2 + |A^(3)(p)| r^3 / 6 + sup|A^(4)| r^4 / 24

    wherever the segment from p to p + h lies in the polygon (the caller
    checks that). Element n runs from node n along (``ex``, ``ey``)
    (``il2``: 1 / its squared length); ``size`` holds per element L (|q_0|
    + |q_1| + |c_0| + |c_1|) / (2 pi): the evaluation error at p is
    `_EVAL_ERROR` times its sum over elements weighted by 1/d + 1/d^2 (d:
    p's distance to the element).
    """
    K = px.shape[0]
    m = yx.shape[0]
    for k in range(K):
        x = px[k]
        y = py[k]
        r = reach[k]
        a2r = 0.0
        a2i = 0.0
        a3r = 0.0
        a3i = 0.0
        b2r = 0.0
        b2i = 0.0
        b3r = 0.0
        b3i = 0.0
        sup = 0.0
        t0 = 0.0
        for n in range(m):
            dx = x - yx[n]
            dy = y - yy[n]
            d2 = dx * dx + dy * dy
            inv = 1.0 / d2
            ur = dx * inv  # u = 1 / (z - y_n)
            ui = -dy * inv
            u2r = ur * ur - ui * ui
            u2i = 2.0 * ur * ui
            u3r = u2r * ur - u2i * ui
            u3i = u2r * ui + u2i * ur
            u4r = u3r * ur - u3i * ui
            u4i = u3r * ui + u3i * ur
            # A'' = sum g_k u^k, A^(3) = -sum k g_k u^(k+1) (moduli below)
            a2r += gr[0, n] * ur - gi[0, n] * ui + gr[1, n] * u2r - gi[1, n] * u2i + gr[2, n] * u3r - gi[2, n] * u3i
            a2i += gr[0, n] * ui + gi[0, n] * ur + gr[1, n] * u2i + gi[1, n] * u2r + gr[2, n] * u3i + gi[2, n] * u3r
            a3r += gr[0, n] * u2r - gi[0, n] * u2i + 2.0 * (gr[1, n] * u3r - gi[1, n] * u3i) + 3.0 * (gr[2, n] * u4r - gi[2, n] * u4i)
            a3i += gr[0, n] * u2i + gi[0, n] * u2r + 2.0 * (gr[1, n] * u3i + gi[1, n] * u3r) + 3.0 * (gr[2, n] * u4i + gi[2, n] * u4r)
            b2r += gr[3, n] * ur - gi[3, n] * ui + gr[4, n] * u2r - gi[4, n] * u2i + gr[5, n] * u3r - gi[5, n] * u3i
            b2i += gr[3, n] * ui + gi[3, n] * ur + gr[4, n] * u2i + gi[4, n] * u2r + gr[5, n] * u3i + gi[5, n] * u3r
            b3r += gr[3, n] * u2r - gi[3, n] * u2i + 2.0 * (gr[4, n] * u3r - gi[4, n] * u3i) + 3.0 * (gr[5, n] * u4r - gi[5, n] * u4i)
            b3i += gr[3, n] * u2i + gi[3, n] * u2r + 2.0 * (gr[4, n] * u3i + gi[4, n] * u3r) + 3.0 * (gr[5, n] * u4i + gi[5, n] * u4r)
            g = max(np.sqrt(d2) - r, 0.0)  # 0: the disc holds the node, 1/0 = inf
            iv = 1.0 / g
            sup += iv * iv * iv * (w[0, n] + iv * (w[1, n] + iv * w[2, n]))
            # the terms' sizes at p, for the evaluation error
            t = min(1.0, max(0.0, (dx * ex[n] + dy * ey[n]) * il2[n]))
            fx = dx - t * ex[n]
            fy = dy - t * ey[n]
            de = 1.0 / np.sqrt(fx * fx + fy * fy)
            t0 += size[n] * (1.0 + de) * de
        r2 = r * r
        tail = sup * r2 * r2 / 24.0
        out[k, 0] = _EVAL_ERROR * t0
        out[k, 1] = 0.5 * np.hypot(a2r, a2i) * r2 + np.hypot(a3r, a3i) * r2 * r / 6.0 + tail
        out[k, 2] = 0.5 * np.hypot(b2r, b2i) * r2 + np.hypot(b3r, b3i) * r2 * r / 6.0 + tail

# --------------------------------------------------------------------------
# Evaluation (`warpcli.maps.bem_eval.evaluate`)
# --------------------------------------------------------------------------


@njit(cache=True, nogil=True, error_model="numpy")
def _gauss_order_index(R, orders):
    """Index of the smallest Gauss rule accurate to ~1e-15 for a point at R = 2|z - c|/L.

    The integrand is analytic inside the Bernstein ellipse through the point,
    parameter rho >= R + sqrt(R^2 - 1); the n-point error is O(rho^-2n).  The
    budget log(1e18) covers the constants (checked in tests/test_bem.py
    against the closed forms for all kernels up to the Hessian's).
    """
    rho = R + np.sqrt(R * R - 1.0)
    need = 41.4 / (2.0 * np.log(rho))
    for i in range(orders.shape[0]):
        if orders[i] >= need:
            return i
    return orders.shape[0] - 1


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})
def _far_to_local(tr, ti, lg, a0, a1, b0r, b0i, b1r, b1i, pe, n, invk, want_val, c0r, c0i, c1r, c1i, order, counts, work):
    """Local expansion coefficients a_k of far charges alpha and dipoles beta at nodes y.

    Phi(z) = sum_j alpha_j log(z - y_j) + beta_j / (z - y_j) = sum_k a_k w^k,
    w = z - c, D_j = y_j - c, t_j = 1/D_j:  log(z - y) = log(-D) - sum_k (t w)^k / k
    and 1/(z - y) = -sum_k t^(k+1) w^k, so a_0 = sum alpha log|D| - beta t (real
    part; the only part used) and a_k = -sum_j alpha_j t_j^k / k + beta_j t_j^(k+1).
    Node j needs terms up to k = pe[j].  Nodes are ordered by decreasing pe,
    and the loop over nodes is innermost: a vectorised sum (hence fastmath's
    reassociation; deterministic on a given machine). Work arrays: ``order``
    (n,) int, ``counts`` (2, kmax + 2) int, ``work`` (10, n) float.
    """
    # counting sort by decreasing pe: nodes with pe >= k are the first cnt[k]
    kmax = c0r.shape[0] - 1
    cnt = counts[0]
    cnt[:] = 0
    for j in range(n):
        cnt[min(pe[j], kmax)] += 1
    for k in range(kmax - 1, -1, -1):
        cnt[k] += cnt[k + 1]
    start = counts[1]  # nodes with pe = p go to [cnt[p+1], cnt[p])
    for k in range(kmax + 1):
        start[k] = cnt[k + 1]
    for j in range(n):
        p = min(pe[j], kmax)
        order[start[p]] = j
        start[p] += 1
    sr = work[0]
    si = work[1]
    q_tr = work[2]
    q_ti = work[3]
    q_a0 = work[4]
    q_a1 = work[5]
    q_b0r = work[6]
    q_b0i = work[7]
    q_b1r = work[8]
    q_b1i = work[9]
    r0 = 0.0
    r1 = 0.0
    for jj in range(n):
        j = order[jj]
        q_tr[jj] = tr[j]
        q_ti[jj] = ti[j]
        q_a0[jj] = a0[j]
        q_a1[jj] = a1[j]
        q_b0r[jj] = b0r[j]
        q_b0i[jj] = b0i[j]
        q_b1r[jj] = b1r[j]
        q_b1i[jj] = b1i[j]
        sr[jj] = tr[j]  # t^k, starting at k = 1
        si[jj] = ti[j]
        if want_val:
            r0 += a0[j] * lg[j] - (b0r[j] * tr[j] - b0i[j] * ti[j])
            r1 += a1[j] * lg[j] - (b1r[j] * tr[j] - b1i[j] * ti[j])
    c0r[0] += r0
    c1r[0] += r1
    for k in range(1, kmax + 1):
        nk = cnt[k]
        if nk == 0:
            break
        s = invk[k]
        x0r = 0.0
        x0i = 0.0
        x1r = 0.0
        x1i = 0.0
        for jj in range(nk):
            pr = sr[jj]
            pi = si[jj]
            qr = pr * q_tr[jj] - pi * q_ti[jj]  # t^(k+1)
            qi = pr * q_ti[jj] + pi * q_tr[jj]
            x0r -= q_a0[jj] * s * pr + (q_b0r[jj] * qr - q_b0i[jj] * qi)
            x0i -= q_a0[jj] * s * pi + (q_b0r[jj] * qi + q_b0i[jj] * qr)
            x1r -= q_a1[jj] * s * pr + (q_b1r[jj] * qr - q_b1i[jj] * qi)
            x1i -= q_a1[jj] * s * pi + (q_b1r[jj] * qi + q_b1i[jj] * qr)
            sr[jj] = qr
            si[jj] = qi
        c0r[k] += x0r
        c0i[k] += x0i
        c1r[k] += x1r
        c1i[k] += x1i


@njit(cache=True, nogil=True, error_model="numpy")
def _add_local_expansion(px, py, s0, nb, cx, cy, c0r, c0i, c1r, c1i, want_val, want_jac, want_hess, acc, work):
    """Add Phi = sum_k a_k w^k (w = z - c) and its derivatives at a block of points.

    Horner's scheme with the coefficient loop outside and the loop over points
    inside (independent per point, so it vectorises). ``work``: (4, nb) or
    more, float.
    """
    P = c0r.shape[0] - 1
    for which in range(3):
        if (which == 0 and not want_val) or (which == 1 and not want_jac) or (which == 2 and not want_hess):
            continue
        # polynomial coefficients of Phi^(which): a_k k!/(k-which)!, k >= which
        top = P
        low = which
        # accumulate with Horner: S = sum_{k=low}^{top} f_k a_k w^(k-low)
        sr0 = work[0]
        si0 = work[1]
        sr1 = work[2]
        si1 = work[3]
        for k in range(nb):
            sr0[k] = 0.0
            si0[k] = 0.0
            sr1[k] = 0.0
            si1[k] = 0.0
        for kk in range(top, low - 1, -1):
            f = 1.0
            for q in range(which):
                f *= kk - q
            ar0 = f * c0r[kk]
            ai0 = f * c0i[kk]
            ar1 = f * c1r[kk]
            ai1 = f * c1i[kk]
            for k in range(nb):
                wr = px[s0 + k] - cx
                wi = py[s0 + k] - cy
                t0 = sr0[k] * wr - si0[k] * wi + ar0
                si0[k] = sr0[k] * wi + si0[k] * wr + ai0
                sr0[k] = t0
                t1 = sr1[k] * wr - si1[k] * wi + ar1
                si1[k] = sr1[k] * wi + si1[k] * wr + ai1
                sr1[k] = t1
        for k in range(nb):
            if which == 0:
                acc[_V0, k] += sr0[k]
                acc[_V1, k] += sr1[k]
            elif which == 1:
                acc[_F0R, k] += sr0[k]
                acc[_F0I, k] += si0[k]
                acc[_F1R, k] += sr1[k]
                acc[_F1I, k] += si1[k]
            else:
                acc[_H0R, k] += sr0[k]
                acc[_H0I, k] += si0[k]
                acc[_H1R, k] += sr1[k]
                acc[_H1I, k] += si1[k]


@njit(cache=True, nogil=True, error_model="numpy")
def bem_evaluate(
    px, py, rows, bstart, bcx, bcy, brad,
    ax, ay, bx, by, ecx, ecy, elen, qc, cc,
    orders, offsets, sx, sy, alpha, beta_re, beta_im,
    near, far_radii, want_val, want_jac, want_hess, val, jac, hess,
    coef, far, far_pe, acc, sort_index, counts, sorted_nodes,
):  # fmt: skip
    """Sum the BEM representation formula over elements, for blocks of points.

    Points (local coordinates) come in spatially coherent blocks
    ``bstart[b]:bstart[b+1]`` with bounding circle (bcx, bcy, brad); point i
    is stored at row ``rows[i]`` of ``val``, ``jac``, ``hess``.  Per block
    and element, by distance:

    - far (``far_radii`` block radii): the element's Gauss charges and dipoles go
      into one local (Taylor) expansion of the block (`_gather_far`,
      `_far_to_local`), evaluated at its points at the end
      (`_add_local_expansion`), so the cost per far element is per block,
      not per point;
    - every point farther than ``near / 2`` element lengths from the element's
      midpoint: the Gauss rule for the closest point, for the whole block
      (`_add_gauss_block`);
    - otherwise each point gets the closed form or the Gauss rule for its own
      distance (`_add_near_element`).

    The Gauss nodes of each element are precomputed as charges and dipoles,
    Phi(z) = sum_j alpha_j log(z - y_j) + beta_j / (z - y_j), with
    phi = Re Phi, grad phi = (Re Phi', -Im Phi'), phi_xx = -phi_yy = Re Phi'',
    phi_xy = -Im Phi''.  Each block sums value, Phi' and Phi'' of both
    components into the rows of one array (``acc``, rows ``_V0`` ...
    ``_H1I``) and stores them at the end (`_store_block`); one array rather
    than ten keeps the calls per element and per point cheap.

    ``near`` is `warpcli.maps.bem_eval.NEAR`, ``far_radii`` ``_FAR`` there.
    The kernel allocates nothing (`warpcli._native` runs it without numba):
    its work arrays come from the caller (`warpcli.maps.bem_eval.evaluate`),
    with P + 1 the local expansions' number of coefficients, G = E times the
    largest Gauss rule and B the largest block:

    - ``coef`` (5, P + 1) float: 1/k, then the coefficients of the two
      components (complex, split);
    - ``far`` (9, G) float, ``far_pe`` (G,) int: a block's far Gauss nodes;
    - ``acc`` (14, B) float: the block's ten sums, then four rows for
      `_add_local_expansion`;
    - ``sort_index`` (G,) int, ``counts`` (2, P + 2) int, ``sorted_nodes``
      (10, G) float: `_far_to_local`'s.
    """
    nblocks = bstart.shape[0] - 1
    E = ax.shape[0]
    P = coef.shape[1] - 1
    invk = coef[0]
    invk[0] = 0.0
    for k in range(1, P + 1):
        invk[k] = 1.0 / k
    # local expansion coefficients of the two components (complex, split)
    c0r = coef[1]
    c0i = coef[2]
    c1r = coef[3]
    c1i = coef[4]
    # ``far``: Gauss nodes of the far elements of a block (gathered, then
    # summed into the local expansion by `_far_to_local`): 1/D, log|D|, alpha, beta
    sums = acc[:10]
    horner = acc[10:]
    for b in range(nblocks):
        s0 = bstart[b]
        nb = bstart[b + 1] - s0
        sums[:] = 0.0
        c0r[:] = 0.0
        c0i[:] = 0.0
        c1r[:] = 0.0
        c1i[:] = 0.0
        nfar = 0
        ng = 0
        for e in range(E):
            L = elen[e]
            dc = np.hypot(ecx[e] - bcx[b], ecy[e] - bcy[b])
            Rmin = 2.0 * (dc - brad[b]) / L
            if Rmin >= near and dc - 0.5 * L >= far_radii * brad[b]:  # far: into the local expansion
                nfar += 1
                ratio = brad[b] / (dc - 0.5 * L)
                ng = _gather_far(e, _gauss_order_index(Rmin, orders), ratio, bcx[b], bcy[b], P,
                                 orders, offsets, sx, sy, alpha, beta_re, beta_im, far, far_pe, ng)  # fmt: skip
            elif Rmin >= near:  # one Gauss rule for the whole block
                _add_gauss_block(px, py, s0, nb, e, _gauss_order_index(Rmin, orders),
                                 orders, offsets, sx, sy, alpha, beta_re, beta_im,
                                 want_val, want_jac, want_hess, sums)  # fmt: skip
            else:  # some points are near: decide per point
                _add_near_element(px, py, s0, nb, e, ax, ay, bx, by, L, qc, cc,
                                  orders, offsets, sx, sy, alpha, beta_re, beta_im, near,
                                  want_val, want_jac, want_hess, sums)  # fmt: skip
        if nfar:
            _far_to_local(far[_GTR], far[_GTI], far[_GLG], far[_GA0], far[_GA1],
                          far[_GB0R], far[_GB0I], far[_GB1R], far[_GB1I], far_pe, ng,
                          invk, want_val, c0r, c0i, c1r, c1i, sort_index, counts, sorted_nodes)  # fmt: skip
            _add_local_expansion(px, py, s0, nb, bcx[b], bcy[b], c0r, c0i, c1r, c1i,
                                 want_val, want_jac, want_hess, sums, horner)  # fmt: skip
        _store_block(s0, nb, rows, sums, want_val, want_jac, want_hess, val, jac, hess)


@njit(cache=True, nogil=True, error_model="numpy")
def _gather_far(e, r, ratio, cx, cy, order, orders, offsets, sx, sy, alpha, beta_re, beta_im, far, far_pe, ng):
    """Append the nodes of element e's Gauss rule r to a block's far nodes; the new count of nodes.

    With D = y - c (c the block's centre), t = 1/D:  log(z - y) = log(-D) -
    sum_k (t w)^k / k and 1/(z - y) = -sum_k t^(k+1) w^k  (w = z - c,
    |w| <= |D| / far_radii); a node keeps the terms needed for ~1e-16, ratio^(p+1)
    with ``ratio`` = |w| / |D| <= 1 / ``far_radii`` (at most ``order`` terms).
    """
    pe = 2  # a single point: a_0, a_1, a_2 are value, gradient, Hessian
    if ratio > 0.0:
        pe = min(order, max(2, int(37.0 / -np.log(ratio)) + 2))
    for j in range(offsets[r], offsets[r] + orders[r]):  # gather the nodes
        Dx = sx[e, j] - cx
        Dy = sy[e, j] - cy
        iD = 1.0 / (Dx * Dx + Dy * Dy)
        far[_GTR, ng] = Dx * iD
        far[_GTI, ng] = -Dy * iD
        far[_GLG, ng] = -0.5 * np.log(iD)
        far[_GA0, ng] = alpha[e, j, 0]
        far[_GA1, ng] = alpha[e, j, 1]
        far[_GB0R, ng] = beta_re[e, j, 0]
        far[_GB0I, ng] = beta_im[e, j, 0]
        far[_GB1R, ng] = beta_re[e, j, 1]
        far[_GB1I, ng] = beta_im[e, j, 1]
        far_pe[ng] = pe
        ng += 1
    return ng


# One Gauss node y with charge alpha and dipole beta adds alpha log(z - y) +
# beta / (z - y) to Phi.  With w = z - y and u = 1/w, the terms below are its
# parts of phi, Phi' and Phi'' (real and imaginary parts of one component).


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _value_term(a, br, bi, lg, ur, ui):
    """Re(alpha log w + beta u), with lg = log|w|."""
    return a * lg + (br * ur - bi * ui)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _gradient_term(a, br, bi, ur, ui, u2r, u2i):
    """alpha u - beta u^2 (Phi'), as (real, imaginary)."""
    return a * ur - (br * u2r - bi * u2i), a * ui - (br * u2i + bi * u2r)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _hessian_term(a, br, bi, u2r, u2i, u3r, u3i):
    """-alpha u^2 + 2 beta u^3 (Phi''), as (real, imaginary)."""
    return -a * u2r + 2.0 * (br * u3r - bi * u3i), -a * u2i + 2.0 * (br * u3i + bi * u3r)


@njit(cache=True, nogil=True, error_model="numpy")
def _add_gauss_block(
    px, py, s0, nb, e, r, orders, offsets, sx, sy, alpha, beta_re, beta_im, want_val, want_jac, want_hess, acc
):  # fmt: skip
    """Add element e's Gauss rule r at every point of a block.

    One branch-free loop over the block's points per node and quantity, so
    that each vectorises.
    """
    for j in range(offsets[r], offsets[r] + orders[r]):
        yx = sx[e, j]
        yy = sy[e, j]
        a0 = alpha[e, j, 0]
        a1 = alpha[e, j, 1]
        b0r = beta_re[e, j, 0]
        b0i = beta_im[e, j, 0]
        b1r = beta_re[e, j, 1]
        b1i = beta_im[e, j, 1]
        if want_val:
            for k in range(nb):
                wx = px[s0 + k] - yx
                wy = py[s0 + k] - yy
                r2 = wx * wx + wy * wy
                inv = 1.0 / r2
                ur = wx * inv  # u = 1/(z - y) = conj(w)/|w|^2
                ui = -wy * inv
                lg = 0.5 * fast_log(r2)
                acc[_V0, k] += _value_term(a0, b0r, b0i, lg, ur, ui)
                acc[_V1, k] += _value_term(a1, b1r, b1i, lg, ur, ui)
        if want_jac:
            for k in range(nb):
                wx = px[s0 + k] - yx
                wy = py[s0 + k] - yy
                inv = 1.0 / (wx * wx + wy * wy)
                ur = wx * inv
                ui = -wy * inv
                u2r = ur * ur - ui * ui
                u2i = 2.0 * ur * ui
                gr, gi = _gradient_term(a0, b0r, b0i, ur, ui, u2r, u2i)
                acc[_F0R, k] += gr
                acc[_F0I, k] += gi
                gr, gi = _gradient_term(a1, b1r, b1i, ur, ui, u2r, u2i)
                acc[_F1R, k] += gr
                acc[_F1I, k] += gi
        if want_hess:
            for k in range(nb):
                wx = px[s0 + k] - yx
                wy = py[s0 + k] - yy
                inv = 1.0 / (wx * wx + wy * wy)
                ur = wx * inv
                ui = -wy * inv
                u2r = ur * ur - ui * ui
                u2i = 2.0 * ur * ui
                u3r = u2r * ur - u2i * ui
                u3i = u2r * ui + u2i * ur
                hr, hi = _hessian_term(a0, b0r, b0i, u2r, u2i, u3r, u3i)
                acc[_H0R, k] += hr
                acc[_H0I, k] += hi
                hr, hi = _hessian_term(a1, b1r, b1i, u2r, u2i, u3r, u3i)
                acc[_H1R, k] += hr
                acc[_H1I, k] += hi


@njit(cache=True, nogil=True, error_model="numpy")
def _add_near_element(
    px, py, s0, nb, e, ax, ay, bx, by, L, qc, cc,
    orders, offsets, sx, sy, alpha, beta_re, beta_im, near, want_val, want_jac, want_hess, acc,
):  # fmt: skip
    """Add element e at a block some of whose points are near it: per point, a Gauss rule or the closed form."""
    delta = complex(bx[e] - ax[e], by[e] - ay[e])
    idelta = crecip(delta)
    logL = np.log(L)
    for k in range(nb):
        zeta, zm = local_pair(px[s0 + k], py[s0 + k], ax[e], ay[e], bx[e], by[e], idelta)
        R = abs(2.0 * zeta - 1.0)
        if R >= near:  # this point is far enough: the Gauss rule for it
            _add_gauss_point(k, px[s0 + k], py[s0 + k], e, _gauss_order_index(R, orders),
                             orders, offsets, sx, sy, alpha, beta_re, beta_im,
                             want_val, want_jac, want_hess, acc)  # fmt: skip
        else:
            _add_closed_form(k, e, zeta, zm, idelta, L, logL, qc, cc, acc)


# `_add_gauss_point` and `_add_closed_form` are inlined: they run per point and
# element near the boundary, where a call each cost ~8 % of an evaluation (measured).
@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _add_gauss_point(
    k, x, y, e, r, orders, offsets, sx, sy, alpha, beta_re, beta_im, want_val, want_jac, want_hess, acc
):  # fmt: skip
    """Add element e's Gauss rule r at the block's point k, (x, y)."""
    for j in range(offsets[r], offsets[r] + orders[r]):
        wx = x - sx[e, j]
        wy = y - sy[e, j]
        r2 = wx * wx + wy * wy
        inv = 1.0 / r2
        ur = wx * inv
        ui = -wy * inv
        a0 = alpha[e, j, 0]
        a1 = alpha[e, j, 1]
        b0r = beta_re[e, j, 0]
        b0i = beta_im[e, j, 0]
        b1r = beta_re[e, j, 1]
        b1i = beta_im[e, j, 1]
        if want_val:
            lg = 0.5 * fast_log(r2)
            acc[_V0, k] += _value_term(a0, b0r, b0i, lg, ur, ui)
            acc[_V1, k] += _value_term(a1, b1r, b1i, lg, ur, ui)
        u2r = ur * ur - ui * ui
        u2i = 2.0 * ur * ui
        if want_jac:
            gr, gi = _gradient_term(a0, b0r, b0i, ur, ui, u2r, u2i)
            acc[_F0R, k] += gr
            acc[_F0I, k] += gi
            gr, gi = _gradient_term(a1, b1r, b1i, ur, ui, u2r, u2i)
            acc[_F1R, k] += gr
            acc[_F1I, k] += gi
        if want_hess:
            u3r = u2r * ur - u2i * ui
            u3i = u2r * ui + u2i * ur
            hr, hi = _hessian_term(a0, b0r, b0i, u2r, u2i, u3r, u3i)
            acc[_H0R, k] += hr
            acc[_H0I, k] += hi
            hr, hi = _hessian_term(a1, b1r, b1i, u2r, u2i, u3r, u3i)
            acc[_H1R, k] += hr
            acc[_H1I, k] += hi


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _add_closed_form(k, e, zeta, zm, idelta, L, logL, qc, cc, acc):
    """Add element e at the block's point k in closed form (`near_integrals`), value and both derivatives.

    phi = -L/2pi (q log|z - y| integrated) - 1/2pi Im(c I1); Phi' and Phi''
    from I1, I2 and I2, I3, divided by (b - a) and (b - a)^2.
    """
    lam0, lam1, i10, i11, i20, i21, i30, i31 = near_integrals(zeta, zm)
    for a in range(2):
        q0 = qc[e, 0, a]
        q1 = qc[e, 1, a]
        c0 = cc[e, 0, a]
        c1 = cc[e, 1, a]
        vv = -L / TWO_PI * (0.5 * (q0 + q1) * logL + q0 * lam0 + q1 * lam1) - (
            c0 * i10.imag + c1 * i11.imag
        ) / TWO_PI
        ff = idelta * (-L / TWO_PI * (q0 * i10 + q1 * i11) - 1j / TWO_PI * (c0 * i20 + c1 * i21))
        hh = idelta * idelta * (L / TWO_PI * (q0 * i20 + q1 * i21) + 1j / np.pi * (c0 * i30 + c1 * i31))
        if a == 0:
            acc[_V0, k] += vv
            acc[_F0R, k] += ff.real
            acc[_F0I, k] += ff.imag
            acc[_H0R, k] += hh.real
            acc[_H0I, k] += hh.imag
        else:
            acc[_V1, k] += vv
            acc[_F1R, k] += ff.real
            acc[_F1I, k] += ff.imag
            acc[_H1R, k] += hh.real
            acc[_H1I, k] += hh.imag


@njit(cache=True, nogil=True, error_model="numpy")
def _store_block(s0, nb, rows, acc, want_val, want_jac, want_hess, val, jac, hess):
    """Store a block's sums as value, Jacobian (Re Phi', -Im Phi') and Hessian (Re Phi'', -Im Phi'') at their rows."""
    for k in range(nb):
        i = rows[s0 + k]
        if want_val:
            val[i, 0] = acc[_V0, k]
            val[i, 1] = acc[_V1, k]
        if want_jac:
            jac[i, 0, 0] = acc[_F0R, k]
            jac[i, 0, 1] = -acc[_F0I, k]
            jac[i, 1, 0] = acc[_F1R, k]
            jac[i, 1, 1] = -acc[_F1I, k]
        if want_hess:
            hess[i, 0, 0, 0] = acc[_H0R, k]
            hess[i, 0, 0, 1] = -acc[_H0I, k]
            hess[i, 0, 1, 0] = -acc[_H0I, k]
            hess[i, 0, 1, 1] = -acc[_H0R, k]
            hess[i, 1, 0, 0] = acc[_H1R, k]
            hess[i, 1, 0, 1] = -acc[_H1I, k]
            hess[i, 1, 1, 0] = -acc[_H1I, k]
            hess[i, 1, 1, 1] = -acc[_H1R, k]
