"""The volume pipeline: cages -> Theta -> tetrahedral meshes -> harmonic maps -> pull-back -> resampled volume."""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..outputs import PendingOutputs, write_checked
from . import _kernels
from .compose import IdentityMap, TetMap, VolumeMap, VolumeThetaMap
from .fem import solve_dirichlet
from .spans import folded, repair_edges, split_flat_spans, split_simplices
from .surface import Surface, check_pair, read_surface
from .tetmesh import Region, auto_edge, graded_from, mesh_polyhedron
from .theta import Theta, theta_for
from .volio import Volume, check_volume_output, encode_volume, read_volume

#: Rounds of splitting the edges of tetrahedra untangling leaves inverted,
#: then solving and untangling again (see `build_tet_map`).
REPAIR_ROUNDS = 3

#: Interpolations by name.
INTERPOLATIONS = ("linear", "nearest")


@dataclass
class VolumeWarpResult:
    """What `warp_volume` made: the output volume, the map, and the seconds each stage took."""

    volume: Volume
    map: VolumeMap
    timings: dict = field(default_factory=dict)
    inside: int = 0


def build_map(
    src: Surface,
    dst: Surface,
    theta: str | os.PathLike[str] = "auto",
    *,
    edge: float | None = None,
    voxel: float = 1.0,
    solver: str = "auto",
    grade: bool = True,
    untangle: bool = True,
    region: Region | None = None,
) -> VolumeMap:
    """Build f between two checked cages: choose Theta, mesh, solve, untangle.

    Parameters
    ----------
    src, dst : Surface
        Cages with the same connectivity (checked here).
    theta : str or path-like
        A strategy of `warpcli.volume.theta.theta_for` or a mesh file.
    edge : float or None
        Nominal tetrahedron edge length in the cages' units; the default
        is `warpcli.volume.tetmesh.auto_edge` of each cage.
    voxel : float
        The voxel size in the cages' units: the finest the default mesh gets.
    solver : str
        See `warpcli.volume.fem.solve_dirichlet`.
    grade : bool
        Refine towards concave edges.
    untangle : bool
        Move the images of the nodes of inverted tetrahedra into the kernels
        of their stars (`warpcli.volume.untangle`); False keeps the discrete
        harmonic maps as they are.
    region : (lo, hi) pair of (3,) arrays, or None
        The box the map is used in (a volume's, `VoxelGrid.bounds`): a cage
        reaching far beyond it is meshed graded from it
        (`warpcli.volume.tetmesh.graded_from`).

    Returns
    -------
    VolumeMap
        Its ``timings`` hold the seconds per stage, summed over both maps.

    Raises
    ------
    SurfaceError
        If the cages do not correspond, or Theta is unusable.
    MeshingError
        If meshing or solving fails.
    """
    check_pair(src, dst)
    t0 = time.perf_counter()
    th = theta_for(src, dst, theta)
    timings = {"theta": time.perf_counter() - t0}
    maps: list[VolumeThetaMap] = []
    same = np.array_equal(src.vertices, dst.vertices)
    for k, cage in enumerate((src, dst)):
        if th.cage == k or (th.cage is not None and same):
            maps.append(IdentityMap(cage, th))
        elif k == 1 and same and isinstance(maps[0], TetMap):
            m0 = maps[0]
            maps.append(TetMap(cage, th, mesh=m0.mesh, values=m0.values, info=m0.info, harmonic=m0.harmonic))  # type: ignore[attr-defined]
        else:
            maps.append(
                build_tet_map(
                    cage, th, edge=edge, voxel=voxel, solver=solver, grade=grade, untangle=untangle, timings=timings,
                    region=region,
                )  # fmt: skip
            )
    result = VolumeMap(maps[0], maps[1])
    result.timings.update(timings)
    return result


def build_tet_map(
    cage: Surface,
    theta: Theta,
    *,
    edge: float | None = None,
    voxel: float = 1.0,
    solver: str = "auto",
    grade: bool = True,
    untangle: bool = True,
    timings: dict | None = None,
    region: Region | None = None,
) -> TetMap:
    """The harmonic map of one cage onto Theta: mesh, P1 Laplacian, Dirichlet solve, then untangled
    (`warpcli.volume.untangle.untangle`) unless ``untangle`` is False.

    Before the solve, the interior edges and faces whose image would lie in
    Theta's boundary are split (`warpcli.volume.spans.split_flat_spans`).
    Where untangling leaves tetrahedra inverted or flat, an edge of each is
    split (`warpcli.volume.spans.repair_edges`) and the map solved and
    untangled again, up to `REPAIR_ROUNDS` times.

    ``info["untangle"]`` says how many tetrahedra were inverted before and
    after (in the last round), and how many nodes moved; the map keeps the
    harmonic values (`TetMap.harmonic`) when any moved.
    """
    from .untangle import MAX_INVERTED
    from .untangle import untangle as untangle_map

    timings = {} if timings is None else timings
    h = auto_edge(cage, voxel, region) if edge is None else float(edge)
    t0 = time.perf_counter()
    mesh = mesh_polyhedron(cage, h, grade=grade, region=region)
    mesh, split = split_flat_spans(mesh, theta.vertices, cage.triangles)
    timings["mesh"] = timings.get("mesh", 0.0) + time.perf_counter() - t0
    # The boundary nodes and their values stay as they are through the splits (new nodes are interior).
    boundary_values = mesh.boundary_values(theta.vertices, cage.triangles)
    base = {"edge": h, "graded_from_region": graded_from(cage, region), **split}
    repaired = 0
    start = None
    best = None  # the round that left the fewest tetrahedra folded: a repair can make things worse
    for round_ in range(REPAIR_ROUNDS + 1):
        t1 = time.perf_counter()
        values, info = solve_dirichlet(mesh, boundary_values, solver, start)
        t2 = time.perf_counter()
        timings["solve"] = timings.get("solve", 0.0) + t2 - t1
        harmonic = None
        info = {**base, **info}
        if not untangle:
            break
        done = untangle_map(values, mesh.tets, mesh.on_boundary)
        info["untangle"] = done.describe()
        if len(done.moved):
            harmonic, values = values, done.values
        timings["untangle"] = timings.get("untangle", 0.0) + time.perf_counter() - t2
        bad = folded(mesh, values)  # what the certificate counts (`TetMap.flipped`)
        if best is None or bad.sum() < best[0]:
            best = (int(bad.sum()), mesh, values, info, harmonic, repaired)
        # A map that folds at large (untangling skipped it: more than MAX_INVERTED) is not mended by a few splits.
        if not bad.any() or round_ == REPAIR_ROUNDS or done.inverted_before > MAX_INVERTED:
            break
        edges = repair_edges(mesh, bad)
        if not len(edges):
            break
        t3 = time.perf_counter()
        applied: list[bool] = []
        new_mesh = split_simplices(mesh, list(edges), applied)
        if not any(applied):
            break
        # The next solve starts from this one's, the new nodes at their edges' midpoints.
        solved = values if harmonic is None else harmonic
        start = np.concatenate([solved, solved[edges[np.array(applied)]].mean(axis=1)])
        mesh = new_mesh
        repaired += int(sum(applied))
        timings["mesh"] = timings.get("mesh", 0.0) + time.perf_counter() - t3
    if best is not None:
        _, mesh, values, info, harmonic, repaired = best
        info["untangle"]["repaired_edges"] = repaired
    return TetMap(cage, theta, mesh=mesh, values=values, info=info, harmonic=harmonic)


def warp_volume(
    volume: Volume,
    vmap: VolumeMap,
    *,
    interpolation: str = "linear",
    background: float = 0.0,
) -> VolumeWarpResult:
    """Warp a volume through a map: every output voxel centre inside the target takes the
    input's value at its pre-image; the rest is ``background``.

    The output has the input's grid (shape and affine) and data type; integer
    types are rounded and clipped to their range.

    Parameters
    ----------
    volume : Volume
    vmap : VolumeMap
        Cages in the volume's world coordinates.
    interpolation : {"linear", "nearest"}
        Trilinear or nearest-voxel resampling.
    background : float
        The value outside the target (and where a pre-image falls outside
        the input volume): a value of the volume's type (`check_background`).

    Returns
    -------
    VolumeWarpResult
    """
    if interpolation not in INTERPOLATIONS:
        raise InputError(f"unknown interpolation {interpolation!r}; use one of {', '.join(INTERPOLATIONS)}")
    check_background(background, volume.data.dtype)
    t0 = time.perf_counter()
    data = volume.data
    dtype = data.dtype
    nc = data.shape[3]
    out = np.empty(data.shape, dtype=dtype)
    bg = _cast(np.full((1, nc), float(background)), dtype)
    out[...] = bg.reshape(1, 1, 1, nc)
    flat_out = out.reshape(-1, nc)
    # The kernels read no half floats: sample a float32 copy (exact), cast back at the end.
    samples = data.astype(np.float32) if dtype == np.float16 else data
    grid = volume.grid
    inside = 0
    for voxels, points in vmap.pull_back_slabs(grid):
        ok_pre = np.isfinite(points[:, 0])
        idx = np.ascontiguousarray(grid.to_index(points[ok_pre]))
        vals = np.empty((len(idx), nc))
        ok = np.empty(len(idx), dtype=np.bool_)
        _kernels.sample(samples, idx, interpolation == "linear", vals, ok)
        target = voxels[ok_pre][ok]
        flat_out[target] = _cast(vals[ok], dtype)
        inside += int(len(voxels))
    timings = dict(vmap.timings)
    timings["warp"] = time.perf_counter() - t0
    return VolumeWarpResult(Volume(out, grid, volume.format, volume.header), vmap, timings, inside)


def check_background(background: float, dtype: np.dtype, name: str = "the volume") -> None:
    """Refuse a background value the volume's type cannot hold: NaN or infinite for an integer
    type, or outside its range (a floating type takes any value, NaN included, as NIfTI masks use).

    Raises
    ------
    InputError
    """
    value = float(background)
    dtype = np.dtype(dtype)
    if dtype.kind in "iub":
        lo, hi = (0, 1) if dtype.kind == "b" else (np.iinfo(dtype).min, np.iinfo(dtype).max)
        if not (lo <= value <= hi):  # NaN fails too
            raise InputError(f"{name}: --background {background!r} is not a value of its type {dtype.name} ({lo}..{hi})")


def _cast(values: np.ndarray, dtype: np.dtype) -> np.ndarray:
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        return np.clip(np.rint(values), info.min, info.max).astype(dtype)
    if dtype == np.bool_:
        return values >= 0.5
    return values.astype(dtype)


def warp_volume_file(
    input: str | os.PathLike[str],
    output: str | os.PathLike[str],
    src: str | os.PathLike[str],
    dst: str | os.PathLike[str],
    *,
    theta: str | os.PathLike[str] = "auto",
    interpolation: str = "linear",
    background: float = 0.0,
    edge: float | None = None,
    solver: str = "auto",
    untangle: bool = True,
    check: bool = True,
    report: str | os.PathLike[str] | None = None,
    picture: str | os.PathLike[str] | None = None,
) -> VolumeWarpResult:
    """Read a volume and two cages, warp, write: the one call ``warp volume`` makes.

    Every input is checked before any work (cages read and validated, output
    paths writable and not inputs); the output volume, the JSON report and
    the picture are written together or not at all (`PendingOutputs`).

    Parameters
    ----------
    input, output : path-like
        NIfTI (``.nii``, ``.nii.gz``; cages in world coordinates, mm) or
        multi-page TIFF (``.tif``; cages in voxel coordinates, voxel
        (i, j, k) centred at (i + 0.5, j + 0.5, k + 0.5)). The output takes
        the input's format, grid and data type.
    src, dst : path-like
        Cages with the same connectivity (OBJ, OFF or PLY).
    theta : str or path-like
        ``auto``, ``source``, ``target``, ``sphere`` or a mesh file.
    interpolation : {"linear", "nearest"}
    background : float
    edge : float or None
        Nominal tetrahedron edge length, in the cages' units.
    solver : str
    untangle : bool
        Untangle the discrete harmonic maps (see `build_map`).
    check : bool
        Refuse (`FoldOverError`) a map that flips any tetrahedron (after
        untangling): nothing is written. False writes it anyway, with a
        warning (the CLI's ``--allow-folds``).
    report : path-like or None
        Write the report (JSON) there.
    picture : path-like or None
        Write the report's picture (PNG) there: three orthogonal slices of
        input and output with a grid carried through the map.

    Returns
    -------
    VolumeWarpResult

    Raises
    ------
    InputError
        Bad volume, cages, Theta or paths (the CLI's exit 2).
    MeshingError, FoldOverError, ImageIOError
        Otherwise.
    """
    inputs = tuple(p for p in (input, src, dst) if p is not None)
    if not (isinstance(theta, str) and theta in ("auto", "source", "target", "sphere")):
        inputs += (theta,)
    check_volume_output(output, inputs)
    from ..outputs import check_output_path

    for extra in (report, picture):
        if extra is not None:
            check_output_path(extra, inputs + (output,))
    a = read_surface(src)
    b = read_surface(dst)
    check_pair(a, b)
    volume = read_volume(input)
    check_background(background, volume.data.dtype, os.fspath(input))
    voxel = float(np.cbrt(abs(np.linalg.det(volume.grid.affine[:3, :3]))))
    t0 = time.perf_counter()
    vmap = build_map(a, b, theta, edge=edge, voxel=voxel, solver=solver, untangle=untangle, region=volume.grid.bounds())
    vmap.timings["build"] = time.perf_counter() - t0
    if check:
        vmap.check_bijective()
    else:
        c0, c1 = vmap.certificates()
        if not (c0.ok and c1.ok):
            logging.getLogger("warpcli").warning(
                "the maps flip %d tetrahedra of %s and %d of %s: the warp folds the volume there (written as asked)",
                c0.flipped, a.name, c1.flipped, b.name,
            )  # fmt: skip
    result = warp_volume(volume, vmap, interpolation=interpolation, background=background)
    body = encode_volume(result.volume, output)
    extras = []
    rgb = None
    if report is not None or picture is not None:
        from .report import build_report, report_picture

        if report is not None:
            import json

            extras.append((report, (json.dumps(build_report(result), indent=2) + "\n").encode()))
        if picture is not None:
            rgb = report_picture(volume, result)
    with PendingOutputs() as pending:
        write_checked(pending.path(output), body, output)
        for path, data in extras:
            write_checked(pending.path(path), data, path)
        if rgb is not None:
            from ..raster.imageio import RasterImage, write_image

            write_image(pending.path(picture), RasterImage(rgb))
    return result
