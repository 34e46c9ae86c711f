"""Surface mesh files by extension: OBJ, PLY or glTF, read into a `UVMesh`."""

from __future__ import annotations

import os

from .gltf import read_gltf
from .mesh import MeshError, UVMesh
from .obj import read_obj
from .ply import read_ply

__all__ = ["read_mesh"]


def read_mesh(path: str | os.PathLike[str]) -> UVMesh:
    """Read an OBJ, PLY or glTF surface patch with texture coordinates.

    Parameters
    ----------
    path : path-like
        ``.obj`` (``v``, ``vt``, ``f`` in the forms ``v/vt`` and ``v/vt/vn``,
        ``mtllib``/``usemtl``; vertex colours as ``v x y z r g b``), ``.ply``
        (ASCII or binary; per-vertex ``u, v`` or ``s, t``), or ``.gltf`` /
        ``.glb`` (the first triangle primitive; see
        `warpcli.surface.gltf.read_gltf`).

    Returns
    -------
    UVMesh

    Raises
    ------
    MeshError
        Naming the file, and the line where one is at fault.
    """
    name = os.fspath(path)
    kind = os.path.splitext(name)[1].lower()
    if kind == ".obj":
        return read_obj(name).mesh
    if kind == ".ply":
        return read_ply(name).mesh
    if kind in (".gltf", ".glb"):
        return read_gltf(name)
    raise MeshError(f"{name}: a surface mesh must be an .obj, .ply, .gltf or .glb file")
