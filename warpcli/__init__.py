"""warpcli: smooth bijective image warping between polygons (Schneider & Hormann 2015)."""

from __future__ import annotations

__version__ = "0.1.0"

from .errors import (
    FoldOverError,
    ImageInputError,
    ImageIOError,
    InputError,
    MeshingError,
    PolygonError,
    WarpError,
)
from .harmonic import HarmonicMap, solve_harmonic
from .imageio import RasterImage, read_image, write_image
from .mapping import BijectiveMap
from .mesh import TriMesh, mesh_polygon
from .pipeline import WarpResult, warp_file, warp_image
from .polygon import Polygon, read_polygon

__all__ = [
    "BijectiveMap",
    "FoldOverError",
    "HarmonicMap",
    "ImageIOError",
    "ImageInputError",
    "InputError",
    "MeshingError",
    "Polygon",
    "PolygonError",
    "RasterImage",
    "TriMesh",
    "WarpError",
    "WarpResult",
    "__version__",
    "mesh_polygon",
    "read_image",
    "read_polygon",
    "solve_harmonic",
    "warp_file",
    "warp_image",
    "write_image",
]
