"""Command-line interface: click commands and nothing else."""

from __future__ import annotations

import json
import logging
import sys
import threading
import time

import click

from . import __version__
from .errors import InputError, WarpError
from .maps.registry import METHODS, THETAS
from .options import BOUNDARIES, CONDITIONS, DTYPES, ENERGIES, HEATMAP_MEASURES, INTERPOLATIONS, STMAP_T, WEIGHTS

#: Exit statuses; decided here and nowhere else.
EXIT_OK, EXIT_FAILURE, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143

EXIT_CODES = """\b
Exit status:
  0    success (in a batch: every input)
  1    failure while processing (for example a write error)
  2    bad input or usage (unreadable or invalid polygon, image or option)
  130  interrupted (Ctrl-C); 143: terminated (SIGTERM); nothing is left behind
"""

WARP_EPILOG = EXIT_CODES + """
\b
Also: warp apply-map MAP.exr INPUT OUTPUT applies a saved map; warp points maps points and OBJ UVs
(see warp apply-map --help, warp points --help).
"""

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


def exit_code(err: WarpError) -> int:
    """The exit status for an error: 2 for bad input, 1 for a failure while processing."""
    return EXIT_BAD_INPUT if isinstance(err, InputError) else EXIT_FAILURE


def _parse_size(ctx, param, value):
    if value is None:
        return None
    try:
        w, h = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected WIDTHxHEIGHT such as 640x480, got {value!r}") from None
    if w <= 0 or h <= 0:
        raise click.BadParameter(f"width and height must be positive, got {value!r}")
    return w, h


def _parse_background(ctx, param, value):
    try:
        vals = [float(v) for v in value.split(",")]
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {value!r}") from None
    if not all(v == v and abs(v) != float("inf") for v in vals):
        raise click.BadParameter(f"values must be finite, got {value!r}")
    return vals


def _parse_max_area(ctx, param, value):
    if value is None or value == "auto":
        return None
    try:
        area = float(value)
    except ValueError:
        raise click.BadParameter(f"expected 'auto' or a positive number, got {value!r}") from None
    if not (area > 0 and area != float("inf")):
        raise click.BadParameter(f"must be positive and finite, got {value!r}")
    return area


def interp_option(f):
    return click.option(
        "--interp", type=click.Choice(INTERPOLATIONS), default="linear", show_default=True, help="Resampling filter."
    )(f)


def background_option(help_text: str):
    return click.option(
        "--background", default="0", show_default=True, callback=_parse_background, metavar="V[,V...]", help=help_text
    )


def dtype_option(f):
    return click.option(
        "--dtype",
        type=click.Choice(DTYPES),
        help="Output pixel type (values keep their meaning: integer types span 0..1).  [default: INPUT's]",
    )(f)


def quiet_option(f):
    return click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")(f)


class _Command(click.Command):
    """A command whose usage line reads "warp ..." also when it is the group's default."""

    def format_usage(self, ctx, formatter):
        formatter.write_usage(ctx.command_path.strip(), " ".join(self.collect_usage_pieces(ctx)))


class DefaultGroup(click.Group):
    """A group whose first argument is a subcommand's name, or else the default command's."""

    def __init__(self, *args, default: str, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.default = default

    def parse_args(self, ctx, args):
        if not (args and args[0] in self.commands):
            args = [self.default, *args]
        return super().parse_args(ctx, args)

    def resolve_command(self, ctx, args):
        name, cmd, rest = super().resolve_command(ctx, args)
        # The default command's usage and messages read "warp ...", not "warp warp ...".
        return ("" if name == self.default else name), cmd, rest


@click.command(cls=_Command, context_settings=CONTEXT, epilog=WARP_EPILOG)
@click.argument("paths", metavar="INPUT OUTPUT | INPUT... --out-dir DIR", nargs=-1, type=click.Path(dir_okay=True))
@click.option("--src", "src_path", required=True, type=click.Path(), help="Source polygon file (JSON, labelme or GeoJSON), in INPUT's pixel coordinates.")
@click.option("--dst", "dst_path", required=True, type=click.Path(), help="Target polygon file (JSON, labelme or GeoJSON), in OUTPUT's pixel coordinates.")
@click.option("--src-label", help="Which polygon of a labelme or GeoJSON --src file holding several: its label, or #N for the N-th (from 0).")
@click.option("--dst-label", help="Which polygon of a labelme or GeoJSON --dst file holding several: its label, or #N for the N-th (from 0).")
@click.option(
    "--frames",
    metavar="SPEC",
    help="Image sequences: INPUT and OUTPUT are patterns (shot.#.exr: # is 4 digits, @ one, or %04d) and SPEC "
    "the frames: 1001-1100, 1-100x2, 1,5,10-12. Polygon files may hold keyframes; one map per distinct pair.",
)
@click.option("--inverse", is_flag=True, help="Undo the warp from SRC to DST: map DST onto SRC (the same polygon files, swapped).")
@click.option("--out-dir", type=click.Path(file_okay=False), help="Batch: every path is an INPUT, written to DIR/NAME with one map.")
@click.option("--scheduler", metavar="ADDRESS|local", help="Batch: run on a Dask cluster (tcp://host:8786), or 'local' for a LocalCluster of --jobs processes; the map is built here once and shipped. Needs warpcli[dask].")
@click.option("--jobs", type=click.IntRange(1, 256), default=1, show_default=True, help="Batch and sequences: images warped at once, by threads sharing the map (output bytes as with 1).")
@click.option("--out-name", default="{name}", show_default=True, help="Batch output file name: {name}, {stem}, {ext} of the input (the extension picks the format).")
@interp_option
@click.option("--size", callback=_parse_size, metavar="WxH", help="Output size in pixels.  [default: INPUT's size]")
@dtype_option
@background_option("Value of pixels outside DST: one for all channels or one per channel, 0..1 for integer images.")
@click.option(
    "--method",
    type=click.Choice(tuple(METHODS)),
    default="fem",
    show_default=True,
    help="How the harmonic maps are computed: " + "; ".join(f"{k}: {v.help}" for k, v in METHODS.items()) + ".",
)
@click.option(
    "--theta",
    default="regular",
    show_default=True,
    metavar="|".join(THETAS) + "|FILE.json",
    help="The convex intermediate polygon: " + "; ".join(f"{k}: {v.help}" for k, v in THETAS.items())
    + "; or a JSON file of n [x, y] vertices, strictly convex (as --save-theta writes).",
)
@click.option(
    "--boundary",
    type=click.Choice(BOUNDARIES),
    help="Boundary behaviour of DST (the paper's 5.2): the point at parameter t of an edge goes to t (linear) or t^2 "
    "(quadratic) along Theta's edge.  [default: linear]",
)
@click.option("--src-boundary", type=click.Choice(BOUNDARIES), default="linear", show_default=True, help="Boundary behaviour of SRC.")
@click.option("--dst-boundary", type=click.Choice(BOUNDARIES), default="linear", show_default=True, help="Boundary behaviour of DST (--boundary sets it).")
@click.option("--save-theta", type=click.Path(dir_okay=False), help="Write the Theta this run used as JSON (to reuse with --theta FILE.json).")
@click.option("--energy", type=click.Choice(ENERGIES), default="conformal", show_default=True, help="What --theta optimized lowers: the area-weighted mean distortion.")
@click.option("--theta-start", type=click.Choice(("regular", "cyclic")), default="regular", show_default=True, help="Where --theta optimized starts.")
@click.option("--nodes", type=click.IntRange(3, 100_000), help="BEM/MFS: boundary nodes (BEM) or sites (MFS), m.  [default: max(256, 8 n)]")
@click.option(
    "--conditions",
    type=click.Choice(CONDITIONS),
    default="dirichlet",
    show_default=True,
    help="EXPERIMENTAL mixed: quadrilaterals onto the unit square with natural boundary conditions (the paper's 5.2); "
    "edges still go onto edges, sliding along them; every result is checked for fold-overs.",
)
@click.option(
    "--max-area",
    default="auto",
    show_default=True,
    callback=_parse_max_area,
    metavar="PX2|auto",
    help="Largest mesh triangle area in square pixels; 1 is the paper's pixel density; auto keeps the map within ~0.02 px (mean) of a 4x finer mesh, much faster.",
)
@click.option(
    "--antialias/--no-antialias",
    default=True,
    show_default=True,
    help="Smooth the target polygon's edge and, with linear, average each pixel over its footprint where the map shrinks.",
)
@click.option(
    "--outside",
    type=click.Choice(("background", "input")),
    default="background",
    show_default=True,
    help="Outside DST: the background, or the input with the warped region pasted over it (the output keeps INPUT's size).",
)
@click.option(
    "--vacated",
    type=click.Choice(("keep", "background")),
    default="keep",
    show_default=True,
    help="With --outside input: the part of SRC that DST leaves uncovered keeps the input, or shows the background.",
)
@click.option(
    "--weights",
    type=click.Choice(WEIGHTS),
    default="cotan",
    show_default=True,
    help="Laplacian weights: cotan solves the harmonic maps; positive (mean-value) is one-to-one on any mesh but not harmonic.",
)
@click.option("--report", "report_path", type=click.Path(dir_okay=False, allow_dash=True), help="Write a JSON report (mesh sizes, fold-overs, Jacobian, distortion, timings); - for stdout.")
@click.option("--grid", "grid_path", type=click.Path(dir_okay=False), help="Write the input with a grid beside the output with the grid carried through the map.")
@click.option("--heatmap", "heatmap_path", type=click.Path(dir_okay=False), help="Write the per-pixel distortion of the map in colour, with a legend.")
@click.option(
    "--heatmap-measure",
    type=click.Choice(HEATMAP_MEASURES),
    default="conformal",
    show_default=True,
    help="What --heatmap shows.",
)
@click.option("--save-map", type=click.Path(dir_okay=False), help="Write the inverse map (output pixel -> input point) as an STMap, e.g. map.exr.")
@click.option("--save-forward-map", type=click.Path(dir_okay=False), help="Write the forward map (input pixel -> output point) as an STMap.")
@click.option(
    "--stmap-t",
    type=click.Choice(STMAP_T),
    default="down",
    show_default=True,
    help="Which way an STMap's t runs: down (OpenImageIO st_warp) or up (Nuke STMap).",
)
@click.option(
    "--tiled",
    is_flag=True,
    help="Warp in strips of 256 rows, never holding the whole image: the same output in bounded memory "
    "(automatic when the image does not fit in memory).",
)
@click.option("-v", "--verbose", count=True, help="Report progress and timings on stderr (-vv for more).")
@quiet_option
@click.version_option(__version__, "--version", prog_name="warp")
def warp(
    paths, src_path, dst_path, src_label, dst_label, frames, inverse, out_dir, scheduler, jobs, out_name, interp, size, dtype, background, method, theta,
    boundary, src_boundary, dst_boundary, save_theta, energy, theta_start, nodes, conditions, max_area, antialias, outside, vacated, weights, report_path,
    grid_path, heatmap_path, heatmap_measure, save_map, save_forward_map, stmap_t, tiled, verbose, quiet,
):  # fmt: skip
    """Warp INPUT so that polygon SRC goes onto polygon DST; write OUTPUT.

    The map is smooth and bijective (no fold-overs) and takes each edge of SRC
    onto the same edge of DST: vertex i of SRC goes to vertex i of DST.
    Coordinates are continuous pixel coordinates, x right and y down, the
    top-left corner of the image at (0, 0), so pixel (row r, column c) has
    its centre at (c + 0.5, r + 0.5). Image formats follow the file
    extensions (anything OpenImageIO reads and writes).

    \b
    Examples:
      warp face.png --src face.json --dst smile.json warped.png
      warp face.png --src face.json --dst smile.json warped.png --report - --grid grid.png
      warp frames/*.png --src a.json --dst b.json --out-dir warped/ -q
    """
    _configure_logging(verbose, quiet)
    from .options import MapOptions, WarpOptions

    if inverse:  # §6: moving the vertices back restores the image (to the map's accuracy)
        src_path, dst_path, src_label, dst_label = dst_path, src_path, dst_label, src_label
    if boundary is not None:
        dst_boundary = boundary
    options = WarpOptions(
        MapOptions(
            method=method, theta=theta, max_area=max_area, weights=weights, src_boundary=src_boundary,
            dst_boundary=dst_boundary, energy=energy, theta_start=theta_start, conditions=conditions, nodes=nodes,
        ),
        interp=interp, background=tuple(background), antialias=antialias, size=size, dtype=dtype,
        outside=outside, vacated=vacated,
    )  # fmt: skip
    single_only = {
        "--report": report_path, "--grid": grid_path, "--heatmap": heatmap_path,
        "--save-map": save_map, "--save-forward-map": save_forward_map, "--size": size, "--save-theta": save_theta,
        "--tiled": True if tiled else None,
    }  # fmt: skip
    used = [name for name, value in single_only.items() if value is not None]
    from .sequence import is_pattern

    if frames is not None or any(is_pattern(p) for p in paths):
        if out_dir is not None or scheduler is not None:
            raise click.UsageError("--frames takes an OUTPUT pattern, not --out-dir or --scheduler")
        if len(paths) != 2:
            raise click.UsageError(f"expected an INPUT and an OUTPUT pattern with --frames, got {len(paths)} path(s)")
        if used:
            raise click.UsageError(f"{', '.join(used)} applies to a single warp, not to a sequence")
        _sequence(paths, frames, src_path, dst_path, src_label, dst_label, options, jobs)
        return
    if out_dir is not None:
        if used:
            raise click.UsageError(f"{', '.join(used)} applies to a single warp, not to --out-dir")
        if not paths:
            raise click.UsageError("no INPUT given")
        _batch(paths, out_dir, out_name, src_path, dst_path, src_label, dst_label, options, jobs, scheduler)
        return
    if scheduler is not None:
        raise click.UsageError("--scheduler runs a batch: give --out-dir DIR")
    if len(paths) != 2:
        raise click.UsageError(f"expected INPUT and OUTPUT (or INPUTs with --out-dir DIR), got {len(paths)} path(s)")
    input_path, output_path = paths
    from .pipeline import warp_file

    with Progress(sys.stderr, enabled=not quiet) as progress:
        result = warp_file(
            input_path,
            output_path,
            src_path,
            dst_path,
            options,
            src_label=src_label,
            dst_label=dst_label,
            save_map=save_map,
            save_forward_map=save_forward_map,
            stmap_t_up=stmap_t == "up",
            report_path=report_path,
            save_theta=save_theta,
            grid_path=grid_path,
            heatmap_path=heatmap_path,
            heatmap_measure=heatmap_measure,
            progress=progress.stage,
            tiled=True if tiled else None,
        )
    if report_path == "-":
        click.echo(json.dumps(result.report, indent=2))
    log = logging.getLogger("warpcli")
    for stage, seconds in result.timings.items():
        log.info("%-9s %7.3f s", stage, seconds)
    for key, value in result.map.describe().items():
        log.debug("%s: %s", key.replace("_", " "), value)


def _sequence(paths, frames, src_path, dst_path, src_label, dst_label, options, jobs=1):
    """Warp the frames of a sequence; report failed frames one line each and go on."""
    from .errors import InputError
    from .batch import warp_sequence
    from .sequence import is_pattern, missing_frames_error, parse_frames

    if frames is None:
        raise missing_frames_error(paths[0])
    for path in paths:
        if not is_pattern(path):
            raise InputError(f"{path}: with --frames, INPUT and OUTPUT are sequence patterns (shot.#.exr, shot.%04d.exr)")
    items = warp_sequence(
        paths[0], paths[1], parse_frames(frames), src_path, dst_path, options, src_label=src_label,
        dst_label=dst_label, on_item=_report_item, jobs=jobs,
    )  # fmt: skip
    _exit_for(items, "frames")


def _batch(paths, out_dir, out_name, src_path, dst_path, src_label, dst_label, options, jobs=1, scheduler=None):
    """Warp every input with one map; report failures one line each and go on."""
    if scheduler is not None:
        from .distributed import warp_batch_dask

        items = warp_batch_dask(
            list(paths), out_dir, src_path, dst_path, options, scheduler=scheduler, pattern=out_name,
            src_label=src_label, dst_label=dst_label, on_item=_report_item, workers=jobs,
        )  # fmt: skip
        _exit_for(items, "inputs")
        return
    from .batch import warp_batch

    items = warp_batch(
        list(paths), out_dir, src_path, dst_path, options, pattern=out_name, src_label=src_label,
        dst_label=dst_label, on_item=_report_item, jobs=jobs,
    )  # fmt: skip
    _exit_for(items, "inputs")


def _report_item(item) -> None:
    """One line per failed input (always), one per written output (with -v)."""
    if item.error is None:
        logging.getLogger("warpcli").info("wrote %s", item.output_path)
    else:
        click.echo(f"warp: error: {item.error}", err=True)


def _exit_for(items, what: str) -> None:
    """Batch exit status: the worst failure's, after every item was tried."""
    failed = [item for item in items if item.error is not None]
    if failed:
        logging.getLogger("warpcli").warning("%d of %d %s failed", len(failed), len(items), what)
        raise click.exceptions.Exit(max(exit_code(item.error) for item in failed))


@click.command("apply-map", context_settings=CONTEXT, epilog=EXIT_CODES)
@click.argument("map_path", metavar="MAP", type=click.Path())
@click.argument("input_path", metavar="INPUT", type=click.Path())
@click.argument("output_path", metavar="OUTPUT", type=click.Path())
@interp_option
@background_option("Value of pixels where the map is undefined.")
@dtype_option
@click.option(
    "--stmap-t",
    type=click.Choice(("auto", *STMAP_T)),
    default="auto",
    show_default=True,
    help="Which way the map's t runs; auto: as its header says (warpcli writes it), else down.",
)
@quiet_option
def apply_map(map_path, input_path, output_path, interp, background, dtype, stmap_t, quiet):
    """Warp INPUT with a map saved by warp --save-map (or any STMap); write OUTPUT.

    MAP holds, for each OUTPUT pixel, the normalized point (s, t) of INPUT it
    comes from (OpenImageIO st_warp's convention); OUTPUT has MAP's size.

    \b
    Example:
      warp apply-map map.exr frame_0002.png warped_0002.png
    """
    _configure_logging(0, quiet)
    from .options import WarpOptions
    from .pipeline import apply_map_file

    t_up = None if stmap_t == "auto" else stmap_t == "up"
    options = WarpOptions(interp=interp, background=tuple(background), dtype=dtype)
    apply_map_file(map_path, input_path, output_path, options, t_up=t_up)


@click.command("points", context_settings=CONTEXT, epilog=EXIT_CODES)
@click.argument("input_path", metavar="IN", type=click.Path())
@click.argument("output_path", metavar="OUT", type=click.Path())
@click.option("--src", "src_path", required=True, type=click.Path(), help="Source polygon file.")
@click.option("--dst", "dst_path", required=True, type=click.Path(), help="Target polygon file.")
@click.option("--src-label", help="Which polygon of a --src file holding several (a label or #N).")
@click.option("--dst-label", help="Which polygon of a --dst file holding several (a label or #N).")
@click.option("--inverse", is_flag=True, help="Map target points back to the source.")
@click.option("--method", type=click.Choice(tuple(METHODS)), default="fem", show_default=True, help="How the harmonic maps are computed (bem and mfs are smooth).")
@click.option("--texture-size", callback=_parse_size, metavar="WxH", help="OBJ: the texture's size in pixels (the polygons' units).")
@click.option("--outside", type=click.Choice(("keep", "error")), default="keep", show_default=True, help="Points outside the polygon: left as they are (with a warning), or an error.")
@quiet_option
def points(input_path, output_path, src_path, dst_path, src_label, dst_label, inverse, method, texture_size, outside, quiet):
    """Map points (JSON, CSV x,y, or an OBJ's vt texture coordinates) from SRC's coordinates to DST's.

    An OBJ keeps every line but its vt lines byte for byte: a mesh's UVs move
    from one texture layout (polygon SRC) to another (DST), the paper's 4.2.

    \b
    Example:
      warp points --src layout_a.json --dst layout_b.json --texture-size 2048x2048 head.obj head_b.obj
    """
    _configure_logging(0, quiet)
    from .options import MapOptions
    from .points import map_points_file

    map_points_file(
        input_path, output_path, src_path, dst_path, MapOptions(method=method), inverse=inverse,
        texture_size=texture_size, outside=outside, src_label=src_label, dst_label=dst_label,
    )  # fmt: skip


@click.command("volume", context_settings=CONTEXT, epilog=EXIT_CODES)
@click.argument("input_path", metavar="IN", type=click.Path())
@click.argument("output_path", metavar="OUT", type=click.Path())
@click.option("--src", "src_path", required=True, type=click.Path(), help="Source cage: a closed genus-0 triangle or quad mesh (OBJ, OFF, PLY).")
@click.option("--dst", "dst_path", required=True, type=click.Path(), help="Target cage, the same connectivity: vertex i of SRC goes to vertex i of DST.")
@click.option("--theta", default="auto", show_default=True, metavar="auto|source|target|sphere|FILE", help="The convex intermediate polyhedron: auto takes a convex cage if either is one, else a certified spherical parameterization; or a convex mesh with the same connectivity.")
@click.option("--interp", "interpolation", type=click.Choice(("linear", "nearest")), default="linear", show_default=True, help="Trilinear or nearest-voxel resampling.")
@click.option("--background", default=0.0, show_default=True, type=float, help="Value of voxels outside DST (in the volume's stored units).")
@click.option("--edge", type=click.FloatRange(min=0, min_open=True), help="Tetrahedron edge length in the cages' units.  [default: from each cage's size and the voxel size]")
@click.option("--untangle/--no-untangle", default=True, show_default=True, help="Move interior nodes of inverted tetrahedra to where their stars keep their orientation (the boundary stays); --no-untangle keeps the discrete harmonic maps as solved.")
@click.option("--allow-folds", is_flag=True, help="Write the volume even if a tetrahedron stays inverted after untangling (with a warning); by default such a map is refused, exit 1, nothing written: in 3D no theorem rules folds out.")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), help="Write a JSON report: flipped tetrahedra before and after untangling, 3D distortion, min det J, timings.")
@click.option("--picture", type=click.Path(dir_okay=False), help="Write three orthogonal slices of input and output with a grid carried through the map (PNG).")
@quiet_option
def volume(input_path, output_path, src_path, dst_path, theta, interpolation, background, edge, untangle, allow_folds, report_path, picture, quiet):
    """Warp a 3D image (NIfTI .nii/.nii.gz, or a multi-page TIFF stack) so that cage SRC goes onto cage DST.

    The paper's 5.3: both solids are mapped harmonically onto one convex
    polyhedron Theta (tetrahedral FEM) and composed. NIfTI cages are in world
    coordinates (mm, through the header's affine); TIFF cages in voxel
    coordinates, voxel (i, j, k) centred at (i + 0.5, j + 0.5, k + 0.5). The
    output keeps the input's format, grid and data type. Needs
    pip install 'warpcli[volume]'.

    \b
    Example:
      warp volume ct.nii.gz --src cube.obj --dst bent.obj ct_bent.nii.gz --report r.json
    """
    _configure_logging(0, quiet)
    from .volume import warp_volume_file

    warp_volume_file(
        input_path, output_path, src_path, dst_path, theta=theta, interpolation=interpolation,
        background=background, edge=edge, untangle=untangle, check=not allow_folds, report=report_path, picture=picture,
    )  # fmt: skip


class Progress:
    """A one-line stage display on stderr for runs longer than ``delay`` seconds.

    Shown only when the stream is a terminal (never in scripts or logs) and
    not with -q; the line is cleared when the run ends.
    """

    def __init__(self, stream, *, enabled: bool = True, delay: float = 1.0, interval: float = 0.2) -> None:
        self._stream = stream
        self._enabled = enabled and _isatty(stream)
        self._delay = delay
        self._interval = interval
        self._stage = "starting"
        self._shown = False
        self._start = 0.0
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    def stage(self, name: str) -> None:
        self._stage = name

    def __enter__(self) -> Progress:
        if self._enabled:
            self._start = time.monotonic()
            self._thread = threading.Thread(target=self._run, name="warp-progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        if self._thread is not None:
            self._done.set()
            self._thread.join()
            if self._shown:
                self._stream.write("\r\x1b[K")
                self._stream.flush()

    def _run(self) -> None:
        if self._done.wait(self._delay):
            return
        while True:
            elapsed = time.monotonic() - self._start
            self._stream.write(f"\r\x1b[Kwarp: {self._stage}... {elapsed:.1f} s")
            self._stream.flush()
            self._shown = True
            if self._done.wait(self._interval):
                return


def _isatty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def _configure_logging(verbose: int, quiet: bool) -> None:
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("warp: %(message)s"))
    log = logging.getLogger("warpcli")
    log.handlers[:] = [handler]
    log.setLevel(level)
    log.propagate = False


cli = DefaultGroup(
    "warp", commands={"warp": warp, "apply-map": apply_map, "points": points, "volume": volume}, default="warp", context_settings=CONTEXT
)


class Terminated(BaseException):
    """SIGTERM arrived: unwind like Ctrl-C, so that no temporary file stays behind."""


def _terminate(signum, frame):
    raise Terminated()


def main(argv: list[str] | None = None) -> int:
    """Run the ``warp`` command; return its exit status instead of raising."""
    import signal
    import warnings

    # SIGTERM (a job scheduler, `kill`) is handled like Ctrl-C: outputs are
    # written to temporary files and renamed at the end, and unwinding removes them.
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate)
    # Nothing but warpcli's own lines on stderr: numpy's and other libraries'
    # warnings are not for the user of a command-line tool.
    warnings.simplefilter("ignore")
    args = list(sys.argv[1:] if argv is None else argv)
    prog = f"warp {args[0]}" if args[:1] in (["apply-map"], ["points"], ["volume"]) else "warp"
    if not args:
        ctx = warp.make_context("warp", ["--help"], resilient_parsing=True)
        click.echo(warp.get_usage(ctx), err=True)
        click.echo("Try 'warp --help' for help; 'warp apply-map --help' for saved maps.", err=True)
        return EXIT_BAD_INPUT
    try:
        # Without standalone mode click returns an Exit's code instead of raising it.
        code = cli.main(args=args, prog_name="warp", standalone_mode=False)
    except click.exceptions.Exit as done:  # --help, --version, a batch's status
        return done.exit_code
    except click.ClickException as err:
        click.echo(f"warp: error: {err.format_message()} (see '{prog} --help')", err=True)
        return EXIT_BAD_INPUT if err.exit_code == 2 else err.exit_code
    except (click.exceptions.Abort, KeyboardInterrupt):
        click.echo("warp: interrupted", err=True)
        return EXIT_INTERRUPTED
    except Terminated:
        click.echo("warp: terminated", err=True)
        return EXIT_TERMINATED
    except WarpError as err:
        click.echo(f"warp: error: {err}", err=True)
        return exit_code(err)
    return code if isinstance(code, int) else EXIT_OK


def run() -> None:
    """Console-script entry point."""
    code = main()
    _exit_now(code)
    sys.exit(code)


def _exit_now(code: int) -> None:
    """End the process without the interpreter's teardown, once the work is done.

    Python's finalization frees every module and object one by one: about
    35 ms after a 1-megapixel warp, a twentieth of the run, for memory the OS
    takes back at once anyway. So the exit handlers run (logging, temporary
    files, whatever a library registered), the standard streams are flushed,
    and the process ends with ``os._exit``. Not while another thread runs that
    may still matter: then Python's own exit waits for it, as usual. Work
    nobody waits for any more (``warpcli_task`` threads: the map of a run that
    bad input stopped) is dropped.
    """
    import atexit
    import os

    for t in threading.enumerate():
        if t is not threading.main_thread() and t.is_alive() and not t.daemon and not getattr(t, "warpcli_task", False):
            return
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):
            code = code or 120  # what Python's own exit reports for a stream it cannot flush
    os._exit(code)
