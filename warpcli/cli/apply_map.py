"""The ``warp apply-map`` command: an image warped with a saved map (an STMap)."""

from __future__ import annotations

import click

from ..options import STMAP_T, WarpOptions
from .exits import EXIT_CODES
from .options import CONTEXT, background_option, collected, dtype_option, interp_option, quiet_option


@click.command("apply-map", context_settings=CONTEXT, epilog=EXIT_CODES)
@click.argument("map_path", metavar="MAP", type=click.Path())
@click.argument("input_path", metavar="INPUT", type=click.Path())
@click.argument("output_path", metavar="OUTPUT", type=click.Path())
@collected("resampling", WarpOptions, interp_option, background_option("Value of pixels where the map is undefined."), dtype_option)
@click.option(
    "--stmap-t",
    type=click.Choice(("auto", *STMAP_T)),
    default="auto",
    show_default=True,
    help="Which way the map's t runs; auto: as its header says (warpcli writes it), else down.",
)
@quiet_option
def apply_map(map_path, input_path, output_path, resampling, stmap_t):
    """Warp INPUT with a map saved by warp --save-map (or any STMap); write OUTPUT.

    MAP holds, for each OUTPUT pixel, the normalized point (s, t) of INPUT it
    comes from (OpenImageIO st_warp's convention); OUTPUT has MAP's size.

    \b
    Example:
      warp apply-map map.exr frame_0002.png warped_0002.png
    """
    from ..pipeline import apply_map_file

    t_up = None if stmap_t == "auto" else stmap_t == "up"
    apply_map_file(map_path, input_path, output_path, resampling, t_up=t_up)
