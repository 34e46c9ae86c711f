"""Batches on a Dask cluster (``warp --out-dir DIR --scheduler ADDRESS``): one map, one task per image.

The client checks every path and builds the map once, as `warp_batch` does,
then computes the map's pull-back for each output size among the inputs (from
their headers) and ships it to the workers once (``Client.scatter``,
broadcast): the same arrays a local batch resamples with, so every output has
the bytes of a local run. Each image is one task: the worker reads it,
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

from .errors import ImageIOError, InputError, WarpError
from .options import WarpOptions
from .pipeline import BatchItem, _batch_setup, _options, _sampling, _warp_one


class _Shipped:
    """Pull-backs by output size, as shipped to a worker (what `_warp_one` asks ``get`` of)."""

    def __init__(self, plans: dict) -> None:
        self.plans = plans

    def get(self, shape):
        try:
            return self.plans[tuple(shape)]
        except KeyError:
            raise ImageIOError(f"no pull-back was made for an output of {shape[0]}x{shape[1]}") from None


def _task(inp: str, out: str, plans, opts: WarpOptions, src) -> BatchItem:
    return _warp_one(inp, out, _Shipped(plans), opts, src)


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
    import OpenImageIO as oiio

    from .maps.compose import BijectiveMap

    opts = _options(options, changes)
    tasks, src, dst = _batch_setup(input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label)
    fmap = BijectiveMap.between(src, dst, opts.map)
    # One pull-back per output size; an input whose header cannot be read
    # fails in its task, with the message a local run gives.
    shapes = set()
    for inp, _ in tasks:
        if opts.size is not None:
            shapes.add(tuple(opts.size))
            break
        probe = oiio.ImageInput.open(inp)
        if probe is None:
            oiio.geterror()  # retrieved, so that OpenImageIO does not print it at exit
            continue
        spec = probe.spec()
        shapes.add((spec.width, spec.height))
        probe.close()
    plans = {shape: _sampling(fmap, shape[0], shape[1], opts, keep_jacobian=False) for shape in sorted(shapes)}

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
        futures = [client.submit(_task, inp, out, shipped, opts, src, pure=False) for inp, out in tasks]
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
