"""Compiled (numba) inner loops of the volume warp: surface self-intersection, scan conversion, point location, sampling.

`scan_slab` scan-converts tetrahedra onto the voxel grid slice by slice (a
map at every voxel centre), `walk` locates a coherent sequence of points in a
tetrahedral mesh, `sample_*` resample a volume at the points found. The
kernels are cached on disk like those of the 2D FEM map. Results never depend
on the number of threads: every kernel is serial.
"""

from __future__ import annotations

import math

import numpy as np
from .._jit import njit

#: Barycentric tolerance for "inside a tetrahedron" (relative to 1).
TOL = 1e-9


# --- surface self-intersection ------------------------------------------------


@njit(cache=True, nogil=True)
def _orient(a, b, c, d):
    """det[b - a, c - a, d - a]: positive when d lies on the side of abc its normal points to."""
    bx, by, bz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    cx, cy, cz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    dx, dy, dz = d[0] - a[0], d[1] - a[1], d[2] - a[2]
    return bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx)


@njit(cache=True, nogil=True)
def _segment_crosses(p, q, a, b, c):
    """Whether segment pq crosses the interior of triangle abc (strictly: touching does not count)."""
    s1 = _orient(a, b, c, p)
    s2 = _orient(a, b, c, q)
    if not ((s1 > 0 and s2 < 0) or (s1 < 0 and s2 > 0)):
        return False
    o1 = _orient(p, q, a, b)
    o2 = _orient(p, q, b, c)
    o3 = _orient(p, q, c, a)
    return (o1 > 0 and o2 > 0 and o3 > 0) or (o1 < 0 and o2 < 0 and o3 < 0)


@njit(cache=True, nogil=True)
def _pair_intersects(v, t, i, j):
    shared = 0
    si = -1
    sj = -1
    for a in range(3):
        for b in range(3):
            if t[i, a] == t[j, b]:
                shared += 1
                si = a
                sj = b
    if shared >= 2:
        return False
    if shared == 1:
        # Only the edge opposite the shared vertex can cross the other triangle.
        p = v[t[i, (si + 1) % 3]]
        q = v[t[i, (si + 2) % 3]]
        if _segment_crosses(p, q, v[t[j, 0]], v[t[j, 1]], v[t[j, 2]]):
            return True
        p = v[t[j, (sj + 1) % 3]]
        q = v[t[j, (sj + 2) % 3]]
        return _segment_crosses(p, q, v[t[i, 0]], v[t[i, 1]], v[t[i, 2]])
    for k in range(3):
        if _segment_crosses(v[t[i, k]], v[t[i, (k + 1) % 3]], v[t[j, 0]], v[t[j, 1]], v[t[j, 2]]):
            return True
        if _segment_crosses(v[t[j, k]], v[t[j, (k + 1) % 3]], v[t[i, 0]], v[t[i, 1]], v[t[i, 2]]):
            return True
    return False


@njit(cache=True, nogil=True)
def _intersections(v, t, cell, dims, lo):
    m = t.shape[0]
    bmin = np.empty((m, 3))
    bmax = np.empty((m, 3))
    cmin = np.empty((m, 3), dtype=np.int64)
    cmax = np.empty((m, 3), dtype=np.int64)
    for i in range(m):
        for d in range(3):
            x0 = min(v[t[i, 0], d], v[t[i, 1], d], v[t[i, 2], d])
            x1 = max(v[t[i, 0], d], v[t[i, 1], d], v[t[i, 2], d])
            bmin[i, d] = x0
            bmax[i, d] = x1
            cmin[i, d] = min(max(int((x0 - lo[d]) / cell), 0), dims[d] - 1)
            cmax[i, d] = min(max(int((x1 - lo[d]) / cell), 0), dims[d] - 1)
    ncell = dims[0] * dims[1] * dims[2]
    count = np.zeros(ncell + 1, dtype=np.int64)
    for i in range(m):
        for a in range(cmin[i, 0], cmax[i, 0] + 1):
            for b in range(cmin[i, 1], cmax[i, 1] + 1):
                for c in range(cmin[i, 2], cmax[i, 2] + 1):
                    count[(a * dims[1] + b) * dims[2] + c + 1] += 1
    for k in range(ncell):
        count[k + 1] += count[k]
    items = np.empty(count[ncell], dtype=np.int64)
    fill = count[:-1].copy()
    for i in range(m):
        for a in range(cmin[i, 0], cmax[i, 0] + 1):
            for b in range(cmin[i, 1], cmax[i, 1] + 1):
                for c in range(cmin[i, 2], cmax[i, 2] + 1):
                    k = (a * dims[1] + b) * dims[2] + c
                    items[fill[k]] = i
                    fill[k] += 1
    out = np.full(2, -1, dtype=np.int64)
    for a in range(dims[0]):
        for b in range(dims[1]):
            for c in range(dims[2]):
                k = (a * dims[1] + b) * dims[2] + c
                for x in range(count[k], count[k + 1]):
                    i = items[x]
                    for y in range(x + 1, count[k + 1]):
                        j = items[y]
                        overlap = True
                        for d in range(3):
                            if bmin[i, d] > bmax[j, d] or bmin[j, d] > bmax[i, d]:
                                overlap = False
                        if not overlap:
                            continue
                        # Test each pair once: in the cell holding the low corner of the boxes' overlap.
                        own = True
                        cc = (a, b, c)
                        for d in range(3):
                            lowc = max(cmin[i, d], cmin[j, d])
                            if lowc != cc[d]:
                                own = False
                        if not own:
                            continue
                        if _pair_intersects(v, t, i, j):
                            if out[0] < 0 or min(i, j) < out[0] or (min(i, j) == out[0] and max(i, j) < out[1]):
                                out[0] = min(i, j)
                                out[1] = max(i, j)
    return out


def first_intersection(vertices: np.ndarray, triangles: np.ndarray) -> tuple[int, int] | None:
    """The first pair (by index) of triangles that cross each other, or None.

    Triangles sharing an edge are not tested; triangles sharing a vertex are
    tested for their far edges crossing each other. Coplanar overlaps are not
    detected.
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    t = np.ascontiguousarray(triangles, dtype=np.int64)
    lo = v.min(axis=0)
    extent = np.maximum(v.max(axis=0) - lo, 1e-300)
    edge = np.linalg.norm(v[t[:, 1]] - v[t[:, 0]], axis=1)
    cell = max(2.0 * float(np.median(edge)), float(extent.max()) / 256.0)
    dims = np.maximum(np.ceil(extent / cell).astype(np.int64), 1)
    out = _intersections(v, t, cell, dims, lo)
    return None if out[0] < 0 else (int(out[0]), int(out[1]))


# --- surface refinement -------------------------------------------------------


@njit(cache=True, nogil=True)
def _dist2(v, a, b):
    return (v[a, 0] - v[b, 0]) ** 2 + (v[a, 1] - v[b, 1]) ** 2 + (v[a, 2] - v[b, 2]) ** 2


@njit(cache=True, nogil=True)
def split_triangles(t, side_edge, new_id, v):
    """Split triangles whose sides have midpoints (``new_id[edge] >= 0``), conformingly.

    One split side gives two triangles, two give three (the quadrilateral cut
    along its shorter diagonal), three give four. Returns the new triangles and
    the index of the triangle each came from.
    """
    m = t.shape[0]
    out = np.empty((4 * m, 3), dtype=np.int64)
    parent = np.empty(4 * m, dtype=np.int64)
    n = 0
    for i in range(m):
        mids = np.empty(3, dtype=np.int64)
        count = 0
        for k in range(3):
            mids[k] = new_id[side_edge[i, k]]
            if mids[k] >= 0:
                count += 1
        if count == 0:
            out[n, 0] = t[i, 0]
            out[n, 1] = t[i, 1]
            out[n, 2] = t[i, 2]
            parent[n] = i
            n += 1
        elif count == 1:
            k = 0
            while mids[k] < 0:
                k += 1
            a = t[i, k]
            b = t[i, (k + 1) % 3]
            c = t[i, (k + 2) % 3]
            mk = mids[k]
            out[n, 0] = a
            out[n, 1] = mk
            out[n, 2] = c
            out[n + 1, 0] = mk
            out[n + 1, 1] = b
            out[n + 1, 2] = c
            parent[n] = i
            parent[n + 1] = i
            n += 2
        elif count == 2:
            # The split sides are k and k + 1 (cyclically).
            k = 0
            while not (mids[k] >= 0 and mids[(k + 1) % 3] >= 0):
                k += 1
            a = t[i, k]
            b = t[i, (k + 1) % 3]
            c = t[i, (k + 2) % 3]
            p = mids[k]
            q = mids[(k + 1) % 3]
            out[n, 0] = p
            out[n, 1] = b
            out[n, 2] = q
            if _dist2(v, a, q) <= _dist2(v, p, c):
                out[n + 1, 0] = a
                out[n + 1, 1] = p
                out[n + 1, 2] = q
                out[n + 2, 0] = a
                out[n + 2, 1] = q
                out[n + 2, 2] = c
            else:
                out[n + 1, 0] = a
                out[n + 1, 1] = p
                out[n + 1, 2] = c
                out[n + 2, 0] = p
                out[n + 2, 1] = q
                out[n + 2, 2] = c
            for r in range(3):
                parent[n + r] = i
            n += 3
        else:
            a = t[i, 0]
            b = t[i, 1]
            c = t[i, 2]
            p = mids[0]
            q = mids[1]
            r_ = mids[2]
            out[n, 0] = a
            out[n, 1] = p
            out[n, 2] = r_
            out[n + 1, 0] = p
            out[n + 1, 1] = b
            out[n + 1, 2] = q
            out[n + 2, 0] = r_
            out[n + 2, 1] = q
            out[n + 2, 2] = c
            out[n + 3, 0] = p
            out[n + 3, 1] = q
            out[n + 3, 2] = r_
            for r in range(4):
                parent[n + r] = i
            n += 4
    return out[:n].copy(), parent[:n].copy()


@njit(cache=True, nogil=True)
def dot(a, b):
    """Serial dot product: the same rounding whatever BLAS's thread count."""
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


# --- point location and scan conversion -----------------------------------------


@njit(cache=True, nogil=True)
def _lam(coef, t, x, y, z):
    dx = x - coef[t, 0]
    dy = y - coef[t, 1]
    dz = z - coef[t, 2]
    l1 = coef[t, 3] * dx + coef[t, 4] * dy + coef[t, 5] * dz
    l2 = coef[t, 6] * dx + coef[t, 7] * dy + coef[t, 8] * dz
    l3 = coef[t, 9] * dx + coef[t, 10] * dy + coef[t, 11] * dz
    return 1.0 - l1 - l2 - l3, l1, l2, l3


@njit(cache=True, nogil=True)
def scan_slab(v, tets, coef, val, order, nx, ny, k0, k1, claimed, voxels, values, where):
    """Evaluate a piecewise-linear map at the voxel centres of slices k0 <= k < k1.

    ``v`` holds the mesh's vertices in voxel index space (voxel (i, j, k) has
    its centre at (i, j, k)); ``val`` the map's values there. Tetrahedra are
    scan-converted in ``order``, slice by slice and row by row: along a row
    each barycentric coordinate is affine, so the centres inside form one
    interval. A centre on a shared face goes to the first tetrahedron in
    ``order``; ``claimed`` (one byte per voxel of the slab) records that.

    Returns the number of voxels found; their flat indices in the whole
    grid, values and tetrahedra are in ``voxels``, ``values``, ``where``.
    """
    count = 0
    for ii in range(order.shape[0]):
        t = order[ii]
        zmin = min(v[tets[t, 0], 2], v[tets[t, 1], 2], v[tets[t, 2], 2], v[tets[t, 3], 2])
        zmax = max(v[tets[t, 0], 2], v[tets[t, 1], 2], v[tets[t, 2], 2], v[tets[t, 3], 2])
        ka = max(int(math.ceil(zmin - 1e-7)), k0)
        kb = min(int(math.floor(zmax + 1e-7)), k1 - 1)
        if ka > kb:
            continue
        ymin = min(v[tets[t, 0], 1], v[tets[t, 1], 1], v[tets[t, 2], 1], v[tets[t, 3], 1])
        ymax = max(v[tets[t, 0], 1], v[tets[t, 1], 1], v[tets[t, 2], 1], v[tets[t, 3], 1])
        ja = max(int(math.ceil(ymin - 1e-7)), 0)
        jb = min(int(math.floor(ymax + 1e-7)), ny - 1)
        for k in range(ka, kb + 1):
            for j in range(ja, jb + 1):
                # lambda_m(x) = a_m + b_m x along the row.
                lo = 0.0
                hi = nx - 1.0
                a0, a1, a2, a3 = _lam(coef, t, 0.0, float(j), float(k))
                c0, c1, c2, c3 = _lam(coef, t, 1.0, float(j), float(k))
                empty = False
                for m in range(4):
                    a = a0 if m == 0 else (a1 if m == 1 else (a2 if m == 2 else a3))
                    c = c0 if m == 0 else (c1 if m == 1 else (c2 if m == 2 else c3))
                    b = c - a
                    if b > 0.0:
                        lo = max(lo, (-TOL - a) / b)
                    elif b < 0.0:
                        hi = min(hi, (-TOL - a) / b)
                    elif a < -TOL:
                        empty = True
                if empty or lo > hi:
                    continue
                ia = max(int(math.ceil(lo)), 0)
                ib = min(int(math.floor(hi)), nx - 1)
                base = (k * ny + j) * nx
                local = ((k - k0) * ny + j) * nx
                for i in range(ia, ib + 1):
                    if claimed[local + i]:
                        continue
                    l0, l1, l2, l3 = _lam(coef, t, float(i), float(j), float(k))
                    if l0 < -TOL or l1 < -TOL or l2 < -TOL or l3 < -TOL:
                        continue
                    claimed[local + i] = 1
                    voxels[count] = base + i
                    where[count] = t
                    p = tets[t, 0]
                    q = tets[t, 1]
                    r = tets[t, 2]
                    s = tets[t, 3]
                    for d in range(3):
                        values[count, d] = l0 * val[p, d] + l1 * val[q, d] + l2 * val[r, d] + l3 * val[s, d]
                    count += 1
    return count


@njit(cache=True, nogil=True)
def walk(points, tets, coef, nbr, other, max_steps, out, where):
    """Locate each point in a mesh by walking from the previous point's tetrahedron.

    ``coef`` and ``nbr`` describe the mesh the points live in; ``other``
    holds the same tetrahedra's vertices in the other mesh, where each point
    is interpolated into ``out[k]``; ``where[k]`` receives the tetrahedron.
    Devillers' remembering stochastic walk (a fixed xorshift sequence picks
    among the faces the point lies beyond, so it cannot cycle and results
    are deterministic). A walk that leaves the mesh or exceeds ``max_steps``
    sets ``where[k] = -1`` for the caller's bucket search.
    """
    hint = 0
    rng = np.uint32(2463534242)
    for p in range(points.shape[0]):
        x = points[p, 0]
        y = points[p, 1]
        z = points[p, 2]
        t = hint
        found = -1
        for _ in range(max_steps):
            l0, l1, l2, l3 = _lam(coef, t, x, y, z)
            if l0 >= -TOL and l1 >= -TOL and l2 >= -TOL and l3 >= -TOL:
                found = t
                break
            rng ^= rng << np.uint32(13)
            rng ^= rng >> np.uint32(17)
            rng ^= rng << np.uint32(5)
            first = int(rng % np.uint32(4))
            k = -1
            for j in range(4):
                kk = (first + j) % 4
                lk = l0 if kk == 0 else (l1 if kk == 1 else (l2 if kk == 2 else l3))
                if lk < -TOL:
                    k = kk
                    break
            t = nbr[t, k]
            if t < 0:
                break
        where[p] = found
        if found < 0:
            continue
        hint = found
        _interpolate(coef, tets, other, found, x, y, z, out, p, False)


@njit(cache=True, nogil=True)
def _interpolate(coef, tets, other, t, x, y, z, out, p, clamp):
    l0, l1, l2, l3 = _lam(coef, t, x, y, z)
    if clamp:
        l0 = max(l0, 0.0)
        l1 = max(l1, 0.0)
        l2 = max(l2, 0.0)
        l3 = max(l3, 0.0)
        s = l0 + l1 + l2 + l3
        l0 /= s
        l1 /= s
        l2 /= s
        l3 /= s
    a = tets[t, 0]
    b = tets[t, 1]
    c = tets[t, 2]
    d = tets[t, 3]
    for e in range(3):
        out[p, e] = l0 * other[a, e] + l1 * other[b, e] + l2 * other[c, e] + l3 * other[d, e]


@njit(cache=True, nogil=True)
def bucket_locate(points, start, items, lo, cell, dims, coef, snap, where, bary):
    """Locate points through a grid of buckets listing the tetrahedra that overlap each cell.

    ``where[p]`` receives the tetrahedron and ``bary[p]`` the point's
    barycentric coordinates in it. A point in no tetrahedron, but within
    ``snap`` (in barycentric terms) of the best one in its cell (a rounding
    error outside the mesh), is snapped onto that one's boundary (its
    coordinates clamped to [0, 1] and normalized); farther ones get
    ``where = -1``.
    """
    for p in range(points.shape[0]):
        x = points[p, 0]
        y = points[p, 1]
        z = points[p, 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            where[p] = -1
            continue
        a = min(max(int((x - lo[0]) / cell), 0), dims[0] - 1)
        b = min(max(int((y - lo[1]) / cell), 0), dims[1] - 1)
        c = min(max(int((z - lo[2]) / cell), 0), dims[2] - 1)
        k = (a * dims[1] + b) * dims[2] + c
        best = -1
        best_min = -1e300
        for s in range(start[k], start[k + 1]):
            t = items[s]
            l0, l1, l2, l3 = _lam(coef, t, x, y, z)
            m = min(l0, l1, l2, l3)
            if m > best_min:
                best_min = m
                best = t
                if m >= -TOL:
                    break
        if best < 0 or best_min < -snap:
            where[p] = -1
            continue
        where[p] = best
        l0, l1, l2, l3 = _lam(coef, best, x, y, z)
        if best_min < -TOL:
            l0 = max(l0, 0.0)
            l1 = max(l1, 0.0)
            l2 = max(l2, 0.0)
            l3 = max(l3, 0.0)
            s = l0 + l1 + l2 + l3
            l0 /= s
            l1 /= s
            l2 /= s
            l3 /= s
        bary[p, 0] = l0
        bary[p, 1] = l1
        bary[p, 2] = l2
        bary[p, 3] = l3


@njit(cache=True, nogil=True)
def build_buckets(v, tets, lo, cell, dims):
    """CSR lists of the tetrahedra whose bounding boxes overlap each cell."""
    m = tets.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    count = np.zeros(ncell + 1, dtype=np.int64)
    box = np.empty((m, 6), dtype=np.int64)
    for t in range(m):
        for d in range(3):
            x0 = min(v[tets[t, 0], d], v[tets[t, 1], d], v[tets[t, 2], d], v[tets[t, 3], d])
            x1 = max(v[tets[t, 0], d], v[tets[t, 1], d], v[tets[t, 2], d], v[tets[t, 3], d])
            box[t, d] = min(max(int((x0 - lo[d]) / cell), 0), dims[d] - 1)
            box[t, 3 + d] = min(max(int((x1 - lo[d]) / cell), 0), dims[d] - 1)
        for a in range(box[t, 0], box[t, 3] + 1):
            for b in range(box[t, 1], box[t, 4] + 1):
                for c in range(box[t, 2], box[t, 5] + 1):
                    count[(a * dims[1] + b) * dims[2] + c + 1] += 1
    for k in range(ncell):
        count[k + 1] += count[k]
    items = np.empty(count[ncell], dtype=np.int64)
    fill = count[:-1].copy()
    for t in range(m):
        for a in range(box[t, 0], box[t, 3] + 1):
            for b in range(box[t, 1], box[t, 4] + 1):
                for c in range(box[t, 2], box[t, 5] + 1):
                    k = (a * dims[1] + b) * dims[2] + c
                    items[fill[k]] = t
                    fill[k] += 1
    return count, items


@njit(cache=True, nogil=True)
def winding(points, v, t):
    """Generalized winding numbers of points with respect to a closed triangle surface (1 inside, 0 outside)."""
    out = np.empty(points.shape[0])
    for p in range(points.shape[0]):
        total = 0.0
        for f in range(t.shape[0]):
            ax = v[t[f, 0], 0] - points[p, 0]
            ay = v[t[f, 0], 1] - points[p, 1]
            az = v[t[f, 0], 2] - points[p, 2]
            bx = v[t[f, 1], 0] - points[p, 0]
            by = v[t[f, 1], 1] - points[p, 1]
            bz = v[t[f, 1], 2] - points[p, 2]
            cx = v[t[f, 2], 0] - points[p, 0]
            cy = v[t[f, 2], 1] - points[p, 1]
            cz = v[t[f, 2], 2] - points[p, 2]
            la = math.sqrt(ax * ax + ay * ay + az * az)
            lb = math.sqrt(bx * bx + by * by + bz * bz)
            lc = math.sqrt(cx * cx + cy * cy + cz * cz)
            det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
            den = la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la
            den += (cx * ax + cy * ay + cz * az) * lb
            total += 2.0 * math.atan2(det, den)
        out[p] = total / (4.0 * math.pi)
    return out


# --- resampling ----------------------------------------------------------------


@njit(cache=True, nogil=True)
def sample(volume, points, linear, out, ok):
    """Values of a volume (nz, ny, nx, C) at points (x, y, z) in voxel index space.

    Trilinear (``linear``) or nearest. A point beyond the volume's extent
    (more than half a voxel outside the centres) gets ``ok = False``; within
    it, neighbours beyond the edge are the edge's voxels.
    """
    nz, ny, nx, nc = volume.shape
    for p in range(points.shape[0]):
        x = points[p, 0]
        y = points[p, 1]
        z = points[p, 2]
        if not (x >= -0.5 and x <= nx - 0.5 and y >= -0.5 and y <= ny - 0.5 and z >= -0.5 and z <= nz - 0.5):
            ok[p] = False
            continue
        ok[p] = True
        if not linear:
            i = min(max(int(math.floor(x + 0.5)), 0), nx - 1)
            j = min(max(int(math.floor(y + 0.5)), 0), ny - 1)
            k = min(max(int(math.floor(z + 0.5)), 0), nz - 1)
            for c in range(nc):
                out[p, c] = volume[k, j, i, c]
            continue
        fx = math.floor(x)
        fy = math.floor(y)
        fz = math.floor(z)
        tx = x - fx
        ty = y - fy
        tz = z - fz
        i0 = min(max(int(fx), 0), nx - 1)
        j0 = min(max(int(fy), 0), ny - 1)
        k0 = min(max(int(fz), 0), nz - 1)
        i1 = min(max(int(fx) + 1, 0), nx - 1)
        j1 = min(max(int(fy) + 1, 0), ny - 1)
        k1 = min(max(int(fz) + 1, 0), nz - 1)
        for c in range(nc):
            c00 = volume[k0, j0, i0, c] * (1 - tx) + volume[k0, j0, i1, c] * tx
            c01 = volume[k0, j1, i0, c] * (1 - tx) + volume[k0, j1, i1, c] * tx
            c10 = volume[k1, j0, i0, c] * (1 - tx) + volume[k1, j0, i1, c] * tx
            c11 = volume[k1, j1, i0, c] * (1 - tx) + volume[k1, j1, i1, c] * tx
            out[p, c] = (c00 * (1 - ty) + c01 * ty) * (1 - tz) + (c10 * (1 - ty) + c11 * ty) * tz
