"""The surface patch value: a triangle mesh with a UV chart, per-vertex attributes, and how it was read."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

__all__ = ["MAX_ELEMENTS", "MAX_MESH_BYTES", "MESH_KINDS", "MeshError", "UVMesh"]

#: Largest mesh file read, in bytes: text formats are parsed into Python objects
#: (some 10 times the file's size at the peak), so this keeps a run within a few GiB;
#: a 256 MiB OBJ holds about 5 million vertices.
MAX_MESH_BYTES = 256 << 20
#: Most vertices, texture coordinates or faces a mesh may have (each): far beyond any
#: UV chart, and small enough that the arrays of a mesh stay within a few GiB.
MAX_ELEMENTS = 20_000_000
#: The mesh formats read and written, by extension.
MESH_KINDS = (".obj", ".ply")


class MeshError(InputError):
    """A mesh file is missing, malformed, or not a disk-shaped patch with texture coordinates."""


@dataclass(frozen=True, eq=False)
class UVMesh:
    """A triangle mesh whose corners carry texture coordinates: a surface patch and its UV chart.

    Positions and texture coordinates are indexed separately, as an OBJ file
    does (a PLY file with per-vertex ``u, v`` has the same indices for both):
    corner k of triangle f is position ``triangles_pos[f, k]`` at texture
    coordinate ``uv[triangles_uv[f, k]]``. Faces with more than three corners
    are split into fans.

    Parameters
    ----------
    positions : (V, 3) ndarray of float
        3D vertex positions (zeros if the file has none).
    uv : (T, 2) ndarray of float
        Texture coordinates (u right, v up, 0..1 across the texture, as written).
    triangles_pos, triangles_uv : (F, 3) ndarray of int
    attributes : dict of str to (V,) ndarray of float
        Per-vertex values other than position, normal and texture coordinate
        (an OBJ's vertex colours are ``red``, ``green``, ``blue`` in 0..1; a
        PLY's properties as stored, 0..255 for uchar colours).
    attribute_types : dict of str to str
        Each attribute's PLY type name (``"uchar"``, ``"float"``, ...).
    name : str
        The file, for messages.
    texture : str or None
        The texture image the file names (an OBJ material's ``map_Kd``, a
        PLY's ``comment TextureFile``), resolved against the file's directory.
    face_lines : (F,) ndarray of int
        For messages: where each triangle is in the file, as ``face_word`` says.
    face_word : str
        ``"line"`` (an OBJ's lines, from 1), ``"face"`` (a PLY's face rows, from
        0) or ``"triangle"`` (the triangles' own numbers, from 0: a glTF
        primitive's, or a mesh made in code).
    """

    positions: NDArray[np.float64]
    uv: NDArray[np.float64]
    triangles_pos: NDArray[np.int64]
    triangles_uv: NDArray[np.int64]
    attributes: dict = field(default_factory=dict)
    attribute_types: dict = field(default_factory=dict)
    name: str = "mesh"
    texture: str | None = None
    face_lines: NDArray[np.int64] | None = field(default=None, repr=False)
    face_word: str = "triangle"

    def __post_init__(self) -> None:
        pos = np.asarray(self.positions, dtype=np.float64).reshape(-1, 3)
        uv = np.asarray(self.uv, dtype=np.float64).reshape(-1, 2)
        tp = np.asarray(self.triangles_pos, dtype=np.int64).reshape(-1, 3)
        tu = np.asarray(self.triangles_uv, dtype=np.int64).reshape(-1, 3)
        if len(tp) != len(tu):
            raise MeshError(f"{self.name}: {len(tp)} triangles of positions but {len(tu)} of texture coordinates")
        if tp.size and (tp.min() < 0 or tp.max() >= len(pos)):
            raise MeshError(f"{self.name}: a face refers to a vertex that does not exist")
        if tu.size and (tu.min() < 0 or tu.max() >= len(uv)):
            raise MeshError(f"{self.name}: a face refers to a texture coordinate that does not exist")
        for key, values in self.attributes.items():
            if np.shape(values) != (len(pos),):
                raise MeshError(f"{self.name}: attribute {key} has {np.size(values)} values for {len(pos)} vertices")
        lines = np.arange(len(tp)) if self.face_lines is None else np.asarray(self.face_lines, dtype=np.int64)
        for name, arr in (("positions", pos), ("uv", uv), ("triangles_pos", tp), ("triangles_uv", tu), ("face_lines", lines)):
            object.__setattr__(self, name, arr)

    def uv_to_position(self) -> NDArray[np.int64]:
        """For each texture coordinate, the position of the first corner using it (-1: unused)."""
        return _first_partner(self.triangles_uv.ravel(), self.triangles_pos.ravel(), len(self.uv))

    def position_to_uv(self) -> NDArray[np.int64]:
        """For each position, the texture coordinate of the first corner using it (-1: unused)."""
        return _first_partner(self.triangles_pos.ravel(), self.triangles_uv.ravel(), len(self.positions))


def _first_partner(keys: NDArray[np.int64], partners: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """For each of ``n`` keys, the partner at its first occurrence in ``keys`` (-1: none)."""
    out = np.full(n, -1, dtype=np.int64)
    uniq, first = np.unique(keys, return_index=True)
    out[uniq] = partners[first]
    return out
