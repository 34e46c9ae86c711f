"""Generated cases for warpcli.polygon: the grid check agrees with all pairs, thin shapes are refused, hostile files fail in one line."""

from __future__ import annotations

import json
import math
import re
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from warpcli.polygon import validate as polymod  # its work limits are patched below
from warpcli.errors import PolygonError
from warpcli.polygon import MIN_CLEARANCE, MIN_CLEARANCE_RELATIVE, Polygon, clearance_floor, read_polygon
from warpcli.polygon.predicates import orient_sign, segments_touch
from warpcli.polygon.validate import check_edges

# --- helpers -----------------------------------------------------------------


def verdict(points, *, grid: bool) -> str | None:
    """The message of the simplicity and clearance checks, through the grid or all pairs; None if valid."""
    try:
        check_edges(np.asarray(points, dtype=float), "p", clearance=True, grid=grid)
    except PolygonError as err:
        return str(err)
    return None


def place(points, angle: float, offset: float) -> np.ndarray:
    """Rotate about the origin, then move by (offset, offset / 2)."""
    c, s = math.cos(angle), math.sin(angle)
    pts = np.asarray(points, dtype=float) @ np.array([[c, s], [-s, c]])
    return pts + np.array([offset, offset / 2])


def comb(teeth: int, width: float, gap: float, length: float) -> np.ndarray:
    """Teeth ``width`` wide and ``length`` long, ``gap`` apart, on a 10 px bar."""
    pts = []
    pitch = width + gap
    for k in range(teeth):
        x = k * pitch
        pts += [[x, 0.0], [x, length], [x + width, length], [x + width, 0.0]]
    end = teeth * pitch - gap
    pts += [[end, -10.0], [0.0, -10.0]]
    return np.array(pts)


def wavy_star(n: int, radius: float = 1e4) -> np.ndarray:
    """r(a) = R (1 + 0.3 sin 17a) at n equal angles (as bench/polygon_validation.py)."""
    a = 2 * np.pi * np.arange(n) / n
    r = radius * (1 + 0.3 * np.sin(17 * a))
    return np.stack([2 * radius + r * np.cos(a), 2 * radius + r * np.sin(a)], axis=1)


def reference_clearance(pts: np.ndarray) -> tuple[float, int, int]:
    """(distance, vertex, edge): the closest vertex to an edge not ending at it, over all n^2 pairs."""
    n = len(pts)
    a = pts[None, :, :]
    d = np.roll(pts, -1, axis=0)[None, :, :] - a
    p = pts[:, None, :]
    t = np.clip(((p - a) * d).sum(-1) / (d * d).sum(-1), 0.0, 1.0)
    dist = np.hypot(*np.moveaxis(p - (a + t[..., None] * d), -1, 0))
    v = np.arange(n)[:, None]
    e = np.arange(n)[None, :]
    dist[(v == e) | (v == (e + 1) % n)] = np.inf
    k = int(np.argmin(dist))
    return float(dist.flat[k]), k // n, k % n


def reference_clearance_of(pts: np.ndarray, v: int, e: int) -> float:
    """Distance from vertex v to edge e."""
    a = pts[e]
    d = pts[(e + 1) % len(pts)] - a
    t = min(max(float((pts[v] - a) @ d / (d @ d)), 0.0), 1.0)
    return float(np.hypot(*(pts[v] - a - t * d)))


# --- strategies ----------------------------------------------------------------


@st.composite
def lattice_polygons(draw):
    """Random vertices on a small lattice: crossings, touching, collinear overlaps, spikes.

    The lattice step is 1 px or 2**-12 px (below the clearance floor), the
    lattice is exact in floating point, and it may sit at 2**20 or 2**29.
    """
    n = draw(st.integers(4, 120))
    side = draw(st.sampled_from([4, 16, 1000]))
    xy = draw(st.lists(st.tuples(st.integers(0, side - 1), st.integers(0, side - 1)), min_size=n, max_size=n, unique=True))
    step = draw(st.sampled_from([1.0, 2.0**-12]))
    offset = draw(st.sampled_from([0.0, 2.0**20, 2.0**29]))
    return np.array(xy, dtype=float) * step + offset


@st.composite
def crowded_polygons(draw):
    """Combs (crowded grid cells, so cells are split) and star polygons, with a few vertices moved."""
    if draw(st.booleans()):
        width = draw(st.sampled_from([1.0, 0.01, 0.0015]))
        gap = draw(st.sampled_from([1.0, 0.01, 0.0015, 0.0008]))
        # Long teeth only where they are wide apart: 60 teeth 0.0015 px wide
        # and 100 px long would need ten million triangles, and are refused
        # as too intricate (see test_too_intricate_polygon_is_refused_with_a_place).
        length = draw(st.sampled_from([5.0, 100.0] if min(width, gap) >= 0.01 else [1.0, 5.0]))
        pts = comb(draw(st.integers(5, 60)), width, gap, length)
    else:
        n = draw(st.integers(40, 300))
        gaps = np.array(draw(st.lists(st.floats(0.05, 1.0), min_size=n, max_size=n)))
        radii = np.array(draw(st.lists(st.floats(0.2, 1.0), min_size=n, max_size=n)))
        a = np.cumsum(gaps) / gaps.sum() * 2 * np.pi
        scale = draw(st.sampled_from([1.0, 100.0, 1e5]))
        pts = scale * np.stack([radii * np.cos(a), radii * np.sin(a)], axis=1)
    pts = place(pts, draw(st.floats(0.0, 2 * math.pi)), draw(st.sampled_from([0.0, 1e6])))
    for _ in range(draw(st.integers(0, 3))):
        i = draw(st.integers(0, len(pts) - 1))
        j = draw(st.integers(0, len(pts) - 1))
        nudge = np.array(draw(st.tuples(st.floats(-1, 1), st.floats(-1, 1))))
        pts[i] = pts[j] + nudge * draw(st.sampled_from([1e-4, 1e-2, 1.0]))
    return pts


def no_repeats(pts) -> bool:
    return len(np.unique(pts, axis=0)) == len(pts)


# --- the grid agrees with testing all pairs ------------------------------------


@given(lattice_polygons())
@settings(max_examples=60)
def test_grid_and_all_pairs_agree_on_lattice_polygons(pts):
    assume(no_repeats(pts))
    expected = verdict(pts, grid=False)
    assert verdict(pts, grid=True) == expected
    if expected is None:
        return
    if "self-intersecting" in expected:
        # The first crossing pair (i, j), i < j, over all non-adjacent pairs.
        n = len(pts)
        i, j = np.triu_indices(n, 2)
        keep = ~((i == 0) & (j == n - 1))
        i, j = i[keep], j[keep]
        b = np.roll(pts, -1, axis=0)
        hit = segments_touch(pts[i], b[i], pts[j], b[j])
        k = int(np.flatnonzero(hit)[0])
        assert f"edges {i[k]} and {j[k]} cross at " in expected


@given(crowded_polygons())
@settings(max_examples=40)
def test_grid_and_all_pairs_agree_on_crowded_polygons(pts):
    assume(no_repeats(pts))
    assert verdict(pts, grid=True) == verdict(pts, grid=False)


@st.composite
def keyholes(draw):
    """A square with a keyhole from the top: a neck ``g`` wide, then a chamber.

    The neck's walls are not adjacent edges, so a neck narrower than the floor
    is a fault found by the grid (or all pairs). The square's sides carry
    extra vertices, so that there are enough for the grid.
    """
    g = draw(st.floats(-9.0, math.log10(20 * MIN_CLEARANCE)).map(lambda e: 10.0**e)) / 2
    neck = draw(st.floats(1.0, 50.0))
    w = draw(st.floats(1.0, 50.0))
    h = draw(st.floats(1.0, 50.0))
    hole = [
        [100 + g, 200], [100 + g, 200 - neck], [100 + w, 200 - neck], [100 + w, 200 - neck - h],
        [100 - w, 200 - neck - h], [100 - w, 200 - neck], [100 - g, 200 - neck], [100 - g, 200],
    ]  # fmt: skip
    k = draw(st.integers(1, 60))
    t = np.linspace(0, 200, k + 2)[1:-1]
    bottom = np.stack([t, np.zeros(k)], axis=1)
    right = np.stack([np.full(k, 200.0), t], axis=1)
    left = np.stack([np.zeros(k), t[::-1]], axis=1)
    pts = np.concatenate([[[0, 0]], bottom, [[200, 0]], right, [[200, 200]], hole, [[0, 200]], left])
    return place(pts, draw(st.floats(0.0, 2 * math.pi)), draw(st.sampled_from([0.0, 1e6])))


@given(keyholes())
@settings(max_examples=30)
def test_named_clearance_fault_is_the_closest_pair(pts):
    assume(no_repeats(pts))
    msg = verdict(pts, grid=True)
    assert msg == verdict(pts, grid=False)
    d, _, _ = reference_clearance(pts - pts.min(axis=0))
    if d >= clearance_floor(pts) * (1 + 1e-9):
        assert msg is None
        return
    if d < clearance_floor(pts) * (1 - 1e-9):
        assert msg is not None
    assume(msg is not None and "too thin" in msg)
    v, e = map(int, re.search(r"vertex (\d+) .* from edge (\d+) ", msg).groups())
    named = reference_clearance_of(pts - pts.min(axis=0), v, e)
    # Distances carry rounding errors of the coordinates' size (1e-10 at 1e6).
    assert named == pytest.approx(d, rel=1e-9, abs=64 * np.finfo(float).eps * np.abs(pts).max())


# --- exact orientation ----------------------------------------------------------------


def exact_sign(ax, ay, bx, by, cx, cy) -> int:
    ax, ay, bx, by, cx, cy = map(Fraction, (ax, ay, bx, by, cx, cy))
    d = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    return (d > 0) - (d < 0)


coordinates = st.floats(-1e9, 1e9, allow_nan=False, allow_infinity=False)


@st.composite
def near_collinear_triples(draw):
    """Three points on a line through two random points (rounded to doubles), or near it."""
    ax, ay, bx, by = (draw(coordinates) for _ in range(4))
    t = draw(st.floats(-3.0, 3.0))
    nudge = draw(st.sampled_from([0.0, 1e-300, 1e-12, 1e-6]))
    return ax, ay, bx, by, ax + t * (bx - ax) + nudge, ay + t * (by - ay)


@given(st.lists(near_collinear_triples() | st.tuples(*[coordinates] * 6), min_size=1, max_size=20))
@settings(max_examples=60)
def test_orientation_signs_are_exact(triples):
    cols = [np.array(c) for c in zip(*triples)]
    got = orient_sign(*cols)
    assert got.tolist() == [exact_sign(*t) for t in triples]


def test_collinear_edges_far_apart_do_not_touch():
    # Two edges on nearly one line, 80 px apart: rounded orientation signs
    # said they cross (found by comparing the grid with all pairs).
    p1, p2 = np.array([[176.76952724970698, 13.19954485973171]]), np.array([[178.8883598217389, 16.499431074664635]])
    q1, q2 = np.array([[229.740341550505, 95.6967002330549]]), np.array([[231.85917412253693, 98.99658644798782]])
    assert not segments_touch(p1, p2, q1, q2)[0]
    naive = [(b[0, 0] - a[0, 0]) * (c[0, 1] - a[0, 1]) - (b[0, 1] - a[0, 1]) * (c[0, 0] - a[0, 0]) for a, b, c in [(p1, p2, q1), (p1, p2, q2), (q1, q2, p1), (q1, q2, p2)]]
    assert naive[0] * naive[1] < 0 and naive[2] * naive[3] < 0  # what the old test saw


# --- valid polygons stay valid -----------------------------------------------------


@st.composite
def star_polygons(draw, max_n: int = 80):
    """Star-shaped (simple by construction), 50 px across or larger, clearance well above the floor."""
    n = draw(st.integers(3, max_n))
    gaps = np.array(draw(st.lists(st.floats(0.2, 1.0), min_size=n, max_size=n)))
    radii = np.array(draw(st.lists(st.floats(0.5, 1.0), min_size=n, max_size=n)))
    a = np.cumsum(gaps) / gaps.sum() * 2 * np.pi
    scale = draw(st.sampled_from([50.0, 1000.0, 1e5]))
    return scale * np.stack([radii * np.cos(a), radii * np.sin(a)], axis=1)


@given(star_polygons(), st.floats(0.0, 2 * math.pi), st.sampled_from([0.0, 1e6, 1e8]), st.booleans())
@settings(max_examples=40)
def test_star_polygons_are_accepted_anywhere(pts, angle, offset, reverse):
    pts = place(pts, angle, offset)
    if reverse:
        pts = pts[::-1]
    poly = Polygon(pts)
    assert poly.n == len(pts)
    assert (poly.signed_area > 0) != reverse


# --- slivers, needles, slits, gaps -------------------------------------------------

placements = st.tuples(st.floats(0.0, 2 * math.pi), st.sampled_from([0.0, 1234.5, 1e6]))


def floor_for(size: float) -> float:
    """The clearance floor of a shape about ``size`` across."""
    return max(MIN_CLEARANCE, MIN_CLEARANCE_RELATIVE * size)


#: (thin, factor): a width of ``factor`` times the floor, well below it (down
#: to 1e-10 of it) or safely above it.
widths = st.booleans().flatmap(
    lambda thin: st.tuples(
        st.just(thin),
        (st.floats(-10.0, math.log10(0.5)) if thin else st.floats(math.log10(2.0), 2.5)).map(lambda e: 10.0**e),
    )
)


@given(widths, st.floats(0.0, 6.0).map(lambda e: 10.0**e), st.floats(0.1, 0.9), placements)
@settings(max_examples=40)
def test_needle_triangles(case, base, t, where):
    thin, factor = case
    height = factor * floor_for(base)
    pts = place([[0.0, 0.0], [base, 0.0], [t * base, height]], *where)
    msg = verdict(pts, grid=False)
    if thin:
        # Lower than rounding at the triangle's place, the apex falls onto
        # the base: then the boundary doubles back.
        assert msg is not None and re.search(r"too thin: vertex 2 .* from edge 0 |edge \d is too short|overlap", msg), msg
    else:
        assert msg is None
        Polygon(pts)


@given(widths, st.floats(0.0, 6.0).map(lambda e: 10.0**e), placements)
@settings(max_examples=30)
def test_sliver_rectangles(case, length, where):
    thin, factor = case
    width = factor * floor_for(length)
    pts = place([[0.0, 0.0], [length, 0.0], [length, width], [0.0, width]], *where)
    if thin:
        with pytest.raises(PolygonError) as info:
            Polygon(pts, name="r.json")
        # Narrower than rounding at the rectangle's place, the sides merge.
        assert re.match(r"r\.json: (edge [13] is too short: |vertices \d and \d are repeated|polygon has zero area)", str(info.value)), str(info.value)
    else:
        assert Polygon(pts).n == 4


sides = st.sampled_from([200.0, 2e4, 2e6])


@given(widths, st.floats(0.005, 0.95), sides, placements)
@settings(max_examples=30)
def test_v_slits(case, depth, side, where):
    thin, factor = case
    mouth = factor * floor_for(side)
    u = side / 200  # the square is 200 u wide, the slit depth * 200 u deep
    pts = place(
        [[0, 0], [200 * u, 0], [200 * u, 200 * u], [100 * u + mouth / 2, 200 * u], [100 * u, 200 * u * (1 - depth)], [100 * u - mouth / 2, 200 * u], [0, 200 * u]],
        *where,
    )
    if thin:
        with pytest.raises(PolygonError) as info:
            Polygon(pts, name="v.json")
        # Vertex 3 or 5, at the mouth, against the far side of the slit (or,
        # narrower than rounding at the slit's place, the same vertex twice).
        assert re.match(r"v\.json: (polygon is too thin: vertex [35] .* from edge [2-5] |vertices 3 and 5 are repeated)", str(info.value)), str(info.value)
    else:
        assert Polygon(pts).n == 7


@given(widths, st.floats(0.01, 0.99), sides, placements)
@settings(max_examples=30)
def test_gaps_between_arms(case, depth, side, where):
    thin, factor = case
    g = factor * floor_for(side) / 2
    u = side / 100  # a U 100 u wide, its gap depth * 100 u deep
    pts = place(
        [[0, 0], [100 * u, 0], [100 * u, 100 * u], [50 * u + g, 100 * u], [50 * u + g, 100 * u * (1 - depth)], [50 * u - g, 100 * u * (1 - depth)], [50 * u - g, 100 * u], [0, 100 * u]],
        *where,
    )
    if thin:
        with pytest.raises(PolygonError, match="edge 4 is too short|are repeated"):
            Polygon(pts)
    else:
        assert Polygon(pts).n == 8


# --- far from the origin, tiny or huge -----------------------------------------------


@given(
    star_polygons(max_n=30),
    st.floats(-10.0, 3.0).map(lambda e: 10.0**e),
    st.sampled_from([0.0, 1e6, -1e6, 5e8, 999_999_000.0, -999_999_000.0]),
    st.integers(-1, 29),
)
@settings(max_examples=60)
def test_any_scale_and_place_gives_a_polygon_or_one_polygon_error(pts, scale, offset, tiny):
    pts = pts / 50.0 * scale + offset
    if tiny >= 0 and tiny < len(pts):
        pts[tiny] = pts[(tiny + 1) % len(pts)] + 1e-9  # an edge 1e-9 px long, or a repeat after rounding
    try:
        poly = Polygon(pts, name="s.json")
    except PolygonError as err:
        assert str(err).startswith("s.json: ")
        assert "\n" not in str(err)
    else:
        assert abs(poly.signed_area) > 0


# --- hostile files -------------------------------------------------------------------

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=5)
    | st.dictionaries(
        st.sampled_from(["points", "shapes", "label", "shape_type", "type", "features", "geometry", "coordinates", "properties", "name", "x"]),
        inner,
        max_size=4,
    ),
    max_leaves=30,
)

VALID_DOCS = [
    [[10.0, 10.0], [50.0, 12.0], [40.0, 45.0]],
    {"shapes": [{"label": "a", "points": [[10.0, 10.0], [50.0, 12.0], [40.0, 45.0]], "shape_type": "polygon"}]},
    {"type": "Feature", "properties": {"label": "a"}, "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [9, 0], [0, 9], [0, 0]]]}},
]


def mutate(doc, path, value):
    """``doc`` with the member or element at ``path`` (indices wrapped around) replaced by ``value``."""
    if not path or not isinstance(doc, (list, dict)) or not doc:
        return value
    if isinstance(doc, list):
        i = path[0] % len(doc)
        return doc[:i] + [mutate(doc[i], path[1:], value)] + doc[i + 1 :]
    key = sorted(doc)[path[0] % len(doc)]
    return {**doc, key: mutate(doc[key], path[1:], value)}


def assert_polygon_or_one_line_error(path: str, label=None) -> None:
    try:
        read_polygon(path, label)
    except PolygonError as err:
        msg = str(err)
        assert msg.startswith(f"{path}: ")
        assert "\n" not in msg and "\r" not in msg
        msg.encode("utf-8")  # printable on any terminal: no lone surrogates


@given(st.binary(max_size=200))
@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_random_bytes(tmp_path, data):
    path = tmp_path / "b.json"
    path.write_bytes(data)
    assert_polygon_or_one_line_error(str(path))


@given(json_values, st.sampled_from([None, "a", "face"]))
@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_random_json_documents(tmp_path, doc, label):
    path = tmp_path / "j.json"
    path.write_text(json.dumps(doc))
    assert_polygon_or_one_line_error(str(path), label)


@given(st.sampled_from(VALID_DOCS), st.lists(st.integers(0, 7), max_size=5), json_values)
@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_mutated_polygon_documents(tmp_path, doc, where, value):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(mutate(doc, where, value)))
    assert_polygon_or_one_line_error(str(path))


@given(st.sampled_from(["[", "{\"points\": [", "[[0, ", "[[0, 0], [1"]), st.integers(1, 6000), st.sampled_from(["0", "9", "-"]))
@settings(max_examples=20, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_truncated_and_overlong_tokens(tmp_path, head, count, char):
    path = tmp_path / "t.json"
    path.write_text(head + char * count)
    assert_polygon_or_one_line_error(str(path))


# --- the work stays near-linear ------------------------------------------------------


def test_wavy_star_tests_a_linear_number_of_pairs():
    pts = wavy_star(20_000)
    tested = check_edges(pts, "w", clearance=True)
    assert tested < 2 * len(pts)


def test_detail_next_to_long_edges_tests_a_linear_number_of_pairs():
    # A rectangle 10 000 px wide whose bottom side is 20 000 edges of 0.5 px:
    # cells sized for the short edges, the long ones crossing 20 000 of them.
    x = np.linspace(0.0, 10_000.0, 20_001)
    bottom = np.stack([x, 3.0 * np.sin(x / 7.0)], axis=1)
    pts = np.concatenate([bottom, [[10_000.0, 5_000.0], [0.0, 5_000.0]]])
    tested = check_edges(pts, "d", clearance=True)
    assert tested < 4 * len(pts)


def test_comb_with_crowded_cells_is_split_and_accepted():
    # 1000 teeth 0.5 px wide and apart, 40 px long: the first cells hold
    # dozens of teeth and are split down to a pixel or so.
    pts = place(comb(1000, 0.5, 0.5, 40.0), 0.3, 10.0)
    tested = check_edges(pts, "c", clearance=True)
    assert tested < 64 * len(pts)  # all pairs would be 2000 n


def test_edges_piled_up_in_one_place_are_refused_quickly():
    # 5000 vertices zigzag within 1e-5 rad of one ray: cells crowd to the
    # finest size; the first fault found there is named.
    m = 5000
    a = np.concatenate([np.linspace(0, 1e-5, m), np.linspace(0.1, 2 * np.pi - 0.1, 300)])
    r = np.concatenate([100 + 0.3 * np.sin(np.arange(m)), np.full(300, 100.0)])
    pts = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    with pytest.raises(PolygonError, match="too short|too thin|self-intersecting"):
        Polygon(pts)


def test_all_edges_through_one_point_give_the_first_crossing():
    n = 20_001  # odd: vertices k * pi (1 - 1/n) around a circle, every edge a near-diameter
    a = np.arange(n) * np.pi * (1 - 1 / n)
    pts = 1000 * np.stack([np.cos(a), np.sin(a)], axis=1)
    with pytest.raises(PolygonError, match="self-intersecting") as info:
        Polygon(pts)
    assert "edges 0 and 2 cross at " in str(info.value)


def test_too_intricate_polygon_is_refused_with_a_place(monkeypatch):
    # With the work limits made small, a comb of long teeth 0.05 px apart
    # exceeds them; the message says where edges crowd.
    monkeypatch.setattr(polymod, "_ENTRIES_EXTRA", 1000)
    monkeypatch.setattr(polymod, "_PAIRS_EXTRA", 1000)
    pts = place(comb(300, 0.05, 0.05, 100.0), 0.3, 50.0)
    with pytest.raises(PolygonError, match="too intricate") as info:
        Polygon(pts, name="comb.json")
    assert re.match(
        r"comb\.json: polygon is too intricate to check in reasonable time: long edges run close together "
        r"over much of it \(for one, [\d,]+ edges pass through the square [\d.e+-]+ px wide centred at "
        r"\([\d.e+-]+, [\d.e+-]+\)\); simplify it$",
        str(info.value),
    ), str(info.value)
