"""What the closed-form methods (BEM, MFS) share: the normalised frame, boundary nodes, least squares, evaluation.

Both methods fit a closed-form approximation of the harmonic map of a
polygon (paper §3.1.2, §3.1.3) in normalised coordinates (`Frame`), on nodes
graded towards the polygon's corners (`boundary_nodes`), by least squares
(`lstsq`), and both evaluate it in the caller's coordinates through
`ClosedForm`.  This module knows nothing of Theta or of `ThetaMap`
(`warpcli.maps.meshless` makes the solutions maps onto Theta).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._extensions import scipy_extension
from ..boundary import to_theta_parameter

__all__ = [
    "TWO_PI",
    "ClosedForm",
    "Frame",
    "boundary_nodes",
    "caller_parameters",
    "distance_to_boundary",
    "interior_angles",
    "local_edges",
    "load_lstsq",
    "lstsq",
    "node_data",
    "on_edges",
    "prepare_polygon",
]

TWO_PI = 2.0 * np.pi


# --------------------------------------------------------------------------
# The normalised frame
# --------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Frame:
    """Normalisation of a polygon and of its boundary data.

    Local coordinates are ``(x - centre) / scale``; local data are
    ``(b - tcentre) / tscale``.  A map Phi computed in local coordinates
    gives ``phi(x) = tcentre + tscale * Phi((x - centre) / scale)``, hence
    ``J = tscale / scale * J_local`` and ``H = tscale / scale**2 * H_local``.

    Attributes
    ----------
    centre : (2,) ndarray of float
        Centre of the polygon's bounding box.
    scale : float
        Longer side of the bounding box.
    tcentre : (2,) ndarray of float
        Mean of the targets.
    tscale : float
        Largest absolute deviation of a target coordinate from ``tcentre``
        (1 if all targets coincide).
    flipped : bool
        The polygon was clockwise and its vertices were reversed: local edge j
        is the caller's edge n - 2 - j (mod n), traversed backwards.
    """

    centre: NDArray[np.float64]
    scale: float
    tcentre: NDArray[np.float64]
    tscale: float
    flipped: bool = False

    def to_local(self, points: ArrayLike) -> NDArray[np.float64]:
        """Local coordinates of points.

        Parameters
        ----------
        points : (K, 2) array_like of float

        Returns
        -------
        (K, 2) ndarray of float
        """
        return (_as_points(points) - self.centre) / self.scale


def _as_points(points: ArrayLike) -> NDArray[np.float64]:
    """Points as a C-contiguous (K, 2) float64 array (a single (2,) point is allowed)."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 1 and p.shape[0] == 2:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must have shape (K, 2), got {np.shape(points)}")
    return np.ascontiguousarray(p)


def prepare_polygon(
    vertices: ArrayLike, targets: ArrayLike
) -> tuple[Frame, NDArray[np.float64], NDArray[np.float64]]:
    """Validate and normalise a polygon and its vertex targets.

    Parameters
    ----------
    vertices : (n, 2) array_like of float
        A simple polygon, either orientation, n >= 3.
    targets : (n, 2) array_like of float
        Image of each vertex; the data are linear along edges.

    Returns
    -------
    frame : Frame
        The normalisation.
    V : (n, 2) ndarray of float
        Local vertices, counter-clockwise.
    T : (n, 2) ndarray of float
        Local targets, in the same (possibly reversed) order as ``V``.
    """
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(targets, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
        raise ValueError(f"vertices must have shape (n, 2) with n >= 3, got {v.shape}")
    if t.shape != v.shape:
        raise ValueError(f"targets must have the shape of vertices {v.shape}, got {t.shape}")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(t))):
        raise ValueError("vertices and targets must be finite")
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = 0.5 * (lo + hi)
    scale = float(np.max(hi - lo))
    if not scale > 0:
        raise ValueError("degenerate polygon")
    tcentre = t.mean(axis=0)
    tscale = float(np.max(np.abs(t - tcentre)))
    if not tscale > 0:
        tscale = 1.0
    V = (v - centre) / scale
    T = (t - tcentre) / tscale
    edges = np.roll(V, -1, axis=0) - V
    if np.min(np.hypot(edges[:, 0], edges[:, 1])) <= 1e-12:
        raise ValueError("polygon has a repeated vertex (zero-length edge)")
    area2 = np.sum(V[:, 0] * np.roll(V[:, 1], -1) - np.roll(V[:, 0], -1) * V[:, 1])
    if abs(area2) <= 1e-12:
        raise ValueError("polygon has zero area")
    if area2 < 0:  # clockwise: reverse, keeping each vertex with its target
        V = V[::-1].copy()
        T = T[::-1].copy()
    frame = Frame(centre=centre, scale=scale, tcentre=tcentre, tscale=tscale, flipped=bool(area2 < 0))
    return frame, np.ascontiguousarray(V), np.ascontiguousarray(T)


def interior_angles(vertices: ArrayLike) -> NDArray[np.float64]:
    """Interior angle at each vertex of a simple polygon.

    Parameters
    ----------
    vertices : (n, 2) array_like of float
        Either orientation.

    Returns
    -------
    (n,) ndarray of float
        Angles in (0, 2 pi); greater than pi at reflex vertices.
    """
    v = np.asarray(vertices, dtype=np.float64)
    v = v - v.mean(axis=0)  # no cancellation in the area when coordinates are large
    area2 = np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
    nxt = np.roll(v, -1, axis=0) - v
    prv = np.roll(v, 1, axis=0) - v
    if area2 < 0:
        nxt, prv = prv, nxt
    # counter-clockwise angle from the outgoing to the incoming edge
    cross = nxt[:, 0] * prv[:, 1] - nxt[:, 1] * prv[:, 0]
    dot = np.sum(nxt * prv, axis=1)
    return np.mod(np.arctan2(cross, dot), TWO_PI)


# --------------------------------------------------------------------------
# Boundary nodes and data
# --------------------------------------------------------------------------


def distance_to_boundary(points: NDArray[np.float64], V: NDArray[np.float64]) -> NDArray[np.float64]:
    """Euclidean distance from points to the boundary of a polygon.

    Parameters
    ----------
    points : (K, 2) ndarray of float
    V : (n, 2) ndarray of float
        The polygon's vertices, either orientation.

    Returns
    -------
    (K,) ndarray of float
    """
    d2 = np.full(len(points), np.inf)
    for i in range(len(V)):  # loop over edges, vectorised over points
        a = V[i]
        e = V[(i + 1) % len(V)] - a
        t = np.clip(((points - a) @ e) / (e @ e), 0.0, 1.0)
        r = points - (a + t[:, None] * e)
        d2 = np.minimum(d2, np.einsum("ij,ij->i", r, r))
    return np.sqrt(d2)


def _allocate(masses: NDArray[np.float64], total: int, minimum: int = 1) -> NDArray[np.int64]:
    """Split ``total`` into integers proportional to ``masses`` (largest remainder), each >= minimum.

    Shares that differ by less than 1e-6 * total count as equal and ties go
    to the lower index, so that rounding noise in the masses (e.g. of a
    polygon far from the origin, whose vertices are known to ~1e-10 of its
    size only) does not change the allocation of a symmetric polygon.
    """
    n = len(masses)
    if total < minimum * n:
        raise ValueError(f"need at least {minimum * n} nodes, got {total}")
    tol = 1e-6 * total
    share = (total - minimum * n) * masses / masses.sum()
    counts = np.floor(share + tol).astype(np.int64)
    rest = int(total - minimum * n - counts.sum())
    if rest > 0:
        rem = share - counts
        cut = np.sort(rem)[::-1][rest - 1]
        sure = rem > cut + tol
        tied = np.flatnonzero(np.abs(rem - cut) <= tol)
        counts[sure] += 1
        counts[tied[: rest - int(sure.sum())]] += 1
    elif rest < 0:  # shares just below an integer were rounded up: undo the smallest
        counts[np.argsort(share - counts, kind="stable")[:-rest]] -= 1
    return counts + minimum


def _graded_edge_parameters(
    length: float, gamma0: float, gamma1: float, count: int
) -> NDArray[np.float64]:
    """Node parameters 0 = t_0 < ... < t_{count-1} < 1 of ``count`` elements on one edge.

    The node density along the edge (arclength r, length l, R = l/2) is
    ``max(1, (r/R)^-gamma0)`` on the first half and the mirror image with
    ``gamma1`` on the second half, so element sizes near a graded end behave
    like ``r^gamma``, i.e. algebraic grading with exponent 1/(1 - gamma):
    the classical remedy for the r^(pi/alpha - 1) singularity of the normal
    derivative at a reflex vertex (paper §3.1.4: "oscillations ... near
    concave corners").
    """
    half = 0.5 * length
    b0, b1 = 1.0 / (1.0 - gamma0), 1.0 / (1.0 - gamma1)
    m0, m1 = half * b0, half * b1
    F = np.arange(count) * (m0 + m1) / count
    r = np.empty(count)
    first = F <= m0
    r[first] = half * (F[first] / m0) ** b0
    F2 = F[~first] - m0
    r[~first] = length - half * ((m1 - F2) / m1) ** b1
    return r / length


def _edge_masses(lengths: NDArray[np.float64], gamma: NDArray[np.float64]) -> NDArray[np.float64]:
    """Node mass of each edge for the density of `_graded_edge_parameters`."""
    g0 = gamma
    g1 = np.roll(gamma, -1)
    return 0.5 * lengths * (1.0 / (1.0 - g0) + 1.0 / (1.0 - g1))


def boundary_nodes(
    V: NDArray[np.float64], total: int, gamma: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Nodes on the boundary of a polygon, including every vertex.

    Parameters
    ----------
    V : (n, 2) ndarray of float
        Polygon (counter-clockwise).
    total : int
        Number of nodes, >= n.
    gamma : (n,) ndarray of float
        Grading strength at each vertex, in [0, 1); 0 means none.

    Returns
    -------
    edge : (total,) ndarray of int
        Edge of each node (node at parameter 0 of edge i is vertex i).
    t : (total,) ndarray of float
        Parameter of each node along its edge, in [0, 1).
    """
    e = np.roll(V, -1, axis=0) - V
    lengths = np.hypot(e[:, 0], e[:, 1])
    counts = _allocate(_edge_masses(lengths, gamma), total)
    edge = np.repeat(np.arange(len(V)), counts)
    t = np.concatenate(
        [
            _graded_edge_parameters(lengths[i], gamma[i], gamma[(i + 1) % len(V)], counts[i])
            for i in range(len(V))  # loop over edges
        ]
    )
    return edge, t


def on_edges(V: NDArray[np.float64], edge: NDArray[np.int64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points at parameters along edges of a polygon.

    Parameters
    ----------
    V : (n, 2) ndarray of float
        The polygon's vertices; edge i runs from vertex i to vertex i + 1.
    edge : (K,) ndarray of int
    t : (K,) ndarray of float
        Parameters in [0, 1] along the edges.

    Returns
    -------
    (K, 2) ndarray of float
    """
    a = V[edge]
    b = V[(edge + 1) % len(V)]
    return a + t[:, None] * (b - a)


def node_data(
    T: NDArray[np.float64], edge: NDArray[np.int64], t: NDArray[np.float64], boundary: str, flipped: bool
) -> NDArray[np.float64]:
    """Boundary data at nodes (local edge, parameter): Theta's points at the boundary behaviour's parameter.

    The behaviour (`warpcli.boundary.to_theta_parameter`: linear, or the
    paper's quadratic of §5.2) is defined along the caller's edges; a reversed
    polygon (``flipped``) runs along them backwards, so there s(t) becomes
    1 - s(1 - t).

    Parameters
    ----------
    T : (n, 2) ndarray of float
        Local targets of the (local, counter-clockwise) vertices.
    edge : (K,) ndarray of int
        Local edge of each node.
    t : (K,) ndarray of float
        Parameter of each node along its edge.
    boundary : {"linear", "quadratic"}
        The boundary behaviour.
    flipped : bool
        `Frame.flipped`.

    Returns
    -------
    (K, 2) ndarray of float
        The data at the nodes.
    """
    if boundary == "linear":
        s = t
    elif flipped:
        s = 1.0 - to_theta_parameter(1.0 - t, boundary)
    else:
        s = to_theta_parameter(t, boundary)
    n = len(T)
    return (1.0 - s)[:, None] * T[edge] + s[:, None] * T[(edge + 1) % n]


def local_edges(edges: tuple[int, ...], n: int, flipped: bool) -> NDArray[np.int64]:
    """Local indices of the caller's edges (see `Frame.flipped`).

    Parameters
    ----------
    edges : tuple of int
        The caller's edge indices (edge i runs from vertex i to i + 1).
    n : int
        Number of vertices.
    flipped : bool
        `Frame.flipped`.

    Returns
    -------
    (len(edges),) ndarray of int
    """
    e = np.asarray(edges, dtype=np.int64) % n
    return (n - 2 - e) % n if flipped else e


def caller_parameters(
    edge: NDArray[np.int64], t: NDArray[np.float64], n: int, flipped: bool
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The caller's (edge, parameter) of local ones (see `Frame.flipped`).

    Parameters
    ----------
    edge : (K,) ndarray of int
        Local edges.
    t : (K,) ndarray of float
        Local parameters.
    n : int
        Number of vertices.
    flipped : bool
        `Frame.flipped`.

    Returns
    -------
    edge : (K,) ndarray of int
    t : (K,) ndarray of float
    """
    if not flipped:
        return edge, t
    return (n - 2 - edge) % n, 1.0 - t


# --------------------------------------------------------------------------
# Least squares and evaluation
# --------------------------------------------------------------------------


def lstsq(A: NDArray[np.float64], b: NDArray[np.float64], cond: float | None = None) -> NDArray[np.float64]:
    """Least squares by LAPACK gelsd, with BLAS on one thread.

    Multithreaded BLAS splits the sums differently for different thread
    counts, which changed BEM and MFS fits in the last bits (measured:
    OPENBLAS_NUM_THREADS=1 against 2), and with the two maps fitted
    concurrently it oversubscribes the cores (a fit took 6-17 s under load
    instead of 0.7 s). One thread: the same bytes on any machine's thread
    settings, and no oversubscription.

    Parameters
    ----------
    A : (M, N) ndarray of float
    b : (M,) or (M, K) ndarray of float
    cond : float, optional
        Relative cut-off for small singular values (LAPACK's default if None).

    Returns
    -------
    (N,) or (N, K) ndarray of float
        The minimum-norm least-squares solution.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _gelsd(A, b, cond)


def _gelsd(A, b, cond: float | None) -> NDArray[np.float64]:
    """``scipy.linalg.lstsq(A, b, cond=cond, lapack_driver="gelsd")[0]``, the same LAPACK calls with
    the same arguments (so the same bits) for real float64 data, without importing scipy.linalg.

    Importing scipy.linalg imports numpy.testing, unittest, importlib.metadata and more
    (0.17 s of a 1.6 s MFS warp at 1 MP, on the map's path); its LAPACK routines live in one
    extension module, loaded here from its file (`_flapack`). Other data, or a scipy whose
    module cannot be loaded so, go through scipy.linalg itself.
    """
    a1 = np.asarray_chkfinite(A)  # lstsq's checks (check_finite=True): NaN or inf raise ValueError
    b1 = np.asarray_chkfinite(b)
    flapack = _flapack() if a1.dtype == np.float64 and b1.dtype == np.float64 and a1.ndim == 2 else None
    m, n = a1.shape if a1.ndim == 2 else (0, 0)
    if flapack is None or b1.ndim not in (1, 2) or b1.shape[0] != m or m < n or n == 0:
        import scipy.linalg

        return scipy.linalg.lstsq(A, b, cond=cond, lapack_driver="gelsd")[0]
    nrhs = b1.shape[1] if b1.ndim == 2 else 1
    if cond is None:
        cond = np.finfo(np.float64).eps
    # scipy's _compute_lwork: the workspace query's sizes, as integers
    work, iwork, info = flapack.dgelsd_lwork(m, n, nrhs, cond)
    if info != 0:
        raise ValueError(f"Internal work array size computation failed: {info}")
    lwork, liwork = int(work.real), int(iwork.real)
    if not (0 <= lwork <= np.iinfo(np.intc).max and 0 <= liwork <= np.iinfo(np.intc).max):
        raise ValueError("Too large work array required -- computation cannot be performed with standard 32-bit LAPACK.")
    x, _, _, info = flapack.dgelsd(a1, b1, lwork, liwork, cond, False, False)
    if info > 0:
        raise np.linalg.LinAlgError("SVD did not converge in Linear Least Squares")
    if info < 0:
        raise ValueError(f"illegal value in {-info}-th argument of internal gelsd")
    return x[:n]


def load_lstsq() -> None:
    """Load what `lstsq` calls (LAPACK's module, threadpoolctl) now: before a fork, the
    children find them loaded rather than each loading them again."""
    from threadpoolctl import threadpool_limits

    _flapack()
    with threadpool_limits(limits=1, user_api="blas"):
        pass


_FLAPACK_NAME = "scipy.linalg._flapack"
_FLAPACK: list = []
_FLAPACK_LOCK = threading.Lock()


def _flapack():
    """scipy's Fortran LAPACK extension module, loaded without importing scipy.linalg
    (`warpcli._extensions.scipy_extension`); None if it cannot be loaded so."""
    with _FLAPACK_LOCK:
        if not _FLAPACK:
            try:
                module = scipy_extension(_FLAPACK_NAME)
            except (ImportError, OSError):
                module = None
            _FLAPACK.append(module if module is not None and hasattr(module, "dgelsd") and hasattr(module, "dgelsd_lwork") else None)
        return _FLAPACK[0]


def __getattr__(name: str):
    # `fast_log` is compiled code (numba) and lives with the kernels in
    # `warpcli.maps._smooth_kernels`: importing it here on first use keeps
    # numba out of processes that only call the kernels natively.
    if name == "fast_log":
        from ._smooth_kernels import fast_log

        return fast_log
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class ClosedForm:
    """A map given in closed form in a `Frame`'s local coordinates (BEM and MFS solutions).

    Subclasses have a ``frame`` and implement ``_local(p, want_val,
    want_jac, want_hess)`` on local points, returning the local value (K, 2),
    Jacobian (K, 2, 2) and Hessian (K, 2, 2, 2) (empty where not wanted);
    this class turns them into the caller's coordinates.
    """

    frame: Frame

    def _local(self, p: NDArray[np.float64], want_val: bool, want_jac: bool, want_hess: bool):
        raise NotImplementedError

    def _eval(self, points: ArrayLike, want_val: bool, want_jac: bool, want_hess: bool):
        f = self.frame
        val, jac, hess = self._local(f.to_local(points), want_val, want_jac, want_hess)
        return f.tcentre + f.tscale * val, jac * (f.tscale / f.scale), hess * (f.tscale / f.scale**2)

    def value(self, points: ArrayLike) -> NDArray[np.float64]:
        """The map at points inside the polygon.

        Parameters
        ----------
        points : (K, 2) array_like of float
            Points inside the polygon, where the closed form approximates phi
            (BEM's representation formula is ~0 outside and undefined on the
            boundary; MFS's is defined everywhere but at its sites).

        Returns
        -------
        (K, 2) ndarray of float
            phi(points).
        """
        return self._eval(points, True, False, False)[0]

    def jacobian(self, points: ArrayLike) -> NDArray[np.float64]:
        """The Jacobian of the map at points inside the polygon.

        Parameters
        ----------
        points : (K, 2) array_like of float

        Returns
        -------
        (K, 2, 2) ndarray of float
            ``J[k, a, b]`` = d phi_a / d x_b.
        """
        return self._eval(points, False, True, False)[1]

    def value_and_jacobian(self, points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Value and Jacobian in one pass (cheaper than two calls).

        Parameters
        ----------
        points : (K, 2) array_like of float

        Returns
        -------
        value : (K, 2) ndarray of float
        jacobian : (K, 2, 2) ndarray of float
        """
        val, jac, _ = self._eval(points, True, True, False)
        return val, jac

    def value_jacobian_hessian(
        self, points: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Value, Jacobian and Hessian in one pass (what the certificate needs).

        Parameters
        ----------
        points : (K, 2) array_like of float

        Returns
        -------
        value : (K, 2) ndarray of float
        jacobian : (K, 2, 2) ndarray of float
        hessian : (K, 2, 2, 2) ndarray of float
        """
        return self._eval(points, True, True, True)

    def _local_bounds(self, p: NDArray[np.float64], reach: NDArray[np.float64]) -> NDArray[np.float64]:
        raise NotImplementedError

    def derivative_bounds(self, points: ArrayLike, reach: ArrayLike) -> NDArray[np.float64]:
        """Bounds over discs of how far the map's complex derivatives stray from their first-order Taylor polynomials.

        Write the map as f = u + i v with u = Re U, v = Re V (U, V analytic
        in the polygon) and let A = (U' + i V') / 2, B = (U' - i V') / 2, so
        that f_z = A, conj(f_zbar) = B and det J = |A|^2 - |B|^2. Each
        closed form is a sum of terms (MFS: sites; BEM: single- and
        double-layer integrals over straight elements) whose k-th
        derivatives are bounded by the term's weight over a power of its
        distance from the disc; summed, they bound the Taylor remainders of
        A and B over the whole disc (see `warpcli.maps.certificate.lower_bound`).

        Parameters
        ----------
        points : (K, 2) array_like of float
            Centres p of the discs (the caller's coordinates).
        reach : (K,) array_like of float
            Their radii r.

        Returns
        -------
        (K, 3) ndarray of float
            Column 0: a bound of the evaluation error of A(p) and B(p)
            (rounding; BEM: its quadrature too); columns 1 and 2: upper
            bounds of |A(p + h) - A(p) - A'(p) h| and of the same for B over
            |h| <= r (inf where the disc reaches a site or the boundary).
        """
        f = self.frame
        r = np.asarray(reach, dtype=np.float64) / f.scale
        b = self._local_bounds(f.to_local(points), np.ascontiguousarray(r))
        # a disc reaching a pole gives 0 * inf = nan for a zero weight: no bound there
        return np.where(np.isnan(b), np.inf, b) * (f.tscale / f.scale)

    def hessian(self, points: ArrayLike) -> NDArray[np.float64]:
        """Second derivatives of the map at points inside the polygon.

        Parameters
        ----------
        points : (K, 2) array_like of float

        Returns
        -------
        (K, 2, 2, 2) ndarray of float
            ``H[k, a, b, c]`` = d^2 phi_a / dx_b dx_c (symmetric in b, c;
            trace-free in b, c since phi is harmonic).
        """
        return self._eval(points, False, False, True)[2]
