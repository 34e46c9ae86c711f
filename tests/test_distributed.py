"""Batches on a Dask cluster: a LocalCluster started by the test gives the bytes of a local run."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

from helpers import star, write_png, write_polygon
from warpcli.cli import main

distributed = pytest.importorskip("dask.distributed")


def test_a_batch_on_a_local_cluster_matches_the_local_batch(tmp_path):
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
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            code = main([*inputs, "--src", src, "--dst", dst, "--out-dir", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address])
    assert code == 2
    assert err.getvalue() == local_err and local_err.count("warp: error:") == 1
    local = {p.name: p.read_bytes() for p in (tmp_path / "local").iterdir()}
    remote = {p.name: p.read_bytes() for p in (tmp_path / "dask").iterdir()}
    assert local == remote and len(local) == 3


def test_an_unreachable_scheduler_is_one_line(tmp_path):
    img = write_png(tmp_path / "in.png", np.zeros((16, 16, 3), dtype=np.uint8))
    poly = write_polygon(tmp_path / "p.json", [[2, 2], [14, 2], [8, 14]])
    (tmp_path / "out").mkdir()
    import dask

    err = io.StringIO()
    with contextlib.redirect_stderr(err), dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
        code = main([img, "--src", poly, "--dst", poly, "--out-dir", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 2 and err.getvalue().count("\n") == 1 and "cannot reach the Dask scheduler" in err.getvalue()
