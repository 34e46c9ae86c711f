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

__all__ = ["ARMIJO", "MAX_HALVINGS", "invert", "thresholds"]

#: Armijo constant of the sufficient-decrease test on d(y) = ||x - fun(y)||^2.
ARMIJO = 1e-4
#: Largest number of step halvings in one line search.
MAX_HALVINGS = 40


def thresholds(targets_xy: NDArray[np.float64], tol: float, floor: float | None) -> tuple[float, float]:
    """The absolute residuals of `invert`'s tests: convergence, and the noise floor.

    Parameters
    ----------
    targets_xy : (K, 2) ndarray of float
        The points to invert (K >= 1).
    tol, floor : float
        `invert`'s ``tol`` and ``floor`` (relative).

    Returns
    -------
    thresh, noise : float
        ``tol * s`` and ``max(thresh, floor * s)`` with ``s = max(1, max |targets_xy|)``.
    """
    s = max(1.0, float(np.max(np.abs(targets_xy))))
    thresh = tol * s
    return thresh, max(thresh, (floor or 0.0) * s)


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
    fun_jac: Callable[[NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.float64]]] | None = None,
    jacobian: bool = False,
    hopeless: Callable[[NDArray[np.float64]], NDArray[np.bool_]] | None = None,
    hopeless_after: int = 2,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]] | tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]:
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
    fun_jac : callable, optional
        ``fun_jac(points)`` returns ``(fun(points), jac(points))`` in one
        pass. Given, every trial point is evaluated with it and a Newton
        step reuses the Jacobian of the iterate's own evaluation, instead of
        a separate ``jac`` pass per iteration: for maps whose Jacobian costs
        little more than their value once evaluated together (BEM's
        treecode: one traversal for both). ``jac`` is then not called.
    jacobian : bool, optional
        Also return ``jac`` at the last iterate of every converged point
        (NaN elsewhere): from the last evaluation with ``fun_jac``, else
        from one pass of ``jac`` over the converged points.

    hopeless : callable, optional
        ``hopeless(targets)`` with targets (k, 2) returns a (k,) bool mask,
        True for targets the caller knows need no pre-image from this
        iteration (BEM: values in its collar's image, whose pre-images lie in
        the collar's band). Asked once, after ``hopeless_after`` iterations,
        for the points still iterating; those it marks stop there, not
        converged. Without it the iteration is as before, bit for bit.
    hopeless_after : int, optional
        The iterations before ``hopeless`` is asked.

    Returns
    -------
    points : (K, 2) ndarray of float
        The last iterate for each point.
    converged : (K,) ndarray of bool
        Whether the residual test was met.
    jacobians : (K, 2, 2) ndarray of float
        With ``jacobian`` only: ``jac(points)`` where converged, NaN elsewhere.
    """
    x = np.array(targets_xy, dtype=np.float64, ndmin=2)
    y = np.array(guess, dtype=np.float64, ndmin=2)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 2:
        raise ValueError(f"targets_xy and guess must both have shape (K, 2); got {x.shape}, {y.shape}")
    K = len(x)
    converged = np.zeros(K, dtype=bool)
    if K == 0:
        return (y, converged, np.zeros((0, 2, 2))) if jacobian else (y, converged)
    thresh, noise = thresholds(x, tol, floor)

    active = np.arange(K)
    if inside is not None:
        active = active[np.asarray(inside(y), dtype=bool)]
    r = np.zeros_like(x)
    # with fun_jac: the Jacobian at each point's current iterate
    J_at = np.full((K, 2, 2), np.nan) if fun_jac is not None else None
    if J_at is not None:
        v0, j0 = fun_jac(y[active])
        r[active] = x[active] - v0
        J_at[active] = j0
    else:
        r[active] = x[active] - fun(y[active])
    f = np.einsum("ij,ij->i", r, r)
    ok = np.sqrt(f[active]) <= thresh
    converged[active[ok]] = True
    active = active[~ok]

    for it in range(max_iter):
        if hopeless is not None and it == hopeless_after and len(active):
            active = active[~np.asarray(hopeless(x[active]), dtype=bool)]
        if len(active) == 0:
            break
        J = J_at[active] if J_at is not None else jac(y[active])
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
        for _ in range(MAX_HALVINGS):
            if len(pending) == 0:
                break
            idx = active[pending]
            trial = y[idx] + step[pending, None] * d[pending]
            good = np.ones(len(pending), dtype=bool)
            if inside is not None:
                good &= np.asarray(inside(trial), dtype=bool)
            rt = np.full_like(trial, np.inf)
            jt = None
            if good.any():
                if J_at is not None:
                    vt, jt = fun_jac(trial[good])
                    rt[good] = x[idx[good]] - vt
                    jt_full = np.empty((len(pending), 2, 2))
                    jt_full[good] = jt
                else:
                    rt[good] = x[idx[good]] - fun(trial[good])
            ft = np.einsum("ij,ij->i", rt, rt)
            good &= ft <= (1.0 - 2.0 * ARMIJO * step[pending]) * f[idx]
            # a step that already meets the tolerance is always welcome
            good |= np.isfinite(ft) & (np.sqrt(ft) <= thresh)
            y[idx[good]] = trial[good]
            r[idx[good]] = rt[good]
            f[idx[good]] = ft[good]
            if jt is not None:
                J_at[idx[good]] = jt_full[good]
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
    if not jacobian:
        return y, converged
    J_out = np.full((K, 2, 2), np.nan)
    done = np.flatnonzero(converged)
    if J_at is not None:
        J_out[done] = J_at[done]
    elif done.size:
        J_out[done] = jac(y[done])
    return y, converged, J_out
