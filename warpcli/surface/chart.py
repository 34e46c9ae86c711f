"""A UV chart's topology: manifold, oriented, one boundary loop (a disk), unfolded; and its pixel coordinates."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .mesh import MeshError, UVMesh

__all__ = ["Chart", "chart_of", "uv_to_pixels"]


@dataclass(frozen=True, eq=False)
class Chart:
    """A surface patch's UV chart, checked to be a disk, and its boundary loop.

    Attributes
    ----------
    mesh : UVMesh
    loop : (L,) ndarray of int
        The boundary's texture coordinates in order, the way the faces run
        along it (the chart's interior on the left when the faces run
        counter-clockwise in UV space).
    loop_vertices : (L,) ndarray of int
        The vertex (position) of each, the numbers users give as corners.
    """

    mesh: UVMesh
    loop: NDArray[np.int64]
    loop_vertices: NDArray[np.int64]


def uv_to_pixels(uv: NDArray[np.float64], size: tuple[int, int], flip_v: bool = False) -> NDArray[np.float64]:
    """Texture coordinates as pixel coordinates of a ``size`` (width, height) image.

    u runs right over the width; v runs up (OBJ's and OpenGL's convention,
    pixel row 0 at v = 1), or down with ``flip_v`` (DirectX's, glTF's).

    >>> uv_to_pixels(np.array([[0.0, 0.0], [0.5, 1.0]]), (200, 100)).tolist()
    [[0.0, 100.0], [100.0, 0.0]]
    >>> uv_to_pixels(np.array([[0.0, 0.0]]), (200, 100), flip_v=True).tolist()
    [[0.0, 0.0]]
    """
    w, h = size
    uv = np.asarray(uv, dtype=np.float64)
    y = uv[:, 1] * h if flip_v else (1.0 - uv[:, 1]) * h
    return np.stack([uv[:, 0] * w, y], axis=1)


def chart_of(mesh: UVMesh) -> Chart:
    """Check that a mesh's UV chart is a disk laid flat without folds, and find its boundary loop.

    The topology is that of the texture coordinates (a cylinder cut open
    along a seam is a disk in UV space). Checked, in order: no triangle
    repeats a corner; every edge in at most two triangles, which run along
    it in opposite directions (a manifold, consistently oriented); one
    boundary loop, through each of its vertices once; Euler characteristic 1
    (no handles); every triangle of non-zero area in UV space and all of one
    orientation (the chart does not fold; with a simple boundary, which the
    polygon check makes sure of, it is then one-to-one).

    Raises
    ------
    MeshError
        Naming the file, the problem, and a line of the file where there is one.
    """
    name = mesh.name
    t = mesh.triangles_uv
    lines = mesh.face_lines

    def where(f) -> str:
        """Where triangle f is in the file: its line (OBJ), its face row (PLY) or triangle (glTF)."""
        return f"{mesh.face_word} {int(lines[int(f)])}"

    bad = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 2] == t[:, 0])
    if bad.any():
        raise MeshError(f"{name}: {where(np.argmax(bad))}: a face uses one texture coordinate twice")
    nuv = len(mesh.uv)
    a = t.ravel()
    b = t[:, [1, 2, 0]].ravel()
    face = np.repeat(np.arange(len(t)), 3)
    key = a * nuv + b
    order = np.argsort(key, kind="stable")
    ks = key[order]
    dup = np.flatnonzero(ks[1:] == ks[:-1])
    undirected = np.minimum(a, b) * nuv + np.maximum(a, b)
    uniq, counts = np.unique(undirected, return_counts=True)
    if (counts > 2).any():
        e = int(uniq[np.argmax(counts > 2)])
        faces = face[undirected == e]
        raise MeshError(
            f"{name}: {', '.join(where(f) for f in faces[:3])}: {int(counts.max())} faces share one edge "
            "(the chart is not a manifold)"
        )
    if dup.size:
        f1, f2 = face[order[dup[0]]], face[order[dup[0] + 1]]
        raise MeshError(
            f"{name}: {where(f1)} and {where(f2)}: two faces run along an edge in the same direction "
            "(the faces are not consistently oriented)"
        )
    reverse = b * nuv + a
    pos = np.searchsorted(ks, reverse)
    pos = np.minimum(pos, len(ks) - 1)
    boundary = ks[pos] != reverse
    if not boundary.any():
        raise MeshError(f"{name}: the chart is closed (no boundary): cut the surface open into a disk")
    ba, bb = a[boundary], b[boundary]
    starts, nstart = np.unique(ba, return_counts=True)
    if (nstart > 1).any():
        v = int(mesh.uv_to_position()[starts[np.argmax(nstart > 1)]])
        raise MeshError(
            f"{name}: vertex {v} is on the boundary twice (two parts of the chart touch there); "
            "the chart must be a disk"
        )
    nxt = np.full(nuv, -1, dtype=np.int64)
    nxt[ba] = bb
    loop = [int(ba[0])]
    while True:
        v = int(nxt[loop[-1]])
        if v == loop[0]:
            break
        loop.append(v)
        if len(loop) > len(ba):  # cannot happen once each vertex has one successor; a guard all the same
            raise MeshError(f"{name}: the chart's boundary does not close")
    if len(loop) != len(ba):
        loops = _count_loops(ba, nxt)
        raise MeshError(
            f"{name}: the chart has {loops} boundary loops (holes, or separate pieces); it must be a disk, with one"
        )
    used = np.unique(a).size
    euler = used - uniq.size + len(t)
    if euler != 1:
        raise MeshError(f"{name}: the chart is not a disk (Euler characteristic {euler}, not 1): it has handles or closed parts")
    uv = mesh.uv
    p, q, r = uv[t[:, 0]], uv[t[:, 1]], uv[t[:, 2]]
    area = (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
    scale = np.abs(np.concatenate([q - p, r - p], axis=1)).max(axis=1) ** 2
    flat = np.abs(area) <= 1e-12 * np.maximum(scale, 1e-300)
    if flat.any():
        raise MeshError(f"{name}: {where(np.argmax(flat))}: a face has no area in UV space")
    sign = np.sign(area)
    major = 1.0 if (sign > 0).sum() >= (sign < 0).sum() else -1.0
    flipped = sign != major
    if flipped.any():
        raise MeshError(
            f"{name}: {where(np.argmax(flipped))}: the UV chart folds over ({int(flipped.sum())} face(s) flipped "
            "against the others)"
        )
    loop_arr = np.array(loop, dtype=np.int64)
    return Chart(mesh, loop_arr, mesh.uv_to_position()[loop_arr])


def _count_loops(ba: NDArray[np.int64], nxt: NDArray[np.int64]) -> int:
    seen = set()
    loops = 0
    for v0 in ba.tolist():
        if v0 in seen:
            continue
        loops += 1
        v = v0
        while v not in seen:
            seen.add(v)
            v = int(nxt[v])
    return loops
