"""warpcli: smooth bijective image warping between polygons (Schneider & Hormann 2015).

The public names below are imported on first use, so that ``import warpcli``
(and ``warp --help``) stays instant.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_EXPORTS = {
    "BijectiveMap": "mapping",
    "FoldOverError": "errors",
    "HarmonicMap": "harmonic",
    "ImageIOError": "errors",
    "ImageInputError": "errors",
    "InputError": "errors",
    "MeshingError": "errors",
    "Polygon": "polygon",
    "PolygonError": "errors",
    "RasterImage": "imageio",
    "TriMesh": "mesh",
    "WarpError": "errors",
    "WarpResult": "pipeline",
    "mesh_polygon": "mesh",
    "read_image": "imageio",
    "read_polygon": "polygon",
    "solve_harmonic": "harmonic",
    "warp_file": "pipeline",
    "warp_image": "pipeline",
    "write_image": "imageio",
}

__all__ = sorted([*_EXPORTS, "__version__"])


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'warpcli' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
