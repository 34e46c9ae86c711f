"""The memory budget: WARPCLI_MAX_IMAGE_BYTES, the share of available memory, and check_fits's messages."""

from __future__ import annotations

import re

import pytest

from warpcli.budget import MAX_IMAGE_BYTES_ENV, check_fits, max_image_bytes
from warpcli.errors import ImageInputError


def test_the_real_memory_limit_is_sane(monkeypatch):
    monkeypatch.delenv(MAX_IMAGE_BYTES_ENV, raising=False)
    limit = max_image_bytes()
    assert 2**20 < limit < 2**60  # at least 1 MiB, and bounded by this machine


@pytest.mark.parametrize(
    "dims,fits",
    [((640, 480, 3, 1), True), ((1000, 1000, 1, 1), True), ((1000, 1000, 1, 2), False),
     ((100000, 100000, 4, 4), False), ((0, 10, 3, 4), True), ((2**31, 2**31, 4, 8), False)],
)  # fmt: skip
def test_check_fits(monkeypatch, dims, fits):
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, "1000000")
    what = "--size {}x{}".format(*dims[:2])
    if fits:
        check_fits(*dims, what)
        return
    with pytest.raises(ImageInputError) as info:
        check_fits(*dims, what)
    w, h, c, b = dims
    msg = str(info.value)
    assert msg.startswith(f"{what}: a {w} x {h} image of {c} channel(s) x {b} byte")
    assert msg.endswith(f"more than the 977 KiB warpcli may use ({MAX_IMAGE_BYTES_ENV})") and "\n" not in msg


def test_check_fits_names_the_size_it_needs(monkeypatch):
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, str(2**30))
    with pytest.raises(ImageInputError, match=r"^--size 100000x100000: .* needs 149 GiB of memory, more than the 1.0 GiB"):
        check_fits(100000, 100000, 4, 4, "--size 100000x100000")


@pytest.mark.parametrize("value", ["abc", "0", "-5", "1.5e9"])
def test_a_bad_limit_is_refused_by_name(monkeypatch, value):
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, value)
    with pytest.raises(ImageInputError, match=f"^{MAX_IMAGE_BYTES_ENV}='{re.escape(value)}': not a positive whole number"):
        check_fits(1, 1, 1, 1, "x.png")



def test_several_copies_are_counted_and_said(monkeypatch):
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, "1000")
    check_fits(10, 10, 1, 5, "a.tif", copies=2)  # exactly the limit
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, "999")
    with pytest.raises(ImageInputError) as info:
        check_fits(10, 10, 1, 5, "a.tif", copies=2, why="to turn it")
    assert "needs 1000 bytes of memory (2 copies, to turn it), more than the 999 bytes" in str(info.value)
