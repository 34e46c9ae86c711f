"""Example cages built in code: boxes, spheres, their bends, twists and star-shaped blobs (tests, bench, docs)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray


def box(n: int = 1, lo: ArrayLike = (0.0, 0.0, 0.0), hi: ArrayLike = (1.0, 1.0, 1.0)):
    """The surface of an axis-aligned box, each side an ``n`` x ``n`` grid of quadrilaterals.

    Parameters
    ----------
    n : int
        Quadrilaterals along each edge of each side.
    lo, hi : (3,) array_like of float
        Opposite corners.

    Returns
    -------
    vertices : (6 n^2 + 2, 3) ndarray of float
    faces : (6 n^2, 4) ndarray of int
        Counter-clockwise seen from outside (outward normals).

    Examples
    --------
    >>> v, f = box(2)
    >>> v.shape, f.shape
    ((26, 3), (24, 4))
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    index: dict[tuple[int, int, int], int] = {}
    verts: list[tuple[int, int, int]] = []

    def vid(p: tuple[int, int, int]) -> int:
        if p not in index:
            index[p] = len(verts)
            verts.append(p)
        return index[p]

    faces = []
    # Each side: the fixed axis, its value (0 or n), and two in-plane axes
    # ordered so that (u, v, outward) is right-handed.
    for axis in range(3):
        u, w = (axis + 1) % 3, (axis + 2) % 3
        for side, (a, b) in ((0, (w, u)), (n, (u, w))):
            for i in range(n):
                for j in range(n):
                    quad = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = [0, 0, 0]
                        p[axis] = side
                        p[a] = i + di
                        p[b] = j + dj
                        quad.append(vid(tuple(p)))
                    faces.append(quad)
    grid = np.array(verts, dtype=np.float64) / n
    return lo + grid * (hi - lo), np.array(faces, dtype=np.int64)


def triangulated(faces: ArrayLike) -> NDArray[np.int64]:
    """Polygonal faces split into triangles, each as a fan from its first vertex.

    >>> triangulated([[0, 1, 2, 3]]).tolist()
    [[0, 1, 2], [0, 2, 3]]
    """
    f = np.asarray(faces, dtype=np.int64)
    return np.stack([f[:, [0, k, k + 1]] for k in range(1, f.shape[1] - 1)], axis=1).reshape(-1, 3)


def icosphere(level: int = 2, radius: float = 1.0):
    """A triangulated sphere: the icosahedron, each triangle split in four ``level`` times.

    Returns
    -------
    vertices : (10 * 4^level + 2, 3) ndarray of float
    faces : (20 * 4^level, 3) ndarray of int
        Outward oriented.

    Examples
    --------
    >>> v, f = icosphere(1)
    >>> len(v), len(f)
    (42, 80)
    """
    t = (1.0 + math.sqrt(5.0)) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
         (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]  # fmt: skip
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
         (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]  # fmt: skip
    verts = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in v]
    faces = [tuple(x) for x in f]
    for _ in range(level):
        mid: dict[tuple[int, int], int] = {}

        def midpoint(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = verts[a] + verts[b]
                verts.append(p / np.linalg.norm(p))
                mid[key] = len(verts) - 1
            return mid[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return radius * np.array(verts), np.array(faces, dtype=np.int64)


def twist(vertices: ArrayLike, turns: float, axis: int = 2) -> NDArray[np.float64]:
    """Rotate each point about the box's central ``axis`` by ``turns`` * 2 pi * its height in [0, 1].

    Heights and the centre are taken from the points' bounding box.
    """
    v = np.array(vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = (lo + hi) / 2
    u, w = (axis + 1) % 3, (axis + 2) % 3
    height = (v[:, axis] - lo[axis]) / (hi[axis] - lo[axis])
    angle = 2 * math.pi * turns * height
    du, dw = v[:, u] - centre[u], v[:, w] - centre[w]
    v[:, u] = centre[u] + np.cos(angle) * du - np.sin(angle) * dw
    v[:, w] = centre[w] + np.sin(angle) * du + np.cos(angle) * dw
    return v


def bend(vertices: ArrayLike, angle: float, axis: int = 2, towards: int = 0) -> NDArray[np.float64]:
    """Bend the points' bounding box about a line, so that its ``axis`` becomes an arc of ``angle`` radians.

    The box's mid-plane across ``towards`` keeps its length along the arc; points
    on the ``towards`` side of it are compressed, the others stretched.
    """
    v = np.array(vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    length = hi[axis] - lo[axis]
    radius = length / angle
    mid = (lo[towards] + hi[towards]) / 2
    s = (v[:, axis] - lo[axis]) / length * angle - angle / 2
    r = radius + (v[:, towards] - mid)
    v[:, towards] = mid + r * np.cos(s) - radius
    v[:, axis] = (lo[axis] + hi[axis]) / 2 + r * np.sin(s)
    return v


def star(vertices: ArrayLike, lobes: int = 3, depth: float = 0.35, phase: float = 0.0) -> NDArray[np.float64]:
    """Points of a sphere about the origin pushed in and out radially: a star-shaped blob.

    The radius becomes ``1 + depth * cos(lobes * azimuth + phase) * sin(polar)^2``
    plus a smaller bump along the poles, so the blob is star-shaped about the
    origin and concave between its lobes.
    """
    v = np.array(vertices, dtype=np.float64)
    r = np.linalg.norm(v, axis=1)
    d = v / r[:, None]
    azimuth = np.arctan2(d[:, 1], d[:, 0])
    s2 = 1.0 - d[:, 2] ** 2
    scale = 1.0 + depth * np.cos(lobes * azimuth + phase) * s2 + 0.5 * depth * d[:, 2] ** 3
    return v * scale[:, None]


def tetrahedron() -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The unit corner tetrahedron, outward oriented."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int64)
    return v, f


def rotation(axis: ArrayLike, angle: float) -> NDArray[np.float64]:
    """The 3 x 3 rotation by ``angle`` radians about ``axis`` (Rodrigues)."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx
