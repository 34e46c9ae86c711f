"""Work in a forked child (`warpcli._fork`): the same result as in the parent, its errors, its crashes."""

from __future__ import annotations

import logging
import os
import signal
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from warpcli import _fork
from warpcli.errors import InputError, MeshingError, WarpError
from warpcli.maps import fem
from warpcli.maps.compose import theta_for
from warpcli.options import MapOptions
from warpcli.polygon import Polygon

from .helpers import simple_polygons

pytestmark = [pytest.mark.skipif(not _fork.available(), reason="no fork here"), pytest.mark.forks]


def _die():
    os.kill(os.getpid(), signal.SIGSEGV)


def _fail():
    raise InputError("bad.json: nothing to mesh")


def _say_and_return(x):
    logging.getLogger("warpcli").warning("from the child: %d", x)
    return {"twice": 2 * x, "array": np.arange(x)}


def test_a_result_and_an_error_come_back_as_they_were():
    got = _fork.Forked(_say_and_return, 5).result()
    assert got["twice"] == 10 and got["array"].tolist() == [0, 1, 2, 3, 4]
    with pytest.raises(InputError, match="^bad.json: nothing to mesh$"):
        _fork.Forked(_fail).result()


def test_a_child_whose_result_is_taken_is_reaped_in_the_background():
    """`result` returns once the result is read, without waiting for the child's exit; the child
    is reaped all the same (no zombie stays), and a later cancel touches no process."""
    pending = _fork.Forked(_say_and_return, 4)
    pid = pending._pid
    assert pending.result()["twice"] == 8
    pending.cancel()
    deadline = time.monotonic() + 10
    while os.path.exists(f"/proc/{pid}") and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not os.path.exists(f"/proc/{pid}")  # reaped: not even a zombie
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)
    assert pid not in _fork._CHILDREN


def test_a_child_that_crashes_is_an_error_not_a_crash():
    with pytest.raises(_fork.ChildDied, match="killed by SIGSEGV"):
        _fork.Forked(_die).result()


def test_what_the_child_logs_is_logged_once_by_the_parent(caplog):
    pending = _fork.Forked(_say_and_return, 3)
    with caplog.at_level(logging.WARNING, logger="warpcli"):
        pending.result()
        pending.result()
    assert [r.getMessage() for r in caplog.records] == ["from the child: 3"]


def test_a_cancelled_child_is_stopped():
    pending = _fork.Forked(time.sleep, 60)
    t0 = time.perf_counter()
    pending.cancel()
    with pytest.raises(_fork.ChildDied, match="SIGKILL"):
        pending.result()
    assert time.perf_counter() - t0 < 10


@settings(max_examples=8, deadline=None)
@given(
    n=st.integers(4, 9), data=st.data(), weights=st.sampled_from(["cotan", "positive"]),
    side=st.sampled_from([("source", "inverse"), ("target", "grid")]),
)
def test_an_fem_map_built_in_a_child_is_the_one_built_here_bit_for_bit(n, data, weights, side):
    src = Polygon(data.draw(simple_polygons(n)), name="a")
    dst = Polygon(data.draw(simple_polygons(n)), name="b")
    opts = MapOptions(weights=weights)
    theta = theta_for(src, dst, opts)
    role, tables = side
    here = fem.build(src, theta, opts, role, (0.0, 0.0, 128.0, 128.0))
    there = fem.build_forked(src, theta, opts, role, (0.0, 0.0, 128.0, 128.0), precompute=tables).result()
    assert np.array_equal(here.mesh.vertices, there.mesh.vertices)
    assert np.array_equal(here.mesh.triangles, there.mesh.triangles)
    assert here.values.tobytes() == there.values.tobytes()
    assert here.weights == there.weights
    # The lookup tables the child made came with the map, the same as made here.
    made = {k: v for k, v in vars(there).items() if isinstance(v, np.ndarray) and k.startswith("_")}
    assert len(made) >= 3
    here.precompute(tables)
    for name, table in made.items():
        assert table.tobytes() == getattr(here, name).tobytes(), name


def test_the_identity_target_of_theta_none_is_not_forked():
    sq = Polygon(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]), name="sq")
    opts = MapOptions(theta="none")
    assert fem.build_forked(sq, theta_for(sq, sq, opts), opts, "target") is None


@pytest.mark.parametrize(
    "method, theta, conditions",
    [(m, t, c) for m in ("fem", "mfs") for t in ("regular", "cyclic", "none") for c in (None, "mixed")
     if t != "none" or (m == "fem" and c is None)],  # --theta none: FEM's straight map only
)  # fmt: skip
def test_children_at_once_are_the_children_the_build_forks(monkeypatch, method, theta, conditions):
    """`compose.children_at_once` (what `warpcli.pipeline` waits for) is the number of children
    `build_map` forks, counted here as it forks them, wherever it says any, and none where the
    method forks none (meshless methods fork after loading their fit, `--theta optimized` after
    its optimization: waiting for those would only delay the caller, so they say 0 too)."""
    from warpcli.maps import base
    from warpcli.maps.compose import build_map, children_at_once

    opts = MapOptions(method=method, theta=theta, **({"conditions": conditions} if conditions else {}))
    forked = []
    init = base.ForkedBuild.__init__

    def counting(self, *args):
        forked.append(args[0])
        init(self, *args)

    monkeypatch.setattr(base.ForkedBuild, "__init__", counting)
    src = Polygon(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 6.0], [4.0, 6.0], [4.0, 10.0], [0.0, 10.0]]), name="L")
    dst = Polygon(src.points * [1.2, 0.9] + [1.0, 2.0], name="L2")
    n = children_at_once(opts)
    try:
        build_map(src, dst, opts, regions=((0.0, 0.0, 12.0, 12.0), (0.0, 0.0, 14.0, 12.0)))
    except WarpError:  # a combination refused later: the forks before it count
        pass
    assert n == 0 or len(forked) == n
    if method == "fem" and theta in ("regular", "cyclic") and conditions is None:
        assert n == 2


def test_an_fem_build_that_dies_in_its_child_names_the_polygon(monkeypatch):
    monkeypatch.setattr(fem, "_built_to_send", lambda *args: _die())
    sq = Polygon(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]), name="square.json")
    opts = MapOptions()
    with pytest.raises(MeshingError, match="^square.json: the process meshing and solving it killed by SIGSEGV"):
        fem.build_forked(sq, theta_for(sq, sq, opts), opts).result()


def test_fork_can_be_turned_off(monkeypatch):
    monkeypatch.setenv(_fork.FORK_ENV, "0")
    assert not _fork.available()
    sq = Polygon(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]), name="sq")
    assert fem.build_forked(sq, theta_for(sq, sq, MapOptions()), MapOptions()) is None


def _echo_or(x):
    if x == "die":
        _die()
    if x == "fail":
        _fail()
    return _say_and_return(x)


def test_a_worker_answers_call_after_call_with_large_arrays_its_errors_and_its_records(caplog):
    workers = [_fork.Worker(_echo_or) for _ in range(2)]  # two alive at once: each must still end when closed
    try:
        for x in (3, 300_000, 5):  # 300_000 values: 2.4 MB, out of band and longer than the pipe
            for w in workers:
                w.submit(x)
            for w in workers:
                with caplog.at_level(logging.WARNING, logger="warpcli"):
                    caplog.clear()
                    out = w.result()
                assert out["twice"] == 2 * x and np.array_equal(out["array"], np.arange(x))
                assert [r.getMessage() for r in caplog.records] == [f"from the child: {x}"]
        workers[0].submit("fail")
        with pytest.raises(InputError, match="nothing to mesh"):
            workers[0].result()
        workers[0].submit(7)
        assert workers[0].result()["twice"] == 14  # still serving after an error
        workers[1].submit("die")
        with pytest.raises(_fork.ChildDied, match="SIGSEGV"):
            workers[1].result()
    finally:
        for w in workers:
            w.close()  # returns: the child saw the end of its requests (or was gone)


@settings(max_examples=5, deadline=None)
@given(calls=st.lists(st.sampled_from([3, 70_000, "fail", "die"]), min_size=2, max_size=5))
def test_calls_queued_on_a_worker_come_back_in_order_and_a_death_fails_those_behind_it(calls):
    """Calls submitted before the earlier ones are taken (70_000 values: out of band, in shared
    memory, a region each): each result is its own call's, in order, also after `finish` (no more
    calls); a call that kills the child raises `ChildDied`, and so does every call queued behind
    it, whose regions are free again."""
    shared = _fork.SharedMemory(len(calls), 70_000 * 8 + 4096)
    worker = _fork.Worker(_echo_or, shared)
    try:
        for x in calls:
            worker.submit(x)
        assert worker.pending == len(calls)
        worker.finish()
        died = False
        for x in calls:
            if died or x == "die":
                with pytest.raises(_fork.ChildDied, match="SIGSEGV"):
                    worker.result()
                died = True
            elif x == "fail":
                with pytest.raises(InputError, match="nothing to mesh"):
                    worker.result()
            else:
                out = worker.result()
                assert out["twice"] == 2 * x and np.array_equal(out["array"], np.arange(x))
                assert _in_shared(shared, out["array"], len(calls)) == (x == 70_000)
                del out
        assert worker.pending == 0
        with pytest.raises(_fork.ChildDied if died else RuntimeError):
            worker.submit(3)
        assert sorted(shared.lend() for _ in calls) == list(range(len(calls)))  # every region given back
    finally:
        worker.close()


def test_a_target_that_dies_in_its_child_fails_the_build_and_names_it(monkeypatch):
    from warpcli.maps.compose import build_map

    real = fem._built_to_send

    def target_dies(polygon, theta, options, role, region, side=None):
        return _die() if role == "target" else real(polygon, theta, options, role, region, side)

    monkeypatch.setattr(fem, "_built_to_send", target_dies)
    sq = Polygon(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]), name="a.json")
    dst = Polygon(np.array([[0.0, 0.0], [12.0, 0.0], [12.0, 10.0], [0.0, 10.0]]), name="b.json")
    region = (0.0, 0.0, 16.0, 16.0)
    with pytest.raises(MeshingError, match="^b.json: the process meshing and solving it killed by SIGSEGV"):
        build_map(sq, dst, MapOptions(), regions=(region, region))


def test_a_fork_beside_a_thread_computing_a_cached_property_does_not_hang():
    """A fork while another thread computes a cached property (any instance of the class): the child reads it.

    Python 3.11's functools.cached_property holds one lock per property for the whole class while it
    computes; a forked map builder then waited on that lock forever (the suite hung at a --save-map
    warp). `warpcli._cached.cached_property` has no lock, as Python 3.12's."""
    import os
    import threading
    import time

    from warpcli._cached import cached_property

    inside, release = threading.Event(), threading.Event()

    class Thing:
        def __init__(self, slow: bool) -> None:
            self.slow = slow

        @cached_property
        def value(self) -> int:
            if self.slow:
                inside.set()
                release.wait(30)
            return 7

    worker = threading.Thread(target=lambda: Thing(True).value)
    worker.start()
    try:
        assert inside.wait(10)
        pid = os.fork()
        if pid == 0:  # the child: one read of another instance's property, then out
            os._exit(0 if Thing(False).value == 7 else 1)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            time.sleep(0.02)
        else:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
            raise AssertionError("the forked child hung reading a cached property")
        assert os.waitstatus_to_exitcode(status) == 0
    finally:
        release.set()
        worker.join()


def test_no_module_uses_the_locking_cached_property_of_the_standard_library():
    """Every cached property in warpcli is `warpcli._cached`'s: a functools one could hang a forked builder."""
    import pathlib
    import re

    package = pathlib.Path(_fork.__file__).parent
    offenders = [
        str(path.relative_to(package))
        for path in sorted(package.rglob("*.py"))
        if path.name != "_cached.py"
        and re.search(r"functools\.cached_property|from functools import[^\n]*\bcached_property", path.read_text())
    ]
    assert offenders == []


@pytest.mark.parametrize(
    "method, side",
    [("mfs", ("source", "inverse")), ("mfs", ("target", "grid")), ("bem", ("source", "inverse")), ("bem", ("target", "grid"))],
)
def test_a_smooth_map_built_in_a_child_is_the_one_built_here_bit_for_bit(method, side):
    """MFS and BEM in a forked child (`warpcli.maps.meshless`): the same fit, certificate, collar,
    first-guess mesh (inverse side), and the same values and pre-images."""
    from warpcli.maps.meshless import BEM, MFS

    builder = {"bem": BEM, "mfs": MFS}[method]
    src = Polygon(np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 18.0], [22.0, 20.0], [20.0, 38.0], [0.0, 40.0]]), name="L")
    dst = Polygon(np.array([[2.0, 0.0], [42.0, 4.0], [38.0, 20.0], [24.0, 22.0], [18.0, 36.0], [0.0, 38.0]]), name="L2")
    opts = MapOptions(method=method, nodes=48)
    theta = theta_for(src, dst, opts)
    role, tables = side
    region = (0.0, 0.0, 48.0, 48.0)
    here = builder.build(src, theta, opts, role, region)
    there = builder.build_forked(src, theta, opts, role, region, precompute=tables).result()
    for name in ("coef", "sites", "nodes"):
        if hasattr(here.solution, name):
            assert np.asarray(getattr(here.solution, name)).tobytes() == np.asarray(getattr(there.solution, name)).tobytes()
    # what the child made came with the map
    assert {"boundary_certificate", "collar", "_certificate"} <= set(vars(there))
    assert ("_guess_mesh" in vars(there)) == ("_guess_locator" in vars(there)) == (tables == "inverse")
    assert there.certify() == here.certify()
    rng = np.random.default_rng(3)
    pts = rng.uniform(0.0, 40.0, (300, 2))
    a, b = here.evaluate(pts, jacobian=True), there.evaluate(pts, jacobian=True)
    assert a.points.tobytes() == b.points.tobytes() and a.jacobian.tobytes() == b.jacobian.tobytes()
    q = a.points[np.isfinite(a.points).all(axis=1)]
    assert here.inverse(q).points.tobytes() == there.inverse(q).points.tobytes()


def test_a_smooth_build_that_dies_in_its_child_names_the_polygon(monkeypatch):
    from warpcli.maps import meshless

    monkeypatch.setattr(meshless, "_built_to_send", lambda *args: _die())
    sq = Polygon(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]), name="square.json")
    opts = MapOptions(method="mfs")
    with pytest.raises(MeshingError, match="^square.json: the process fitting and certifying it killed by SIGSEGV"):
        meshless.MFS.build_forked(sq, theta_for(sq, sq, opts), opts).result()


_FORK_REQUESTED: list = []


def _note_fork_request() -> None:
    for event in _FORK_REQUESTED:
        event.set()


def test_a_fork_waits_for_a_kernel_being_loaded_and_the_child_can_load_kernels():
    """A child that loads a compiled kernel while a thread of the parent held the kernels' lock at the
    fork would wait forever: the fork waits for the lock (`warpcli._native`), the child gets its own."""
    import threading

    from warpcli import _native

    requested = threading.Event()
    if not _FORK_REQUESTED:
        # registered after warpcli._native's handler, so it runs before it: the fork has been asked for
        os.register_at_fork(before=_note_fork_request)
    _FORK_REQUESTED[:] = [requested]
    held, release = threading.Event(), threading.Event()

    def loader():
        with _native._LOCK:  # as a thread loading a kernel holds it
            held.set()
            release.wait(30)

    worker = threading.Thread(target=loader)
    worker.start()
    assert held.wait(10)
    forked = []
    forking = threading.Thread(target=lambda: forked.append(_fork.Forked(_native_kernel_call)))
    forking.start()
    try:
        assert requested.wait(10)
        assert not forked  # asked for while the lock is held: the fork waits
    finally:
        release.set()
        worker.join()
        _FORK_REQUESTED.clear()
    forking.join(20)
    assert forked and forked[0].result() is True


def _native_kernel_call():
    from warpcli.maps.meshless import _load_runtime

    signal.alarm(20)  # a child stuck on the lock ends (ChildDied) rather than hanging the suite
    _load_runtime()
    return True


def _arrays(n, fill):
    """Two large arrays (out of band: 10 n bytes) and a small one (in the pickle), of ``fill``."""
    return {"a": np.full(n, fill, dtype=np.float64), "b": np.full((n // 4, 2), -fill, dtype=np.float32), "small": np.full(3, fill)}


def _is(out, n, fill):
    return (np.array_equal(out["a"], np.full(n, fill)) and np.array_equal(out["b"], np.full((n // 4, 2), -fill, np.float32))
            and out["small"].tolist() == [fill] * 3)  # fmt: skip


def _in_shared(shared, array, regions):
    """Whether ``array``'s memory lies in one of ``shared``'s ``regions`` regions."""
    at = array.ctypes.data
    for k in range(regions):
        start = np.frombuffer(shared.region(k), dtype=np.uint8).ctypes.data
        if start <= at < start + shared.capacity:
            return True
    return False


@settings(max_examples=6, deadline=None)
@given(sizes=st.lists(st.integers(9_000, 60_000), min_size=4, max_size=4))  # "a": 72 kB or more, out of band
def test_results_come_through_shared_memory_never_written_over_while_alive(sizes):
    """A worker's large arrays come back in shared memory, without a copy; a region is lent again
    only once the arrays made over it are gone, so results the caller keeps keep their values; with
    no region free they come through the pipe."""
    shared = _fork.SharedMemory(2, 10 * 60_000 + 128)
    worker = _fork.Worker(_arrays, shared)

    def call(k):
        worker.submit(sizes[k], float(k + 1))
        return worker.result()

    try:
        first, second = call(0), call(1)
        assert _in_shared(shared, first["a"], 2) and _in_shared(shared, second["a"], 2)
        third = call(2)  # both regions hold live results: through the pipe
        assert not _in_shared(shared, third["a"], 2)
        del first
        fourth = call(3)  # the first's region, free again
        assert _in_shared(shared, fourth["a"], 2)
        for out, k in ((second, 1), (third, 2), (fourth, 3)):
            assert _is(out, sizes[k], float(k + 1))  # none written over
    finally:
        worker.close()


def test_a_call_submitted_to_a_worker_that_has_died_raises_and_so_do_those_queued():
    worker = _fork.Worker(_echo_or)
    try:
        worker.submit(3)
        os.kill(worker._pid, signal.SIGKILL)
        os.waitid(os.P_PID, worker._pid, os.WEXITED | os.WNOWAIT)  # dead, not yet reaped
        with pytest.raises(_fork.ChildDied, match="SIGKILL"):
            worker.submit(4)
        with pytest.raises(_fork.ChildDied, match="SIGKILL"):
            worker.result()  # the call queued before its death
        assert worker.pending == 0
    finally:
        worker.close()


def _made_in_place(n, fill):
    """Arrays made by `_fork.empty` (one too large for what is left of the region), and one by numpy."""
    a = _fork.empty((n, 2))
    a[:] = fill
    b = _fork.empty(n * 4, np.float32)
    b[:] = -fill
    c = np.full(n, 2 * fill)
    return {"a": a, "b": b, "c": c, "none": _fork.empty(0)}


@settings(max_examples=5, deadline=None)
@given(n=st.integers(9_000, 30_000), fill=st.floats(-1e6, 1e6))
def test_arrays_made_in_the_lent_region_come_back_without_a_copy_and_the_rest_after_them(n, fill):
    """`_fork.empty` in a worker's call makes its large arrays in the region lent to the call: the
    parent's arrays are those, at their place; a numpy array of the result is copied after them,
    over none of them; an array that does not fit is numpy's, sent as before."""
    shared = _fork.SharedMemory(1, n * 16 + n * 16 + 1024)  # a, b; not c as well
    worker = _fork.Worker(_made_in_place, shared)
    try:
        worker.submit(n, fill)
        out = worker.result()
        assert np.all(out["a"] == fill) and np.all(out["b"] == np.float32(-fill)) and np.all(out["c"] == 2 * fill)
        assert _in_shared(shared, out["a"], 1) and _in_shared(shared, out["b"], 1)
        base = np.frombuffer(shared.region(0), dtype=np.uint8).ctypes.data
        assert out["a"].ctypes.data == base  # made first, at the region's start
        assert not _in_shared(shared, out["c"], 1) and out["none"].size == 0  # no room left for c: the pipe
    finally:
        worker.close()
    assert _fork.empty((3, 2)).shape == (3, 2)  # outside a worker's call: numpy's


def test_an_array_larger_than_a_region_comes_through_the_pipe():
    shared = _fork.SharedMemory(1, 1 << 17)
    worker = _fork.Worker(_arrays, shared)
    try:
        worker.submit(40_000, 2.5)  # 320 kB, more than the region, through the pipe; 80 kB in the region
        out = worker.result()
        assert _is(out, 40_000, 2.5) and not _in_shared(shared, out["a"], 1) and _in_shared(shared, out["b"], 1)
        del out
        worker.submit(4_000, 1.5)  # 32 kB: in band, in the pickle
        assert _is(worker.result(), 4_000, 1.5)
    finally:
        worker.close()


def test_a_brood_kills_its_children_and_those_forked_after_it_is_cancelled():
    """`_fork.Brood`: the children forked in its context (on threads started there too) are killed by
    `cancel`, and a child forked after that is killed at once (the map of a run whose image is refused)."""
    from warpcli.maps.compose import Task

    brood = _fork.Brood()
    context = _fork.watching(brood)
    first = context.run(_fork.Forked, time.sleep, 60)
    on_thread = [context.run(Task, _fork.Forked, time.sleep, 60).result()]  # a Task runs in a copy of the context
    assert brood.wait(2, timeout=10)
    outside = _fork.Forked(_say_and_return, 3)  # not in the context: not the brood's
    t0 = time.perf_counter()
    brood.cancel()
    for child in (first, on_thread[0]):
        with pytest.raises(_fork.ChildDied, match="SIGKILL"):
            child.result()
    late = context.run(_fork.Forked, time.sleep, 60)
    with pytest.raises(_fork.ChildDied, match="SIGKILL"):
        late.result()
    assert time.perf_counter() - t0 < 10
    assert outside.result()["twice"] == 6
    assert not brood.wait(4, timeout=0.01)  # three forked in it, no more
