"""Tests of warpcli.keyframes: keyframed polygon files, linear interpolation, holds."""

from __future__ import annotations

import json
import math
import os
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from helpers import regular, similarity, write_polygon
from warpcli.errors import InputError, PolygonError
from warpcli.keyframes import Keyframes, read_animated, read_keyframes
from warpcli.polygon import MAX_FILE_BYTES, Polygon
from warpcli.sequence import FRAME_LIMIT

SQUARE = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]

# Both keyframes are simple, but vertex 2 moves from (10, 10) to (20, 30)
# straight across the polygon: halfway, at (15, 20), edge 1 (from (40, 0))
# crosses edge 3 (from (20, 10) to (10, 40)). With the keyframes at frames 0
# and 10, frames 2 to 6 are invalid and frames 1 and 7 to 9 are fine.
CROSSING_0 = [[0, 0], [40, 0], [10, 10], [20, 10], [10, 40]]
CROSSING_10 = [[0, 0], [40, 0], [20, 30], [20, 10], [10, 40]]


def write_doc(path, doc) -> str:
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return str(path)


def keyframes_doc(keys: dict) -> dict:
    return {"frames": {str(k): np.asarray(v, dtype=float).tolist() for k, v in keys.items()}}


def error_of(path, **kw) -> str:
    """The one-line message of the PolygonError that read_keyframes(path) raises."""
    with pytest.raises(PolygonError) as info:
        read_keyframes(path, **kw)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(str(path))
    return msg


def moving_squares(tmp_path, keys=(1001, 1050)):
    """Regular octagons growing and moving from keyframe to keyframe: valid at every frame."""
    shapes = [similarity(regular(8, r=20.0), scale=1.0 + k, shift=(7.0 * k, -3.0 * k)) for k in range(len(keys))]
    path = write_doc(tmp_path / "oct.json", keyframes_doc(dict(zip(keys, shapes))))
    return path, shapes


# --- reading --------------------------------------------------------------------


def test_a_plain_polygon_file_has_no_keyframes(tmp_path):
    path = write_polygon(tmp_path / "p.json", SQUARE)
    assert read_keyframes(path) is None
    path = write_doc(tmp_path / "q.json", {"points": SQUARE, "comment": "frames are elsewhere"})
    assert read_keyframes(path) is None


def test_keyframes_are_read_sorted(tmp_path):
    shapes = {10: SQUARE, -5: np.add(SQUARE, 1.0), 0: np.add(SQUARE, 2.0)}
    path = write_doc(tmp_path / "k.json", keyframes_doc(shapes))
    kf = read_keyframes(path)
    assert kf.frames == (-5, 0, 10)
    assert kf.name == path
    assert kf.n == 4
    assert kf.animated
    for f, poly in zip(kf.frames, kf.polygons):
        assert poly.points.tolist() == np.asarray(shapes[f], dtype=float).tolist()
        assert poly.name == f"{path} (keyframe {f})"


def test_keys_may_be_zero_padded_or_negative(tmp_path):
    path = write_doc(tmp_path / "k.json", {"frames": {"0042": SQUARE, "-0007": SQUARE, "-0": SQUARE}})
    assert read_keyframes(path).frames == (-7, 0, 42)


def test_keyframe_values_take_every_polygon_format(tmp_path):
    ring = [*SQUARE, SQUARE[0]]
    doc = {
        "frames": {
            "1": SQUARE,
            "2": {"points": SQUARE},
            "3": {"type": "Polygon", "coordinates": [ring]},
            "4": {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [ring]}},
            "5": {"shapes": [{"label": "mouth", "points": SQUARE, "shape_type": "polygon"}]},
        }
    }
    kf = read_keyframes(write_doc(tmp_path / "k.json", doc))
    assert kf.frames == (1, 2, 3, 4, 5)
    for poly in kf.polygons:
        assert poly.points.tolist() == SQUARE


def test_a_label_chooses_the_polygon_in_each_keyframe(tmp_path):
    def labelme(shift):
        return {"shapes": [
            {"label": "eye", "points": np.add(SQUARE, 100).tolist()},
            {"label": "mouth", "points": np.add(SQUARE, shift).tolist()},
        ]}

    path = write_doc(tmp_path / "k.json", {"frames": {"1": labelme(0), "3": labelme(2)}})
    kf = read_keyframes(path, label="mouth")
    assert kf.at(2).points.tolist() == np.add(SQUARE, 1.0).tolist()
    assert "choose one with a label option" in error_of(path)


def test_other_top_level_members_are_ignored(tmp_path):
    path = write_doc(tmp_path / "k.json", {"version": 2, "comment": {"x": [1]}, "frames": {"1": SQUARE}})
    assert read_keyframes(path).frames == (1,)


def test_a_single_keyframe_holds_everywhere(tmp_path):
    kf = read_keyframes(write_doc(tmp_path / "k.json", {"frames": {"12": SQUARE}}))
    assert not kf.animated
    assert kf.at(-(10**9)) is kf.polygons[0]
    assert kf.at(12) is kf.polygons[0]
    assert kf.at(10**40) is kf.polygons[0]
    assert kf.same(-5, 5000)


def test_read_animated_takes_plain_and_keyframed_files(tmp_path):
    plain = read_animated(write_polygon(tmp_path / "p.json", SQUARE))
    assert isinstance(plain, Keyframes)
    assert plain.frames == (0,) and not plain.animated
    assert plain.name == plain.polygons[0].name == str(tmp_path / "p.json")
    assert plain.at(1001).points.tolist() == SQUARE
    path, _ = moving_squares(tmp_path)
    assert read_animated(path).frames == (1001, 1050)


def test_read_animated_reports_a_plain_file_as_read_polygon_does(tmp_path):
    path = write_doc(tmp_path / "p.json", [[0, 0], [1, 1], [2, 2]])
    with pytest.raises(PolygonError, match=r"p\.json: polygon has zero area"):
        read_animated(path)


# --- interpolation ------------------------------------------------------------------


def test_keyframes_are_exact(tmp_path):
    # Decimals that are not binary fractions: a blend would not give them back.
    a = [[0.1, 0.2], [10.3, 0.7], [10.9, 10.1], [0.3, 10.7]]
    b = [[3.3, 1.1], [13.7, 0.9], [13.1, 12.3], [2.9, 11.1]]
    c = [[0.7, 0.3], [10.1, 0.1], [10.3, 10.3], [0.1, 10.9]]
    kf = read_keyframes(write_doc(tmp_path / "k.json", keyframes_doc({1: a, 7: b, 30: c})))
    for f, pts in ((1, a), (7, b), (30, c)):
        assert kf.at(f).points.tolist() == pts
        assert kf.at(f) is kf.polygons[kf.frames.index(f)]
        assert kf.at(float(f)) is kf.at(f)


def test_halfway_is_the_average(tmp_path):
    path, (a, b) = moving_squares(tmp_path, keys=(0, 10))
    kf = read_keyframes(path)
    np.testing.assert_allclose(kf.at(5).points, (a + b) / 2, rtol=0, atol=1e-12)
    assert kf.at(5).name == f"{path} (frame 5, between keyframes 0 and 10)"


@given(data=st.data())
def test_vertices_move_linearly_between_keyframes(tmp_path_factory, data):
    keys = data.draw(st.lists(st.integers(-5000, 5000), min_size=2, max_size=4, unique=True).map(sorted))
    path, shapes = moving_squares(tmp_path_factory.mktemp("kf"), keys=tuple(keys))
    kf = read_keyframes(path)
    i = data.draw(st.integers(0, len(keys) - 2))
    a, b = keys[i], keys[i + 1]
    frame = data.draw(st.integers(a, b))
    t = (frame - a) / (b - a)
    expected = shapes[i] + t * (shapes[i + 1] - shapes[i])
    got = kf.at(frame).points
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    # Linear in the frame: the step from frame to frame is the same all along.
    if a < frame < b:
        step = (shapes[i + 1] - shapes[i]) / (b - a)
        np.testing.assert_allclose(kf.at(frame + 1).points - got, step, rtol=0, atol=1e-9)
        np.testing.assert_allclose(got - kf.at(frame - 1).points, step, rtol=0, atol=1e-9)


@given(frame=st.integers(-(10**12), 10**12))
def test_held_before_the_first_keyframe_and_after_the_last(tmp_path_factory, frame):
    path, _ = moving_squares(tmp_path_factory.mktemp("kf"), keys=(-20, 0, 30))
    kf = read_keyframes(path)
    if frame <= -20:
        assert kf.at(frame) is kf.polygons[0]
    elif frame >= 30:
        assert kf.at(frame) is kf.polygons[-1]
    else:
        assert kf.same(frame, frame)


def test_sub_frames_are_interpolated(tmp_path):
    path, (a, b) = moving_squares(tmp_path, keys=(1, 2))
    kf = read_keyframes(path)
    poly = kf.at(1.25)
    np.testing.assert_allclose(poly.points, a + 0.25 * (b - a), rtol=0, atol=1e-12)
    assert "(frame 1.25, between keyframes 1 and 2)" in poly.name
    assert kf.at(np.float64(2.0)) is kf.polygons[1]


@pytest.mark.parametrize("frame", [math.nan, math.inf, -math.inf])
def test_a_frame_must_be_finite(tmp_path, frame):
    path, _ = moving_squares(tmp_path)
    kf = read_keyframes(path)
    with pytest.raises(InputError, match="is not a finite number"):
        kf.at(frame)
    with pytest.raises(InputError, match="is not a finite number"):
        kf.same(1001, frame)


@pytest.mark.parametrize("frame", [True, "1001", None])
def test_a_frame_must_be_a_number(tmp_path, frame):
    path, _ = moving_squares(tmp_path)
    with pytest.raises(TypeError):
        read_keyframes(path).at(frame)


# --- when the polygon changes -------------------------------------------------------------


def test_same_tells_where_the_polygon_moves(tmp_path):
    a, b = SQUARE, np.add(SQUARE, [[0, 0], [5, 0], [5, 5], [0, 5]]).tolist()
    # Held until 10, moving 10..20, held 20..30 (equal keyframes), moving back 30..40.
    kf = read_keyframes(write_doc(tmp_path / "k.json", keyframes_doc({10: a, 20: b, 30: b, 40: a})))
    assert kf.same(-100, 10) and kf.same(0, 5)
    assert not kf.same(10, 11) and not kf.same(11, 12) and not kf.same(19, 20)
    assert kf.same(20, 25) and kf.same(21, 30) and kf.same(20, 30)
    assert not kf.same(30, 31)
    assert kf.same(40, 10**6)
    assert kf.same(10, 40) and kf.same(0, 100)  # back to the same vertices
    assert kf.same(15, 15)
    # Between equal keyframes the polygon is the keyframe itself, not a copy.
    assert kf.at(25) is kf.polygons[1]
    changes = [f for f in range(50) if not kf.same(f - 1, f)]
    assert changes == [*range(11, 21), *range(31, 41)]


def test_animated_is_false_when_every_keyframe_is_equal(tmp_path):
    kf = read_keyframes(write_doc(tmp_path / "k.json", keyframes_doc({1: SQUARE, 5: SQUARE, 9: SQUARE})))
    assert not kf.animated
    assert kf.same(0, 100)
    # Every frame is one of the keyframes themselves: nothing is blended or validated again.
    assert all(any(kf.at(f) is p for p in kf.polygons) for f in range(12))


# --- bad keyframes -----------------------------------------------------------------------


def test_vertex_counts_must_match(tmp_path):
    path = write_doc(tmp_path / "k.json", keyframes_doc({1001: SQUARE, 1020: SQUARE, 1050: SQUARE[:3]}))
    assert error_of(path) == (
        f"{path}: keyframe 1050 has 3 vertices but keyframe 1001 has 4; "
        "every keyframe needs the same vertices, in the same order"
    )


def test_an_interpolated_self_intersection_is_refused_with_its_frame(tmp_path):
    path = write_doc(tmp_path / "k.json", keyframes_doc({0: CROSSING_0, 10: CROSSING_10}))
    kf = read_keyframes(path)  # both keyframes are fine
    with pytest.raises(PolygonError) as info:
        kf.at(5)
    msg = str(info.value)
    assert msg.startswith(f"{path} (frame 5, between keyframes 0 and 10): polygon is self-intersecting: edges 1 and 3 cross at")
    for f in (0, 1, 7, 8, 9, 10):
        kf.at(f)
    refused = []
    for f in range(11):
        try:
            kf.at(f)
        except PolygonError as err:
            assert f"(frame {f}, between keyframes 0 and 10)" in str(err)
            refused.append(f)
    assert refused == [2, 3, 4, 5, 6]


def test_an_invalid_keyframe_is_named(tmp_path):
    bow_tie = [[0, 0], [40, 40], [40, 0], [0, 60]]
    path = write_doc(tmp_path / "k.json", keyframes_doc({1001: SQUARE, 1050: bow_tie}))
    assert error_of(path).startswith(f"{path} (keyframe 1050): polygon is self-intersecting: edges 0 and 2 cross")


def test_a_reversed_keyframe_is_refused(tmp_path):
    path = write_doc(tmp_path / "k.json", keyframes_doc({0: SQUARE, 10: SQUARE[::-1]}))
    msg = error_of(path)
    assert "keyframe 10 runs counter-clockwise but keyframe 0 runs clockwise" in msg
    assert "the same way round" in msg


@pytest.mark.parametrize(
    "key", ["1.5", "1.0", "+5", "1e3", " 7", "7 ", "", "abc", "0x10", "\u0661", "1_000", "--1", "1-2", "\u00bd"]
)
def test_keys_must_be_whole_numbers(tmp_path, key):
    path = write_doc(tmp_path / "k.json", {"frames": {"1": SQUARE, key: SQUARE}})
    msg = error_of(path)
    assert f"{path}: keyframe {json.dumps(key)} is not a whole frame number" in msg
    assert 'the keys of "frames" must be integers such as "1001" or "-5"' in msg


@pytest.mark.parametrize("key", ["99999999999", f"{FRAME_LIMIT + 1}", f"-{FRAME_LIMIT + 1}", "9" * 5000])
def test_keys_must_be_in_range(tmp_path, key):
    path = write_doc(tmp_path / "k.json", {"frames": {"1": SQUARE, key: SQUARE}})
    assert "is out of range (frame numbers must be within +-2147483647)" in error_of(path)


def test_extreme_keys_are_accepted(tmp_path):
    path = write_doc(tmp_path / "k.json", {"frames": {str(FRAME_LIMIT): SQUARE, str(-FRAME_LIMIT): SQUARE}})
    assert read_keyframes(path).frames == (-FRAME_LIMIT, FRAME_LIMIT)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('{"frames": {"1": %s, "1": %s}}', r'keyframe "1" appears twice in "frames"'),
        ('{"frames": {"7": %s, "007": %s}}', r'keyframes "7" and "007" are both frame 7'),
        ('{"frames": {"0": %s, "-0": %s}}', r'keyframes "0" and "-0" are both frame 0'),
        ('{"frames": {"1": %s}, "frames": {"2": %s}}', r'"frames" appears twice'),
    ],
)
def test_a_frame_given_twice_is_refused(tmp_path, text, match):
    square = json.dumps(SQUARE)
    path = write_doc(tmp_path / "k.json", text % (square, square))
    with pytest.raises(PolygonError, match=match):
        read_keyframes(path)


@pytest.mark.parametrize(
    ("doc", "match"),
    [
        ({"frames": []}, r'"frames" must be an object mapping frame numbers to polygons.*not \[\]'),
        ({"frames": [[0, 0], [1, 0], [0, 1]]}, '"frames" must be an object'),
        ({"frames": None}, '"frames" must be an object'),
        ({"frames": {}}, '"frames" holds no keyframes'),
        ({"frames": {"1": SQUARE}, "points": SQUARE}, r'has both "frames" \(keyframes\) and "points" \(a single polygon\)'),
        ({"frames": {"1": SQUARE}, "shapes": []}, r'has both "frames" \(keyframes\) and "shapes"'),
        ({"frames": {"1": SQUARE}, "type": "Polygon"}, r'has both "frames" \(keyframes\) and GeoJSON "type" "Polygon"'),
        ({"frames": {"1": "square"}}, r"\(keyframe 1\): expected an array of \[x, y\] pairs"),
        ({"frames": {"1": [[0, 0], [1, "a"], [0, 1]]}}, r"\(keyframe 1\): vertex 1 has a non-numeric coordinate"),
        ({"frames": {"1": {"frames": {"2": SQUARE}}}}, r'\(keyframe 1\): JSON object has no "points" member'),
    ],
)
def test_malformed_keyframe_files_are_refused(tmp_path, doc, match):
    path = write_doc(tmp_path / "k.json", doc)
    assert re.search(match, error_of(path))


def test_a_huge_integer_in_a_keyframe_is_named(tmp_path):
    square = json.dumps(SQUARE)
    text = '{"n": ' + "7" * 5000 + ', "frames": {"1": ' + square + ', "2": [[0, 0], [' + "9" * 5000 + ", 0], [0, 1]]}}"
    path = write_doc(tmp_path / "k.json", text)
    assert "(keyframe 2): vertex 1 has a coordinate out of range: an integer of 5000 digits" in error_of(path)


def test_deep_nesting_is_refused(tmp_path):
    path = write_doc(tmp_path / "k.json", '{"frames": {"1": ' + "[" * 100_000 + "]" * 100_000 + "}}")
    assert "nested too deeply" in error_of(path)


# --- reading safeguards, shared with read_polygon ----------------------------------------------


def test_a_directory_is_refused(tmp_path):
    assert "it is a directory, not a regular file" in error_of(tmp_path)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_is_refused_without_waiting(tmp_path):
    fifo = tmp_path / "k.json"
    os.mkfifo(fifo)
    assert "a FIFO (named pipe), not a regular file" in error_of(fifo)


def test_a_huge_file_is_refused_without_reading_it(tmp_path):
    path = tmp_path / "k.json"
    with open(path, "wb") as fh:
        fh.truncate(MAX_FILE_BYTES + 1)  # sparse: nothing is written
    assert "polygon file is too large" in error_of(path)


def test_a_missing_file_is_refused(tmp_path):
    assert error_of(tmp_path / "nope.json").endswith("nope.json: no such file")


def test_invalid_json_is_refused(tmp_path):
    path = write_doc(tmp_path / "k.json", '{"frames": {"1": [[0, 0], [1, 0], [0, 1]],}}')
    assert "invalid JSON at line 1" in error_of(path)


# --- the Keyframes type -----------------------------------------------------------------------


def test_keyframes_built_in_code():
    a = Polygon(SQUARE, name="a")
    b = Polygon(np.add(SQUARE, 4.0), name="b")
    kf = Keyframes([np.int64(3), 9], [a, b], name="anim")
    assert kf.frames == (3, 9) and all(type(f) is int for f in kf.frames)
    assert kf.polygons == (a, b)
    assert kf.at(6).points.tolist() == np.add(SQUARE, 2.0).tolist()
    assert Keyframes.still(a).at(123) is a


@pytest.mark.parametrize(
    ("frames", "polygons", "match"),
    [
        ((), (), "anim: no keyframes"),
        ((1, 2), (SQUARE,), "anim: 2 keyframe numbers but 1 polygons"),
        ((2, 1), (SQUARE, SQUARE), "anim: keyframes must increase, but 1 follows 2"),
        ((1, 1), (SQUARE, SQUARE), "anim: keyframes must increase, but 1 follows 1"),
        ((0, FRAME_LIMIT + 1), (SQUARE, SQUARE), "anim: keyframe 2147483648 is out of range"),
    ],
)
def test_keyframes_are_checked(frames, polygons, match):
    with pytest.raises(PolygonError, match=match):
        Keyframes(frames, tuple(Polygon(p) for p in polygons), name="anim")


def test_keyframe_numbers_must_be_integers():
    with pytest.raises(TypeError):
        Keyframes((1.5,), (Polygon(SQUARE),))
