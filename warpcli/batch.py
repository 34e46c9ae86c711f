"""Batches and sequences: many images warped with one map (or one per run of frames), on threads or processes.

Each output size gets one `warpcli.plan.SamplingPlan`, made once and shared
by the threads (`PlanCache`); each image is read, rendered through it and
written (`warp_one`). An image too large for memory goes strip by strip
(`warpcli.tiled`) with the same map. `warpcli.distributed` runs the same
`warp_one` on Dask workers with plans shipped to them. An animated sequence
(a new polygon pair every few frames) has its maps built in forked children
while this process warps the frames whose plans have arrived (`_pipelined`),
or goes to worker processes run by run (`warp_run`): building a map holds
the GIL, so threads would take turns.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import shutil
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from .cores import check_jobs, jobs as core_budget
from .errors import ImageInputError, InputError, WarpError, naming
from .files import check_regular_file
from .maps.cage import map_between
from .maps.compose import BijectiveMap
from .options import WarpOptions, outline_file, resolve_options
from .outputs import RunInputs, check_distinct
from .pipeline import read_header_or_none, write_like
from .plan import SamplingPlan, background_values, check_paste, plan_for
from .polygon import Polygon
from .polygon.partition import Partition, check_shapes, read_shape
from .raster.imageio import check_image_output, check_writes, read_header, read_image
from .tiled import in_parts, warp_file_tiled

__all__ = [
    "BatchItem", "FrameMaps", "MissingFrameError", "PlanCache", "RunMaps", "apply_map_sequence", "link_or_copy",
    "output_name", "prepare_batch", "warp_batch", "warp_one", "warp_run", "warp_sequence",
]  # fmt: skip


def _within_budget(fn: Callable) -> Callable:
    """``fn`` run with its ``jobs`` as the process's core budget (`warpcli.cores.jobs`; None:
    the budget as it is), and given the budget as ``jobs``: the threads and processes it starts."""

    @functools.wraps(fn)
    def run(*args: Any, jobs: int | None = None, **kwargs: Any) -> Any:
        with core_budget(jobs) as n:
            return fn(*args, jobs=n, **kwargs)

    return run


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


@_within_budget
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
    jobs: int | None = None,
    **changes: Any,
) -> list[BatchItem]:
    """Warp many images with one map: ``out_dir/<pattern>`` for each input.

    The map is computed once, and its pull-back onto each output size once
    (inputs of one size share it). With ``jobs`` > 1 the images are read,
    resampled and written by that many threads (the compiled kernels and
    OpenImageIO release the GIL); every output's bytes are those of
    ``jobs=1``, which keeps one core busy and no more.

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
    jobs : int or None
        The cores the batch may keep busy (`warpcli.cores`): threads
        warping images at once, and the kernels' threads; 1: one core, no
        thread beside the caller's. None: the process's budget (`set_jobs`,
        else every core it may use).

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
    tasks, src, dst = prepare_batch(
        input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label, theta_file=opts.map.theta_file,
        within=opts.within,
    )
    plans = PlanCache(map_between(src, dst, opts.map), opts)
    return _each(lambda task: warp_one(task[0], task[1], plans), tasks, jobs, on_item)


def prepare_batch(input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label, theta_file=None, within=None):
    """A batch's checks before any work: the (input, output) pairs, and the two polygons.

    ``theta_file`` is the Theta file the map reads, if any (an input too, as is ``within``'s outline file).
    ``within``: the polygons are the cages of a retouch within that outline
    (`warpcli.within.within_pair`), made at the first input's size (an
    outline of ``"image"`` is the first input's rectangle for every input).

    Raises
    ------
    InputError
        For a missing directory, a bad pattern, two inputs with one output,
        an output that is any input of the run, or bad polygons.
    """
    directory = os.fspath(out_dir)
    if not os.path.isdir(directory):
        raise InputError(f"{directory}: output directory does not exist")
    outputs = [os.path.join(directory, output_name(p, pattern)) for p in input_paths]
    seen: dict[str, str] = {}
    inputs = RunInputs(p for p in (*input_paths, src_path, dst_path, theta_file, outline_file(within)) if p is not None)
    for inp, out in zip(input_paths, outputs):
        key = os.path.abspath(out)
        if key in seen:
            raise InputError(f"{out}: both {seen[key]} and {os.fspath(inp)} would be written there")
        seen[key] = os.fspath(inp)
        check_image_output(out, inputs=inputs)
    if within is not None and input_paths:
        from .within import read_within_pair

        size = read_header(input_paths[0]).displayed_size
        check_same_size(input_paths, size)
        pair = read_within_pair(src_path, dst_path, within, size, src_label=src_label, dst_label=dst_label)
        src, dst = pair.src, pair.dst
    else:
        src = read_shape(src_path, src_label)
        dst = read_shape(dst_path, dst_label)
    check_shapes(src, dst)
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


@dataclass(frozen=True)
class FrameMaps:
    """A sequence's per-frame STMaps (`warpcli.raster.stmap`): where they go, and which way t runs.

    Frames of one run share their map: it is computed and written once per
    distinct polygon pair (and image size), and the other frames' files are
    hard links to that file (copies where the file system cannot link).

    Parameters
    ----------
    inverse, forward : str or None
        Sequence patterns (``map.#.exr``) for the inverse map (output pixel ->
        input point) and the forward map (input pixel -> output point); None:
        not written.
    t_up : bool
        Nuke's orientation of t (up) instead of OpenImageIO's (down).
    """

    inverse: str | None = None
    forward: str | None = None
    t_up: bool = False

    def paths(self, frame: int) -> tuple[str | None, str | None]:
        """The inverse and forward map files of ``frame`` (None: not written)."""
        from .sequence import frame_path

        return tuple(None if p is None else frame_path(p, frame) for p in (self.inverse, self.forward))  # type: ignore[return-value]


class RunMaps:
    """The map files of one run of frames (one polygon pair), shared by the threads warping them.

    The first frame of each (input size, output size) writes its maps; the
    others wait for it and link to them (`link_or_copy`).

    Parameters
    ----------
    maps : FrameMaps
    """

    def __init__(self, maps: FrameMaps) -> None:
        self.maps = maps
        self.written: dict[tuple, tuple[str | None, str | None]] = {}
        self.lock = threading.Lock()

    def save(self, frame: int, fmap: BijectiveMap, plan: SamplingPlan, in_size: tuple[int, int]) -> None:
        """Write (or link) the maps of ``frame``, warped with ``plan`` from an input of ``in_size``.

        Raises
        ------
        ImageIOError
            If a file cannot be written.
        """
        from .raster.stmap import save_stmap

        paths = self.maps.paths(frame)
        key = (tuple(in_size), tuple(plan.size))
        with self.lock:  # one thread writes a run's map; the others wait, then link to it
            first = self.written.get(key)
            if first is not None and any(p is not None and not os.path.exists(p) for p in first):
                first = None  # its frame failed, and its maps went with it (`discard`): written anew
            if first is None:
                if paths[0] is not None:
                    save_stmap(paths[0], plan.whole_points(), in_size, kind="inverse", t_up=self.maps.t_up)
                if paths[1] is not None:
                    fwd = fmap.forward_grid(*in_size)
                    save_stmap(paths[1], fwd, plan.size, kind="forward", t_up=self.maps.t_up)
                self.written[key] = paths
                return
            for target, source in zip(paths, first):
                if target is not None and os.path.abspath(target) != os.path.abspath(source):
                    link_or_copy(source, target)

    def discard(self, frame: int) -> None:
        """Remove the maps of ``frame``, whose image failed: a frame's outputs succeed or fail together.

        (Other frames' maps are their own names, links or copies: they stay.)
        """
        with self.lock:
            for path in self.maps.paths(frame):
                if path is not None:
                    with contextlib.suppress(OSError):
                        os.unlink(path)


def link_or_copy(source: str, target: str) -> None:
    """``target`` becomes the file ``source`` (atomically): a hard link, or a copy where links are refused.

    Raises
    ------
    ImageIOError
        If neither works.
    """
    from .outputs import atomic_path

    with atomic_path(target) as tmp:
        os.unlink(tmp)
        try:
            os.link(source, tmp)
        except OSError:  # another file system, or one without hard links (FAT, some network mounts)
            shutil.copyfile(source, tmp)


def warp_one(
    inp: str, out: str, plans: PlanCache, *, frame: int | None = None, maps: RunMaps | None = None
) -> BatchItem:
    """One image of a batch or sequence: read, render through its size's plan, write; its error in the item.

    An image too large for memory is warped in strips (`warpcli.tiled`) with the same map.

    Parameters
    ----------
    inp, out : str
        The input image and the output path (checked already, `prepare_batch`).
    plans : PlanCache
    frame : int or None
        The frame number, in a sequence writing maps.
    maps : RunMaps or None
        A run's map files (`warp_run`), written (or linked) before the frame
        (which is then warped whole, never in strips).

    Returns
    -------
    BatchItem
    """
    opts, fmap = plans.opts, plans.fmap
    try:
        header = read_header_or_none(inp) if fmap is not None else None
        if header is not None:
            check_writes(out, header.channels, header.dtype, opts.dtype)
        if header is not None and maps is None and in_parts(inp, header, opts.size, None):
            warp_file_tiled(inp, out, fmap.src, fmap.dst, opts, fmap=fmap, header=header)
            return BatchItem(inp, out)
        image = read_image(inp)
        if header is None:  # (checked above from the header where it was read)
            check_writes(out, image.pixels.shape[2], image.pixels.dtype, opts.dtype)
        shape = opts.size if opts.size is not None else (image.width, image.height)
        check_paste(opts.outside, shape, (image.width, image.height), inp)
        try:  # a frame with other channels than the background's: name the frame
            background_values(opts.background, image.pixels)
        except InputError as err:
            raise naming(err, inp) from err
        plan = plans.get(shape)
        if maps is not None:
            maps.save(frame, fmap, plan, (image.width, image.height))
        try:
            px = plan.render(image.pixels, alpha_channel=image.alpha_channel, associated_alpha=image.associated_alpha)
            write_like(out, image, px, opts.dtype, opts.compression)
        except BaseException:
            if maps is not None:  # a frame's outputs succeed or fail together: no map without its image
                maps.discard(frame)
            raise
        return BatchItem(inp, out)
    except WarpError as err:
        # Without its traceback: that holds this frame, and so the plans and
        # their map, alive as long as the item (a long sequence of failures
        # kept every map).
        return BatchItem(inp, out, err.with_traceback(None))


def _each(work: Callable, tasks: list, jobs: int, on_item: Callable[[BatchItem], None] | None) -> list[BatchItem]:
    """``work`` over ``tasks`` on ``jobs`` threads; items (and ``on_item`` calls) in task order."""
    jobs = check_jobs(jobs) or 1
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


def warp_run(
    src: Polygon, dst: Polygon, tasks: Sequence[tuple[str, str, int]], opts: WarpOptions, *,
    maps: FrameMaps | None = None, jobs: int = 1, on_item: Callable[[BatchItem], None] | None = None,
    missing: dict[int, BatchItem] | None = None,
) -> list[BatchItem]:  # fmt: skip
    """A run of frames that share one polygon pair: its map, then each frame through it.

    Parameters
    ----------
    src, dst : Polygon
        The run's pair (checked already).
    tasks : sequence of (str, str, int)
        Input, output and frame number of each frame, in order.
    opts : WarpOptions
    maps : FrameMaps or None
        Per-frame STMaps to write.
    jobs : int
        Threads warping the run's frames at once.
    on_item : callable or None
        Called with each `BatchItem`, in frame order.
    missing : dict of int to BatchItem, or None
        Frames whose image is missing, with their items: they need no map
        (with every frame missing, ``src`` and ``dst`` may be None and no map
        is built).

    Returns
    -------
    list of BatchItem
        In frame order; a map that cannot be built fails every frame of the run.
    """
    missing = missing or {}
    if all(f in missing for _, _, f in tasks):
        done = [missing[f] for _, _, f in tasks]
        for item in done:
            if on_item is not None:
                on_item(item)
        return done
    try:
        plans = PlanCache(map_between(src, dst, opts.map), opts)
    except WarpError as err:  # a map that cannot be built fails its frames, not the others
        done = [missing.get(f) or BatchItem(inp, out, err.with_traceback(None)) for inp, out, f in tasks]
        for item in done:
            if on_item is not None:
                on_item(item)
        return done
    run_maps = None if maps is None else RunMaps(maps)

    def one(task):
        if task[2] in missing:
            return missing[task[2]]
        return warp_one(task[0], task[1], plans, frame=task[2], maps=run_maps)

    return _each(one, list(tasks), jobs, on_item)


def _pair_of(tasks, pairs, missing):
    """The polygon pair of a run's frames (None, None when every image of it is missing)."""
    first = next((f for _, _, f in tasks if f not in missing), None)
    return pairs[first] if first is not None else (None, None)


def _warp_run_in_worker(src, dst, tasks, opts, maps, level, filters, missing=None, budget=None):
    """`warp_run` in a worker process: its items, and its log records for the parent to log in order."""
    import warnings

    from ._fork import KeptRecords
    from .cores import set_jobs

    set_jobs(budget)  # the parent's (a spawned process starts with the default)

    warnings.filters[:] = filters  # the parent's: the CLI shows no library's warnings
    log = logging.getLogger("warpcli")
    keep = KeptRecords()
    log.handlers[:] = [keep]
    log.propagate = False
    log.setLevel(level)
    try:
        return warp_run(src, dst, tasks, opts, maps=maps, missing=missing), keep.records
    finally:
        log.handlers[:] = []


@_within_budget
def warp_sequence(
    input_pattern: str,
    output_pattern: str,
    frames: Sequence[int] | None,
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    options: WarpOptions | None = None,
    *,
    src_label: str | None = None,
    dst_label: str | None = None,
    on_item: Callable[[BatchItem], None] | None = None,
    jobs: int | None = None,
    maps: FrameMaps | None = None,
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

    With ``jobs`` > 1, one run of frames (still polygons) is warped by
    threads sharing its map; with several runs (animated polygons) the
    maps of the next ``jobs`` runs are built in forked child processes, as
    many at once as the memory budget holds (`warpcli.budget`), while this
    process reads, resamples and writes the frames whose sampling plans
    have arrived: building a map holds the GIL, so on threads the builds
    would take turns. Where that cannot be (forward maps to write, frames
    warped in strips, no ``fork``), the runs go to ``jobs`` worker
    processes, a run each. Items, messages and output bytes are those of
    ``jobs=1``, in frame order; ``jobs=1`` keeps one core busy and no more
    (no thread or process beside the caller's).

    Parameters
    ----------
    input_pattern, output_pattern : str
        Sequence patterns; the output's must differ from the input's.
    frames : sequence of int, or None
        The frames, in order (`warpcli.sequence.parse_frames`); None: those
        of the input pattern on disk (`warpcli.sequence.frames_from_disk`,
        which logs how many as a warning).
    src_path, dst_path : path-like
        Polygon files, still or keyframed.
    options : WarpOptions or None
        As for `warp_image`; ``**changes`` change its fields.
    src_label, dst_label : str or None
        Which polygon of a file holding several (in every keyframe).
    on_item : callable or None
        Called with each `BatchItem` as it is done, in frame order.
    jobs : int or None
        The cores the sequence may keep busy (`warpcli.cores`): threads or
        processes warping frames at once, and the kernels' threads. None:
        the process's budget (`set_jobs`, else every core it may use).
    maps : FrameMaps or None
        Per-frame STMaps to write beside the frames (`FrameMaps`).

    Returns
    -------
    list of BatchItem
        In frame order.

    Raises
    ------
    InputError
        At once, before any work: bad patterns, polygons (at any frame) or
        options, an output that is an input, an input pattern that finds no
        frame where Nuke's reading of ``####`` would (the message says so). A
        frame that fails later (a missing or unreadable image, a write
        error) is reported through ``on_item`` and in its item, and the
        rest go on.
    """
    from .keyframes import read_animated
    from .sequence import expand, frames_from_disk, other_reading_hint, parse_pattern

    opts = resolve_options(options, changes)
    if frames is None:
        frames, message = frames_from_disk(input_pattern)
        logging.getLogger("warpcli").warning("%s", message)
    patterns = {"input": parse_pattern(os.fspath(input_pattern))}
    outputs = {"output": output_pattern}
    if maps is not None:
        outputs.update({"map": maps.inverse, "forward map": maps.forward})
    for what, pattern in outputs.items():
        if pattern is None:
            continue
        parsed = parse_pattern(os.fspath(pattern))
        if parsed is None:
            raise InputError(f"{pattern}: the {what} of a sequence must be a pattern too (#, @ or %04d)")
        for other, known in patterns.items():
            if parsed.pattern == known.pattern:
                raise InputError(f"{pattern}: the {what} pattern is the {other} pattern; frames would be overwritten")
        patterns[what] = parsed
    if maps is not None:
        from .raster.stmap import check_stmap_path

        for pattern in (maps.inverse, maps.forward):
            if pattern is not None:
                check_stmap_path(pattern)
    ins = expand(os.fspath(input_pattern), frames)
    outs = expand(os.fspath(output_pattern), frames)
    hint = other_reading_hint(input_pattern, frames)  # shot.####.exr typed as in Nuke
    if hint is not None:
        raise InputError(hint)
    _warn_about_outputs([output_pattern, *((maps.inverse, maps.forward) if maps is not None else ())], frames)
    # Every output against every input of the run: f.1@.png's frame 1 is f.@.png's frame 11.
    inputs = RunInputs(
        p for p in (*(inp for _, inp in ins), src_path, dst_path, opts.map.theta_file, opts.within_file) if p is not None
    )
    for (f, _), (_, out) in zip(ins, outs):
        check_image_output(out, inputs=inputs)
        for extra in maps.paths(f) if maps is not None else ():
            if extra is not None:
                check_image_output(extra, inputs=inputs)
    # Every file the run writes against every other, as files, not as patterns: out.#.exr and
    # --save-map out.%04d.exr are the same files; o.@.exr's frame 11 is o.1@.exr's map of frame 1.
    check_distinct(
        (what, path) for (f, _), (_, out) in zip(ins, outs)
        for what, path in (("frame", out), *zip(("map", "forward map"), maps.paths(f) if maps is not None else ()))
    )  # fmt: skip
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
            if opts.within is None:  # within_pair checks its cages (several at once, too)
                check_shapes(*pairs[f])
    if opts.within is not None:
        pairs = _within_pairs(pairs, ins, missing, opts.within)
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
    width = _processes(jobs, len(runs), ins, opts)
    if width > 1 and _pipelines(runs, opts, maps, missing):  # maps built in forked children, frames warped here as they arrive
        return _pipelined(runs, pairs, opts, maps, width, jobs, on_item, missing)
    if width <= 1:  # the frames of a run go to the threads
        items: list[BatchItem] = []
        for _, tasks in runs:
            items += warp_run(*_pair_of(tasks, pairs, missing), tasks, opts, maps=maps, jobs=jobs, on_item=on_item, missing=missing)
        return items
    units = []
    for _, tasks in runs:
        # A long run is cut in pieces, each building the map again, so that
        # all workers have work; not when its frames share map files.
        size = len(tasks) if maps is not None else max(1, math.ceil(len(ins) / width))
        units += [tasks[k : k + size] for k in range(0, len(tasks), size)]
    return _in_processes(units, pairs, opts, maps, width, on_item, missing)


def _within_pairs(pairs: dict, ins: list[tuple[int, str]], missing: dict, within: str) -> dict:
    """Each frame's cages within the outline (`warpcli.within.within_pair`), at the first frame's image size.

    Frames with the same cages share one cage mesh; a frame whose cages
    cannot be cut fails the sequence before any work, as a bad polygon does.
    """
    from .within import within_pair

    first = next((inp for f, inp in ins if f not in missing), None)
    if first is None:
        return pairs
    size = read_header(first).displayed_size
    check_same_size([inp for f, inp in ins if f not in missing], size)
    made: dict[tuple[bytes, bytes], tuple] = {}
    out = {}
    for f, (src, dst) in pairs.items():
        key = (src.points.tobytes(), dst.points.tobytes())
        if key not in made:
            pair = within_pair(src, dst, within, size)
            made[key] = (pair.src, pair.dst)
        out[f] = made[key]
    return out


def check_same_size(paths: Sequence[str], size: tuple[int, int]) -> None:
    """Refuse a ``--within`` run whose images differ in size from the first: its outline
    (``image``, a margin clipped to the image) is made once, at the first image's size.

    Images whose header cannot be read are left to fail in their own item.

    Raises
    ------
    InputError
        One line naming the first image of another size, both sizes.
    """
    for path in paths[1:]:
        header = read_header_or_none(path)
        if header is not None and tuple(header.displayed_size) != tuple(size):
            w, h = header.displayed_size
            raise InputError(
                f"{os.fspath(path)}: {w}x{h}, but --within's outline is made once, at the first image's size "
                f"{size[0]}x{size[1]} ({os.fspath(paths[0])}): warp images of each size in a run of their own"
            )


def _warn_about_outputs(patterns, frames) -> None:
    """One warning per output pattern written with ``##``... (16 digits for ``####`` here, 4 in Nuke)."""
    from .sequence import output_reading_warning

    for pattern in patterns:
        line = None if pattern is None or not frames else output_reading_warning(pattern, frames[0])
        if line is not None:
            logging.getLogger("warpcli").warning("%s", line)


def _processes(jobs: int, runs: int, ins: list[tuple[int, str]], opts: WarpOptions) -> int:
    """How many worker processes a sequence gets: 1 (threads only) for one run, else
    ``jobs``, fewer when that many frames would not fit in the memory budget at once."""
    if jobs <= 1 or runs <= 1:
        return 1
    from .budget import max_image_bytes

    header = next((h for h in (read_header_or_none(inp) for _, inp in ins[:8]) if h is not None), None)
    if header is None:
        return jobs
    w, h = opts.size if opts.size is not None else (header.width, header.height)
    # What `tiled.tiled_needed` counts for one frame: its pixels, and the output with its map.
    need = header.width * header.height * header.channels * header.dtype.itemsize + w * h * (header.channels + 12) * 4
    return max(1, min(jobs, runs, max_image_bytes() // max(1, need)))


def _pipelines(runs, opts, maps, missing) -> bool:
    """Whether the runs go through `_pipelined`.

    Not without forked children (`warpcli._fork.available`), nor with
    forward maps to write (they need the map itself, which stays in the
    child), nor when the first run's frames are warped in strips (that needs
    the map too; frames that large go to worker processes whole,
    `_in_processes`). Only the first run's headers are read here: the others'
    are read when their turn comes (`_run_sizes`), beside the workers' builds.
    """
    from ._fork import available

    if not available() or (maps is not None and maps.forward is not None):
        return False
    first = next((tasks for _, tasks in runs if any(f not in missing for _, _, f in tasks)), None)
    return first is None or _run_sizes(first, opts, missing) is not None


def _run_sizes(tasks, opts, missing) -> list[tuple[int, int]] | None:
    """The output sizes of a run's frames, from their headers; None when a frame is warped in
    strips (`_pipelined` then warps the run here, with its map, as `warp_run` does)."""
    found: list[tuple[int, int]] = []
    for inp, _, f in tasks:
        if f in missing:
            continue
        header = read_header_or_none(inp)
        if header is None:
            continue  # its read says why, in its item
        try:
            if in_parts(inp, header, opts.size, None):
                return None
        except WarpError:
            return None
        size = tuple(opts.size) if opts.size is not None else (header.width, header.height)
        if size not in found:
            found.append(size)
    return found


def _plans_in_child(
    src: Polygon | Partition, dst: Polygon | Partition, opts: WarpOptions, sizes, share: int = 1
) -> dict[tuple[int, int], SamplingPlan]:
    """In a forked child (`_pipelined`): a run's map, and its sampling plan for each output size."""
    from ._fork import FORK_ENV
    from .cores import set_jobs

    # This child is already one of the builders beside the parent: its two
    # maps are built one after the other, not in a child of its own, and it
    # keeps to its share of the run's cores (``share``: 1 when there are as
    # many builders as cores), so that the builders and the parent's warping
    # do not crowd the cores with threads.
    os.environ[FORK_ENV] = "0"
    set_jobs(share, pools=False)
    fmap = map_between(src, dst, opts.map)
    return {size: plan_for(fmap, size[0], size[1], opts) for size in sizes}


def _pipelined(runs, pairs, opts, maps, width, jobs, on_item, missing) -> list[BatchItem]:
    """An animated sequence on all cores: the maps of the next runs are built in
    ``width`` forked worker processes while this process reads, resamples and
    writes the frames of the run whose map has arrived.

    A map holds the GIL while it is built (triangle, SuperLU), so the builds go
    to forked children, each with a GIL of its own (`warpcli._fork.Worker`:
    forked once, not per map); only the sampling plans (arrays) come back,
    through memory shared with the workers (`warpcli._fork.SharedMemory`: no
    copy through a pipe). Each worker has the next run queued behind the one
    it builds (``_QUEUED`` calls a worker, as the memory budget allows), so that
    it goes on as soon as it has sent a run's plans, however long this process
    takes to warp the frames before. Runs are taken in frame order, so items,
    ``on_item`` calls and log records (a child's are logged when its plans are
    taken, as `warp_run` would have logged them while building) come in the
    order of ``jobs=1``, and the plans are those `warp_run` makes, bit for bit.
    """
    from collections import deque

    from ._fork import ChildDied, Worker

    items: list[BatchItem] = []
    # [tasks, output sizes, the worker building their plans or None: built here], in run order
    queue: deque[list] = deque()
    workers: list[Worker] = []
    todo = iter(runs)
    # Made when the first run's sizes are known, before the first worker is forked (the
    # workers inherit it); its regions hold plans of that size (a larger one comes through
    # the pipe).
    shared, depth, planned = None, _QUEUED, False

    def least_busy() -> Worker | None:
        if len(workers) < width:  # a worker of its own first
            try:
                workers.append(Worker(_plans_in_child, shared))
            except OSError:  # no process left: the runs go to the workers there are, or are built here
                pass
            else:
                return workers[-1]
        free = [w for w in workers if w.pending < depth]
        return min(free, key=lambda w: w.pending) if free else None

    def submit(entry: list) -> None:
        nonlocal shared, depth, planned
        tasks, run_sizes = entry[0], entry[1]
        src, dst = _pair_of(tasks, pairs, missing)
        if src is not None and run_sizes and not planned:
            shared, depth = _plan_memory([run_sizes], opts, width)
            planned = True
        while src is not None and run_sizes:
            job = least_busy()
            if job is None:
                break
            try:
                job.submit(src, dst, opts, run_sizes, max(1, jobs // width))
            except ChildDied:
                workers.remove(job)
                continue
            entry[2] = job
            return
        entry[2] = None

    def fill() -> None:
        while sum(entry[2] is not None for entry in queue) < width * depth:
            nxt = next(todo, None)
            if nxt is None:
                # No run left to build: the workers with none queued end now, on the
                # other cores, while this process warps the last frames.
                for worker in workers:
                    if not worker.busy:
                        worker.finish()
                return
            _, tasks = nxt
            # None: a frame in strips, warped here with the map (an empty list: no frame readable)
            queue.append([tasks, _run_sizes(tasks, opts, missing) or [], None])
            submit(queue[-1])

    def done(batch: list[BatchItem]) -> None:
        for item in batch:
            items.append(item)
            if on_item is not None:
                on_item(item)

    def warp_frames(tasks, plans) -> None:
        # A function of its own: the plans are let go when it returns, before the next
        # result is taken, so that their shared memory can be lent to the next build.
        cache = PlanCache(None, opts, plans)
        run_maps = None if maps is None else RunMaps(maps)

        def one(task):
            if task[2] in missing:
                return missing[task[2]]
            return warp_one(task[0], task[1], cache, frame=task[2], maps=run_maps)

        items.extend(_each(one, list(tasks), jobs, on_item))

    # The method's kernels loaded here, once, before the builders are forked:
    # each would load its own copy otherwise (about 0.1 s of CPU each).
    from .maps.registry import METHODS

    prepare = getattr(METHODS[opts.map.method].load(), "prepare", None)
    if callable(prepare):
        prepare()
    failed = True
    try:
        fill()
        while queue:
            tasks, _, job = queue.popleft()
            if job is None:  # every image missing, or none readable, or no worker: as with jobs=1
                fill()
                items.extend(warp_run(*_pair_of(tasks, pairs, missing), tasks, opts, maps=maps, jobs=jobs,
                                      on_item=on_item, missing=missing))  # fmt: skip
                continue
            try:
                plans = job.result()
            except WarpError as err:  # a map that cannot be built fails its frames, not the others
                fill()
                done([missing.get(f) or BatchItem(inp, out, err.with_traceback(None)) for inp, out, f in tasks])
                continue
            except ChildDied as err:
                if job in workers:  # (a submit may have found it gone already)
                    workers.remove(job)
                # The runs queued behind this one on the same worker are built here, when their
                # turn comes: given to another worker, they could come back out of order.
                for entry in queue:
                    if entry[2] is job:
                        entry[2] = None
                fill()
                done([missing.get(f) or BatchItem(inp, out, WarpError(f"{inp}: the process building its map ended: {err}"))
                      for inp, out, f in tasks])  # fmt: skip
                continue
            fill()  # the next maps are built while these frames are warped
            warp_frames(tasks, plans)
            del plans
        failed = False
    finally:
        for worker in workers:  # after an error, the builds still running are not waited for
            worker.close(kill=failed)
    return items


#: Calls queued on each of `_pipelined`'s workers at most: the run it builds and the next, so that
#: it never waits for this process to take a result before it starts the next build.
_QUEUED = 2


def _plan_memory(sizes, opts: WarpOptions, width: int):
    """Shared memory for the sampling plans of `_pipelined`'s workers (`warpcli._fork.SharedMemory`),
    and how many calls each worker may have queued: ``(None, 1)`` where even one call each would
    not fit in the memory budget (the plans then come through pipes).

    A region per call in flight (``_QUEUED`` per worker, or one if that many
    would not fit) and one more (the plans this process warps with while
    the workers build the next); each holds a run's plans: the points and
    Jacobians of every pixel of each output size (48 bytes a pixel, the most
    a window takes) and their edge coverage (a few values per pixel of the
    perimeter). Only the pages written take memory.
    """
    from ._fork import SharedMemory
    from .budget import max_image_bytes

    def plan_bytes(w: int, h: int) -> int:
        per_pixel = 16 + (32 if opts.antialias and opts.interp != "nearest" else 0)
        return w * h * per_pixel + 64 * (w + h) * 8 + (1 << 20)

    capacity = max((sum(plan_bytes(w, h) for w, h in run_sizes) for run_sizes in sizes), default=0)
    if capacity == 0:
        return None, 1
    for depth in range(_QUEUED, 0, -1):
        count = width * depth + 1
        if count * capacity <= max_image_bytes():
            try:
                return SharedMemory(count, capacity), depth
            except (OSError, ValueError):  # no shared memory to be had: the pipes
                return None, 1
    return None, 1


def _in_processes(units, pairs, opts, maps, width, on_item, missing) -> list[BatchItem]:
    """Runs of frames on ``width`` worker processes; items, log records and ``on_item`` calls in frame order."""
    import multiprocessing
    import warnings
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from ._fork import die_with_parent, replay
    from .cores import explicit

    level = logging.getLogger("warpcli").getEffectiveLevel()
    filters = list(warnings.filters)
    # Spawned, not forked: OpenImageIO's and OpenEXR's thread pools do not survive a fork.
    # Each worker dies with this process: a SIGTERM's end (warpcli.cli.run) kills only the children
    # it forked, and orphaned workers went on writing frames, then waited for ever.
    pool = ProcessPoolExecutor(
        max_workers=width, mp_context=multiprocessing.get_context("spawn"), initializer=die_with_parent,
        initargs=(os.getpid(),),
    )  # fmt: skip
    items: list[BatchItem] = []
    try:
        futures = [pool.submit(_warp_run_in_worker, *_pair_of(u, pairs, missing), u, opts, maps, level, filters,
                               {f: missing[f] for _, _, f in u if f in missing}, explicit()) for u in units]  # fmt: skip
        for unit, future in zip(units, futures):
            try:
                done, records = future.result()
            except BrokenProcessPool as err:
                done, records = [BatchItem(inp, out, WarpError(f"{inp}: the process warping it ended: {err}")) for inp, out, _ in unit], []
            replay(records)
            for item in done:
                items.append(item)
                if on_item is not None:
                    on_item(item)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return items


@_within_budget
def apply_map_sequence(
    map_path: str | os.PathLike[str],
    input_pattern: str,
    output_pattern: str,
    frames: Sequence[int] | None,
    options: WarpOptions | None = None,
    *,
    t_up: bool | None = None,
    on_item: Callable[[BatchItem], None] | None = None,
    jobs: int | None = None,
    map_scale: str = "refuse",
    **changes: Any,
) -> list[BatchItem]:
    """Warp the frames of a sequence with saved STMaps: one per frame (a pattern), or one for all.

    Each frame is what `warpcli.pipeline.apply_map_file` makes of it. A map
    file is read once for all the frames that use it (per input size): one
    map over the whole sequence, or the hard links `FrameMaps` writes for
    frames that share a map.

    Parameters
    ----------
    map_path : str or path-like
        A sequence pattern (``map.#.exr``: frame ``f`` uses ``map.000f.exr``)
        or one STMap for every frame.
    input_pattern, output_pattern : str
        Sequence patterns, different.
    frames : sequence of int, or None
        The frames; None: those of the input pattern on disk (logged).
    options : WarpOptions or None
        ``interp``, ``background`` and ``dtype`` are used; ``**changes`` change them.
    t_up : bool or None
        Which way the maps' t runs; None: as each map's header says.
    on_item : callable or None
        Called with each `BatchItem`, in frame order.
    jobs : int or None
        The cores the sequence may keep busy (`warpcli.cores`): threads
        warping frames at once (bytes as with 1). None: the process's
        budget (`set_jobs`, else every core it may use).
    map_scale : {"refuse", "stretch"}
        A frame of another size than its map was made for: refused (in its
        item), or the map stretched to it.

    Returns
    -------
    list of BatchItem
        In frame order; a frame whose map, input or output fails is reported
        in its item and the others go on.

    Raises
    ------
    InputError
        At once, for bad patterns or options, or an output that is an input.
    """
    from .raster.stmap import check_stmap_path, load_stmap
    from .sequence import expand, frames_from_disk, other_reading_hint, parse_pattern

    opts = resolve_options(options, changes)
    if frames is None:
        frames, message = frames_from_disk(input_pattern)
        logging.getLogger("warpcli").warning("%s", message)
    seqs = {}
    for what, pattern in (("input", input_pattern), ("output", output_pattern), ("map", map_path)):
        seqs[what] = parse_pattern(os.fspath(pattern))
        if seqs[what] is None and what != "map":
            raise InputError(f"{os.fspath(pattern)}: the {what} of a sequence must be a pattern (#, @ or %04d)")
    if seqs["output"].pattern in (seqs["input"].pattern, seqs["map"] and seqs["map"].pattern):
        raise InputError(f"{output_pattern}: the output pattern is an input pattern; frames would be overwritten")
    check_stmap_path(os.fspath(map_path))
    ins = expand(os.fspath(input_pattern), frames)
    outs = expand(os.fspath(output_pattern), frames)
    for seq in (seqs["input"], seqs["map"]):
        hint = None if seq is None else other_reading_hint(seq.pattern, frames)
        if hint is not None:
            raise InputError(hint)
    _warn_about_outputs([output_pattern], frames)
    tasks = []
    for (f, inp), (_, out) in zip(ins, outs):
        mp = seqs["map"].path(f) if seqs["map"] is not None else os.fspath(map_path)
        check_image_output(out, inputs=(inp, mp))
        tasks.append((mp, inp, out))
    plans: dict[tuple, SamplingPlan] = {}
    lock = threading.Lock()

    def one(task: tuple[str, str, str]) -> BatchItem:
        mp, inp, out = task
        try:
            image = read_image(inp)
            check_writes(out, image.pixels.shape[2], image.pixels.dtype, opts.dtype)
            try:
                st = os.stat(mp)
                key = (st.st_dev, st.st_ino, st.st_mtime_ns, image.width, image.height)
            except OSError:
                key = (mp, image.width, image.height)  # load_stmap says what is wrong
            with lock:  # one load per distinct map file
                plan = plans.get(key)
                if plan is None:
                    points = load_stmap(
                        mp, (image.width, image.height), t_up=t_up, scale=map_scale, image_name=inp
                    )
                    plan = SamplingPlan.from_points(points, interp=opts.interp, background=opts.background)
                    if len(plans) > jobs:  # a map per frame: keep those of the frames in flight, not all
                        del plans[next(iter(plans))]
                    plans[key] = plan
            px = plan.render(image.pixels, alpha_channel=image.alpha_channel, associated_alpha=image.associated_alpha)
            write_like(out, image, px, opts.dtype, opts.compression)
            return BatchItem(inp, out)
        except WarpError as err:
            return BatchItem(inp, out, err)

    return _each(one, tasks, jobs, on_item)
