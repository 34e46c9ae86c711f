"""The ``warp points`` command: points, CSV and OBJ texture coordinates carried through the map."""

from __future__ import annotations

import click

from .exits import EXIT_CODES
from .options import CONTEXT, jobs_option, map_options, parse_size, polygon_options, quiet_option


def _columns(ctx, param, value):
    """--columns X,Y: two column names or numbers."""
    if value is None:
        return None
    parts = [p.strip() for p in value.split(",")]
    if len(parts) != 2 or not all(parts):
        raise click.BadParameter(f"{value!r}: give two columns, as X,Y (names or numbers from 1)")
    return tuple(parts)


@click.command("points", context_settings=CONTEXT, epilog=EXIT_CODES)
@click.argument("input_path", metavar="IN", type=click.Path())
@click.argument("output_path", metavar="OUT", type=click.Path())
@polygon_options("Source polygon file.", "Target polygon file.", "Which polygon of a --{side} file holding several (a label or #N).")
@click.option("--inverse", is_flag=True, help="Map target points back to the source.")
@map_options
@click.option("--texture-size", callback=parse_size, metavar="WxH", help="OBJ: the texture's size in pixels (the polygons' units).")
@click.option("--outside", type=click.Choice(("keep", "error")), default="keep", show_default=True, help="Points outside the polygon: left as they are (with a warning), or an error.")
@click.option("--frame", type=int, metavar="N", help="Keyframed polygon files: the polygons at frame N.")
@click.option("--precision", type=click.IntRange(0, 9), default=6, show_default=True, metavar="N", help="Decimals of the coordinates written (JSON and tables): 6 is a millionth of a pixel, below any method's accuracy.")
@click.option("--columns", metavar="X,Y", callback=_columns, help="Tables: the x and y columns, by header name or number from 1 (default: the columns named x and y, else the first two).")
@click.option("--within", metavar="image|MARGIN|FILE.json", help="A retouch within a fixed outline, as warp --within (the same map as the image's): points outside the outline stay.")
@click.option("--image-size", callback=parse_size, metavar="WxH", help="--within: the image's size (an OBJ's --texture-size when not given).")
@jobs_option("the map's two halves built side by side (one in a forked child), the kernels on N threads", expose_value=False)
@quiet_option
def points(input_path, output_path, polygons, inverse, mapping, texture_size, outside, frame, precision, columns, within, image_size):
    """Map points (JSON, a CSV or text table, or an OBJ's vt texture coordinates) from SRC's coordinates to DST's.

    The map is the image warp's: give the same method and Theta options
    (and --within, with the image's size) as to warp.

    A table (.csv: commas, semicolons or tabs; .txt: spaces) keeps its other
    columns and lines; x and y are the columns its header names x and y, else
    the first two (or --columns). Coordinates are written to --precision decimals.

    An OBJ keeps every line but its vt lines byte for byte: a mesh's UVs move
    from one texture layout (polygon SRC) to another (DST), the paper's 4.2.

    \b
    Examples:
      warp points --src layout_a.json --dst layout_b.json --texture-size 2048x2048 head.obj head_b.obj
      warp points --src a.json --dst b.json --columns px,py tracks.csv tracks_b.csv
      warp points --src cage.json --dst moved.json --within 40 --image-size 4000x3000 marks.json marks_b.json
    """
    from ..points import map_points_file

    map_points_file(
        input_path, output_path, polygons.src_path, polygons.dst_path, mapping, inverse=inverse,
        texture_size=texture_size, outside=outside, src_label=polygons.src_label, dst_label=polygons.dst_label,
        frame=frame, precision=precision, columns=columns, within=within, image_size=image_size,
    )  # fmt: skip
