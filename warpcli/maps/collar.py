"""The collar: a smooth map's values in the thin band between its polygon and the curve it is proved on.

BEM's closed form is singular at its boundary nodes, and next to them it
can fold (slivers under 0.01 px); MFS can fold on the boundary itself next
to reflex vertices. `warpcli.maps.boundary_certificate` proves such a map
one-to-one on the region R bounded by a curve Gamma a distance delta
inside the polygon (`offset_band`). In the band between the polygon and
Gamma the map is replaced by the collar: on each cell of the band (the
points (1 - t) F(s) + t G(s), F on the polygon's edge, G on Gamma),

    phi_c((1 - t) F(s) + t G(s)) = (1 - t) g(F(s)) + t phi(G(s)),

g the boundary data (linear or t^2 along each edge onto Theta's edge), phi
the closed form. It is continuous, equal to phi on Gamma and to g on the
polygon, and the certificate's conditions 4 and 5 (phi(Gamma) strictly
inside Theta; each segment from g(F(s)) to phi(G(s)) crossing phi(Gamma)
the right way round) make it one-to-one from the band onto the ring
between Theta's boundary and phi(Gamma): so the whole map is one-to-one
from the polygon onto Theta, with det J > 0 (docs/proving.md).

The collar's values differ from the closed form's by what the closed form
changes over the band's width (0.01 px at most, 1e-5 of the polygon's
size below 1000 px): no pixel moves visibly; only that nothing in the band
folds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .._arrays import first_of_each
from .._cached import cached_property
from .._native import Kernels
from ..boundary import BoundaryData
from .boundary_certificate import OffsetBand

__all__ = ["Collar"]

_compiled = Kernels("warpcli.maps._smooth_kernels")

#: Iterations of the bracketed root search along a cell (`Collar.inverse`): halving at worst.
ROOT_STEPS = 80
#: Slack on the cells' parameters, relative (points on a shared segment belong to both cells).
EDGE_SLACK = 1e-9
#: How far from the collar's segment (relative to Theta's size) a value may be and be found on it:
#: the closed form's rounding (MFS's sums of large weights: 1e-11 at m = 1024, measured), within
#: which `SmoothMap.inverse`'s Newton accepts a pre-image too (its NEWTON_FLOOR).
MISS = 1e-9


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


@dataclass(frozen=True)
class Collar:
    """The map in the band of a smooth map proved on its `OffsetBand` (see the module's docstring).

    Parameters
    ----------
    band : OffsetBand
        The cells, in the polygon's coordinates.
    solution : ClosedForm
        ``value_and_jacobian`` of the closed form (valid on Gamma).
    data : BoundaryData
        The boundary data.
    knots : (K, 4) ndarray of float
        The certificate's piece centres: Gamma's edge, parameter, value
        (`BoundaryCertificate.knots`).
    """

    band: OffsetBand
    solution: object = field(repr=False)
    data: BoundaryData = field(repr=False)
    knots: NDArray[np.float64] = field(repr=False)

    @property
    def band_width(self) -> float:
        """The band's width: no point of it is farther from the polygon's boundary."""
        return float(np.hypot(*(self.band.g0 - self.band.f0).T).max()) if len(self.band.f0) else 0.0

    def inside(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether each point (known to be inside the polygon) lies in R, inside Gamma (else in the band).

        `warpcli.grid.inside_polygon`'s test and arithmetic, compiled: Newton's line search in
        `SmoothMap._band_inverse` asks it about a few points at a time, up to 800 times a point
        (20 iterations, 40 halvings), against Gamma's ~100 edges; numpy's pass per edge made that
        2 s of a 1 MP MFS warp for 7 points (measured, bench/results/2026-11-24-smooth-speed.md).
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(len(p), dtype=np.bool_)
        if len(p):
            g = self._gamma_xy
            _compiled.inside_points(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), g[0], g[1], out)
        return out

    @cached_property
    def _gamma_xy(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Gamma's x and y, contiguous (for `inside_points`)."""
        gamma = np.asarray(self.band.gamma, dtype=np.float64)
        return np.ascontiguousarray(gamma[:, 0]), np.ascontiguousarray(gamma[:, 1])

    def _data(self, c: NDArray[np.intp], s: NDArray[np.float64]):
        """g(F(s)) on cells c, and its derivative in s: (K, 2) each."""
        b = self.band
        dt = (b.t1 - b.t0)[c]
        t = b.t0[c] + s * dt
        return self.data.points(b.edge[c], t), self.data.tangent(b.edge[c], t) * dt[:, None]

    def locate(self, points: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
        """The cell and its parameters (s, t) of each point of the band; cell -1 where none holds it.

        In a cell, cross(y - F(s), G(s) - F(s)) = 0 is linear in s for
        every kind (strips: G - F constant; fans: F or G constant), and t
        follows by projection on G(s) - F(s).
        """
        b = self.band
        y = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        cell = np.full(len(y), -1, dtype=np.intp)
        s_out = np.zeros(len(y))
        t_out = np.zeros(len(y))
        best = np.full(len(y), np.inf)
        df, dg = b.f1 - b.f0, b.g1 - b.g0
        # Only a cell whose box holds a point can take it: (s, t) within EDGE_SLACK of [0, 1]^2 is
        # a point of the bilinear patch F + t (G - F) over [-slack, 1 + slack]^2, whose box is that
        # of the patch's four corners; widened far beyond rounding, so that the cells left out
        # miss by more than the slack (they would lose to the cell that holds the point, or leave
        # it at -1: the answer is the same). Points sorted by x: each cell's candidates by bisection.
        lo, hi = self._cell_boxes
        order = np.argsort(y[:, 0], kind="stable")
        xs = y[order, 0]
        first = np.searchsorted(xs, lo[:, 0], side="left")
        last = np.searchsorted(xs, hi[:, 0], side="right")
        for c in np.flatnonzero(first < last):  # loop over cells with candidates, vectorised over those
            k = order[first[c] : last[c]]
            k = k[(y[k, 1] >= lo[c, 1]) & (y[k, 1] <= hi[c, 1])]
            if not k.size:
                continue
            yk = y[k]
            a = yk - b.f0[c]
            base = b.g0[c] - b.f0[c]
            slope = _cross(a, (dg[c] - df[c])[None]) - _cross(df[c][None], base[None])
            with np.errstate(divide="ignore", invalid="ignore"):
                s = -_cross(a, base[None]) / slope
                f = b.f0[c] + s[:, None] * df[c]
                gf = b.g0[c] + s[:, None] * dg[c] - f
                t = ((yk - f) * gf).sum(axis=1) / (gf * gf).sum(axis=1)
            # how far outside [0, 1]^2 (0 inside): the best cell wins, so shared segments are taken once
            miss = np.fmax(np.fmax(-s, s - 1.0), np.fmax(-t, t - 1.0))
            miss = np.where(np.isfinite(miss), np.maximum(miss, 0.0), np.inf)
            take = miss < best[k]
            kt = k[take]
            best[kt] = miss[take]
            cell[kt] = c
            s_out[kt] = s[take]
            t_out[kt] = t[take]
        cell[~(best <= EDGE_SLACK)] = -1
        return cell, np.clip(s_out, 0.0, 1.0), np.clip(t_out, 0.0, 1.0)

    @cached_property
    def _cell_boxes(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Boxes (lo, hi: (C, 2) each) holding every point `locate` may give each cell, widened."""
        b = self.band
        e = EDGE_SLACK
        corners = []
        for s in (-e, 1.0 + e):
            f = b.f0 + s * (b.f1 - b.f0)
            g = b.g0 + s * (b.g1 - b.g0)
            corners += [f - e * (g - f), g + e * (g - f)]
        c = np.stack(corners)
        lo, hi = c.min(axis=0), c.max(axis=0)
        # far beyond the rounding of (s, t): a thousandth of the cell, and of the coordinates' size
        pad = 1e-3 * (hi - lo).max(axis=1, keepdims=True) + 1e-9 * (1.0 + np.abs(c).max(axis=(0, 2)))[:, None]
        return lo - pad, hi + pad

    def evaluate(self, points: NDArray[np.float64], jacobian: bool = False):
        """The collar's values (and Jacobians) at points of the band; NaN where no cell holds a point.

        Returns
        -------
        values : (K, 2) ndarray of float
        jac : (K, 2, 2) ndarray of float or None
        """
        b = self.band
        y = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.full(y.shape, np.nan)
        jac = np.full((len(y), 2, 2), np.nan) if jacobian else None
        cell, s, t = self.locate(y)
        k = np.flatnonzero(cell >= 0)
        if not k.size:
            return out, jac
        c, s, t = cell[k], s[k][:, None], t[k][:, None]
        f = b.f0[c] + s * (b.f1 - b.f0)[c]
        g = b.g0[c] + s * (b.g1 - b.g0)[c]
        gf, dgf = self._data(c, s[:, 0])
        val, j = self.solution.value_and_jacobian(g)
        out[k] = (1.0 - t) * gf + t * val
        if jac is not None:
            img_s = (1.0 - t) * dgf + t * np.einsum("kab,kb->ka", j, (b.g1 - b.g0)[c])
            img_t = val - gf
            dom_s = (1.0 - t) * (b.f1 - b.f0)[c] + t * (b.g1 - b.g0)[c]
            dom_t = g - f
            img = np.stack([img_s, img_t], axis=2)
            dom = np.stack([dom_s, dom_t], axis=2)
            det = dom[:, 0, 0] * dom[:, 1, 1] - dom[:, 0, 1] * dom[:, 1, 0]
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = np.stack([np.stack([dom[:, 1, 1], -dom[:, 0, 1]], 1), np.stack([-dom[:, 1, 0], dom[:, 0, 0]], 1)], 1) / det[:, None, None]
            jac[k] = img @ inv
        return out, jac

    def inverse(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """The points of the band the collar takes to these values (NaN for a value not in its image).

        Along each cell, h(s) = cross(w - g(F(s)), phi(G(s)) - g(F(s))) is
        0 where the collar's segment through s passes through w. The
        certificate's piece centres (exact values of phi) bracket its sign
        changes, in the intervals between them whose image's box (proved
        from the pieces' capsules, `_knots`) holds w: lines through far
        values cross too, and an estimate of where the segment lies
        (interpolating phi between centres) missed pre-images in bands
        0.01 px wide, where phi bends across an interval by more than the
        segment's length. Every bracket of every value is narrowed at once
        (Newton's step inside the bracket, else Illinois'), one evaluation of
        the closed form per step for all of them, and accepted when w lies on
        the segment there (t in [0, 1], to the closed form's rounding,
        `MISS`): the collar is one-to-one, so an accepted point is the
        pre-image.
        """
        b = self.band
        w = np.asarray(values, dtype=np.float64).reshape(-1, 2)
        out = np.full(w.shape, np.nan)
        if not len(w):
            return out
        who, cell, lo, hi, h_lo, h_hi = self._brackets(w)
        if not who.size:
            return out
        s, t = self._roots(w[who], cell, lo, hi, h_lo, h_hi)
        good = np.flatnonzero(np.isfinite(t))
        # the first accepted bracket of each value (one, but for values on a shared segment)
        first = good[first_of_each(who[good])]
        c, sh, th = cell[first], s[first][:, None], np.clip(t[first], 0.0, 1.0)[:, None]
        f = b.f0[c] + sh * (b.f1 - b.f0)[c]
        g = b.g0[c] + sh * (b.g1 - b.g0)[c]
        out[who[first]] = f + th * (g - f)
        return out

    def _brackets(self, w):
        """Every (value, cell, knot interval) where h changes sign and the value lies in the box that
        holds the interval's image: index arrays and h at the ends."""
        parts = []
        for c, (s_k, v_k, g_k, box_lo, box_hi) in enumerate(self._knots):  # loop over cells, vectorised over the values near one
            near = np.flatnonzero(((w >= box_lo.min(axis=0)) & (w <= box_hi.max(axis=0))).all(axis=1))
            if not near.size:
                continue
            wn = w[near]
            # the knot intervals whose image's box holds the value: every other interval's image misses it
            held = ((wn[:, None, :] >= box_lo[None]) & (wn[:, None, :] <= box_hi[None])).all(axis=2)
            row, col = np.nonzero(held)
            if not row.size:
                continue
            d_k = v_k - g_k
            h_lo = _cross(wn[row] - g_k[col], d_k[col])
            h_hi = _cross(wn[row] - g_k[col + 1], d_k[col + 1])
            # lines through far values cross too; the boxes leave those out
            change = np.sign(h_lo) * np.sign(h_hi) <= 0
            if change.any():
                row, col = row[change], col[change]
                parts.append((near[row], np.full(row.size, c), s_k[col], s_k[col + 1], h_lo[change], h_hi[change]))
        if not parts:
            empty = np.zeros(0)
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp), empty, empty, empty, empty
        return tuple(np.concatenate(col) for col in zip(*parts))

    def _roots(self, w, c, s0, s1, h0, h1):
        """s in each bracket [s0, s1] of cell c where h changes sign (all at once), and t there
        (NaN unless w lies on the segment there, to the closed form's rounding: `MISS`).

        Each step is Newton's from the last trial, h' from the closed form's Jacobian that its
        evaluation gives anyway, where that falls strictly inside the bracket; else Illinois'
        (regula falsi, the kept end's value halved when the same end is kept twice). The bracket
        is kept either way (a Newton step that would leave it is Illinois' instead), and the steps
        stop as before: a trial repeated, h = 0, the bracket at rounding, or `ROOT_STEPS`. Newton
        gets there in 6-12 steps where Illinois took 9-52 (one evaluation each, 0.3-1 ms for a
        handful of points: 10 % of a 1 MP BEM pull-back, measured)."""
        b = self.band
        a, z = s0.astype(np.float64), s1.astype(np.float64)
        fa, fz = h0.astype(np.float64), h1.astype(np.float64)
        side = np.zeros(len(w), dtype=np.int8)
        s = a.copy()
        newton = np.full(len(w), np.nan)  # Newton's next trial from the last one (NaN: none yet)
        live = np.arange(len(w))
        for _ in range(ROOT_STEPS):  # each step evaluates the closed form once for the brackets still open
            k = live
            with np.errstate(divide="ignore", invalid="ignore"):
                trial = np.where(fz[k] != fa[k], z[k] - fz[k] * (z[k] - a[k]) / (fz[k] - fa[k]), 0.5 * (a[k] + z[k]))
            inside = (trial > a[k]) & (trial < z[k]) | (trial < a[k]) & (trial > z[k])
            trial = np.where(inside, trial, 0.5 * (a[k] + z[k]))
            nk = newton[k]
            use = (nk > a[k]) & (nk < z[k]) | (nk < a[k]) & (nk > z[k])
            trial = np.where(use, nk, trial)
            before = s[k]
            s[k] = trial
            dg = (b.g1 - b.g0)[c[k]]
            g = b.g0[c[k]] + trial[:, None] * dg
            gf, dgf = self._data(c[k], trial)
            val, jac = self.solution.value_and_jacobian(g)
            h = _cross(w[k] - gf, val - gf)
            dh = _cross(-dgf, val - gf) + _cross(w[k] - gf, np.einsum("kab,kb->ka", jac, dg) - dgf)
            with np.errstate(divide="ignore", invalid="ignore"):
                newton[k] = trial - h / dh
            left = np.sign(h) == np.sign(fa[k])
            # Illinois: halve the kept end's value when the same end is kept twice
            fz[k] = np.where(~left & (side[k] == -1), 0.5 * fz[k], fz[k])
            fa[k] = np.where(left & (side[k] == 1), 0.5 * fa[k], fa[k])
            a[k], fa[k] = np.where(left, trial, a[k]), np.where(left, h, fa[k])
            z[k], fz[k] = np.where(left, z[k], trial), np.where(left, fz[k], h)
            side[k] = np.where(left, 1, -1)
            live = k[~((trial == before) | (h == 0) | (np.abs(z[k] - a[k]) <= 4e-16))]
            if not live.size:
                break
        g = b.g0[c] + s[:, None] * (b.g1 - b.g0)[c]
        gf = self._data(c, s)[0]
        val = self.solution.value_and_jacobian(g)[0]
        d = val - gf
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((w - gf) * d).sum(axis=1) / (d * d).sum(axis=1)
        miss = np.hypot(*(gf + t[:, None] * d - w).T)
        scale = np.hypot(*d.T)
        scale = np.maximum(scale, 1e-300)
        # w on the segment, within the closed form's rounding (MISS) across it and along it
        slack = EDGE_SLACK + self._miss / scale
        on = (miss <= 1e-9 * scale + self._miss) & (t >= -slack) & (t <= 1.0 + slack)
        t[~on] = np.nan
        return s, t

    @cached_property
    def _knots(self):
        """Per cell: the parameters s where phi(G(s)) is known (the pieces' centres, and the ends), its
        values there, g(F(s)) there, and per interval between two of them a box (lower and upper
        corners) holding the interval's image.

        The box is proved, up to rounding: on an interval, g(F(s)) lies on the chord of the data
        within `BoundaryData.stray`, and phi(G(s)) in the capsules of the certificate's pieces that
        cover it (the two whose centres end it); the collar's segments between them, and the
        values `_roots` accepts (within `MISS` of a segment), lie in the box of those.
        """
        b = self.band
        ends = np.concatenate([b.g0, b.g1])
        vals = self.solution.value_and_jacobian(ends)[0]
        n = len(b.f0)
        v0, v1 = vals[:n], vals[n:]
        on_gamma = np.full(n, -1, dtype=np.intp)
        on_gamma[b.of_gamma] = np.arange(len(b.of_gamma))
        kg = self.knots[:, 0].astype(np.intp)
        pad = self._miss
        out = []
        for c in range(n):  # loop over cells: knots of its Gamma edge, between the two ends
            mine = np.flatnonzero(kg == on_gamma[c])
            mine = mine[np.argsort(self.knots[mine, 1], kind="stable")]
            s_k = np.concatenate([[0.0], self.knots[mine, 1], [1.0]])
            v_k = np.concatenate([v0[c][None], self.knots[mine, 2:4], v1[c][None]])
            g_k = self._data(np.full(len(s_k), c), s_k)[0]
            # the capsules: w0 +- r D0, thickened; interval j is covered by pieces j - 1 and j
            reach = np.abs(self.knots[mine, 4:6]) + self.knots[mine, 6:7]
            cap_lo, cap_hi = self.knots[mine, 2:4] - reach, self.knots[mine, 2:4] + reach
            lo, hi = np.full((len(s_k) - 1, 2), np.inf), np.full((len(s_k) - 1, 2), -np.inf)
            if len(mine):
                lo[:-1], hi[:-1] = cap_lo, cap_hi
                lo[1:], hi[1:] = np.minimum(lo[1:], cap_lo), np.maximum(hi[1:], cap_hi)
            else:  # no piece to bound phi(G(s)) (not expected: every edge of Gamma has one): anywhere
                lo[:], hi[:] = -np.inf, np.inf
            # the data over each interval: the tangent at its middle +- half, and how far they stray from it
            t_a = b.t0[c] + s_k[:-1] * (b.t1 - b.t0)[c]
            t_b = b.t0[c] + s_k[1:] * (b.t1 - b.t0)[c]
            e = np.full(len(t_a), b.edge[c])
            half = 0.5 * (t_b - t_a)
            gm = self.data.points(e, 0.5 * (t_a + t_b))
            span = np.abs(self.data.tangent(e, 0.5 * (t_a + t_b)) * half[:, None])
            stray = self.data.stray(e, t_a, t_b, half)[:, None]
            lo, hi = np.minimum(lo, gm - span - stray), np.maximum(hi, gm + span + stray)
            out.append((s_k, v_k, g_k, lo - pad, hi + pad))
        return out

    @property
    def _miss(self) -> float:
        """How far from a segment a value may be and still be found on it (`MISS` of Theta's size)."""
        theta = np.asarray(self.data.theta, dtype=np.float64)
        return MISS * float(np.ptp(theta, axis=0).max())
