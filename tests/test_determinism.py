"""Scripts and CI: byte-identical output whatever the thread count; no size limit."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

from helpers import read_pixels, star, write_png, write_polygon


def _run(args, env_extra):
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    env.update(env_extra)
    done = subprocess.run([sys.executable, "-m", "warpcli", *args], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done


def test_output_bytes_do_not_depend_on_the_thread_count(tmp_path):
    rng = np.random.default_rng(13)
    px = rng.integers(0, 256, (150, 170, 4), dtype=np.uint8)
    inp = write_png(tmp_path / "in.png", px)
    src = write_polygon(tmp_path / "s.json", star(6, 85, 75, 30, 70))
    dst = write_polygon(tmp_path / "d.json", star(6, 85, 75, 22, 72, 0.3))
    outs = []
    for k, env in enumerate(({}, {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}, {"OMP_NUM_THREADS": "2", "NUMBA_NUM_THREADS": "2"})):
        out = tmp_path / f"out{k}.png"
        smap = tmp_path / f"map{k}.exr"
        _run([inp, str(out), "--src", src, "--dst", dst, "--interp", "cubic", "--save-map", str(smap), "-q"], env)
        outs.append((out.read_bytes(), read_pixels(smap).tobytes()))
    assert outs[0] == outs[1] == outs[2]


def test_smooth_methods_give_the_same_bytes_whatever_the_blas_threads(tmp_path):
    """BEM and MFS fit dense least-squares systems; multithreaded BLAS sums them in an order
    that depends on the thread count (it did: OPENBLAS_NUM_THREADS=1 against 2).

    BLAS reads its thread count when it loads, so each count is its own process; each
    process runs the command twice, once per method (``warpcli.cli.main``, what ``python -m
    warpcli`` runs), to start half as many interpreters."""
    px = np.random.default_rng(5).integers(0, 256, (90, 100, 3), dtype=np.uint8)
    inp = write_png(tmp_path / "in.png", px)
    src = write_polygon(tmp_path / "s.json", star(5, 50, 45, 18, 40))
    dst = write_polygon(tmp_path / "d.json", star(5, 50, 45, 14, 42, 0.3))
    script = (
        "import sys\n"
        "from warpcli.cli import main\n"
        "inp, src, dst, out = sys.argv[1:5]\n"
        "for method in ('bem', 'mfs'):\n"
        "    code = main([inp, out.format(method), '--src', src, '--dst', dst, '--method', method, '--nodes', '512', '-q'])\n"
        "    if code:\n"
        "        sys.exit(code)\n"
    )
    # The fits run with BLAS limited to one thread (closed_form.lstsq): any other count than 1
    # shows a limit that does not hold (1 against 2 is where the issue saw the bytes change).
    for k, threads in enumerate(("1", "2")):
        env = {k_: v for k_, v in os.environ.items() if not k_.endswith("_NUM_THREADS")}
        env.update({"OPENBLAS_NUM_THREADS": threads, "OMP_NUM_THREADS": threads})
        out = str(tmp_path / f"{{}}{k}.png")
        done = subprocess.run([sys.executable, "-c", script, inp, src, dst, out], env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    for method in ("bem", "mfs"):
        outs = [(tmp_path / f"{method}{k}.png").read_bytes() for k in range(2)]
        assert outs[0] == outs[1], method


def test_images_wider_than_32767_pixels_warp(tmp_path):
    # OpenCV's remap stops at 32767 px; warpcli has no limit below memory.
    w, h = 33000, 24
    x = np.arange(w)
    px = np.repeat(((x % 256).astype(np.uint8))[None, :, None], h, axis=0)
    inp = write_png(tmp_path / "wide.png", px)
    rect = [[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]
    src = write_polygon(tmp_path / "s.json", rect)
    dst = write_polygon(tmp_path / "d.json", rect)
    _run([inp, str(tmp_path / "out.png"), "--src", src, "--dst", dst, "--interp", "nearest", "-q"], {})
    out = read_pixels(tmp_path / "out.png")
    assert out.shape == (h, w, 1)
    np.testing.assert_array_equal(out, px)  # the identity, exactly, out to column 32999
