"""Composition: the bijection f = phi1^-1 o phi0 between two polygons (eq. (2)), and the policy that builds it."""

from __future__ import annotations

import contextvars
import threading
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._fork import empty
from .._native import Kernels, parallel
from ..cores import budget
from ..errors import InputError
from ..grid import inside_polygon, window
from ..options import MapOptions, check_size
from ..polygon import Polygon, check_pair
from ..mapping import Certificate, ComposedMap
from .base import ThetaMap
from .registry import METHODS, THETAS
from .straight import fold_message as straight_fold_message
from .theta import SMOOTH_MAX_ASPECT, TargetTheta, Theta, aspect_ratio, from_file

#: The compiled helpers of the composition (`warpcli.maps._kernels`), loaded without numba.
_compiled = Kernels("warpcli.maps._kernels")

#: A rectangle ``(xmin, ymin, xmax, ymax)`` in a polygon's coordinates.
Region = tuple[float, float, float, float]

#: The composition works through the output grid in bands of about this many
#: pixels, so its temporary arrays stay small whatever the image size.
BAND_PIXELS = 1 << 18
#: The rows and columns `_most_work_first` samples a band's work on.
WORK_STRIDE = 8


@dataclass(frozen=True)
class PullBack:
    """The inverse map f^-1 at the pixel centres of an output grid, in a window.

    Only the window around the target polygon's bounding box (see
    `warpcli.grid.window`) is computed and stored: outside it no pixel
    centre has a pre-image, so a small target on a huge image costs little.

    Attributes
    ----------
    points : (h, w, 2) ndarray of float
        Source point of each pixel centre of the window; NaN outside the target.
    jacobian : (h, w, 2, 2) ndarray of float or None
        Jacobian of f^-1 there (d source / d target), if asked for; NaN where
        unknown.
    origin : (int, int)
        ``(row, column)`` of the window's top-left pixel in the grid.
    size : (int, int)
        The whole grid's ``(width, height)``.
    """

    points: NDArray[np.float64]
    jacobian: NDArray[np.float64] | None
    origin: tuple[int, int]
    size: tuple[int, int]

    def full_points(self) -> NDArray[np.float64]:
        """`points` spread over the whole grid: (height, width, 2), NaN outside the window."""
        return self.spread(self.points)

    def spread(self, values: NDArray) -> NDArray:
        """Window-shaped float ``values`` (h, w, ...) spread over the whole grid, NaN outside."""
        width, height = self.size
        out = np.full((height, width) + values.shape[2:], np.nan, dtype=values.dtype)
        r, c = self.origin
        out[r : r + values.shape[0], c : c + values.shape[1]] = values
        return out


class BijectiveMap(ComposedMap):
    """The smooth bijective map f between two polygons, as two maps onto one Theta.

    ``forward`` takes source points to the target, ``inverse`` takes target
    points back to the source: f = phi1^-1 o phi0 and f^-1 = phi0^-1 o phi1
    (the paper's eq. (2)), for any two `ThetaMap` of the same Theta, whatever
    the method that made them. Build one with `BijectiveMap.between`.
    ``forward``, ``inverse``, their Jacobians and the certificates are
    `warpcli.mapping.ComposedMap`'s, the same for polyhedra; what is here
    knows pixel grids and polygons.

    Parameters
    ----------
    phi0 : ThetaMap
        The source polygon onto Theta.
    phi1 : ThetaMap
        The target polygon onto the same Theta.

    Raises
    ------
    InputError
        If the maps go onto different Thetas, or the polygons' vertex counts differ.

    References
    ----------
    Schneider & Hormann, Smooth bijective maps between arbitrary planar
    polygons, CAGD 2015, eq. (2).
    """

    def __init__(self, phi0: ThetaMap, phi1: ThetaMap) -> None:
        check_pair(phi0.polygon, phi1.polygon)
        if not phi0.theta.same_as(phi1.theta):
            raise InputError(
                f"{phi0.polygon.name} and {phi1.polygon.name} are mapped onto different Thetas "
                f"({phi0.theta.name}, {phi1.theta.name}); f = phi1^-1 o phi0 needs one"
            )
        super().__init__(phi0, phi1)

    @classmethod
    def between(
        cls,
        src: Polygon,
        dst: Polygon,
        options: MapOptions | None = None,
        *,
        regions: tuple[Region | None, Region | None] = (None, None),
        **changes: Any,
    ) -> BijectiveMap:
        """Build the map between two polygons (see `build_map`).

        Parameters
        ----------
        src, dst : Polygon or (n, 2) array_like
            Corresponding polygons: vertex i of ``src`` goes to vertex i of ``dst``.
        options : MapOptions or None
            How to build it; the defaults otherwise.
        regions : (region, region)
            Where the source and the target map will be evaluated, each
            ``(xmin, ymin, xmax, ymax)`` or None (see `build_map`).
        **changes
            Fields of `MapOptions` to change, e.g. ``max_area=4``.

        Returns
        -------
        BijectiveMap

        Raises
        ------
        InputError
            If the options are bad or the polygons do not correspond.
        FoldOverError
            If the map would fold (never handed back).
        """
        opts = options or MapOptions()
        if changes:
            import dataclasses

            try:
                opts = dataclasses.replace(opts, **changes)
            except TypeError as err:
                raise InputError(f"unknown map option: {err}") from None
        return build_map(src, dst, opts, regions=regions)

    @property
    def src(self) -> Polygon:
        """The source polygon."""
        return self.phi0.polygon

    @property
    def dst(self) -> Polygon:
        """The target polygon."""
        return self.phi1.polygon

    @property
    def orientation_preserving(self) -> bool:
        """False when the polygons run in opposite directions: f is then a mirror image."""
        return (self.src.signed_area > 0) == (self.dst.signed_area > 0)

    def fold_message(self, source: Certificate, target: Certificate) -> str:
        """What `check_bijective` says when either map flips."""
        return (
            f"the maps flip {source.flipped} {source.kind} of {self.src.name} and {target.flipped} {target.kind} of "
            f"{self.dst.name}; the warp would fold the image over itself"
        )

    def check_bijective(self) -> None:
        """Raise `FoldOverError` unless both maps are certified one-to-one.

        With ``--theta none`` (Theta the target itself, `warpcli.maps.straight`)
        a fold is no failure of the method but of the choice: the straight map
        does not exist for this pair, which is bad input (`InputError`, one line).
        """
        if isinstance(self.theta, TargetTheta):
            source = self.phi0.certify()
            if not source.ok:
                raise InputError(straight_fold_message(self.src, self.dst, source.flipped))
        super().check_bijective()

    def flipped_triangles(self) -> int:
        """Elements (triangles, or samples) where either map flips: 0 for a bijection."""
        return sum(c.flipped for c in self.certificates())

    def forward_boundary(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """The exact boundary map: the target point of parameter t on source edge i."""
        return self.phi1.boundary_from_theta(edge, self.phi0.to_theta_parameter(edge, t))

    def inverse_boundary(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """The exact boundary map backwards: the source point of parameter t on target edge i."""
        return self.phi0.boundary_from_theta(edge, self.phi1.to_theta_parameter(edge, t))

    def pull_back(
        self, width: int, height: int, *, jacobian: bool = True, rows: tuple[int, int] | None = None
    ) -> PullBack:
        """f^-1 (and its Jacobian) at the pixel centres of a ``width`` x ``height`` output grid.

        Only the window around the target's bounding box is computed, in
        bands of rows: phi1 on the band's pixel grid
        (`ThetaMap.evaluate_grid`), then phi0^-1 of those points of Theta in
        the order they were found (coherent).

        Parameters
        ----------
        width, height : int
            Output size in pixels (the target polygon's coordinates).
        jacobian : bool
            Also compute the Jacobian of f^-1 per pixel.
        rows : (int, int) or None
            Only the rows ``start <= r < stop`` of the grid (the window is cut
            to them; it may be empty): for images warped strip by strip
            (`warpcli.tiled`). The bands are those of the whole grid, so the
            values are those of the whole pull-back, bit for bit.

        Returns
        -------
        PullBack
        """
        width, height = check_size((width, height))
        return _through_theta(self.phi1, self.phi0, width, height, jacobian, rows)

    def inverse_grid(self, width: int, height: int) -> NDArray[np.float64]:
        """`inverse` at every pixel centre of a ``width`` x ``height`` output image.

        Returns
        -------
        (height, width, 2) ndarray of float
            Source point of each output pixel centre; NaN outside the target.
        """
        return self.pull_back(width, height, jacobian=False).full_points()

    def forward_grid(self, width: int, height: int) -> NDArray[np.float64]:
        """`forward` at every pixel centre of a ``width`` x ``height`` source image.

        Returns
        -------
        (height, width, 2) ndarray of float
            Target point of each source pixel centre; NaN outside the source.
        """
        width, height = check_size((width, height))
        return _through_theta(self.phi0, self.phi1, width, height, False).full_points()

    def describe(self) -> dict:
        """What the methods add to a report, prefixed by ``source_`` and ``target_``."""
        out = {f"source_{k}": v for k, v in self.phi0.describe().items()}
        out.update({f"target_{k}": v for k, v in self.phi1.describe().items()})
        return out


#: What `_compiled.scatter_band` is given for Jacobians and their indices when none are asked for.
_NO_JAC = np.zeros((1, 2, 2))
_NO_INDEX, _NO_INDEX32 = np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int32)

#: The bands the last strip of a pull-back computed, by the map whose grid they scan
#: (see `_through_theta`); weak, so that they go with their map.
_STRIP_BANDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _through_theta(
    phi_grid: ThetaMap, phi_other: ThetaMap, width: int, height: int, jacobian: bool,
    rows: tuple[int, int] | None = None,
) -> PullBack:  # fmt: skip
    """phi_other^-1 o phi_grid at the pixel centres of the grid phi_grid's polygon lives on
    (in the rows ``rows`` only, if given)."""
    w0, w1, c0, c1 = window(phi_grid.polygon.bounds, width, height)
    band = max(1, BAND_PIXELS // width)
    r0, r1 = w0, w1
    if rows is not None:
        r0 = min(max(rows[0], w0), w1)
        r1 = max(min(rows[1], w1), r0)
    ww = c1 - c0
    # In a sequence's map worker, made in the memory the plan is sent back through (no copy there).
    points = empty(((r1 - r0) * ww, 2))
    jac = empty(((r1 - r0) * ww, 2, 2)) if jacobian else None

    # Methods whose Jacobians are constant per cell (FEM) give the cells, and the
    # products are made from their tables as the band is scattered (`scatter_band`).
    cells = jacobian and hasattr(phi_grid, "grid_cells") and hasattr(phi_other, "inverse_cells")

    def band_values(first: int, last: int) -> tuple:
        if cells:
            g, grid_cells = phi_grid.grid_cells(width, height, (first, last))
            pixels, values, jac_grid = g.pixels, g.values, grid_cells
        else:
            g = phi_grid.evaluate_grid(width, height, (first, last), jacobian=jacobian)
            pixels, values, jac_grid = g.pixels, g.values, g.jacobian
        # The window holds every centre in the polygon (its bounding box and
        # a margin); a method that reported one beyond it would be dropped.
        pixels = np.ascontiguousarray(pixels, dtype=np.int64)
        if _compiled.outside_columns(pixels, width, c0, c1):
            keep = (pixels % width >= c0) & (pixels % width < c1)
            pixels, values = pixels[keep], values[keep]
            jac_grid = None if jac_grid is None else jac_grid[keep]
        if cells:
            return (pixels, *phi_other.inverse_cells(values, coherent=True), jac_grid)
        m = phi_other.inverse(values, jacobian=jacobian, coherent=True)
        return pixels, m.points, m.jacobian, jac_grid

    # Strips (``rows``) of a narrow image are thinner than a band (BAND_PIXELS
    # over the width): each strip would compute its whole band again, so a
    # tall thin image cost time quadratic in its height. The bands of the
    # last strip are kept for the next (at most a strip and a band of points).
    kept = made = lock = None
    if rows is not None:
        lock = threading.Lock()
        last_bands = _STRIP_BANDS.get(phi_grid)
        kept = last_bands[1] if last_bands is not None and last_bands[0] is phi_other else {}
        made = {}

    def one_band(first: int) -> None:
        # Bands are independent (each walk starts afresh) and write their own
        # rows of the window, so they run on all cores with the same result.
        # They are the whole window's bands, whatever ``rows`` cuts out, and
        # every point of a band is inverted: a walk's rounding depends on
        # where it starts.
        last = min(first + band, w1)
        start, stop = max(first, r0), min(last, r1)
        lo, hi = (start - r0) * ww, (stop - r0) * ww
        points[lo:hi] = np.nan
        if jac is not None:
            jac[lo:hi] = np.nan
        key = (width, height, first, jacobian)
        hit = kept.get(key) if kept is not None else None
        if hit is None:
            hit = band_values(first, last)
        if kept is not None:
            with lock:
                made[key] = hit
        pixels, found, jac_found, jac_grid = hit
        found = np.ascontiguousarray(found, dtype=np.float64)
        # Each pixel of the band in the rows wanted, into its place in the window, the Jacobians'
        # products from per-cell tables (FEM) or per pixel (one compiled pass).
        if jac is None:
            tables = (_NO_JAC, _NO_INDEX, _NO_JAC, _NO_INDEX32)
        elif cells:
            tables = (phi_other.jacobian_table("inverse"), np.ascontiguousarray(jac_found),
                      phi_grid.jacobian_table("grid"), np.ascontiguousarray(jac_grid))  # fmt: skip
        else:
            k = np.arange(len(pixels))
            tables = (np.ascontiguousarray(jac_found), k, np.ascontiguousarray(jac_grid), k.astype(np.int32))
        _compiled.scatter_band(
            pixels, width, r0, c0, ww, start, stop, found, *tables, jac is not None, points,
            _NO_JAC if jac is None else jac,
        )  # fmt: skip

    if r1 > r0:
        firsts = range(w0 + (r0 - w0) // band * band, r1, band)
        parallel(one_band, _most_work_first(firsts, band, w1, c0, c1, phi_grid.polygon.points))
    if made is not None:
        _STRIP_BANDS[phi_grid] = (phi_other, made)
    shape = (r1 - r0, ww)
    return PullBack(
        points.reshape(*shape, 2), None if jac is None else jac.reshape(*shape, 2, 2), (r0, c0), (width, height)
    )


def _most_work_first(firsts: range, band: int, last: int, c0: int, c1: int, vertices) -> list[int]:
    """The bands' first rows, those with the most pixel centres in the polygon first (counted on
    every `WORK_STRIDE`-th row and column).

    `parallel` hands each thread the next band when it is free: with the largest first, the small
    ones fill in at the end. In their own order, a 1 MP star's four bands of 28k, 105k, 66k and 3k
    pixels left one core idle for a quarter of a BEM pull-back (measured). Bands are independent,
    so their order does not change a value."""
    if len(firsts) <= 1:
        return list(firsts)
    # the bands' rows only: a strip's bands are a few of the window's, and counting the rest of
    # the window for each strip would cost a gigapixel run time quadratic in its strips
    rows = np.arange(firsts[0], min(firsts[-1] + band, last), WORK_STRIDE) + 0.5
    cols = np.arange(c0, c1, WORK_STRIDE) + 0.5
    xx, yy = np.meshgrid(cols, rows)
    inside = inside_polygon(np.stack([xx.ravel(), yy.ravel()], axis=1), vertices).reshape(len(rows), len(cols))
    per_row = inside.sum(axis=1)
    which = (rows.astype(np.int64) - firsts[0]) // band
    work = np.bincount(which, weights=per_row, minlength=len(firsts))[: len(firsts)]
    return [firsts[i] for i in np.argsort(-work, kind="stable")]


class Task:
    """``fn(*args)`` on a thread of its own; `result` waits for it and returns or raises what it did.

    ``fn`` runs in a copy of the creator's context (`contextvars`), as if
    called there. Its thread is marked ``warpcli_task``: work that nobody
    may wait for any more (the map of a run stopped by bad input) and that
    the ``warp`` command does not wait for before it exits; Python's own
    exit does, as for any thread.

    With a core budget of 1 (`warpcli.cores`) nothing runs beside the
    creator: ``fn`` runs when `result` is first called, on the caller's
    thread (after the creator's own work, the order in which a forked
    builder's records are logged), and never if nobody asks.
    """

    def __init__(self, fn: Callable[..., Any], *args: Any, name: str = "warp-task") -> None:
        self._value: Any = None
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        context = contextvars.copy_context()
        if budget() <= 1:  # one core (`warpcli.cores`): run by `result`, on the caller's thread
            self._later: tuple | None = (context, fn, args)
            return
        self._later = None
        self._thread = threading.Thread(target=context.run, args=(self._run, fn, args), name=name)
        self._thread.warpcli_task = True  # type: ignore[attr-defined]
        self._thread.start()

    def _run(self, fn: Callable[..., Any], args: tuple) -> None:
        try:
            self._value = fn(*args)
        except BaseException as err:  # handed to whoever asks for the result
            self._error = err

    def result(self) -> Any:
        if self._later is not None:
            context, fn, args = self._later
            self._later = None
            context.run(self._run, fn, args)
        if self._thread is not None:
            self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value


def theta_for(src: Polygon, dst: Polygon, options) -> Theta:
    """The Theta ``options.theta`` asks for: a registered strategy's, or a file's.

    Part of the policy, here rather than in `warpcli.maps.theta`: it looks the
    strategy up in `warpcli.maps.registry`, which names ``theta``'s strategies,
    so ``theta`` must not import it.

    Parameters
    ----------
    src, dst : Polygon
    options : MapOptions
        ``theta`` (a name in `warpcli.maps.registry.THETAS` or a JSON file)
        and ``conditions`` (``"mixed"`` takes the unit square).

    Returns
    -------
    Theta

    Raises
    ------
    InputError
        If the file cannot be read, or mixed conditions meet another Theta
        or polygons that are not quadrilaterals; also for a file's Theta
        flatter than `warpcli.maps.theta.SMOOTH_MAX_ASPECT` with BEM or MFS.
    """
    if getattr(options, "conditions", "dirichlet") == "mixed":
        # §5.2: natural boundary conditions need Theta to be the unit square.
        if src.n != 4:
            raise InputError(f"{src.name}: mixed boundary conditions need quadrilaterals (4 vertices), got {src.n}")
        if options.theta != "regular":
            raise InputError(f"mixed boundary conditions use the unit square as Theta, not {options.theta!r}")
        return Theta(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), name="unit square")
    if options.theta in THETAS:
        return THETAS[options.theta].load()(src, dst, options)
    theta = from_file(options.theta, src.n)
    method = getattr(options, "method", "fem")
    if method in ("bem", "mfs"):
        ratio = aspect_ratio(theta.points)
        if ratio > SMOOTH_MAX_ASPECT:
            raise InputError(
                f"{options.theta}: Theta is too flat for --method {method} (its axes' ratio is {ratio:.3g}:1, the "
                f"limit is {SMOOTH_MAX_ASPECT:g}:1); stretching Theta does not change the map: "
                "scale it to a rounder box, or use --method fem"
            )
    return theta


def build_map(
    src: Polygon,
    dst: Polygon,
    options: MapOptions | None = None,
    *,
    regions: tuple[Region | None, Region | None] = (None, None),
) -> BijectiveMap:
    """The construction policy: choose Theta, build both maps concurrently, certify.

    Parameters
    ----------
    src, dst : Polygon or (n, 2) array_like
        Corresponding polygons (vertex i of ``src`` goes to vertex i of ``dst``).
    options : MapOptions or None
        The method and Theta strategy by name, and their parameters.
    regions : (region, region)
        Where each map will be evaluated: the input and the output image,
        ``(xmin, ymin, xmax, ymax)``, or None. A method may spend its accuracy
        there (FEM meshes a polygon that reaches far beyond its image graded
        from the image), so that the cost follows the images, not the
        polygons' size.

    Returns
    -------
    BijectiveMap
        Its ``timings`` hold the seconds of each stage of building, summed
        over both maps (they are built at once, so the sum can exceed the wall
        time).

    Raises
    ------
    InputError
        If the polygons do not correspond or the options are bad.
    FoldOverError
        If, with ``options.check``, either map is not certified one-to-one.
    """
    opts = options or MapOptions()
    src = src if isinstance(src, Polygon) else Polygon(np.asarray(src, dtype=np.float64), name="src")
    dst = dst if isinstance(dst, Polygon) else Polygon(np.asarray(dst, dtype=np.float64), name="dst")
    check_pair(src, dst)
    theta = theta_for(src, dst, opts)
    result = _build_onto(src, dst, theta, opts, regions)
    fallback = theta.notes.get("fallback") if isinstance(theta, TargetTheta) else None
    if fallback is not None and not result.phi0.certify().ok:
        # The optimizer kept the straight map, certified at the run's density
        # without a region; meshed graded from a region it folds: the best
        # convex Theta instead (`warpcli.maps.optimize`).
        notes = {k: v for k, v in theta.notes.items() if not k.startswith("fallback")}
        notes.update(kept=theta.notes.get("fallback_name"), after=theta.notes.get("fallback_after"), none=None)
        result = _build_onto(src, dst, Theta(np.asarray(fallback), name=theta.name, notes=notes), opts, regions)
    if opts.check:
        result.check_bijective()
    return result


def children_at_once(options: MapOptions) -> int:
    """How many children `map_between` forks as soon as it starts with these options (0, 1 or 2).

    A caller that starts the build on a thread and then holds the GIL for a while (an import)
    may let them be forked first (`warpcli.pipeline`). The method says whether it forks at
    once (``forks``); Theta must be one chosen without an optimization, and the straight map
    onto the target (``--theta none``) forks the source's child alone.
    """
    method = METHODS[options.method].load() if options.method in METHODS else None
    if method is None or not getattr(method, "forks", lambda _: False)(options):
        return 0
    return {"regular": 2, "cyclic": 2, "none": 1}.get(options.theta, 0)


def _build_onto(src: Polygon, dst: Polygon, theta: Theta, opts: MapOptions, regions) -> BijectiveMap:
    """`build_map` for a chosen Theta, uncertified."""
    method = METHODS[opts.method].load()

    def built(polygon: Polygon, role: str, region: Region | None, side: str, pending: Any = None) -> ThetaMap:
        phi = pending.result() if pending is not None else method.build(polygon, theta, opts, role, region)
        # Maps built for images (regions given) are pulled back next: the
        # target evaluated on the output grid, the source inverted. A method
        # that keeps lookup tables for that makes them here, on this thread.
        if region is not None and hasattr(phi, "precompute"):
            phi.precompute(side)
        return phi

    # Each map is built in a forked child where the method can (FEM: triangle
    # and SuperLU hold the GIL, so two threads would take turns), with its
    # lookup tables, while this process loads the method's kernels (and the
    # caller reads the image): three jobs at once instead of this process
    # building the target, making its tables and loading the kernels in turns
    # on one GIL (its share was the longest, 70 ms more than the child's at
    # 1 MP). Otherwise the source is built on a second thread and the target
    # here. Each map is independent, so the results do not depend on the
    # scheduling.
    forked = getattr(method, "build_forked", None)
    pending: list[Any] = [None, None]
    if forked is not None:
        for k, (polygon, role, side) in enumerate(((src, "source", "inverse"), (dst, "target", "grid"))):
            pending[k] = forked(polygon, theta, opts, role, regions[k], precompute=side if regions[k] is not None else None)
    source = Task(built, src, "source", regions[0], "inverse", pending[0])
    Task(method.prepare)  # nobody waits: a kernel called before it is loaded waits for it
    try:
        phi1 = built(dst, "target", regions[1], "grid", pending[1])
    except BaseException:
        for child in pending:  # the source is no longer wanted (nor the target, if this was interrupted)
            if child is not None:
                child.cancel()
        raise
    phi0 = source.result()
    result = BijectiveMap(phi0, phi1)
    for phi in (phi0, phi1):
        for stage, seconds in phi.timings.items():
            result.timings[stage] = result.timings.get(stage, 0.0) + seconds
    return result
