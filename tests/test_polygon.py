"""Tests of warpcli.polygon: reading polygon files, validation, orientation."""

from __future__ import annotations

import json
import math
import os
import re
import threading

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from helpers import l_shape, regular, star
from warpcli.errors import InputError, PolygonError
from warpcli.polygon import (
    MAX_FILE_BYTES,
    MIN_CLEARANCE,
    MIN_CLEARANCE_RELATIVE,
    Polygon,
    check_pair,
    clearance_floor,
    read_polygon,
    signed_area,
)

SQUARE = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]

# An asymmetric bow-tie, so that its signed area does not cancel (400, not 0).
# Edge 0 runs along y = x from (0, 0) to (40, 40); edge 2 runs from (40, 0) to
# (0, 60), on y = 60 - 1.5 x. They meet where x = 60 - 1.5 x: at (24, 24),
# t = 0.6 along edge 0. Edges 1 (x = 40) and 3 (x = 0) are parallel.
BOW_TIE = [[0, 0], [40, 40], [40, 0], [0, 60]]


def write_text(path, text: str | bytes) -> str:
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return str(path)


def polygon_error(points, name="p.json") -> str:
    """The message of the PolygonError that Polygon(points) raises."""
    with pytest.raises(PolygonError) as info:
        Polygon(points, name=name)
    return str(info.value)


# --- reading -----------------------------------------------------------------


def test_reads_an_array_of_pairs(tmp_path):
    path = write_text(tmp_path / "tri.json", "[[0, 0], [4.5, 0], [0, 3]]")
    poly = read_polygon(path)
    assert poly.points.tolist() == [[0.0, 0.0], [4.5, 0.0], [0.0, 3.0]]
    assert poly.points.dtype == np.float64
    assert poly.name == path
    assert poly.n == 3


def test_reads_an_object_with_a_points_member(tmp_path):
    doc = {"name": "ignored", "points": SQUARE, "comment": [1, 2, 3]}
    path = write_text(tmp_path / "sq.json", json.dumps(doc, indent=2))
    poly = read_polygon(tmp_path / "sq.json")  # a Path works too; the name is its text
    assert poly.points.tolist() == SQUARE
    assert poly.name == path


def test_both_forms_give_the_same_polygon(tmp_path):
    a = read_polygon(write_text(tmp_path / "a.json", json.dumps(SQUARE)))
    b = read_polygon(write_text(tmp_path / "b.json", json.dumps({"points": SQUARE})))
    np.testing.assert_array_equal(a.points, b.points)


def test_points_are_read_only():
    poly = Polygon(SQUARE)
    with pytest.raises(ValueError):
        poly.points[0, 0] = 1.0
    assert poly.points[0, 0] == 0.0


def test_polygon_error_is_an_input_error_and_a_value_error():
    # The CLI maps InputError to exit status 2; library callers may catch ValueError.
    assert issubclass(PolygonError, InputError)
    assert issubclass(PolygonError, ValueError)


# --- unreadable files --------------------------------------------------------


def test_missing_file(tmp_path):
    path = str(tmp_path / "nope.json")
    with pytest.raises(PolygonError) as info:
        read_polygon(path)
    assert str(info.value) == f"{path}: no such file"


def test_path_with_a_nul_character():
    with pytest.raises(PolygonError, match="embedded null") as info:
        read_polygon("a\0b.json")
    assert str(info.value) == "'a\\x00b.json': cannot read polygon file: embedded null byte"


def test_directory_is_not_a_polygon_file(tmp_path):
    (tmp_path / "dir.json").mkdir()
    path = str(tmp_path / "dir.json")
    with pytest.raises(PolygonError, match="cannot read polygon file") as info:
        read_polygon(path)
    assert str(info.value) == f"{path}: cannot read polygon file: it is a directory, not a regular file"


def read_in_thread(path, timeout=10.0):
    """read_polygon(path) in a daemon thread: (finished, exception), so a hang fails instead of blocking."""
    out = {}

    def run():
        try:
            read_polygon(path)
        except Exception as err:  # handed back to the test to check
            out["err"] = err

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(timeout)
    return not worker.is_alive(), out.get("err")


def test_fifo_is_refused_without_waiting_for_a_writer(tmp_path):
    path = str(tmp_path / "pipe.json")
    os.mkfifo(path)  # no writer: opening it for reading in blocking mode would wait forever
    finished, err = read_in_thread(path)
    assert finished
    assert isinstance(err, PolygonError)
    assert str(err) == f"{path}: cannot read polygon file: it is a FIFO (named pipe), not a regular file"


def test_fifo_swapped_in_after_the_check_is_refused(tmp_path, monkeypatch):
    # The path passes the look before opening (a regular file then), but is a
    # FIFO when opened: the non-blocking open returns, and fstat refuses it.
    path = str(tmp_path / "pipe.json")
    os.mkfifo(path)
    regular = os.stat(write_text(tmp_path / "plain.json", "[]"))
    real_stat = os.stat
    monkeypatch.setattr(os, "stat", lambda p, *a, **k: regular if os.fspath(p) == path else real_stat(p, *a, **k))
    finished, err = read_in_thread(path)
    assert finished
    assert isinstance(err, PolygonError)
    assert "it is a FIFO (named pipe), not a regular file" in str(err)


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero")
def test_device_is_refused_unread():
    finished, err = read_in_thread("/dev/zero")
    assert finished
    assert isinstance(err, PolygonError)
    assert str(err) == "/dev/zero: cannot read polygon file: it is a character device, not a regular file"


def test_file_larger_than_the_limit_is_refused_unread(tmp_path):
    path = str(tmp_path / "huge.json")
    with open(path, "wb") as fh:
        fh.truncate(7 << 30)  # sparse: 7 GiB of zero bytes that take no space
    with pytest.raises(PolygonError, match="too large") as info:
        read_polygon(path)
    assert str(info.value) == f"{path}: polygon file is too large: 7.0 GiB, more than the limit of 64 MiB"
    assert MAX_FILE_BYTES == 64 << 20


def test_file_at_the_limit_is_read(tmp_path):
    # Padding after the JSON value is whitespace: valid, and exactly MAX_FILE_BYTES long.
    text = json.dumps(SQUARE)
    path = write_text(tmp_path / "big.json", text + " " * (MAX_FILE_BYTES - len(text)))
    assert os.path.getsize(path) == MAX_FILE_BYTES
    assert read_polygon(path).points.tolist() == SQUARE


def test_integer_of_thousands_of_digits(tmp_path):
    # Python's int() refuses more than 4300 digits (a ValueError inside json.loads).
    path = write_text(tmp_path / "digits.json", "[[0, 0], [1" + "0" * 4999 + ", 0], [0, 4]]")
    with pytest.raises(PolygonError, match="out of range") as info:
        read_polygon(path)
    assert str(info.value) == (
        f"{path}: vertex 1 has a coordinate out of range: an integer of 5000 digits "
        "(coordinates must be within +-1e+09 pixels)"
    )


def test_integer_of_thousands_of_digits_elsewhere_is_ignored(tmp_path):
    path = write_text(tmp_path / "digits.json", json.dumps({"points": SQUARE})[:-1] + ', "n": ' + "9" * 5000 + "}")
    assert read_polygon(path).points.tolist() == SQUARE


@pytest.mark.parametrize(
    "text",
    [
        "[" + "[" * 900 + "]" * 900 + ", [0, 0], [1, 1]]",
        '{"type": "Polygon", "coordinates": [[' + "[" * 900 + "]" * 900 + ", [0, 0], " + "[" * 900 + "]" * 900 + "]]}",
        '{"shapes": [{"label": ' + "[" * 900 + "]" * 900 + ', "points": []}, {"points": []}]}',
    ],
    ids=["vertex", "geojson-ring", "labelme-label"],
)
def test_nesting_just_below_the_parser_limit(tmp_path, text):
    # Parsed, but then compared or printed: still one line, never a RecursionError.
    path = write_text(tmp_path / "deep.json", text)
    with pytest.raises(PolygonError) as info:
        read_polygon(path)
    assert str(info.value).startswith(f"{path}: ")
    assert "\n" not in str(info.value)


def test_byte_order_mark_is_ignored(tmp_path):
    path = write_text(tmp_path / "bom.json", b"\xef\xbb\xbf" + json.dumps(SQUARE).encode())
    assert read_polygon(path).points.tolist() == SQUARE


def test_text_from_the_file_is_shown_on_one_line(tmp_path):
    doc = {"shapes": [{"label": "left\nright", "points": PTS}, {"label": "\ud800", "points": PTS}]}
    path = write_text(tmp_path / "lm.json", json.dumps(doc))
    with pytest.raises(PolygonError, match="2 polygons") as info:
        read_polygon(path)
    msg = str(info.value)
    assert msg == f'{path}: labelme file has 2 polygons ("left\\nright", "\\ud800"); choose one with a label option'
    msg.encode("utf-8")  # no lone surrogate
    geo = {"type": "Feature", "geometry": {"type": ["Line\nString"]}}
    with pytest.raises(PolygonError, match="not a Polygon") as info:
        read_polygon(write_text(tmp_path / "g.json", json.dumps(geo)))
    assert str(info.value).endswith(': GeoJSON geometry is a ["Line\\nString"], not a Polygon')


def test_labelme_labels_are_listed_up_to_ten(tmp_path):
    doc = {"shapes": [{"label": f"s{k}", "points": PTS} for k in range(25)]}
    path = write_text(tmp_path / "lm.json", json.dumps(doc))
    with pytest.raises(PolygonError, match="25 polygons") as info:
        read_polygon(path)
    assert "(s0, s1, s2, s3, s4, s5, s6, s7, s8, s9, ... (15 more))" in str(info.value)


def test_geojson_features_must_be_an_array(tmp_path):
    path = write_text(tmp_path / "fc.json", '{"type": "FeatureCollection", "features": 5}')
    with pytest.raises(PolygonError, match="must be an array") as info:
        read_polygon(path)
    assert str(info.value) == f'{path}: GeoJSON FeatureCollection "features" must be an array'


@pytest.mark.parametrize(
    "text, where",
    [
        ("[\n  [0, 0],\n  [1, 2],,\n]", "line 3, column 10: Expecting value"),
        ("[[8, 8], [56, 8],\n [56, 56] [8, 56]]", "line 2, column 11: Expecting ',' delimiter"),
        ("", "line 1, column 1: Expecting value"),
        ("[[0, 0], [1, 0], [0, 1]", "line 1, column 24"),
    ],
    ids=["double-comma", "missing-comma", "empty", "unclosed"],
)
def test_invalid_json_gives_line_and_column(tmp_path, text, where):
    path = write_text(tmp_path / "bad.json", text)
    with pytest.raises(PolygonError, match="invalid JSON") as info:
        read_polygon(path)
    assert str(info.value).startswith(f"{path}: invalid JSON at ")
    assert where in str(info.value)


def test_invalid_utf8(tmp_path):
    path = write_text(tmp_path / "bin.json", b"[[0, 0]\xff]")
    with pytest.raises(PolygonError, match=r"invalid UTF-8 at byte 7") as info:
        read_polygon(path)
    assert str(info.value).startswith(f"{path}: ")


# --- wrong structure ---------------------------------------------------------


@pytest.mark.parametrize(
    "text, problem",
    [
        ('{"vertices": [[0, 0], [1, 0], [0, 1]]}', 'JSON object has no "points" member (and is neither a labelme file nor GeoJSON)'),
        ("{}", 'JSON object has no "points" member (and is neither a labelme file nor GeoJSON)'),
        ("42", "expected an array of [x, y] pairs"),
        ('"[[0, 0], [1, 0], [0, 1]]"', "expected an array of [x, y] pairs"),
        ('{"points": {"0": [0, 0]}}', "expected an array of [x, y] pairs"),
        ("[[0, 0], [1, 0, 2], [0, 1]]", "vertex 1 is not an [x, y] pair: [1, 0, 2]"),
        ("[[0, 0], [1], [0, 1]]", "vertex 1 is not an [x, y] pair: [1]"),
        ("[[0, 0], [1, 0], 7, [0, 1]]", "vertex 2 is not an [x, y] pair: 7"),
        ('[[0, 0], [1, 0], {"x": 0, "y": 1}]', 'vertex 2 is not an [x, y] pair: {"x": 0, "y": 1}'),
        ("[0, 0, 1, 0, 0, 1]", "vertex 0 is not an [x, y] pair: 0"),
    ],
    ids=[
        "object-without-points",
        "empty-object",
        "number",
        "string",
        "points-not-array",
        "triple",
        "single",
        "scalar-entry",
        "object-entry",
        "flat-list",
    ],
)
def test_wrong_structure(tmp_path, text, problem):
    path = write_text(tmp_path / "shape.json", text)
    with pytest.raises(PolygonError, match=re.escape(problem)) as info:
        read_polygon(path)
    assert str(info.value) == f"{path}: {problem}"


@pytest.mark.parametrize("points, n", [([], 0), ([[0, 0]], 1), ([[0, 0], [1, 1]], 2)])
def test_fewer_than_three_vertices(tmp_path, points, n):
    path = write_text(tmp_path / "few.json", json.dumps(points))
    with pytest.raises(PolygonError, match="at least 3 vertices") as info:
        read_polygon(path)
    assert str(info.value) == f"{path}: a polygon needs at least 3 vertices, got {n}"


@pytest.mark.parametrize(
    "value, shown",
    [('"1"', '"1"'), ('"x"', '"x"'), ("true", "true"), ("false", "false"), ("null", "null"), ("[1]", "[1]")],
)
def test_non_numeric_coordinate(tmp_path, value, shown):
    path = write_text(tmp_path / "nn.json", f"[[0, 0], [4, 0], [4, {value}], [0, 4]]")
    with pytest.raises(PolygonError, match="non-numeric") as info:
        read_polygon(path)
    assert str(info.value) == f"{path}: vertex 2 has a non-numeric coordinate: {shown}"


@pytest.mark.parametrize(
    "token, shown",
    [("NaN", "[nan, 0.0]"), ("Infinity", "[inf, 0.0]"), ("-Infinity", "[-inf, 0.0]"), ("1e400", "[inf, 0.0]")],
)
def test_non_finite_coordinate(tmp_path, token, shown):
    # Python's json accepts NaN and Infinity (and overflows 1e400 to inf).
    path = write_text(tmp_path / "nf.json", f"[[0, 0], [{token}, 0], [4, 4], [0, 4]]")
    with pytest.raises(PolygonError, match="non-finite") as info:
        read_polygon(path)
    assert str(info.value) == f"{path}: vertex 1 has a non-finite coordinate: {shown}"


def test_integer_too_large_for_a_float(tmp_path):
    # JSON integers have no size limit; 10**400 is read as a Python int.
    path = write_text(tmp_path / "huge.json", "[[0, 0], [1" + "0" * 400 + ", 0], [0, 4]]")
    with pytest.raises(PolygonError, match="vertex 1") as info:
        read_polygon(path)
    assert str(info.value).startswith(f"{path}: ")


def test_deeply_nested_json(tmp_path):
    path = write_text(tmp_path / "deep.json", "[" * 100_000 + "]" * 100_000)
    with pytest.raises(PolygonError) as info:
        read_polygon(path)
    assert str(info.value).startswith(f"{path}: ")


@pytest.mark.parametrize(
    "array",
    [np.zeros((4, 3)), np.zeros((4,)), np.zeros((4, 2), dtype=bool), np.array([["0", "1"]] * 3)],
    ids=["n-by-3", "flat", "bool", "str"],
)
def test_array_input_must_be_n_by_2_numbers(array):
    with pytest.raises(PolygonError, match=r"must be an \(n, 2\) array of numbers") as info:
        Polygon(array, name="arr")
    assert str(info.value).startswith("arr: ")


# --- invalid polygons --------------------------------------------------------


def test_repeated_vertices_are_named():
    msg = polygon_error([[0, 0], [4, 0], [4, 4], [4, 0], [0, 4]])
    assert msg == "p.json: vertices 1 and 3 are repeated at (4.0, 0.0)"
    assert "closes itself" not in msg


def test_closing_vertex_equal_to_the_first_gets_a_hint(tmp_path):
    path = write_text(tmp_path / "closed.json", json.dumps(SQUARE + [SQUARE[0]]))
    with pytest.raises(PolygonError, match="repeated") as info:
        read_polygon(path)
    assert str(info.value) == (
        f"{path}: vertices 0 and 4 are repeated at (0.0, 0.0) "
        "(list each vertex once; the polygon closes itself)"
    )


@pytest.mark.parametrize(
    "points",
    [
        [[0, 0], [1, 1], [2, 2], [3, 3]],
        [[0, 0], [1, 0], [2, 0]],
        [[5, 1], [5, 7], [5, 3]],
    ],
    ids=["diagonal", "horizontal", "vertical-back-and-forth"],
)
def test_collinear_points_have_zero_area(points):
    msg = polygon_error(points)
    assert msg == "p.json: polygon has zero area"


@pytest.mark.parametrize(
    "shift, edges",
    [(0, (0, 2)), (1, (1, 3)), (2, (0, 2)), (3, (1, 3))],
)
def test_bow_tie_names_the_crossing_edges_and_point(shift, edges):
    # Starting the list at vertex `shift` renumbers the edges: the crossing
    # pair (0, 2) becomes (1, 3) after one step, (2, 0) = (0, 2) after two.
    pts = np.roll(np.array(BOW_TIE, dtype=float), -shift, axis=0)
    assert signed_area(pts) != 0  # so the crossing test, not the area test, must catch it
    with pytest.raises(PolygonError, match="self-intersecting") as info:
        Polygon(pts, name="bow.json")
    e, f = edges
    assert str(info.value) == f"bow.json: polygon is self-intersecting: edges {e} and {f} cross at (24.0, 24.0)"


def test_bow_tie_crossing_point_with_fractional_coordinates():
    # Edge 0: (0, 0) -> (3, 1); edge 2: (3, 0) -> (0, 2). On edge 0, y = x / 3;
    # on edge 2, y = 2 - 2x / 3; so x = 2, y = 2 / 3.
    msg = polygon_error([[0, 0], [3, 1], [3, 0], [0, 2]])
    assert msg == "p.json: polygon is self-intersecting: edges 0 and 2 cross at (2.0, 0.666667)"


def test_symmetric_bow_tie_is_reported_as_self_intersecting():
    # Edges 0 ((0,0)->(4,4)) and 2 ((4,0)->(0,4)) cross at (2, 2); the lobes
    # have equal and opposite signed areas, but the polygon's area is not zero.
    msg = polygon_error([[0, 0], [4, 4], [4, 0], [0, 4]])
    assert "edges 0 and 2 cross at (2.0, 2.0)" in msg


def test_vertex_touching_a_non_adjacent_edge():
    # Vertex 3 = (10, 0) lies inside edge 0 ((0, 0) -> (20, 0)); edge 2 ends there.
    msg = polygon_error([[0, 0], [20, 0], [20, 20], [10, 0], [0, 20]])
    assert msg == "p.json: polygon is self-intersecting: edges 0 and 2 cross at (10.0, 0.0)"


def test_slot_cut_down_onto_the_boundary():
    # A slot cut from the top edge (y = 10) down to the bottom edge (edge 0,
    # y = 0): its walls, edges 3 and 5, end on edge 0, and edge 4 runs along it.
    msg = polygon_error([[0, 0], [30, 0], [30, 10], [20, 10], [20, 0], [10, 0], [10, 10], [0, 10]])
    assert msg == "p.json: polygon is self-intersecting: edges 0 and 3 cross at (20.0, 0.0)"


def test_boundary_doubling_back_is_a_spike():
    # (20, 0) -> (20, 20) -> (20, 10): edge 2 runs back along edge 1.
    msg = polygon_error([[0, 0], [20, 0], [20, 20], [20, 10]])
    assert msg == (
        "p.json: edges 1 and 2 overlap (the boundary doubles back at vertex 2, (20.0, 20.0))"
    )


def test_spike_at_vertex_zero_names_the_last_edge():
    msg = polygon_error([[20, 20], [20, 10], [0, 0], [20, 0]])
    assert msg == "p.json: edges 3 and 0 overlap (the boundary doubles back at vertex 0, (20.0, 20.0))"


def test_check_pair_rejects_different_vertex_counts():
    src = Polygon(SQUARE, name="src.json")
    dst = Polygon([[0, 0], [4, 0], [0, 4]], name="dst.json")
    with pytest.raises(PolygonError, match="vertices but") as info:
        check_pair(src, dst)
    assert str(info.value) == "dst.json: polygon has 3 vertices but src.json has 4"


def test_check_pair_accepts_equal_counts():
    assert check_pair(Polygon(SQUARE), Polygon(regular(4))) is None


# --- clearance: slivers, needles, slits ---------------------------------------


@pytest.mark.parametrize("height", [1e-4, 1e-5, 1e-6])
def test_needle_triangle_is_too_thin(height):
    # Apex over the middle of a 1000 px base: every edge is long, but vertex 2
    # is `height` from edge 0.
    msg = polygon_error([[0, 0], [1000, 0], [500, height]])
    assert msg == (
        f"p.json: polygon is too thin: vertex 2 (500.0, {height:g}) is {height:g} px from edge 0 "
        "(the minimum clearance is 0.001 px)"
    )


def test_sliver_rectangle_has_edges_too_short():
    msg = polygon_error([[0, 0], [236, 0], [236, 0.0002], [0, 0.0002]])
    assert msg == (
        "p.json: edge 1 is too short: 0.0002 px from vertex 1 (236.0, 0.0) to vertex 2 (236.0, 0.0002) "
        "(the minimum is 0.001 px)"
    )


def test_slit_with_a_closed_mouth_is_too_thin():
    # A square with a V-shaped slit from the top edge down to (100, 50),
    # its mouth 1e-12 px wide (this one crashed the mesher).
    w = 1e-12
    msg = polygon_error([[0, 0], [200, 0], [200, 200], [100 + w / 2, 200], [100, 50], [100 - w / 2, 200], [0, 200]])
    assert msg.startswith("p.json: polygon is too thin: vertex 3 (100.0, 200.0) is 9.9476e-13 px from edge 4 ")


@pytest.mark.parametrize("gap, ok", [(0.05, True), (0.0011, True), (0.0009, False), (1e-9, False)])
def test_gap_between_two_arms(gap, ok):
    # A U: two arms 100 px long, `gap` apart. Thin but deliberate at 0.05 px.
    pts = [[0, 0], [100, 0], [100, 100], [50 + gap / 2, 100], [50 + gap / 2, 10], [50 - gap / 2, 10], [50 - gap / 2, 100], [0, 100]]
    if ok:
        assert Polygon(pts).n == 8
    else:
        assert "edge 4 is too short" in polygon_error(pts)


def test_a_crossing_is_named_before_a_clearance_fault():
    # The bow-tie again, with vertex 0 doubled 1e-4 px away (edge 4 too short).
    msg = polygon_error([[0, 0], [40, 40], [40, 0], [0, 60], [0, 1e-4]])
    assert msg == "p.json: polygon is self-intersecting: edges 0 and 2 cross at (24.0, 24.0)"


def test_clearance_floor_grows_with_the_polygon():
    assert clearance_floor(SQUARE) == MIN_CLEARANCE
    # A 3e5 x 4e5 px triangle: diagonal 5e5 px, floor 0.5 px.
    assert clearance_floor([[0, 0], [3e5, 0], [3e5, 4e5]]) == pytest.approx(MIN_CLEARANCE_RELATIVE * 5e5)
    msg = polygon_error([[0, 0], [3e5, 0], [3e5, 4e5], [3e5 - 0.25, 4e5]])
    assert msg == (
        "p.json: edge 2 is too short: 0.25 px from vertex 2 (300000.0, 400000.0) to vertex 3 (300000.0, 400000.0) "
        "(the minimum is 0.5 px for a polygon this large: 1e-06 of its bounding box's diagonal)"
    )


def test_needle_that_crashed_the_mesher_is_too_thin():
    # 1e8 px long, 26 px wide at its base: a tip angle of 2.6e-7 rad.
    # Its base is an edge only 26 px long, where the polygon's size asks for 100.
    msg = polygon_error([[100000032.0, 24.0], [20.99605623705275, 34.19378348121512], [28.673896426063155, 9.373413418864791]])
    assert msg == (
        "p.json: edge 1 is too short: 25.9808 px from vertex 1 (20.9961, 34.1938) to vertex 2 (28.6739, 9.37341) "
        "(the minimum is 100.0 px for a polygon this large: 1e-06 of its bounding box's diagonal)"
    )


def test_a_value_just_under_the_floor_is_shown_with_enough_digits():
    msg = polygon_error([[0, 0], [100, 0], [100, 0.000999999]])
    assert "0.000999999 px" in msg


# --- far from the origin --------------------------------------------------------


def test_small_polygon_far_from_the_origin_keeps_its_area():
    # A 10 px square at 1e9 - 20: the plain shoelace sum would lose the
    # area's digits in products near 1e18.
    x0 = 1e9 - 20
    pts = [[x0, x0], [x0 + 10, x0], [x0 + 10, x0 + 10], [x0, x0 + 10]]
    poly = Polygon(pts)
    assert poly.signed_area == 100.0
    assert Polygon(pts[::-1]).signed_area == -100.0


@pytest.mark.parametrize(
    "offset, problem",
    [(1e6, "edge 0 is too short: 1"), (-1e6, "edge 0 is too short: 1"), (999_999_000.0, "vertices 0 and 1 are repeated")],
)
def test_tiny_edge_far_from_the_origin(offset, problem):
    # 1e-9 px is 8 units in the last place at 1e6, and rounds away at 1e9.
    pts = np.array([[0, 0], [1e-9, 0], [100, 50], [0, 100]]) + offset
    assert problem in polygon_error(pts)


# --- valid polygons ----------------------------------------------------------


def test_both_orientations_are_accepted_with_opposite_signed_areas():
    cw = Polygon(SQUARE)  # right along the top, then down: clockwise on screen (y down)
    ccw = Polygon(SQUARE[::-1])
    assert cw.signed_area == 16.0
    assert ccw.signed_area == -16.0
    assert cw.bounds == ccw.bounds == (0.0, 0.0, 4.0, 4.0)


def test_signed_area_of_the_l_shape_is_exact():
    # 112 x 112 square minus its 56 x 56 top-right quadrant.
    assert Polygon(l_shape()).signed_area == 112.0**2 - 56.0**2
    assert Polygon(l_shape()[::-1]).signed_area == -(112.0**2 - 56.0**2)


@pytest.mark.parametrize("shift", range(6))
@pytest.mark.parametrize("reverse", [False, True])
def test_l_shape_has_exactly_one_reflex_vertex(shift, reverse):
    pts = l_shape()
    corner = pts[2].copy()  # (64, 64): the inner corner of the notch
    if reverse:
        pts = pts[::-1]
    pts = np.roll(pts, -shift, axis=0)
    reflex = Polygon(pts).reflex_vertices()
    assert len(reflex) == 1
    assert pts[reflex[0]].tolist() == corner.tolist()
    expected = ((5 - 2) if reverse else 2) - shift
    assert reflex.tolist() == [expected % 6]


def test_reflex_vertices_of_convex_and_star_polygons():
    assert Polygon(regular(7)).reflex_vertices().tolist() == []
    # helpers.star puts the outer points at even indices: the inner ones are reflex.
    assert Polygon(star(5)).reflex_vertices().tolist() == [1, 3, 5, 7, 9]
    assert Polygon(star(5)[::-1]).reflex_vertices().tolist() == [0, 2, 4, 6, 8]


def test_a_straight_angle_vertex_is_accepted_and_not_reflex():
    # Vertex 1 sits on the straight line from vertex 0 to vertex 2 (180 degrees).
    poly = Polygon([[0, 0], [10, 0], [20, 0], [20, 20], [0, 20]])
    assert poly.signed_area == 400.0
    assert poly.reflex_vertices().tolist() == []


# --- properties --------------------------------------------------------------


@st.composite
def star_shaped(draw):
    """Random radii in [15, 50] px at sorted random angles, every wedge under pi.

    With each angular gap (including the wrap-around) below pi, the centre is
    in the polygon's kernel, so the polygon is simple; with gaps over 1e-3 rad
    its vertices are over 0.015 px apart, well clear of MIN_CLEARANCE.
    """
    angles = draw(
        st.lists(
            st.floats(0.0, 2 * math.pi, exclude_max=True, allow_nan=False),
            min_size=3,
            max_size=40,
            unique=True,
        )
    )
    angles = np.sort(np.array(angles))
    gaps = np.diff(np.append(angles, angles[0] + 2 * math.pi))
    assume(gaps.min() > 1e-3 and gaps.max() < math.pi - 1e-3)
    radii = 50.0 * np.array(draw(st.lists(st.floats(0.3, 1.0), min_size=len(angles), max_size=len(angles))))
    return 64.0 + np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=1)


@given(star_shaped())
def test_random_star_shaped_polygons_are_accepted(points):
    poly = Polygon(points)
    assert poly.n == len(points)
    # Increasing angle with y down is clockwise on screen: positive area.
    assert poly.signed_area > 0


@given(star_shaped(), st.integers(0, 39))
def test_reversing_the_vertex_order_flips_the_signed_area(points, shift):
    fwd = Polygon(np.roll(points, shift, axis=0))
    back = Polygon(points[::-1])
    assert back.signed_area == pytest.approx(-fwd.signed_area, rel=1e-12)
    assert math.copysign(1.0, back.signed_area) == -math.copysign(1.0, fwd.signed_area)


# --- other formats: labelme and GeoJSON, recognised by content ------------------

PTS = [[10.0, 10.0], [50.0, 12.0], [40.0, 45.0], [12.0, 40.0]]


def labelme(*shapes):
    return {
        "version": "5.4.1",
        "flags": {},
        "shapes": [{"label": lab, "points": pts, "group_id": None, "shape_type": kind, "flags": {}} for lab, pts, kind in shapes],
        "imagePath": "in.png",
        "imageData": None,
        "imageHeight": 64,
        "imageWidth": 64,
    }


def geo_polygon(pts):
    return {"type": "Polygon", "coordinates": [pts + [pts[0]]]}


@pytest.mark.parametrize(
    "doc",
    [
        PTS,
        {"points": PTS},
        labelme(("face", PTS, "polygon")),
        labelme(("dot", [[1.0, 1.0]], "point"), ("face", PTS, "polygon")),
        geo_polygon(PTS),
        {"type": "Feature", "properties": {}, "geometry": geo_polygon(PTS)},
        {"type": "FeatureCollection", "features": [{"type": "Feature", "properties": None, "geometry": geo_polygon(PTS)}]},
    ],
    ids=["array", "points", "labelme", "labelme-with-a-point", "geojson", "feature", "collection"],
)
def test_every_format_gives_the_same_polygon(tmp_path, doc):
    path = write_text(tmp_path / "p.json", json.dumps(doc))
    assert read_polygon(path).points.tolist() == PTS


def test_labelme_with_several_polygons_needs_a_label(tmp_path):
    other = [[0.0, 0.0], [5.0, 0.0], [0.0, 5.0]]
    path = write_text(tmp_path / "lm.json", json.dumps(labelme(("face", PTS, "polygon"), ("eye", other, "polygon"))))
    with pytest.raises(PolygonError, match=r"2 polygons \(face, eye\); choose one") as info:
        read_polygon(path)
    assert str(info.value).startswith(f"{path}: ")
    assert read_polygon(path, label="eye").points.tolist() == other
    with pytest.raises(PolygonError, match="no polygon labelled 'nose'"):
        read_polygon(path, label="nose")


def test_geojson_rules(tmp_path):
    open_ring = {"type": "Polygon", "coordinates": [PTS]}
    with pytest.raises(PolygonError, match="ring must end with its first vertex"):
        read_polygon(write_text(tmp_path / "a.json", json.dumps(open_ring)))
    holed = {"type": "Polygon", "coordinates": [PTS + [PTS[0]], [[20, 20], [25, 20], [22, 25], [20, 20]]]}
    with pytest.raises(PolygonError, match="hole"):
        read_polygon(write_text(tmp_path / "b.json", json.dumps(holed)))
    point = {"type": "Feature", "geometry": {"type": "Point", "coordinates": [1, 2]}}
    with pytest.raises(PolygonError, match="Point, not a Polygon"):
        read_polygon(write_text(tmp_path / "c.json", json.dumps(point)))
    two = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"name": "a"}, "geometry": geo_polygon(PTS)},
        {"type": "Feature", "properties": {"label": "b"}, "geometry": geo_polygon(PTS[::-1])},
    ]}  # fmt: skip
    path = write_text(tmp_path / "d.json", json.dumps(two))
    with pytest.raises(PolygonError, match="2 features"):
        read_polygon(path)
    assert read_polygon(path, label="b").points.tolist() == PTS[::-1]


def test_a_label_for_a_single_plain_polygon_is_an_error(tmp_path):
    path = write_text(tmp_path / "p.json", json.dumps(PTS))
    with pytest.raises(PolygonError, match="no labels"):
        read_polygon(path, label="face")


def test_a_polygon_is_chosen_by_index_when_labels_do_not_tell_them_apart(tmp_path):
    import json as _json

    a = [[0, 0], [10, 0], [0, 10]]
    b = [[20, 20], [30, 20], [20, 30]]
    path = tmp_path / "two.json"
    path.write_text(_json.dumps({"shapes": [{"label": "", "points": a}, {"label": "", "points": b}]}))
    assert read_polygon(path, "#1").points.tolist() == [[20.0, 20.0], [30.0, 20.0], [20.0, 30.0]]
    assert read_polygon(path, "#0").points.tolist() == [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]]
    with pytest.raises(PolygonError, match="no polygon #2"):
        read_polygon(path, "#2")
    geo = tmp_path / "two.geojson"
    feats = [{"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [p + [p[0]]]}} for p in (a, b)]
    geo.write_text(_json.dumps({"type": "FeatureCollection", "features": feats}))
    assert read_polygon(geo, "#1").points[0].tolist() == [20.0, 20.0]
    # A shape literally labelled "#1" wins over the index.
    path.write_text(_json.dumps({"shapes": [{"label": "#1", "points": a}, {"label": "", "points": b}]}))
    assert read_polygon(path, "#1").points[0].tolist() == [0.0, 0.0]
