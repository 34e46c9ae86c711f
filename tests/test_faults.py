"""Faults outside warpcli: a full disk, a file size limit, a read-only directory, a cut-off input.

A full disk is a small tmpfs (``mount -t tmpfs -o size=64k``), a read-only
directory a tmpfs mounted ``ro``: both need root (CAP_SYS_ADMIN) and skip
with the reason where mounting is not permitted. A file size limit
(RLIMIT_FSIZE, ``ulimit -f``: writes past it fail with EFBIG) needs nothing
and runs everywhere, in a subprocess.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from helpers import write_png, write_polygon
from warpcli.errors import ImageInputError, ImageIOError
from warpcli.outputs import atomic_path
from warpcli.raster import imageio
from warpcli.raster.imageio import RasterImage, read_image, write_image
from warpcli.raster.stmap import save_stmap

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# What each format is written from: noise, so that no format compresses it
# below the 64 KiB of the full disk.
CASES = {
    "png-uint8": ("png", np.uint8, 3), "png-uint16": ("png", np.uint16, 4), "jpg-uint8": ("jpg", np.uint8, 3),
    "tif-uint8": ("tif", np.uint8, 3), "tif-uint16": ("tif", np.uint16, 3), "tif-float": ("tif", np.float32, 4),
    "exr-half": ("exr", np.float16, 3), "exr-float": ("exr", np.float32, 4),
}  # fmt: skip


def noise(h, w, c, dtype):
    x = np.random.default_rng(7).random((h, w, c))
    if np.issubdtype(dtype, np.integer):
        return (x * np.iinfo(dtype).max).astype(dtype)
    return x.astype(dtype)


def mount_tmpfs(where, options):
    """Mount a tmpfs at ``where``, or skip the test saying why it cannot be."""
    mount = shutil.which("mount")
    if mount is None:
        pytest.skip("no mount command here: cannot simulate a full or read-only file system")
    where.mkdir()
    done = subprocess.run([mount, "-t", "tmpfs", "-o", options, "tmpfs", str(where)], capture_output=True, text=True)
    if done.returncode != 0:
        reason = " ".join(done.stderr.split()) or f"exit status {done.returncode}"
        pytest.skip(f"cannot mount a tmpfs here (needs root, CAP_SYS_ADMIN): {reason}")
    return where


def unmount(where):
    subprocess.run([shutil.which("umount") or "umount", "-l", str(where)], capture_output=True)


@pytest.fixture
def full_disk(tmp_path):
    """A directory on a 64 KiB file system."""
    where = mount_tmpfs(tmp_path / "full", "size=64k,mode=0755")
    yield where
    unmount(where)


@pytest.fixture
def read_only(tmp_path):
    """A directory on a read-only file system (root ignores permission bits, not that)."""
    where = mount_tmpfs(tmp_path / "ro", "ro,size=64k")
    yield where
    unmount(where)


def listing(directory):
    return sorted(os.listdir(directory))


def write_case(path, case):
    ext, dtype, channels = CASES[case]
    write_image(path, RasterImage(noise(256, 256, channels, dtype)))


@pytest.mark.parametrize("staging", ["in-memory", "direct"])
@pytest.mark.parametrize("case", [*CASES, "stmap-exr", "stmap-tif"])
def test_a_full_disk_is_an_error_naming_the_file_and_leaves_nothing(full_disk, monkeypatch, case, staging):
    # "direct": no memfd (as on other systems): OpenImageIO writes the file
    # itself; libpng then truncates it silently and libjpeg would end the
    # process, so the file is checked afterwards and a JPEG is refused beforehand.
    if staging == "direct":
        monkeypatch.setattr(imageio, "memory_file", lambda name: None)
    ext = case.split("-")[0]
    out = full_disk / f"out.{case.split('-')[1] if ext == 'stmap' else ext}"
    # A small file fits, and stays whole when a larger one then fails to replace it.
    if ext == "stmap":
        save_stmap(out, np.zeros((4, 4, 2)), (4, 4))
    else:
        write_image(out, RasterImage(noise(8, 8, CASES[case][2], CASES[case][1])))
    before = out.read_bytes()
    with pytest.raises(ImageIOError) as info:
        if ext == "stmap":
            save_stmap(out, np.random.default_rng(3).random((256, 256, 2)) * 256, (256, 256))
        else:
            write_case(out, case)
    msg = str(info.value)
    assert not isinstance(info.value, ImageInputError)  # a failure while writing: exit 1
    assert msg.startswith(f"{out}: cannot write: No space left on device") and "\n" not in msg
    assert ".warpcli-tmp-" not in msg and "/proc/self/fd" not in msg
    assert listing(full_disk) == [out.name] and out.read_bytes() == before


@pytest.mark.parametrize("case", ["png-uint8", "jpg-uint8", "tif-uint8", "exr-float"])
def test_the_cli_reports_a_full_disk_on_one_line(full_disk, tmp_path, case):
    ext, dtype, channels = CASES[case]
    inp = tmp_path / f"in.{ext}"
    write_image(inp, RasterImage(noise(256, 256, channels, dtype)))
    frame = write_polygon(tmp_path / "frame.json", [[0, 0], [256, 0], [256, 256], [0, 256]])
    out = f"out.{ext}"  # as a user types it, in the directory it goes to: the message names it so
    args = [sys.executable, "-m", "warpcli", str(inp), "--src", frame, "--dst", frame, out, "--interp", "nearest"]
    done = subprocess.run(args, capture_output=True, text=True, cwd=full_disk, timeout=300)
    assert done.returncode == 1, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"warp: error: {out}: cannot write: No space left on device"), lines
    assert listing(full_disk) == []


SIZE_LIMIT_SCRIPT = textwrap.dedent(
    """
    import json, resource, sys
    import numpy as np
    from warpcli.raster.imageio import RasterImage, write_image
    from warpcli.raster.stmap import save_stmap
    cases = json.loads(sys.argv[2])
    resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536))  # Python ignores SIGXFSZ: writes fail with EFBIG
    for name, (ext, dtype, channels) in cases.items():
        x = np.random.default_rng(7).random((256, 256, channels))
        dt = np.dtype(dtype)
        px = (x * np.iinfo(dt).max).astype(dt) if dt.kind == "u" else x.astype(dt)
        try:
            if name.startswith("stmap"):
                save_stmap(f"{sys.argv[1]}/{name}.{ext}", x[..., :2] * 256, (256, 256))
            else:
                write_image(f"{sys.argv[1]}/{name}.{ext}", RasterImage(px))
            print(json.dumps([name, "written", ""]))
        except Exception as err:
            print(json.dumps([name, type(err).__name__, str(err)]))
    """
)


def test_a_file_size_limit_is_an_error_naming_the_file_and_leaves_nothing(tmp_path):
    # Needs no privilege, so it runs everywhere: RLIMIT_FSIZE (ulimit -f) in a subprocess.
    cases = {name: [ext, np.dtype(dt).name, c] for name, (ext, dt, c) in CASES.items()}
    cases.update({"stmap-exr": ["exr", "float32", 2], "stmap-tif": ["tif", "float32", 2]})
    out = tmp_path / "out"
    out.mkdir()
    done = subprocess.run(
        [sys.executable, "-c", SIZE_LIMIT_SCRIPT, str(out), json.dumps(cases)],
        capture_output=True, text=True, cwd=REPO, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0 and done.stderr == "", done.stderr
    results = [json.loads(line) for line in done.stdout.splitlines()]
    assert [r[0] for r in results] == list(cases)
    for name, kind, msg in results:
        ext = cases[name][0]
        assert kind == "ImageIOError", (name, kind, msg)
        assert msg.startswith(f"{out}/{name}.{ext}: cannot write: File too large") and "\n" not in msg, msg
    assert listing(out) == []


def test_a_batch_with_bad_input_and_a_failed_write_exits_with_the_failure(tmp_path):
    # Exit 2 means "some input was bad, and nothing worse happened" (docs/usage.md): a batch where
    # one input is not an image and another's output passes the file size limit must exit 1.
    import resource

    rng = np.random.default_rng(3)
    write_png(tmp_path / "noise.png", rng.integers(0, 256, (200, 200, 3)).astype(np.uint8))  # ~120 kB
    (tmp_path / "junk.png").write_bytes(b"not a png")
    square = write_polygon(tmp_path / "a.json", [[20, 20], [180, 20], [180, 180], [20, 180]])
    moved = write_polygon(tmp_path / "b.json", [[30, 10], [190, 30], [170, 190], [10, 170]])
    (tmp_path / "o").mkdir()

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (40_000, 40_000))

    args = [str(tmp_path / "junk.png"), str(tmp_path / "noise.png"), "--src", square, "--dst", moved, "--out-dir", str(tmp_path / "o")]
    done = subprocess.run([sys.executable, "-m", "warpcli", *args], capture_output=True, text=True, cwd=REPO,
                          timeout=120, preexec_fn=limit)  # fmt: skip
    assert done.returncode == 1, done.stderr
    assert "junk.png: cannot read image" in done.stderr and "File too large" in done.stderr
    assert listing(tmp_path / "o") == []


def test_a_read_only_directory_is_refused_on_one_line(read_only, tmp_path):
    out = read_only / "out.png"
    image = RasterImage(noise(8, 8, 3, np.uint8))
    for attempt in (
        lambda: write_image(out, image),
        lambda: save_stmap(read_only / "map.exr", np.zeros((4, 4, 2)), (4, 4)),
        lambda: atomic_path(str(read_only / "report.json")).__enter__(),
    ):
        with pytest.raises(ImageInputError) as info:  # an unusable output path: exit 2
            attempt()
        msg = str(info.value)
        assert msg.startswith(f"{read_only}/") and "Read-only file system" in msg and "\n" not in msg
    inp = write_png(tmp_path / "in.png", noise(8, 8, 3, np.uint8))
    frame = write_polygon(tmp_path / "frame.json", [[0, 0], [8, 0], [8, 8], [0, 8]])
    done = subprocess.run(
        [sys.executable, "-m", "warpcli", inp, "--src", frame, "--dst", frame, str(out)],
        capture_output=True, text=True, cwd=REPO, timeout=300,
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.splitlines() == [f"warp: error: {out}: cannot write in {read_only}: Read-only file system"]
    assert listing(read_only) == []


def test_a_directory_without_write_permission_is_refused(tmp_path):
    if os.geteuid() == 0:
        pytest.skip("root writes in a directory whatever its permission bits (see the read-only tmpfs test)")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(ImageInputError, match=f"^{locked}/out.png: cannot write in {locked}: Permission denied$"):
            write_image(locked / "out.png", RasterImage(noise(8, 8, 3, np.uint8)))
        assert listing(locked) == []
    finally:
        locked.chmod(0o700)


def test_the_cli_shows_one_line_for_a_truncated_png(tmp_path):
    # libpng prints "libpng error: ..." on stderr itself; OpenImageIO's error
    # has several lines: the CLI must show one, warpcli's.
    whole = write_png(tmp_path / "whole.png", noise(64, 64, 3, np.uint8))
    data = open(whole, "rb").read()
    cut = tmp_path / "cut.png"
    cut.write_bytes(data[: len(data) // 2])
    frame = write_polygon(tmp_path / "frame.json", [[0, 0], [64, 0], [64, 64], [0, 64]])
    out = tmp_path / "out.png"
    done = subprocess.run(
        [sys.executable, "-m", "warpcli", str(cut), "--src", frame, "--dst", frame, str(out)],
        capture_output=True, text=True, cwd=REPO, timeout=300,
    )  # fmt: skip
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"warp: error: {cut}: cannot read image: "), done.stderr
    assert "libpng" not in done.stderr
    assert not out.exists() and listing(tmp_path) == ["cut.png", "frame.json", "whole.png"]
    with pytest.raises(ImageInputError):  # and the same in-process
        read_image(cut)


# ---------------------------------------------------------------------------
# Strips (--tiled): every format the strip writer accepts, under a file size
# limit; OpenImageIO's image-size limit; SIGTERM at any moment.

#: The formats `warpcli.raster.parts.StripWriter` writes (JPEG, WebP and JPEG 2000 are refused).
STRIP_FORMATS = ["exr", "tif", "png", "bmp", "dpx", "fits", "hdr", "tga", "sgi", "ppm", "pgm", "rla", "iff", "gif", "jxl"]

STRIP_SCRIPT = textwrap.dedent(
    """
    import json, os, resource, sys
    import numpy as np
    sys.path.insert(0, "tests")
    from helpers import write_png, write_polygon
    import OpenImageIO as oiio
    from warpcli.pipeline import warp_file
    d, limit, oiio_mb, formats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4].split(",")
    w, h = (int(v) for v in sys.argv[5].split("x"))
    inp = write_png(f"{d}/in.png", (np.random.default_rng(1).random((h, w, 3)) * 255).astype(np.uint8))
    frame = write_polygon(f"{d}/f.json", [[0, 0], [w, 0], [w, h], [0, h]])
    if oiio_mb:
        oiio.attribute("limits:imagesize_MB", oiio_mb)
    if limit:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))  # Python ignores SIGXFSZ: writes fail with EFBIG
    for ext in formats:
        out = f"{d}/out.{ext}"
        try:
            warp_file(inp, out, frame, frame, tiled=True, interp="nearest")
            print(json.dumps([ext, "written", os.path.getsize(out)]))
        except Exception as err:
            print(json.dumps([ext, type(err).__name__, str(err)]))
    print(json.dumps(["limit", oiio.get_int_attribute("limits:imagesize_MB", 0), 0]))
    """
)


def _strips(tmp_path, limit, oiio_mb, formats, size="800x600"):
    done = subprocess.run(
        [sys.executable, "-c", STRIP_SCRIPT, str(tmp_path), str(limit), str(oiio_mb), ",".join(formats), size],
        capture_output=True, text=True, cwd=REPO, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0 and done.stderr == "", done.stderr
    return [json.loads(line) for line in done.stdout.splitlines()]


def test_strips_under_a_file_size_limit_fail_in_every_format_and_leave_nothing(tmp_path):
    # 200 x 150 noise: every output is far more than 20 kB (at least 30,000 bytes of 8-bit
    # indices for GIF, 90,000 for the others; noise does not compress) and the first strip
    # alone is past the limit, as at any larger size: the size changes nothing here (400 x 300
    # under 100 kB failed alike, at twice the CPU).
    results = _strips(tmp_path, 20_000, 0, STRIP_FORMATS, "200x150")
    assert [r[0] for r in results[:-1]] == STRIP_FORMATS
    for ext, kind, msg in results[:-1]:
        assert kind == "ImageIOError", (ext, kind, msg)
        assert msg.startswith(f"{tmp_path}/out.{ext}: cannot write: ") and "\n" not in msg, msg
        assert "File too large" in msg, msg
    assert sorted(os.listdir(tmp_path)) == ["f.json", "in.png"]


def test_strips_are_not_refused_by_openimageios_image_size_limit(tmp_path):
    # 800 x 600 x 3 bytes (1.44 MB) over a limit lowered to 1 MB: without the
    # lift, the header read and the read-back refuse it and the output is lost.
    formats = ["tif", "exr", "fits", "png"]
    results = _strips(tmp_path, 0, 1, formats)
    assert [r[1] for r in results[:-1]] == ["written"] * len(formats), results
    assert results[-1][:2] == ["limit", 1]  # restored afterwards
    source = read_image(tmp_path / "in.png").pixels
    for ext in formats:
        back = read_image(tmp_path / f"out.{ext}").pixels
        assert back.shape == source.shape
        assert np.array_equal(back.astype(np.float64), source.astype(np.float64)) or ext == "exr"


def test_formats_that_cannot_be_written_in_strips_are_refused_first(tmp_path):
    # The three formats in one process (one interpreter start, not three): each is refused before
    # anything is written, so each next one starts from the same directory.
    formats = ["webp", "jp2", "jpg"]
    results = _strips(tmp_path, 0, 0, formats)
    assert [r[0] for r in results[:-1]] == formats
    for ext, kind, msg in results[:-1]:
        # (This OpenImageIO's JPEG 2000 writer makes files its reader cannot open: refused as a format
        # that cannot hold the image at all, by `check_writes`, which comes first.)
        said = "cannot write a 3-channel uint8 image as jpeg2000" if ext == "jp2" else "cannot be written in parts"
        assert kind == "ImageInputError" and said in msg, (ext, msg)
    assert sorted(os.listdir(tmp_path)) == ["f.json", "in.png"]


def test_sigterm_at_any_moment_ends_in_one_line_and_leaves_nothing(tmp_path):
    """SIGTERM from 0.05 s to 2 s after start (imports, map, writing): exit 143 (or killed
    before the handler exists), never 0 after "terminated", no traceback, no hang, no leftover,
    all of a run's outputs or none."""
    import signal as sig
    import time

    img = write_png(tmp_path / "in.png", noise(256, 256, 3, np.uint8))
    frame = write_polygon(tmp_path / "frame.json", [[0, 0], [256, 0], [256, 256], [0, 256]])
    dst = write_polygon(tmp_path / "dst.json", [[10, 0], [256, 20], [240, 256], [0, 230]])
    # Dense over the imports (0.3-0.5 s here, where the issue saw aborts and hangs), sparse after.
    delays = np.r_[np.linspace(0.05, 0.6, 12), np.linspace(0.8, 2.0, 4)] + np.random.default_rng(5).uniform(0, 0.03, 16)
    t_end = time.monotonic() + 240
    for k, delay in enumerate(delays):
        if time.monotonic() > t_end:
            break
        out = tmp_path / f"out{k}"
        out.mkdir()
        proc = subprocess.Popen(
            [sys.executable, "-m", "warpcli", img, "--src", frame, "--dst", dst, str(out / "o.png"),
             "--report", str(out / "r.json"), "--save-map", str(out / "m.exr")],
            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        time.sleep(delay)
        proc.send_signal(sig.SIGTERM)
        try:
            stdout, stderr = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            pytest.fail(f"hangs after SIGTERM at {delay:.2f} s")
        assert "Traceback" not in stderr and "nanobind" not in stderr, (delay, stderr)
        if proc.returncode == 0:  # finished before the signal: every output there
            assert "terminated" not in stderr and sorted(os.listdir(out)) == ["m.exr", "o.png", "r.json"]
        else:
            assert proc.returncode in (143, -sig.SIGTERM), (delay, proc.returncode, stderr)
            # The handler's line is there whenever the handler ran (it was lost when the signal came
            # while a C library's stderr was captured); nothing when killed before it was installed.
            assert stderr.strip() == ("warp: terminated" if proc.returncode == 143 else ""), (delay, stderr)
            # All of a run's outputs or none (the signal may come after the renames), never a temporary.
            assert sorted(os.listdir(out)) in ([], ["m.exr", "o.png", "r.json"]), (delay, os.listdir(out))


_SIGTERM_WHILE_CAPTURED = """
import os, signal, sys, time
from warpcli.cli.run import _terminate
signal.signal(signal.SIGTERM, _terminate)
if sys.argv[1] == "c_stderr":
    from warpcli.capture import c_stderr
    block = c_stderr()
else:
    from warpcli.volume.tetmesh import _quiet_fds
    block = _quiet_fds()
with block:
    os.write(2, b"C library noise\\n")
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(5)
"""


@pytest.mark.parametrize("where", ["c_stderr", "tetgen"])
def test_sigterm_while_c_output_is_captured_still_says_terminated(where):
    """File descriptor 2 points into a capture (OpenImageIO's writes, TetGen's run) when SIGTERM comes:
    the line goes to the real stderr, the library's noise does not."""
    proc = subprocess.run([sys.executable, "-c", _SIGTERM_WHILE_CAPTURED, where], cwd=REPO, capture_output=True,
                          text=True, timeout=60)  # fmt: skip
    assert (proc.returncode, proc.stderr) == (143, "warp: terminated\n")


_LINE_WHILE_CAPTURED = """
import logging, os, sys, threading
from warpcli.capture import c_stderr, stderr_apart
from warpcli.volume.tetmesh import _quiet_fds
stderr_apart()
logging.basicConfig(format="%(message)s")  # a handler made after the set-up, as the command's
inside, done = threading.Event(), threading.Event()

def worker():
    with (c_stderr() if sys.argv[1] == "c_stderr" else _quiet_fds()):
        os.write(2, b"C library noise\\n")
        inside.set()
        done.wait(30)

t = threading.Thread(target=worker)
t.start()
inside.wait(30)
print("warp: error: a.png: not an image", file=sys.stderr)
logging.getLogger("warpcli").warning("warp: warning: b.png: a warning")
done.set()
t.join()
"""


@pytest.mark.parametrize("where", ["c_stderr", "tetgen"])
def test_lines_written_while_another_thread_captures_c_output_reach_stderr(where):
    """A batch's error for one input, written while a worker's OpenImageIO call (or TetGen) has file
    descriptor 2 pointing into a capture: with the command's `stderr_apart` it reaches stderr, and the
    library's noise still does not (without it, 40 % of such runs lost the line)."""
    proc = subprocess.run([sys.executable, "-c", _LINE_WHILE_CAPTURED, where], cwd=REPO, capture_output=True,
                          text=True, timeout=60)  # fmt: skip
    assert (proc.returncode, proc.stderr) == (0, "warp: error: a.png: not an image\nwarp: warning: b.png: a warning\n")


def test_the_command_writes_python_stderr_apart_from_descriptor_2():
    script = (
        "import importlib, sys\nr = importlib.import_module('warpcli.cli.run')\n"
        "r.main = lambda: print(sys.stderr.fileno() not in (1, 2), sys.stderr.fileno() == r.stderr_fd()) or 0\n"
        "r.run()\n"
    )
    proc = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert (proc.returncode, proc.stdout) == (0, "True True\n")


def test_strips_stop_at_the_first_that_the_full_disk_refuses(full_disk, tmp_path, monkeypatch):
    """PNG's writer keeps returning success after a failed write: the run went on to the last of
    its strips (all of a 30 GB image) before saying so. Now it stops at the first failure."""
    from warpcli.pipeline import warp_file
    from warpcli.raster import parts

    strips = []
    write = parts.StripWriter.write
    monkeypatch.setattr(parts.StripWriter, "write", lambda self, px: (strips.append(len(px)), write(self, px))[1])
    # Noise stretched 4 times: each strip holds 64 distinct rows (75 KiB), more than the disk.
    inp = write_png(tmp_path / "in.png", noise(640, 400, 3, np.uint8))
    frame = write_polygon(tmp_path / "f.json", [[0, 0], [400, 0], [400, 640], [0, 640]])
    tall = write_polygon(tmp_path / "t.json", [[0, 0], [400, 0], [400, 2560], [0, 2560]])
    with pytest.raises(ImageIOError):
        warp_file(inp, full_disk / "out.png", frame, tall, tiled=True, interp="nearest", size=(400, 2560))
    # (Other formats report the failed write at once, or have their room checked first: only PNG went on.)
    assert len(strips) <= 2, f"{len(strips)} of 10 strips written to a full disk"
    assert listing(full_disk) == []


@pytest.mark.parametrize("ext", STRIP_FORMATS)
def test_strips_on_a_full_disk_fail_in_every_format_and_leave_nothing(full_disk, tmp_path, ext):
    from warpcli.pipeline import warp_file

    inp = write_png(tmp_path / "in.png", noise(300, 400, 3, np.uint8))
    frame = write_polygon(tmp_path / "f.json", [[0, 0], [400, 0], [400, 300], [0, 300]])
    out = full_disk / f"out.{ext}"
    with pytest.raises(ImageIOError) as info:
        warp_file(inp, out, frame, frame, tiled=True, interp="nearest")
    msg = str(info.value)
    assert not isinstance(info.value, ImageInputError)  # a failure while writing: exit 1
    assert msg.startswith(f"{out}: cannot write: ") and "No space left on device" in msg and "\n" not in msg, msg
    assert listing(full_disk) == []


def test_a_temporary_is_registered_for_removal_before_it_exists(tmp_path, monkeypatch):
    """A SIGTERM handled at any bytecode finds every temporary it must remove: the name is in the
    registry when the file is created (with mkstemp it was registered a few bytecodes after, and a
    signal there left a '.warpcli-tmp-' file behind, seen once in the SIGTERM test above)."""
    from warpcli import outputs

    seen = []
    real_open = os.open

    def spy(name, flags, mode=0o777, **kw):
        if flags & os.O_CREAT and ".warpcli-" in os.fspath(name):
            seen.append((os.fspath(name), os.fspath(name) in outputs._live, os.path.exists(name)))
        return real_open(name, flags, mode, **kw)

    monkeypatch.setattr(outputs.os, "open", spy)
    with outputs.atomic_path(tmp_path / "a.png") as tmp:
        with open(tmp, "wb") as fh:
            fh.write(b"x")
    with outputs.PendingOutputs() as pending:
        with open(pending.path(tmp_path / "b.png"), "wb") as fh:
            fh.write(b"y")
    assert len(seen) == 2 and all(registered and not existed for _, registered, existed in seen), seen
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.png"] and not outputs._live


_SIGTERM_WITH_A_CHILD = """
import os, signal, sys, time
from warpcli import _fork
from warpcli.cli.run import _terminate
signal.signal(signal.SIGTERM, _terminate)
child = _fork.Forked(time.sleep, 60)  # a map still being built, say
print(child._pid, flush=True)
time.sleep(0.3)  # the child sets itself up
if sys.argv[1] == "group":
    os.killpg(0, signal.SIGTERM)  # a scheduler ending the job: every process of it
elif sys.argv[1] == "process":
    os.kill(os.getpid(), signal.SIGTERM)  # kill PID: this process alone
time.sleep(60)
"""

_INTERRUPT_WITH_A_CHILD = """
import os, signal, sys, time
from warpcli import _fork
from warpcli.cli.run import main
run = sys.modules["warpcli.cli.run"]
# Python leaves SIGINT ignored when it starts so (a job started with & or nohup, as a CI runner
# may start the suite); warp at a terminal has the default handler that raises KeyboardInterrupt.
signal.signal(signal.SIGINT, signal.default_int_handler)

def warp_that_builds(*args, **kwargs):  # the command, its map being built in a child
    child = _fork.Forked(time.sleep, 60)
    print(child._pid, flush=True)
    time.sleep(0.3)
    os.kill(os.getpid(), signal.SIGINT)  # kill -INT PID: this process alone
    time.sleep(60)

run.cli.main = warp_that_builds
sys.exit(main(["x.png", "y.png"]))
"""


def _gone(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] in "ZX"  # a zombie computes nothing
    except FileNotFoundError:
        return True


@pytest.mark.forks
@pytest.mark.parametrize("to", ["process", "group", "interrupt"])
def test_sigterm_ends_the_children_too_and_says_so_once(tmp_path, to):
    """SIGTERM (or SIGINT) to warp alone kills the children it forked (they would build a map on
    after the run ended); SIGTERM to its whole process group ends each child quietly, not with the
    parent's handler (which would say "terminated" once per process and remove the parent's files)."""
    import time

    script = _INTERRUPT_WITH_A_CHILD if to == "interrupt" else _SIGTERM_WITH_A_CHILD
    proc = subprocess.Popen(
        [sys.executable, "-c", script, to], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, start_new_session=True,
    )  # fmt: skip
    try:
        out, err = proc.communicate(timeout=10)  # a child left alive holds the pipes open
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, 9)
    child = int(out.split()[0])
    deadline = time.monotonic() + 5
    while not _gone(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    alive = not _gone(child)
    if alive:
        os.kill(child, 9)
    want = (130, "warp: interrupted\n") if to == "interrupt" else (143, "warp: terminated\n")
    assert (proc.returncode, err) == want
    assert not alive
