"""--jobs N is the number of cores a run may keep busy (warpcli.cores): the bytes and messages of
every kind of run do not depend on N, and --jobs 1 starts no thread, no process and leaves the
libraries' pools at one thread."""

from __future__ import annotations

import os
import re
import threading

import numpy as np
import pytest

from helpers import run_cli, star, write_png, write_polygon

import warpcli
from warpcli import cores

pytestmark = pytest.mark.forks  # the budget decides whether maps are built in forked children


def _shapes(tmp_path, rng, w, h):
    """A generated star pair inside a w x h image."""
    cx, cy, r = w / 2 + rng.uniform(-2, 2), h / 2 + rng.uniform(-2, 2), min(w, h) / 2
    n = int(rng.integers(4, 7))
    src = star(n=n, cx=cx, cy=cy, r_in=0.35 * r, r_out=0.85 * r, phase=rng.uniform(0, 0.5))
    dst = star(n=n, cx=cx, cy=cy, r_in=0.3 * r, r_out=0.9 * r, phase=rng.uniform(0, 0.5))
    return write_polygon(tmp_path / "s.json", src), write_polygon(tmp_path / "d.json", dst)


def _animated(tmp_path, rng, w, h, first, last):
    import json

    keys = {}
    for name, (r_in, r_out) in (("src", (0.35, 0.85)), ("dst", (0.3, 0.9))):
        frames = {}
        for f in (first, last):
            r = min(w, h) / 2
            frames[str(f)] = star(n=5, cx=w / 2 + rng.uniform(-3, 3), cy=h / 2 + rng.uniform(-3, 3), r_in=r_in * r,
                                  r_out=r_out * r, phase=rng.uniform(0, 0.6)).tolist()  # fmt: skip
        (tmp_path / f"{name}k.json").write_text(json.dumps({"frames": frames}))
        keys[name] = str(tmp_path / f"{name}k.json")
    return keys["src"], keys["dst"]


def _images(directory, rng, count, w, h, name="f.{:04d}.png"):
    os.makedirs(directory, exist_ok=True)
    return [write_png(directory / name.format(k + 1), rng.integers(0, 256, (h, w, 3), dtype=np.uint8)) for k in range(count)]


def _case(kind, tmp_path, seed):
    """The command lines of one generated run, as a function of its output directory."""
    rng = np.random.default_rng(seed)
    w, h = (40, 300) if kind == "tiled" else (int(rng.integers(40, 64)), int(rng.integers(40, 64)))
    frames = _images(tmp_path / "in", rng, 4 if kind in ("batch", "animated", "apply-map") else 1, w, h)
    src, dst = _shapes(tmp_path, rng, w, h)
    polys = ["--src", src, "--dst", dst]
    if kind in ("fem", "tiled"):
        extra = ["--method", kind, "--max-area", "30"] if kind == "fem" else ["--tiled", "--max-area", "30"]
        maps = [] if kind == "tiled" else ["--save-map", "m.exr"]
        return lambda out: [[frames[0], out / "o.png", *polys, *extra, *[out / m if m.endswith(".exr") else m for m in maps], "-v"]]
    if kind == "batch":
        return lambda out: [[*frames, *polys, "--out-dir", out, "-v"]]
    asrc, adst = _animated(tmp_path, rng, w, h, 1, 4)
    seq = [tmp_path / "in" / "f.#.png", "--frames", "1-4"]
    if kind == "animated":
        return lambda out: [[seq[0], out / "o.#.png", *seq[1:], "--src", asrc, "--dst", adst, "--save-map", out / "m.#.exr", "-v"]]
    # apply-map: per-frame maps of an animated shot, then every frame through its map again
    return lambda out: [
        [seq[0], out / "o.#.png", *seq[1:], "--src", asrc, "--dst", adst, "--save-map", out / "m.#.exr"],
        ["apply-map", out / "m.#.exr", seq[0], out / "again.#.png", *seq[1:]],
    ]


def _run(commands, out, jobs):
    out.mkdir()
    said = []
    for args in commands(out):
        code, err = run_cli([*args, "--jobs", jobs])
        said.append((code, re.sub(r" +\d+\.\d+ s\b", " T s", err.replace(str(out), "OUT"))))  # timings vary
    return said, {p.name: p.read_bytes() for p in sorted(out.iterdir())}


@pytest.mark.parametrize("kind", ["fem", "batch", "animated", "apply-map", "tiled"])
def test_bytes_and_messages_do_not_depend_on_the_core_budget(tmp_path, kind):
    seed = sum(map(ord, kind))  # a generated case per kind
    commands = _case(kind, tmp_path, seed)
    runs = {n: _run(commands, tmp_path / f"j{n}", n) for n in (1, 2, 3)}
    said, files = runs[1]
    assert all(code == 0 for code, _ in said), said
    assert len(files) >= {"fem": 2, "tiled": 1, "batch": 4, "animated": 8, "apply-map": 12}[kind]
    for n in (2, 3):
        assert runs[n] == runs[1], f"--jobs {n} differs from --jobs 1"
    assert cores.explicit() is None  # each run's budget ends with it


@pytest.mark.parametrize("method", ["bem", "mfs"])
def test_smooth_methods_do_not_depend_on_the_core_budget(method):
    """BEM and MFS through the library's control (their certificates cost seconds: not checked here)."""
    rng = np.random.default_rng(len(method))
    pixels = rng.integers(0, 256, (44, 52, 4), dtype=np.uint8)
    src = warpcli.Polygon(star(n=5, cx=26, cy=22, r_in=8, r_out=19, phase=rng.uniform(0, 0.5)))
    dst = warpcli.Polygon(star(n=5, cx=26, cy=22, r_in=7, r_out=20, phase=rng.uniform(0, 0.5)))
    made = []
    for n in (1, 2, 3):
        with warpcli.jobs(n):
            r = warpcli.warp_image(pixels, src, dst, alpha_channel=3, method=method, nodes=48, check=False)
        made.append((r.pixels.tobytes(), r.inverse_map.tobytes(), r.jacobian.tobytes()))
    assert made[0] == made[1] == made[2]


class _Observed:
    """Threads started, processes forked or spawned, and the libraries' pools, while a run renders."""

    def __init__(self, monkeypatch):
        import concurrent.futures

        from warpcli.plan import SamplingPlan

        self.threads: list[str] = []
        self.forks = 0
        self.pools: list[str] = []
        self.at_render: list[tuple] = []
        start, fork, render = threading.Thread.start, os.fork, SamplingPlan.render

        def started(thread):
            self.threads.append(thread.name)
            return start(thread)

        def forked():
            self.forks += 1
            return fork()

        def pool(kind):
            init = getattr(concurrent.futures, kind).__init__

            def made(executor, *args, **kwargs):
                self.pools.append(kind)
                return init(executor, *args, **kwargs)

            return made

        def rendering(plan, *args, **kwargs):
            import OpenImageIO as oiio
            from threadpoolctl import threadpool_info

            from warpcli._native import cores as kernel_threads

            blas = tuple(sorted({lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}))
            self.at_render.append((kernel_threads(), oiio.get_int_attribute("threads"), oiio.get_int_attribute("exr_threads"), blas))
            return render(plan, *args, **kwargs)

        monkeypatch.setattr(threading.Thread, "start", started)
        monkeypatch.setattr(os, "fork", forked)
        for kind in ("ThreadPoolExecutor", "ProcessPoolExecutor"):
            monkeypatch.setattr(getattr(concurrent.futures, kind), "__init__", pool(kind))
        monkeypatch.setattr(SamplingPlan, "render", rendering)


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("shot")
    rng = np.random.default_rng(23)
    frames = _images(tmp_path / "in", rng, 3, 48, 40)
    src, dst = _shapes(tmp_path, rng, 48, 40)
    asrc, adst = _animated(tmp_path, rng, 48, 40, 1, 3)
    (tmp_path / "pts.json").write_text("[[24, 20], [20, 18]]")
    return tmp_path, frames, (src, dst), (asrc, adst)


def _commands(shot):
    tmp, frames, (src, dst), (asrc, adst) = shot
    seq = [tmp / "in" / "f.#.png", "--frames", "1-3"]
    return {
        "single": [frames[0], tmp / "o1.png", "--src", src, "--dst", dst, "--save-map", tmp / "m1.exr"],
        "batch": [*frames, "--src", src, "--dst", dst, "--out-dir", tmp / "batch"],
        "animated": [seq[0], tmp / "o.#.png", *seq[1:], "--src", asrc, "--dst", adst, "--save-map", tmp / "m.#.exr"],
        "apply-map": ["apply-map", tmp / "m.#.exr", seq[0], tmp / "again.#.png", *seq[1:]],
        "points": ["points", tmp / "pts.json", tmp / "pts_out.json", "--src", src, "--dst", dst],
    }


def test_jobs_1_keeps_to_one_thread_and_one_process(shot, monkeypatch):
    """No thread, fork or pool is started, and the kernels, OpenImageIO, OpenEXR and BLAS are on one thread."""
    os.makedirs(shot[0] / "batch", exist_ok=True)
    seen = _Observed(monkeypatch)
    for name, args in _commands(shot).items():
        code, err = run_cli([*args, "--jobs", "1"])
        assert code == 0, (name, err)
        assert (seen.threads, seen.forks, seen.pools) == ([], 0, []), name
    assert seen.at_render and set(seen.at_render) == {(1, 1, -1, (1,))}
    assert cores.explicit() is None


def test_jobs_2_does_start_them(shot, monkeypatch):
    """The observation above is not blind: the same runs on two cores fork and start threads."""
    os.makedirs(shot[0] / "batch", exist_ok=True)
    seen = _Observed(monkeypatch)
    for name in ("single", "animated", "batch"):
        assert run_cli([*_commands(shot)[name], "--jobs", "2"])[0] == 0
    assert seen.forks >= 2 and seen.threads and "ThreadPoolExecutor" in seen.pools
    assert {kernels for kernels, *_ in seen.at_render} == {2}


def test_the_library_takes_the_budget_and_puts_it_back(shot, monkeypatch):
    tmp, frames, (src, dst), _ = shot
    import OpenImageIO as oiio

    before = (oiio.get_int_attribute("threads"), oiio.get_int_attribute("exr_threads"), os.environ.get("OPENBLAS_NUM_THREADS"))
    seen = _Observed(monkeypatch)
    pixels = np.zeros((40, 48, 3), np.uint8)
    with warpcli.jobs(1) as n:
        assert n == cores.budget() == 1 and os.environ["OPENBLAS_NUM_THREADS"] == "1"
        warpcli.warp_image(pixels, warpcli.read_polygon(src), warpcli.read_polygon(dst), max_area=40)
    assert (seen.threads, seen.forks) == ([], 0)
    assert cores.explicit() is None and cores.budget() == cores.available()
    assert (oiio.get_int_attribute("threads"), oiio.get_int_attribute("exr_threads"), os.environ.get("OPENBLAS_NUM_THREADS")) == before
    warpcli.warp_batch(frames, tmp / "batch", src, dst, jobs=1)
    assert (seen.threads, seen.forks, seen.pools) == ([], 0, [])
    warpcli.set_jobs(3)
    try:
        assert cores.budget() == 3 and oiio.get_int_attribute("threads") == 3
    finally:
        warpcli.set_jobs(None)
    assert oiio.get_int_attribute("threads") == before[0]


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_a_budget_is_a_whole_number_of_at_least_one(bad):
    with pytest.raises(warpcli.InputError, match="jobs must be a whole number of at least 1"):
        warpcli.set_jobs(bad)
    assert cores.explicit() is None


@pytest.mark.parametrize("command", ["warp", "apply-map", "points", "texture", "volume"])
def test_every_command_that_computes_takes_jobs(command):
    from click.testing import CliRunner

    from warpcli.cli.run import cli

    out = CliRunner().invoke(cli.commands[command], ["--help"])
    assert "--jobs N" in out.output and "cores this run may keep busy" in " ".join(out.output.split())
