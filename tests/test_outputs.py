"""Tests of warpcli.outputs and of a run's outputs succeeding or failing together."""

from __future__ import annotations

import fnmatch
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from helpers import star, write_png, write_polygon
from warpcli.errors import ImageInputError, ImageIOError
from warpcli.outputs import PENDING_MARKER, TEMP_NAME_GLOB, TEMP_NAME_PATTERN, PendingOutputs, atomic_path


def test_pending_outputs_are_renamed_together(tmp_path):
    with PendingOutputs() as out:
        a = out.path(tmp_path / "a.png")
        b = out.path(tmp_path / "b.json")
        assert os.path.basename(a).startswith(".a" + PENDING_MARKER) and a.endswith(".png")
        open(a, "w").write("a")
        open(b, "w").write("b")
        assert sorted(os.listdir(tmp_path)) == sorted(os.path.basename(p) for p in (a, b))
    assert sorted(os.listdir(tmp_path)) == ["a.png", "b.json"]


@pytest.mark.parametrize("char", ["x", "é", "日"])
def test_pending_outputs_take_every_name_the_file_system_allows(tmp_path, char):
    # Any name up to NAME_MAX bytes, in one-, two- and three-byte UTF-8: the pending file's
    # longer name is shortened to fit, and the output gets the name asked for.
    limit = os.pathconf(tmp_path, "PC_NAME_MAX")
    step = len(char.encode())
    names = {char * max(1, (n - 4) // step) + ".png" for n in range(5, limit + 1, 7)} | {char * ((limit - 4) // step) + ".png"}
    with PendingOutputs() as out:
        for name in names:
            tmp = out.path(tmp_path / name)
            assert len(os.fsencode(os.path.basename(tmp))) <= limit and PENDING_MARKER in tmp and tmp.endswith(".png")
            open(tmp, "w").write(name)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)
    assert all((tmp_path / name).read_text() == name for name in names)


def test_the_command_writes_outputs_with_the_longest_names_allowed(tmp_path):
    # The image, its report and its map, each named up to the file system's limit (a pending
    # file's longer name made a traceback after the work was done).
    from warpcli.cli import main

    limit = os.pathconf(tmp_path, "PC_NAME_MAX")
    img = write_png(tmp_path / "in.png", np.zeros((40, 40, 3), np.uint8))
    src, dst = write_polygon(tmp_path / "a.json", star(5, 20, 20, 8, 16)), write_polygon(tmp_path / "b.json", star(5, 20, 20, 9, 17))
    outs = [tmp_path / ("o" * (limit - len(ext)) + ext) for ext in (".png", ".json", ".exr")]
    assert main([img, "--src", src, "--dst", dst, str(outs[0]), "--report", str(outs[1]), "--save-map", str(outs[2])]) == 0
    assert all(p.is_file() and p.stat().st_size for p in outs)
    assert not [p for p in os.listdir(tmp_path) if PENDING_MARKER in p]


def test_a_pending_output_that_cannot_be_created_is_one_error_naming_it(tmp_path):
    with pytest.raises(ImageInputError, match=r"/nowhere/a.png: cannot write: No such file or directory$"):
        with PendingOutputs() as out:
            out.path(tmp_path / "nowhere" / "a.png")
    assert os.listdir(tmp_path) == []


def test_a_failure_leaves_nothing_and_names_the_final_path(tmp_path):
    with pytest.raises(ImageIOError) as info:
        with PendingOutputs() as out:
            a = out.path(tmp_path / "a.png")
            open(a, "w").write("a")
            raise ImageIOError(f"{a}: cannot write: disk full")
    assert os.listdir(tmp_path) == []
    assert str(info.value) == f"{tmp_path / 'a.png'}: cannot write: disk full"


def _inputs(tmp_path):
    img = write_png(tmp_path / "in.png", np.full((64, 64, 3), 128, dtype=np.uint8))
    src = write_polygon(tmp_path / "s.json", star(cx=32, cy=32, r_in=12, r_out=28))
    dst = write_polygon(tmp_path / "d.json", star(cx=32, cy=32, r_in=10, r_out=30, phase=0.2))
    return img, src, dst


def test_a_failing_report_leaves_no_output_at_all(tmp_path, monkeypatch):
    import warpcli.pipeline as pipeline

    img, src, dst = _inputs(tmp_path)
    out_dir = tmp_path / "out"
    out_dir.mkdir()

    def fail(path, doc):
        raise ImageIOError(f"{path}: cannot write: No space left on device")

    monkeypatch.setattr(pipeline, "_write_json", fail)
    with pytest.raises(ImageIOError, match=r"out/r.json: cannot write"):
        pipeline.warp_file(
            img, out_dir / "o.png", src, dst, report_path=out_dir / "r.json", grid_path=out_dir / "g.png",
            save_map=out_dir / "m.exr",
        )  # fmt: skip
    assert os.listdir(out_dir) == []


def test_sigterm_while_writing_leaves_nothing(tmp_path):
    """SIGTERM is handled like Ctrl-C: exit 143, one line, no output, no temporary file."""
    img, src, dst = _inputs(tmp_path)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    script = f"""
import os, signal, sys
import warpcli.raster.imageio as io
real = io._write
def write_then_die(*args, **kwargs):
    real(*args, **kwargs)
    os.kill(os.getpid(), signal.SIGTERM)
io._write = write_then_die
from warpcli.cli import main
sys.exit(main([{str(img)!r}, "--src", {src!r}, "--dst", {dst!r}, {str(out_dir / "o.png")!r}, "--report", {str(out_dir / "r.json")!r}]))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 143, done.stderr
    assert done.stderr.strip() == "warp: terminated"
    assert os.listdir(out_dir) == []


def test_a_checked_write_to_a_full_device_is_one_error():
    from warpcli.outputs import write_checked

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    with pytest.raises(ImageIOError, match=r"^out.json: cannot write: No space left on device$"):
        write_checked("/dev/full", b"{}\n" * 10000, "out.json")


# --- One file written atomically ------------------------------------------------------------


def temp_name_regex(stem, ext):
    head, tail = TEMP_NAME_PATTERN.split("XXXXXXXX")
    return re.escape(head.format(stem=stem)) + r"[a-z0-9_]{8}" + re.escape(tail.format(ext=ext))


@pytest.mark.parametrize("name", ["out.png", "out.tar.exr", "noext", "ünï cödé.tif", "x" * 240 + ".png"])
def test_temporary_files_are_hidden_recognisable_and_beside_the_output(tmp_path, name):
    out = tmp_path / name
    with atomic_path(str(out)) as tmp:
        assert os.path.dirname(tmp) == str(tmp_path)  # same file system: an atomic rename
        base = os.path.basename(tmp)
        stem, ext = os.path.splitext(name)
        assert base.startswith(".") and base.endswith(ext) and fnmatch.fnmatch(base, TEMP_NAME_GLOB)
        if len(name) < 200:
            assert re.fullmatch(temp_name_regex(stem, ext), base), base
        else:  # shortened to fit the file system's limit, still recognisable
            assert len(os.fsencode(base)) <= 255 and ".warpcli-tmp-" in base
        with open(tmp, "w") as fh:
            fh.write("data")
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]
    assert out.read_text() == "data"


@pytest.mark.parametrize(
    "failure,error,reason",
    [
        (RuntimeError("a bug"), RuntimeError, "a bug"),
        (OSError(28, os.strerror(28)), ImageIOError, "No space left on device"),
        (OSError(5, os.strerror(5)), ImageIOError, "Input/output error"),
        (OSError(13, os.strerror(13)), ImageInputError, "Permission denied"),
        (ImageIOError("x.png: its own message"), ImageIOError, "its own message"),
    ],
)
def test_a_failed_body_leaves_nothing_and_names_the_file(tmp_path, failure, error, reason):
    out = tmp_path / "out.json"
    out.write_text("old")
    with pytest.raises(error) as info:
        with atomic_path(str(out)) as tmp:
            with open(tmp, "w") as fh:
                fh.write("partial")
            raise failure
    assert reason in str(info.value)
    if isinstance(failure, OSError) and not isinstance(failure, ImageIOError):
        assert str(info.value) == f"{out}: cannot write: {reason}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"] and out.read_text() == "old"


def test_outputs_budget_and_capture_are_base_modules():
    """They import neither raster, maps, report nor pipeline (not even through another
    module), nor numpy: anything may use them."""
    script = (
        "import sys, warpcli.outputs, warpcli.budget, warpcli.capture; "
        "print(sorted(m for m in sys.modules if m.startswith(('warpcli.', 'numpy'))))"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == str(
        sorted(["warpcli.budget", "warpcli.capture", "warpcli.errors", "warpcli.files", "warpcli.outputs"])
    )
