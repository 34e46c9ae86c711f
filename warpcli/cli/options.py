"""Command-line options shared by the commands, and the option objects their values become.

As in rasterio's ``rio/options.py``, each option is defined once and the
commands stack the decorators. A group of options that the library takes as
one object (`warpcli.options.MapOptions`, `warpcli.options.WarpOptions`)
reaches the command as that object, built by `collected`, never as loose
values: ``map_options`` hands the command ``mapping``, ``resample_options``
hands it ``resampling``, ``polygon_options`` hands it ``polygons``.

Only the names of the choices are imported here (from the registry and
`warpcli.options`), so that ``warp --help`` stays instant.
"""

from __future__ import annotations

import functools
import logging
import sys
from typing import Any, Callable, NamedTuple

import click

from ..maps.registry import METHODS, THETAS
from ..options import (
    BOUNDARIES, CONDITIONS, DTYPES, ENERGIES, INTERPOLATIONS, MAX_SIDE, PNG_COMPRESSION, WEIGHTS, MapOptions, WarpOptions,
)  # fmt: skip

#: Context settings of every command: -h as well as --help, and help up to 100 columns wide.
CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


# --- grouping options into one object -----------------------------------------


def collected(name: str | None, build: Callable[..., Any], *options: Callable) -> Callable:
    """A decorator adding ``options`` to a command and handing the command their values as one object.

    click calls a command with one keyword argument per option; the command
    decorated with this receives instead ``name=build(**values)``, ``values``
    being those options' values by parameter name. The object is built before
    the command runs, so that a value the object refuses is reported before
    any work.

    Parameters
    ----------
    name : str or None
        The keyword under which the command receives the object; None: the
        command receives nothing (``build`` is called for its effect).
    build : callable
        Called with the options' values as keyword arguments.
    *options : decorator
        ``click.option`` decorators, in the order in which they appear in the
        help (the order one stacks them in).

    Returns
    -------
    decorator
    """

    def decorate(f: Callable) -> Callable:
        @functools.wraps(f)
        def command(*args, **kwargs):
            values = {key: kwargs.pop(key) for key in keys}
            built = build(**values)
            if name is not None:
                kwargs[name] = built
            return f(*args, **kwargs)

        # wraps() copied f's list of options by reference: give the wrapper its own.
        below = list(getattr(f, "__click_params__", ()))
        command.__click_params__ = list(below)  # type: ignore[attr-defined]
        for option in reversed(options):
            option(command)
        # click keeps a function's options last-stacked first: read them back in the order of ``options``.
        keys = [param.name for param in reversed(command.__click_params__[len(below) :])]  # type: ignore[attr-defined]
        return command

    return decorate


# --- value parsers (click callbacks) ---------------------------------------------


def parse_size(ctx, param, value):
    """``WIDTHxHEIGHT`` as ``(width, height)`` of positive integers, or None."""
    if value is None:
        return None
    try:
        w, h = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected WIDTHxHEIGHT such as 640x480, got {value!r}") from None
    if w <= 0 or h <= 0:
        raise click.BadParameter(f"width and height must be positive, got {value!r}")
    if max(w, h) > MAX_SIDE:
        shown = value if len(value) <= 40 else value[:37] + "..."
        raise click.BadParameter(f"a side of at most {MAX_SIDE} pixels (OpenImageIO's limit), got {shown!r}")
    return w, h


def parse_background(ctx, param, value):
    """``V[,V...]`` as a tuple of finite floats."""
    try:
        vals = [float(v) for v in value.split(",")]
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {value!r}") from None
    if not all(v == v and abs(v) != float("inf") for v in vals):
        raise click.BadParameter(f"values must be finite, got {value!r}")
    return tuple(vals)


def parse_max_area(ctx, param, value):
    """``auto`` as None, else a positive finite area."""
    if value is None or value == "auto":
        return None
    try:
        area = float(value)
    except ValueError:
        raise click.BadParameter(f"expected 'auto' or a positive number, got {value!r}") from None
    if not (area > 0 and area != float("inf")):
        raise click.BadParameter(f"must be positive and finite, got {value!r}")
    return area


# --- the polygons ------------------------------------------------------------------


class PolygonFiles(NamedTuple):
    """The polygon files of a run (--src, --dst) and which polygon of each (--src-label, --dst-label).

    A named tuple rather than a frozen dataclass: defining one costs a tenth
    as much, and every ``warp --help`` defines it.

    Parameters
    ----------
    src_path, dst_path : str
        The source and target polygon files.
    src_label, dst_label : str or None
        Which polygon of a file holding several: its label, or ``#N``.
    """

    src_path: str
    dst_path: str
    src_label: str | None = None
    dst_label: str | None = None

    def swapped(self) -> PolygonFiles:
        """The same files the other way round: the target becomes the source."""
        return PolygonFiles(self.dst_path, self.src_path, self.dst_label, self.src_label)


def polygon_options(src_help: str, dst_help: str, label_help: str) -> Callable:
    """--src, --dst, --src-label and --dst-label, handed to the command as ``polygons``, a `PolygonFiles`.

    Parameters
    ----------
    src_help, dst_help : str
        The help of --src and --dst: what the files hold in this command.
    label_help : str
        The help of --src-label and --dst-label; ``{side}`` is ``src`` or ``dst``.
    """
    return collected(
        "polygons",
        PolygonFiles,
        click.option("--src", "src_path", required=True, type=click.Path(), help=src_help),
        click.option("--dst", "dst_path", required=True, type=click.Path(), help=dst_help),
        click.option("--src-label", help=label_help.format(side="src")),
        click.option("--dst-label", help=label_help.format(side="dst")),
    )


# --- the map: MapOptions ------------------------------------------------------------


def method_option(help_text: str) -> Callable:
    """--method, one of the registry's methods."""
    return click.option("--method", type=click.Choice(tuple(METHODS)), default="fem", show_default=True, help=help_text)


#: The help of --method that lists every method of the registry.
METHOD_HELP = "How the harmonic maps are computed: " + "; ".join(f"{k}: {v.help}" for k, v in METHODS.items()) + "."


def build_map_options(*, boundary: str | None, dst_boundary: str, **values: Any) -> MapOptions:
    """The `MapOptions` of map_options' values: --boundary, when given, sets the target's boundary."""
    return MapOptions(dst_boundary=dst_boundary if boundary is None else boundary, **values)


#: The options of how the map is built, handed to the command as ``mapping``, a `MapOptions`.
map_options = collected(
    "mapping",
    build_map_options,
    method_option(METHOD_HELP),
    click.option(
        "--theta",
        default="regular",
        show_default=True,
        metavar="|".join(THETAS) + "|FILE.json",
        help="The convex intermediate polygon: " + "; ".join(f"{k}: {v.help}" for k, v in THETAS.items())
        + "; or a JSON file of n [x, y] vertices, strictly convex (as --save-theta writes).",
    ),
    click.option(
        "--boundary",
        type=click.Choice(BOUNDARIES),
        help="Boundary behaviour of DST (the paper's 5.2): the point at parameter t of an edge goes to t (linear) or t^2 "
        "(quadratic) along Theta's edge.  [default: linear]",
    ),
    click.option("--src-boundary", type=click.Choice(BOUNDARIES), default="linear", show_default=True, help="Boundary behaviour of SRC."),
    click.option("--dst-boundary", type=click.Choice(BOUNDARIES), default="linear", show_default=True, help="Boundary behaviour of DST (--boundary sets it)."),
    click.option("--energy", type=click.Choice(ENERGIES), default="conformal", show_default=True, help="What --theta optimized lowers: the mean distortion over the source, or (max-) a smooth stand-in for its maximum (the mean of its 8th power, to the 1/8)."),
    click.option("--theta-start", type=click.Choice(("regular", "cyclic")), default="regular", show_default=True, help="--theta optimized starts from both; this one is the report's 'before'."),
    click.option("--nodes", type=click.IntRange(3, 100_000), help="BEM/MFS: boundary nodes (BEM) or sites (MFS), m, from n (the vertices) to what memory allows.  [default: max(256, 8 n), at most 2048]"),
    click.option(
        "--conditions",
        type=click.Choice(CONDITIONS),
        default="dirichlet",
        show_default=True,
        help="EXPERIMENTAL mixed: quadrilaterals onto the unit square with natural boundary conditions (the paper's 5.2); "
        "edges still go onto edges, sliding along them; every result is checked for fold-overs.",
    ),
    click.option(
        "--max-area",
        default="auto",
        show_default=True,
        callback=parse_max_area,
        metavar="PX2|auto",
        help="Largest mesh triangle area in square pixels; 1 is the paper's pixel density; auto keeps the map within ~0.02 px (mean) of a 4x finer mesh, much faster.",
    ),
    click.option(
        "--weights",
        type=click.Choice(WEIGHTS),
        default="cotan",
        show_default=True,
        help="Laplacian weights: cotan solves the harmonic maps; positive (mean-value) is one-to-one on any mesh but not harmonic.",
    ),
)  # fmt: skip


# --- the resampling: WarpOptions ---------------------------------------------------


def interp_option(f: Callable) -> Callable:
    """--interp, the resampling filter."""
    return click.option(
        "--interp", type=click.Choice(INTERPOLATIONS), default="linear", show_default=True, help="Resampling filter."
    )(f)


def background_option(help_text: str) -> Callable:
    """--background, one value or one per channel."""
    return click.option(
        "--background", default="0", show_default=True, callback=parse_background, metavar="V[,V...]", help=help_text
    )


def dtype_option(f: Callable) -> Callable:
    """--dtype, the output pixel type."""
    return click.option(
        "--dtype",
        type=click.Choice(DTYPES),
        help="Output pixel type (values keep their meaning: integer types span 0..1).  [default: INPUT's]",
    )(f)


def compression_option(f: Callable) -> Callable:
    """--compression, the zlib level of PNG outputs."""
    return click.option(
        "--compression",
        type=click.IntRange(0, 9),
        metavar="0-9",
        help="PNG outputs: zlib level, 0 (fastest to write, largest) to 9 (smallest, slowest); the pixels are "
        f"the same at every level.  [default: {PNG_COMPRESSION}, as OpenCV]",
    )(f)


#: The options of how the image is resampled, handed to the command as
#: ``resampling``, a `WarpOptions` whose map is the default one.
def _resampling(**values: Any) -> WarpOptions:
    """`WarpOptions` from the options' values; ``--within`` with ``--outside background`` given is refused."""
    if values.get("within") is not None and values.get("outside") == "background":
        source = click.get_current_context().get_parameter_source("outside")
        if source is not None and source.name == "COMMANDLINE":
            raise click.UsageError("--within keeps the input outside the outline: it takes no --outside background")
    return WarpOptions(**values)


resample_options = collected(
    "resampling",
    _resampling,
    interp_option,
    click.option("--size", callback=parse_size, metavar="WxH", help="Output size in pixels.  [default: INPUT's size]"),
    dtype_option,
    compression_option,
    background_option("Value of pixels outside DST: one for all channels or one per channel, 0..1 for integer images."),
    click.option(
        "--antialias/--no-antialias",
        default=True,
        show_default=True,
        help="Smooth the target polygon's edge and, with linear, average each pixel over its footprint where the map shrinks.",
    ),
    click.option(
        "--outside",
        type=click.Choice(("background", "input")),
        default="background",
        show_default=True,
        help="Outside DST: the background, or the input with the warped region pasted over it (the output keeps INPUT's size).",
    ),
    click.option(
        "--vacated",
        type=click.Choice(("keep", "background")),
        default="keep",
        show_default=True,
        help="With --outside input: the part of SRC that DST leaves uncovered keeps the input, or shows the background.",
    ),
    click.option(
        "--feather",
        type=click.FloatRange(min=0.0),
        default=0.0,
        show_default=True,
        metavar="PX",
        help="With --outside input: blend the warp into the input over a band PX pixels wide inside DST's edge "
        "(smoothstep of the distance), a cosmetic blend; --within is the seamless choice.",
    ),
    click.option(
        "--within",
        metavar="image|MARGIN|FILE.json",
        help="A retouch within a fixed outline: the whole image, the cages' box grown by MARGIN pixels, or a "
        "polygon file. The outline stays, SRC's cages move onto DST's and the ring between is mapped too: no "
        "seam, nothing vacated; the input is kept outside the outline (--outside input implied). SRC and DST may "
        "hold several cages (labelme/GeoJSON polygons that do not share edges, or {\"cages\": [...]}).",
    ),
)  # fmt: skip


# --- what is printed ------------------------------------------------------------------


def configure_logging(verbose: int = 0, quiet: bool = False) -> None:
    """warpcli's log on stderr as ``warp: ...`` lines: warnings, with -v progress, with -vv details, with -q errors only."""
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("warp: %(message)s"))
    log = logging.getLogger("warpcli")
    log.handlers[:] = [handler]
    log.setLevel(level)
    log.propagate = False


_quiet = click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")

#: -v/--verbose and -q/--quiet; the log is set up before the command runs.
verbosity = collected(
    None,
    configure_logging,
    click.option("-v", "--verbose", count=True, help="Report progress and timings on stderr (-vv for more)."),
    _quiet,
)

#: -q/--quiet alone, for the commands that report no progress; the log is set up before the command runs.
quiet_option = collected(None, configure_logging, _quiet)


# --- how many cores -------------------------------------------------------------------


def _set_jobs(ctx, param, value):
    """The run's core budget (`warpcli.cores`), set as soon as the option is read: every
    thread pool of the run, the libraries' included, is sized by it."""
    from ..cores import set_jobs

    set_jobs(value)
    return value


def jobs_option(what: str, *, expose_value: bool = True) -> Callable:
    """``--jobs N``: the cores the command may keep busy (`warpcli.cores`); ``what`` says what runs on them."""
    return click.option(
        "--jobs",
        "jobs",
        type=click.IntRange(1, 256),
        default=None,
        metavar="N",
        callback=_set_jobs,
        expose_value=expose_value,
        help=f"The cores this run may keep busy: {what}. 1: one core, no threads or child processes (OpenImageIO's "
        "and BLAS's pools too). Output bytes as with any other N.  [default: the cores this process may use]",
    )
