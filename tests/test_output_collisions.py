"""Two outputs of one run that are one file are refused before any work, whatever their spelling (a review's finding)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from helpers import run_cli, write_png, write_polygon

SRC = [[4, 4], [28, 4], [28, 20], [4, 20]]
DST = [[5, 4], [28, 6], [27, 20], [4, 19]]

# (output pattern, --save-map pattern, --save-forward-map pattern): each names some file twice.
SAME_FILES = [
    ("out/x.#.exr", "out/x.%04d.exr", None),
    ("out/x.#.exr", None, "out/x.%04d.exr"),  # (#### would be 16 digits here, as in oiiotool)
    ("out/y.#.exr", "out/m.#.exr", "out/m.@@@@.exr"),
    ("out/o.@.exr", "out/o.1@.exr", None),  # frame 1's map is o.11.exr, frame 11's image
    ("out/z.%04d.exr", "out/../out/z.#.exr", None),
    ("out/w.#.exr", "link/w.#.exr", None),  # link -> out
]


@pytest.fixture()
def shot(tmp_path):
    (tmp_path / "in").mkdir()
    (tmp_path / "out").mkdir()
    os.symlink(tmp_path / "out", tmp_path / "link")
    img = np.random.default_rng(0).integers(0, 255, (24, 32, 3), dtype=np.uint8)
    for f in range(1, 13):
        write_png(tmp_path / "in" / f"p.{f}.png", img)
        write_png(tmp_path / "in" / f"p.{f:04d}.png", img)
    write_polygon(tmp_path / "a.json", SRC)
    write_polygon(tmp_path / "b.json", DST)
    return tmp_path


@pytest.mark.parametrize(("out", "inverse", "forward"), SAME_FILES)
def test_a_sequence_writing_one_file_twice_is_refused(shot, out, inverse, forward):
    pattern = "in/p.@.png" if "@" in out and "@@@@" not in out else "in/p.#.png"
    args = [pattern, out, "--src", "a.json", "--dst", "b.json", "--frames", "1-12"]
    args += ["--save-map", inverse] if inverse else []
    args += ["--save-forward-map", forward] if forward else []
    cwd = os.getcwd()
    os.chdir(shot)
    try:
        code, err = run_cli(args)
    finally:
        os.chdir(cwd)
    assert code == 2 and err.count("\n") == 1 and "is the same file as the" in err, err
    assert os.listdir(shot / "out") == []


def test_single_warp_outputs_through_a_link_or_dot_are_one_file(shot):
    base = [str(shot / "in/p.1.png"), "--src", str(shot / "a.json"), "--dst", str(shot / "b.json")]
    cases = [
        ([str(shot / "out/o.png"), "--save-map", str(shot / "out/m.exr"), "--save-forward-map", str(shot / "link/m.exr")], "link/m.exr", "--save-map output"),
        ([str(shot / "out/o.png"), "--save-map", str(shot / "out/m2.exr"), "--save-forward-map", str(shot / "out/./m2.exr")], "out/./m2.exr", "--save-map output"),
        ([str(shot / "out/o.png"), "--grid", str(shot / "link/o.png")], "link/o.png", "the output"),
    ]  # fmt: skip
    for extra, named, first in cases:
        code, err = run_cli(base + extra)
        assert code == 2 and err.count("\n") == 1, err
        assert err.startswith(f"warp: error: {shot / named}: ") and first in err, err
        assert os.listdir(shot / "out") == []
    # Different files: written.
    code, err = run_cli(base + [str(shot / "out/o.png"), "--save-map", str(shot / "out/m.exr")])
    assert code == 0, err


@pytest.mark.parametrize("failing", [1, 2])
def test_a_sequence_frame_that_fails_keeps_no_map(shot, monkeypatch, failing):
    # A frame's map was renamed into place before its image was rendered: a frame whose image
    # failed kept its STMap, and a pipeline checking for the map took the frame as done. The run's
    # maps are written by its first frame and linked by the others: a failing first frame's maps
    # go, and the next frame writes them anew.
    from warpcli import batch
    from warpcli.batch import FrameMaps, warp_sequence
    from warpcli.errors import ImageIOError

    real = batch.write_like

    def write_like(out, *args, **kwargs):
        if os.path.basename(out) == f"o.{failing:04d}.png":
            raise ImageIOError(f"{out}: cannot write: no room")
        return real(out, *args, **kwargs)

    monkeypatch.setattr(batch, "write_like", write_like)
    items = warp_sequence(
        str(shot / "in/p.#.png"), str(shot / "out/o.#.png"), [1, 2, 3], shot / "a.json", shot / "b.json",
        maps=FrameMaps(inverse=str(shot / "out/m.#.exr"), forward=str(shot / "out/f.#.exr")), jobs=1,
    )  # fmt: skip
    assert [item.error is not None for item in items] == [f == failing for f in (1, 2, 3)]
    written = sorted(os.listdir(shot / "out"))
    want = sorted(f"{kind}.{f:04d}.{ext}" for f in (1, 2, 3) if f != failing for kind, ext in (("o", "png"), ("m", "exr"), ("f", "exr")))
    assert written == want
