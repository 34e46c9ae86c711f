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
    out = full_disk / f"out.{ext}"
    args = [sys.executable, "-m", "warpcli", str(inp), "--src", frame, "--dst", frame, str(out), "--interp", "nearest"]
    done = subprocess.run(args, capture_output=True, text=True, cwd=REPO, timeout=300)
    assert done.returncode == 1, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"warp: error: {out}: cannot write: No space left on device")
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
