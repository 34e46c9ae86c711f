"""Command-line interface: click commands and nothing else."""

from __future__ import annotations

import json
import logging
import sys
import threading
import time

import click

from . import __version__

EXIT_CODES = """\b
Exit status:
  0  success
  1  failure while processing (for example a write error)
  2  bad input or usage (unreadable or invalid polygon, image or option)
"""

_INTERPS = ("nearest", "linear", "cubic")


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


@click.command(
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    epilog=EXIT_CODES,
)
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=True))
@click.argument("output_path", metavar="OUTPUT", type=click.Path(dir_okay=True))
@click.option("--src", "src_path", required=True, type=click.Path(), help="Source polygon file (JSON), in INPUT's pixel coordinates.")
@click.option("--dst", "dst_path", required=True, type=click.Path(), help="Target polygon file (JSON), in OUTPUT's pixel coordinates.")
@click.option("--interp", type=click.Choice(_INTERPS), default="linear", show_default=True, help="Resampling filter.")
@click.option("--size", callback=_parse_size, metavar="WxH", help="Output size in pixels.  [default: INPUT's size]")
@click.option(
    "--background",
    default="0",
    show_default=True,
    callback=_parse_background,
    metavar="V[,V...]",
    help="Value of pixels outside DST: one for all channels or one per channel, 0..1 for integer images.",
)
@click.option(
    "--max-area",
    default="auto",
    show_default=True,
    callback=_parse_max_area,
    metavar="PX2|auto",
    help="Largest mesh triangle area in square pixels; 1 is the paper's pixel density, auto keeps the map within ~0.01 px of it, faster.",
)
@click.option(
    "--weights",
    type=click.Choice(("cotan", "positive")),
    default="cotan",
    show_default=True,
    help="Laplacian weights: cotan solves the harmonic maps; positive (mean-value) is one-to-one on any mesh but not harmonic.",
)
@click.option("--report", "report_path", type=click.Path(dir_okay=False, allow_dash=True), help="Write a JSON report (mesh sizes, fold-overs, Jacobian, distortion, timings); - for stdout.")
@click.option("--grid", "grid_path", type=click.Path(dir_okay=False), help="Write the input with a grid beside the output with the grid carried through the map.")
@click.option("--heatmap", "heatmap_path", type=click.Path(dir_okay=False), help="Write the per-pixel distortion of the map in colour, with a legend.")
@click.option(
    "--heatmap-measure",
    type=click.Choice(("conformal", "isometric", "det")),
    default="conformal",
    show_default=True,
    help="What --heatmap shows.",
)
@click.option("-v", "--verbose", count=True, help="Report progress and timings on stderr (-vv for more).")
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")
@click.version_option(__version__, "--version", prog_name="warp")
def warp(
    input_path, output_path, src_path, dst_path, interp, size, background, max_area, weights,
    report_path, grid_path, heatmap_path, heatmap_measure, verbose, quiet,
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
    """
    _configure_logging(verbose, quiet)
    from .pipeline import warp_file

    with Progress(sys.stderr, enabled=not quiet) as progress:
        result = warp_file(
            input_path,
            output_path,
            src_path,
            dst_path,
            size=size,
            interp=interp,
            background=background,
            max_area=max_area,
            weights=weights,
            report_path=report_path,
            grid_path=grid_path,
            heatmap_path=heatmap_path,
            heatmap_measure=heatmap_measure,
            progress=progress.stage,
        )
    if report_path == "-":
        click.echo(json.dumps(result.report, indent=2))
    log = logging.getLogger("warpcli")
    for stage, seconds in result.timings.items():
        log.info("%-9s %7.3f s", stage, seconds)
    log.debug(
        "source mesh %d vertices, target mesh %d vertices",
        result.map.phi0.mesh.n_vertices,
        result.map.phi1.mesh.n_vertices,
    )


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


def main(argv: list[str] | None = None) -> int:
    """Run the ``warp`` command; return its exit status instead of raising."""
    from .errors import WarpError

    try:
        warp.main(args=argv, prog_name="warp", standalone_mode=False)
    except click.exceptions.Exit as done:  # --help, --version
        return done.exit_code
    except click.ClickException as err:
        click.echo(f"warp: error: {err.format_message()} (see 'warp --help')", err=True)
        return err.exit_code
    except click.exceptions.Abort:
        click.echo("warp: interrupted", err=True)
        return 130
    except WarpError as err:
        click.echo(f"warp: error: {err}", err=True)
        return err.exit_code
    except KeyboardInterrupt:
        click.echo("warp: interrupted", err=True)
        return 130
    return 0


def run() -> None:
    """Console-script entry point."""
    sys.exit(main())
