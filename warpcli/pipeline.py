"""Pipeline: polygons -> maps onto Theta -> composed map -> resampled image; the calls the CLI makes."""

from __future__ import annotations

import contextvars
import dataclasses
import functools
import json
import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError, WarpError
from .maps.compose import BijectiveMap, PullBack
from .options import WarpOptions
from .polygon import Polygon, check_pair, read_polygon
from .budget import check_fits
from .outputs import PendingOutputs, check_output_path, write_checked
from .raster.imageio import (
    ImageHeader,
    RasterImage,
    check_image_output,
    convert_pixels,
    read_header,
    read_image,
    write_image,
)
from .raster.pixels import unit
from .raster.resample import EdgeCoverage, edge_coverage, resample
from .report import build_report
from .report.metrics import Distortion, distortion

__all__ = [
    "BatchItem", "WarpResult", "apply_map_file", "build_report", "output_name", "warp_batch", "warp_file", "warp_image",
]  # fmt: skip

log = logging.getLogger("warpcli")


@dataclass(frozen=True)
class WarpResult:
    """What a warp produced.

    Attributes
    ----------
    pixels : (H, W, C) ndarray
        The warped image, in the input's pixel type (H, W: the output's
        height and width).
    map : BijectiveMap
    pull : PullBack
        The inverse map and its Jacobians in the window of output pixels
        around the target polygon (see `warpcli.maps.compose.PullBack`).
    timings : dict of str to float
        Seconds per stage.
    report : dict or None
        The report of `build_report`, when `warp_file` was asked for one.
    """

    pixels: NDArray
    map: BijectiveMap
    pull: PullBack = field(repr=False)
    timings: dict[str, float] = field(default_factory=dict)
    report: dict | None = None

    @cached_property
    def inverse_map(self) -> NDArray[np.float64]:
        """(H, W, 2): the source point of every output pixel centre; NaN outside the target."""
        return self.pull.full_points()

    @cached_property
    def jacobian(self) -> NDArray[np.float64] | None:
        """(H, W, 2, 2): the Jacobian of the inverse map at every output pixel (d source / d
        output); NaN outside the target; None if the warp kept none."""
        return None if self.pull.jacobian is None else self.pull.spread(self.pull.jacobian)

    def measure(self, name: str) -> NDArray[np.float64]:
        """One distortion measure at every output pixel: (H, W), NaN outside the target.

        Parameters
        ----------
        name : {"conformal", "isometric", "det", "weight"}
            See `warpcli.report.metrics.Distortion`.

        Returns
        -------
        (H, W) ndarray of float

        Raises
        ------
        ValueError
            If the result kept no Jacobians.
        """
        from .report.metrics import measure

        if self.pull.jacobian is None:
            raise ValueError("this result kept no Jacobians")
        return self.pull.spread(measure(self.pull.jacobian, name))

    def distortion(self) -> Distortion:
        """Distortion of the map at every output pixel (flattened, row-major; NaN outside the target).

        Raises
        ------
        ValueError
            If the result kept no Jacobians.
        """
        if self.pull.jacobian is None:
            raise ValueError("this result kept no Jacobians")
        d = distortion(self.pull.jacobian)
        shape = self.pull.points.shape[:2]
        return Distortion(*(self.pull.spread(v.reshape(shape)).ravel() for v in dataclasses.astuple(d)))


def _options(options: WarpOptions | None, changes: dict[str, Any]) -> WarpOptions:
    opts = options if options is not None else WarpOptions()
    if not isinstance(opts, WarpOptions):
        raise InputError(f"options must be WarpOptions, got {type(opts).__name__}")
    return opts.changed(**changes) if changes else opts


def warp_image(
    image: ArrayLike,
    src: Polygon | ArrayLike,
    dst: Polygon | ArrayLike,
    options: WarpOptions | None = None,
    *,
    alpha_channel: int | None = None,
    associated_alpha: bool = False,
    warp_map: BijectiveMap | None = None,
    progress: Callable[[str], None] | None = None,
    **changes: Any,
) -> WarpResult:
    """Warp an image so that polygon ``src`` goes onto polygon ``dst``.

    Parameters
    ----------
    image : (H, W) or (H, W, C) array_like
        Pixels in any numeric type; the result has the same type.
    src, dst : Polygon or (n, 2) array_like of float
        Corresponding polygons: ``src`` in the input image's coordinates, ``dst``
        in the output's (x right, y down, pixel centres at +0.5).
    options : WarpOptions or None
        Map, resampling and output options; the defaults otherwise.
    alpha_channel : int or None
        Index of an alpha channel: colour is resampled premultiplied.
    associated_alpha : bool
        Whether the colour is already premultiplied by alpha.
    warp_map : BijectiveMap or None
        A map already built between these polygons, to reuse.
    progress : callable or None
        Called with the name of each stage as it starts.
    **changes
        Fields of `WarpOptions` or `MapOptions` to change, e.g.
        ``interp="cubic"`` or ``max_area=4``.

    Returns
    -------
    WarpResult

    Raises
    ------
    InputError
        For a bad image shape, polygons or options (also a `ValueError`).
    FoldOverError
        If the map would fold the image (never written).

    References
    ----------
    Schneider & Hormann, Smooth bijective maps between arbitrary planar
    polygons, CAGD 2015, eq. (2) and §4.1.

    Examples
    --------
    >>> img = np.zeros((8, 8), dtype=np.uint8)
    >>> tri = [[1, 1], [7, 1], [1, 7]]
    >>> warp_image(img, tri, tri).pixels.shape
    (8, 8, 1)
    """
    opts = _options(options, changes)
    return _warp(image, src, dst, opts, alpha_channel, associated_alpha, warp_map, progress)


def _warp(
    image: ArrayLike,
    src: Polygon | ArrayLike,
    dst: Polygon | ArrayLike,
    opts: WarpOptions,
    alpha_channel: int | None,
    associated_alpha: bool,
    warp_map: BijectiveMap | None,
    progress: Callable[[str], None] | None,
    early: _EarlyMap | None = None,
) -> WarpResult:
    """`warp_image`, taking the map from ``early`` when it was built for this image's size."""
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3 or 0 in img.shape:
        raise InputError(f"image must be a non-empty (H, W) or (H, W, C) array, got shape {img.shape}")
    if img.dtype.kind not in "uif":
        raise InputError(f"image must hold numbers, got dtype {img.dtype}")
    src = src if isinstance(src, Polygon) else Polygon(src, name="src")
    dst = dst if isinstance(dst, Polygon) else Polygon(dst, name="dst")
    check_pair(src, dst)
    width, height = opts.size if opts.size is not None else (img.shape[1], img.shape[0])
    _check_paste(opts, (width, height), (img.shape[1], img.shape[0]), "the input")
    # The output in the working type, and per pixel of the window the source
    # point and the Jacobian (2 + 4 float64): refuse what cannot fit at once.
    check_fits(width, height, img.shape[2] + 12, 4, f"an output of {width}x{height}")
    bg = _background(opts.background, img)
    stage = progress or (lambda name: None)
    timings: dict[str, float] = {}
    fmap = warp_map
    if fmap is None:
        stage("optimizing Theta and building the map" if opts.map.theta == "optimized" else "building the map")
        regions = ((0.0, 0.0, float(img.shape[1]), float(img.shape[0])), (0.0, 0.0, float(width), float(height)))
        if early is not None and early.regions == regions:
            fmap = early.take()
        else:
            fmap = BijectiveMap.between(src, dst, opts.map, regions=regions)
        timings.update(fmap.timings)
    elif not (_same_polygon(fmap.src, src) and _same_polygon(fmap.dst, dst)):
        raise InputError("warp_map was built between other polygons than src and dst")
    clock = time.perf_counter
    t0 = clock()
    stage("composing the map")
    plan = _sampling(fmap, width, height, opts, keep_jacobian=True)
    t1 = clock()
    stage("resampling")
    out = _resample_with(plan, img, opts, bg, alpha_channel, associated_alpha, fmap.src)
    timings["compose"] = t1 - t0
    timings["resample"] = clock() - t1
    return WarpResult(out, fmap, plan.pull, timings)


def _same_polygon(a: Polygon, b: Polygon) -> bool:
    return a.points.shape == b.points.shape and bool(np.array_equal(a.points, b.points))


@dataclass(frozen=True)
class _Sampling:
    """What a warp needs of the map on an output grid, whatever the image: where each
    pixel of the window around the target comes from, the Jacobians there, and the
    edge coverage."""

    pull: PullBack
    coverage: EdgeCoverage | None
    # Resample with the Jacobians: footprints where the map shrinks (linear),
    # coverage along the pre-image of the input's border (linear and cubic).
    jacobians: bool


def _sampling(fmap: BijectiveMap, width: int, height: int, opts: WarpOptions, *, keep_jacobian: bool) -> _Sampling:
    jacobians = opts.antialias and opts.interp != "nearest"
    pull = fmap.pull_back(width, height, jacobian=keep_jacobian or jacobians)
    coverage = None
    if opts.antialias and opts.interp != "nearest":
        cov = edge_coverage(fmap.dst.points, np.isfinite(pull.points[..., 0]), pull.origin)
        coverage = dataclasses.replace(cov, source_points=fmap.inverse_boundary(cov.edge, cov.t))
    return _Sampling(pull, coverage, jacobians)


def _check_paste(opts: WarpOptions, size: tuple[int, int], input_size: tuple[int, int], name: str) -> None:
    """``outside="input"`` pastes the warp over its input: the sizes must agree."""
    if opts.outside == "input" and tuple(size) != tuple(input_size):
        raise InputError(
            f"--outside input pastes the warp over {name}, so the output must have its size "
            f"{input_size[0]}x{input_size[1]}, not {size[0]}x{size[1]}"
        )


def _resample_with(
    plan: _Sampling,
    img: NDArray,
    opts: WarpOptions,
    bg: NDArray,
    alpha_channel: int | None,
    associated_alpha: bool,
    src: Polygon,
) -> NDArray:
    """The whole output: the window around the target resampled, the background (or, with
    ``outside="input"``, the input: `warpcli.composite`) elsewhere."""
    if opts.outside == "input":
        from .composite import paste_over

        def warp(pixels: NDArray, alpha: int) -> NDArray:
            return _resample_window(plan, pixels, opts, np.zeros(pixels.shape[2]), alpha, True)

        return paste_over(
            img, warp, src=src.points, background=bg, alpha_channel=alpha_channel,
            associated_alpha=associated_alpha, vacated=opts.vacated,
        )  # fmt: skip
    return _resample_window(plan, img, opts, bg, alpha_channel, associated_alpha)


def _resample_window(
    plan: _Sampling, img: NDArray, opts: WarpOptions, bg: NDArray, alpha_channel: int | None, associated_alpha: bool
) -> NDArray:
    """The window around the target resampled, ``bg`` elsewhere."""

    def sample(points, jacobian=None, coverage=None):
        return resample(
            img, points, interp=opts.interp, background=bg, alpha_channel=alpha_channel,
            associated_alpha=associated_alpha, jacobian=jacobian, coverage=coverage,
        )  # fmt: skip

    pull = plan.pull
    width, height = pull.size
    window = sample(pull.points, pull.jacobian if plan.jacobians else None, plan.coverage)
    if window.shape[:2] == (height, width):
        return window
    # Pixels outside the window have no pre-image: the background, exactly as
    # the resampler writes it for such a pixel (rounded, alpha convention).
    out = np.empty((height, width, window.shape[2]), dtype=window.dtype)
    out[:] = sample(np.full((1, 1, 2), np.nan))[0, 0]
    r, c = pull.origin
    out[r : r + window.shape[0], c : c + window.shape[1]] = window
    return out


def _write_like(path: str | os.PathLike[str], image: RasterImage, pixels: NDArray, dtype: str | None = None) -> None:
    """Write pixels made from ``image`` with its channel names, alpha, alpha convention
    and metadata, converted to ``dtype`` if given."""
    px = pixels if dtype is None else convert_pixels(pixels, dtype)
    write_image(path, RasterImage(px, image.channel_names, image.alpha_channel, image.attributes, image.associated_alpha))


#: Log records held back by the thread building an `_EarlyMap` (and the threads it
#: starts, which inherit the context): None everywhere else.
_HELD_RECORDS: contextvars.ContextVar[list | None] = contextvars.ContextVar("warpcli_held_records", default=None)


def _hold_back(record: logging.LogRecord) -> bool:
    held = _HELD_RECORDS.get()
    if held is None:
        return True
    held.append(record)
    return False


class _EarlyMap:
    """The map of `warp_file`, built on a thread from the image's size while its pixels are read.

    Started only when `warp_image`'s checks of that size will pass, so it
    refuses what it always did, before any map. Its log records (a repair's
    warning, an optimization's progress) are held back and given out when
    the map is taken, where building it logged them before; if the map is
    never taken (the image cannot be read), they are dropped with it.
    """

    def __init__(self, src: Polygon, dst: Polygon, opts: WarpOptions, regions: tuple) -> None:
        from .maps.compose import Task

        self.regions = regions
        self._records: list[logging.LogRecord] = []
        log.addFilter(_hold_back)  # once: the same function
        context = contextvars.copy_context()
        context.run(_HELD_RECORDS.set, self._records)
        build = functools.partial(BijectiveMap.between, src, dst, opts.map, regions=regions)
        self._task = context.run(Task, build, name="warp-map")

    def take(self) -> BijectiveMap:
        """The map once built (or its error), after its held-back log records."""
        try:
            return self._task.result()
        finally:
            for record in self._records:
                log.handle(record)

    @classmethod
    def start(cls, header: ImageHeader | None, src: Polygon, dst: Polygon, opts: WarpOptions) -> _EarlyMap | None:
        """Start building the map for an image with this header (None: unread, then no map is started)."""
        if header is None:
            return None
        (w, h), channels = header.displayed_size, header.channels
        width, height = opts.size if opts.size is not None else (w, h)
        try:
            _check_paste(opts, (width, height), (w, h), "the input")
            check_fits(width, height, channels + 12, 4, f"an output of {width}x{height}")
            _background(opts.background, np.zeros((1, 1, channels)))
        except WarpError:
            return None  # warp_image refuses it later, in its own order
        regions = ((0.0, 0.0, float(w), float(h)), (0.0, 0.0, float(width), float(height)))
        return cls(src, dst, opts, regions)


def warp_file(
    input_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str],
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    options: WarpOptions | None = None,
    *,
    report_path: str | os.PathLike[str] | None = None,
    save_theta: str | os.PathLike[str] | None = None,
    grid_path: str | os.PathLike[str] | None = None,
    heatmap_path: str | os.PathLike[str] | None = None,
    heatmap_measure: str = "conformal",
    save_map: str | os.PathLike[str] | None = None,
    save_forward_map: str | os.PathLike[str] | None = None,
    stmap_t_up: bool = False,
    src_label: str | None = None,
    dst_label: str | None = None,
    progress: Callable[[str], None] | None = None,
    tiled: bool | None = None,
    **changes: Any,
) -> WarpResult:
    """Read an image and two polygon files, warp, and write the result atomically.

    Everything that can be checked before the work starts is checked first
    (polygons, input image, every output path), so bad input fails fast and
    leaves no file behind.

    Parameters
    ----------
    input_path, output_path : path-like
        The image to warp and where to write the result (format by extension).
    src_path, dst_path : path-like
        Polygon files (plain JSON, labelme or GeoJSON).
    options : WarpOptions or None
        As for `warp_image`; ``**changes`` change its fields.
    report_path : path-like or None
        Write the JSON report of `build_report` there; ``"-"`` computes it
        (``result.report``) without writing a file.
    save_theta : path-like or None
        Write the Theta the map used as JSON (``{"points": [[x, y], ...]}``),
        to pass back as ``theta`` (a file) to later runs.
    grid_path, heatmap_path : path-like or None
        Write `warpcli.report.figures.grid_figure` / `heatmap_figure` there.
    heatmap_measure : {"conformal", "isometric", "det"}
    save_map, save_forward_map : path-like or None
        Write the inverse map (output pixel -> input point) or the forward map
        (input pixel -> output point) as an STMap (see `warpcli.raster.stmap`).
    stmap_t_up : bool
        Write STMaps with t running up (Nuke) instead of down (OpenImageIO).
    src_label, dst_label : str or None
        Which polygon to take from a polygon file holding several.
    progress : callable or None
        Called with the name of each stage as it starts.
    tiled : bool or None
        Warp in strips, never holding the whole image (`warpcli.tiled`):
        True always, None (the default) when a whole warp would not fit in
        memory. The output is the same; the result then has no pixels (they
        are in the file), and the report, figures and STMaps are refused.

    Returns
    -------
    WarpResult or warpcli.tiled.TiledResult

    Raises
    ------
    InputError
        For bad polygons, images, options or output paths (a `PolygonError`
        or `ImageInputError` names the file).
    WarpError
        If processing fails (a write error, a map that would fold).
    """
    opts = _options(options, changes)
    from .options import HEATMAP_MEASURES

    if heatmap_measure not in HEATMAP_MEASURES:
        raise InputError(f"unknown heatmap measure {heatmap_measure!r}; choose one of {', '.join(HEATMAP_MEASURES)}")
    clock = time.perf_counter
    stage = progress or (lambda name: None)
    inputs = (input_path, src_path, dst_path)
    extra = [p for p in (grid_path, heatmap_path, save_map, save_forward_map) if p is not None]
    for path in (output_path, *extra):
        check_image_output(path, inputs=inputs)
    if report_path is not None and os.fspath(report_path) != "-":
        check_output_path(report_path, inputs=inputs)
    if save_theta is not None:
        check_output_path(save_theta, inputs=inputs)
    from .raster.stmap import check_stmap_path

    for path in (save_map, save_forward_map):
        if path is not None:
            check_stmap_path(path)
    outputs = [
        os.path.abspath(os.fspath(p)) for p in (output_path, *extra, report_path, save_theta) if p not in (None, "-")
    ]
    if len(set(outputs)) != len(outputs):
        raise InputError(f"{os.fspath(output_path)}: the same path is given for two outputs")
    src = read_polygon(src_path, src_label)
    dst = read_polygon(dst_path, dst_label)
    check_pair(src, dst)
    header = _header(input_path)
    if _in_parts(input_path, header, opts, tiled):
        return _warp_file_tiled(
            input_path, output_path, src, dst, opts, progress,
            {"--report": report_path, "--grid": grid_path, "--heatmap": heatmap_path, "--save-map": save_map,
             "--save-forward-map": save_forward_map},
            save_theta, header,
        )  # fmt: skip
    # The map needs the image's size, not its pixels: it is built on other
    # threads while the pixels are decoded (the decoder releases the GIL).
    early = _EarlyMap.start(header, src, dst, opts)
    t0 = clock()
    stage("reading")
    image = read_image(input_path)
    t_read = clock() - t0
    _warn_if_outside(src, (image.width, image.height), os.fspath(input_path), "all background")
    out_size = opts.size if opts.size is not None else (image.width, image.height)
    _warn_if_outside(dst, out_size, os.fspath(output_path), "all background")
    if not ((src.signed_area > 0) == (dst.signed_area > 0)):
        log.warning(
            "%s and %s run in opposite directions: the warp mirrors the image (reverse one file's vertex order "
            "if that is not what you want)",
            src.name,
            dst.name,
        )
    result = _warp(image.pixels, src, dst, opts, image.alpha_channel, image.associated_alpha, None, progress, early)
    # Every output is written under a pending name and renamed into place
    # only when all are written: a run's outputs succeed or fail together.
    with PendingOutputs() as pending:
        t0 = clock()
        stage("writing")
        _write_like(pending.path(output_path), image, result.pixels, opts.dtype)
        result.timings["read"] = t_read
        result.timings["write"] = clock() - t0
        if grid_path is not None or heatmap_path is not None:
            from .report import figures

            t0 = clock()
            stage("drawing figures")
            if grid_path is not None:
                fig = figures.grid_figure(image.pixels, result.inverse_map, src, dst, alpha_channel=image.alpha_channel)
                write_image(pending.path(grid_path), figures.picture(fig))
            if heatmap_path is not None:
                values = result.measure(heatmap_measure)
                write_image(pending.path(heatmap_path), figures.picture(figures.heatmap_figure(values, heatmap_measure)))
            result.timings["figures"] = clock() - t0
        if save_map is not None or save_forward_map is not None:
            from .raster.stmap import save_stmap

            t0 = clock()
            stage("saving maps")
            out_h, out_w = result.pull.size[1], result.pull.size[0]
            if save_map is not None:
                save_stmap(
                    pending.path(save_map), result.inverse_map, (image.width, image.height), kind="inverse",
                    t_up=stmap_t_up,
                )  # fmt: skip
            if save_forward_map is not None:
                fwd = result.map.forward_grid(image.width, image.height)
                save_stmap(pending.path(save_forward_map), fwd, (out_w, out_h), kind="forward", t_up=stmap_t_up)
            result.timings["maps"] = clock() - t0
        if save_theta is not None:
            theta = result.map.theta
            _write_json(pending.path(save_theta), {"theta": theta.name, "points": theta.points.tolist()})
        if report_path is not None:
            stage("measuring distortion")
            doc = build_report(result)
            if os.fspath(report_path) != "-":
                _write_json(pending.path(report_path), doc)
            result = dataclasses.replace(result, report=doc)
    return result


def _header(input_path) -> ImageHeader | None:
    """The image's header, or None if it cannot be read (`read_image` then says why)."""
    try:
        return read_header(input_path)
    except WarpError:
        return None


def _in_parts(input_path, header: ImageHeader | None, opts: WarpOptions, tiled: bool | None) -> bool:
    """Whether `warp_file` warps in strips: asked to, or a whole warp would not fit in memory."""
    if tiled is not None:
        return bool(tiled)
    if header is None:
        return False
    from .tiled import check_plausible, tiled_needed

    width, height = opts.size if opts.size is not None else (header.width, header.height)
    if not tiled_needed(header, width, height):
        return False
    check_plausible(input_path, header)
    return True


def _warp_file_tiled(input_path, output_path, src, dst, opts, progress, refused: dict, save_theta, header):
    from .tiled import warp_file_tiled

    used = [name for name, value in refused.items() if value is not None]
    if used:
        raise InputError(
            f"{os.fspath(input_path)}: {', '.join(used)} needs the whole image in memory, and it is warped in parts "
            "(it does not fit, or --tiled was given)"
        )
    with PendingOutputs() as pending:
        result = warp_file_tiled(input_path, pending.path(output_path), src, dst, opts, progress=progress, header=header)
        if save_theta is not None:
            theta = result.map.theta
            _write_json(pending.path(save_theta), {"theta": theta.name, "points": theta.points.tolist()})
    return result


def _write_json(path: str, doc: dict) -> None:
    """Write a JSON document, checked (see `warpcli.outputs.write_checked`)."""
    write_checked(path, (json.dumps(doc, indent=2) + "\n").encode())


@dataclass(frozen=True)
class BatchItem:
    """One input of a batch: where it went, and the error that stopped it, if any."""

    input_path: str
    output_path: str
    error: WarpError | None = None


def output_name(input_path: str | os.PathLike[str], pattern: str = "{name}") -> str:
    """The output file name for an input: ``pattern`` with ``{name}`` (the input's
    file name), ``{stem}`` (without extension) and ``{ext}`` (with its dot).

    Only those three fields, without attributes, indices or conversions, and
    the result must be a plain file name (no directory part, not ``.`` or
    ``..``), so that outputs stay inside the output directory.

    Raises
    ------
    InputError
        If the pattern uses anything else or names another directory.

    Examples
    --------
    >>> output_name("shots/frame_0001.png", "{stem}_warped.exr")
    'frame_0001_warped.exr'
    """
    import string

    name = os.path.basename(os.fspath(input_path))
    stem, ext = os.path.splitext(name)
    fields = {"name": name, "stem": stem, "ext": ext}
    bad = InputError(f"output name pattern {pattern!r} is invalid: use {{name}}, {{stem}} and {{ext}} and plain text")
    try:
        pieces = list(string.Formatter().parse(pattern))
    except ValueError as err:
        raise bad from err
    out = []
    for text, field_name, spec, conversion in pieces:
        out.append(text)
        if field_name is None:
            continue
        if field_name not in fields or spec or conversion:
            raise bad
        out.append(fields[field_name])
    result = "".join(out)
    if not result or result in (".", "..") or "/" in result or os.sep in result or "\0" in result:
        raise InputError(f"output name pattern {pattern!r} gives {result!r}, which is not a file name in the output directory")
    return result


def warp_batch(
    input_paths: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    options: WarpOptions | None = None,
    *,
    pattern: str = "{name}",
    src_label: str | None = None,
    dst_label: str | None = None,
    on_item: Callable[[BatchItem], None] | None = None,
    jobs: int = 1,
    **changes: Any,
) -> list[BatchItem]:
    """Warp many images with one map: ``out_dir/<pattern>`` for each input.

    The map is computed once, and its pull-back onto each output size once
    (inputs of one size share it). With ``jobs`` > 1 the images are read,
    resampled and written by that many threads (the compiled kernels and
    OpenImageIO release the GIL); every output's bytes are those of
    ``jobs=1``.

    Parameters
    ----------
    input_paths : sequence of path-like
        The images.
    out_dir : path-like
        An existing directory.
    src_path, dst_path : path-like
        Polygon files.
    options : WarpOptions or None
        As for `warp_image`; ``**changes`` change its fields.
    pattern : str
        Output file name, see `output_name`.
    src_label, dst_label : str or None
        Which polygon to take from a polygon file holding several.
    on_item : callable or None
        Called with each `BatchItem` as it is done, in input order.
    jobs : int
        Threads warping images at once.

    Returns
    -------
    list of BatchItem
        In input order.

    Raises
    ------
    InputError
        At once, before any work, for bad polygons or options, a missing
        directory, an unknown format, two inputs with the same output, or an
        output that is one of the inputs. An input that fails later
        (unreadable, not an image, a write error) is reported through
        ``on_item`` and in its item, and the rest still go through.
    """
    opts = _options(options, changes)
    tasks, src, dst = _batch_setup(input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label)
    fmap = BijectiveMap.between(src, dst, opts.map)
    plans = _Plans(fmap, opts)
    return _each(lambda task: _warp_one(task[0], task[1], plans, opts, src), tasks, jobs, on_item)


def _batch_setup(input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label):
    """A batch's checks before any work: (input, output) pairs, and the two polygons."""
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
        check_image_output(out, inputs=(*input_paths, src_path, dst_path))
    src = read_polygon(src_path, src_label)
    dst = read_polygon(dst_path, dst_label)
    check_pair(src, dst)
    return [(os.fspath(inp), out) for inp, out in zip(input_paths, outputs)], src, dst


class _Plans:
    """A map's pull-back per output size, made once and shared by threads."""

    def __init__(self, fmap: BijectiveMap, opts: WarpOptions) -> None:
        import threading

        self.fmap, self.opts = fmap, opts
        self._plans: dict[tuple[int, int], _Sampling] = {}
        self._lock = threading.Lock()

    def get(self, shape: tuple[int, int]) -> _Sampling:
        with self._lock:
            if shape not in self._plans:
                self._plans[shape] = _sampling(self.fmap, shape[0], shape[1], self.opts, keep_jacobian=False)
            return self._plans[shape]


def _warp_one(inp: str, out: str, plans: _Plans, opts: WarpOptions, src: Polygon) -> BatchItem:
    """One image of a batch or sequence: read, resample, write; its error in the item.

    An image too large for memory is warped in strips (`warpcli.tiled`) with the same map."""
    try:
        fmap = getattr(plans, "fmap", None)  # a Dask worker has the pull-backs only
        header = _header(inp) if fmap is not None else None
        if header is not None and _in_parts(inp, header, opts, None):
            from .tiled import warp_file_tiled

            warp_file_tiled(inp, out, fmap.src, fmap.dst, opts, fmap=fmap, header=header)
            return BatchItem(inp, out)
        image = read_image(inp)
        shape = opts.size if opts.size is not None else (image.width, image.height)
        _check_paste(opts, shape, (image.width, image.height), inp)
        plan = plans.get(shape)
        bg = _background(opts.background, image.pixels)
        px = _resample_with(plan, image.pixels, opts, bg, image.alpha_channel, image.associated_alpha, src)
        _write_like(out, image, px, opts.dtype)
        return BatchItem(inp, out)
    except WarpError as err:
        return BatchItem(inp, out, err)


def _each(work: Callable, tasks: list, jobs: int, on_item: Callable[[BatchItem], None] | None) -> list[BatchItem]:
    """``work`` over ``tasks`` on ``jobs`` threads; items (and ``on_item`` calls) in task order."""
    if not (isinstance(jobs, int) and jobs >= 1):
        raise InputError(f"jobs must be a whole number of at least 1, got {jobs!r}")
    items: list[BatchItem] = []
    if jobs == 1 or len(tasks) <= 1:
        results = map(work, tasks)
        pool = None
    else:
        from concurrent.futures import ThreadPoolExecutor

        pool = ThreadPoolExecutor(max_workers=jobs, thread_name_prefix="warp-job")
        results = pool.map(work, tasks)
    try:
        for item in results:
            items.append(item)
            if on_item is not None:
                on_item(item)
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    return items


def warp_sequence(
    input_pattern: str,
    output_pattern: str,
    frames: Sequence[int],
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    options: WarpOptions | None = None,
    *,
    src_label: str | None = None,
    dst_label: str | None = None,
    on_item: Callable[[BatchItem], None] | None = None,
    jobs: int = 1,
    **changes: Any,
) -> list[BatchItem]:
    """Warp the frames of an image sequence; the polygon files may hold keyframes.

    Frame paths follow oiiotool's conventions (`warpcli.sequence`: ``#`` is
    4 digits, ``@`` one, ``%04d``). A polygon file with ``{"frames": {...}}``
    gives each frame its polygon, linear between keyframes and held outside
    them (`warpcli.keyframes`); a map is built only when a frame's pair
    differs from the previous frame's, so still polygons cost one map for
    the whole sequence (the paper's §6: with one Theta, the maps of
    successive steps compose to the map of the whole step).

    Parameters
    ----------
    input_pattern, output_pattern : str
        Sequence patterns; the output's must differ from the input's.
    frames : sequence of int
        The frames, in order (`warpcli.sequence.parse_frames`).
    src_path, dst_path : path-like
        Polygon files, still or keyframed.
    options : WarpOptions or None
        As for `warp_image`; ``**changes`` change its fields.
    src_label, dst_label : str or None
        Which polygon of a file holding several (in every keyframe).
    on_item : callable or None
        Called with each `BatchItem` as it is done, in frame order.
    jobs : int
        Threads warping frames at once (as in `warp_batch`).

    Returns
    -------
    list of BatchItem
        In frame order.

    Raises
    ------
    InputError
        At once, before any work: bad patterns, polygons (at any frame) or
        options, an output that is an input. A frame that fails later (a
        missing or unreadable image, a write error) is reported through
        ``on_item`` and in its item, and the rest go on.
    """
    from .keyframes import read_animated
    from .sequence import expand, parse_pattern

    opts = _options(options, changes)
    if parse_pattern(os.fspath(output_pattern)) is None:
        raise InputError(f"{output_pattern}: the output of a sequence must be a pattern too (#, @ or %04d)")
    if parse_pattern(os.fspath(output_pattern)).pattern == parse_pattern(os.fspath(input_pattern)).pattern:
        raise InputError(f"{output_pattern}: the output pattern is the input pattern; frames would be overwritten")
    ins = expand(os.fspath(input_pattern), frames)
    outs = expand(os.fspath(output_pattern), frames)
    for (_, inp), (_, out) in zip(ins, outs):
        check_image_output(out, inputs=(inp, src_path, dst_path))
    src_keys = read_animated(src_path, src_label)
    dst_keys = read_animated(dst_path, dst_label)
    # Every frame's polygons first (interpolation can self-intersect): errors before any work.
    pairs = {}
    for f, _ in ins:
        if f not in pairs:
            pairs[f] = (src_keys.at(f), dst_keys.at(f))
            check_pair(*pairs[f])
    # Runs of frames with the same pair share one map; the frames of a run go to the threads.
    runs: list[tuple[tuple[bytes, bytes], list[tuple[str, str]]]] = []
    for (f, inp), (_, out) in zip(ins, outs):
        src, dst = pairs[f]
        key = (src.points.tobytes(), dst.points.tobytes())
        if not runs or runs[-1][0] != key:
            runs.append((key, []))
        runs[-1][1].append((inp, out, f))
    items: list[BatchItem] = []
    for _, tasks in runs:
        src, dst = pairs[tasks[0][2]]
        try:
            plans = _Plans(BijectiveMap.between(src, dst, opts.map), opts)
        except WarpError as err:  # a map that cannot be built fails its frames, not the others
            done = [BatchItem(inp, out, err) for inp, out, _ in tasks]
            for item in done:
                if on_item is not None:
                    on_item(item)
            items += done
            continue
        items += _each(lambda task: _warp_one(task[0], task[1], plans, opts, src), tasks, jobs, on_item)
    return items


def apply_map_file(
    map_path: str | os.PathLike[str],
    input_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str],
    options: WarpOptions | None = None,
    *,
    t_up: bool | None = None,
    **changes: Any,
) -> NDArray:
    """Warp an image with a saved STMap (see `warpcli.raster.stmap`); the output has the map's size.

    Parameters
    ----------
    map_path, input_path, output_path : path-like
    options : WarpOptions or None
        ``interp``, ``background`` and ``dtype`` are used; ``**changes``
        change them.
    t_up : bool or None
        Which way the map's t runs; None: as its header says.

    Returns
    -------
    ndarray
        The warped pixels, as written.

    Raises
    ------
    InputError
        For a bad map, image or output path.
    """
    from .raster.stmap import load_stmap

    opts = _options(options, changes)
    check_image_output(output_path, inputs=(input_path, map_path))
    image = read_image(input_path)
    points = load_stmap(map_path, (image.width, image.height), t_up=t_up)
    bg = _background(opts.background, image.pixels)
    out = resample(
        image.pixels, points, interp=opts.interp, background=bg,
        alpha_channel=image.alpha_channel, associated_alpha=image.associated_alpha,
    )  # fmt: skip
    _write_like(output_path, image, out, opts.dtype)
    return out


def _background(background: float | ArrayLike, img: NDArray) -> NDArray[np.float64]:
    """Normalized background values (0..1 spans an integer type) in the image's units."""
    nc = img.shape[2]
    bg = np.asarray(background, dtype=np.float64).ravel()
    if bg.size not in (1, nc):
        raise InputError(f"background has {bg.size} values but the image has {nc} channels")
    # Values beyond what the output type holds are clipped there anyway; clip
    # them first, so that they blend as the value written and cannot overflow.
    if np.issubdtype(img.dtype, np.integer):
        bg = np.clip(bg, 0.0, 1.0)
    else:
        top = float(np.finfo(np.float32 if img.dtype != np.float64 else np.float64).max)
        bg = np.clip(bg, -top, top)
    return bg * unit(img.dtype)


def _warn_if_outside(poly: Polygon, size: tuple[int, int], image_name: str, consequence: str) -> None:
    """Warn when a polygon misses an image of ``size`` (width, height) entirely."""
    xmin, ymin, xmax, ymax = poly.bounds
    width, height = size
    if xmax <= 0 or ymax <= 0 or xmin >= width or ymin >= height:
        log.warning(
            "%s lies entirely outside %s (%dx%d): the output will be %s", poly.name, image_name, width, height,
            consequence,
        )  # fmt: skip
