"""Tests of warpcli.sequence: frame-number wildcards in paths, frame specs, expansion."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest
from hypothesis import given
from hypothesis import strategies as st

from warpcli.errors import InputError
from warpcli.sequence import (
    FRAME_LIMIT,
    MAX_FRAMES,
    MAX_PADDING,
    SequencePattern,
    expand,
    frame_path,
    is_pattern,
    missing_frames_error,
    parse_frames,
    parse_pattern,
)


def oiiotool() -> str | None:
    """The oiiotool beside this Python (the OpenImageIO wheel ships one), or on PATH."""
    here = os.path.join(os.path.dirname(sys.executable), "oiiotool")
    return here if os.access(here, os.X_OK) else shutil.which("oiiotool")


def enumerate_like_oiiotool(first: int, last: int, step: int, complement: bool) -> list[int]:
    """One item N-MxS / N-MyS as Filesystem::enumerate_sequence walks it, for step >= 1."""
    direction = 1 if last >= first else -1
    out = []
    i = first
    while i != last + direction:
        if (abs(i - first) % step == 0) != complement:
            out.append(i)
        i += direction
    return out


# --- patterns ----------------------------------------------------------------


@pytest.mark.parametrize(
    "path",
    ["a.#.exr", "a.@.exr", "a.@@@.png", "a.#@@.tif", "a.%d.exr", "a.%04d.exr", "a.%4d.exr",
     "#.exr", "shots/s.#/beauty.exr", "a.#.b.#.exr", "a.%0d.exr"],
)
def test_is_pattern(path):
    assert is_pattern(path)


@pytest.mark.parametrize(
    "path", ["a.0001.exr", "plain.png", "100%.png", "a.%04x.tif", "a.%s.exr", "a%.exr", "", "a.%-4d.exr"]
)
def test_is_not_a_pattern(path):
    assert not is_pattern(path)
    assert parse_pattern(path) is None


@pytest.mark.parametrize(
    ("path", "padding"),
    [
        ("a.#.exr", 4),
        ("a.##.exr", 8),
        ("a.####.exr", 16),  # oiiotool's #, unlike Nuke's: 4 digits each
        ("a.@.exr", 1),
        ("a.@@@.exr", 3),
        ("a.#@@.exr", 6),
        ("a.@#.exr", 5),
        ("a.%d.exr", 0),
        ("a.%0d.exr", 0),
        ("a.%01d.exr", 1),
        ("a.%04d.exr", 4),
        ("a.%004d.exr", 4),
        ("a.%012d.exr", 12),
    ],
)
def test_padding(path, padding):
    seq = parse_pattern(path)
    assert seq.padding == padding
    assert (seq.prefix, seq.suffix) == ("a.", ".exr")
    assert seq.pattern == path


def test_the_pattern_is_split_around_its_wildcard():
    assert parse_pattern("/data/plate_v2.%04d.exr") == SequencePattern("/data/plate_v2.", "%04d", ".exr", 4)


@pytest.mark.parametrize(
    ("pattern", "frame", "path"),
    [
        ("o.#.exr", 1, "o.0001.exr"),
        ("o.#.exr", 1001, "o.1001.exr"),
        ("o.#.exr", 0, "o.0000.exr"),
        ("o.@.exr", 7, "o.7.exr"),
        ("o.@@@.exr", 7, "o.007.exr"),
        ("o.#@@.exr", 7, "o.000007.exr"),
        ("o.%d.exr", 7, "o.7.exr"),
        ("o.%d.exr", 1001, "o.1001.exr"),
        ("o.%03d.exr", 7, "o.007.exr"),
        ("o.##.exr", 42, "o.00000042.exr"),
    ],
)
def test_frame_path(pattern, frame, path):
    assert frame_path(pattern, frame) == path


@pytest.mark.parametrize(
    ("pattern", "frame", "path"),
    [
        ("o.#.exr", 12345, "o.12345.exr"),
        ("o.@.exr", 1001, "o.1001.exr"),
        ("o.%02d.exr", 123, "o.123.exr"),
        ("o.#.exr", FRAME_LIMIT, f"o.{FRAME_LIMIT}.exr"),
    ],
)
def test_a_frame_too_wide_for_the_padding_is_written_in_full(pattern, frame, path):
    assert frame_path(pattern, frame) == path


@pytest.mark.parametrize(
    ("pattern", "frame", "path"),
    [
        # printf's %0Nd, as oiiotool writes them: the sign takes one of the N places.
        ("o.#.exr", -7, "o.-007.exr"),
        ("o.#.exr", -1, "o.-001.exr"),
        ("o.#.exr", -123, "o.-123.exr"),
        ("o.#.exr", -1234, "o.-1234.exr"),
        ("o.@.exr", -7, "o.-7.exr"),
        ("o.@@@.exr", -7, "o.-07.exr"),
        ("o.%d.exr", -7, "o.-7.exr"),
        ("o.%04d.exr", -7, "o.-007.exr"),
    ],
)
def test_negative_frames_keep_their_sign_inside_the_padding(pattern, frame, path):
    assert frame_path(pattern, frame) == path


def test_wildcards_in_directories_count_as_in_oiiotool():
    assert frame_path("renders/shot.#/beauty.exr", 12) == "renders/shot.0012/beauty.exr"


def test_a_path_like_pattern_is_accepted(tmp_path):
    assert frame_path(tmp_path / "f.@@.png", 3) == os.path.join(str(tmp_path), "f.03.png")


def test_numpy_integers_are_frame_numbers():
    np = pytest.importorskip("numpy")
    assert frame_path("o.#.exr", np.int64(5)) == "o.0005.exr"


@pytest.mark.parametrize("frame", [1.0, 1.5, True, "1", None])
def test_a_frame_must_be_an_integer(frame):
    with pytest.raises(TypeError):
        frame_path("o.#.exr", frame)


@pytest.mark.parametrize(
    ("path", "match"),
    [
        ("a.#.b.#.exr", r"a\.#\.b\.#\.exr: .* only one frame-number wildcard, but this one has 2 \(# at character 3, # at character 7\)"),
        ("a.%04d.b.@.exr", "has 2 "),
        ("me@host/s.#.exr", "has 2 "),
        ("#@ #@ #@ #@ #@ #@", r"has 6 \(.*\.\.\. \(2 more\)"),
        ("a.%4d.exr", r"a\.%4d\.exr: %4d pads frame numbers with spaces; use %04d"),
        ("a.%10d.exr", "use %010d"),
        ("a.%033d.exr", f"more than {MAX_PADDING} digits"),
        ("a." + "#" * 9 + ".exr", f"more than {MAX_PADDING} digits"),
        ("a.%0" + "9" * 5000 + "d.exr", f"more than {MAX_PADDING} digits"),
    ],
)
def test_malformed_patterns_are_refused(path, match):
    assert is_pattern(path)
    with pytest.raises(InputError, match=match) as info:
        parse_pattern(path)
    assert "\n" not in str(info.value)
    with pytest.raises(InputError, match=match):
        frame_path(path, 1)


def test_padding_up_to_the_limit_is_accepted():
    assert parse_pattern("a.%032d.exr").padding == MAX_PADDING
    assert parse_pattern("a." + "#" * 8 + ".exr").padding == MAX_PADDING


def test_digits_before_a_wildcard_are_part_of_the_name():
    # oiiotool would read '2#' as frame 2; here frames come from the spec only.
    assert frame_path("take2#.exr", 5) == "take20005.exr"
    assert frame_path("a.1-10#.exr", 5) == "a.1-100005.exr"


# --- expansion ------------------------------------------------------------------


def test_expand_keeps_the_frames_order():
    assert expand("in.@@.png", (3, 1, -2)) == [(3, "in.03.png"), (1, "in.01.png"), (-2, "in.-2.png")]


def test_expand_of_a_parsed_spec():
    assert expand("o.%03d.tif", parse_frames("3,4,10-20x2")) == [
        (f, f"o.{f:03d}.tif") for f in (3, 4, 10, 12, 14, 16, 18, 20)
    ]


def test_a_pattern_without_frames_is_an_error():
    with pytest.raises(InputError) as info:
        expand("in.#.exr", None)
    msg = str(info.value)
    assert msg == "in.#.exr: image sequence pattern (#) given without frames; add --frames, e.g. --frames 1001-1100"
    assert isinstance(missing_frames_error("in.#.exr"), InputError)
    assert str(missing_frames_error("in.#.exr")) == msg


def test_the_missing_frames_message_names_the_option():
    with pytest.raises(InputError, match="add --src-frames, e.g. --src-frames 1001-1100"):
        expand("in.%04d.exr", None, option="--src-frames")


def test_expand_of_a_plain_path_is_an_error():
    with pytest.raises(InputError, match=r"^in\.0001\.exr: not an image sequence pattern: it has no frame-number wildcard"):
        expand("in.0001.exr", [1])
    with pytest.raises(InputError, match="not an image sequence pattern"):
        frame_path("in.exr", 1)


def test_expand_wants_frame_numbers_not_a_spec():
    with pytest.raises(TypeError, match="parse_frames"):
        expand("in.#.exr", "1-10")


@given(
    padding=st.integers(0, 12),
    frames=st.lists(st.integers(-FRAME_LIMIT, FRAME_LIMIT), min_size=1, max_size=20, unique=True),
)
def test_expanded_paths_read_back_as_their_frames(padding, frames):
    pattern = f"dir.{padding}/img_%0{padding}d.v2.exr"
    pairs = expand(pattern, frames)
    assert [f for f, _ in pairs] == frames
    paths = [p for _, p in pairs]
    assert len(set(paths)) == len(paths)  # one file per frame
    for f, p in pairs:
        assert p.startswith(f"dir.{padding}/img_") and p.endswith(".v2.exr")
        number = p[len(f"dir.{padding}/img_") : -len(".v2.exr")]
        assert int(number) == f
        assert len(number) == max(padding, len(str(f)))


# --- frame specs ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("spec", "frames"),
    [
        ("7", (7,)),
        ("0", (0,)),
        ("-3", (-3,)),
        ("1001-1005", (1001, 1002, 1003, 1004, 1005)),
        ("1-10x2", (1, 3, 5, 7, 9)),
        ("1-10x3", (1, 4, 7, 10)),
        ("1-5x2", (1, 3, 5)),  # oiiotool's documented example
        ("1-5y2", (2, 4)),  # ... and its complement
        ("1-3x5", (1,)),
        ("5-1", (5, 4, 3, 2, 1)),  # backwards
        ("10-1x3", (10, 7, 4, 1)),  # stepping counts from the first frame
        ("5-1y2", (4, 2)),
        ("1,5,10-12", (1, 5, 10, 11, 12)),
        ("3,4,10-20x2", (3, 4, 10, 12, 14, 16, 18, 20)),  # oiiotool's --framepadding example
        ("-5--3", (-5, -4, -3)),
        ("-2-2", (-2, -1, 0, 1, 2)),
        ("2--2x2", (2, 0, -2)),
        ("4-4", (4,)),
        (" 1-3 , 7 ", (1, 2, 3, 7)),
        ("0042", (42,)),
        ("1-4,3-6", (1, 2, 3, 4, 5, 6)),  # a frame listed twice is kept once, where it first appears
        ("5,1-5", (5, 1, 2, 3, 4)),
        ("1-1000x999", (1, 1000)),
        ("1-10x99999999999999", (1,)),
    ],
)
def test_frame_specs(spec, frames):
    assert parse_frames(spec) == frames


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ("", "no frames given"),
        ("   ", "no frames given"),
        ("1,,2", "empty item between commas"),
        ("1,", "empty item between commas"),
        (",1", "empty item between commas"),
        ("a", "'a' is not a frame, a range or a stepped range"),
        ("1-", "not a frame, a range"),
        ("-", "not a frame, a range"),
        ("1-5x", "not a frame, a range"),
        ("1-5z2", "not a frame, a range"),
        ("1-5abc", "not a frame, a range"),
        ("1.5", "not a frame, a range"),
        ("1-2.5", "not a frame, a range"),
        ("+5", "not a frame, a range"),
        ("5x2", "not a frame, a range"),
        ("1e3", "not a frame, a range"),
        ("0x10", "not a frame, a range"),
        ("1 2", "not a frame, a range"),
        ("1 - 3", "not a frame, a range"),  # spaces around items only
        ("1;2", "not a frame, a range"),
        ("\u0661-\u0663", "not a frame, a range"),  # Arabic-Indic digits
        ("1-5x0", r"the step in '1-5x0' must be at least 1, got 0"),
        ("1-5x-2", r"must be at least 1, got -2 \(to count down, write the range backwards: 5-1x2\)"),
        ("1-5y0", "must be at least 1, got 0"),
        ("1-5x-99999999999", r"got -99999999999 \(to count down, write the range backwards: 5-1x99999999999\)"),
        ("1-5y1", r"'1-5y1' selects no frames"),
        ("4-4y3", "selects no frames"),
        ("99999999999", f"frame 99999999999 is out of range \\(frame numbers must be within \\+-{FRAME_LIMIT}"),
        (f"{FRAME_LIMIT + 1}", "out of range"),
        (f"-{FRAME_LIMIT + 1}", "out of range"),
        ("1-" + "9" * 5000, "out of range"),
        ("1-999999999999", "out of range"),
        ("1-2000000", f"selects more than {MAX_FRAMES:,} frames \\('1-2000000' alone selects 2,000,000\\)"),
        (f"-{FRAME_LIMIT}-{FRAME_LIMIT}", "selects more than 1,000,000 frames"),
        ("1-600000,1-600000", r"selects more than 1,000,000 frames$"),
        (",".join(["1"] * (MAX_FRAMES + 1)), "selects more than 1,000,000 frames"),
    ],
)
def test_malformed_specs_are_refused(spec, match):
    with pytest.raises(InputError, match=match) as info:
        parse_frames(spec)
    msg = str(info.value)
    assert msg.startswith("--frames '")
    assert "\n" not in msg and len(msg) < 300


def test_a_spec_message_names_the_option():
    with pytest.raises(InputError, match=r"^--range '1-5x0': "):
        parse_frames("1-5x0", option="--range")


def test_exactly_max_frames_are_accepted():
    frames = parse_frames(f"1-{MAX_FRAMES}")
    assert len(frames) == MAX_FRAMES
    assert frames[0] == 1 and frames[-1] == MAX_FRAMES


def test_extreme_frames_are_accepted():
    assert parse_frames(f"-{FRAME_LIMIT},{FRAME_LIMIT}") == (-FRAME_LIMIT, FRAME_LIMIT)


def test_a_spec_must_be_text():
    with pytest.raises(TypeError):
        parse_frames(7)


@given(
    first=st.integers(-300, 300),
    last=st.integers(-300, 300),
    step=st.integers(1, 40),
)
def test_stepped_ranges_walk_as_oiiotool_does(first, last, step):
    taken = parse_frames(f"{first}-{last}x{step}")
    assert list(taken) == enumerate_like_oiiotool(first, last, step, complement=False)
    if step > 1 and abs(last - first) >= 1:
        skipped = parse_frames(f"{first}-{last}y{step}")
        assert list(skipped) == enumerate_like_oiiotool(first, last, step, complement=True)
        # Together, x and y cover the range once each.
        assert sorted(taken + skipped) == list(range(min(first, last), max(first, last) + 1))


@given(st.lists(st.tuples(st.integers(-50, 50), st.integers(-50, 50), st.integers(1, 7)), min_size=1, max_size=6))
def test_lists_are_their_items_in_order_without_repeats(items):
    spec = ",".join(f"{a}-{b}x{s}" for a, b, s in items)
    listed = [f for a, b, s in items for f in enumerate_like_oiiotool(a, b, s, complement=False)]
    assert parse_frames(spec) == tuple(dict.fromkeys(listed))


# --- agreement with oiiotool itself -----------------------------------------------------------


@pytest.mark.skipif(oiiotool() is None, reason="oiiotool is not installed")
@pytest.mark.parametrize(
    ("pattern", "spec"),
    [
        ("a.#.png", "1-3"),
        ("a.#.png", "-3-2"),
        ("a.@@@.png", "5-1x2"),
        ("a.#@@.png", "1-5y2"),
        ("a.%03d.png", "3,4,10-20x2"),
        ("a.%d.png", "-12--9,998-1002"),
        ("a.##.png", "7"),
        ("d.#/a.png", "1-2"),
    ],
)
def test_names_and_order_agree_with_oiiotool(tmp_path, pattern, spec):
    os.makedirs(tmp_path / "d.0001")
    os.makedirs(tmp_path / "d.0002")
    run = subprocess.run(
        [oiiotool(), "--frames", spec, "--create", "1x1", "1", "-o", pattern, "--echo", "{FRAME_NUMBER}"],
        cwd=tmp_path, capture_output=True, text=True, timeout=60, check=True,
    )
    assert [int(line) for line in run.stdout.split()] == list(parse_frames(spec))
    written = {os.path.relpath(os.path.join(root, f), tmp_path) for root, _, files in os.walk(tmp_path) for f in files}
    assert written == {p for _, p in expand(pattern, parse_frames(spec))}
