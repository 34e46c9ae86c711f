"""Batches and sequences: many images warped with one map (or one per run of frames), on threads.

Each output size gets one `warpcli.plan.SamplingPlan`, made once and shared
by the threads (`PlanCache`); each image is read, rendered through it and
written (`warp_one`). An image too large for memory goes strip by strip
(`warpcli.tiled`) with the same map. `warpcli.distributed` runs the same
`warp_one` on Dask workers with plans shipped to them.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from .errors import ImageInputError, InputError, WarpError
from .files import check_regular_file
from .maps.compose import BijectiveMap
from .options import WarpOptions, resolve_options
from .pipeline import read_header_or_none, write_like
from .plan import SamplingPlan, check_paste, plan_for
from .polygon import check_pair, read_polygon
from .raster.imageio import check_image_output, read_image
from .tiled import in_parts, warp_file_tiled

__all__ = [
    "BatchItem", "MissingFrameError", "PlanCache", "output_name", "prepare_batch", "warp_batch", "warp_one", "warp_sequence",
]  # fmt: skip


@dataclass(frozen=True)
class BatchItem:
    """One input of a batch: where it went, and the error that stopped it, if any."""

    input_path: str
    output_path: str
    error: WarpError | None = None


class MissingFrameError(ImageInputError):
    """A frame of a sequence whose image is missing (or not a regular file): it fails without a map."""


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
    opts = resolve_options(options, changes)
    tasks, src, dst = prepare_batch(input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label)
    plans = PlanCache(BijectiveMap.between(src, dst, opts.map), opts)
    return _each(lambda task: warp_one(task[0], task[1], plans), tasks, jobs, on_item)


def prepare_batch(input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label):
    """A batch's checks before any work: the (input, output) pairs, and the two polygons.

    Raises
    ------
    InputError
        For a missing directory, a bad pattern, two inputs with one output,
        an output that is an input, or bad polygons.
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
        check_image_output(out, inputs=(*input_paths, src_path, dst_path))
    src = read_polygon(src_path, src_label)
    dst = read_polygon(dst_path, dst_label)
    check_pair(src, dst)
    return [(os.fspath(inp), out) for inp, out in zip(input_paths, outputs)], src, dst


class PlanCache:
    """Sampling plans by output size, each made once from one map and shared by threads.

    Parameters
    ----------
    fmap : BijectiveMap or None
        The map (None on a Dask worker, which has only the plans shipped to it:
        it cannot make new ones, nor warp an image in strips).
    opts : WarpOptions
    plans : dict or None
        Plans already made, by ``(width, height)``.
    """

    def __init__(self, fmap: BijectiveMap | None, opts: WarpOptions, plans: dict | None = None) -> None:
        self.fmap, self.opts = fmap, opts
        self.plans: dict[tuple[int, int], SamplingPlan] = dict(plans or {})
        self._lock = threading.Lock()

    def __getstate__(self) -> dict:  # shipped to Dask workers without its lock
        return {"fmap": None, "opts": self.opts, "plans": self.plans}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["fmap"], state["opts"], state["plans"])

    def get(self, size: tuple[int, int]) -> SamplingPlan:
        """The plan for an output of ``size`` (width, height).

        Raises
        ------
        ImageIOError
            If there is no map to make it from (a worker given other sizes).
        """
        from .errors import ImageIOError

        size = tuple(size)
        with self._lock:
            if size not in self.plans:
                if self.fmap is None:
                    raise ImageIOError(f"no sampling plan was made for an output of {size[0]}x{size[1]}")
                self.plans[size] = plan_for(self.fmap, size[0], size[1], self.opts)
            return self.plans[size]


def warp_one(inp: str, out: str, plans: PlanCache) -> BatchItem:
    """One image of a batch or sequence: read, render through its size's plan, write; its error in the item.

    An image too large for memory is warped in strips (`warpcli.tiled`) with the same map.

    Parameters
    ----------
    inp, out : str
        The input image and the output path (checked already, `prepare_batch`).
    plans : PlanCache

    Returns
    -------
    BatchItem
    """
    opts, fmap = plans.opts, plans.fmap
    try:
        header = read_header_or_none(inp) if fmap is not None else None
        if header is not None and in_parts(inp, header, opts.size, None):
            warp_file_tiled(inp, out, fmap.src, fmap.dst, opts, fmap=fmap, header=header)
            return BatchItem(inp, out)
        image = read_image(inp)
        shape = opts.size if opts.size is not None else (image.width, image.height)
        check_paste(opts.outside, shape, (image.width, image.height), inp)
        px = plans.get(shape).render(image.pixels, alpha_channel=image.alpha_channel,
                                     associated_alpha=image.associated_alpha)  # fmt: skip
        write_like(out, image, px, opts.dtype)
        return BatchItem(inp, out)
    except WarpError as err:
        # Without its traceback: that holds this frame, and so the plans and
        # their map, alive as long as the item (a long sequence of failures
        # kept every map).
        return BatchItem(inp, out, err.with_traceback(None))


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

    opts = resolve_options(options, changes)
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
    # Frames whose image is missing fail without a map, and without their polygons:
    # a map is built for a run only if one of its frames has an image.
    missing: dict[int, BatchItem] = {}
    for (f, inp), (_, out) in zip(ins, outs):
        try:
            check_regular_file(inp, "image", MissingFrameError)
        except MissingFrameError as err:
            missing[f] = BatchItem(inp, out, err.with_traceback(None))
    # Every other frame's polygons first (interpolation can self-intersect): errors before any work.
    pairs = {}
    for f, _ in ins:
        if f not in pairs and f not in missing:
            pairs[f] = (src_keys.at(f), dst_keys.at(f))
            check_pair(*pairs[f])
    # Runs of frames with the same pair share one map (a missing frame breaks
    # no run); the frames of a run go to the threads.
    runs: list[tuple[tuple[bytes, bytes] | None, list[tuple[str, str, int]]]] = []
    for (f, inp), (_, out) in zip(ins, outs):
        key = None
        if f not in missing:
            src, dst = pairs[f]
            key = (src.points.tobytes(), dst.points.tobytes())
        if not runs or (key is not None and runs[-1][0] not in (None, key)):
            runs.append((key, []))
        elif key is not None and runs[-1][0] is None:
            runs[-1] = (key, runs[-1][1])
        runs[-1][1].append((inp, out, f))
    items: list[BatchItem] = []
    for key, tasks in runs:
        if key is None:  # every image of the run is missing
            for _, _, f in tasks:
                items.append(missing[f])
                if on_item is not None:
                    on_item(missing[f])
            continue
        src, dst = pairs[next(f for _, _, f in tasks if f not in missing)]
        try:
            plans = PlanCache(BijectiveMap.between(src, dst, opts.map), opts)
        except WarpError as err:  # a map that cannot be built fails its frames, not the others
            done = [missing.get(f) or BatchItem(inp, out, err.with_traceback(None)) for inp, out, f in tasks]
            for item in done:
                if on_item is not None:
                    on_item(item)
            items += done
            continue
        items += _each(
            lambda task: missing[task[2]] if task[2] in missing else warp_one(task[0], task[1], plans), tasks, jobs, on_item
        )
        plans = None  # this run's map goes before the next is built
    return items
