"""Batches on a Dask cluster (``warp --out-dir DIR --scheduler ADDRESS``): one map, one task per image.

The client checks every path and builds the map once, as `warp_batch` does,
then makes its sampling plan (`warpcli.plan.SamplingPlan`) for each output
size among the inputs (from their headers) and ships the plans to the workers
once (``Client.scatter``, broadcast): the plans a local batch renders with,
so every output has the bytes of a local run. Each image is one task: the worker reads it,
resamples, writes (atomically, as everywhere). A task that fails is that
image's error (a bad input, a full disk, a lost worker); the others go on.

Workers need warpcli installed and the paths visible (a shared file system);
on a laptop, ``--scheduler local`` starts a `LocalCluster`. Needs
``pip install 'warpcli[dask]'``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

from .batch import BatchItem, PlanCache, prepare_batch, warp_one
from .errors import ImageIOError, InputError, WarpError
from .options import WarpOptions, resolve_options
from .pipeline import read_header_or_none


def warp_batch_dask(
    input_paths: Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    options: WarpOptions | None = None,
    *,
    scheduler: Any = None,
    pattern: str = "{name}",
    src_label: str | None = None,
    dst_label: str | None = None,
    on_item: Callable[[BatchItem], None] | None = None,
    workers: int = 2,
    **changes: Any,
) -> list[BatchItem]:
    """`warp_batch` on a Dask cluster.

    Parameters
    ----------
    input_paths, out_dir, src_path, dst_path, options, pattern, src_label, dst_label, on_item
        As for `warp_batch`.
    scheduler : str, dask.distributed.Client or None
        A scheduler's address (``tcp://host:8786``), ``"local"`` (a
        `LocalCluster` of ``workers`` processes, closed at the end), or a
        Client.
    workers : int
        Workers of a local cluster.
    **changes
        Fields of `WarpOptions` or `MapOptions` to change.

    Returns
    -------
    list of BatchItem
        In input order; ``on_item`` is called in input order too.

    Raises
    ------
    InputError
        As `warp_batch`, before any work; also if dask.distributed is not
        installed or the scheduler cannot be reached.
    """
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise InputError("--scheduler needs dask.distributed: pip install 'warpcli[dask]'") from None
    from .maps.compose import BijectiveMap

    opts = resolve_options(options, changes)
    tasks, src, dst = prepare_batch(
        input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label, theta_file=opts.map.theta_file
    )
    # One sampling plan per output size, made here and shipped; an input whose
    # header cannot be read fails in its task, with the message a local run gives.
    cache = PlanCache(BijectiveMap.between(src, dst, opts.map), opts)
    for inp, _ in tasks:
        header = read_header_or_none(inp) if opts.size is None else None
        if opts.size is not None or header is not None:
            cache.get(tuple(opts.size) if opts.size is not None else header.displayed_size)
    plans = PlanCache(None, opts, cache.plans)

    cluster = None
    if isinstance(scheduler, Client):
        client, own = scheduler, False
    else:
        try:
            if scheduler in (None, "local"):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
                client = Client(cluster)
            else:
                client = Client(scheduler)  # waits distributed.comm.timeouts.connect (30 s by default)
        except (OSError, TimeoutError) as err:
            raise InputError(f"cannot reach the Dask scheduler {scheduler}: {err}") from None
        own = True
    try:
        shipped = client.scatter(plans, broadcast=True)
        futures = [client.submit(warp_one, inp, out, shipped, pure=False) for inp, out in tasks]
        items = []
        for (inp, out), future in zip(tasks, futures):
            try:
                item = future.result()
            except WarpError as err:
                item = BatchItem(inp, out, err)
            except Exception as err:  # a lost worker, a killed task: that image's failure
                item = BatchItem(inp, out, ImageIOError(f"{inp}: the task failed on the cluster: {err}"))
            items.append(item)
            if on_item is not None:
                on_item(item)
        return items
    finally:
        if own:
            client.close()
        if cluster is not None:
            cluster.close()
