"""Start-up: what each kind of ``warp`` run imports (timings are for bench/startup.py, not tests)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import star, write_png, write_polygon
from warpcli import _elf

#: Imported only when a run needs them (scipy: --interp cubic, BEM and MFS;
#: numba and llvmlite: compiling a kernel the first time on a machine, and llvmlite to load
#: kernels where `warpcli._elf` cannot; _hashlib: OpenSSL, which warpcli does not need).
HEAVY = ("numpy", "scipy", "numba", "llvmlite", "OpenImageIO", "triangle", "_hashlib")

_PROBE = """
import json, sys
from warpcli.cli import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "modules": sorted(m for m in sys.modules if m.split(".")[0] in %r)}))
""" % (HEAVY,)


def _imports(args, env_extra=None, full=False):
    """Run the CLI in a fresh interpreter: its exit status, the heavy packages it imported, its stderr.

    scipy counts only if the package itself was imported: SuperLU's extension
    module alone is loaded without it (warpcli.maps.fem.sparse).
    """
    env = dict(os.environ, **(env_extra or {}))
    done = subprocess.run([sys.executable, "-c", _PROBE, *args], capture_output=True, text=True, env=env)
    doc = json.loads(done.stdout.strip().splitlines()[-1])
    return doc["code"], {m for m in doc["modules"] if full or "." not in m}, done.stderr


def _inputs(tmp_path):
    px = np.random.default_rng(2).integers(0, 256, (60, 70, 3), dtype=np.uint8)
    inp = write_png(tmp_path / "in.png", px)
    src = write_polygon(tmp_path / "s.json", star(6, 35, 30, 12, 27))
    dst = write_polygon(tmp_path / "d.json", star(6, 35, 30, 9, 28, 0.3))
    return inp, src, dst


def test_help_imports_nothing_heavy():
    code, modules, _ = _imports(["--help"])
    assert code == 0
    assert modules == set()


def test_a_missing_polygon_file_fails_before_any_heavy_import(tmp_path):
    inp, _, dst = _inputs(tmp_path)
    code, modules, err = _imports([inp, str(tmp_path / "out.png"), "--src", str(tmp_path / "none.json"), "--dst", dst])
    assert code == 2
    assert "none.json" in err and len(err.strip().splitlines()) == 1
    # numpy and OpenImageIO check the output path first; nothing that builds maps.
    assert not modules & {"scipy", "numba", "llvmlite", "triangle"}
    assert not (tmp_path / "out.png").exists()


def test_a_default_warp_imports_neither_scipy_nor_numba(tmp_path):
    inp, src, dst = _inputs(tmp_path)
    args = [inp, str(tmp_path / "out.png"), "--src", src, "--dst", dst, "-q"]
    _imports(args)  # the first run on a machine may compile the kernels (with numba)
    code, modules, _ = _imports(args, full=True)
    assert code == 0
    assert "scipy" not in modules and "numba" not in modules
    assert {"numpy", "OpenImageIO"} <= modules
    # The cached kernels are loaded by warpcli._elf where it can (no LLVM: 0.04 s of CPU and
    # 50 MB of memory less a process), else by llvmlite; their keys are hashed without OpenSSL.
    assert ("llvmlite" in modules) != _elf.supported()
    assert "_hashlib" not in modules
    # Both maps are meshed in forked children (warpcli._fork): triangle is theirs.
    assert "triangle" not in modules
    # np.unique's test for masked arrays imports numpy.ma (10-20 ms); meshing and
    # edge coverage take their unique values without it.
    assert "numpy.ma" not in modules


_BLAS_PROBE = """
import json, sys
import warpcli.cli
r = sys.modules["warpcli.cli.run"]  # the package's name ``run`` is the function

def probe():
    import numpy  # noqa: F401  (loads its OpenBLAS)
    from threadpoolctl import threadpool_info
    print(json.dumps([p["num_threads"] for p in threadpool_info() if p["internal_api"] == "openblas"]))
    return 0

r.main = probe  # what run() calls once it has set the process up
r.run()
"""


@pytest.mark.parametrize("given", [None, "2"])
def test_the_command_runs_openblas_on_one_thread_unless_told(given):
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    done = subprocess.run([sys.executable, "-c", _BLAS_PROBE], capture_output=True, text=True, env=env, check=False)
    assert done.returncode == 0, done.stderr
    threads = json.loads(done.stdout.strip().splitlines()[-1])
    assert threads and set(threads) == {int(given or 1)}


def test_the_same_bytes_with_the_numba_functions_themselves(tmp_path):
    """WARPCLI_NATIVE=0 calls the @njit kernels instead of their cached machine code."""
    inp, src, dst = _inputs(tmp_path)
    outs = {}
    for native in ("1", "0"):
        for interp in ("linear", "nearest"):
            out = tmp_path / f"out_{native}_{interp}.png"
            code, modules, err = _imports(
                [inp, str(out), "--src", src, "--dst", dst, "--interp", interp, "-q"], {"WARPCLI_NATIVE": native}
            )
            assert code == 0, err
            outs[native, interp] = out.read_bytes()
    assert outs["1", "linear"] == outs["0", "linear"]
    assert outs["1", "nearest"] == outs["0", "nearest"]


# The map is built on other threads while the image is read (warpcli.pipeline._EarlyMap).


def _capture():
    import logging

    records = []

    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record.getMessage())

    handler = Keep()
    logging.getLogger("warpcli").addHandler(handler)
    return records, handler


def _logging_build(monkeypatch):
    """BijectiveMap.between, logging a warning on the thread that builds the map; the
    early maps started (to check the map was indeed built while the image was read)."""
    import logging

    from warpcli import pipeline
    from warpcli.maps.compose import BijectiveMap

    real = BijectiveMap.between.__func__

    def between(cls, *args, **kwargs):
        logging.getLogger("warpcli").warning("built on %s", "its thread")
        return real(cls, *args, **kwargs)

    monkeypatch.setattr(BijectiveMap, "between", classmethod(between))
    started = []
    real_start = pipeline._EarlyMap.start.__func__

    def start(cls, *args):
        started.append(real_start(cls, *args))
        return started[-1]

    monkeypatch.setattr(pipeline._EarlyMap, "start", classmethod(start))
    # A PNG's map is started from the size its first bytes state (warpcli.raster.peek).
    real_guess = pipeline._EarlyMap.guess.__func__

    def guess(cls, *args):
        found = real_guess(cls, *args)
        if found is not None:
            started.append(found)
        return found

    monkeypatch.setattr(pipeline._EarlyMap, "guess", classmethod(guess))
    return started


def test_the_map_threads_log_where_building_the_map_logged(tmp_path, monkeypatch):
    import logging

    from warpcli.pipeline import warp_file, warp_image
    from warpcli.raster.imageio import read_image

    inp, src, dst = _inputs(tmp_path)
    mirrored = write_polygon(tmp_path / "m.json", star(6, 35, 30, 9, 28, 0.3)[::-1])
    started = _logging_build(monkeypatch)
    records, handler = _capture()
    try:
        result = warp_file(inp, tmp_path / "out.png", src, mirrored)
    finally:
        logging.getLogger("warpcli").removeHandler(handler)
    assert started and started[0] is not None
    # The mirror warning (this thread, after reading) first, then the map's, once.
    assert "opposite directions" in records[0]
    assert records[1:] == ["built on its thread"]
    image = read_image(inp)
    again = warp_image(image.pixels, result.map.src, result.map.dst)
    assert again.pixels.tobytes() == result.pixels.tobytes()


def test_an_image_that_cannot_be_read_drops_the_maps_records(tmp_path, monkeypatch):
    import logging

    import pytest

    from warpcli.errors import ImageInputError
    from warpcli.pipeline import warp_file

    inp, src, dst = _inputs(tmp_path)
    data = open(inp, "rb").read()
    cut = tmp_path / "cut.png"
    cut.write_bytes(data[: len(data) // 2])  # the header is whole, the pixels are not
    started = _logging_build(monkeypatch)
    records, handler = _capture()
    try:
        with pytest.raises(ImageInputError, match="cut.png"):
            warp_file(cut, tmp_path / "out.png", src, dst)
    finally:
        logging.getLogger("warpcli").removeHandler(handler)
    assert started and started[0] is not None
    assert records == []
    assert not (tmp_path / "out.png").exists()


def _cancels(monkeypatch):
    """The early maps cancelled (`warpcli.pipeline._EarlyMap.cancel`), by their regions."""
    from warpcli import pipeline

    cancelled = []
    real = pipeline._EarlyMap.cancel

    def cancel(self):
        cancelled.append(self.regions)
        real(self)

    monkeypatch.setattr(pipeline._EarlyMap, "cancel", cancel)
    return cancelled


def test_the_map_of_an_image_that_cannot_be_read_is_cancelled(tmp_path, monkeypatch):
    import pytest

    from warpcli.errors import ImageInputError
    from warpcli.pipeline import warp_file

    inp, src, dst = _inputs(tmp_path)
    data = open(inp, "rb").read()
    cut = tmp_path / "cut.png"
    cut.write_bytes(data[:60])  # the first chunk (the size) whole, nothing after it
    cancelled = _cancels(monkeypatch)
    with pytest.raises(ImageInputError, match="cut.png"):
        warp_file(cut, tmp_path / "out.png", src, dst)
    assert cancelled == [((0.0, 0.0, 70.0, 60.0), (0.0, 0.0, 70.0, 60.0))]  # the size the header states
    assert not (tmp_path / "out.png").exists()


def test_a_png_whose_size_is_turned_by_its_orientation_gets_the_map_of_the_turned_size(tmp_path, monkeypatch):
    """The first bytes' size is a guess: OpenImageIO's header says the image is read turned a quarter
    (EXIF orientation 6), so the map started from the guess is dropped and the right one built."""
    import OpenImageIO as oiio

    from warpcli.pipeline import warp_file, warp_image
    from warpcli.raster.imageio import read_image

    px = np.random.default_rng(5).integers(0, 256, (70, 60, 3), dtype=np.uint8)  # 60 wide, 70 high as stored
    path = str(tmp_path / "turned.png")
    spec = oiio.ImageSpec(60, 70, 3, "uint8")
    spec.attribute("Orientation", 6)
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec) and out.write_image(px) and out.close()
    _, src, dst = _inputs(tmp_path)  # within 70 x 60: the image as displayed
    cancelled = _cancels(monkeypatch)
    result = warp_file(path, tmp_path / "out.png", src, dst)
    assert cancelled == [((0.0, 0.0, 60.0, 70.0), (0.0, 0.0, 60.0, 70.0))]
    image = read_image(path)
    assert image.pixels.shape[:2] == (60, 70)
    again = warp_image(image.pixels, result.map.src, result.map.dst)
    assert again.pixels.tobytes() == result.pixels.tobytes() == read_image(tmp_path / "out.png").pixels.tobytes()


_COMMANDS_PROBE = """
import importlib, json, sys
already = set(sys.modules)  # what the interpreter's site (a sitecustomize, say) loaded is not warp's doing
import click
import warpcli.capture, warpcli.outputs, warpcli.pipeline, warpcli.cli.warp
# before any work starts (a kernel-loading thread may import tempfile once the map is under way)
early = [m for m in ("secrets", "hmac", "tempfile") if m in sys.modules and m not in already]
from warpcli.cli import main
code = main(sys.argv[1:])
loaded = sorted(m for m in sys.modules if m.startswith("warpcli.cli."))
import warpcli.cli as package
module = importlib.import_module("warpcli.cli.points")  # a command's module imported first, by name
from warpcli.cli import points, warp
from warpcli.cli.run import cli
print(json.dumps({
    "code": code, "loaded": loaded,
    "names_are_commands": isinstance(points, click.Command) and isinstance(warp, click.Command)
                          and points is module.points and package.points is points,
    "commands": {name: cli.commands[name].name for name in cli.commands},
    "early": early,
}))
"""


def test_a_warp_imports_its_own_command_module_only_and_every_command_is_still_there(tmp_path):
    """The group's commands are imported when run (`warpcli.cli.group.LazyCommands`); the package's
    names stay the commands whichever module is imported first."""
    _, _, dst = _inputs(tmp_path)
    args = [str(tmp_path / "in.png"), str(tmp_path / "out.png"), "--src", str(tmp_path / "none.json"), "--dst", dst]
    done = subprocess.run([sys.executable, "-c", _COMMANDS_PROBE, *args], capture_output=True, text=True)
    doc = json.loads(done.stdout.strip().splitlines()[-1])
    assert doc["code"] == 2
    commands = {"warpcli.cli.apply_map", "warpcli.cli.edit", "warpcli.cli.points", "warpcli.cli.texture", "warpcli.cli.volume"}
    assert "warpcli.cli.warp" in doc["loaded"] and not commands & set(doc["loaded"])
    assert doc["early"] == []  # nor what outputs and capture no longer import before the work
    assert doc["names_are_commands"]
    assert doc["commands"] == {
        "warp": "warp", "apply-map": "apply-map", "edit": "edit", "points": "points", "texture": "texture", "volume": "volume"
    }


_GC_PROBE = """
import gc, json, sys
before = gc.get_threshold()
collections = []
gc.callbacks.append(lambda phase, info: phase == "start" and collections.append(info["generation"]))
import warpcli._entry
entry_imported = gc.get_threshold()
import warpcli.cli, warpcli.pipeline
imported = gc.get_threshold()
r = sys.modules["warpcli.cli.run"]  # (warpcli.cli.run is the command function: the package's names are commands)
collections.clear()

def probe():  # what run() calls once it has set the process up: a command that only reports
    print(json.dumps([before, entry_imported, imported, gc.get_threshold(), gc.isenabled(), collections]))
    return 0

r.main = probe
warpcli._entry.run()
"""


def test_the_command_collects_garbage_less_often_and_a_library_import_does_not_change_it():
    done = subprocess.run([sys.executable, "-c", _GC_PROBE], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    before, entry_imported, imported, running, enabled, _ = json.loads(done.stdout.strip().splitlines()[-1])
    assert entry_imported == imported == before  # importing warpcli (its entry point too) changes nothing
    assert running[0] >= 20_000 and running[1:] == imported[1:] and enabled


def test_the_entry_point_raises_the_threshold_before_the_command_is_imported():
    """`warpcli._entry.run` (the console script, ``python -m warpcli``) raises it before importing
    click and the command's modules: ``warp --version`` then runs without a collection (at
    Python's 700 its imports made 18)."""
    probe = (
        "import atexit, gc, sys\n"
        "seen = []\n"
        "gc.callbacks.append(lambda phase, info: phase == 'start' and seen.append(info['generation']))\n"
        "atexit.register(lambda: print('collections', len(seen), 'click' in sys.modules, flush=True))\n"
        "import warpcli._entry\n"
        "seen.clear()\n"  # (the package's own import, typing's, made some)
        "sys.argv = ['warp', '--version']\n"
        "warpcli._entry.run()\n"  # ends the process, its exit handlers run
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "collections 0 True"
