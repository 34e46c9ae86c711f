"""End-to-end tests of the ``warp`` command: through CliRunner and through main()."""

from __future__ import annotations

import io
import logging
import os
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from helpers import read_pixels, write_png, write_polygon
from warpcli import __version__
from warpcli.cli import main, warp
from warpcli.maps.fem.mesh import MAX_TRIANGLES

SRC = [[8.0, 8.0], [56.0, 8.0], [56.0, 56.0], [8.0, 56.0]]
DST = [[4.0, 10.0], [60.0, 6.0], [50.0, 58.0], [10.0, 50.0]]


@pytest.fixture(autouse=True)
def _restore_warpcli_logger():
    """warp installs a handler on the stream of the moment; don't leak it to other tests."""
    log = logging.getLogger("warpcli")
    saved = (log.handlers[:], log.level, log.propagate)
    yield
    log.handlers[:], log.level, log.propagate = saved


@pytest.fixture
def files(tmp_path):
    """A 64x64 RGB uint8 image and two 4-gons in tmp_path; OUTPUT not yet written."""
    pixels = np.random.default_rng(7).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    return SimpleNamespace(
        dir=tmp_path,
        pixels=pixels,
        image=write_png(tmp_path / "in.png", pixels),
        src=write_polygon(tmp_path / "src.json", SRC),
        dst=write_polygon(tmp_path / "dst.json", DST),
        out=str(tmp_path / "out.png"),
    )


def argv(f, *extra, image=None, out=None, src=None, dst=None):
    return [
        image or f.image,
        out or f.out,
        "--src",
        src or f.src,
        "--dst",
        dst or f.dst,
        *extra,
    ]


def invoke(*args):
    return CliRunner().invoke(warp, list(args), catch_exceptions=False)


# --- success -----------------------------------------------------------------


def test_warp_writes_output_like_the_input_and_prints_nothing(files):
    result = invoke(*argv(files))
    assert result.exit_code == 0, result.output
    assert result.stdout == ""
    assert result.stderr == ""
    out = read_pixels(files.out)
    assert out.shape == files.pixels.shape
    assert out.dtype == files.pixels.dtype
    # Inside DST the picture came from the input, outside it is the background.
    assert out[32, 32].any()
    assert (out[0, 0] == 0).all()
    assert sorted(os.listdir(files.dir)) == ["dst.json", "in.png", "out.png", "src.json"]


def test_main_returns_zero_and_prints_nothing(files, capsys):
    assert main(argv(files)) == 0
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == ""
    assert read_pixels(files.out).shape == (64, 64, 3)


@pytest.mark.parametrize("size", ["40x30", "40X30"])
def test_size_sets_the_output_size(files, size):
    result = invoke(*argv(files, "--size", size))
    assert result.exit_code == 0, result.output
    out = read_pixels(files.out)
    assert out.shape == (30, 40, 3)  # (height, width, channels)
    assert out.dtype == np.uint8


def test_quiet_prints_nothing_at_all(files):
    result = invoke(*argv(files, "-q"))
    assert result.exit_code == 0
    assert result.output == ""
    assert result.stdout == ""
    assert result.stderr == ""
    assert os.path.exists(files.out)


def test_quiet_still_reports_errors(files, capsys):
    missing = str(files.dir / "missing.json")
    assert main(argv(files, "-q", src=missing)) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f"warp: error: {missing}: ")


def test_verbose_reports_timings_on_stderr_only(files):
    result = invoke(*argv(files, "-v"))
    assert result.exit_code == 0
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert any(line.startswith("warp: mesh ") for line in lines)
    assert any(line.startswith("warp: resample ") for line in lines)


def test_version(capsys):
    result = invoke("--version")
    assert result.exit_code == 0
    assert result.stdout.strip() == f"warp, version {__version__}"
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"warp, version {__version__}"


def assert_full_help(text):
    assert text.startswith("Usage: warp [OPTIONS] INPUT OUTPUT")
    assert "Examples:" in text
    assert "warp face.png --src face.json --dst smile.json warped.png" in text
    assert "Exit status:" in text
    for code in ("0    success", "1    failure", "2    bad input", "143: terminated"):
        assert code in text
    assert "[nearest|linear|cubic]" in text


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_help_shows_an_example_and_the_exit_codes(flag, capsys):
    result = invoke(flag)
    assert result.exit_code == 0
    assert result.stderr == ""
    assert_full_help(result.stdout)
    assert main([flag]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert_full_help(captured.out)


def test_interp_offers_exactly_three_filters():
    (param,) = [p for p in warp.params if p.name == "interp"]
    assert tuple(param.type.choices) == ("nearest", "linear", "cubic")


@pytest.mark.parametrize("interp", ["nearest", "linear", "cubic"])
def test_interp_accepts_each_filter(files, interp):
    result = invoke(*argv(files, "--interp", interp))
    assert result.exit_code == 0, result.output
    assert read_pixels(files.out).shape == (64, 64, 3)


@pytest.mark.parametrize("interp", ["bilinear", "NEAREST", "lanczos", ""])
def test_interp_rejects_anything_else(files, interp):
    result = invoke(*argv(files, "--interp", interp))
    assert result.exit_code == 2
    assert "--interp" in result.stderr
    assert not os.path.exists(files.out)


def test_nearest_identity_warp_reproduces_the_pixels_inside(files):
    result = invoke(*argv(files, "--interp", "nearest", dst=files.src))
    assert result.exit_code == 0
    out = read_pixels(files.out)
    # Pixel centres strictly inside SRC (8..56) map to themselves.
    np.testing.assert_array_equal(out[9:55, 9:55], files.pixels[9:55, 9:55])


def test_existing_output_is_replaced_atomically(files):
    with open(files.out, "wb") as fh:
        fh.write(b"old contents, not an image")
    old_inode = os.stat(files.out).st_ino
    with open(files.out, "rb") as reader:  # a reader that opened the old file ...
        assert main(argv(files)) == 0
        # ... still sees the whole old file: the new one was renamed over it,
        # not written into it.
        assert reader.read() == b"old contents, not an image"
    assert os.stat(files.out).st_ino != old_inode
    out = read_pixels(files.out)
    assert out.shape == (64, 64, 3)
    assert out.dtype == np.uint8
    assert sorted(os.listdir(files.dir)) == ["dst.json", "in.png", "out.png", "src.json"]


def test_failed_run_leaves_an_existing_output_untouched(files, capsys):
    with open(files.out, "wb") as fh:
        fh.write(b"previous result")
    bad = write_polygon(files.dir / "two.json", SRC[:2])
    assert main(argv(files, src=bad)) == 2
    with open(files.out, "rb") as fh:
        assert fh.read() == b"previous result"


def test_same_run_twice_gives_identical_files(files):
    args = argv(files, "--interp", "cubic", "--size", "48x40", "--background", "0.2,0.4,0.6")
    assert invoke(*args).exit_code == 0
    with open(files.out, "rb") as fh:
        first = fh.read()
    os.unlink(files.out)
    assert invoke(*args).exit_code == 0
    with open(files.out, "rb") as fh:
        second = fh.read()
    assert first == second


# --- bad input: exit 2, one line on stderr, no output ------------------------


def write_text(path, text: str) -> str:
    path.write_text(text)
    return str(path)


def _missing_polygon(f):
    p = str(f.dir / "missing.json")
    return argv(f, src=p), [p, "no such file"]


def _invalid_json(f):
    p = write_text(f.dir / "bad.json", "[[8, 8], [56, 8],\n [56, 56] [8, 56]]")
    return argv(f, dst=p), [p, "invalid JSON at line 2, column 11"]


def _too_few_vertices(f):
    p = write_polygon(f.dir / "two.json", SRC[:2])
    return argv(f, src=p), [p, "at least 3 vertices, got 2"]


def _vertex_counts_differ(f):
    p = write_polygon(f.dir / "tri.json", DST[:3])
    return argv(f, dst=p), [f"{p}: polygon has 3 vertices but {f.src} has 4"]


def _non_finite(f):
    p = write_text(f.dir / "nan.json", "[[8, 8], [NaN, 8], [56, 56], [8, 56]]")
    return argv(f, src=p), [p, "vertex 1 has a non-finite coordinate"]


def _infinite(f):
    p = write_text(f.dir / "inf.json", "[[8, 8], [56, 8], [56, -Infinity], [8, 56]]")
    return argv(f, dst=p), [p, "vertex 2 has a non-finite coordinate"]


def _non_numeric(f):
    p = write_text(f.dir / "str.json", '[[8, 8], ["56", 8], [56, 56], [8, 56]]')
    return argv(f, src=p), [p, 'vertex 1 has a non-numeric coordinate: "56"']


def _repeated(f):
    p = write_polygon(f.dir / "closed.json", SRC + [SRC[0]])
    return argv(f, src=p), [p, "vertices 0 and 4 are repeated at (8.0, 8.0)", "closes itself"]


def _zero_area(f):
    p = write_polygon(f.dir / "line.json", [[8, 8], [20, 20], [32, 32], [44, 44]])
    return argv(f, src=p), [p, "zero area"]


def _self_intersecting(f):
    # Edge 0 (y = x) and edge 2 (y = 60 - 1.5 x) meet at (24, 24).
    p = write_polygon(f.dir / "bow.json", [[0, 0], [40, 40], [40, 0], [0, 60]])
    return argv(f, dst=p), [p, "self-intersecting", "edges 0 and 2 cross at (24.0, 24.0)"]


def _image_missing(f):
    p = str(f.dir / "missing.png")
    return argv(f, image=p), [p, "no such file"]


def _image_not_an_image(f):
    p = write_text(f.dir / "text.png", "this is not a PNG\n")
    return argv(f, image=p), [p, "cannot read image"]


def _image_is_a_directory(f):
    (f.dir / "dir.png").mkdir()
    p = str(f.dir / "dir.png")
    return argv(f, image=p), [p, "directory"]


def _unknown_output_format(f):
    p = str(f.dir / "out.xyz")
    return argv(f, out=p), [p, "unknown output image format", ".xyz"]


def _output_directory_missing(f):
    p = str(f.dir / "no-such-dir" / "out.png")
    return argv(f, out=p), [p, "does not exist"]


def _output_is_a_directory(f):
    (f.dir / "out-dir.png").mkdir()
    p = str(f.dir / "out-dir.png")
    return argv(f, out=p), [p, "is a directory"]


def _bad_size(value):
    def case(f):
        return argv(f, "--size", value), ["--size", repr(value)]

    return case


def _bad_background(value):
    def case(f):
        return argv(f, "--background", value), ["--background", repr(value)]

    return case


def _background_channel_count(f):
    return argv(f, "--background", "0.5,0.5"), ["background has 2 values but the image has 3 channels"]


def _bad_max_area(value):
    def case(f):
        return argv(f, "--max-area", value), ["--max-area", repr(value)]

    return case


def _missing_src_option(f):
    return [f.image, f.out, "--dst", f.dst], ["--src"]


BAD_INPUTS = {
    "missing-polygon": _missing_polygon,
    "invalid-json": _invalid_json,
    "too-few-vertices": _too_few_vertices,
    "vertex-counts-differ": _vertex_counts_differ,
    "nan": _non_finite,
    "infinity": _infinite,
    "non-numeric": _non_numeric,
    "repeated-vertex": _repeated,
    "zero-area": _zero_area,
    "self-intersecting": _self_intersecting,
    "image-missing": _image_missing,
    "image-not-an-image": _image_not_an_image,
    "image-is-a-directory": _image_is_a_directory,
    "unknown-output-format": _unknown_output_format,
    "output-directory-missing": _output_directory_missing,
    "output-is-a-directory": _output_is_a_directory,
    "size-no-x": _bad_size("40"),
    "size-zero": _bad_size("0x30"),
    "size-words": _bad_size("widexhigh"),
    "size-three": _bad_size("4x3x2"),
    "background-word": _bad_background("black"),
    "background-nan": _bad_background("nan"),
    "background-inf": _bad_background("1,inf,0"),
    "background-channels": _background_channel_count,
    "max-area-zero": _bad_max_area("0"),
    "max-area-negative": _bad_max_area("-1"),
    "max-area-nan": _bad_max_area("nan"),
    "max-area-inf": _bad_max_area("inf"),
    "max-area-word": _bad_max_area("fine"),
    "interp": lambda f: (argv(f, "--interp", "bicubic"), ["--interp", "bicubic"]),
    "missing-src-option": _missing_src_option,
}


def assert_one_line_error(captured, expected):
    assert captured.out == ""
    assert captured.err.endswith("\n")
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("warp: error: ")
    assert "Traceback" not in captured.err
    for text in expected:
        assert text in lines[0]


@pytest.mark.parametrize("case", BAD_INPUTS.values(), ids=BAD_INPUTS.keys())
def test_bad_input_exits_2_with_one_line_and_writes_nothing(files, capsys, case):
    args, expected = case(files)
    out = args[1]
    before = sorted(os.listdir(files.dir))
    status = main(args)
    captured = capsys.readouterr()
    assert status == 2
    assert_one_line_error(captured, expected)
    assert not os.path.exists(out) or os.path.isdir(out)
    assert sorted(os.listdir(files.dir)) == before  # no output, no temporary file


def test_coordinate_too_large_for_a_float_is_bad_input(files, capsys):
    p = write_text(files.dir / "huge.json", "[[8, 8], [1" + "0" * 400 + ", 8], [56, 56], [8, 56]]")
    before = sorted(os.listdir(files.dir))
    assert main(argv(files, src=p)) == 2
    assert_one_line_error(capsys.readouterr(), [p, "vertex 1"])
    assert sorted(os.listdir(files.dir)) == before


@pytest.mark.parametrize(
    "out",
    [
        lambda f: f.image,
        # os.path.join, not pathlib, which would drop the "." itself.
        lambda f: os.path.join(f.dir, ".", "in.png"),
        lambda f: os.path.join(f.dir, "sub", "..", "in.png"),
    ],
    ids=["same", "dot", "dotdot"],
)
def test_output_equal_to_the_input_is_refused(files, capsys, out):
    (files.dir / "sub").mkdir()
    with open(files.image, "rb") as fh:
        original = fh.read()
    before = sorted(os.listdir(files.dir))
    target = out(files)
    assert main(argv(files, out=target)) == 2
    assert_one_line_error(capsys.readouterr(), [target, "would overwrite the input", files.image])
    with open(files.image, "rb") as fh:
        assert fh.read() == original
    assert sorted(os.listdir(files.dir)) == before


@pytest.mark.parametrize("which", ["src", "dst"])
def test_output_equal_to_a_polygon_file_is_refused(files, capsys, which):
    poly = getattr(files, which)
    with open(poly, "rb") as fh:
        original = fh.read()
    before = sorted(os.listdir(files.dir))
    assert main(argv(files, out=poly)) == 2
    assert_one_line_error(capsys.readouterr(), [poly, "would overwrite the input"])
    with open(poly, "rb") as fh:
        assert fh.read() == original
    assert sorted(os.listdir(files.dir)) == before


def test_polygon_file_named_like_an_image_is_not_overwritten(files, capsys):
    # The format check alone would let this through: only the same-file check stops it.
    poly = write_polygon(files.dir / "poly.png", DST)
    with open(poly, "rb") as fh:
        original = fh.read()
    assert main(argv(files, out=poly, dst=poly)) == 2
    assert_one_line_error(capsys.readouterr(), [poly, "would overwrite the input"])
    with open(poly, "rb") as fh:
        assert fh.read() == original


def test_huge_polygon_at_pixel_density_is_meshed_only_near_the_image(files):
    """1e5 px at --max-area 1: the density applies where the image is; the mesh grows away from it."""
    # 1e5 px, not 1e7: meshed uniformly at 1 px^2 it would be 2e10 triangles (refused, or killed
    # by the timeout) as 2e14 would; graded, 200k triangles where 1e7 made 330k.
    side = 1e5
    big = write_polygon(files.dir / "big.json", [[0, 0], [side, 0], [side, side], [0, side]])
    # A separate process, so that a regression that tries to mesh the whole
    # polygon at pixel density is killed by the timeout.
    proc = subprocess.run(
        [sys.executable, "-m", "warpcli", *argv(files, "--max-area", "1", "--report", "-", src=big, dst=big)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    import json

    report = json.loads(proc.stdout)
    assert report["source_mesh"]["triangles"] < 1_000_000


def test_a_density_too_fine_for_the_image_is_refused_without_meshing(files):
    proc = subprocess.run(
        [sys.executable, "-m", "warpcli", *argv(files, "--max-area", "1e-6")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith((f"warp: error: {files.src}: ", f"warp: error: {files.dst}: "))
    assert f"{MAX_TRIANGLES:,}" in lines[0]
    assert "Traceback" not in proc.stderr
    assert not os.path.exists(files.out)
    assert sorted(os.listdir(files.dir)) == ["dst.json", "in.png", "src.json"]


class _FakeTerminal(io.StringIO):
    def __init__(self, tty: bool) -> None:
        super().__init__()
        self._tty = tty

    def isatty(self) -> bool:
        return self._tty


@pytest.mark.parametrize("tty,enabled,shown", [(True, True, True), (False, True, False), (True, False, False)])
def test_progress_only_on_a_terminal_and_not_when_quiet(tty, enabled, shown):
    import time

    from warpcli.cli import Progress

    stream = _FakeTerminal(tty)
    with Progress(stream, enabled=enabled, delay=0.01, interval=0.01) as progress:
        progress.stage("solving")
        time.sleep(0.1)
    text = stream.getvalue()
    assert ("warp: solving..." in text) == shown
    if shown:
        assert text.endswith("\r\x1b[K")  # the line is cleared at the end


def test_progress_stays_silent_for_short_runs():
    from warpcli.cli import Progress

    stream = _FakeTerminal(True)
    with Progress(stream, delay=5.0) as progress:
        progress.stage("solving")
    assert stream.getvalue() == ""


def test_progress_says_when_kernels_are_being_compiled_here_or_in_a_forked_child():
    """A first run compiles kernels for seconds, most of it in the children that build the maps:
    the line says so while this process or a child it forked compiles, and only then."""
    import os

    from warpcli import _native
    from warpcli.cli import Progress

    progress = Progress(_FakeTerminal(True))
    progress.stage("building the map")
    note = "compiling warpcli's kernels"
    assert note not in progress.line(1.0)
    with _native.compiling_kernel():
        assert note in progress.line(1.0)
    assert note not in progress.line(1.0)
    ready, go = os.pipe(), os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: compiling until told to stop
        try:
            with _native.compiling_kernel():
                os.write(ready[1], b"x")
                os.read(go[0], 1)
        finally:
            os._exit(0)
    os.read(ready[0], 1)
    try:
        assert note in progress.line(1.0)
    finally:
        os.write(go[1], b"x")
        os.waitpid(pid, 0)
    assert note not in progress.line(1.0)
    # A child killed while it compiles (a build no longer wanted: `Forked.cancel`) is forgotten.
    from warpcli._fork import Forked

    ready = os.pipe()
    child = Forked(_compile_for_ever, ready[1])
    os.read(ready[0], 1)
    assert note in progress.line(1.0)
    child.cancel()
    assert note not in progress.line(1.0)


def _compile_for_ever(fd):
    import time

    from warpcli import _native

    with _native.compiling_kernel():
        os.write(fd, b"x")
        time.sleep(60)


# --- report, grid and heatmap -------------------------------------------------

REPORT_KEYS = [
    "vertices", "source_mesh", "target_mesh", "flipped_triangles", "min_jacobian_det",
    "conformal", "isometric", "timings",
]  # fmt: skip


def test_report_to_a_file_and_to_stdout(files, capsys):
    import json

    rep_path = files.dir / "report.json"
    assert main(argv(files, "--report", str(rep_path))) == 0
    doc = json.loads(rep_path.read_text())
    assert list(doc) == REPORT_KEYS
    assert doc["vertices"] == 4
    assert set(doc["source_mesh"]) == {"vertices", "triangles"} == set(doc["target_mesh"])
    assert doc["flipped_triangles"] == 0 and doc["min_jacobian_det"] > 0
    assert set(doc["conformal"]) == {"mean", "max"} == set(doc["isometric"])
    assert doc["conformal"]["mean"] >= 2.0 and doc["isometric"]["mean"] >= 1.0
    assert {"mesh", "solve", "compose", "resample", "read", "write", "metrics"} <= set(doc["timings"])
    capsys.readouterr()
    assert main(argv(files, "--report", "-", out=str(files.dir / "o2.png"))) == 0
    out = capsys.readouterr().out
    again = json.loads(out)
    assert list(again) == REPORT_KEYS
    assert again["conformal"] == doc["conformal"]  # deterministic


def test_grid_and_heatmap_pictures(files):
    grid = files.dir / "grid.png"
    heat = files.dir / "heat.png"
    assert main(argv(files, "--grid", str(grid), "--heatmap", str(heat), "--heatmap-measure", "det")) == 0
    g = read_pixels(grid)
    assert g.shape[0] == 64 and g.shape[1] > 2 * 64 and g.shape[2] == 3
    h = read_pixels(heat)
    assert h.shape[2] == 3 and h.shape[1] > 64  # the picture and its legend


@pytest.mark.parametrize("weights", ["cotan", "positive"])
def test_weights_option(files, weights):
    assert main(argv(files, "--weights", weights)) == 0
    assert os.path.exists(files.out)


def test_report_beside_a_missing_directory_is_bad_input(files, capsys):
    bad = str(files.dir / "nope" / "r.json")
    before = sorted(os.listdir(files.dir))
    assert main(argv(files, "--report", bad)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope" in err[0]
    assert sorted(os.listdir(files.dir)) == before


def test_grid_may_not_overwrite_an_input_or_the_output(files, capsys):
    before = sorted(os.listdir(files.dir))
    assert main(argv(files, "--grid", files.image)) == 2
    assert main(argv(files, "--grid", files.out)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "overwrite" in err[0] and "is the same file as the output" in err[1]
    assert sorted(os.listdir(files.dir)) == before


# --- batch ----------------------------------------------------------------------


def _frames(files, count=3):
    paths = []
    for k in range(count):
        px = np.roll(files.pixels, 5 * k, axis=1)
        paths.append(write_png(files.dir / f"frame_{k:04d}.png", px))
    return paths


def test_batch_writes_every_input_with_one_map(files):
    frames = _frames(files)
    out_dir = files.dir / "out"
    out_dir.mkdir()
    assert main([*frames, "--src", files.src, "--dst", files.dst, "--out-dir", str(out_dir), "-q"]) == 0
    assert sorted(os.listdir(out_dir)) == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    # Each equals the single-image warp of the same input.
    single = files.dir / "single.png"
    assert main([frames[1], str(single), "--src", files.src, "--dst", files.dst]) == 0
    assert (out_dir / "frame_0001.png").read_bytes() == single.read_bytes()


def test_batch_name_pattern_and_format(files):
    frames = _frames(files, 2)
    out_dir = files.dir / "out"
    out_dir.mkdir()
    args = [*frames, "--src", files.src, "--dst", files.dst, "--out-dir", str(out_dir), "--out-name", "{stem}_w.tif"]
    assert main(args) == 0
    assert sorted(os.listdir(out_dir)) == ["frame_0000_w.tif", "frame_0001_w.tif"]
    assert read_pixels(out_dir / "frame_0000_w.tif").dtype == np.uint8


def test_batch_reports_a_failing_input_and_goes_on(files, capsys):
    frames = _frames(files)
    broken = files.dir / "broken.png"
    broken.write_text("not an image")
    out_dir = files.dir / "out"
    out_dir.mkdir()
    code = main([frames[0], str(broken), frames[2], "--src", files.src, "--dst", files.dst, "--out-dir", str(out_dir), "-q"])
    assert code == 2  # bad input, and nothing worse
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "broken.png" in err[0] and err[0].startswith("warp: error:")
    assert sorted(os.listdir(out_dir)) == ["frame_0000.png", "frame_0002.png"]


def test_batch_refuses_colliding_or_overwriting_outputs_before_any_work(files, capsys):
    frames = _frames(files, 2)
    other = files.dir / "sub"
    other.mkdir()
    twin = write_png(other / "frame_0000.png", files.pixels)
    out_dir = files.dir / "out"
    out_dir.mkdir()
    assert main([frames[0], twin, "--src", files.src, "--dst", files.dst, "--out-dir", str(out_dir)]) == 2
    assert main([*frames, "--src", files.src, "--dst", files.dst, "--out-dir", str(files.dir)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "both" in err[0] and "overwrite" in err[1]
    assert os.listdir(out_dir) == []


def test_batch_usage_errors(files, capsys):
    assert main([files.image, "--src", files.src, "--dst", files.dst, "--out-dir", str(files.dir / "missing")]) == 2
    assert main([files.image, files.out, "x.png", "--src", files.src, "--dst", files.dst]) == 2
    assert main([files.image, "--src", files.src, "--dst", files.dst, "--out-dir", str(files.dir), "--report", "-"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3
    assert "missing" in err[0] and "got 3 path" in err[1] and "--report applies to a single warp" in err[2]


# --- polygon formats through the CLI ---------------------------------------------------


def test_same_polygon_in_every_format_gives_byte_identical_output(files):
    import json

    def ring(p):
        return {"type": "Polygon", "coordinates": [p + [p[0]]]}

    docs = {
        "plain.json": DST,
        "points.json": {"points": DST},
        "labelme.json": {"shapes": [{"label": "a", "points": DST, "shape_type": "polygon"}]},
        "geo.json": ring(DST),
        "feature.json": {"type": "Feature", "properties": {"label": "a"}, "geometry": ring(DST)},
    }
    outs = []
    for name, doc in docs.items():
        (files.dir / name).write_text(json.dumps(doc))
        out = files.dir / f"out_{name}.png"
        assert main([files.image, str(out), "--src", files.src, "--dst", str(files.dir / name)]) == 0
        outs.append(out.read_bytes())
    assert all(o == outs[0] for o in outs)


def test_labels_choose_polygons_from_labelme_files(files):
    import json

    lm = {"shapes": [
        {"label": "from", "points": SRC, "shape_type": "polygon"},
        {"label": "to", "points": DST, "shape_type": "polygon"},
    ]}  # fmt: skip
    (files.dir / "both.json").write_text(json.dumps(lm))
    both = str(files.dir / "both.json")
    labelled = files.dir / "labelled.png"
    assert main([files.image, str(labelled), "--src", both, "--src-label", "from", "--dst", both, "--dst-label", "to"]) == 0
    assert main(argv(files)) == 0
    assert labelled.read_bytes() == open(files.out, "rb").read()


# --- everyday use ---------------------------------------------------------------


def test_a_mirroring_pair_is_warned_about_by_default_and_not_with_q(files, capsys):
    mirrored = write_polygon(files.dir / "mirror.json", [[64 - x, y] for x, y in DST])
    assert main(argv(files, dst=mirrored)) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "mirrors the image" in err
    assert main(argv(files, "-q", dst=mirrored)) == 0
    assert capsys.readouterr().err == ""


def test_a_target_outside_the_output_is_warned_about(files, capsys):
    far = write_polygon(files.dir / "far.json", [[x + 1000, y] for x, y in DST])
    assert main(argv(files, dst=far)) == 0
    err = capsys.readouterr().err
    assert "lies entirely outside" in err and "all background" in err
    assert (read_pixels(files.out) == 0).all()


def test_no_arguments_prints_the_usage(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err
    assert err.startswith("Usage: warp [OPTIONS] INPUT OUTPUT") and "warp --help" in err


def test_apply_map_is_a_subcommand(files, capsys):
    assert main(argv(files, "--save-map", str(files.dir / "m.exr"))) == 0
    out = str(files.dir / "again.png")
    assert main(["apply-map", str(files.dir / "m.exr"), files.image, out, "-q"]) == 0
    assert os.path.exists(out)
    assert main(["apply-map", "--help"]) == 0
    assert capsys.readouterr().out.startswith("Usage: warp apply-map [OPTIONS] MAP INPUT OUTPUT")


def test_verbose_shows_every_stage_including_metrics(files, capsys):
    assert main(argv(files, "-v", "--report", str(files.dir / "r.json"), "--heatmap", str(files.dir / "h.png"))) == 0
    err = capsys.readouterr().err
    for stage in ("mesh", "solve", "compose", "resample", "read", "write", "figures", "metrics"):
        assert f"warp: {stage}" in err, stage
