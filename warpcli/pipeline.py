"""Image and file warps: polygons -> map -> sampling plan -> resampled image -> files, checked and atomic.

Batches and sequences (many images, one map) are `warpcli.batch`; images
larger than memory go strip by strip through `warpcli.tiled`; what a pixel
gets is decided once, by `warpcli.plan.SamplingPlan`.
"""

from __future__ import annotations

import contextvars
import dataclasses
import functools
import json
import logging
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._cached import cached_property
from .annotations import warp_labels
from .budget import check_fits
from .cores import budget
from .errors import ImageInputError, InputError, WarpError, naming
from .keyframes import read_shape_at
from .maps.cage import map_between
from .maps.compose import BijectiveMap, PullBack, children_at_once
from .options import WarpOptions, resolve_options
from .outputs import PendingOutputs, check_distinct, check_output_path, write_checked
from .plan import SamplingPlan, as_image, background_values, check_paste, plan_for, warn_if_outside
from .polygon import Polygon
from .polygon.partition import Partition, check_shapes
from .raster.imageio import (
    ImageHeader,
    RasterImage,
    check_image_output,
    check_writes,
    convert_pixels,
    output_format,
    read_header,
    read_image,
    ready_to_write,
    with_compression,
    write_image,
)
from .raster.peek import png_size
from .report import build_report
from .tiled import TiledResult, check_plausible, in_parts, warp_file_tiled

if TYPE_CHECKING:  # imported where used: a default warp needs neither (5-10 ms of every run's start)
    from .report.metrics import Distortion
    from .within import WithinPair

__all__ = [
    "WarpResult", "apply_map_file", "build_report", "check_output", "read_header_or_none", "warp_file", "warp_image",
    "write_like",
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
    plan : SamplingPlan or None
        The sampling plan the pixels were rendered with: render it again on
        another image of the input's size and type for the same warp.
    within : WithinPair or None
        With ``within``: the cage mesh of the cages and the ring
        (`warpcli.within.within_pair`) the map was built between.
    """

    pixels: NDArray
    map: BijectiveMap
    pull: PullBack = field(repr=False)
    timings: dict[str, float] = field(default_factory=dict)
    report: dict | None = None
    plan: SamplingPlan | None = field(default=None, repr=False)
    within: WithinPair | None = field(default=None, repr=False)

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
        from .report.metrics import Distortion, distortion

        if self.pull.jacobian is None:
            raise ValueError("this result kept no Jacobians")
        d = distortion(self.pull.jacobian)
        shape = self.pull.points.shape[:2]
        return Distortion(*(self.pull.spread(v.reshape(shape)).ravel() for v in dataclasses.astuple(d)))


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
    src, dst : Polygon, Partition or (n, 2) array_like of float
        Corresponding polygons: ``src`` in the input image's coordinates, ``dst``
        in the output's (x right, y down, pixel centres at +0.5); or two cage
        meshes with the same faces (`warpcli.maps.cage`). With ``within``,
        also a list of such cages on each side (several cages in one outline).
    options : WarpOptions or None
        Map, resampling and output options; the defaults otherwise.
    alpha_channel : int or None
        Index of an alpha channel: colour is resampled premultiplied.
    associated_alpha : bool
        Whether the colour is already premultiplied by alpha.
    warp_map : BijectiveMap, CageMap or None
        A map already built between these polygons (or cage meshes), to reuse.
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
    opts = resolve_options(options, changes)
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
    pair: WithinPair | None = None,
    streamed: list | None = None,
) -> WarpResult:
    """`warp_image`, taking the map from ``early`` when it was built for this image's size.

    ``pair``: the cage mesh of ``within`` already made from ``src`` and ``dst`` (then they are its sides).
    ``streamed``: a list to which, where the output can be made band by band (`_streams`), the
    `_RowsMade` that makes it on a thread is appended; the result's pixels are then being made
    when this returns, and are all made once that has been iterated to its end.
    """
    img = as_image(image)
    if opts.within is not None and pair is None:
        from .within import within_pair

        pair = within_pair(_cages_of(src, "src"), _cages_of(dst, "dst"), opts.within, (img.shape[1], img.shape[0]))
        src, dst = pair.src, pair.dst
    src = src if isinstance(src, (Polygon, Partition)) else Polygon(src, name="src")
    dst = dst if isinstance(dst, (Polygon, Partition)) else Polygon(dst, name="dst")
    check_shapes(src, dst)
    width, height = opts.size if opts.size is not None else (img.shape[1], img.shape[0])
    check_output(opts, (width, height), (img.shape[1], img.shape[0]), img[:1, :1])
    stage = progress or (lambda name: None)
    timings: dict[str, float] = {}
    fmap = warp_map
    if fmap is None:
        stage("optimizing Theta and building the map" if opts.map.theta == "optimized" else "building the map")
        regions = ((0.0, 0.0, float(img.shape[1]), float(img.shape[0])), (0.0, 0.0, float(width), float(height)))
        if early is not None and early.regions == regions:
            fmap = early.take()
        else:
            fmap = map_between(src, dst, opts.map, regions=regions)
        timings.update(fmap.timings)
    elif not (_same_polygon(_shape_of(fmap, "src"), src) and _same_polygon(_shape_of(fmap, "dst"), dst)):
        raise InputError("warp_map was built between other polygons than src and dst")
    clock = time.perf_counter
    t0 = clock()
    stage("composing the map")
    plan = plan_for(fmap, width, height, opts, jacobian=True)
    t1 = clock()
    stage("resampling")
    timings["compose"] = t1 - t0
    if streamed is not None and _streams(opts):
        out = np.empty((height, width, img.shape[2]), dtype=img.dtype)
        streamed.append(_RowsMade(plan.render_rows(img, out, alpha_channel=alpha_channel,
                                                   associated_alpha=associated_alpha), timings))  # fmt: skip
    else:
        out = plan.render(img, alpha_channel=alpha_channel, associated_alpha=associated_alpha)
        timings["resample"] = clock() - t1
    return WarpResult(out, fmap, plan.pull, timings, plan=plan, within=pair)


def _streams(opts: WarpOptions) -> bool:
    """Whether `warp_file` resamples the output band by band while the first bands are encoded:
    a core budget of more than one (`warpcli.cores`; with one, the bands' `Task` would only run
    when the encoder had taken them all, and nothing may run beside the encoder anyway), the
    background around the warp (nothing pasted), no conversion of the pixel type before
    writing, and not ``cubic`` (whose spline would prefilter the input for every band)."""
    return budget() > 1 and opts.outside == "background" and opts.dtype is None and opts.interp != "cubic"


class _RowsMade:
    """The output's bands made on a thread of their own (`SamplingPlan.render_rows`); iterating
    gives the rows ``(y0, y1)`` of each band once it is made, then raises what making them raised.

    The PNG encoder (one core: zlib) then works on the first bands while the
    next are resampled (on the others), instead of after all of them.
    """

    def __init__(self, bands: Iterator[tuple[int, int]], timings: dict[str, float]) -> None:
        import queue

        from .maps.compose import Task

        self._made: queue.SimpleQueue = queue.SimpleQueue()
        self._ended = False
        self._task = Task(self._make, bands, timings, name="warp-rows")

    def _make(self, bands: Iterator[tuple[int, int]], timings: dict[str, float]) -> None:
        t0 = time.perf_counter()
        try:
            for rows in bands:
                self._made.put(rows)
        finally:
            timings["resample"] = time.perf_counter() - t0
            self._made.put(None)

    def __iter__(self) -> Iterator[tuple[int, int]]:
        while not self._ended and (rows := self._made.get()) is not None:
            yield rows
        self._ended = True
        self._task.result()

    def finish(self) -> None:
        """Wait until every band is made (raising what making them raised)."""
        for _ in self:
            pass


def _cages_of(shapes: Any, name: str) -> list[Polygon | Partition]:
    """The cages of ``within``: one polygon or mesh, or a list of them (a polygon as an (n, 2) array too)."""
    if isinstance(shapes, (Polygon, Partition)):
        return [shapes]
    items = shapes if isinstance(shapes, (list, tuple)) and shapes and not np.isscalar(shapes[0]) else [shapes]
    if items and all(not isinstance(x, (Polygon, Partition)) for x in items) and np.asarray(items[0]).ndim == 1:
        items = [shapes]  # one polygon given as a list of points
    return [x if isinstance(x, (Polygon, Partition)) else Polygon(x, name=f"{name} cage {k}") for k, x in enumerate(items)]


def _shape_of(fmap: Any, side: str) -> Polygon | Partition:
    """A map's source or target: its polygon, or a cage map's mesh."""
    return getattr(fmap, f"{side}_mesh", None) or getattr(fmap, side)


def _same_polygon(a: Polygon | Partition, b: Polygon | Partition) -> bool:
    if isinstance(a, Partition) != isinstance(b, Partition):
        return False
    if isinstance(a, Partition) and a.faces != b.faces:  # type: ignore[union-attr]
        return False
    return a.points.shape == b.points.shape and bool(np.array_equal(a.points, b.points))


def check_output(opts: WarpOptions, size: tuple[int, int], input_size: tuple[int, int], probe: NDArray) -> None:
    """The checks of a warp's output before any map is built: the paste's size, memory, the background.

    Parameters
    ----------
    opts : WarpOptions
    size, input_size : (int, int)
        The output's and the input's (width, height).
    probe : (h, w, C) ndarray
        Pixels of the input's type and channel count (only those are used).

    Raises
    ------
    InputError
        If the output cannot be made: ``outside="input"`` with another size,
        an output too large for memory, a background that fits no channel count.
    """
    width, height = size
    check_paste(opts.outside, size, input_size, "the input")
    # The output in the working type, and per pixel of the window the source
    # point and the Jacobian (2 + 4 float64): refuse what cannot fit at once.
    check_fits(width, height, probe.shape[2] + 12, 4, f"an output of {width}x{height}")
    background_values(opts.background, probe)


def write_like(
    path: str | os.PathLike[str], image: RasterImage, pixels: NDArray, dtype: str | None = None,
    compression: int | None = None, rows: Iterable[tuple[int, int]] | None = None,
) -> None:  # fmt: skip
    """Write pixels made from ``image`` with its channel names, alpha, alpha convention
    and metadata, converted to ``dtype`` if given, a PNG at zlib level ``compression``
    if given (`warpcli.options.WarpOptions`); ``rows``: the pixels are still being made
    (`warpcli.raster.imageio.write_image`)."""
    if dtype is not None and rows is not None:
        for _ in rows:  # converted whole
            pass
        rows = None
    px = pixels if dtype is None else convert_pixels(pixels, dtype)
    attrs = with_compression(image.attributes, compression)
    write_image(path, RasterImage(px, image.channel_names, image.alpha_channel, attrs, image.associated_alpha), rows)


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
    never taken (the image cannot be read), they are dropped with it, and
    `cancel` kills the children forked to build it (`warpcli._fork.Brood`).
    """

    def __init__(self, src: Polygon, dst: Polygon, opts: WarpOptions, regions: tuple) -> None:
        from ._fork import Brood, watching
        from .maps.compose import Task

        self.regions = regions
        self._records: list[logging.LogRecord] = []
        self._brood = Brood()
        log.addFilter(_hold_back)  # once: the same function
        context = watching(self._brood)
        context.run(_HELD_RECORDS.set, self._records)
        build = functools.partial(map_between, src, dst, opts.map, regions=regions)
        self._task = context.run(Task, build, name="warp-map")

    def take(self) -> BijectiveMap:
        """The map once built (or its error), after its held-back log records."""
        try:
            return self._task.result()
        finally:
            for record in self._records:
                log.handle(record)

    def cancel(self) -> None:
        """The map is not wanted: stop its children (a map already taken is not touched)."""
        self._brood.cancel()

    @staticmethod
    def regions_for(size: tuple[int, int], channels: int, opts: WarpOptions) -> tuple | None:
        """The regions of the map of an image of ``size`` (displayed) and ``channels``, or None
        where `warp_image` will refuse that image (it then does so in its own order)."""
        w, h = size
        width, height = opts.size if opts.size is not None else (w, h)
        try:
            check_output(opts, (width, height), (w, h), np.zeros((1, 1, channels)))
        except WarpError:
            return None
        return ((0.0, 0.0, float(w), float(h)), (0.0, 0.0, float(width), float(height)))

    @classmethod
    def start(cls, header: ImageHeader | None, src: Polygon, dst: Polygon, opts: WarpOptions) -> _EarlyMap | None:
        """Start building the map for an image with this header (None: unread, then no map is started)."""
        if header is None:
            return None
        regions = cls.regions_for(header.displayed_size, header.channels, opts)
        return None if regions is None else cls(src, dst, opts, regions)

    @classmethod
    def guess(cls, input_path, src: Polygon, dst: Polygon, opts: WarpOptions) -> _EarlyMap | None:
        """Start building the map for the size a PNG's first bytes state (`warpcli.raster.peek`),
        before OpenImageIO is imported and its header read; None if there is no guess."""
        found = png_size(input_path)
        if found is None:
            return None
        regions = cls.regions_for(found[:2], found[2], opts)
        if regions is None:
            return None
        children = children_at_once(opts.map)
        early = cls(src, dst, opts, regions)
        if children:
            # The map's children are forked first, about 15 ms from now: the import of
            # OpenImageIO that follows would hold the GIL against that.
            early._brood.wait(children, timeout=0.05)
        return early

    def fits(self, header: ImageHeader | None, opts: WarpOptions) -> bool:
        """Whether this map is the one `start` would build for ``header`` (the guess was right)."""
        return header is not None and self.regions_for(header.displayed_size, header.channels, opts) == self.regions


def _warn_if_relabelled(src: Polygon, dst: Polygon) -> None:
    """Warn when the target's vertex list starts elsewhere: src's vertex i matches
    dst's vertex i + k far better than vertex i (the warp then twists the image)."""
    from .polygon import cyclic_relabelling

    found = cyclic_relabelling(src, dst)
    if found is not None:
        k, d0, dk = found
        log.warning(
            "%s matches %s far better with its vertex i onto vertex i + %d than onto vertex i (shape distance %.2g "
            "against %.2g): the warp twists the image; start %s's vertex list at its vertex %d if that is not "
            "what you want", src.name, dst.name, k, dk, d0, dst.name, k,
        )  # fmt: skip


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
    labels: Sequence[tuple[str | os.PathLike[str], str | os.PathLike[str]]] = (),
    frame: int | None = None,
    prefer_strips: bool = False,
    **changes: Any,
) -> WarpResult | TiledResult:
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
    frame : int or None
        The frame to take from keyframed polygon files (`warpcli.keyframes.read_polygon_at`).
    progress : callable or None
        Called with the name of each stage as it starts.
    tiled : bool or None
        Warp in strips, never holding the whole image (`warpcli.tiled`):
        True always, None (the default) when a whole warp would not fit in
        memory. The output is the same; the result then has no pixels (they
        are in the file), and the report, figures and STMaps are refused.
    prefer_strips : bool
        With ``tiled`` None, also go strip by strip when that writes the same
        bytes with less memory and no other output needs the whole image: an
        output of at least `STRIP_PIXELS` pixels, ``nearest`` or ``linear``,
        the background outside, no report, figures, STMaps or labels, a
        format written in parts (what the ``warp`` command asks: 12 MP in
        0.45 GB instead of 0.8 GB, in the same time; issue 24).
    labels : sequence of (path-like, path-like)
        Masks and label images of the input, each ``(input, output)``: each
        is warped through the same map to the same output size with nearest
        (`warpcli.annotations.warp_labels`: labels never blended, 0 where
        the output has no pre-image) and written in its own type and format,
        with the main output (all or none). Each must have the input's size.

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
    opts = resolve_options(options, changes)
    from .options import HEATMAP_MEASURES

    if heatmap_measure not in HEATMAP_MEASURES:
        raise InputError(f"unknown heatmap measure {heatmap_measure!r}; choose one of {', '.join(HEATMAP_MEASURES)}")
    clock = time.perf_counter
    stage = progress or (lambda name: None)
    inputs = tuple(p for p in (input_path, src_path, dst_path, opts.map.theta_file, opts.within_file) if p is not None)
    labels = [(label_in, label_out) for label_in, label_out in labels]
    if labels and opts.outside == "input" and opts.within is None:
        # (A retouch's map covers its whole outline, and outside it each pixel keeps its own label:
        # `warp_labels`. A paste over the input would keep the labels where the polygon moved from.)
        raise InputError(f"{os.fspath(labels[0][0])}: labels are warped onto the background, not with --outside input")
    for _, label_out in labels:
        check_labels_format(label_out)
    inputs = (*inputs, *(label_in for label_in, _ in labels))
    extra = [p for p in (grid_path, heatmap_path, save_map, save_forward_map) if p is not None]
    extra += [label_out for _, label_out in labels]
    later = []  # PNG outputs: OpenImageIO's check of the format can wait until the map is started
    for path in (output_path, *extra):
        if _known_format(path):
            check_output_path(path, inputs)
            later.append(path)
        else:
            check_image_output(path, inputs=inputs)
    if report_path is not None and os.fspath(report_path) != "-":
        check_output_path(report_path, inputs=inputs)
    if save_theta is not None:
        check_output_path(save_theta, inputs=inputs)
    from .raster.stmap import check_stmap_path

    for path in (save_map, save_forward_map):
        if path is not None:
            check_stmap_path(path)
    check_distinct([
        ("output", output_path), ("--grid output", grid_path), ("--heatmap output", heatmap_path),
        ("--save-map output", save_map), ("--save-forward-map output", save_forward_map),
        *(("--labels output", label_out) for _, label_out in labels), ("--report output", report_path),
        ("--save-theta output", save_theta),
    ])  # fmt: skip
    pair = None
    if opts.within is not None:
        if save_theta is not None:
            raise InputError(f"{os.fspath(save_theta)}: --save-theta writes one Theta, but --within maps several faces")
        from .within import read_within_pair

        header = read_header(input_path)  # the outline needs the image's size before the map
        pair = read_within_pair(
            src_path, dst_path, opts.within, header.displayed_size, src_label=src_label, dst_label=dst_label, frame=frame
        )
        src, dst = pair.src, pair.dst
    else:
        src = read_shape_at(src_path, src_label, frame)
        dst = read_shape_at(dst_path, dst_label, frame)
        header = None
    check_shapes(src, dst)
    if isinstance(src, Partition) and save_theta is not None:
        raise InputError(f"{os.fspath(save_theta)}: --save-theta writes one Theta, but a cage mesh has one per face")
    if opts.map.theta == "none" and save_theta is not None:
        raise InputError(f"{os.fspath(save_theta)}: --save-theta writes Theta, but --theta none has none (f goes straight onto the target)")
    # Before the route is chosen: a warp in strips warns alike.
    if not ((src.signed_area > 0) == (dst.signed_area > 0)):
        log.warning(
            "%s and %s run in opposite directions: the warp mirrors the image (reverse one file's vertex order "
            "if that is not what you want)",
            src.name,
            dst.name,
        )
    elif isinstance(src, Polygon):
        _warn_if_relabelled(src, dst)
    # The map needs the image's size, not its pixels: it is built in other
    # processes and threads while the pixels are decoded (the decoder releases
    # the GIL). A PNG states its size in its first bytes: the map is started
    # from that before OpenImageIO is imported (25-40 ms), and kept only if
    # OpenImageIO's header agrees (else stopped, and started again if need be).
    early = _EarlyMap.guess(input_path, src, dst, opts) if header is None else None
    try:
        for path in later:
            check_image_output(path, inputs=inputs)
        header = header or read_header_or_none(input_path)
        if header is not None:
            check_writes(output_path, header.channels, header.dtype, opts.dtype)
        if early is not None and not early.fits(header, opts):
            early.cancel()
            early = None
        preferred = False  # strips chosen for their memory, not because a whole warp would not fit
        if tiled is None and prefer_strips and _strips_pay(header, opts, output_path, extra, report_path):
            check_plausible(input_path, header)  # decoded strip by strip: no header declaring a bomb
            tiled = preferred = True
        if in_parts(input_path, header, opts.size, tiled):
            return _warp_file_tiled(
                input_path, output_path, src, dst, opts, progress,
                {"--report": report_path, "--grid": grid_path, "--heatmap": heatmap_path, "--save-map": save_map,
                 "--save-forward-map": save_forward_map, "--labels": labels or None},
                save_theta, header, early, preferred,
            )  # fmt: skip
        early = early or _EarlyMap.start(header, src, dst, opts)
        t0 = clock()
        stage("reading")
        image = read_image(input_path)
        label_images = [_read_labels(label_in, image) for label_in, _ in labels]
        t_read = clock() - t0
        if early is not None:
            ready_to_write(image, output_path)  # while the map is built elsewhere: not at the encoder's start
        warn_if_outside(src, (image.width, image.height), os.fspath(input_path), "all background")
        out_size = opts.size if opts.size is not None else (image.width, image.height)
        warn_if_outside(dst, out_size, os.fspath(output_path), "all background")
        try:  # an image with other channels than the background's: name the image
            background_values(opts.background, image.pixels)
        except InputError as err:
            raise naming(err, os.fspath(input_path)) from err
        streamed: list[_RowsMade] = []
        result = _warp(
            image.pixels, src, dst, opts, image.alpha_channel, image.associated_alpha, None, progress, early, pair,
            streamed,
        )  # fmt: skip
    except BaseException:
        if early is not None:  # its children stop now rather than compute for nobody
            early.cancel()
        raise
    rows = streamed[0] if streamed else None
    # Every output is written under a pending name and renamed into place
    # only when all are written: a run's outputs succeed or fail together.
    with PendingOutputs() as pending:
        t0 = clock()
        stage("writing")
        write_like(pending.path(output_path), image, result.pixels, opts.dtype, opts.compression, rows=rows)
        if rows is not None:
            rows.finish()  # every band made (a writer that stopped early stopped reading them)
        for (_, label_out), label_image in zip(labels, label_images):
            _write_labels(pending.path(label_out), label_out, label_image, warp_labels(label_image.pixels, result), opts)
        result.timings["read"] = t_read
        result.timings["write"] = clock() - t0
        if grid_path is not None or heatmap_path is not None:
            from .report import figures

            t0 = clock()
            stage("drawing figures")
            if grid_path is not None:
                # Within an outline the whole picture is one map (the identity outside the outline): draw it all.
                points = result.plan.whole_points() if pair is not None else result.inverse_map
                fig = figures.grid_figure(image.pixels, points, src, dst, alpha_channel=image.alpha_channel)
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
                # With --outside input: the map of the whole retouch (identity outside the target).
                points = result.inverse_map if opts.outside != "input" else result.plan.whole_points()
                if opts.feather > 0:
                    log.warning("%s: a map cannot blend; it holds the warp without the feather", os.fspath(save_map))
                save_stmap(
                    pending.path(save_map), points, (image.width, image.height), kind="inverse", t_up=stmap_t_up,
                )  # fmt: skip
            if save_forward_map is not None:
                fwd = result.map.forward_grid(image.width, image.height)
                save_stmap(pending.path(save_forward_map), fwd, (out_w, out_h), kind="forward", t_up=stmap_t_up)
            result.timings["maps"] = clock() - t0
        if save_theta is not None:
            _write_theta(pending.path(save_theta), result.map.theta)
        if report_path is not None:
            stage("measuring distortion")
            doc = build_report(result)
            if pair is not None:
                doc["within"] = _within_summary(result)
            if os.fspath(report_path) != "-":
                _write_json(pending.path(report_path), doc)
            result = dataclasses.replace(result, report=doc)
    return result


def _within_summary(result: WarpResult) -> dict:
    """The report's ``"within"`` section: the outline, which faces are the cages' and which the ring's, the seams.

    The seams (`warpcli.within.within_seams`): the jumps of neighbouring
    output values, and of the inverse map's Jacobian, across the cages'
    edges, the ring's cuts and the outline, against those elsewhere.
    """
    from .within import within_seams

    pair = result.within
    if pair is None:
        raise InputError("the warp was not made within an outline")
    jac = result.jacobian
    return {
        "outline": pair.outline.tolist(),
        "cage_faces": list(range(pair.cage_faces)),
        "ring_faces": list(range(pair.cage_faces, pair.src.n_faces)),
        "cuts": len(pair.cuts),
        "seams": within_seams(result.pixels.astype(np.float64), jac, pair),
    }


#: Formats that keep no value exactly (lossy compression), by OpenImageIO's name, for messages:
#: labels written there would blend at every edge between them, and take values none had.
LOSSY_FORMATS = {"jpeg": "JPEG", "webp": "WebP", "jpeg2000": "JPEG 2000", "heif": "HEIF", "jpegxl": "JPEG XL"}


def check_labels_format(path: str | os.PathLike[str]) -> None:
    """Refuse, before any work, a label output in a lossy format (`LOSSY_FORMATS`).

    Raises
    ------
    InputError
        Naming the file and its format.
    """
    fmt = output_format(os.fspath(path))
    if fmt in LOSSY_FORMATS:
        raise InputError(
            f"{os.fspath(path)}: {LOSSY_FORMATS[fmt]} compresses with loss, so labels would blend at their edges; "
            "write them to a lossless format (TIFF holds labels of every type)"
        )


def _write_labels(path: str, shown: str | os.PathLike[str], image: RasterImage, labels: NDArray, opts: WarpOptions) -> None:
    """Write warped labels to ``path`` like ``image``, then read them back: every value must be
    the one given, or the format cannot hold them (BMP has 8 bits, a PNG no sign, OpenEXR turns
    16-bit integers into fractions) and the run fails, naming ``shown``, the user's name."""
    write_like(path, image, labels, None, opts.compression)
    back = read_image(path).pixels
    given = labels if labels.ndim == 3 else labels[:, :, None]
    if back.shape != given.shape:
        wrong, example = True, f" (its {back.shape[2]} channels for {given.shape[2]})"
    else:
        a, b = given.astype(np.float64).ravel(), back.astype(np.float64).ravel()
        differ = np.flatnonzero((a != b) & ~(np.isnan(a) & np.isnan(b)))
        wrong = differ.size > 0
        example = f" ({a[differ[0]]:g} became {b[differ[0]]:g})" if wrong else ""
    if wrong:
        raise ImageInputError(
            f"{os.fspath(shown)}: {output_format(path) or 'this format'} cannot hold these labels ({given.dtype}) "
            f"exactly{example}; TIFF holds labels of every type"
        )


def _read_labels(path: str | os.PathLike[str], image: RasterImage) -> RasterImage:
    """A mask or label image of ``image``: read, and checked to have its size."""
    labels = read_image(path)
    if (labels.width, labels.height) != (image.width, image.height):
        raise ImageInputError(
            f"{os.fspath(path)}: labels are {labels.width}x{labels.height} but the image they annotate is "
            f"{image.width}x{image.height}"
        )
    return labels


#: Output extensions whose format OpenImageIO is known to write (PNG is in every build): their
#: check by OpenImageIO (`check_image_output`) waits until the map is started, so that it is not
#: what imports OpenImageIO before the map's children are forked.
_KNOWN_EXTENSIONS = (".png",)


def _known_format(path: str | os.PathLike[str]) -> bool:
    return os.path.splitext(os.fspath(path))[1].lower() in _KNOWN_EXTENSIONS


def read_header_or_none(input_path: str | os.PathLike[str]) -> ImageHeader | None:
    """The image's header, or None if it cannot be read (`read_image` then says why)."""
    try:
        return read_header(input_path)
    except WarpError:
        return None


#: Outputs of at least this many pixels go strip by strip when `warp_file` is
#: asked to prefer strips and they write the same bytes: a whole warp holds the
#: pull-back and its Jacobian, 48 bytes per output pixel (0.58 GB at 12 MP);
#: strips hold `warpcli.raster.parts.TILE` rows of it. Measured for issue 24
#: (bench/README.md): 12 MP in 0.45 GB instead of 0.8 GB, the same time.
STRIP_PIXELS = 8_000_000


def _strips_pay(header: ImageHeader | None, opts: WarpOptions, output_path, extra: list, report_path) -> bool:
    """Whether a warp that could go whole is better strip by strip (`warp_file`'s ``prefer_strips``)."""
    from .raster.parts import NOT_IN_PARTS

    if header is None or header.oriented or extra or report_path is not None:
        return False
    width, height = opts.size if opts.size is not None else header.displayed_size
    # Cubic strips prefilter their own parts (close to, not bit for bit, the whole image's).
    if width * height < STRIP_PIXELS or opts.interp == "cubic" or opts.outside != "background":
        return False
    fmt = output_format(os.fspath(output_path))
    return bool(fmt) and fmt not in NOT_IN_PARTS


def _warp_file_tiled(
    input_path, output_path, src, dst, opts, progress, refused: dict, save_theta, header, early=None, preferred=False
):
    used = [name for name, value in refused.items() if value is not None]
    if used:
        raise InputError(
            f"{os.fspath(input_path)}: {', '.join(used)} needs the whole image in memory, and it is warped in parts "
            "(it does not fit, or --tiled was given)"
        )
    fmap, timings, pixels = None, {}, None
    if early is not None and not header.oriented:  # (strips refuse an oriented image before any map)
        from .raster.parts import check_writable_in_parts
        from .tiled import tiled_needed

        check_writable_in_parts(output_format(os.fspath(output_path)), os.fspath(output_path))
        width, height = opts.size if opts.size is not None else (header.width, header.height)
        if preferred and not tiled_needed(header, width, height):
            # Strips for their memory, of an image that fits: its pixels are decoded now, while
            # the map's children mesh and solve, rather than strip by strip after them (each
            # strip's read then waiting for the encoder's hold of the captured stderr).
            if progress is not None:
                progress("reading")
            t0 = time.perf_counter()
            image = read_image(input_path)
            pixels = image.pixels
            timings["read"] = time.perf_counter() - t0
            ready_to_write(image, output_path)  # while the map is built, not when the first strip is (`ready_to_write`)
        if progress is not None:
            progress("building the map")
        t0 = time.perf_counter()
        fmap = early.take()  # the map of the same regions as warp_file_tiled's
        timings.update(fmap.timings, map=time.perf_counter() - t0)
    with PendingOutputs() as pending:
        result = warp_file_tiled(
            input_path, pending.path(output_path), src, dst, opts, fmap=fmap, progress=progress, header=header,
            pixels=pixels,
        )
        result.timings.update(timings)
        if save_theta is not None:
            _write_theta(pending.path(save_theta), result.map.theta)
    return result


def _write_theta(path: str, theta) -> None:
    """``--save-theta``: Theta as JSON (a file ``--theta`` reads back); refused when the optimizer kept
    the straight map, which has no Theta to save."""
    from .maps.theta import TargetTheta

    if isinstance(theta, TargetTheta):
        raise InputError(
            f"{path}: --theta optimized kept no Theta but the map straight onto the target (--theta none), "
            "so there is no Theta to save"
        )
    _write_json(path, {"theta": theta.name, "points": theta.points.tolist()})


def _write_json(path: str, doc: dict) -> None:
    """Write a JSON document, checked (see `warpcli.outputs.write_checked`)."""
    write_checked(path, (json.dumps(doc, indent=2) + "\n").encode())


#: Bytes per output pixel that applying an STMap holds besides the decoded
#: map and the output: the map as float64 values, its points (2 float64),
#: and the sampling plan's weights and indices (measured: a 3000 x 3000
#: float STMap peaks at ~60 bytes per pixel in all).
STMAP_BYTES_PER_PIXEL = 40


def check_stmap_fits(map_path: str | os.PathLike[str], input_path: str | os.PathLike[str]) -> None:
    """Refuse, from the headers and before decoding anything, an STMap whose warp does not fit in memory.

    Raises
    ------
    ImageInputError
        If either header cannot be read, or the map's pixels, their float64
        copy, the points, the plan and the output together need more than
        `warpcli.budget.max_image_bytes`.
    """
    import math

    header = read_header(map_path)
    image = read_header(input_path)
    w, h = header.displayed_size
    decoded = header.channels * header.dtype.itemsize
    per_pixel = decoded + 8 * header.channels + STMAP_BYTES_PER_PIXEL + image.channels * max(image.dtype.itemsize, 4)
    check_fits(
        w, h, header.channels, header.dtype.itemsize, os.fspath(map_path), copies=max(1, math.ceil(per_pixel / decoded)),
        why="the map decoded, as points, as a sampling plan and as the output image",
    )  # fmt: skip


def apply_map_file(
    map_path: str | os.PathLike[str],
    input_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str],
    options: WarpOptions | None = None,
    *,
    t_up: bool | None = None,
    map_scale: str = "refuse",
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
    map_scale : {"refuse", "stretch"}
        An image of another size than the map was made for: refused (one
        line naming both sizes), or the map's coordinates stretched to it.

    Returns
    -------
    ndarray
        The warped pixels, as written.

    Raises
    ------
    InputError
        For a bad map, image or output path, or an image of another size
        than the map's with ``map_scale="refuse"``.
    """
    from .raster.stmap import load_stmap

    opts = resolve_options(options, changes)
    check_image_output(output_path, inputs=(input_path, map_path))
    check_stmap_fits(map_path, input_path)
    image = read_image(input_path)
    points = load_stmap(
        map_path, (image.width, image.height), t_up=t_up, scale=map_scale, image_name=os.fspath(input_path)
    )
    plan = SamplingPlan.from_points(points, interp=opts.interp, background=opts.background)
    out = plan.render(image.pixels, alpha_channel=image.alpha_channel, associated_alpha=image.associated_alpha)
    write_like(output_path, image, out, opts.dtype, opts.compression)
    return out
