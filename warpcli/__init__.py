"""warpcli: smooth bijective image warping between polygons (Schneider & Hormann 2015).

The public names below are imported on first use, so that ``import warpcli``
(and ``warp --help``) stays instant; type checkers and IDEs see them through
the ``TYPE_CHECKING`` imports.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.2.0"

_EXPORTS = {
    "BatchItem": "batch",
    "BijectiveMap": "maps.compose",
    "CageMap": "maps.cage",
    "Certificate": "mapping",
    "FoldOverError": "errors",
    "ImageIOError": "errors",
    "ImageInputError": "errors",
    "InputError": "errors",
    "MapOptions": "options",
    "MeshError": "surface",
    "MeshingError": "errors",
    "Polygon": "polygon",
    "Partition": "polygon.partition",
    "PolygonTransform": "transform",
    "PolygonError": "errors",
    "PullBack": "maps.compose",
    "RasterImage": "raster.imageio",
    "SamplingPlan": "plan",
    "Theta": "maps.theta",
    "ThetaMap": "maps.base",
    "UVMesh": "surface",
    "WarpError": "errors",
    "WarpOptions": "options",
    "WarpResult": "pipeline",
    "WarpedBoxes": "annotations",
    "WarpedPoints": "annotations",
    "apply_map_file": "pipeline",
    "build_cage_map": "maps.cage",
    "build_map": "maps.compose",
    "build_report": "report",
    "load_stmap": "raster.stmap",
    "pixel_centres": "grid",
    "read_image": "raster.imageio",
    "read_partition": "polygon.partition",
    "read_polygon": "polygon",
    "read_shape": "polygon.partition",
    "save_stmap": "raster.stmap",
    "resample": "raster.resample",
    "warp_batch": "batch",
    "warp_boxes": "annotations",
    "warp_labels": "annotations",
    "warp_points": "annotations",
    "warp_file": "pipeline",
    "warp_image": "pipeline",
    "warp_sequence": "batch",
    "read_keyframes": "keyframes",
    "read_mesh": "surface",
    "transfer_attributes": "surface",
    "transfer_file": "surface",
    "transfer_texture": "surface",
    "parse_frames": "sequence",
    "jobs": "cores",
    "set_jobs": "cores",
    "write_image": "raster.imageio",
    "WithinPair": "within",
    "read_cages": "within",
    "within_pair": "within",
}

__all__ = sorted([*_EXPORTS, "__version__"])

if TYPE_CHECKING:
    from .annotations import WarpedBoxes, WarpedPoints, warp_boxes, warp_labels, warp_points
    from .errors import (
        FoldOverError,
        ImageInputError,
        ImageIOError,
        InputError,
        MeshingError,
        PolygonError,
        WarpError,
    )
    from .grid import pixel_centres
    from .mapping import Certificate
    from .maps.base import ThetaMap
    from .maps.cage import CageMap, build_cage_map
    from .maps.compose import BijectiveMap, PullBack, build_map
    from .maps.theta import Theta
    from .options import MapOptions, WarpOptions
    from .keyframes import read_keyframes
    from .batch import BatchItem, warp_batch, warp_sequence
    from .pipeline import WarpResult, apply_map_file, warp_file, warp_image
    from .plan import SamplingPlan
    from .sequence import parse_frames
    from .cores import jobs, set_jobs
    from .polygon import Polygon, read_polygon
    from .polygon.partition import Partition, read_partition, read_shape
    from .transform import PolygonTransform
    from .raster.imageio import RasterImage, read_image, write_image
    from .raster.resample import resample
    from .raster.stmap import load_stmap, save_stmap
    from .report import build_report
    from .surface import MeshError, UVMesh, read_mesh, transfer_attributes, transfer_file, transfer_texture
    from .within import WithinPair, read_cages, within_pair


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'warpcli' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
