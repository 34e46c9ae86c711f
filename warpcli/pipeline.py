"""Pipeline: polygons -> meshes -> harmonic maps -> composed map -> resampled image."""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError, WarpError
from .imageio import RasterImage, atomic_path, check_output_path, convert_pixels, read_image, write_image
from .mapping import BijectiveMap, GridPullBack
from .metrics import Distortion, distortion_at_pixels, triangle_jacobians
from .polygon import Polygon, check_pair, read_polygon
from .resample import INTERPOLATIONS, EdgeCoverage, Footprint, edge_coverage, resample

log = logging.getLogger("warpcli")

#: The default resampling filter.
DEFAULT_INTERP = "linear"


@dataclass(frozen=True)
class WarpResult:
    """What a warp produced.

    Attributes
    ----------
    pixels : (H, W, C) ndarray
        The warped image, in the input's pixel type.
    map : BijectiveMap
    inverse_map : (H, W, 2) ndarray of float
        Source position of every output pixel centre; NaN outside the target.
    timings : dict of str to float
        Seconds per stage.
    source_triangle, target_triangle : (H, W) ndarray of int32
        Mesh triangles each output pixel went through (-1 outside).
    report : dict or None
        The report of `build_report`, when `warp_file` was asked for one.
    """

    pixels: NDArray
    map: BijectiveMap
    inverse_map: NDArray[np.float64]
    timings: dict[str, float] = field(default_factory=dict)
    source_triangle: NDArray[np.int32] | None = field(default=None, repr=False)
    target_triangle: NDArray[np.int32] | None = field(default=None, repr=False)
    report: dict | None = None

    def distortion(self) -> Distortion:
        """Distortion of the map at every output pixel (NaN outside the target)."""
        if self.source_triangle is None or self.target_triangle is None:
            raise ValueError("this result carries no per-pixel triangles")
        return distortion_at_pixels(self.map.phi0, self.map.phi1, self.source_triangle, self.target_triangle)


def pixel_centres(width: int, height: int) -> NDArray[np.float64]:
    """Centres of a ``width`` x ``height`` pixel grid, row by row, as (H*W, 2) points.

    >>> pixel_centres(2, 1).tolist()
    [[0.5, 0.5], [1.5, 0.5]]
    """
    x = np.arange(width, dtype=np.float64) + 0.5
    y = np.arange(height, dtype=np.float64) + 0.5
    xx, yy = np.meshgrid(x, y)
    return np.stack([xx.ravel(), yy.ravel()], axis=1)


def warp_image(
    image: ArrayLike,
    src: Polygon | ArrayLike,
    dst: Polygon | ArrayLike,
    *,
    size: tuple[int, int] | None = None,
    interp: str = DEFAULT_INTERP,
    background: float | ArrayLike = 0.0,
    alpha_channel: int | None = None,
    associated_alpha: bool = False,
    max_area: float | None = None,
    weights: str = "cotan",
    antialias: bool = True,
    warp_map: BijectiveMap | None = None,
    progress: Callable[[str], None] | None = None,
) -> WarpResult:
    """Warp an image so that polygon ``src`` goes onto polygon ``dst``.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        Pixels in any numeric type; the result has the same type.
    src, dst : Polygon or (n, 2) array_like of float
        Corresponding polygons: ``src`` in the input image's coordinates, ``dst``
        in the output's (x right, y down, pixel centres at +0.5).
    size : (width, height) or None
        Output size; the input's by default.
    interp : {"nearest", "linear", "cubic"}
    background : float or (C,) array_like
        Value of output pixels outside ``dst`` or whose pre-image lies outside
        the input, normalized: 0..1 spans an integer type's range, floats are
        taken as they are.
    alpha_channel : int or None
        Index of an alpha channel: colour is resampled premultiplied.
    associated_alpha : bool
        Whether the colour is already premultiplied by alpha.
    max_area : float or None
        Largest mesh triangle area in square pixels (None: automatic).
    weights : {"cotan", "positive"}
        Laplacian weights: the harmonic maps, or mean-value weights (see
        `BijectiveMap.between`).
    antialias : bool
        Antialias the target polygon's edge (``linear`` and ``cubic``), and
        with ``linear`` average each pixel over its footprint in the source
        where the map shrinks. ``nearest`` never blends.
    warp_map : BijectiveMap or None
        A map already built for these polygons, to reuse.
    progress : callable or None
        Called with the name of each stage as it starts.

    Returns
    -------
    WarpResult

    Examples
    --------
    >>> img = np.zeros((8, 8), dtype=np.uint8)
    >>> tri = [[1, 1], [7, 1], [1, 7]]
    >>> warp_image(img, tri, tri).pixels.shape
    (8, 8, 1)
    """
    timings: dict[str, float] = {}
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3:
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {img.shape}")
    src = src if isinstance(src, Polygon) else Polygon(src, name="src")
    dst = dst if isinstance(dst, Polygon) else Polygon(dst, name="dst")
    check_pair(src, dst)
    _check_interp(interp)
    width, height = size if size is not None else (img.shape[1], img.shape[0])
    bg = _background(background, img)

    stage = progress or (lambda name: None)
    fmap = warp_map
    if fmap is None:
        stage("meshing and solving")
        fmap = BijectiveMap.between(src, dst, max_area=max_area, weights=weights, timings=timings)
    clock = time.perf_counter
    t0 = clock()
    stage("composing the map")
    plan = _sampling(fmap, width, height, interp, antialias)
    t1 = clock()
    stage("resampling")
    out = _resample_with(plan, img, interp, bg, alpha_channel, associated_alpha)
    timings["compose"] = t1 - t0
    timings["resample"] = clock() - t1
    pulled = plan.pulled
    return WarpResult(out, fmap, pulled.inverse_map, timings, pulled.source_triangle, pulled.target_triangle)


@dataclass(frozen=True)
class _Sampling:
    """What a warp needs of the map on an output grid, whatever the image: where each
    pixel comes from and, with antialiasing, its footprint and the edge coverage."""

    pulled: GridPullBack
    footprint: Footprint | None
    coverage: EdgeCoverage | None


def _sampling(fmap: BijectiveMap, width: int, height: int, interp: str, antialias: bool) -> _Sampling:
    pulled = fmap.pull_back_grid(width, height)
    footprint = coverage = None
    if antialias and interp != "nearest":
        inside = np.isfinite(pulled.inverse_map[..., 0])
        coverage = edge_coverage(fmap.dst.points, fmap.src.points, width, height, inside)
        if interp == "linear":
            footprint = Footprint(
                pulled.source_triangle,
                pulled.target_triangle,
                triangle_jacobians(fmap.phi0, inverse=True),
                triangle_jacobians(fmap.phi1),
            )
    return _Sampling(pulled, footprint, coverage)


def _resample_with(
    plan: _Sampling, img: NDArray, interp: str, bg: NDArray, alpha_channel: int | None, associated_alpha: bool
) -> NDArray:
    return resample(
        img, plan.pulled.inverse_map, interp=interp, background=bg, alpha_channel=alpha_channel,
        associated_alpha=associated_alpha, footprint=plan.footprint, coverage=plan.coverage,
    )  # fmt: skip


def _write_like(path: str | os.PathLike[str], image: RasterImage, pixels: NDArray, dtype: str | None = None) -> None:
    """Write pixels made from ``image`` with its channel names, alpha, alpha convention
    and metadata, converted to ``dtype`` if given."""
    px = pixels if dtype is None else convert_pixels(pixels, dtype)
    write_image(path, RasterImage(px, image.channel_names, image.alpha_channel, image.attributes, image.associated_alpha))


def warp_file(
    input_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str],
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    *,
    report_path: str | os.PathLike[str] | None = None,
    grid_path: str | os.PathLike[str] | None = None,
    heatmap_path: str | os.PathLike[str] | None = None,
    heatmap_measure: str = "conformal",
    save_map: str | os.PathLike[str] | None = None,
    save_forward_map: str | os.PathLike[str] | None = None,
    stmap_t_up: bool = False,
    src_label: str | None = None,
    dst_label: str | None = None,
    dtype: str | None = None,
    **options,
) -> WarpResult:
    """Read an image and two polygon files, warp, and write the result atomically.

    Everything that can be checked before the work starts is checked first
    (polygons, input image, every output path), so bad input fails fast and
    leaves no file behind. ``options`` are those of `warp_image`.

    Parameters
    ----------
    report_path : path-like or None
        Write the JSON report of `build_report` there; ``"-"`` computes it
        (``result.report``) without writing a file.
    grid_path, heatmap_path : path-like or None
        Write `warpcli.figures.grid_figure` / `heatmap_figure` there.
    heatmap_measure : {"conformal", "isometric", "det"}
    save_map, save_forward_map : path-like or None
        Write the inverse map (output pixel -> input point) or the forward map
        (input pixel -> output point) as an STMap (see `warpcli.stmap`).
    stmap_t_up : bool
        Write STMaps with t running up (Nuke) instead of down (OpenImageIO).
    src_label, dst_label : str or None
        Which polygon to take from a polygon file holding several.
    dtype : {"uint8", "uint16", "half", "float"} or None
        Output pixel type; the input's by default.
    """
    clock = time.perf_counter
    stage = options.get("progress") or (lambda name: None)
    inputs = (input_path, src_path, dst_path)
    extra = [p for p in (grid_path, heatmap_path, save_map, save_forward_map) if p is not None]
    for path in (output_path, *extra):
        check_output_path(path, inputs=inputs)
    if report_path is not None and os.fspath(report_path) != "-":
        check_output_path(report_path, inputs=inputs, image=False)
    outputs = [os.path.abspath(os.fspath(p)) for p in (output_path, *extra, report_path) if p not in (None, "-")]
    if len(set(outputs)) != len(outputs):
        raise InputError(f"{os.fspath(output_path)}: the same path is given for two outputs")
    src = read_polygon(src_path, src_label)
    dst = read_polygon(dst_path, dst_label)
    check_pair(src, dst)
    t0 = clock()
    stage("reading")
    image = read_image(input_path)
    t_read = clock() - t0
    _warn_if_outside(src, image.width, image.height, os.fspath(input_path))
    if not ((src.signed_area > 0) == (dst.signed_area > 0)):
        log.info("%s and %s run in opposite directions: the warp mirrors the image", src.name, dst.name)
    result = warp_image(
        image.pixels, src, dst, alpha_channel=image.alpha_channel, associated_alpha=image.associated_alpha, **options
    )
    t0 = clock()
    stage("writing")
    _write_like(output_path, image, result.pixels, dtype)
    result.timings["read"] = t_read
    result.timings["write"] = clock() - t0
    if grid_path is not None or heatmap_path is not None:
        from . import figures

        t0 = clock()
        stage("drawing figures")
        if grid_path is not None:
            fig = figures.grid_figure(image.pixels, result.inverse_map, src, dst, alpha_channel=image.alpha_channel)
            write_image(grid_path, RasterImage(fig))
        if heatmap_path is not None:
            values = getattr(result.distortion(), heatmap_measure).reshape(result.inverse_map.shape[:2])
            write_image(heatmap_path, RasterImage(figures.heatmap_figure(values, heatmap_measure)))
        result.timings["figures"] = clock() - t0
    if save_map is not None or save_forward_map is not None:
        from .stmap import save_stmap

        t0 = clock()
        stage("saving maps")
        out_h, out_w = result.inverse_map.shape[:2]
        if save_map is not None:
            save_stmap(save_map, result.inverse_map, (image.width, image.height), kind="inverse", t_up=stmap_t_up)
        if save_forward_map is not None:
            fwd = result.map.forward_grid(image.width, image.height)
            save_stmap(save_forward_map, fwd, (out_w, out_h), kind="forward", t_up=stmap_t_up)
        result.timings["maps"] = clock() - t0
    if report_path is not None:
        stage("measuring distortion")
        doc = build_report(result)
        if os.fspath(report_path) != "-":
            with atomic_path(os.fspath(report_path)) as tmp:
                with open(tmp, "w") as fh:
                    json.dump(doc, fh, indent=2)
                    fh.write("\n")
        result = dataclasses.replace(result, report=doc)
    return result


@dataclass(frozen=True)
class BatchItem:
    """One input of a batch: where it went, and the error that stopped it, if any."""

    input_path: str
    output_path: str
    error: WarpError | None = None


def output_name(input_path: str | os.PathLike[str], pattern: str = "{name}") -> str:
    """The output file name for an input: ``pattern`` with ``{name}`` (the input's
    file name), ``{stem}`` (without extension) and ``{ext}`` (with its dot).

    >>> output_name("shots/frame_0001.png", "{stem}_warped.exr")
    'frame_0001_warped.exr'
    """
    name = os.path.basename(os.fspath(input_path))
    stem, ext = os.path.splitext(name)
    try:
        return pattern.format(name=name, stem=stem, ext=ext)
    except (KeyError, IndexError, ValueError) as err:
        raise InputError(f"output name pattern {pattern!r} is invalid: use {{name}}, {{stem}} and {{ext}}") from err


def warp_batch(
    input_paths: list[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    *,
    pattern: str = "{name}",
    src_label: str | None = None,
    dst_label: str | None = None,
    on_item: Callable[[BatchItem], None] | None = None,
    interp: str = DEFAULT_INTERP,
    background: float | ArrayLike = 0.0,
    size: tuple[int, int] | None = None,
    antialias: bool = True,
    max_area: float | None = None,
    weights: str = "cotan",
    dtype: str | None = None,
) -> list[BatchItem]:
    """Warp many images with one map: ``out_dir/<pattern>`` for each input.

    The options are those of `warp_image` and `warp_file`. The map is
    computed once, and its pull-back onto each output size once (inputs of one
    size share it). Every output path is checked before any work
    (a missing directory, an unknown format, two inputs with the same output,
    or an output that is one of the inputs is bad input, raised at once); an
    input that then fails (unreadable, not an image, a write error) is
    reported through ``on_item`` and the rest still go through.

    Returns
    -------
    list of BatchItem
        In input order.
    """
    directory = os.fspath(out_dir)
    if not os.path.isdir(directory):
        raise InputError(f"{directory}: output directory does not exist")
    outputs = [os.path.join(directory, output_name(p, pattern)) for p in input_paths]
    seen: dict[str, str] = {}
    for inp, out in zip(input_paths, outputs):
        key = os.path.abspath(out)
        if key in seen:
            raise InputError(f"{out}: both {seen[key]} and {os.fspath(inp)} would be written there")
        seen[key] = os.fspath(inp)
        check_output_path(out, inputs=(*input_paths, src_path, dst_path))
    src = read_polygon(src_path, src_label)
    dst = read_polygon(dst_path, dst_label)
    check_pair(src, dst)
    _check_interp(interp)
    fmap = BijectiveMap.between(src, dst, max_area=max_area, weights=weights)
    plans: dict[tuple[int, int], _Sampling] = {}
    items = []
    for inp, out in zip(input_paths, outputs):
        try:
            image = read_image(inp)
            shape = size if size is not None else (image.width, image.height)
            if shape not in plans:
                plans[shape] = _sampling(fmap, shape[0], shape[1], interp, antialias)
            bg = _background(background, image.pixels)
            px = _resample_with(plans[shape], image.pixels, interp, bg, image.alpha_channel, image.associated_alpha)
            _write_like(out, image, px, dtype)
            item = BatchItem(os.fspath(inp), out)
        except WarpError as err:
            item = BatchItem(os.fspath(inp), out, err)
        items.append(item)
        if on_item is not None:
            on_item(item)
    return items


def apply_map_file(
    map_path: str | os.PathLike[str],
    input_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str],
    *,
    interp: str = DEFAULT_INTERP,
    background: float | ArrayLike = 0.0,
    t_up: bool | None = None,
) -> NDArray:
    """Warp an image with a saved STMap (see `warpcli.stmap`); the output has the map's size.

    Returns
    -------
    ndarray
        The warped pixels, as written.
    """
    from .stmap import load_stmap

    check_output_path(output_path, inputs=(input_path, map_path))
    image = read_image(input_path)
    points = load_stmap(map_path, (image.width, image.height), t_up=t_up)
    bg = _background(background, image.pixels)
    out = resample(
        image.pixels, points, interp=interp, background=bg,
        alpha_channel=image.alpha_channel, associated_alpha=image.associated_alpha,
    )  # fmt: skip
    _write_like(output_path, image, out)
    return out


def _check_interp(interp: str) -> None:
    if interp not in INTERPOLATIONS:
        raise InputError(f"unknown interpolation {interp!r}; choose one of {', '.join(INTERPOLATIONS)}")


def _background(background: float | ArrayLike, img: NDArray) -> NDArray[np.float64]:
    """Normalized background values (0..1 spans an integer type) in the image's units."""
    nc = img.shape[2]
    bg = np.asarray(background, dtype=np.float64).ravel()
    if bg.size not in (1, nc):
        raise InputError(f"background has {bg.size} values but the image has {nc} channels")
    if np.issubdtype(img.dtype, np.integer):
        bg = bg * np.iinfo(img.dtype).max
    return bg


def build_report(result: WarpResult) -> dict:
    """The map's mesh sizes, fold-over count, Jacobian and distortion (the paper's Table 2).

    Distortion is sampled at the output pixels: each stands for the source
    area it pulls back (see `warpcli.metrics.distortion_at_pixels`), so the
    means are area-weighted means over the source polygon, and the maxima
    and ``min_jacobian_det`` are taken over the sampled points.
    """
    clock = time.perf_counter
    t0 = clock()
    summary = result.distortion().summary()
    f = result.map
    timings = dict(result.timings)
    timings["metrics"] = clock() - t0
    return {
        "vertices": f.src.n,
        "source_mesh": {"vertices": f.phi0.mesh.n_vertices, "triangles": f.phi0.mesh.n_triangles},
        "target_mesh": {"vertices": f.phi1.mesh.n_vertices, "triangles": f.phi1.mesh.n_triangles},
        "flipped_triangles": f.flipped_triangles(),
        "min_jacobian_det": summary["min_jacobian_det"],
        "conformal": summary["conformal"],
        "isometric": summary["isometric"],
        "timings": {k: round(v, 4) for k, v in timings.items()},
    }


def _warn_if_outside(src: Polygon, width: int, height: int, image_name: str) -> None:
    xmin, ymin, xmax, ymax = src.bounds
    if xmax <= 0 or ymax <= 0 or xmin >= width or ymin >= height:
        log.warning(
            "%s lies entirely outside %s (%dx%d): the output will be all background",
            src.name,
            image_name,
            width,
            height,
        )
