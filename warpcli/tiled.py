"""Images larger than memory: the warp computed, read and written strip by strip.

`warp_file` takes this route when a whole warp would not fit in memory (the
limit of `warpcli.budget.max_image_bytes`), or when asked
(``warp --tiled``). Memory is then bounded by a strip of the output, the
parts of the input it reaches, OpenImageIO's tile cache and the map, not by
the image:

- the map is built once, as for any warp (its meshes depend on the polygons,
  at most `warpcli.maps.fem.mesh.AUTO_MAX_TRIANGLES` triangles by default);
- the output is made in strips of `TILE` rows: the pull-back of the strip's
  rows only (`BijectiveMap.pull_back` with ``rows``), the edge coverage of its
  pixels, then chunks of `CHUNK` columns, each resampled from the rectangle
  of the input its samples reach (`PartReader`), read through the cache (an
  image decoded whole, ``pixels``, is resampled as it is, in runs of rows);
- each strip is written as it is done (`StripWriter`: tiles for TIFF and
  OpenEXR, scanlines for PNG), under a temporary name renamed into place at
  the end.

Map work is done only in the window around the target polygon; strips
outside it are background. A retouch (``outside="input"``) pastes the warp
over each strip of the input as `warpcli.composite.paste_over` pastes it over
the whole image (the parts of the input resampled as its carrier), with the
same bytes. With ``nearest`` and ``linear`` the output is
that of the in-memory warp bit for bit (the pull-back is computed in the same
bands, and a sampler given part of an image reads the same pixels); ``cubic``
prefilters each part with a margin of `CUBIC_MARGIN` pixels, which agrees
with the whole image's prefilter to about 0.27^12 of the data's range.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .budget import MAX_COMPRESSION
from .cores import budget
from .errors import InputError
from .maps.cage import map_between
from .maps.compose import BijectiveMap
from .options import WarpOptions
from .plan import SamplingPlan, check_paste, plan_for, warn_if_outside
from .polygon import Polygon
from .raster.imageio import ImageHeader, output_format, read_header, size_limit_lifted, with_compression
from .raster.parts import TILE, PartReader, StripWriter, check_writable_in_parts
from .raster.pixels import fill
from .raster.resample import footprint_bounds, samples_as_is

log = logging.getLogger("warpcli")

#: Columns of the output resampled at once within a strip (from a decoded image,
#: runs of whole rows of about `TILE` x `CHUNK` pixels: `_Sampler._row_runs`).
CHUNK = 2048
#: Bytes of input one chunk may read at once; a chunk reaching more is split.
PART_BYTES = 256 << 20
#: Extra input pixels around each part for the cubic spline's prefilter.
CUBIC_MARGIN = 12
#: The largest strip plan made ahead of the strip being resampled (`_Ahead`): wider
#: images plan each strip when it is resampled, so that memory stays bounded by a strip's plan.
AHEAD_PLAN_BYTES = 128 << 20


@dataclass
class TiledResult:
    """What a warp in strips produced: its map and timings (the pixels are in the file)."""

    map: BijectiveMap
    size: tuple[int, int]
    timings: dict[str, float]
    report: dict | None = None


def warp_file_tiled(
    input_path: str | os.PathLike[str],
    output_path: str,
    src: Polygon,
    dst: Polygon,
    opts: WarpOptions,
    *,
    fmap: BijectiveMap | None = None,
    progress: Callable[[str], None] | None = None,
    header: ImageHeader | None = None,
    pixels: NDArray | None = None,
) -> TiledResult:
    """Warp the image at ``input_path`` into ``output_path`` strip by strip.

    The caller has checked the paths and the polygons (`warpcli.pipeline.warp_file`);
    ``header`` is the input's `read_header` when the caller has read it, ``pixels``
    the input's pixels (`warpcli.raster.imageio.read_image`) when it has decoded them
    (then parts of them are resampled instead of parts of the file).

    Raises
    ------
    InputError
        For options this route does not take, or an image it cannot read in parts.
    WarpError
        If reading or writing fails.
    """
    from .outputs import atomic_path
    from .raster.dtypes import DTYPES
    from .raster.imageio import convert_pixels

    stage = progress or (lambda name: None)
    clock = time.perf_counter
    header = header or read_header(input_path)
    name = os.fspath(input_path)
    if header.oriented:
        raise InputError(f"{name}: an image with an EXIF orientation cannot be warped in parts; upright it first")
    check_writable_in_parts(output_format(output_path), output_path)
    width, height = opts.size if opts.size is not None else (header.width, header.height)
    check_paste(opts.outside, (width, height), (header.width, header.height), name)
    warn_if_outside(src, (header.width, header.height), name, "all background")
    warn_if_outside(dst, (width, height), os.fspath(output_path), "all background")
    timings: dict[str, float] = {}
    if fmap is None:
        stage("building the map")
        t0 = clock()
        regions = ((0.0, 0.0, float(header.width), float(header.height)), (0.0, 0.0, float(width), float(height)))
        fmap = map_between(src, dst, opts.map, regions=regions)
        timings.update(fmap.timings)
        timings["map"] = clock() - t0
    out_header = dataclasses.replace(header, dtype=np.dtype(DTYPES[opts.dtype])) if opts.dtype else header
    out_header = dataclasses.replace(out_header, attributes=with_compression(out_header.attributes, opts.compression))
    sampler = _Sampler(fmap, header, opts)
    timings.update(compose=0.0, resample=0.0, write=0.0)
    stage("warping in strips")
    log.info("%s: warping in strips of %d rows, %d x %d -> %d x %d", name, TILE, header.width, header.height, width, height)
    # OpenImageIO's size limit (a guard for whole-image decoders) must not refuse
    # the images strips exist for: the input is read and the output checked in parts.
    parts = PartReader(input_path, header) if pixels is None else _Decoded(pixels)
    with size_limit_lifted(), atomic_path(output_path) as tmp, parts as reader:
        plans = (sampler.plan(width, height, y, min(height, y + TILE), timings) for y in range(0, height, TILE))
        # With cores to spare, three stages at once: the next strips planned, this
        # one resampled, the last one encoded (`_Ahead`); only where the two more
        # plans that holds are small (a plan is 48 bytes a pixel of the strip).
        ahead = _Ahead(plans, name="warp-plans") if budget() > 1 and 48 * TILE * width <= AHEAD_PLAN_BYTES else None
        try:
            # Opened while the first strip is planned: an output's first opening in a
            # process loads OpenImageIO's colour configuration (20-25 ms at 12 MP, measured).
            writer = StripWriter(tmp, output_path, width, height, out_header)
        except BaseException:
            if ahead is not None:
                ahead.stop()
            raise
        strips = (sampler.render(reader, width, planned, timings) for planned in (ahead if ahead is not None else plans))
        made = None
        try:
            made = _Ahead(strips, upstream=ahead) if budget() > 1 else None
            for strip in made if made is not None else strips:
                t0 = clock()
                writer.write(strip if not opts.dtype else convert_pixels(strip, opts.dtype))
                timings["write"] += clock() - t0
            writer.close()
        except BaseException:
            # Both threads end (the strips' stops its upstream) before the input is closed.
            if made is not None:
                made.stop()
            elif ahead is not None:
                ahead.stop()
            writer.abandon()
            raise
    return TiledResult(fmap, (width, height), timings)


class _Decoded:
    """`PartReader`'s rectangles, of an image already decoded (each a contiguous copy, as read)."""

    def __init__(self, pixels: NDArray) -> None:
        self.pixels = pixels

    def read(self, x0: int, y0: int, x1: int, y1: int) -> NDArray:
        return np.ascontiguousarray(self.pixels[y0:y1, x0:x1])

    def __enter__(self) -> _Decoded:
        return self

    def __exit__(self, *exc) -> None:
        self.pixels = None


class _Ahead:
    """Strips (or their plans) made on a thread of their own, one ahead of the one being used.

    The encoder (zlib, one core, GIL released in OpenImageIO) writes strip k
    while the next is pulled back and resampled, in compiled kernels that
    release the GIL, instead of after it: 12 MP in strips, about a third less
    time for the strips. And the strips' plans are made on a thread of their
    own too, so that strip k+1 is pulled back while strip k is resampled:
    each stage has stretches on one core (the edge coverage, the reach of a
    part, numpy between kernels), which left the second core idle while the
    encoder waited for the next strip. The items come in order, so the file
    is the same. Iterating gives each item, then raises what making them
    raised; `stop` makes the thread end after the item it is making (the
    writer failed), and the ``upstream`` one it takes its items from.
    """

    def __init__(self, items, *, name: str = "warp-strips", upstream: _Ahead | None = None) -> None:
        import queue
        import threading

        from .maps.compose import Task

        self._made: queue.Queue = queue.Queue(maxsize=1)
        self._stopped = threading.Event()
        self._upstream = upstream
        self._task = Task(self._make, items, name=name)

    def _make(self, items) -> None:
        try:
            for item in items:
                if self._stopped.is_set() or not self._put((item, None)):
                    return
        except BaseException as err:  # handed to the writer, which raises it
            self._put((None, err))
            return
        self._put((None, None))

    def _put(self, entry: tuple) -> bool:
        """Hand ``entry`` on, unless `stop` comes first (then nobody takes it: False).

        A plain ``put`` could wait for ever: once stopped, nobody reads the queue,
        and a strip made after the writer failed (its input closed meanwhile)
        would raise, with its error put into a full queue."""
        import queue

        while not self._stopped.is_set():
            try:
                self._made.put(entry, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def __iter__(self):
        import queue

        while True:
            try:
                item, err = self._made.get(timeout=0.05)
            except queue.Empty:
                if self._stopped.is_set():  # stopped: its thread may have ended without a last word
                    return
                continue
            if err is not None:
                raise err
            if item is None:
                return
            yield item

    def stop(self) -> None:
        """End the thread, and the ``upstream`` one: no more items are wanted. Returns once both
        have ended (each finishes the item it is making), so that what they read (the input's
        parts) may be closed."""
        import queue

        self._stopped.set()
        try:
            while True:
                self._made.get_nowait()  # drop what was made: nobody takes it
        except queue.Empty:
            pass
        if self._upstream is not None:
            self._upstream.stop()
        self._task.result()  # its errors went to the queue: this only waits


class _Sampler:
    """The strips of one warp: each strip's sampling plan, resampled chunk by chunk from parts of the input."""

    def __init__(self, fmap: BijectiveMap, header: ImageHeader, opts: WarpOptions) -> None:
        self.fmap, self.header, self.opts = fmap, header, opts
        self.margin = 1 + (CUBIC_MARGIN if opts.interp == "cubic" else 0)
        self.alpha = {"alpha_channel": header.alpha_channel, "associated_alpha": header.associated_alpha}

    def plan(self, width: int, height: int, y0: int, y1: int, timings: dict) -> tuple[int, int, SamplingPlan]:
        """The sampling plan of output rows ``y0 <= y < y1``, with those rows (for `render`)."""
        t0 = time.perf_counter()
        plan = plan_for(self.fmap, width, height, self.opts, rows=(y0, y1))
        timings["compose"] += time.perf_counter() - t0
        return y0, y1, plan

    def render(self, reader: PartReader, width: int, planned: tuple[int, int, SamplingPlan], timings: dict) -> NDArray:
        """The rows of a `plan`: (rows, width, C) in the input's pixel type."""
        y0, y1, plan = planned
        if plan.outside == "input":
            return self._pasted(reader, plan, width, y0, y1, timings)
        out = np.empty((y1 - y0, width, self.header.channels), dtype=self.header.dtype)
        fill(out, plan.empty_pixel(self.header.dtype, self.header.channels, **self.alpha))
        if plan.pull.points.size == 0:
            return out
        t0 = time.perf_counter()
        if isinstance(reader, _Decoded) and self._reads_as_is(reader.pixels):
            for box in self._row_runs(plan):
                self._from_whole(reader.pixels, plan, box, out, y0)
        else:
            for box in self._boxes(plan):
                self._chunk(reader, plan, box, out, y0)
        timings["resample"] += time.perf_counter() - t0
        return out

    def _reads_as_is(self, pixels: NDArray) -> bool:
        """Whether the samplers read the decoded image as it is: then runs of rows are sampled
        from it whole (`_from_whole`). Otherwise (straight alpha to premultiply, a type the
        kernels do not read, ``cubic``'s prefilter) every call would first copy the whole
        image, so parts of it are read as from a file (`_chunk`), each copied alone."""
        return self.opts.interp != "cubic" and samples_as_is(pixels.dtype, interp=self.opts.interp, **self.alpha)

    @staticmethod
    def _boxes(plan: SamplingPlan) -> list[tuple[int, int, int, int]]:
        """The chunks ``(first row, last row, first column, last column)`` of a strip's window
        resampled from parts of the input: `CHUNK` columns of the whole strip."""
        rows, cols = plan.pull.points.shape[:2]
        return [(0, rows, cx, min(cols, cx + CHUNK)) for cx in range(0, cols, CHUNK)]

    @staticmethod
    def _row_runs(plan: SamplingPlan) -> list[tuple[int, int, int, int]]:
        """The chunks of a strip's window resampled from the whole decoded image: runs of its
        whole rows, about `TILE` x `CHUNK` pixels each (a row wider than that on its own).

        Their points and Jacobians are contiguous parts of the plan's, which the
        samplers take as they are; `CHUNK` columns of them were copied, twice
        (the reach, then the sampler), 1.2 GB of copies into fresh pages in a
        12 MP warp. The result is the same however the window is cut: each
        pixel is sampled from its own point, Jacobian and coverage.
        """
        rows, cols = plan.pull.points.shape[:2]
        n = min(rows, max(1, -(-rows * cols // (TILE * CHUNK))))
        cuts = [rows * k // n for k in range(n + 1)]
        return [(a, b, 0, cols) for a, b in zip(cuts[:-1], cuts[1:])]

    def _from_whole(self, pixels: NDArray, plan: SamplingPlan, box, out: NDArray, y0: int) -> None:
        """Resample the window's rows ``box[0]:box[1]`` and columns ``box[2]:box[3]`` into ``out`` (from
        row y0) from the whole decoded image ``pixels``: what `_chunk` gives from the part the samples
        reach, with ``nearest`` and ``linear`` (a sampler given part of an image reads the same pixels),
        without its reach, its copy of the part, or its halving of a part too large."""
        a, b, c, d = box
        part_plan = plan.crop((a, b), (c, d))
        if part_plan.is_empty():
            return  # no pixel has a pre-image or covers the target's edge: the background already there
        r, q = part_plan.pull.origin
        out[r - y0 : r - y0 + (b - a), q : q + (d - c)] = part_plan.sample_window(pixels, **self.alpha)

    def _pasted(self, reader: PartReader, plan: SamplingPlan, width: int, y0: int, y1: int, timings: dict) -> NDArray:
        """Rows ``y0 <= y < y1`` of a retouch (``--outside input``): the strip's input with the warp pasted over it,
        as `warpcli.composite.paste_over` pastes a whole image (each part of the input resampled as its carrier)."""
        from .composite import carrier_pixels, paste_over

        t0 = time.perf_counter()
        alpha, associated = self.header.alpha_channel, self.header.associated_alpha
        nc = self.header.channels

        def warp(carrier: NDArray, channels: int) -> NDArray:
            out = np.zeros(carrier.shape, dtype=carrier.dtype)
            if plan.pull.points.size == 0:
                return out
            convert = functools.partial(carrier_pixels, alpha_channel=alpha, associated_alpha=associated)
            kw = {"alpha_channel": nc, "associated_alpha": True, "background": np.zeros(nc + 1)}
            for box in self._boxes(plan):
                self._chunk(reader, plan, box, out, y0, convert, kw)
            return out

        base = reader.read(0, y0, width, y1)
        src = plan.src
        done = paste_over(
            base, warp, src=src, background=plan.background_values(base), alpha_channel=alpha,
            associated_alpha=associated, vacated=plan.vacated, feather=plan.feather, dst=plan.dst, rows=(y0, y1),
        )  # fmt: skip
        timings["resample"] += time.perf_counter() - t0
        return done

    def _chunk(self, reader: PartReader, plan: SamplingPlan, box, out: NDArray, y0: int, convert=None, kw=None) -> None:
        """Resample the window's rows ``box[0]:box[1]`` and columns ``box[2]:box[3]`` into ``out`` (from row y0);
        ``convert`` turns the input's pixels into what is resampled, ``kw`` the sampling's arguments."""
        a, b, c, d = box
        part_plan = plan.crop((a, b), (c, d))
        if part_plan.is_empty():
            return  # no pixel has a pre-image or covers the target's edge: the background already there
        pull, coverage = part_plan.pull, part_plan.coverage
        part = _reach(pull.points, pull.jacobian, None if coverage is None else coverage.source_points, self.header,
                      self.margin)  # fmt: skip
        x0, py0, x1, py1 = part
        nbytes = (x1 - x0) * (py1 - py0) * self.header.channels * self.header.dtype.itemsize
        if nbytes > PART_BYTES and (b - a) * (d - c) > 1:
            # Too much input for one read (the map shrinks a lot here): halves.
            if b - a >= d - c:
                m = (a + b) // 2
                halves = ((a, m, c, d), (m, b, c, d))
            else:
                m = (c + d) // 2
                halves = ((a, b, c, m), (a, b, m, d))
            for half in halves:
                self._chunk(reader, plan, half, out, y0, convert, kw)
            return
        pixels = reader.read(x0, py0, x1, py1)
        if convert is not None:
            pixels = convert(pixels)
        done = part_plan.sample_window(
            pixels, part=(x0, py0, self.header.width, self.header.height), **(self.alpha if kw is None else kw)
        )
        r, q = pull.origin
        out[r - y0 : r - y0 + (b - a), q : q + (d - c)] = done


def _reach(points: NDArray, jac: NDArray | None, extra: NDArray | None, header: ImageHeader, margin: int):
    """The rectangle ``(x0, y0, x1, y1)`` of input pixels that samples at ``points`` may read.

    A sample reads the pixels around a point of its footprint, the
    parallelogram ``J [-1/2, 1/2]^2`` about its source point, so each point
    is widened by half the footprint's extent (``jac`` None: none;
    `warpcli.raster.resample.footprint_bounds`), then by the two pixels
    bilinear interpolation reads and ``margin``; clipped to the image
    (samples beyond it are background or read its edge pixels).
    """
    w, h = header.width, header.height
    # Beyond the image by more than a pixel (or infinite) reads no more than its edge.
    limits = (-2.0, w + 2.0, -2.0, h + 2.0)
    bounds = [b for b in (footprint_bounds(points, jac, limits),) if b is not None]
    if extra is not None and len(extra):
        e = np.asarray(extra, dtype=np.float64).reshape(-1, 2)
        e = e[np.isfinite(e).all(axis=1)]
        if len(e):
            bounds.append(footprint_bounds(e, None, limits))
    if not bounds:
        return 0, 0, 1, 1
    lo_x, hi_x = min(b[0] for b in bounds), max(b[1] for b in bounds)
    lo_y, hi_y = min(b[2] for b in bounds), max(b[3] for b in bounds)
    x0 = min(max(math.floor(lo_x - 0.5) - margin, 0), w - 1)
    x1 = min(max(math.floor(hi_x - 0.5) + 2 + margin, x0 + 1), w)
    y0 = min(max(math.floor(lo_y - 0.5) - margin, 0), h - 1)
    y1 = min(max(math.floor(hi_y - 0.5) + 2 + margin, y0 + 1), h)
    return x0, y0, x1, y1


def check_plausible(path: str | os.PathLike[str], header: ImageHeader) -> None:
    """Refuse to warp in strips, unasked, an image whose header declares far more
    pixels than its file could hold (a decompression bomb): it would run for
    hours and fill the disk. ``--tiled`` takes it anyway.

    Raises
    ------
    ImageInputError
    """
    from .errors import ImageInputError

    decoded = header.width * header.height * header.channels * header.dtype.itemsize
    size = max(os.stat(path).st_size, 1)
    if decoded > MAX_COMPRESSION * size:
        raise ImageInputError(
            f"{os.fspath(path)}: declares {header.width} x {header.height} pixels ({decoded / 1e9:.3g} GB) in a "
            f"file of {size} bytes, more than any compression gives: refused as a decompression bomb "
            "(it does not fit in memory; --tiled warps it in strips anyway)"
        )


def in_parts(
    input_path: str | os.PathLike[str], header: ImageHeader | None, size: tuple[int, int] | None, tiled: bool | None
) -> bool:
    """Whether a warp of this input goes strip by strip: asked to (``tiled`` True), or, with
    ``tiled`` None, a whole warp would not fit in memory (and the file is plausible).

    Parameters
    ----------
    input_path : path-like
    header : ImageHeader or None
        The input's header (None: unread; then not in parts, and the read says why).
    size : (int, int) or None
        The output's size (None: the input's).
    tiled : bool or None

    Raises
    ------
    ImageInputError
        If the image would go in parts unasked but its header declares more
        than its file could hold (`check_plausible`).
    """
    if tiled is not None:
        return bool(tiled)
    if header is None:
        return False
    width, height = size if size is not None else (header.width, header.height)
    if not tiled_needed(header, width, height):
        return False
    check_plausible(input_path, header)
    return True


def tiled_needed(header: ImageHeader, width: int, height: int) -> bool:
    """Whether a whole warp would not fit in memory: the input's pixels, or the
    output with its per-pixel map (the limits `warpcli.pipeline.warp_image` checks)."""
    from .budget import check_fits
    from .errors import ImageInputError

    try:
        check_fits(header.width, header.height, header.channels, header.dtype.itemsize, "input")
        check_fits(width, height, header.channels + 12, 4, "output")
    except ImageInputError:
        return True
    return False


__all__ = [
    "AHEAD_PLAN_BYTES", "CHUNK", "CUBIC_MARGIN", "MAX_COMPRESSION", "PART_BYTES", "TiledResult", "check_plausible", "in_parts", "tiled_needed",
    "warp_file_tiled",
]  # fmt: skip
