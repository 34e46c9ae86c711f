"""The ``warp`` command: one image, a batch (on threads or Dask) or a sequence, each with one map."""

from __future__ import annotations

import dataclasses
import json
import logging
import sys
from typing import NamedTuple

import click

from .. import __version__
from ..options import HEATMAP_MEASURES, STMAP_T
from .exits import EXIT_CODES, EXIT_FAILURE, exit_code
from .group import DefaultCommand
from .options import CONTEXT, collected, jobs_option, map_options, polygon_options, resample_options, verbosity
from .progress import Progress

WARP_EPILOG = EXIT_CODES + """
\b
Also: warp apply-map MAP.exr INPUT OUTPUT applies a saved map; warp points maps points and OBJ UVs;
warp texture SRC.obj DST.obj OUT.png moves a texture between two meshes' UV charts;
warp edit IMAGE draws the polygons in the browser (see warp apply-map --help, warp points --help,
warp texture --help, warp edit --help).
"""


class SingleOutputs(NamedTuple):
    """What a single warp writes besides OUTPUT, and how: the options that apply to one image only.

    A named tuple, as `warpcli.cli.options.PolygonFiles` is, for ``warp --help``'s speed.

    Parameters
    ----------
    save_theta, report_path, grid_path, heatmap_path, save_map, save_forward_map : str or None
        Where to write Theta, the report (``-``: stdout), the grid and
        heatmap pictures, the inverse and forward STMaps; None: not written.
    heatmap_measure : str
        What the heatmap shows.
    stmap_t : {"down", "up"}
        Which way the STMaps' t runs.
    tiled : bool
        Warp in strips.
    labels : tuple of (str, str)
        Masks and label images to carry through the same map, each (input, output).
    """

    save_theta: str | None
    report_path: str | None
    grid_path: str | None
    heatmap_path: str | None
    heatmap_measure: str
    save_map: str | None
    save_forward_map: str | None
    stmap_t: str
    tiled: bool
    labels: tuple[tuple[str, str], ...] = ()


single_outputs = collected(
    "outputs",
    SingleOutputs,
    click.option("--save-theta", type=click.Path(dir_okay=False), help="Write the Theta this run used as JSON (to reuse with --theta FILE.json)."),
    click.option("--report", "report_path", type=click.Path(dir_okay=False, allow_dash=True), help="Write a JSON report (mesh sizes, fold-overs, Jacobian, distortion, timings); - for stdout."),
    click.option("--grid", "grid_path", type=click.Path(dir_okay=False), help="Write the input with a grid beside the output with the grid carried through the map."),
    click.option("--heatmap", "heatmap_path", type=click.Path(dir_okay=False), help="Write the per-pixel distortion of the map in colour, with a legend."),
    click.option(
        "--heatmap-measure",
        type=click.Choice(HEATMAP_MEASURES),
        default="conformal",
        show_default=True,
        help="What --heatmap shows.",
    ),
    click.option("--save-map", type=click.Path(dir_okay=False), help="Write the inverse map (output pixel -> input point) as an STMap, e.g. map.exr."),
    click.option("--save-forward-map", type=click.Path(dir_okay=False), help="Write the forward map (input pixel -> output point) as an STMap."),
    click.option(
        "--stmap-t",
        type=click.Choice(STMAP_T),
        default="down",
        show_default=True,
        help="Which way an STMap's t runs: down (OpenImageIO st_warp) or up (Nuke STMap).",
    ),
    click.option(
        "--tiled",
        is_flag=True,
        help="Warp in strips of 256 rows, never holding the whole image: the same output in bounded memory "
        "(automatic when the image does not fit in memory).",
    ),
    click.option(
        "--labels",
        nargs=2,
        multiple=True,
        type=click.Path(dir_okay=False),
        metavar="IN OUT",
        help="A mask or label image of INPUT, warped through the same map to OUT (nearest: labels never blended, "
        "0 outside the target), written with OUTPUT; repeat for more.",
    ),
)  # fmt: skip


@click.command(cls=DefaultCommand, context_settings=CONTEXT, epilog=WARP_EPILOG)
@click.argument("paths", metavar="INPUT OUTPUT | INPUT... --out-dir DIR", nargs=-1, type=click.Path(dir_okay=True))
@polygon_options(
    "Source polygon file (JSON, labelme or GeoJSON), in INPUT's pixel coordinates; or a cage mesh: "
    '{"vertices": [...], "faces": [[i, j, k, ...], ...]}, or several polygons sharing edges.',
    "Target polygon file (JSON, labelme or GeoJSON), in OUTPUT's pixel coordinates; or a cage mesh with SRC's faces.",
    "Which polygon of a labelme or GeoJSON --{side} file holding several: its label, or #N for the N-th (from 0).",
)
@click.option(
    "--frames",
    metavar="SPEC",
    help="Image sequences: INPUT and OUTPUT are patterns (shot.#.exr: # is 4 digits as in oiiotool, @ one, or %04d) "
    "and SPEC the frames: 1001-1100, 1-100x2, 1,5,10-12; without it, the frames of INPUT on disk. Polygon files may "
    "hold keyframes; one map per distinct pair. --save-map map.#.exr writes one STMap per frame.",
)
@click.option("--frame", "frame", type=int, metavar="N", help="Keyframed polygon files in a single warp: the polygons at frame N.")
@click.option("--inverse", is_flag=True, help="Undo the warp from SRC to DST: map DST onto SRC (the same polygon files, swapped).")
@click.option("--out-dir", type=click.Path(file_okay=False), help="Batch: every path is an INPUT, written to DIR/NAME with one map.")
@click.option("--scheduler", metavar="ADDRESS|local", help="Batch: run on a Dask cluster (tcp://host:8786), or 'local' for a LocalCluster of --jobs processes (default: the cores this process may use); the map is built here once and shipped; a scheduler silent for 10 s (WARPCLI_DASK_TIMEOUT) is an error. Needs warpcli[dask].")
@jobs_option("batch images and sequence frames warped N at a time (threads sharing a map; for animated polygons, processes building the next maps), the kernels on N threads")
@click.option("--out-name", default="{name}", show_default=True, help="Batch output file name: {name}, {stem}, {ext} of the input ({ext} with its dot: {stem}_warped{ext}; the extension picks the format).")
@resample_options
@map_options
@single_outputs
@verbosity
@click.version_option(__version__, "--version", prog_name="warp")
def warp(paths, polygons, frames, frame, inverse, out_dir, scheduler, jobs, out_name, resampling, mapping, outputs):  # fmt: skip
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
      warp face.png --src face.json --dst smile.json warped.png --labels seg.png seg_warped.png
      warp frames/*.png --src a.json --dst b.json --out-dir warped/ -q
    """
    if inverse:  # §6: moving the vertices back restores the image (to the map's accuracy)
        polygons = polygons.swapped()
    options = dataclasses.replace(resampling, map=mapping)
    single_only = {
        "--report": outputs.report_path, "--grid": outputs.grid_path, "--heatmap": outputs.heatmap_path,
        "--save-map": outputs.save_map, "--save-forward-map": outputs.save_forward_map, "--size": options.size,
        "--save-theta": outputs.save_theta, "--tiled": True if outputs.tiled else None,
        "--labels": outputs.labels or None,
    }  # fmt: skip
    used = [name for name, value in single_only.items() if value is not None]
    from ..sequence import is_pattern

    if frames is None and out_dir is None and len(paths) == 2 and _numbered(paths[1]) and not is_pattern(paths[0]):
        raise click.UsageError(
            f"{paths[1]}: OUTPUT is a sequence pattern but INPUT {paths[0]} is one image; "
            "give INPUT as a pattern too (with --frames), or OUTPUT as a file name"
        )
    if frames is not None or (out_dir is None and scheduler is None and _sequence_paths(paths)):
        if out_dir is not None or scheduler is not None:
            raise click.UsageError("--frames takes an OUTPUT pattern, not --out-dir or --scheduler")
        if frame is not None:
            raise click.UsageError("--frame N picks one frame of keyframed polygons for a single warp; a sequence takes each frame's")
        if len(paths) != 2:
            raise click.UsageError(f"expected an INPUT and an OUTPUT pattern with --frames, got {len(paths)} path(s)")
        per_frame = ("--save-map", "--save-forward-map")  # sequences write one map per frame
        if [name for name in used if name not in per_frame]:
            names = ", ".join(name for name in used if name not in per_frame)
            raise click.UsageError(f"{names} applies to a single warp, not to a sequence")
        _sequence(paths, frames, polygons, options, jobs, outputs)
        return
    if out_dir is not None:
        if used or frame is not None:
            raise click.UsageError(f"{', '.join(used + (['--frame'] if frame is not None else []))} applies to a single warp, not to --out-dir")
        if not paths:
            raise click.UsageError("no INPUT given")
        _batch(paths, out_dir, out_name, polygons, options, jobs, scheduler)
        return
    if scheduler is not None:
        raise click.UsageError("--scheduler runs a batch: give --out-dir DIR")
    if len(paths) != 2:
        raise click.UsageError(f"expected INPUT and OUTPUT (or INPUTs with --out-dir DIR), got {len(paths)} path(s)")
    _single(*paths, polygons, options, outputs, frame)


def _sequence_paths(paths) -> bool:
    """Whether paths given without --frames or --out-dir name a sequence: an INPUT
    pattern that is not itself an existing file (``photo@2x.png`` is a file name)."""
    import os

    from ..sequence import is_pattern

    return bool(paths) and is_pattern(paths[0]) and not os.path.isfile(paths[0])


def _numbered(path) -> bool:
    """Whether ``path`` is a sequence pattern by # or %d: ``@`` alone is common in file names (``icon@2x.png``)."""
    from ..sequence import parse_pattern

    found = parse_pattern(path)
    return found is not None and "@" not in found.wildcard.replace("#", "")


def _single(input_path, output_path, polygons, options, outputs, frame=None) -> None:
    """Warp one image, with the extra outputs asked for; log the timings (-v) and the map (-vv)."""
    from ..pipeline import warp_file

    log = logging.getLogger("warpcli")
    # The progress line is chatter like the log's warnings: -q silences both.
    with Progress(sys.stderr, enabled=log.isEnabledFor(logging.WARNING)) as progress:
        result = warp_file(
            input_path,
            output_path,
            polygons.src_path,
            polygons.dst_path,
            options,
            src_label=polygons.src_label,
            dst_label=polygons.dst_label,
            save_map=outputs.save_map,
            save_forward_map=outputs.save_forward_map,
            stmap_t_up=outputs.stmap_t == "up",
            report_path=outputs.report_path,
            save_theta=outputs.save_theta,
            grid_path=outputs.grid_path,
            heatmap_path=outputs.heatmap_path,
            heatmap_measure=outputs.heatmap_measure,
            progress=progress.stage,
            tiled=True if outputs.tiled else None,
            labels=outputs.labels,
            frame=frame,
            prefer_strips=True,
        )
    if outputs.report_path == "-":
        click.echo(json.dumps(result.report, indent=2))
    for stage, seconds in result.timings.items():
        log.info("%-9s %7.3f s", stage, seconds)
    for key, value in result.map.describe().items():
        log.debug("%s: %s", key.replace("_", " "), value)


def _sequence(paths, frames, polygons, options, jobs=None, outputs=None):
    """Warp the frames of a sequence; report failed frames one line each and go on."""
    from ..errors import InputError
    from ..batch import FrameMaps, warp_sequence
    from ..sequence import is_pattern

    for path in paths:
        if not is_pattern(path):
            raise InputError(f"{path}: with --frames, INPUT and OUTPUT are sequence patterns (shot.#.exr, shot.%04d.exr)")
    maps = None
    if outputs is not None and (outputs.save_map is not None or outputs.save_forward_map is not None):
        maps = FrameMaps(outputs.save_map, outputs.save_forward_map, outputs.stmap_t == "up")
    spec = frames_or_disk(frames, paths[0])
    with progress_for(spec) as progress:
        report = _MissingFrames(reporter(progress))
        items = warp_sequence(
            paths[0], paths[1], spec, polygons.src_path, polygons.dst_path, options, src_label=polygons.src_label,
            dst_label=polygons.dst_label, on_item=report, jobs=jobs, maps=maps,
        )  # fmt: skip
    report.summary()
    exit_for(items, "frames")


#: Missing frames of a sequence reported one line each before the rest are counted.
MISSING_SHOWN = 5


class _MissingFrames:
    """A sequence's item reporter, with the lines of missing frames after the first `MISSING_SHOWN` counted."""

    def __init__(self, report) -> None:
        self.report = report
        self.missing = 0

    def __call__(self, item) -> None:
        from ..batch import MissingFrameError

        if isinstance(item.error, MissingFrameError):
            self.missing += 1
            if self.missing > MISSING_SHOWN:
                return
        self.report(item)

    def summary(self) -> None:
        more = self.missing - MISSING_SHOWN
        if more > 0:
            click.echo(f"warp: error: ... and {more} more missing frame{'s' if more > 1 else ''}", err=True)


def _batch(paths, out_dir, out_name, polygons, options, jobs=None, scheduler=None):
    """Warp every input with one map; report failures one line each and go on."""
    if scheduler is not None:
        from ..distributed import warp_batch_dask

        items = warp_batch_dask(
            list(paths), out_dir, polygons.src_path, polygons.dst_path, options, scheduler=scheduler,
            pattern=out_name, src_label=polygons.src_label, dst_label=polygons.dst_label, on_item=report_item,
            workers=jobs,
        )  # fmt: skip
        exit_for(items, "inputs")
        return
    from ..batch import warp_batch

    with progress_for(paths, "inputs") as progress:
        items = warp_batch(
            list(paths), out_dir, polygons.src_path, polygons.dst_path, options, pattern=out_name,
            src_label=polygons.src_label, dst_label=polygons.dst_label, on_item=reporter(progress), jobs=jobs,
        )  # fmt: skip
    exit_for(items, "inputs")


def frames_or_disk(frames: str | None, pattern: str) -> tuple[int, ...]:
    """--frames SPEC, or without it the frames of the input pattern on disk (said in one line)."""
    from ..sequence import frames_from_disk, parse_frames

    if frames is not None:
        return parse_frames(frames)
    spec, message = frames_from_disk(pattern)
    logging.getLogger("warpcli").warning("%s", message)
    return spec


def progress_for(items, what: str = "frames") -> Progress:
    """The progress line of a sequence or batch: items done of the total, rate and time left (terminal only, not -q)."""
    log = logging.getLogger("warpcli")
    return Progress(sys.stderr, enabled=log.isEnabledFor(logging.WARNING), total=len(items), what=what)


def reporter(progress: Progress):
    """`report_item` under a progress line: the line is cleared before a message and counts the item."""

    def report(item) -> None:
        progress.clear()
        report_item(item)
        progress.item_done()

    return report


def report_item(item) -> None:
    """One line per failed input (always), one per written output (with -v)."""
    if item.error is None:
        logging.getLogger("warpcli").info("wrote %s", item.output_path)
    else:
        click.echo(f"warp: error: {item.error}", err=True)


def exit_for(items, what: str) -> None:
    """Batch exit status: the worst failure's, after every item was tried: 1 (a failure while
    processing) if any item had one, else 2 (bad input only)."""
    failed = [item for item in items if item.error is not None]
    if failed:
        logging.getLogger("warpcli").warning("%d of %d %s failed", len(failed), len(items), what)
        codes = {exit_code(item.error) for item in failed}
        raise click.exceptions.Exit(EXIT_FAILURE if EXIT_FAILURE in codes else max(codes))
