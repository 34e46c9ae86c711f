"""Evaluating a BEM solution: the representation formula at points, near and far from each element.

The solution of `warpcli.maps.bem` is a flux q and data c per boundary
element; inside the polygon phi(x) = int G_x q - int c dG_x/dn (paper
§3.1.2).  Per (point, element) pair the integrals are taken

- in closed form (`near_integrals`) when the point lies within ``NEAR / 2``
  element lengths of the element's midpoint, so values and derivatives stay
  accurate arbitrarily close to the boundary (the collocation of
  `warpcli.maps.bem` uses the same closed forms);
- otherwise by Gauss-Legendre rules with 2 to 12 nodes, chosen from the
  Bernstein-ellipse bound so that the quadrature error is ~1e-15, whose
  nodes are precomputed per element as charges and dipoles
  (`gauss_sources`).

Evaluation sorts the points along a Z-order curve and works on blocks of 256
nearby points; the far field of each block is summed as one local (Taylor)
expansion (a one-level treecode), so evaluating value and Jacobian at 1e6
points costs seconds, not minutes (paper §3.1.4 calls BEM evaluation "rather
slow": 2 m boundary integrals per point).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from .._jit import njit
from numpy.typing import NDArray

from ._smooth_kernels import fast_log
from .closed_form import TWO_PI

__all__ = ["NEAR", "ElementSources", "crecip", "evaluate", "gauss01", "gauss_sources", "local_pair", "near_integrals"]

#: Gauss-Legendre rules used for regular integrals, by number of nodes.
_GAUSS_ORDERS = np.array([2, 3, 4, 5, 6, 8, 10, 12], dtype=np.int64)
#: A (point, element) pair is integrated in closed form when the point lies
#: within ``NEAR / 2`` element lengths of the element's midpoint.
NEAR = 4.0
#: Points per block in evaluation (blocks of nearby points share one choice of
#: quadrature rule per element, and one local expansion of the far field).
_BLOCK = 256
#: Elements farther than ``_FAR`` block radii from a block's centre enter the
#: block's local (Taylor) expansion, of order up to ``_ORDER`` (fewer terms for
#: farther elements): truncation error ~ _FAR^-(order+1) for values and
#: ~ order^2 _FAR^-(order-1) for Hessians, ~1e-14 at most (measured: faster
#: than _FAR = 4 or 5 with orders 28 or 24).
_FAR = 3.0
_ORDER = 36
#: Rows of a block's accumulators in `_evaluate` (``acc``): value, Phi' and
#: Phi'' of the two components, complex ones as real and imaginary parts.
_V0, _V1, _F0R, _F0I, _F1R, _F1I, _H0R, _H0I, _H1R, _H1I = range(10)
#: Rows of a block's far Gauss nodes in `_evaluate` (``far``): 1/D (complex),
#: log|D|, the charges and the dipoles (complex) of the two components.
_GTR, _GTI, _GLG, _GA0, _GA1, _GB0R, _GB0I, _GB1R, _GB1I = range(9)


def gauss01(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """n-point Gauss-Legendre nodes and weights on [0, 1].

    Parameters
    ----------
    n : int

    Returns
    -------
    nodes : (n,) ndarray of float
    weights : (n,) ndarray of float
    """
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


# --------------------------------------------------------------------------
# Closed forms on one element (also the collocation's, in `warpcli.maps.bem`)
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
# Gauss charges and dipoles of the elements
# --------------------------------------------------------------------------


class ElementSources(NamedTuple):
    """The elements of a BEM solution, and their Gauss nodes as charges and dipoles (`gauss_sources`).

    Attributes
    ----------
    ax, ay, bx, by : (E,) ndarray of float
        Start and end points of the elements (local coordinates).
    cx, cy : (E,) ndarray of float
        Midpoints of the elements.
    length : (E,) ndarray of float
        Lengths of the elements.
    orders : (R,) ndarray of int
        Number of nodes of each Gauss rule.
    offsets : (R,) ndarray of int
        Where rule r's nodes start along the second axis of the arrays below.
    sx, sy : (E, sum(orders)) ndarray of float
        The nodes y_j of every rule on every element.
    alpha : (E, sum(orders), 2) ndarray of float
        Charges (real), per component of the map.
    beta_re, beta_im : (E, sum(orders), 2) ndarray of float
        Dipoles (complex, split), per component of the map.
    """

    ax: NDArray[np.float64]
    ay: NDArray[np.float64]
    bx: NDArray[np.float64]
    by: NDArray[np.float64]
    cx: NDArray[np.float64]
    cy: NDArray[np.float64]
    length: NDArray[np.float64]
    orders: NDArray[np.int64]
    offsets: NDArray[np.int64]
    sx: NDArray[np.float64]
    sy: NDArray[np.float64]
    alpha: NDArray[np.float64]
    beta_re: NDArray[np.float64]
    beta_im: NDArray[np.float64]


def gauss_sources(
    a: NDArray[np.float64], b: NDArray[np.float64], qflux: NDArray[np.float64], cdata: NDArray[np.float64]
) -> ElementSources:
    """Precompute, per element and Gauss rule, charges and dipoles of the representation formula.

    For the n-point rule (t_j, w_j) on element e (length L, outward normal n):
    y_j = a + t_j (b - a), alpha_j = -L w_j q(t_j) / (2 pi),
    beta_j = -L w_j c(t_j) n / (2 pi), so that int G q - int c dG/dn
    = Re sum_j [alpha_j log(z - y_j) + beta_j / (z - y_j)].

    Parameters
    ----------
    a, b : (E, 2) ndarray of float
        Start and end points of the elements (local coordinates,
        counter-clockwise).
    qflux : (E, 2, 2) ndarray of float
        ``qflux[e, s, a]``: flux of component a at the start (s = 0) or end
        (s = 1) of element e.
    cdata : (E, 2, 2) ndarray of float
        The same for the boundary data.

    Returns
    -------
    ElementSources
    """
    E = len(a)
    d = b - a
    L = np.hypot(d[:, 0], d[:, 1])
    normal = np.stack([d[:, 1], -d[:, 0]], axis=1) / L[:, None]  # n = -i tau (counter-clockwise)
    orders = _GAUSS_ORDERS
    offsets = np.concatenate([[0], np.cumsum(orders)[:-1]]).astype(np.int64)
    total = int(orders.sum())
    sx = np.empty((E, total))
    sy = np.empty((E, total))
    alpha = np.empty((E, total, 2))
    bre = np.empty((E, total, 2))
    bim = np.empty((E, total, 2))
    for r, nq in enumerate(orders):  # loop over quadrature rules
        tq, wq = gauss01(int(nq))
        sl = slice(offsets[r], offsets[r] + nq)
        sx[:, sl] = a[:, 0, None] + tq[None, :] * d[:, 0, None]
        sy[:, sl] = a[:, 1, None] + tq[None, :] * d[:, 1, None]
        qv = (1 - tq)[None, :, None] * qflux[:, None, 0, :] + tq[None, :, None] * qflux[:, None, 1, :]
        cv = (1 - tq)[None, :, None] * cdata[:, None, 0, :] + tq[None, :, None] * cdata[:, None, 1, :]
        wl = (L[:, None] * wq[None, :])[:, :, None] / TWO_PI
        alpha[:, sl] = -wl * qv
        bre[:, sl] = -wl * cv * normal[:, None, None, 0]
        bim[:, sl] = -wl * cv * normal[:, None, None, 1]
    c = a + 0.5 * d
    return ElementSources(
        np.ascontiguousarray(a[:, 0]), np.ascontiguousarray(a[:, 1]),
        np.ascontiguousarray(b[:, 0]), np.ascontiguousarray(b[:, 1]),
        np.ascontiguousarray(c[:, 0]), np.ascontiguousarray(c[:, 1]), L,
        orders, offsets, sx, sy, alpha, bre, bim,
    )  # fmt: skip


# --------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------


def evaluate(
    p: NDArray[np.float64],
    sources: ElementSources,
    flux: NDArray[np.float64],
    data: NDArray[np.float64],
    want_val: bool,
    want_jac: bool,
    want_hess: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The representation formula's value, Jacobian and Hessian at local points.

    The points are sorted along a Z-order curve and cut into blocks of
    ``_BLOCK``; the compiled sum works block by block (`_evaluate`) and the
    results come back in the points' order.

    Parameters
    ----------
    p : (K, 2) ndarray of float
        Points inside the polygon, local coordinates
        (`warpcli.maps.closed_form.Frame`).
    sources : ElementSources
        The solution's elements (`gauss_sources`).
    flux, data : (E, 2, 2) ndarray of float
        The solution's flux and data at both ends of each element (used by
        the closed forms near an element).
    want_val, want_jac, want_hess : bool
        Which quantities to compute.

    Returns
    -------
    value : (K, 2) ndarray of float
    jacobian : (K, 2, 2) ndarray of float
        ``J[k, a, b]`` = d phi_a / d x_b.
    hessian : (K, 2, 2, 2) ndarray of float
        ``H[k, a, b, c]`` = d^2 phi_a / dx_b dx_c.

    Each has length 0 when not wanted.
    """
    K = len(p)
    val = np.zeros((K if want_val else 0, 2))
    jac = np.zeros((K if want_jac else 0, 2, 2))
    hess = np.zeros((K if want_hess else 0, 2, 2, 2))
    if K == 0:
        return val, jac, hess
    order = _morton_order(p)
    ps = p[order]
    bstart = np.append(np.arange(0, K, _BLOCK), K).astype(np.int64)
    lo = np.minimum.reduceat(ps, bstart[:-1], axis=0)
    hi = np.maximum.reduceat(ps, bstart[:-1], axis=0)
    bc = 0.5 * (lo + hi)
    brad = 0.5 * np.hypot(*(hi - lo).T)
    ax, ay, bx, by, ecx, ecy, elen, orders, offsets, sx, sy, alpha, bre, bim = sources
    _evaluate(
        np.ascontiguousarray(ps[:, 0]), np.ascontiguousarray(ps[:, 1]), bstart,
        np.ascontiguousarray(bc[:, 0]), np.ascontiguousarray(bc[:, 1]), brad,
        ax, ay, bx, by, ecx, ecy, elen, flux, data,
        orders, offsets, sx, sy, alpha, bre, bim,
        want_val, want_jac, want_hess, val, jac, hess,
    )  # fmt: skip
    inv = np.empty_like(order)
    inv[order] = np.arange(K)
    return val[inv] if want_val else val, jac[inv] if want_jac else jac, hess[inv] if want_hess else hess


def _morton_order(p: NDArray[np.float64]) -> NDArray[np.int64]:
    """Permutation sorting local points (roughly in [-1, 1]^2) along a Z-order curve.

    Consecutive points are then spatially close, so blocks of them have small
    bounding boxes (evaluation picks one quadrature rule per block and element).
    """
    q = np.clip(((p + 1.0) * 32768.0).astype(np.int64), 0, 65535)  # 16 bits per coordinate

    def spread(v: NDArray[np.int64]) -> NDArray[np.int64]:
        v = (v | (v << 8)) & 0x00FF00FF
        v = (v | (v << 4)) & 0x0F0F0F0F
        v = (v | (v << 2)) & 0x33333333
        v = (v | (v << 1)) & 0x55555555
        return v

    key = spread(q[:, 0]) | (spread(q[:, 1]) << 1)
    return np.argsort(key, kind="stable")


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
def _far_to_local(tr, ti, lg, a0, a1, b0r, b0i, b1r, b1i, pe, n, invk, want_val, c0r, c0i, c1r, c1i):
    """Local expansion coefficients a_k of far charges alpha and dipoles beta at nodes y.

    Phi(z) = sum_j alpha_j log(z - y_j) + beta_j / (z - y_j) = sum_k a_k w^k,
    w = z - c, D_j = y_j - c, t_j = 1/D_j:  log(z - y) = log(-D) - sum_k (t w)^k / k
    and 1/(z - y) = -sum_k t^(k+1) w^k, so a_0 = sum alpha log|D| - beta t (real
    part; the only part used) and a_k = -sum_j alpha_j t_j^k / k + beta_j t_j^(k+1).
    Node j needs terms up to k = pe[j].  Nodes are ordered by decreasing pe,
    and the loop over nodes is innermost: a vectorised sum (hence fastmath's
    reassociation; deterministic on a given machine).
    """
    # counting sort by decreasing pe: nodes with pe >= k are the first cnt[k]
    kmax = c0r.shape[0] - 1
    cnt = np.zeros(kmax + 2, dtype=np.int64)
    for j in range(n):
        cnt[min(pe[j], kmax)] += 1
    for k in range(kmax - 1, -1, -1):
        cnt[k] += cnt[k + 1]
    start = cnt[1:].copy()  # nodes with pe = p go to [cnt[p+1], cnt[p])
    order = np.empty(n, dtype=np.int64)
    for j in range(n):
        p = min(pe[j], kmax)
        order[start[p]] = j
        start[p] += 1
    sr = np.empty(n)
    si = np.empty(n)
    q_tr = np.empty(n)
    q_ti = np.empty(n)
    q_a0 = np.empty(n)
    q_a1 = np.empty(n)
    q_b0r = np.empty(n)
    q_b0i = np.empty(n)
    q_b1r = np.empty(n)
    q_b1i = np.empty(n)
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
def _add_local_expansion(px, py, s0, nb, cx, cy, c0r, c0i, c1r, c1i, want_val, want_jac, want_hess, acc):
    """Add Phi = sum_k a_k w^k (w = z - c) and its derivatives at a block of points.

    Horner's scheme with the coefficient loop outside and the loop over points
    inside (independent per point, so it vectorises).
    """
    P = c0r.shape[0] - 1
    for which in range(3):
        if (which == 0 and not want_val) or (which == 1 and not want_jac) or (which == 2 and not want_hess):
            continue
        # polynomial coefficients of Phi^(which): a_k k!/(k-which)!, k >= which
        top = P
        low = which
        # accumulate with Horner: S = sum_{k=low}^{top} f_k a_k w^(k-low)
        sr0 = np.zeros(nb)
        si0 = np.zeros(nb)
        sr1 = np.zeros(nb)
        si1 = np.zeros(nb)
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
def _evaluate(
    px, py, bstart, bcx, bcy, brad,
    ax, ay, bx, by, ecx, ecy, elen, qc, cc,
    orders, offsets, sx, sy, alpha, beta_re, beta_im,
    want_val, want_jac, want_hess, val, jac, hess,
):  # fmt: skip
    """Sum the BEM representation formula over elements, for blocks of points.

    Points (local coordinates) come in spatially coherent blocks
    ``bstart[b]:bstart[b+1]`` with bounding circle (bcx, bcy, brad).  Per block
    and element, by distance:

    - far (``_FAR`` block radii): the element's Gauss charges and dipoles go
      into one local (Taylor) expansion of the block (`_gather_far`,
      `_far_to_local`), evaluated at its points at the end
      (`_add_local_expansion`), so the cost per far element is per block,
      not per point;
    - every point farther than ``NEAR/2`` element lengths from the element's
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
    """
    nblocks = bstart.shape[0] - 1
    E = ax.shape[0]
    top = orders.shape[0] - 1
    P = _ORDER
    invk = np.zeros(P + 1)
    for k in range(1, P + 1):
        invk[k] = 1.0 / k
    # local expansion coefficients of the two components (complex, split)
    c0r = np.zeros(P + 1)
    c0i = np.zeros(P + 1)
    c1r = np.zeros(P + 1)
    c1i = np.zeros(P + 1)
    # Gauss nodes of the far elements of a block (gathered, then summed into
    # the local expansion by `_far_to_local`): 1/D, log|D|, alpha, beta
    G = E * orders[top]
    far = np.empty((9, G))
    far_pe = np.empty(G, dtype=np.int64)
    B = 0
    for b in range(nblocks):
        B = max(B, bstart[b + 1] - bstart[b])
    acc = np.zeros((10, B))
    for b in range(nblocks):
        s0 = bstart[b]
        nb = bstart[b + 1] - s0
        acc[:] = 0.0
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
            if Rmin >= NEAR and dc - 0.5 * L >= _FAR * brad[b]:  # far: into the local expansion
                nfar += 1
                ratio = brad[b] / (dc - 0.5 * L)
                ng = _gather_far(e, _gauss_order_index(Rmin, orders), ratio, bcx[b], bcy[b],
                                 orders, offsets, sx, sy, alpha, beta_re, beta_im, far, far_pe, ng)  # fmt: skip
            elif Rmin >= NEAR:  # one Gauss rule for the whole block
                _add_gauss_block(px, py, s0, nb, e, _gauss_order_index(Rmin, orders),
                                 orders, offsets, sx, sy, alpha, beta_re, beta_im,
                                 want_val, want_jac, want_hess, acc)  # fmt: skip
            else:  # some points are near: decide per point
                _add_near_element(px, py, s0, nb, e, ax, ay, bx, by, L, qc, cc,
                                  orders, offsets, sx, sy, alpha, beta_re, beta_im,
                                  want_val, want_jac, want_hess, acc)  # fmt: skip
        if nfar:
            _far_to_local(far[_GTR], far[_GTI], far[_GLG], far[_GA0], far[_GA1],
                          far[_GB0R], far[_GB0I], far[_GB1R], far[_GB1I], far_pe, ng,
                          invk, want_val, c0r, c0i, c1r, c1i)  # fmt: skip
            _add_local_expansion(px, py, s0, nb, bcx[b], bcy[b], c0r, c0i, c1r, c1i,
                                 want_val, want_jac, want_hess, acc)  # fmt: skip
        _store_block(s0, nb, acc, want_val, want_jac, want_hess, val, jac, hess)


@njit(cache=True, nogil=True, error_model="numpy")
def _gather_far(e, r, ratio, cx, cy, orders, offsets, sx, sy, alpha, beta_re, beta_im, far, far_pe, ng):
    """Append the nodes of element e's Gauss rule r to a block's far nodes; the new count of nodes.

    With D = y - c (c the block's centre), t = 1/D:  log(z - y) = log(-D) -
    sum_k (t w)^k / k and 1/(z - y) = -sum_k t^(k+1) w^k  (w = z - c,
    |w| <= |D| / _FAR); a node keeps the terms needed for ~1e-16, ratio^(p+1)
    with ``ratio`` = |w| / |D| <= 1/_FAR.
    """
    pe = 2  # a single point: a_0, a_1, a_2 are value, gradient, Hessian
    if ratio > 0.0:
        pe = min(_ORDER, max(2, int(37.0 / -np.log(ratio)) + 2))
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
    orders, offsets, sx, sy, alpha, beta_re, beta_im, want_val, want_jac, want_hess, acc,
):  # fmt: skip
    """Add element e at a block some of whose points are near it: per point, a Gauss rule or the closed form."""
    delta = complex(bx[e] - ax[e], by[e] - ay[e])
    idelta = crecip(delta)
    logL = np.log(L)
    for k in range(nb):
        zeta, zm = local_pair(px[s0 + k], py[s0 + k], ax[e], ay[e], bx[e], by[e], idelta)
        R = abs(2.0 * zeta - 1.0)
        if R >= NEAR:  # this point is far enough: the Gauss rule for it
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
def _store_block(s0, nb, acc, want_val, want_jac, want_hess, val, jac, hess):
    """Store a block's sums as value, Jacobian (Re Phi', -Im Phi') and Hessian (Re Phi'', -Im Phi'')."""
    for k in range(nb):
        i = s0 + k
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
