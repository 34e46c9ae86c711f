"""BEM and MFS as map methods (the paper's §3.1.2, §3.1.3, §3.2): smooth maps onto Theta without a mesh.

`bem` and `mfs` compute closed-form approximations of the harmonic map with
analytic derivatives; this module makes them `ThetaMap`s:

- evaluate: the closed form inside the polygon, moved onto Theta where the
  approximation lands just outside it (the exact map cannot); on its
  boundary the exact boundary data (the Dirichlet data is known there; BEM's
  integrals are singular at boundary nodes and both methods only
  approximate it);
- inverse (§3.2): a piecewise-linear first guess from a triangulation of
  the polygon mapped into Theta, then damped Newton steps on
  ||x - phi(y)||^2 with the analytic Jacobian, constrained to the polygon
  (`newton.invert`); points of Theta's boundary go through the exact
  inverse boundary map;
- certify: `warpcli.maps.boundary_certificate`, a proof from one curve
  (the polygon for MFS, 0.01 px inside it for BEM) that det J > 0 and the
  map is one-to-one inside it (maximum modulus of the dilatation B/A, the
  argument principle, a simple image curve); where the boundary data
  themselves force det J -> 0 at a vertex (its behaviour, its conditions),
  `warpcli.maps.certificate` instead: det J and the values cell by cell,
  with a sub-band ball left out at such vertices (a smooth map has no
  triangles to check; Radó-Kneser-Choquet holds for the exact map, and the
  approximations converge to it as m grows).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._cached import cached_property
from .._native import Kernels
from ..boundary import BoundaryData, nearest_edge, slide
from ..budget import MAX_IMAGE_BYTES_ENV, max_image_bytes
from ..errors import InputError, MeshingError
from ..files import format_bytes
from ..polygon import Polygon
from .base import Certificate, EdgeTables, ForkedBuild, Mapped, ThetaMap, as_points, inv2, sliding_tables
from .boundary_certificate import BoundaryCertificate, certify_boundary, offset_band
from .certificate import CellCertificate, band_floor, certify_cells, degenerate_vertices, vertex_ball
from .collar import Collar
from .theta import Theta

#: Points closer than this (times the polygon's size) to its boundary take the exact boundary data.
ON_BOUNDARY = 1e-9
#: Triangles of the first-guess triangulation (§3.2).
GUESS_TRIANGLES = 4000
#: Residual (relative to Theta) within which Newton accepts a point it cannot improve further.
NEWTON_FLOOR = 1e-9
#: The most nodes warpcli chooses by itself: the default m, max(256, 8 n), is
#: capped here, and a map that folds with it is fitted again with twice the
#: nodes only while that stays within it. A fit costs ~m^3 time and ~m^2
#: memory: MFS, m = 2400: 20 s and 0.9 GB for the fit alone; a 53-vertex comb
#: refitted 424 -> 3392 took 338 s and 3.9 GB (to be refused: still folded);
#: m = 4800, a 600-vertex polygon's default: 70 s and 6.5 GB, then a failure.
MAX_AUTO_NODES = 2048
#: Peak bytes of a whole warp per m^2 (measured: MFS 6.5 GB, BEM 4.9 GB at
#: m = 4800, 512 x 512): a fit with m nodes is refused, or not attempted as a
#: refit, when this times m^2 is more than `warpcli.budget.max_image_bytes`.
FIT_BYTES_PER_NODE2 = {"bem": 220, "mfs": 300}

#: Methods certified by `certify_boundary` (rigorous, and 0.3-0.5x the first-order cell test's time for BEM,
#: 0.02-0.15x the rigorous cells' for MFS on the bench pairs; docs/proving.md), unless a vertex is
#: degenerate; the others by the cell certificate (`certify_cells`).
BOUNDARY_CERTIFIED = frozenset({"bem", "mfs"})
#: Gamma's distances inside the polygon, in units of `band_floor` (0.01 px at 1 MP): the first that
#: proves the map with its band is taken (`SmoothMap.boundary_certificate`).
BAND_STEPS = (1.0, 4.0, 16.0, 64.0, 256.0)
#: BEM's first distance is at least this fraction of the polygon's size (`band_floor`'s 0.01 px is less
#: above 1e4 px). Its evaluation error bound at Gamma (`warpcli.maps._bem_kernels.bem_bounds`: 1e-13 of
#: the terms' sizes over their squared distance) grows like 1/delta^2 in the fit's normalised frame,
#: while the margin of phi(Gamma) inside Theta shrinks like delta: pieces no longer than ~delta |A| / eta,
#: their number growing like (size / delta)^3. 0.01 px inside a 2e5 px square (5e-8 of its size): eta
#: ~0.3 |A|, tens of millions of pieces; at 1e-6 of any size, 7,250 pieces (0.4 s), the same at every scale.
BEM_BAND_RELATIVE = 1e-6
#: Starts Newton tries, nearest first, for a point of Theta it did not invert from its first guess
#: (`SmoothMap._second_starts`).
SECOND_STARTS = 8

log = logging.getLogger("warpcli")
_compiled = Kernels("warpcli.maps._smooth_kernels")


@dataclass(eq=False)
class SmoothMap(ThetaMap):
    """A smooth map onto Theta given in closed form (a BEM or MFS solution).

    Parameters
    ----------
    polygon : Polygon
    theta : Theta
    solution : BEMSolution or MFSSolution
        ``value_and_jacobian(points)`` of the harmonic map, in the
        polygon's coordinates.
    method : str
        ``"bem"`` or ``"mfs"``.

    References
    ----------
    Schneider & Hormann, CAGD 2015, §3.1.2, §3.1.3, §3.2.
    """

    solution: Any = field(repr=False, default=None)
    name: str = "bem"
    conditions: str = "dirichlet"

    @property
    def method(self) -> str:  # type: ignore[override]
        return self.name

    @cached_property
    def _size(self) -> float:
        xmin, ymin, xmax, ymax = self.polygon.bounds
        return max(xmax - xmin, ymax - ymin)

    def _split(self, p: NDArray[np.float64]):
        """Indices of the points strictly inside (the closed form's domain), and of those on the
        boundary (to ON_BOUNDARY) with their edge and parameter; then those of the first in the
        collar's band (`collar`), which are no longer among them."""
        finite = np.flatnonzero(np.isfinite(p).all(axis=1))
        on = ON_BOUNDARY * self._size
        cand, edge, t, dist = _nearest_within(p[finite], self.polygon.points, self._polygon_xy, max(on, self._band_width))
        on_edge = dist <= on
        near = cand[on_edge]
        inside = self._inside_polygon(p[finite])
        inside[near] = False
        k = finite[inside]
        band = np.zeros(0, dtype=np.intp)
        close = cand[inside[cand] & (dist <= self._band_width)]
        if close.size and self.collar is not None:
            in_band = ~self.collar.inside(p[finite[close]])
            band = finite[close[in_band]]
            inside[close[in_band]] = False
            k = finite[inside]
        return k, finite[near], edge[on_edge], t[on_edge], band

    @cached_property
    def _band_width(self) -> float:
        """How far from the boundary a point may be in the collar's band (0: no band)."""
        return 1.0001 * max(self._band_widths) if self.name in BOUNDARY_CERTIFIED else 0.0

    @cached_property
    def collar(self) -> Collar | None:
        """The map in the band between the polygon and the curve the certificate proved it on
        (`warpcli.maps.collar`); None when there is no band (MFS proved on its polygon) or the band
        was not proved (boundary data other than linear, a map that failed)."""
        proof = self.boundary_certificate if self.name in BOUNDARY_CERTIFIED else None
        if proof is None or not proof.ok or not proof.band:
            return None
        band = offset_band(self.polygon.points, proof.offset)
        return Collar(band, self.solution, self._collar_data, proof.knots)

    def evaluate(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        p = as_points(points)
        out = np.full(p.shape, np.nan)
        jac = np.full((len(p), 2, 2), np.nan) if jacobian else None
        k, on, edge, t, band = self._split(p)
        if k.size:
            v, j = self.solution.value_and_jacobian(p[k])
            self.theta.clamp(v)
            out[k] = v
            if jac is not None:
                jac[k] = j
        out[on] = self.boundary_to_theta(edge, t)
        if band.size:
            out[band], jb = self.collar.evaluate(p[band], jacobian=jac is not None)
            if jac is not None:
                jac[band] = jb
        return Mapped(out, jac)

    def hessian(self, points: ArrayLike) -> NDArray[np.float64]:
        """Second derivatives of phi at points inside the polygon (the closed form's, exact for it).

        Parameters
        ----------
        points : (K, 2) array_like of float

        Returns
        -------
        (K, 2, 2, 2) ndarray of float
            ``H[k, a, b, c]`` = d^2 phi_a / dx_b dx_c; NaN outside the polygon
            and on its boundary, and in the collar's band (`collar`).
        """
        p = as_points(points)
        out = np.full((len(p), 2, 2, 2), np.nan)
        k = self._split(p)[0]  # not in the collar's band: NaN there too
        if k.size:
            out[k] = self.solution.hessian(p[k])
        return out

    def inverse(self, points: ArrayLike, *, jacobian: bool = False, coherent: bool = False) -> Mapped:
        from .newton import invert, thresholds

        q = as_points(points)
        out = np.full(q.shape, np.nan)
        finite = np.flatnonzero(np.isfinite(q).all(axis=1))
        w = self.theta.points
        k = np.zeros(0, dtype=np.intp)
        jac_k = None
        if finite.size:
            scale = float(np.ptp(w, axis=0).max())
            near, edge, s = _on_boundary(q[finite], w, self._theta_xy, ON_BOUNDARY * scale)
            inside = _inside_points(q[finite], *self._theta_xy)
            inside[near] = False
            out[finite[near]] = self.boundary_from_theta(edge, s)
            k = finite[inside]
            if k.size:
                mesh = self._guess_mesh[0]
                compiled = getattr(self.solution, "invert_newton", None)
                # MFS, coherent targets (a pull-back's pixels, row by row): a point in a run of
                # evenly spaced targets starts from the extrapolation of the pre-images before
                # it (`MFSSolution.invert_newton`'s ``chain``), the others from the first guess
                chain = _steady(q[k]) if compiled is not None and coherent else None
                located = None  # BEM, coherent: which starts are first guesses (the others interpolated)
                if chain is None and coherent and self.name == "bem":
                    guess, located = self._coherent_guess(q[k])
                elif chain is None:
                    guess = self._first_guess(q[k])
                else:
                    guess = np.full((len(k), 2), np.nan)
                    need = np.flatnonzero(~chain)
                    guess[need] = self._first_guess(q[k[need]])
                # Converged when phi(y) is within rounding of x: relative to
                # Theta, scaled by how far the polygon sits from the origin
                # compared with its size (coordinates near 1e6 round at 1e-10).
                far = float(np.abs(self.polygon.points).max()) / self._size
                # Sums of many large terms (MFS weights grow with m: 1e5 at
                # m = 1024) round at ~1e-11; Newton accepts a point stuck
                # there (NEWTON_FLOOR: 1e-9 of Theta, ~1e-6 px).
                # BEM's treecode evaluates the Jacobian with the value for
                # little more than the value alone: every trial point gets
                # both and Newton's next step reuses them (measured at 1 MP:
                # a third less evaluation). MFS's compiled Newton does the same
                # per point (`warpcli.maps._smooth_kernels.mfs_invert`).
                tol = 1e-12 * max(1.0, 4.0 * far)
                if compiled is not None:
                    # MFS: the same iteration per point, compiled (measured at
                    # 1 MP: the numpy passes around its cheap sums cost as much
                    # as the sums)
                    thresh, noise = thresholds(q[k], tol, NEWTON_FLOOR)
                    y, ok, j_mfs = compiled(q[k], guess, self.polygon.points, thresh, noise, jacobian=jacobian, chain=chain)
                    again = np.zeros(0, dtype=np.intp) if chain is None else np.flatnonzero(chain & ~ok)
                    if again.size:
                        # chained points whose run broke off (a predecessor not converged) or
                        # whose extrapolation did not converge: again from the first guess
                        guess[again] = self._first_guess(q[k[again]])
                        y2, ok2, j2 = compiled(q[k[again]], guess[again], self.polygon.points, thresh, noise, jacobian=jacobian)
                        y[again], ok[again] = y2, ok2
                        if jacobian:
                            j_mfs[again] = j2
                    jy = [j_mfs]
                elif self.name == "bem":
                    thresh, noise = thresholds(q[k], tol, NEWTON_FLOOR)
                    y, ok, *jy = self._bem_newton(q[k], guess, thresh, noise, jacobian)
                    again = np.zeros(0, dtype=np.intp) if located is None else np.flatnonzero(~ok & ~located)
                    if again.size:
                        # interpolated starts Newton did not converge from: again from the first guess
                        guess[again] = self._first_guess(q[k[again]])
                        located[again] = True
                        y2, ok2, *j2 = self._bem_newton(q[k[again]], guess[again], thresh, noise, jacobian)
                        y[again], ok[again] = y2, ok2
                        if jacobian:
                            jy[0][again] = j2[0]
                else:
                    y, ok, *jy = invert(
                        self.solution.value, self.solution.jacobian, q[k], guess, tol=tol,
                        inside=self._inside_polygon, floor=NEWTON_FLOOR, jacobian=jacobian,
                    )  # fmt: skip
                y[~ok] = np.nan
                jac_k = jy[0] if jacobian else None
                redo = self._in_band(y)
                if redo.size:
                    unset = redo[np.isnan(guess[redo, 0]) if located is None else ~located[redo]]
                    if unset.size:  # chained or interpolated starts: the band's Newton starts from the first guess
                        guess[unset] = self._first_guess(q[k[unset]])
                    self._band_inverse(q[k[redo]], guess[redo], y, jac_k, redo, tol, mesh)
                ok = np.isfinite(y).all(axis=1)
                lost = np.flatnonzero(~ok)
                if lost.size:
                    self._second_starts(q[k[lost]], y, jac_k, lost, tol, mesh)
                    ok = np.isfinite(y).all(axis=1)
                out[k] = y
                if jacobian:
                    # phi's Jacobian at the pre-images Newton found (it
                    # evaluated them there), not a pass of its own; NaN within
                    # ON_BOUNDARY of the polygon's edges, as `evaluate` gives.
                    near_y, _, _ = _on_boundary(y[ok], self.polygon.points, self._polygon_xy, ON_BOUNDARY * self._size)
                    jac_k[np.flatnonzero(ok)[near_y]] = np.nan
                    jac_k[~ok] = np.nan
        jac = None
        if jacobian:
            jac = np.full((len(q), 2, 2), np.nan)
            if jac_k is not None:
                jac[k] = inv2(jac_k)
        return Mapped(out, jac)

    def _coherent_guess(self, q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """`_first_guess` for coherent targets (a pull-back's pixels), located for a quarter of them;
        and which were located (the caller starts again from `_first_guess` where an interpolated
        start did not converge).

        In each run of evenly spaced targets (`_runs`: consecutive pixels of a row), the points at
        multiples of `GUESS_STRIDE` and the run's last take `_first_guess`; those between take the
        cubic interpolation, in the pixel's index, of those guesses on either side (two each side
        where the run has them). The guess's own error (O(h^3), median 5e-4 px at 1 MP) dominates
        the interpolation's (1e-5 px, median, for the pre-images themselves), and `taylor_step`
        proves each point or sends it on to Newton, so only the time changes.
        """
        K = len(q)
        run, pos, last = _runs(q)
        node = (pos % GUESS_STRIDE == 0) | (pos == last)
        guess = np.full((K, 2), np.nan)
        at = np.flatnonzero(node)
        guess[at] = self._first_guess(q[at])
        rest = np.flatnonzero(~node)
        if rest.size:
            j = np.searchsorted(at, rest)  # at[j - 1] < rest < at[j], in the same run (its ends are nodes)
            cols = j[:, None] + np.arange(-2, 2)[None, :]
            ok = (cols >= 0) & (cols < len(at))
            nodes = at[np.clip(cols, 0, len(at) - 1)]
            ok &= run[nodes] == run[rest][:, None]
            ok &= np.isfinite(guess[:, 0])[nodes]
            x = nodes - rest[:, None]
            # inside a run the four nodes are a stride apart, at offsets fixed by the point's position
            # between them: one set of weights per position (a table), the general case elsewhere
            table = np.zeros((GUESS_STRIDE, 4))
            for r in range(1, GUESS_STRIDE):
                offsets = np.arange(-1, 3) * GUESS_STRIDE - r
                table[r] = _lagrange_at_zero(offsets[None, :].astype(np.float64), np.ones((1, 4), dtype=bool))[0]
            regular = ok[:, 0] & ok[:, 3] & (x[:, 3] - x[:, 0] == 3 * GUESS_STRIDE)
            w = table[np.where(regular, -x[:, 1], 0)]
            odd = np.flatnonzero(~regular)
            w[odd] = _lagrange_at_zero(x[odd].astype(np.float64), ok[odd])
            g = guess[nodes]
            g[~ok] = 0.0
            both = ok[:, 1] & ok[:, 2]
            guess[rest[both]] = np.einsum("kn,knc->kc", w[both], g[both])
            lost = rest[~both]
            if lost.size:
                guess[lost] = self._first_guess(q[lost])
                node[lost] = True
        return guess, node

    def _bem_newton(self, q, guess, thresh, noise, jacobian):
        """`newton.invert` for BEM (its points, tolerance and results), its first step proved.

        Every start inside the polygon gets one evaluation with the Hessian and a second-order step
        (`taylor_step`); where the step's residual is proved within half the tolerance, that is the
        pre-image, with its Jacobian from the same expansion. The others go on with ``invert`` from
        the step (or from their start). ``thresh`` and ``noise`` are `newton.thresholds` of all the
        points of the call to `inverse` (absolute: the same for any subset).
        """
        from .newton import invert

        K = len(q)
        y = np.array(guess, dtype=np.float64)
        ok = np.zeros(K, dtype=bool)
        jac = np.full((K, 2, 2), np.nan) if jacobian else None
        start = np.flatnonzero(self._inside_polygon(y))
        if start.size:
            rho = self._distance_below(y[start])
            y1, done, j1 = taylor_step(self.solution, q[start], y[start], rho, self._value_spread, thresh)
            y[start] = y1  # the step where it is finite and nearer than rho (in the polygon), else the start
            ok[start[done]] = True
            if jac is not None:
                jac[start[done]] = j1[done]
        rest = np.flatnonzero(~ok)
        if rest.size:
            # the same absolute thresholds as ``invert`` on all the points (its ``tol`` and ``floor``
            # are relative to the largest target it is given)
            s = max(1.0, float(np.max(np.abs(q[rest]))))
            y2, ok2, *j2 = invert(
                self.solution.value, self.solution.jacobian, q[rest], y[rest], tol=thresh / s,
                inside=self._inside_polygon, floor=noise / s, fun_jac=self.solution.value_and_jacobian,
                jacobian=jacobian, hopeless=self._in_collar_image,
            )  # fmt: skip
            y[rest], ok[rest] = y2, ok2
            if jac is not None:
                jac[rest] = j2[0]
        return (y, ok, jac) if jacobian else (y, ok)

    def _in_collar_image(self, q: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which values q the collar takes a point of its band to (`Collar.inverse`; none without a collar).

        Newton's hopeless points (`_bem_newton`): the collar maps its band onto Theta less phi(Gamma), so such
        a value has its pre-image in the band, where `inverse` takes the collar's (`_band_inverse`) whatever
        Newton finds. Within ~1e-5 of Theta's edges the closed form's image can stop short of Theta (its
        least residual there is ~1e-6, at the polygon), and Newton on it ran all its iterations of 40
        halvings for one point at a time (0.03-0.05 s of CPU per point, 1 MP; bench/results/2026-11-26-bem-speed.md)."""
        if self.collar is None:
            return np.zeros(len(q), dtype=bool)
        return np.isfinite(self.collar.inverse(q)).all(axis=1)

    def _distance_below(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        """A lower bound of each point's distance to the curve Gamma the map is proved on (points inside it):
        the distance to the polygon's boundary less the collar's band width, within `TAYLOR_REACH` of the
        polygon's size; that reach beyond. A disc of this radius lies inside Gamma, where `_value_spread`
        holds."""
        reach = TAYLOR_REACH * self._size
        cand, _, _, dist = _nearest_within(p, self.polygon.points, self._polygon_xy, reach)
        out = np.full(len(p), reach)
        out[cand] = np.minimum(dist, reach)
        out -= self._band_width
        return np.maximum(out, 0.0) * (1.0 - 1e-9)  # rounding of the distances

    @cached_property
    def _value_spread(self) -> NDArray[np.float64]:
        """Bounds of |u - c| inside Gamma for each component u of phi and a constant c (`taylor_step`'s D):
        half Theta's extent in that component (c its middle), and a tenth more for rounding.

        The boundary certificate proves phi(Gamma) strictly inside Theta (its condition 4, which every
        accepted map meets); phi is harmonic inside Gamma, so by the maximum principle its values there
        stay within Theta's bounding box. (Beyond Gamma, in the band, BEM's closed form is singular at its
        nodes and is not bounded this way: `_distance_below` keeps the discs inside Gamma.)"""
        return 0.55 * np.ptp(self.theta.points, axis=0)

    def _second_starts(self, q, y, jac, rows, tol: float, mesh) -> None:
        """Newton again for points of Theta it did not invert from their first guess, from the
        `SECOND_STARTS` vertices of `_guess_mesh` whose images lie nearest each, nearest first,
        into ``y`` (and ``jac``) at ``rows``; a point none converges from stays NaN.

        Every point of Theta has a pre-image (the map is certified onto it), so a NaN here was
        Newton's failure, not the map's: 9 of 74,000 pixels' pre-images of an MFS star pair,
        up to 91 px inside the polygon, came back NaN from `forward` (and `warp_points` called
        such keypoints outside), and BEM did the same once. A pre-image in the collar's band is
        the band's to give, as for the first starts (`_band_inverse`).
        """
        from .newton import invert

        image = self._guess_mesh[1]
        count = min(SECOND_STARTS, len(image))
        nearest = np.empty((len(q), count), dtype=np.intp)
        for lo in range(0, len(q), 256):  # (points x vertices) distances, 256 points at a time
            d2 = ((q[lo : lo + 256, None, :] - image[None, :, :]) ** 2).sum(axis=2)
            nearest[lo : lo + 256] = np.argsort(d2, axis=1, kind="stable")[:, :count]
        todo = np.arange(len(q))
        for c in range(count):
            if not todo.size:
                break
            start = mesh.vertices[nearest[todo, c]]
            found, ok, *jy = invert(
                self.solution.value, self.solution.jacobian, q[todo], start, tol=tol,
                inside=self._inside_polygon, floor=NEWTON_FLOOR, jacobian=jac is not None,
                fun_jac=self.solution.value_and_jacobian,
            )  # fmt: skip
            done = todo[ok]
            y[rows[done]] = found[ok]
            if jac is not None:
                jac[rows[done]] = jy[0][ok]
            band = self._in_band(found[ok])
            if band.size:
                self._band_inverse(q[done[band]], start[ok][band], y, jac, rows[done[band]], tol, mesh)
            todo = todo[~ok]

    def _first_guess(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Newton's start for points q of Theta (§3.2): linear in the image of `_guess_mesh`'s
        triangle that holds q; between that image and Theta's boundary (the approximation does not
        fit the boundary exactly) the nearest boundary point's pre-image, pulled inside."""
        from .fem.locate import barycentric_combine

        mesh = self._guess_mesh[0]
        if not len(q):
            return np.zeros((0, 2))
        tri, bary = self._guess_locator.locate(q)
        guess = barycentric_combine(mesh.vertices, mesh.triangles, tri, bary)
        if self.name == "bem":
            # the quadratic patches' guess (`warpcli.maps.quadratic_guess`): 2.3 of BEM's
            # costly evaluations per point instead of 2.9 (1 MP, measured)
            found = np.flatnonzero(tri >= 0)
            guess[found] = self._quadratic_guess.guess(q[found], tri[found], bary[found], guess[found], self._inside_polygon)
        lost = np.flatnonzero(tri < 0)
        if lost.size:
            e2, s2, _ = nearest_edge(q[lost], self.theta.points)
            start = self.boundary_from_theta(e2, s2)
            centre = mesh.vertices[mesh.triangles[_nearest_triangles(mesh, start)]].mean(axis=1)
            guess[lost] = start + 0.01 * (centre - start)
        return guess

    def _band_inverse(self, q, guess, y, jac_k, redo, tol, mesh) -> None:
        """Pre-images of values q whose Newton pre-image lies in the collar's band (or was not found):
        the collar's (`Collar.inverse`), else the closed form's in R, by Newton kept inside Gamma;
        written into ``y[redo]`` and ``jac_k[redo]`` (phi's Jacobian; ``jac_k`` may be None), NaN where
        neither has one."""
        from .newton import invert, thresholds

        collar = self.collar
        y[redo] = np.nan
        got = collar.inverse(q)
        found = np.isfinite(got).all(axis=1)
        y[redo[found]] = got[found]
        if jac_k is not None and found.any():
            jac_k[redo[found]] = collar.evaluate(got[found], jacobian=True)[1]
        rest = np.flatnonzero(~found)
        if not rest.size:
            return
        # not in the collar's image, so in phi(R): Newton again, its iterates kept inside Gamma
        start = guess[rest].copy()
        out = ~collar.inside(start)
        if out.any():
            start[out] = mesh.vertices[mesh.triangles[_nearest_triangles(mesh, start[out])]].mean(axis=1)
        compiled = getattr(self.solution, "invert_newton", None)
        if compiled is not None:
            # MFS: the same iteration compiled, Gamma as its domain (measured at 1 MP: 7 points that
            # cannot be found in R, 20 iterations of 40 halvings each, 0.25 s in numpy's passes)
            thresh, noise = thresholds(q[rest], tol, NEWTON_FLOOR)
            y2, ok2, j_mfs = compiled(q[rest], start, collar.band.gamma, thresh, noise, jacobian=jac_k is not None)
            j2 = [j_mfs]
        else:
            fused = self.solution.value_and_jacobian if self.name == "bem" else None
            y2, ok2, *j2 = invert(
                self.solution.value, self.solution.jacobian, q[rest], start, tol=tol, inside=collar.inside,
                floor=NEWTON_FLOOR, fun_jac=fused, jacobian=jac_k is not None,
            )  # fmt: skip
        ok2 &= collar.inside(np.where(np.isfinite(y2), y2, 0.0))
        y[redo[rest[ok2]]] = y2[ok2]
        if jac_k is not None:
            jac_k[redo[rest[ok2]]] = j2[0][ok2]

    def _inside_polygon(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """`warpcli.grid.inside_polygon` against the polygon, compiled (the same booleans): Newton's
        line search (BEM) asks it ~900 times in a 1 MP pull-back, most calls for a few points, where
        numpy's pass per edge cost 0.30 s of a 3.9 s single-thread pull-back (measured)."""
        return _inside_points(points, *self._polygon_xy)

    @cached_property
    def _polygon_xy(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _columns(self.polygon.points)

    @cached_property
    def _theta_xy(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _columns(self.theta.points)

    def _in_band(self, y: NDArray[np.float64]) -> NDArray[np.intp]:
        """Newton's pre-images (NaN: none found) that the collar must give instead: those in its
        band, and those not found within its width of the boundary (their value may be the
        collar's); none without a collar."""
        if not self._band_width:
            return np.zeros(0, dtype=np.intp)
        found = np.isfinite(y).all(axis=1)
        close = np.zeros(len(y), dtype=bool)
        if found.any():
            cand, _, _, dist = _nearest_within(y[found], self.polygon.points, self._polygon_xy, self._band_width)
            close[np.flatnonzero(found)[cand[dist <= self._band_width]]] = True
        if not (close.any() or (~found).any()) or self.collar is None:
            return np.zeros(0, dtype=np.intp)
        c = np.flatnonzero(close)
        c = c[~self.collar.inside(y[c])]
        return np.sort(np.concatenate([c, np.flatnonzero(~found)]))

    @cached_property
    def _guess_mesh(self):
        """A triangulation of the polygon and its image in Theta: the first guess of §3.2."""
        mesh, mapped = self._guess_evaluated
        return mesh, mapped.points

    @cached_property
    def _guess_evaluated(self):
        """`_guess_mesh`'s triangulation and the map at its vertices, with its Jacobian for BEM (the
        quadratic guess's midpoints, `_quadratic_guess`)."""
        from .fem.mesh import mesh_polygon

        area = abs(self.polygon.signed_area)
        mesh = mesh_polygon(self.polygon, max(area / GUESS_TRIANGLES, 1e-12 * area))
        return mesh, self.evaluate(mesh.vertices, jacobian=self.name == "bem")

    @cached_property
    def _guess_locator(self):
        """`warpcli.maps.fem.locate.TriangleLocator` of `_guess_mesh`'s image: made once (it was made
        for every call of `inverse`, 0.04 s each at 1 MP: a pull-back calls it per band)."""
        from .fem.locate import TriangleLocator

        mesh, image = self._guess_mesh
        return TriangleLocator(image, mesh.triangles)

    @cached_property
    def _quadratic_guess(self):
        """`_guess_mesh`'s triangles as quadratic patches in Theta (BEM's first guess)."""
        from .quadratic_guess import QuadraticGuess

        mesh, mapped = self._guess_evaluated
        return QuadraticGuess.of(
            mesh.vertices, mesh.triangles, mapped.points, lambda p: self.evaluate(p).points, jacobian=mapped.jacobian
        )

    def precompute(self, side: str) -> None:
        """Make now what a pull-back asks first: the certificate with the collar's band (`collar`), and
        for the ``"inverse"`` side the first guess's triangulation (`_guess_mesh`) and its locator. Built in a forked
        child (`_Method.build_forked`), the map comes back with them: made there beside the other
        map's build, not by the parent on one GIL."""
        self.certify()
        _ = self.collar
        if side == "inverse":
            _ = self._guess_locator
            if self.name == "bem":
                _ = self._quadratic_guess

    def certify(self) -> Certificate:
        return self._certificate

    @cached_property
    def _certificate(self) -> Certificate:
        proof = self.boundary_certificate if self.name in BOUNDARY_CERTIFIED else None
        if proof is None:
            proof = self.cell_certificate
        return Certificate(proof.failed, proof.checked, "samples")

    @cached_property
    def _degenerate(self) -> NDArray[np.bool_]:
        return degenerate_vertices(self.polygon.points, self.theta.points, self.boundary_to_theta, self.conditions == "mixed")

    @cached_property
    def boundary_certificate(self) -> BoundaryCertificate:
        """`warpcli.maps.boundary_certificate.certify_boundary`, computed once, with the collar's band.

        Gamma is the polygon moved inwards by the first of `_band_widths` that proves the map with its band
        (the collar, `collar`), for BEM (its closed form is singular at its boundary nodes, and folds next to
        them) and MFS alike (its fit leaves Theta along the boundary, and folds there next to some reflex
        vertices), whatever the boundary data (`_collar_data`); ``closer`` counts the first width's failures
        when a later one holds. A vertex where the data force det J -> 0 (t^2, mixed conditions at a sharp
        corner) lies in the band, which the collar covers.
        """
        first = None
        for width in self._band_widths:
            moved = self.certify_boundary_at(width)
            if moved.ok:
                return moved if first is None else replace(moved, closer=first.failed)
            first = first or moved
        return first

    @cached_property
    def _collar_data(self) -> BoundaryData:
        """The boundary data as the collar takes them (the same as `boundary_to_theta`): Dirichlet data
        (linear or t^2 along each edge), or the correspondence a boundary that slides along Theta's edges
        settles on (mixed conditions: the solution's trace, `_edge_tables`)."""
        if self.solution.trace is not None:
            return BoundaryData(self.theta.points, tables=self._edge_tables)
        return BoundaryData(self.theta.points, self.boundary)

    @cached_property
    def _band_widths(self) -> tuple[float, ...]:
        """Gamma's distances inside the polygon tried in turn (`BAND_STEPS` times `band_floor`, for BEM at
        least `BEM_BAND_RELATIVE` of the size): a closed form whose values 0.01 px inside still leave Theta
        (MFS's fit, BEM next to a node) is proved farther in, with the collar between."""
        inner = band_floor(self._size)
        if self.name == "bem":  # its certificate's work, relative to the size, not to pixels
            inner = max(inner, BEM_BAND_RELATIVE * self._size)
        return tuple(inner * k for k in BAND_STEPS)

    def certify_boundary_at(self, offset: float) -> BoundaryCertificate:
        """`warpcli.maps.boundary_certificate.certify_boundary` of this map on Gamma ``offset`` inside its
        polygon (0: the polygon itself), not cached: `boundary_certificate` chooses the offsets."""
        sign = self.theta.orientation * np.sign(self.polygon.signed_area)
        # the band is proved for Dirichlet data (linear or t^2), not for natural or mixed
        # conditions, whose boundary slides as the solution says
        boundary = self._collar_data if offset > 0 else None
        return certify_boundary(self.solution, self.polygon.points, self.theta, sign, offset, boundary)

    @cached_property
    def cell_certificate(self) -> CellCertificate:
        """`warpcli.maps.certificate.certify_cells`, computed once (the build, the check and the report
        ask), with balls of at most `vertex_ball` left out around the `degenerate_vertices`."""
        # MFS: the rigorous cell bound (1.2-2.3x the first-order test's time on the bench pairs, median
        # 1.8; docs/proving.md); BEM's costs 3-5x, so it keeps the first-order test for now.
        return self.certify_cells_with(rigorous=self.name == "mfs")

    def certify_cells_with(self, rigorous: bool) -> CellCertificate:
        """`cell_certificate`'s call with the cell test chosen (``rigorous``: the order-4 bound, else the
        first-order test), not cached: for comparing the two."""
        sign = self.theta.orientation * np.sign(self.polygon.signed_area)
        near = ON_BOUNDARY * self._size
        balls = np.where(self._degenerate, vertex_ball(self._size), 0.0)
        return certify_cells(self.solution, self.polygon.points, self.theta, sign, near, balls, rigorous=rigorous)

    def describe(self) -> dict:
        return {"nodes": {"m": int(self.solution.m)}}

    def to_theta_parameter(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        if self.solution.trace is None:
            return super().to_theta_parameter(edge, t)
        return slide(self._edge_tables, edge, t, forward=True)

    def from_theta_parameter(self, edge: ArrayLike, s: ArrayLike) -> NDArray[np.float64]:
        if self.solution.trace is None:
            return super().from_theta_parameter(edge, s)
        return slide(self._edge_tables, edge, s, forward=False)

    @cached_property
    def _edge_tables(self) -> EdgeTables:
        """Natural conditions let the boundary slide along Theta's edges: the solution's correspondence."""
        return sliding_tables(self.theta.points, *self.solution.trace)


def _columns(points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A polygon's x and y, each contiguous (what `_inside_points` takes)."""
    v = np.asarray(points, dtype=np.float64)
    return np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1])


def _inside_points(points: ArrayLike, vx: NDArray[np.float64], vy: NDArray[np.float64]) -> NDArray[np.bool_]:
    """`warpcli.grid.inside_polygon`'s booleans against the polygon (vx, vy), compiled: one pass over
    the points rather than numpy's passes per edge (the pixel grid's test in the pull-back, 1 MP of
    points against 12 edges: 0.36 of a 5.6 s single-thread pull-back under load, measured)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(len(p), dtype=np.bool_)
    if len(p):
        _compiled.inside_points(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), vx, vy, out)
    return out


#: Largest change between consecutive steps of a run of targets, relative to the step, that
#: `_steady` still calls even (consecutive pixels of a row change by far less).
STEADY = 0.25


def _steady(q: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Points k >= 3 whose three steps before them (q[k] - q[k-1], q[k-1] - q[k-2], q[k-2] - q[k-3])
    change by at most `STEADY` of themselves from one to the next: a run of evenly spaced targets
    (a row of pixels mapped into Theta), along which the pre-images are extrapolated."""
    out = np.zeros(len(q), dtype=bool)
    if len(q) > 3:
        d = np.diff(q, axis=0)
        dd = np.diff(d, axis=0)
        even = np.einsum("ij,ij->i", dd, dd) <= STEADY**2 * np.einsum("ij,ij->i", d[:-1], d[:-1])
        out[3:] = even[1:] & even[:-1]
    return out


#: `SmoothMap._coherent_guess`: the points of a run located for a first guess, one in this many.
GUESS_STRIDE = 4


def _runs(q: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """Runs of evenly spaced targets: per point its run, its position in it and the run's last position.

    A run is a maximal stretch of consecutive points whose steps q[i+1] - q[i] each agree within
    `STEADY` with a neighbouring step, and with the one before where that one is in a run too:
    consecutive pixels of a row mapped into Theta (a row's end, or a pixel left out, breaks it;
    where the spacing changes, the point between goes with the run before).
    """
    K = len(q)
    link = np.zeros(max(K - 1, 0), dtype=bool)
    if K > 2:
        d = np.diff(q, axis=0)
        e = d[1:] - d[:-1]
        ee = np.einsum("ij,ij->i", e, e)
        with_before = ee <= STEADY**2 * np.einsum("ij,ij->i", d[:-1], d[:-1])  # step i + 1 with step i
        with_after = ee <= STEADY**2 * np.einsum("ij,ij->i", d[1:], d[1:])  # step i with step i + 1
        link[1:] |= with_before
        link[:-1] |= with_after
        link[1:] &= ~(link[:-1] & ~with_before)  # a change of spacing after a linked step
    first = np.r_[True, ~link] if K else np.zeros(0, dtype=bool)
    run = np.cumsum(first) - 1
    starts = np.flatnonzero(first)
    pos = np.arange(K) - starts[run]
    last = (np.r_[starts[1:], K] - 1 - starts)[run]
    return run, pos, last


def _lagrange_at_zero(x: NDArray[np.float64], use: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Lagrange weights at 0 of the nodes x (K, N) in use (distinct), 0 for the others."""
    w = np.where(use, 1.0, 0.0)
    for a in range(x.shape[1]):
        for b in range(x.shape[1]):
            if a != b:
                pair = use[:, a] & use[:, b]
                w[:, a] *= np.where(pair, -x[:, b] / np.where(pair, x[:, a] - x[:, b], 1.0), 1.0)
    return w


#: How far from the polygon's boundary (times its size) `SmoothMap._distance_below` measures the distance
#: of Newton's starts; farther points take this as theirs (a step of 1e-3 px then qualifies at 1 MP).
TAYLOR_REACH = 0.05


def taylor_step(
    solution, q: NDArray[np.float64], y0: NDArray[np.float64], rho: NDArray[np.float64], spread: NDArray[np.float64],
    thresh: float,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]:
    """One second-order step towards phi(y) = q from y0, and where it is proved converged.

    With value v, Jacobian J and Hessian H of the closed form at y0 (one
    evaluation) and r = q - v: the Newton step d0 = J^-1 r and its
    second-order correction d = d0 - J^-1 s, s = H[d0, d0] / 2 (Chebyshev's
    method). The residual at y1 = y0 + d is

        q - phi(y1) = e - R,  e = r - J d - H[d, d] / 2 (computed),

    R the Taylor remainder of order 3. Each component u of phi is harmonic in
    the disc of radius rho around y0 (``rho`` keeps it inside the polygon, and
    the caller's keeps it inside Gamma, where ``spread`` is proved: see
    `SmoothMap._value_spread`), so u = Re f with f holomorphic there, and
    f's Taylor coefficients obey |a_k| <= 2 D / rho^k (k >= 1) whenever
    |u - c| <= D on the disc for some constant c (a_k rho^k = (1/pi) int
    (u - c) e^(-ik theta) d theta over the circle; ``spread``, per
    component): |R| <= 2 |D| t^3 / (1 - t), t = |d| / rho. A point is
    converged if already within ``thresh`` at y0 (``invert``'s first test),
    or if |e| + |R| <= thresh / 2 (half: room for the evaluation's rounding,
    ~1e-14 of the values): the same residual test as ``invert``'s, proved
    instead of evaluated, so the pre-images are as accurate. Its Jacobian is
    J + H d, within 6 D t^2 / rho (the same series, differentiated) of the
    Jacobian at y1: ~1e-12 relative for the steps that qualify, as close as
    ``invert``'s own at a point within the tolerance.

    At 1 MP the quadratic first guess is ~5e-4 px from the pre-image (median;
    `warpcli.maps.quadratic_guess`): t ~ 1e-5 and |R| ~ 1e-15 of Theta, so
    nearly every point is proved after this one evaluation, where Newton
    evaluated 2.33 times per point (its second to confirm a step that had
    already converged). The Hessian costs ~25 % more than value and Jacobian
    in the BEM treecode (measured).

    Parameters
    ----------
    solution : ClosedForm
        With ``value_jacobian_hessian`` (caller's coordinates).
    q : (K, 2) ndarray of float
        The targets.
    y0 : (K, 2) ndarray of float
        Starts, strictly inside the polygon.
    rho : (K,) ndarray of float
        Radii of discs around the starts on which ``spread`` holds (inside the polygon).
    spread : (2,) ndarray of float
        Per component u, a bound D of |u - c| on those discs for some constant c.
    thresh : float
        The absolute residual tolerance (`warpcli.maps.newton.thresholds`).

    Returns
    -------
    y : (K, 2) ndarray of float
        y1 where the step is finite and shorter than rho / 2 (so inside the polygon), else y0.
    done : (K,) ndarray of bool
        Proved within ``thresh`` (at y0 or y1).
    jacobian : (K, 2, 2) ndarray of float
        phi's Jacobian at ``y`` where done (J at y0, or J + H d at y1).
    """
    v, J, H = solution.value_jacobian_hessian(y0)
    r = q - v
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]

    def solve(b):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.stack(
                [(J[:, 1, 1] * b[:, 0] - J[:, 0, 1] * b[:, 1]) / det, (J[:, 0, 0] * b[:, 1] - J[:, 1, 0] * b[:, 0]) / det],
                axis=1,
            )

    def quadratic(h):  # H[h, h] / 2 per component (numpy's einsum of three operands: 5x slower)
        xx, xy, yy = 0.5 * h[:, 0] * h[:, 0], h[:, 0] * h[:, 1], 0.5 * h[:, 1] * h[:, 1]
        return np.stack([H[:, a, 0, 0] * xx + 0.5 * (H[:, a, 0, 1] + H[:, a, 1, 0]) * xy + H[:, a, 1, 1] * yy for a in (0, 1)], axis=1)

    d0 = solve(r)
    s = quadratic(d0)
    d = d0 - solve(s)
    jd = np.stack([J[:, a, 0] * d[:, 0] + J[:, a, 1] * d[:, 1] for a in (0, 1)], axis=1)
    e = r - jd - quadratic(d)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = np.hypot(d[:, 0], d[:, 1]) / rho
        rem = 2.0 * np.hypot(*spread) * t**3 / (1.0 - t)
        bound = np.hypot(e[:, 0], e[:, 1]) + rem
    at_start = np.hypot(r[:, 0], r[:, 1]) <= thresh
    step = np.isfinite(d).all(axis=1) & (t <= 0.5) & ~at_start
    done = at_start | (step & (bound <= 0.5 * thresh))
    y = y0.copy()
    y[step] = y0[step] + d[step]
    jac = J.copy()
    hs, ds = H[step], d[step]
    jac[step] += hs[:, :, :, 0] * ds[:, None, None, 0] + hs[:, :, :, 1] * ds[:, None, None, 1]
    return y, done, jac


def _nearest_within(
    points: NDArray[np.float64], vertices: NDArray[np.float64], xy: tuple[NDArray[np.float64], NDArray[np.float64]], reach: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """`warpcli.boundary.nearest_edge` of the points that may lie within ``reach`` of the polygon
    (``vertices``, its columns ``xy``): their indices, then its edge, parameter and distance for them.

    The compiled `near_boundary` picks a superset of the points within reach in one pass;
    `nearest_edge` then runs on those alone (its values per point do not depend on the others: a
    test compares them), so the distances and decisions are its own, bit for bit. The pull-back
    asks this of every pixel (1 MP: a thin band along the boundary qualifies), where
    `nearest_edge` on every point was a fifth of its time (measured: 0.40 of 1.9 s on one thread)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    flag = np.zeros(len(p), dtype=np.uint8)
    if len(p):
        _compiled.near_boundary(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), *xy, float(reach), flag)
    cand = np.flatnonzero(flag)
    edge, t, dist = nearest_edge(p[cand], vertices)
    return cand, edge, t, dist


def _on_boundary(
    points: NDArray[np.float64], vertices: NDArray[np.float64], xy: tuple[NDArray[np.float64], NDArray[np.float64]], tolerance: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """`warpcli.boundary.on_boundary`'s result, by `_nearest_within`."""
    cand, edge, t, dist = _nearest_within(points, vertices, xy, tolerance)
    close = dist <= tolerance
    return cand[close], edge[close], t[close]


def _nearest_triangles(mesh, points: NDArray[np.float64]) -> NDArray[np.intp]:
    """The mesh triangle whose centroid is nearest each point (few points)."""
    c = mesh.vertices[mesh.triangles].mean(axis=1)
    return np.array([int(np.argmin(np.hypot(*(c - p).T))) for p in points], dtype=np.intp)


class _Method:
    """A registry entry: ``build`` and ``prepare`` for one meshless method."""

    def __init__(self, name: str) -> None:
        self.name = name

    def build(self, polygon: Polygon, theta: Theta, options, role: str = "source", region=None) -> SmoothMap:
        boundary = options.src_boundary if role == "source" else options.dst_boundary
        # Mixed conditions (§5.2; Theta the unit square): x slides along the
        # edges where y is prescribed (0 and 2), y along the others, as for FEM.
        free = ((0, 2), (1, 3)) if options.conditions == "mixed" else ((), ())
        t0 = time.perf_counter()
        m = self.nodes_for(polygon, options.nodes)
        most = min(MAX_AUTO_NODES, self.most_nodes())
        while True:
            fit = self._fit(polygon, theta, m, boundary, free)
            phi = SmoothMap(polygon, theta, fit, self.name, options.conditions, boundary=boundary)
            # Repair what can be repaired: with the default m, a map whose
            # certificate fails (MFS oscillates near reflex corners, the
            # paper's Fig. 5) is fitted again with twice the nodes, within
            # MAX_AUTO_NODES and memory (FIT_BYTES_PER_NODE2): past that the
            # certificate refuses the map in one line.
            if options.nodes is not None or not options.check or 2 * phi.solution.m > most:
                break
            if phi.certify().ok:
                break
            m = 2 * phi.solution.m
            log.warning("%s: the %s map folds with m = %d; fitting again with m = %d", polygon.name, self.name, phi.solution.m, m)
        phi.timings["solve"] = time.perf_counter() - t0
        return phi

    def build_forked(
        self, polygon: Polygon, theta: Theta, options, role: str = "source", region=None, *, precompute: str | None = None,
    ) -> ForkedBuild | None:
        """`build` in a forked child process, with `SmoothMap.precompute` for side ``precompute``
        (the certificate and collar whatever the side); None where that is not available
        (`warpcli._fork.available`). ``.result()`` is what `build` returns, bit for bit.

        The fit (LAPACK), the certificate and the first guess's mesh hold the GIL
        for most of their time: on two threads the two maps took turns (measured:
        the two builds of a 1 MP warp on threads ended together, each as long as
        both). In two children they run on two cores while the parent reads the image."""
        from .._fork import available

        if not available():
            return None
        # Before the fork (beside the image's decoding), loaded once for the children and this process
        # (which unpickles the maps) rather than in each.
        _load_runtime()
        self._load_fit()
        try:
            return ForkedBuild(polygon.name, "fitting and certifying", _built_to_send, self, polygon, theta, options, role, region, precompute)
        except OSError:  # no memory or processes left for a child: the caller builds on a thread
            return None

    def fit_bytes(self, m: int) -> int:
        """About how many bytes a warp with ``m`` nodes holds at its peak (`FIT_BYTES_PER_NODE2`)."""
        return FIT_BYTES_PER_NODE2[self.name] * int(m) ** 2

    def most_nodes(self) -> int:
        """The most nodes whose fit fits in the memory budget (`warpcli.budget.max_image_bytes`)."""
        from ..budget import max_image_bytes

        return math.isqrt(max_image_bytes() // FIT_BYTES_PER_NODE2[self.name])

    def nodes_for(self, polygon: Polygon, nodes: int | None) -> int | None:
        """The m to fit first: ``nodes`` if it is possible, else the default (None) or its cap.

        Raises
        ------
        InputError
            If ``nodes`` is fewer than the polygon's vertices, or its fit would
            need more memory than warpcli may use; or if the polygon has more
            vertices than the memory allows nodes.
        """
        n = len(polygon.points)
        most = self.most_nodes()
        what = "boundary nodes" if self.name == "bem" else "sites"
        if nodes is not None:
            if nodes < n:
                raise InputError(
                    f"{polygon.name}: --nodes {nodes} is fewer than its {n} vertices; {self.name.upper()} needs at least "
                    f"one of its {what} per vertex (the default is max(256, 8 n))"
                )
            if nodes > most:
                raise InputError(
                    f"--nodes {nodes}: {'an' if self.name == 'mfs' else 'a'} {self.name.upper()} fit with m = {nodes} needs about "
                    f"{format_bytes(self.fit_bytes(nodes))} of memory, more than the {format_bytes(max_image_bytes())} "
                    f"warpcli may use (m <= {most} here; {MAX_IMAGE_BYTES_ENV}); use fewer --nodes or --method fem"
                )
            return nodes
        default = max(256, 8 * n)  # default_bem_nodes and default_mfs_sites
        cap = min(MAX_AUTO_NODES, most)
        if default <= cap:
            return None
        if n > most:
            raise InputError(
                f"{polygon.name}: {n} vertices need at least {n} {self.name.upper()} {what}, about "
                f"{format_bytes(self.fit_bytes(n))} of memory, more than the {format_bytes(max_image_bytes())} "
                f"warpcli may use ({MAX_IMAGE_BYTES_ENV}); use --method fem"
            )
        m = max(cap, n)
        log.warning(
            "%s: %d vertices: %s fits with m = %d %s, not the default 8 n = %d (about %s of memory and %.0fx the time); "
            "--nodes chooses m",
            polygon.name, n, self.name.upper(), m, what, default, format_bytes(self.fit_bytes(default)), (default / m) ** 3,
        )  # fmt: skip
        return m

    def _load_fit(self) -> None:
        """Import the fit's modules and load its least squares' LAPACK (`closed_form.load_lstsq`)."""
        from .closed_form import load_lstsq

        if self.name == "bem":
            from . import bem  # noqa: F401
        else:
            from . import mfs  # noqa: F401
        load_lstsq()

    def _fit(self, polygon: Polygon, theta: Theta, m: int | None, boundary: str, free):
        if self.name == "bem":
            from .bem import fit_bem

            return fit_bem(polygon.points, theta.points, m, boundary=boundary, free=free)
        from .mfs import SitePlacementError, fit_mfs

        try:
            return fit_mfs(polygon.points, theta.points, m, boundary=boundary, free=free)
        except SitePlacementError as err:
            raise MeshingError(f"{polygon.name}: MFS with m = {err.m} sites: {err}; use --method fem or bem") from None

    def prepare(self) -> None:
        """Load what the pull-back imports and calls first, while the maps are built.

        `warpcli.maps.compose.build_map` runs this on a thread of its own: the kernels'
        runtime (`_load_runtime`), the modules the maps (and their pickles, from forked
        children) and the inverse need, and numpy.ma (``np.median``'s test for masked
        arrays imports it, in the first guess's triangle locator: 10-20 ms the pull-back
        would otherwise pay).
        """
        from .._fork import available

        if not available():
            # Built in forked children, BEM's and MFS's maps come with their locators
            # (`SmoothMap.precompute`): this process never calls np.median then (numpy.ma:
            # 50-100 ms of CPU under load, beside the children)
            import numpy.ma  # noqa: F401

        from . import newton  # noqa: F401
        from .fem import locate  # noqa: F401

        if self.name == "bem":
            from . import bem_eval  # noqa: F401
        self._load_fit()
        _load_runtime()


def _load_runtime() -> None:
    """The compiled kernels' runtime (`warpcli._native`: llvmlite and its JIT engine where
    `warpcli._elf` cannot load them, 0.04 s quiet) and the polygon
    test every certificate and pull-back calls, loaded by a call on a triangle."""
    v = np.array([0.0, 1.0, 0.0])
    _compiled.inside_points(np.zeros(1), np.zeros(1), v, v[::-1].copy(), np.zeros(1, dtype=np.bool_))


def _built_to_send(method: _Method, polygon: Polygon, theta: Theta, options, role: str, region, side) -> SmoothMap:
    """What a forked child runs (`_Method.build_forked`): the map, with what its side's pull-back asks first."""
    phi = method.build(polygon, theta, options, role, region)
    phi.precompute(side or "")
    return phi


BEM = _Method("bem")
MFS = _Method("mfs")
