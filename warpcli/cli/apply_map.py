"""The ``warp apply-map`` command: an image, or a sequence of frames, warped with saved maps (STMaps)."""

from __future__ import annotations

import click

from ..options import MAP_SCALES, STMAP_T, WarpOptions
from .exits import EXIT_CODES
from .options import CONTEXT, background_option, collected, compression_option, dtype_option, interp_option, jobs_option, quiet_option


@click.command("apply-map", context_settings=CONTEXT, epilog=EXIT_CODES)
@click.argument("map_path", metavar="MAP", type=click.Path())
@click.argument("input_path", metavar="INPUT", type=click.Path())
@click.argument("output_path", metavar="OUTPUT", type=click.Path())
@collected(
    "resampling", WarpOptions, interp_option, background_option("Value of pixels where the map is undefined."), dtype_option,
    compression_option,
)  # fmt: skip
@click.option(
    "--stmap-t",
    type=click.Choice(("auto", *STMAP_T)),
    default="auto",
    show_default=True,
    help="Which way the map's t runs; auto: as its header says (warpcli writes it), else down.",
)
@click.option(
    "--frames",
    metavar="SPEC",
    help="Sequences: INPUT and OUTPUT are patterns (shot.#.exr), MAP a pattern (one map per frame) or one "
    "map for all; SPEC the frames (1001-1100); without it, the frames of INPUT on disk.",
)
@jobs_option("sequence frames warped N at a time, on threads, the kernels on N threads")
@click.option(
    "--map-scale",
    type=click.Choice(MAP_SCALES),
    default="refuse",
    show_default=True,
    help="INPUT of another size than MAP was made for: refuse it, or stretch MAP's coordinates to it.",
)
@quiet_option
def apply_map(map_path, input_path, output_path, resampling, stmap_t, frames, jobs, map_scale):
    """Warp INPUT with a map saved by warp --save-map (or any STMap); write OUTPUT.

    MAP holds, for each OUTPUT pixel, the normalized point (s, t) of INPUT it
    comes from (OpenImageIO st_warp's convention); OUTPUT has MAP's size.
    INPUT must have the size MAP was made for (unless --map-scale stretch).

    \b
    Examples:
      warp apply-map map.exr frame_0002.png warped_0002.png
      warp apply-map map.#.exr shot.#.exr out.#.exr --frames 1001-1024
      warp apply-map map.exr shot.#.exr out.#.exr
    """
    from ..sequence import is_pattern

    t_up = None if stmap_t == "auto" else stmap_t == "up"
    if frames is not None or is_pattern(input_path) or is_pattern(output_path):
        _sequence(map_path, input_path, output_path, resampling, t_up, frames, jobs, map_scale)
        return
    from ..pipeline import apply_map_file

    apply_map_file(map_path, input_path, output_path, resampling, t_up=t_up, map_scale=map_scale)


def _sequence(map_path, input_path, output_path, resampling, t_up, frames, jobs, map_scale="refuse") -> None:
    """Every frame through its map; failed frames one line each, the others go on."""
    from ..batch import apply_map_sequence
    from .warp import exit_for, frames_or_disk, progress_for, reporter

    spec = frames_or_disk(frames, input_path)
    with progress_for(spec) as progress:
        items = apply_map_sequence(
            map_path, input_path, output_path, spec, resampling, t_up=t_up, on_item=reporter(progress), jobs=jobs,
            map_scale=map_scale,
        )
    exit_for(items, "frames")
