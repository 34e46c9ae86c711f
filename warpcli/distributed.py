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

import contextlib
import logging
import os
import re
from collections.abc import Callable, Sequence
from typing import Any

from .batch import BatchItem, PlanCache, prepare_batch, warp_one
from .errors import ImageIOError, InputError, WarpError
from .options import WarpOptions, resolve_options
from .pipeline import read_header_or_none

log = logging.getLogger("warpcli")


#: Seconds to wait for a scheduler to answer (connect and handshake) before
#: giving up with one line; ``WARPCLI_DASK_TIMEOUT`` sets another.
CONNECT_TIMEOUT = 10.0
#: Environment variable: seconds to wait for the scheduler.
CONNECT_TIMEOUT_ENV = "WARPCLI_DASK_TIMEOUT"
#: How many times the tasks of images lost with a worker are sent again.
RESUBMITS = 3

_ADDRESS = re.compile(r"(?:(?:tcp|tls|ws|wss)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9][A-Za-z0-9.\-_]*):([0-9]{1,5})")


def check_scheduler(address: object) -> None:
    """Refuse, before any work, what cannot be a scheduler's address.

    ``"local"``, None or a Client pass; a string must be ``[tcp|tls|ws|wss://]HOST:PORT``.

    Raises
    ------
    InputError
    """
    if address is None or address == "local" or not isinstance(address, str):
        return
    m = _ADDRESS.fullmatch(address.strip())
    if m is None or not 0 < int(m.group(2)) < 65536:
        shown = address if len(address) <= 60 else address[:57] + "..."
        raise InputError(f"--scheduler {shown!r}: not a scheduler address; give tcp://HOST:PORT, or 'local'")


def connect_timeout() -> float:
    """Seconds to wait for a scheduler: ``WARPCLI_DASK_TIMEOUT``, else `CONNECT_TIMEOUT`.

    Raises
    ------
    InputError
        If ``WARPCLI_DASK_TIMEOUT`` is not a positive number of seconds.
    """
    value = os.environ.get(CONNECT_TIMEOUT_ENV, "").strip()
    if not value:
        return CONNECT_TIMEOUT
    try:
        seconds = float(value)
    except ValueError:
        seconds = 0.0
    if not 0 < seconds < float("inf"):
        raise InputError(f"{CONNECT_TIMEOUT_ENV}={value!r}: not a positive number of seconds")
    return seconds


def probe_scheduler(address: str, timeout: float) -> None:
    """Connect to ``address`` and shake hands as a Dask client would, within ``timeout`` seconds.

    `dask.distributed.Client`'s timeout covers the connection, not the
    handshake: a server that accepts and never answers would hang it.

    Raises
    ------
    InputError
        If nothing answers in time, or what answers is not a Dask scheduler.
    """
    import asyncio

    from distributed.comm import connect

    async def shake() -> None:
        comm = await asyncio.wait_for(connect(address, timeout=timeout), timeout)
        await comm.close()

    try:
        asyncio.run(shake())
    except (OSError, TimeoutError) as err:
        raise InputError(
            f"cannot reach the Dask scheduler {address}: {str(err) or f'no answer within {timeout:g} s ({CONNECT_TIMEOUT_ENV})'}"
        ) from None
    except Exception as err:  # noqa: BLE001 - any bytes may come back: their decoding fails in any way
        # (struct.error, ValueError of an absurd size, MemoryError, KeyError...).
        first = (str(err).splitlines() or [""])[0][:120]
        raise InputError(
            f"{address}: the server there does not answer as a Dask scheduler ({type(err).__name__}: {first})"
        ) from None


def _resubmit(client, plans, tasks, futures, first: int, err: BaseException) -> bool:
    """Ship the plans again and resubmit every task from ``first`` on that has not succeeded.

    A worker lost mid-batch takes its copy of the plans with it; a worker that
    joined after they were shipped never had one. When no copy is left, every
    task still to run fails ("already forgotten"): shipping them again lets
    the rest of the batch go on. Returns False if the cluster takes nothing more.
    """
    remaining = len(tasks) - first
    log.warning(
        "%s: the task failed on the cluster (%s); shipping the plans again and resubmitting %d image(s)",
        tasks[first][0], str(err) or type(err).__name__, remaining,
    )  # fmt: skip
    try:
        shipped = client.scatter(plans, broadcast=True)
        for j in range(first, len(tasks)):
            if futures[j].status != "finished":
                futures[j].cancel()
                futures[j] = client.submit(warp_one, *tasks[j], shipped, pure=False)
    except Exception as again:  # noqa: BLE001 - the cluster is gone, whatever it raised: the images fail with the first error
        log.warning("cannot resubmit to the cluster: %s", str(again) or type(again).__name__)
        return False
    return True


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
    workers: int | None = None,
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
    workers : int or None
        Workers of a local cluster; None: the core budget (`warpcli.cores.budget`).
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
    from .maps.cage import map_between

    check_scheduler(scheduler)
    timeout = connect_timeout()
    opts = resolve_options(options, changes)
    tasks, src, dst = prepare_batch(
        input_paths, out_dir, src_path, dst_path, pattern, src_label, dst_label, theta_file=opts.map.theta_file,
        within=opts.within,
    )
    # One sampling plan per output size, made here and shipped; an input whose
    # header cannot be read fails in its task, with the message a local run gives.
    cache = PlanCache(map_between(src, dst, opts.map), opts)
    for inp, _ in tasks:
        header = read_header_or_none(inp) if opts.size is None else None
        if opts.size is not None or header is not None:
            cache.get(tuple(opts.size) if opts.size is not None else header.displayed_size)
    plans = PlanCache(None, opts, cache.plans)

    if workers is None:
        from .cores import budget

        workers = budget()
    with quiet_dask():
        return _run(Client, LocalCluster, scheduler, workers, timeout, tasks, plans, on_item)


@contextlib.contextmanager
def quiet_dask():
    """Keep Dask's own log lines off stderr while a batch runs: warp says what went wrong, in its words.

    The handlers distributed gives its loggers in this process are muted; the
    worker processes a `LocalCluster` starts inherit
    ``DASK_LOGGING__DISTRIBUTED`` (read when they import dask). Both are
    restored at the end.
    """
    # distributed gives its loggers ("distributed", "distributed.client",
    # "tornado", ...) stderr handlers of their own: those are muted.
    # (A filter, not a level: a LocalCluster sets their levels when it starts.)
    handlers = {
        handler
        for name, logger in list(logging.root.manager.loggerDict.items())
        if name.split(".")[0] in _DASK_LOGGERS and isinstance(logger, logging.Logger)
        for handler in logger.handlers
    }
    env = os.environ.get(_DASK_LOG_ENV)
    for handler in handlers:
        handler.addFilter(_mute)
    os.environ[_DASK_LOG_ENV] = "critical"
    try:
        yield
    finally:
        for handler in handlers:
            handler.removeFilter(_mute)
        if env is None:
            os.environ.pop(_DASK_LOG_ENV, None)
        else:
            os.environ[_DASK_LOG_ENV] = env


_DASK_LOG_ENV = "DASK_LOGGING__DISTRIBUTED"
_DASK_LOGGERS = ("distributed", "tornado", "bokeh")


def _mute(record: logging.LogRecord) -> bool:
    return False


def _named(err: WarpError | None, absolute: tuple[str, str], given: tuple[str, str]) -> WarpError | None:
    """A worker's error with the paths as the user gave them (the worker was given absolute ones)."""
    if err is not None and len(err.args) == 1 and isinstance(err.args[0], str):
        text = err.args[0]
        for a, g in zip(absolute, given):
            text = text.replace(a, str(g))
        err.args = (text,)
    return err


def _run(Client, LocalCluster, scheduler, workers, timeout, tasks, plans, on_item) -> list[BatchItem]:
    cluster = None
    if isinstance(scheduler, Client):
        client, own = scheduler, False
    else:
        try:
            if scheduler in (None, "local"):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
                client = Client(cluster)
            else:
                probe_scheduler(scheduler, timeout)
                client = Client(scheduler, timeout=timeout)
        except (OSError, TimeoutError) as err:
            raise InputError(f"cannot reach the Dask scheduler {scheduler}: {err}") from None
        own = True
    # The workers get absolute paths: they run in directories of their own (a `dask worker`
    # started anywhere on the shared file system), where the relative names given here
    # meant nothing ("i00.png: no such file" for every image).
    named = tasks
    tasks = [(os.path.abspath(inp), os.path.abspath(out)) for inp, out in tasks]
    try:
        shipped = client.scatter(plans, broadcast=True)
        futures = [client.submit(warp_one, inp, out, shipped, pure=False) for inp, out in tasks]
        items = []
        resent = 0
        for k, (inp, out) in enumerate(named):
            while True:
                try:
                    item = BatchItem(inp, out, _named(futures[k].result().error, tasks[k], (inp, out)))
                except WarpError as err:
                    item = BatchItem(inp, out, err)
                except Exception as err:  # a lost worker, a killed task: that image's failure
                    if resent < RESUBMITS and _resubmit(client, plans, tasks, futures, k, err):
                        resent += 1
                        continue
                    item = BatchItem(inp, out, ImageIOError(f"{inp}: the task failed on the cluster: {err}"))
                break
            items.append(item)
            if on_item is not None:
                on_item(item)
        return items
    finally:
        if own:
            client.close()
        if cluster is not None:
            cluster.close()
