"""The volume report: 3D distortion of the map at sampled voxels, inversion counts, and a picture of three slices."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .. import distortion as measures
from .compose import VolumeMap, VoxelGrid, safe_inverse

#: The distortion is measured at about this many output voxels (a regular subgrid).
SAMPLES = 200_000

#: Grid lines of the picture every this many input voxels.
GRID_STEP = 8


def distortion(jacobian: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
    """3D distortion measures of a stack of Jacobians (K, 3, 3) of f.

    Returns
    -------
    dict of (K,) arrays
        ``conformal``: (s1^2 + s2^2 + s3^2) / (s1 s2 s3)^(2/3), the 3D MIPS
        energy (3 for a similarity, as the 2D s1/s2 + s2/s1 is 2);
        ``isometric``: max(s1, 1 / s3) (1 for a rigid motion); ``det``.

    Examples
    --------
    >>> m = distortion(np.array([2.0 * np.eye(3)]))
    >>> [round(float(m[k][0]), 12) for k in ("conformal", "isometric", "det")]
    [3.0, 2.0, 8.0]
    """
    # The measures of `warpcli.distortion`, taken on J itself (rather than on
    # J^-1, as the 2D report does) because that is how these numbers were first
    # rounded; the two agree up to rounding.
    finite = np.isfinite(jacobian).all(axis=(1, 2))
    s = tuple(np.full(len(jacobian), np.nan) for _ in range(3))
    for k, sk in enumerate(measures.singular_values(jacobian[finite])):
        s[k][finite] = sk
    det = np.full(len(jacobian), np.nan)
    det[finite] = measures.determinant(jacobian[finite])
    conformal = measures.conformal(s, det)
    isometric = measures.isometric(s)
    return {"conformal": conformal, "isometric": isometric, "det": det}


def sample_voxels(grid: VoxelGrid, vmap: VolumeMap, samples: int = SAMPLES) -> NDArray[np.float64]:
    """World coordinates of output voxel centres on a regular subgrid of the target's bounding box."""
    nx, ny, nz = grid.shape
    idx = grid.to_index(vmap.dst.vertices)
    lo = np.clip(np.floor(idx.min(axis=0)), 0, [nx - 1, ny - 1, nz - 1]).astype(int)
    hi = np.clip(np.ceil(idx.max(axis=0)), 0, [nx - 1, ny - 1, nz - 1]).astype(int)
    count = np.prod(hi - lo + 1)
    step = max(1, int(np.ceil((count / samples) ** (1 / 3))))
    axes = [np.arange(lo[d], hi[d] + 1, step) for d in range(3)]
    i, j, k = np.meshgrid(*axes, indexing="ij")
    return grid.to_world(np.column_stack([i.ravel(), j.ravel(), k.ravel()]).astype(np.float64))


def build_report(result) -> dict:
    """The report of a volume warp (`warpcli.volume.pipeline.VolumeWarpResult`) as JSON-ready data."""
    vmap: VolumeMap = result.map
    grid = result.volume.grid
    points = sample_voxels(grid, vmap)
    pre, jac_inv = vmap.inverse_mapped(points)
    ok = np.isfinite(pre[:, 0]) & np.isfinite(jac_inv).all(axis=(1, 2))
    summary: dict = {"samples": int(ok.sum())}
    if ok.any():
        jac = safe_inverse(jac_inv[ok])
        m = distortion(jac)
        weight = np.abs(np.linalg.det(jac_inv[ok]))  # source volume each sample stands for
        good = np.isfinite(m["conformal"]) & np.isfinite(m["isometric"])
        w = weight[good]
        summary.update(
            {
                "min_jacobian_det": float(np.nanmin(m["det"])),
                "inverted_samples": int((m["det"] <= 0).sum()),
                "singular_samples": int((~np.isfinite(m["det"])).sum()),
                "conformal": {"mean": float((m["conformal"][good] * w).sum() / w.sum()), "max": float(m["conformal"][good].max())},
                "isometric": {"mean": float((m["isometric"][good] * w).sum() / w.sum()), "max": float(m["isometric"][good].max())},
            }
        )  # fmt: skip
    c0, c1 = vmap.certificates()
    moved = vmap.untangling_displacement()
    voxel = float(np.cbrt(abs(np.linalg.det(grid.affine[:3, :3]))))
    untangling = {
        "source": _untangle_info(vmap.phi0), "target": _untangle_info(vmap.phi1),
        "max_displacement_voxels": 0.0 if moved is None else round(moved / voxel, 4),
    }  # fmt: skip
    return {
        "source": vmap.src.name,
        "target": vmap.dst.name,
        "theta": {"name": vmap.theta.name, "convex": vmap.theta.convex, **vmap.theta.notes},
        "maps": {"source": vmap.phi0.describe(), "target": vmap.phi1.describe()},
        "flipped_tetrahedra": {"source": c0.flipped, "target": c1.flipped},
        "untangling": untangling,
        "output_voxels_inside": int(result.inside),
        "distortion": summary,
        "timings": {k: round(v, 4) for k, v in result.timings.items()},
    }


def _untangle_info(phi) -> dict | None:
    """Inverted tetrahedra of the harmonic map and of the untangled one, and the nodes moved; None without a mesh."""
    info = getattr(phi, "info", {}).get("untangle")
    return dict(info) if info else None


def report_picture(volume, result, step: int = GRID_STEP) -> NDArray[np.uint8]:
    """The report's picture: three orthogonal slices through the target's centre, input above and
    output below, with a grid of input planes every ``step`` voxels drawn on the input and carried
    through the map.

    Returns
    -------
    (H, W, 3) ndarray of uint8
        RGB, to write with `warpcli.raster.imageio.write_image` (a PNG
        without a time stamp: the same bytes run after run).
    """
    vmap: VolumeMap = result.map
    grid = volume.grid
    nx, ny, nz = grid.shape
    centre = np.clip(np.round(grid.to_index(vmap.dst.vertices).mean(axis=0)).astype(int), 0, [nx - 1, ny - 1, nz - 1])
    lo, hi = np.percentile(volume.data[..., 0], [1, 99])
    panels_in, panels_out = [], []
    for axis in (2, 1, 0):  # slices across z (axial), y, x
        free = [d for d in range(3) if d != axis]
        sizes = [grid.shape[d] for d in free]
        a, b = np.meshgrid(np.arange(sizes[0]), np.arange(sizes[1]), indexing="xy")
        idx = np.zeros((a.size, 3))
        idx[:, free[0]] = a.ravel()
        idx[:, free[1]] = b.ravel()
        idx[:, axis] = centre[axis]
        flat = ((idx[:, 2] * ny + idx[:, 1]) * nx + idx[:, 0]).astype(np.int64)
        src_img = _grey(volume.data[..., 0].reshape(-1)[flat], lo, hi).reshape(b.shape)
        out_img = _grey(result.volume.data[..., 0].reshape(-1)[flat], lo, hi).reshape(b.shape)
        on_in = _on_grid(idx, step)
        pre = vmap.inverse(grid.to_world(idx))
        on_out = _on_grid(grid.to_index(pre), step)
        panels_in.append(_overlay(src_img, on_in.reshape(b.shape)))
        panels_out.append(_overlay(out_img, on_out.reshape(b.shape)))
    return _tile([panels_in, panels_out])


def _grey(values, lo, hi) -> NDArray[np.uint8]:
    t = (np.asarray(values, dtype=np.float64) - lo) / max(hi - lo, 1e-300)
    return (np.clip(t, 0, 1) * 255).astype(np.uint8)


def _on_grid(index: NDArray[np.float64], step: int) -> NDArray[np.bool_]:
    with np.errstate(invalid="ignore"):
        r = np.abs(((index + step / 2) % step) - step / 2)
    return (r < 0.5).any(axis=1) & np.isfinite(index[:, 0])


def _overlay(grey: NDArray[np.uint8], lines: NDArray[np.bool_]) -> NDArray[np.uint8]:
    rgb = np.repeat(grey[..., None], 3, axis=2)
    rgb[lines] = (230, 40, 40)
    return rgb


def _tile(rows: list[list[NDArray[np.uint8]]], gap: int = 4) -> NDArray[np.uint8]:
    h = max(p.shape[0] for row in rows for p in row)
    w = [max(rows[r][c].shape[1] for r in range(len(rows))) for c in range(len(rows[0]))]
    out = np.full((len(rows) * (h + gap) - gap, sum(w) + gap * (len(w) - 1), 3), 255, dtype=np.uint8)
    for r, row in enumerate(rows):
        x = 0
        for c, p in enumerate(row):
            y = r * (h + gap)
            out[y : y + p.shape[0], x : x + p.shape[1]] = p[::-1]  # rows upwards, as a viewer shows them
            x += w[c] + gap
    return out
