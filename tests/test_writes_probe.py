"""`check_writes`: a format that cannot hold an image is refused before any work, and the probe says what the real write would."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import run_cli
from warpcli.errors import ImageInputError, ImageIOError
from warpcli.raster.imageio import RasterImage, check_writes, write_image

EXTENSIONS = (
    ".zfile", ".j2k", ".jp2", ".jxl", ".webp", ".gif", ".pnm", ".ppm", ".bmp", ".tga", ".hdr", ".sgi", ".ico", ".dpx",
    ".fits", ".rla", ".png", ".tif",
)  # fmt: skip
CASES = [(ext, c, d) for ext in EXTENSIONS for c in (1, 3, 4) for d in ("uint8", "uint16", "uint32", "float32")]


@pytest.mark.parametrize(("ext", "channels", "dtype"), CASES, ids=[f"{e}-{c}-{d}" for e, c, d in CASES])
def test_the_probe_says_what_a_real_write_does(tmp_path, ext, channels, dtype):
    # A real image (32 x 24, not the probe's 4 x 4 of zeros) is written whenever the probe passes,
    # and fails whenever the probe refuses: the probe is a prediction, checked here.
    rng = np.random.default_rng(channels)
    px = (rng.random((24, 32, channels)) * (255 if dtype == "uint8" else 1000)).astype(dtype)
    check_writes.__globals__["_write_fails"].cache_clear()
    path = tmp_path / f"out{ext}"
    try:
        check_writes(path, channels, dtype)
        refused = None
    except ImageInputError as err:
        refused = str(err)
    try:
        write_image(path, RasterImage(px))
        failed = None
    except ImageIOError as err:
        failed = str(err)
    if refused is None:
        # JPEG XL's writer here fails on some images and not others (a one-channel 8-bit ramp,
        # 32-bit noise): the probe cannot tell those, and the read-back after the write catches them.
        assert failed is None or (ext == ".jxl" and "does not read back" in failed), failed
    else:
        assert refused.startswith(str(path) + ": ") and "\n" not in refused and str(tmp_path) not in refused.split(": ", 1)[1]
        assert failed is not None or ext in (".png", ".tif"), "refused, but a real write works"


def test_the_probe_does_not_blame_the_format_for_a_full_disk(tmp_path, monkeypatch):
    # Where nothing can be written in the temporary directory (here: every write fails), the
    # format is not refused: the real write says what is wrong, as a write failure.
    import warpcli.raster.imageio as imageio

    imageio._write_fails.cache_clear()

    def no_room(path, image, rows=None):
        raise ImageIOError(f"{path}: cannot write: [Errno 28] No space left on device")

    monkeypatch.setattr(imageio, "write_image", no_room)
    check_writes(tmp_path / "out.zfile", 3, "uint8")  # would be refused with room
    imageio._write_fails.cache_clear()


def test_a_format_that_cannot_hold_the_image_is_refused_before_the_work(tmp_path):
    src = tmp_path / "a.json"
    src.write_text("[[2, 2], [30, 2], [30, 22], [2, 22]]")
    dst = tmp_path / "b.json"
    dst.write_text("[[3, 2], [30, 4], [28, 22], [2, 20]]")
    img = tmp_path / "in.png"
    write_image(img, RasterImage(np.zeros((24, 32, 3), dtype=np.uint8)))
    code, err = run_cli([img, "--src", src, "--dst", dst, tmp_path / "out.zfile"])
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"warp: error: {tmp_path / 'out.zfile'}: "), err
    assert "zfile does not support 3-channel images" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.json", "in.png"]  # nothing left behind
