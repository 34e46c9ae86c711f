"""Pointwise inversion of a smooth map by damped Newton iteration (paper §3.2).

The paper minimises d(y) = ||x - phi_1(y)||^2 with Ipopt, constrained to the
domain of phi_1.  With the analytic 2x2 Jacobian of the BEM or MFS map, a
Newton step for phi_1(y) = x is a closed-form 2x2 solve per point; a
backtracking line search on d makes it globally convergent from any start
where the Jacobian is regular, and halving the step whenever the trial point
leaves the domain keeps the iterates where phi_1 is defined.  All points
iterate together; points that converged (or cannot make progress) drop out.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["invert"]

#: Armijo constant of the sufficient-decrease test on d(y) = ||x - fun(y)||^2.
_ARMIJO = 1e-4
#: Largest number of step halvings in one line search.
_MAX_HALVINGS = 40


def invert(
    fun: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    jac: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    targets_xy: ArrayLike,
    guess: ArrayLike,
    *,
    tol: float = 1e-12,
    max_iter: int = 20,
    inside: Callable[[NDArray[np.float64]], NDArray[np.bool_]] | None = None,
    floor: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Solve fun(y) = x for y, for every row x of ``targets_xy``, by damped Newton.

    Parameters
    ----------
    fun : callable
        ``fun(points)`` with points (k, 2) returns (k, 2): the map.
    jac : callable
        ``jac(points)`` returns (k, 2, 2): its Jacobian, ``J[i, a, b]`` =
        d fun_a / d y_b.
    targets_xy : (K, 2) array_like of float
        The points x to invert.
    guess : (K, 2) array_like of float
        Starting points y_0, inside the domain.
    tol : float, optional
        A point has converged when ``||x - fun(y)|| <= tol * s`` with
        ``s = max(1, max |targets_xy|)`` (a relative residual in the image).
    max_iter : int, optional
        Newton iterations at most.
    inside : callable, optional
        ``inside(points)`` with points (k, 2) returns a (k,) bool mask, True
        where fun is defined.  Trial points outside get their step halved;
        a starting point outside fails at once.
    floor : float, optional
        The rounding noise of ``fun``, relative like ``tol``: a point whose
        line search can make no more progress (or that runs out of
        iterations) has converged if its residual is within it. A map summed
        from large terms (MFS with many sites) cannot get below ``tol``.

    Returns
    -------
    points : (K, 2) ndarray of float
        The last iterate for each point.
    converged : (K,) ndarray of bool
        Whether the residual test was met.
    """
    x = np.array(targets_xy, dtype=np.float64, ndmin=2)
    y = np.array(guess, dtype=np.float64, ndmin=2)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 2:
        raise ValueError(f"targets_xy and guess must both have shape (K, 2); got {x.shape}, {y.shape}")
    K = len(x)
    converged = np.zeros(K, dtype=bool)
    if K == 0:
        return y, converged
    thresh = tol * max(1.0, float(np.max(np.abs(x))))
    noise = max(thresh, (floor or 0.0) * max(1.0, float(np.max(np.abs(x)))))

    active = np.arange(K)
    if inside is not None:
        active = active[np.asarray(inside(y), dtype=bool)]
    r = np.zeros_like(x)
    r[active] = x[active] - fun(y[active])
    f = np.einsum("ij,ij->i", r, r)
    ok = np.sqrt(f[active]) <= thresh
    converged[active[ok]] = True
    active = active[~ok]

    for _ in range(max_iter):
        if len(active) == 0:
            break
        J = jac(y[active])
        ra = r[active]
        # Newton step J d = r, closed form per point
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.stack(
                [
                    (J[:, 1, 1] * ra[:, 0] - J[:, 0, 1] * ra[:, 1]) / det,
                    (J[:, 0, 0] * ra[:, 1] - J[:, 1, 0] * ra[:, 0]) / det,
                ],
                axis=1,
            )
        regular = np.all(np.isfinite(d), axis=1)
        active, d = active[regular], d[regular]

        # Backtracking: halve the step until the trial point is inside and
        # d(y) decreases enough (Armijo; the Newton direction has slope -2 d).
        step = np.ones(len(active))
        pending = np.arange(len(active))
        accepted = np.zeros(len(active), dtype=bool)
        for _ in range(_MAX_HALVINGS):
            if len(pending) == 0:
                break
            idx = active[pending]
            trial = y[idx] + step[pending, None] * d[pending]
            good = np.ones(len(pending), dtype=bool)
            if inside is not None:
                good &= np.asarray(inside(trial), dtype=bool)
            rt = np.full_like(trial, np.inf)
            if good.any():
                rt[good] = x[idx[good]] - fun(trial[good])
            ft = np.einsum("ij,ij->i", rt, rt)
            good &= ft <= (1.0 - 2.0 * _ARMIJO * step[pending]) * f[idx]
            # a step that already meets the tolerance is always welcome
            good |= np.isfinite(ft) & (np.sqrt(ft) <= thresh)
            y[idx[good]] = trial[good]
            r[idx[good]] = rt[good]
            f[idx[good]] = ft[good]
            accepted[pending[good]] = True
            pending = pending[~good]
            step[pending] *= 0.5
        # points whose line search failed cannot make progress: converged
        # if within the rounding noise, dropped otherwise
        stuck = active[~accepted]
        converged[stuck[np.sqrt(f[stuck]) <= noise]] = True
        active = active[accepted]
        ok = np.sqrt(f[active]) <= thresh
        converged[active[ok]] = True
        active = active[~ok]
    converged[active[np.sqrt(f[active]) <= noise]] = True
    return y, converged
