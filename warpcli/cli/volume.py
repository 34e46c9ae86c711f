"""The ``warp volume`` command: a 3D image warped so that one cage goes onto another."""

from __future__ import annotations

import click

from .exits import EXIT_CODES
from .options import CONTEXT, jobs_option, quiet_option


@click.command("volume", context_settings=CONTEXT, epilog=EXIT_CODES)
@click.argument("input_path", metavar="IN", type=click.Path())
@click.argument("output_path", metavar="OUT", type=click.Path())
@click.option("--src", "src_path", required=True, type=click.Path(), help="Source cage: a closed genus-0 triangle or quad mesh (OBJ, OFF, PLY).")
@click.option("--dst", "dst_path", required=True, type=click.Path(), help="Target cage, the same connectivity: vertex i of SRC goes to vertex i of DST.")
@click.option("--theta", default="auto", show_default=True, metavar="auto|source|target|sphere|FILE", help="The convex intermediate polyhedron: auto takes a convex cage if either is one, else a certified spherical parameterization; or a convex mesh with the same connectivity.")
@click.option("--interp", "interpolation", type=click.Choice(("linear", "nearest")), default="linear", show_default=True, help="Trilinear or nearest-voxel resampling.")
@click.option("--background", default=0.0, show_default=True, type=float, help="Value of voxels outside DST (in the volume's stored units).")
@click.option("--edge", type=click.FloatRange(min=0, min_open=True), help="Tetrahedron edge length in the cages' units.  Near the volume, for a cage meshed graded from the volume's box.  [default: from each cage's size (the box's, for a cage far larger than the volume) and the voxel size]")
@click.option("--untangle/--no-untangle", default=True, show_default=True, help="Move interior nodes of inverted tetrahedra to where their stars keep their orientation (the boundary stays); --no-untangle keeps the discrete harmonic maps as solved.")
@click.option("--allow-folds", is_flag=True, help="Write the volume even if a tetrahedron stays inverted after untangling (with a warning); by default such a map is refused, exit 1, nothing written: in 3D no theorem rules folds out.")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), help="Write a JSON report: flipped tetrahedra before and after untangling, 3D distortion, min det J, timings.")
@click.option("--picture", type=click.Path(dir_okay=False), help="Write three orthogonal slices of input and output with a grid carried through the map (PNG).")
@jobs_option("the libraries' thread pools (BLAS, OpenImageIO) with N threads; the tetrahedral maps are built one after the other", expose_value=False)
@quiet_option
def volume(input_path, output_path, src_path, dst_path, theta, interpolation, background, edge, untangle, allow_folds, report_path, picture):
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
    from ..volume import warp_volume_file

    warp_volume_file(
        input_path, output_path, src_path, dst_path, theta=theta, interpolation=interpolation,
        background=background, edge=edge, untangle=untangle, check=not allow_folds, report=report_path, picture=picture,
    )  # fmt: skip
