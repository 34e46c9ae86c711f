"""The ``warp texture`` command: a texture or vertex colours moved between two surface patches through their UV charts."""

from __future__ import annotations

import click

from ..options import WarpOptions
from .exits import EXIT_CODES
from .options import (
    CONTEXT,
    background_option,
    collected,
    dtype_option,
    interp_option,
    jobs_option,
    map_options,
    parse_size,
    quiet_option,
)


def _indices(ctx, param, value):
    """``I,J,K``: vertex numbers (from 0)."""
    if value is None:
        return None
    try:
        out = [int(v) for v in value.split(",")]
    except ValueError:
        raise click.BadParameter(f"expected vertex numbers separated by commas, such as 0,12,40,52; got {value!r}") from None
    if any(v < 0 for v in out):
        raise click.BadParameter(f"vertex numbers start at 0, got {value!r}")
    return out


resampling_options = collected(
    "resampling",
    WarpOptions,
    interp_option,
    click.option("--size", callback=parse_size, metavar="WxH", help="Size of the texture written (DST's).  [default: SRC's texture's size]"),
    dtype_option,
    background_option("Value of texels beyond the chart and its padding: one for all channels or one per channel."),
    click.option("--antialias/--no-antialias", default=True, show_default=True, help="With linear, average each texel over its footprint where the map shrinks."),
)  # fmt: skip


@click.command("texture", context_settings=CONTEXT, epilog=EXIT_CODES)
@click.argument("src_path", metavar="SRC_MESH", type=click.Path())
@click.argument("dst_path", metavar="DST_MESH", type=click.Path())
@click.argument("output_path", metavar="OUT", type=click.Path())
@click.option("--texture", type=click.Path(), help="SRC's texture image.  [default: the map_Kd of SRC's material, or its PLY comment TextureFile]")
@click.option("--src-corners", callback=_indices, metavar="I,J,...", help="Vertices (numbered from 0) of SRC's boundary that go onto --dst-corners; the boundary between corners goes by arclength.")
@click.option("--dst-corners", callback=_indices, metavar="I,J,...", help="DST's corners, as many, in the same order along the boundary.")
@click.option("--src-start", type=click.IntRange(0), metavar="I", help="Without corners: the boundary vertex of SRC that goes onto DST's start.  [default: the boundary vertex of smallest number]")
@click.option("--dst-start", type=click.IntRange(0), metavar="I", help="Without corners: DST's start.  [default: its boundary vertex of smallest number]")
@click.option("--flip-v/--no-flip-v", default=False, show_default=True, help="v runs down the texture (DirectX, glTF) for both meshes; by default up (OBJ, OpenGL).")
@click.option("--src-flip-v", is_flag=True, help="v runs down for SRC only.")
@click.option("--dst-flip-v", is_flag=True, help="v runs down for DST only.")
@click.option("--padding", type=click.IntRange(0, 4096), default=8, show_default=True, metavar="N", help="Texels around the chart that repeat its edge texels (a baker's dilation); 0: none, the edge antialiased against the background.")
@click.option("--attribute", "attributes", multiple=True, metavar="NAME", help="Mesh OUT: a vertex attribute to move (repeat for several).  [default: all of SRC's; for an OBJ, its colours]")
@map_options
@resampling_options
@jobs_option("the map's two halves built side by side (one in a forked child), the kernels on N threads", expose_value=False)
@quiet_option
def texture(src_path, dst_path, output_path, texture, src_corners, dst_corners, src_start, dst_start, flip_v, src_flip_v,
            dst_flip_v, padding, attributes, mapping, resampling):  # fmt: skip
    """Move SRC_MESH's texture (or vertex colours) onto DST_MESH through the map between their UV charts.

    Each mesh is a disk-shaped patch with texture coordinates (OBJ with vt;
    PLY with u,v or s,t; glTF, read only); its UV chart's boundary is the polygon, and the
    two charts are mapped onto each other bijectively (the paper's 4.2). If
    OUT is an image, SRC's texture is resampled into DST's UV layout; if it
    is a mesh (DST's format), DST is written with SRC's vertex attributes
    carried onto its vertices.

    Boundaries with as many vertices go onto each other in loop order from
    the boundary vertex of smallest number (or --src-start, --dst-start);
    otherwise name corners on both, and the boundary between two corners goes
    by arclength.

    \b
    Examples:
      warp texture head_a.obj head_b.obj head_b.png
      warp texture a.obj b.obj b.png --texture a.png --src-corners 0,8,80,88 --dst-corners 0,5,30,35
      warp texture scan_a.ply scan_b.ply scan_b_coloured.ply
    """
    import dataclasses

    from ..surface import transfer_file

    options = dataclasses.replace(resampling, map=mapping)
    transfer_file(
        src_path, dst_path, output_path, options, texture=texture, padding=padding, attributes=list(attributes) or None,
        flip_v=(flip_v or src_flip_v, flip_v or dst_flip_v), src_start=src_start, dst_start=dst_start,
        src_corners=src_corners, dst_corners=dst_corners,
    )  # fmt: skip
