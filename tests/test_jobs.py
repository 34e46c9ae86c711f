"""--jobs: batches and sequences on several threads give the bytes and messages of one."""

from __future__ import annotations


import numpy as np
import pytest

from helpers import star, write_png, write_polygon, run_cli

pytestmark = pytest.mark.forks  # --jobs 3 runs batches on forked workers, as `warp` does



def test_batch_and_sequence_bytes_and_messages_do_not_depend_on_jobs(tmp_path):
    rng = np.random.default_rng(4)
    (tmp_path / "in").mkdir()
    inputs = []
    for k in range(7):
        size = (96, 128, 3) if k % 3 else (64, 80, 4)  # two output sizes: two pull-backs shared
        inputs.append(write_png(tmp_path / "in" / f"f.{k + 1:04d}.png", rng.integers(0, 256, size, dtype=np.uint8)))
    (tmp_path / "in" / "f.0004.png").write_bytes(b"not a png")  # one bad input in the middle
    src = write_polygon(tmp_path / "s.json", star(cx=40, cy=32, r_in=10, r_out=28))
    dst = write_polygon(tmp_path / "d.json", star(cx=40, cy=32, r_in=8, r_out=30, phase=0.3))
    runs = {}
    for jobs in (1, 3):
        (tmp_path / f"b{jobs}").mkdir()
        batch = run_cli([*inputs, "--src", src, "--dst", dst, "--out-dir", tmp_path / f"b{jobs}", "--jobs", jobs])
        seq = run_cli([tmp_path / "in" / "f.#.png", tmp_path / f"s{jobs}.#.png", "--src", src, "--dst", dst, "--frames", "1-8", "--jobs", jobs])
        files = {p.name: p.read_bytes() for p in sorted(tmp_path.glob(f"b{jobs}/*"))}
        files.update({p.name.replace(f"s{jobs}", "s"): p.read_bytes() for p in sorted(tmp_path.glob(f"s{jobs}.*"))})
        runs[jobs] = (batch, seq, files)
    (b1, s1, f1), (b3, s3, f3) = runs[1], runs[3]
    assert b1 == b3 and b1[0] == 2 and b1[1].count("warp: error:") == 1
    assert s1 == (s3[0], s3[1].replace("s3.", "s1.")) and s1[1].count("warp: error:") == 2  # bad 4, missing 8
    assert f1 == f3 and len(f1) == 6 + 6
