"""Batches on a Dask cluster: a LocalCluster started by the test gives the bytes of a local run."""

from __future__ import annotations

import contextlib
import importlib.util
import io

import numpy as np
import pytest

from helpers import star, write_png, write_polygon
from warpcli.cli import main

# Skipped without dask.distributed, which is imported by the tests that use it: every xdist worker
# collects this file and only one runs it (the import is 0.4 s of CPU in each).
pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("dask") is None or importlib.util.find_spec("distributed") is None,
    reason="dask.distributed is not installed",
)


@pytest.fixture(scope="module")
def cluster():
    """Two worker processes, started once for the tests that only send work (each start
    imports dask and warpcli in every worker: seconds of CPU), in the directory the run
    began in, not in any test's."""
    from dask import distributed

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        yield c


def test_a_batch_on_a_local_cluster_matches_the_local_batch(tmp_path, cluster):
    rng = np.random.default_rng(9)
    inputs = [
        write_png(tmp_path / f"in{k}.png", rng.integers(0, 256, (72, 96, 3) if k != 2 else (60, 80, 4), dtype=np.uint8))
        for k in range(4)
    ]
    (tmp_path / "in3.png").write_bytes(b"not a png")  # fails on its worker, the rest go on
    src = write_polygon(tmp_path / "s.json", star(cx=40, cy=30, r_in=9, r_out=26))
    dst = write_polygon(tmp_path / "d.json", star(cx=40, cy=30, r_in=7, r_out=28, phase=0.3))
    (tmp_path / "local").mkdir()
    (tmp_path / "dask").mkdir()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main([*inputs, "--src", src, "--dst", dst, "--out-dir", str(tmp_path / "local")]) == 2
    local_err = err.getvalue()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main([*inputs, "--src", src, "--dst", dst, "--out-dir", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address])
    assert code == 2
    assert err.getvalue() == local_err and local_err.count("warp: error:") == 1
    local = {p.name: p.read_bytes() for p in (tmp_path / "local").iterdir()}
    remote = {p.name: p.read_bytes() for p in (tmp_path / "dask").iterdir()}
    assert local == remote and len(local) == 3


def test_relative_paths_reach_workers_that_run_in_another_directory(tmp_path, monkeypatch, cluster):
    """Workers started elsewhere (a `dask worker` in its own directory) get the images the names
    given here mean, and errors name them as given (every image was "no such file")."""
    rng = np.random.default_rng(4)
    for k in range(3):
        write_png(tmp_path / f"in{k}.png", rng.integers(0, 256, (40, 56, 3), dtype=np.uint8))
    (tmp_path / "in2.png").write_bytes(b"not a png")
    write_polygon(tmp_path / "s.json", star(cx=28, cy=20, r_in=6, r_out=16))
    write_polygon(tmp_path / "d.json", star(cx=28, cy=20, r_in=5, r_out=17, phase=0.3))
    (tmp_path / "out").mkdir()
    args = ["in0.png", "in1.png", "in2.png", "--src", "s.json", "--dst", "d.json", "--out-dir", "out"]
    monkeypatch.chdir(tmp_path)  # the workers started before: they run in the directory the run began in
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main([*args, "--scheduler", cluster.scheduler_address])
    assert code == 2 and sorted(p.name for p in (tmp_path / "out").iterdir()) == ["in0.png", "in1.png"]
    lines = [line for line in err.getvalue().splitlines() if "error" in line]
    assert len(lines) == 1 and lines[0].startswith("warp: error: in2.png:"), err.getvalue()


def test_an_unreachable_scheduler_is_one_line(tmp_path):
    img = write_png(tmp_path / "in.png", np.zeros((16, 16, 3), dtype=np.uint8))
    poly = write_polygon(tmp_path / "p.json", [[2, 2], [14, 2], [8, 14]])
    (tmp_path / "out").mkdir()
    err = io.StringIO()
    with contextlib.redirect_stderr(err), pytest.MonkeyPatch.context() as mp:
        # Refused at once, then retried by dask until the timeout: a short one holds the test
        # process idle for less (2 s before; the line is the same).
        mp.setenv("WARPCLI_DASK_TIMEOUT", "0.5")
        code = main([img, "--src", poly, "--dst", poly, "--out-dir", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 2 and err.getvalue().count("\n") == 1 and "cannot reach the Dask scheduler" in err.getvalue()


def _batch_files(tmp_path, n=2):
    inputs = [write_png(tmp_path / f"in{k}.png", np.full((16, 16, 3), 40 * k, dtype=np.uint8)) for k in range(n)]
    poly = write_polygon(tmp_path / "p.json", [[2, 2], [14, 2], [8, 14]])
    (tmp_path / "out").mkdir()
    return inputs, poly


@pytest.mark.parametrize(
    "address", ["foo", "", " ", "xyz://h:1", "tcp://h", "tcp://h:0", "tcp://h:99999", "tcp://h:port", "inproc://x", "tcp://:1", "h:1:2"]
)
def test_what_is_not_a_scheduler_address_is_refused_in_one_line_before_any_work(tmp_path, address, monkeypatch):
    import warpcli.distributed as wd

    inputs, poly = _batch_files(tmp_path)
    monkeypatch.setattr(wd, "prepare_batch", lambda *a, **k: pytest.fail("work before the address was checked"))
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main([*inputs, "--src", poly, "--dst", poly, "--out-dir", str(tmp_path / "out"), "--scheduler", address])
    assert code == 2 and err.getvalue().count("\n") == 1 and "not a scheduler address" in err.getvalue(), err.getvalue()


def _server(answer):
    """A TCP server on 127.0.0.1 that sends ``answer`` (bytes, or None: nothing) to every client and keeps the line open."""
    import socket
    import threading

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(8)
    held = []

    def serve():
        while True:
            try:
                conn, _ = sock.accept()
            except OSError:
                return
            held.append(conn)
            if answer is not None:
                with contextlib.suppress(OSError):
                    conn.sendall(answer)

    threading.Thread(target=serve, daemon=True).start()
    return sock, held


def _garbage(seed):
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes()


@pytest.mark.parametrize(
    "answer",
    [None, b"HTTP/1.0 200 OK\r\n\r\nhello", b"\xff" * 64, b"\x01" + b"\x00" * 7 + b"\xff" * 8, *(_garbage(s) for s in range(4))],
    ids=["silent", "http", "ff", "lengths", *(f"random{s}" for s in range(4))],
)
def test_a_server_that_is_not_a_scheduler_is_one_line_within_the_timeout(tmp_path, monkeypatch, answer):
    import time

    inputs, poly = _batch_files(tmp_path)
    sock, held = _server(answer)
    # The silent server is answered by the timeout alone: a short one (2 s before) holds the test
    # process idle for less; the others answer at once, within the 2 s a loaded machine may need.
    monkeypatch.setenv("WARPCLI_DASK_TIMEOUT", "0.5" if answer is None else "2")
    err = io.StringIO()
    t0 = time.monotonic()
    try:
        with contextlib.redirect_stderr(err):
            code = main([*inputs, "--src", poly, "--dst", poly, "--out-dir", str(tmp_path / "out"), "--scheduler", f"tcp://127.0.0.1:{sock.getsockname()[1]}"])
    finally:
        sock.close()
        for conn in held:
            conn.close()
    assert code == 2 and err.getvalue().count("\n") == 1, err.getvalue()
    assert "Dask scheduler" in err.getvalue()
    assert time.monotonic() - t0 < 30
    assert not any((tmp_path / "out").iterdir())


def test_a_fifo_among_the_inputs_does_not_block_before_the_cluster(tmp_path):
    import os
    import subprocess
    import sys

    inputs, poly = _batch_files(tmp_path)
    os.mkfifo(tmp_path / "fifo.png")
    env = {**os.environ, "WARPCLI_DASK_TIMEOUT": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "warpcli", *inputs, str(tmp_path / "fifo.png"), "--src", poly, "--dst", poly,
         "--out-dir", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:9"],
        capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip
    assert done.returncode == 2 and "cannot reach the Dask scheduler" in done.stderr, done.stderr


# One kill point: after the first image, the most images (seven) are still to run on plans the
# dead worker held; killing after the third took the same path (the plans shipped again; about 12 s of CPU,
# a second local cluster) and nothing more.
@pytest.mark.parametrize("kill_after", [1])
def test_a_worker_killed_mid_batch_loses_no_image_and_dask_stays_quiet(tmp_path, capfd, kill_after):
    # The worker holding the only copy of the plans (the second one joins
    # after they were shipped) is killed: every image still to run would fail
    # ("already forgotten"); they are shipped again and the batch completes
    # with the bytes of a local run, and stderr has warp's lines only.
    import os
    import signal

    from dask import distributed

    from warpcli.distributed import warp_batch_dask

    rng = np.random.default_rng(kill_after)
    inputs = [write_png(tmp_path / f"in{k}.png", rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)) for k in range(8)]
    src = write_polygon(tmp_path / "s.json", star(cx=32, cy=24, r_in=8, r_out=20))
    dst = write_polygon(tmp_path / "d.json", star(cx=32, cy=24, r_in=6, r_out=22, phase=0.3))
    (tmp_path / "local").mkdir()
    (tmp_path / "dask").mkdir()
    assert main([*inputs, "--src", src, "--dst", dst, "--out-dir", str(tmp_path / "local")]) == 0
    capfd.readouterr()
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            first = next(iter(client.run(os.getpid).values()))
            seen = []

            def on_item(item):
                seen.append(item)
                if len(seen) == kill_after:
                    cluster.scale(2)
                    client.wait_for_workers(2)
                    # Its nanny is told not to start another worker in its place: the dead worker's
                    # plans are lost all the same, the batch ends on the second worker (a third
                    # start of dask and warpcli was 2-3 s of CPU for nothing).
                    nanny = next(n for n in cluster.workers.values() if n.pid == first)
                    nanny.close_gracefully("the test kills its worker")
                    os.kill(first, signal.SIGKILL)

            items = warp_batch_dask(inputs, tmp_path / "dask", src, dst, scheduler=client, on_item=on_item)
            err = capfd.readouterr().err
    assert [i.error for i in items] == [None] * len(inputs), [str(i.error) for i in items]
    local = {p.name: p.read_bytes() for p in (tmp_path / "local").iterdir()}
    remote = {p.name: p.read_bytes() for p in (tmp_path / "dask").iterdir()}
    assert local == remote and len(local) == len(inputs)
    assert "distributed." not in err and "Traceback" not in err, err
