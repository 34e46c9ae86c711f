"""Surfaces (the paper's §4.2): textures and vertex attributes moved between surface patches through their UV charts.

One module per job, each importing only those before it:

- `mesh`: the `UVMesh` value and `MeshError`;
- `obj`, `ply`, `gltf`: strict readers of Wavefront OBJ, Stanford PLY and glTF 2.0; writers of new vertex values (OBJ, PLY);
- `formats`: `read_mesh`, by extension;
- `chart`: a chart's topology (a disk, unfolded) and its boundary loop; UV to pixels;
- `correspond`: two boundary loops as polygons of one vertex count (start, or corners and arclength);
- `transfer`: the map between two charts, a texture and vertex attributes through it;
- `run`: ``warp texture`` from files.
"""

from __future__ import annotations

from .chart import Chart, chart_of, uv_to_pixels
from .correspond import LoopPair, corresponding_loops
from .formats import read_mesh
from .mesh import MeshError, UVMesh
from .run import TransferResult, transfer_file
from .transfer import (
    ChartMap,
    TextureTransfer,
    chart_map,
    transfer_attributes,
    transfer_texture,
)

__all__ = [
    "Chart", "ChartMap", "LoopPair", "MeshError", "TextureTransfer", "TransferResult", "UVMesh", "chart_map", "chart_of",
    "corresponding_loops", "read_mesh", "transfer_attributes", "transfer_file", "transfer_texture", "uv_to_pixels",
]  # fmt: skip
