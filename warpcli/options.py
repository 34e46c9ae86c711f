"""Options: the typed objects that carry a run's choices, and the one list of each choice.

This module is imported by the CLI to build ``--help``, so it imports nothing heavy; and it
is read by maps, raster and pipelines alike, so it imports nothing of warpcli but errors.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from .errors import InputError
from .raster.dtypes import COMPRESSION_LEVELS, DTYPES, PNG_COMPRESSION  # noqa: F401  (re-exported)

#: Methods that approximate the harmonic maps onto Theta; `warpcli.maps.registry.METHODS`
#: says which module implements each (the same names, in the same order: tested).
METHODS = ("fem", "bem", "mfs")
#: Named strategies that choose Theta; `warpcli.maps.registry.THETAS` implements them.
THETAS = ("regular", "cyclic", "optimized", "none")
#: Resampling filters (see `warpcli.raster.resample.resample`).
INTERPOLATIONS = ("nearest", "linear", "cubic")
#: Edge weights of the FEM Laplacian.
WEIGHTS = ("cotan", "positive")
#: What a distortion heatmap shows.
HEATMAP_MEASURES = ("conformal", "isometric", "det")
#: Which way an STMap's t coordinate runs.
STMAP_T = ("down", "up")
#: What the output holds outside the target polygon.
OUTSIDE = ("background", "input")
#: With OUTSIDE "input": what the part of the source the target leaves uncovered shows.
VACATED = ("keep", "background")
#: How `warp apply-map` takes a map made for an image of another size: refuse it, or stretch its coordinates.
MAP_SCALES = ("refuse", "stretch")
#: Boundary conditions: Dirichlet everywhere, or the experimental mixed conditions of §5.2.
CONDITIONS = ("dirichlet", "mixed")
#: Energies the Theta optimization can lower: area-weighted means over the source, or smooth maxima.
ENERGIES = ("conformal", "isometric", "max-conformal", "max-isometric")
#: Boundary behaviours: parameter t of a polygon edge goes to t, or t^2, of Theta's edge.
BOUNDARIES = ("linear", "quadratic")


def _choice(what: str, value: object, choices) -> None:
    if value not in choices:
        raise InputError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")


def _positive(what: str, value: object) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a positive number, got {value!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise InputError(f"{what} must be positive and finite, got {value!r}")
    return v


@dataclass(frozen=True)
class MapOptions:
    """How the bijective map between two polygons is built.

    Parameters
    ----------
    method : str
        Name of the method that approximates the harmonic maps onto Theta, one
        of `METHODS` (``"fem"``).
    theta : str
        Name of the strategy that chooses the convex intermediate polygon Theta,
        one of `THETAS` (``"regular"``, ``"cyclic"``, ``"optimized"``),
        or a JSON file holding one (n ``[x, y]`` vertices, strictly convex);
        ``"none"`` (FEM only): no Theta, the plain harmonic map straight onto
        the target, refused where it folds (`warpcli.maps.straight`).
    max_area : float, (float, float) or None
        FEM: largest triangle area in square pixels, for both meshes or
        (source, target); None: automatic (`warpcli.maps.fem.mesh.auto_max_area`).
    weights : {"cotan", "positive"}
        FEM: ``cotan`` solves the harmonic maps (the paper's §3.1.1);
        ``positive`` uses mean-value weights, one-to-one on any mesh but no
        longer harmonic (§3.1.4).
    check : bool
        Certify that neither map folds (and let a method repair what it can);
        never hand back a folding map.
    src_boundary, dst_boundary : {"linear", "quadratic"}
        The boundary behaviour of each side (§5.2): the point at parameter t
        of an edge goes to parameter t (linear) or t^2 (quadratic) of Theta's
        edge. The paper makes the target quadratic.
    energy : {"conformal", "isometric", "max-conformal", "max-isometric"}
        What ``theta="optimized"`` lowers: the area-weighted mean distortion
        over the source, or (``max-``) a smooth stand-in for its maximum.
    theta_start : {"regular", "cyclic"}
        The optimization starts from both; this one is reported as ``before``.
    nodes : int or None
        BEM and MFS: the number m of boundary nodes (BEM) or sites (MFS),
        at least the vertex count and within memory
        (`warpcli.maps.meshless.FIT_BYTES_PER_NODE2`); None: max(256, 8 n),
        at most `warpcli.maps.meshless.MAX_AUTO_NODES`.
    conditions : {"dirichlet", "mixed"}
        Experimental (§5.2, quadrilaterals only): ``mixed`` maps onto the unit
        square with natural boundary conditions, each coordinate prescribed on
        the two edges where it is constant and free to slide along the others;
        the result is still certified, never folded.
    grade : bool
        FEM: refine the meshes geometrically towards reflex vertices, where
        the map's gradient is singular (the default, for accuracy there);
        False: meshes of ``max_area`` alone, several times fewer vertices,
        for previews (`warpcli.edit`).

    Raises
    ------
    InputError
        If a name is unknown or a number is out of range.
    """

    method: str = "fem"
    theta: str = "regular"
    max_area: float | tuple[float, float] | None = None
    weights: str = "cotan"
    check: bool = True
    src_boundary: str = "linear"
    dst_boundary: str = "linear"
    energy: str = "conformal"
    theta_start: str = "regular"
    conditions: str = "dirichlet"
    nodes: int | None = None
    grade: bool = True

    @property
    def theta_file(self) -> str | None:
        """The Theta file these options read (``theta`` a .json path), else None: an input of the run."""
        return None if self.theta in THETAS else str(self.theta)

    def __post_init__(self) -> None:
        _choice("method", self.method, METHODS)
        if not isinstance(self.grade, bool):
            raise InputError(f"grade must be True or False, got {self.grade!r}")
        if self.theta not in THETAS and not str(self.theta).lower().endswith(".json"):
            raise InputError(
                f"unknown Theta {self.theta!r}; choose one of {', '.join(THETAS)} or give a JSON file (.json)"
            )
        _choice("energy", self.energy, ENERGIES)
        if self.nodes is not None and not (isinstance(self.nodes, int) and 3 <= self.nodes <= 100_000):
            raise InputError(f"nodes must be a whole number from 3 to 100000, got {self.nodes!r}")
        _choice("boundary conditions", self.conditions, CONDITIONS)
        _choice("start of the Theta optimization", self.theta_start, ("regular", "cyclic"))
        _choice("source boundary", self.src_boundary, BOUNDARIES)
        _choice("target boundary", self.dst_boundary, BOUNDARIES)
        _choice("weights", self.weights, WEIGHTS)
        if self.max_area is not None:
            if isinstance(self.max_area, (tuple, list)):
                if len(self.max_area) != 2:
                    raise InputError(f"max_area must be one number or a (source, target) pair, got {self.max_area!r}")
                areas = tuple(_positive("max_area", a) for a in self.max_area)
                object.__setattr__(self, "max_area", areas)
            else:
                object.__setattr__(self, "max_area", _positive("max_area", self.max_area))

    def areas(self) -> tuple[float | None, float | None]:
        """``max_area`` as a (source, target) pair."""
        a = self.max_area
        return a if isinstance(a, tuple) else (a, a)  # type: ignore[return-value]


def outline_file(within: str | None) -> str | None:
    """The polygon file a retouch's ``within`` names, else None (no retouch, ``"image"``, or a margin).

    The one reading of ``within`` (`warpcli.polygon.outline.outline_polygon`
    follows it): the file is an input of the run, which no output may replace.

    >>> outline_file("image"), outline_file(" 12.5 "), outline_file("outline.json")
    (None, None, 'outline.json')
    """
    if within is None:
        return None
    text = str(within).strip()
    if text == "image":
        return None
    try:
        float(text)
    except ValueError:
        return str(within)
    return None


@dataclass(frozen=True)
class WarpOptions:
    """How an image is warped: the map, the resampling, and the output.

    Parameters
    ----------
    map : MapOptions
    interp : {"nearest", "linear", "cubic"}
        ``linear`` is bilinear (reproduces linear data exactly), ``cubic`` the
        interpolating cubic B-spline, ``nearest`` the pixel the point falls in.
    background : float or tuple of float
        Value of output pixels outside the target, or whose pre-image lies
        outside the input: one for every channel or one per channel; 0..1 spans
        an integer type's range, floats are taken as they are.
    antialias : bool
        Antialias the target polygon's edge and, with ``linear``, average each
        output pixel over its footprint where the map shrinks.
    size : (width, height) or None
        Output size in pixels (width first); the input's by default.
    dtype : {"uint8", "uint16", "half", "float"} or None
        Output pixel type; the input's by default.
    outside : {"background", "input"}
        What the output holds outside the target polygon: the background, or
        the input image with the warped region composited over it (then the
        output has the input's size; see `warpcli.composite`).
    vacated : {"keep", "background"}
        With ``outside="input"``: the part of the source polygon the target
        no longer covers keeps the input's pixels, or is filled with the
        background.
    feather : float
        With ``outside="input"``: blend the warp into the input over a band
        this many pixels wide inside the target's edge (weight
        ``smoothstep(d / feather)`` at distance ``d`` from the edge, see
        `warpcli.composite.feather_weights`), as GIMP and Photoshop feather a
        selection; 0: no blend (a hard edge, antialiased).
    compression : int or None
        PNG outputs: the zlib level, 0 (stored: fastest, largest) to 9
        (smallest, slowest); None: `warpcli.raster.dtypes.PNG_COMPRESSION`
        (1). Other formats keep their own compression. The pixels are the
        same at every level.
    within : str or None
        A retouch within a fixed outline (`warpcli.within`): ``"image"``, a
        margin in pixels round the cages, or a polygon file. The cages move,
        the outline stays, the ring between them is mapped too (nothing
        vacated, no seam); outside the outline the output is the input's own
        pixels, so ``within`` implies ``outside="input"`` and the input's
        size, and takes no ``vacated="background"`` or ``feather``.

    Raises
    ------
    InputError
        If a value is out of range.

    Examples
    --------
    >>> WarpOptions().changed(interp="cubic", max_area=4).map.max_area
    4.0
    """

    map: MapOptions = field(default_factory=MapOptions)
    interp: str = "linear"
    background: float | tuple[float, ...] = 0.0
    antialias: bool = True
    size: tuple[int, int] | None = None
    dtype: str | None = None
    outside: str = "background"
    vacated: str = "keep"
    feather: float = 0.0
    compression: int | None = None
    within: str | None = None

    @property
    def within_file(self) -> str | None:
        """The outline file ``within`` names (`outline_file`), else None: an input of the run."""
        return outline_file(self.within)

    def __post_init__(self) -> None:
        if not isinstance(self.map, MapOptions):
            raise InputError(f"map must be MapOptions, got {type(self.map).__name__}")
        if self.within is not None:
            if not isinstance(self.within, str) or not self.within.strip():
                raise InputError(f"within must be 'image', a margin in pixels or a polygon file, got {self.within!r}")
            if self.size is not None:
                raise InputError("--within keeps the input's size: it takes no --size")
            if self.vacated != "keep":
                raise InputError("--within leaves nothing vacated: it takes no --vacated background")
            if self.feather:
                raise InputError("--within is seamless without a blend: it takes no --feather")
            object.__setattr__(self, "outside", "input")  # the outline's outside is the input's own
        _choice("interpolation", self.interp, INTERPOLATIONS)
        _choice("outside", self.outside, OUTSIDE)
        _choice("vacated", self.vacated, VACATED)
        try:
            feather = float(self.feather)
        except (TypeError, ValueError):
            raise InputError(f"feather must be a number of pixels, got {self.feather!r}") from None
        if not (feather >= 0 and math.isfinite(feather)):
            raise InputError(f"feather must be a finite number of pixels, 0 or more, got {self.feather!r}")
        if feather > 0 and self.outside != "input":
            raise InputError("--feather blends the warp into the input: it needs --outside input")
        object.__setattr__(self, "feather", feather)
        if self.dtype is not None:
            _choice("dtype", self.dtype, DTYPES)
        if self.compression is not None and (
            isinstance(self.compression, bool) or not isinstance(self.compression, int)
            or self.compression not in COMPRESSION_LEVELS
        ):  # fmt: skip
            raise InputError(f"compression must be an integer from 0 to 9, got {self.compression!r}")
        bg = self.background
        values = tuple(bg) if isinstance(bg, (tuple, list)) else (bg,)
        try:
            values = tuple(float(v) for v in values)
        except (TypeError, ValueError):
            raise InputError(f"background must be numbers, got {bg!r}") from None
        if not values or not all(math.isfinite(v) for v in values):
            raise InputError(f"background values must be finite numbers, got {bg!r}")
        object.__setattr__(self, "background", values[0] if len(values) == 1 else values)
        if self.size is not None:
            object.__setattr__(self, "size", check_size(self.size))

    def changed(self, **changes: Any) -> WarpOptions:
        """A copy with some fields changed; names of `MapOptions` fields change ``map``.

        Raises
        ------
        InputError
            If a name is not an option.
        """
        own = {f.name for f in dataclasses.fields(self)}
        mine = {k: v for k, v in changes.items() if k in own}
        theirs = {k: v for k, v in changes.items() if k not in own}
        map_fields = {f.name for f in dataclasses.fields(MapOptions)}
        unknown = sorted(set(theirs) - map_fields)
        if unknown:
            raise InputError(f"unknown option(s): {', '.join(unknown)}")
        if theirs:
            mine["map"] = dataclasses.replace(mine.get("map", self.map), **theirs)
        return dataclasses.replace(self, **mine)


#: The longest side of an image, in pixels: OpenImageIO keeps sizes in C ints.
MAX_SIDE = 2**31 - 1


def check_size(size: object) -> tuple[int, int]:
    """An image size ``(width, height)`` of positive integers, or `InputError`.

    >>> check_size((640, 480))
    (640, 480)
    """
    try:
        w, h = size  # type: ignore[misc]
        if int(w) != w or int(h) != h:
            raise ValueError
        w, h = int(w), int(h)
    except (TypeError, ValueError):
        raise InputError(f"size must be (width, height), two whole numbers, got {size!r}") from None
    if w <= 0 or h <= 0:
        raise InputError(f"size must be positive, got width {w} and height {h}")
    if max(w, h) > MAX_SIDE:
        raise InputError(f"size {w} x {h}: a side of more than {MAX_SIDE} pixels (OpenImageIO's limit)")
    return w, h


def resolve_options(options: WarpOptions | None, changes: dict[str, Any]) -> WarpOptions:
    """``options`` (the defaults if None) with ``changes`` applied: what every library call takes.

    Raises
    ------
    InputError
        If ``options`` is not a `WarpOptions`, or a change is unknown or invalid.
    """
    opts = options if options is not None else WarpOptions()
    if not isinstance(opts, WarpOptions):
        raise InputError(f"options must be WarpOptions, got {type(opts).__name__}")
    return opts.changed(**changes) if changes else opts
