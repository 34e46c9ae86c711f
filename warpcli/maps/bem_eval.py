"""Evaluating a BEM solution: the representation formula at points, near and far from each element.

The solution of `warpcli.maps.bem` is a flux q and data c per boundary
element; inside the polygon phi(x) = int G_x q - int c dG_x/dn (paper
§3.1.2).  Per (point, element) pair the integrals are taken

- in closed form (`warpcli.maps._bem_kernels.near_integrals`) when the point lies within ``NEAR / 2``
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
from numpy.typing import NDArray

from .._arrays import median
from .._native import Kernels
from .closed_form import TWO_PI

__all__ = ["NEAR", "ElementSources", "evaluate", "gauss01", "gauss_sources"]

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
#: Blocks wider than this many (median) element lengths are halved, down to ``_MIN_BLOCK`` points.
_SPLIT_RADIUS = 4.0
_MIN_BLOCK = 32
_ORDER = 36

#: The compiled kernels (`warpcli.maps._bem_kernels`; `fast_log` is inlined from `_smooth_kernels`).
_compiled = Kernels("warpcli.maps._bem_kernels", depends=("_smooth_kernels.py",))


#: `gauss01`'s nodes and weights on [0, 1] for the orders BEM uses (`_GAUSS_ORDERS` and the fit's 16),
#: numpy's ``leggauss`` bit for bit (tests/test_bem.py compares them): numpy.polynomial is then not
#: imported in the processes that fit or evaluate a BEM map.
_GAUSS01 = {
    2: (
        (
            0.21132486540518713, 0.7886751345948129,
        ),
        (
            0.5, 0.5,
        ),
    ),
    3: (
        (
            0.1127016653792583, 0.5, 0.8872983346207417,
        ),
        (
            0.27777777777777785, 0.4444444444444444, 0.27777777777777785,
        ),
    ),
    4: (
        (
            0.06943184420297371, 0.33000947820757187, 0.6699905217924281, 0.9305681557970262,
        ),
        (
            0.17392742256872679, 0.3260725774312732, 0.3260725774312732, 0.17392742256872679,
        ),
    ),
    5: (
        (
            0.04691007703066802, 0.23076534494715845, 0.5, 0.7692346550528415, 0.9530899229693319,
        ),
        (
            0.11846344252809464, 0.23931433524968315, 0.28444444444444433, 0.23931433524968315,
            0.11846344252809464,
        ),
    ),
    6: (
        (
            0.03376524289842403, 0.16939530676686776, 0.38069040695840156, 0.6193095930415985,
            0.8306046932331322, 0.9662347571015759,
        ),
        (
            0.08566224618958514, 0.18038078652406936, 0.23395696728634552, 0.23395696728634552,
            0.18038078652406936, 0.08566224618958514,
        ),
    ),
    8: (
        (
            0.019855071751231912, 0.10166676129318664, 0.2372337950418355, 0.4082826787521751,
            0.5917173212478248, 0.7627662049581645, 0.8983332387068134, 0.9801449282487681,
        ),
        (
            0.05061426814518853, 0.11119051722668721, 0.15685332293894344, 0.18134189168918083,
            0.18134189168918083, 0.15685332293894344, 0.11119051722668721, 0.05061426814518853,
        ),
    ),
    10: (
        (
            0.013046735741414128, 0.06746831665550773, 0.16029521585048778, 0.2833023029353764,
            0.4255628305091844, 0.5744371694908156, 0.7166976970646236, 0.8397047841495122, 0.9325316833444923,
            0.9869532642585859,
        ),
        (
            0.03333567215434407, 0.0747256745752902, 0.109543181257991, 0.13463335965499826,
            0.1477621123573764, 0.1477621123573764, 0.13463335965499826, 0.109543181257991, 0.0747256745752902,
            0.03333567215434407,
        ),
    ),
    12: (
        (
            0.009219682876640378, 0.0479413718147626, 0.11504866290284765, 0.20634102285669126,
            0.31608425050090994, 0.43738329574426554, 0.5626167042557344, 0.6839157494990901,
            0.7936589771433087, 0.8849513370971523, 0.9520586281852375, 0.9907803171233596,
        ),
        (
            0.023587668193255706, 0.05346966299765953, 0.08003916427167321, 0.10158371336153287,
            0.1167462682691773, 0.12457352290670134, 0.12457352290670134, 0.1167462682691773,
            0.10158371336153287, 0.08003916427167321, 0.05346966299765953, 0.023587668193255706,
        ),
    ),
    16: (
        (
            0.005299532504175031, 0.0277124884633837, 0.06718439880608412, 0.1222977958224985,
            0.19106187779867811, 0.2709916111713863, 0.35919822461037054, 0.4524937450811813,
            0.5475062549188188, 0.6408017753896295, 0.7290083888286136, 0.8089381222013219, 0.8777022041775016,
            0.9328156011939159, 0.9722875115366163, 0.994700467495825,
        ),
        (
            0.013576229705877088, 0.031126761969323728, 0.0475792558412463, 0.062314485627767036,
            0.07479799440828835, 0.08457825969750132, 0.09130170752246182, 0.09472530522753432,
            0.09472530522753432, 0.09130170752246182, 0.08457825969750132, 0.07479799440828835,
            0.062314485627767036, 0.0475792558412463, 0.031126761969323728, 0.013576229705877088,
        ),
    ),
}


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
    if n in _GAUSS01:
        t, w = _GAUSS01[n]
        return np.array(t), np.array(w)
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


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
    ``_BLOCK``; the compiled sum works block by block (`warpcli.maps._bem_kernels.bem_evaluate`) and the
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
    # every point is stored by the kernel, at its own row
    val = np.empty((K if want_val else 0, 2))
    jac = np.empty((K if want_jac else 0, 2, 2))
    hess = np.empty((K if want_hess else 0, 2, 2, 2))
    if K == 0:
        return val, jac, hess
    order = _morton_order(p)
    px = p[:, 0][order]
    py = p[:, 1][order]
    bstart, bcx, bcy, brad = _blocks(px, py, _SPLIT_RADIUS * median(sources.length))
    ax, ay, bx, by, ecx, ecy, elen, orders, offsets, sx, sy, alpha, bre, bim = sources
    # the kernel's work arrays (it allocates nothing): G far Gauss nodes at most, blocks of B points
    G = len(ax) * int(orders[-1])
    B = int(np.diff(bstart).max())
    _compiled.bem_evaluate(
        px, py, order, bstart, bcx, bcy, brad,
        ax, ay, bx, by, ecx, ecy, elen, flux, data,
        orders, offsets, sx, sy, alpha, bre, bim,
        NEAR, _FAR, want_val, want_jac, want_hess, val, jac, hess,
        np.zeros((5, _ORDER + 1)), np.empty((9, G)), np.empty(G, dtype=np.int64), np.zeros((14, B)),
        np.empty(G, dtype=np.int64), np.empty((2, _ORDER + 2), dtype=np.int64), np.empty((10, G)),
    )  # fmt: skip
    return val, jac, hess


def _blocks(
    px: NDArray[np.float64], py: NDArray[np.float64], cap: float
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Blocks of Z-ordered points: their starts (and the end), bounding-box centres (x, y) and radii.

    Blocks of ``_BLOCK`` points, halved while their radius exceeds ``cap``
    and they hold more than ``_MIN_BLOCK``: points along a curve (the
    certificate's) or a jump of the Z-order curve make wide blocks, which
    leave most elements near, summed per point instead of in one expansion.
    Only the halves of wide blocks are measured again (few: ~5 % of a pixel
    grid's blocks).
    """
    K = len(px)
    starts = np.arange(0, K, _BLOCK, dtype=np.int64)
    box = np.stack(
        [np.minimum.reduceat(px, starts), np.minimum.reduceat(py, starts),
         np.maximum.reduceat(px, starts), np.maximum.reduceat(py, starts)], axis=1,
    )  # fmt: skip
    bstart = np.append(starts, K)
    while True:
        size = np.diff(bstart)
        rad = 0.5 * np.hypot(box[:, 2] - box[:, 0], box[:, 3] - box[:, 1])
        wide = np.flatnonzero((rad > cap) & (size > _MIN_BLOCK))
        if not wide.size:
            return bstart, 0.5 * (box[:, 0] + box[:, 2]), 0.5 * (box[:, 1] + box[:, 3]), rad
        halves = np.empty((2 * len(wide), 4))
        mids = bstart[wide] + size[wide] // 2
        for i, (s0, m, s1) in enumerate(zip(bstart[wide], mids, bstart[wide + 1])):  # loop over wide blocks
            for h, (a, b) in enumerate(((s0, m), (m, s1))):
                x, y = px[a:b], py[a:b]
                halves[2 * i + h] = (x.min(), y.min(), x.max(), y.max())
        box = np.insert(box, wide + 1, halves[1::2], axis=0)
        box[wide + np.arange(len(wide))] = halves[0::2]
        bstart = np.insert(bstart, wide + 1, mids)


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
