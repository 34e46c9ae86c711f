"""The ``warp edit`` command: the cage editor in the browser, served on 127.0.0.1 until Ctrl-C."""

from __future__ import annotations

import dataclasses

import click

from .exits import EDIT_EXIT_CODES
from .options import CONTEXT, interp_option, map_options, quiet_option


@click.command("edit", context_settings=CONTEXT, epilog=EDIT_EXIT_CODES)
@click.argument("image_path", metavar="IMAGE", type=click.Path(dir_okay=False))
@click.option("--src", "src_path", type=click.Path(dir_okay=False), help="Source polygon file: loaded if it exists; saved there.  [default: IMAGE_STEM.src.json]")
@click.option("--dst", "dst_path", type=click.Path(dir_okay=False), help="Target polygon file: loaded if it exists; saved there.  [default: IMAGE_STEM.dst.json]")
@click.option("--output", "output_path", type=click.Path(dir_okay=False), help="Where Export writes the warped image.  [default: IMAGE_STEM.warped.EXT]")
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True, help="Port on 127.0.0.1; 0: any free one.")
@click.option("--browser/--no-browser", default=True, show_default=True, help="Open the page in the browser; --no-browser only prints its address.")
@map_options
@interp_option
@click.option("--outside", type=click.Choice(("background", "input")), default="background", show_default=True, help="Outside DST: the background, or the input.")
@click.option("--within", metavar="image|MARGIN|FILE.json", help="A retouch within a fixed outline (as warp --within): the whole image, the cage's box grown by MARGIN pixels, or a polygon file; the page can change it.")
@quiet_option
def edit(image_path, src_path, dst_path, output_path, port, browser, mapping, interp, outside, within):
    """Draw the two polygons on IMAGE in the browser and watch the warp follow the mouse.

    Click to place the source polygon's vertices, close it, and drag the
    target's: the preview is the map itself, built at a preview density.
    Save writes the polygon files (the paths given here, or names chosen on
    the page, saved in IMAGE's directory); the page shows the equivalent
    warp command, and Export runs it on the full image. The server listens on
    127.0.0.1 only and answers only requests that carry the printed URL's token.

    \b
    Example:
      warp edit face.png --src face.json --dst smile.json
      warp face.png --src face.json --dst smile.json smile.png   (the command the page shows)
    """
    from ..edit import serve
    from ..options import WarpOptions

    if within is not None and outside == "background":
        source = click.get_current_context().get_parameter_source("outside")
        if source is not None and source.name == "COMMANDLINE":
            raise click.UsageError("--within keeps the input outside the outline: it takes no --outside background")
    if within is not None and within.strip() != "image":
        _check_within(within)
    options = dataclasses.replace(WarpOptions(map=mapping), interp=interp, outside=outside, within=within)

    def announce(url: str) -> None:
        click.echo(f"warp edit: {image_path} at {url} (Ctrl-C stops)", err=True)

    try:
        serve(image_path, src_path, dst_path, output_path, options, port=port, browser=browser, announce=announce)
    except KeyboardInterrupt:  # the way a user stops the server: not a failure
        click.echo("warp edit: stopped", err=True)


def _check_within(within: str) -> None:
    """A margin must be a positive number of pixels, a file a polygon the CLI reads (read once here, at the start)."""
    from ..polygon.outline import outline_polygon

    outline_polygon(within, (1, 1), [[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]])
