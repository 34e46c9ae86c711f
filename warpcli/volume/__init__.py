"""Volumes: smooth maps between polyhedra with the same connectivity, and warps of 3D images through them (§5.3).

The 3D counterpart of the 2D pipeline, kept beside it: cages (closed genus-0
surface meshes) -> Theta -> tetrahedral meshes -> harmonic maps -> the
composed map's pull-back of voxel centres -> a resampled volume. What does
not depend on the dimension is shared with the 2D maps and imported from the
base layer: the map seam (`warpcli.mapping`: `Mapped`, `Certificate`, the
composition's ``forward``/``inverse`` and Jacobians) and the distortion
measures (`warpcli.distortion`); images (the report's picture, TIFF checks)
go through `warpcli.raster.imageio`. What is here is what differs by
dimension: meshing (TetGen), cage validation, how Theta is built,
untangling, volume I/O and the voxel kernels. Nothing here imports the 2D
maps (`warpcli.maps`), and nothing there imports this.

Meshing needs ``tetgen`` and NIfTI needs ``nibabel`` (``pip install
'warpcli[volume]'``); they are imported only when used.
"""

from __future__ import annotations

from .compose import IdentityMap, Mapped, TetMap, VolumeMap, VolumeThetaMap, VoxelGrid
from .pipeline import INTERPOLATIONS, VolumeWarpResult, build_map, warp_volume, warp_volume_file
from .surface import Surface, SurfaceError, check_pair, check_surface, read_surface
from .theta import THETA_STRATEGIES, Theta, theta_for
from .volio import Volume, read_volume, write_volume

__all__ = [
    "INTERPOLATIONS", "THETA_STRATEGIES", "IdentityMap", "Mapped", "Surface", "SurfaceError", "TetMap", "Theta",
    "Volume", "VolumeMap", "VolumeThetaMap", "VolumeWarpResult", "VoxelGrid", "build_map", "check_pair",
    "check_surface", "read_surface", "read_volume", "theta_for", "warp_volume", "warp_volume_file", "write_volume",
]  # fmt: skip
