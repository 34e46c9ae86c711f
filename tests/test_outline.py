"""The ring between a fixed outline and moved cages, cut into faces simple on both sides (warpcli.polygon.outline)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from warpcli.errors import PolygonError
from warpcli.grid import inside_polygon
from warpcli.polygon import Polygon
from warpcli.polygon.outline import cut_ring, outline_polygon
from warpcli.polygon.validate import validate_points


def exact_area(points) -> Fraction:
    """Shoelace area in rationals (exact for the doubles given)."""
    p = [(Fraction(float(x)), Fraction(float(y))) for x, y in points]
    return sum((p[i][0] * p[(i + 1) % len(p)][1] - p[(i + 1) % len(p)][0] * p[i][1] for i in range(len(p))), Fraction(0)) / 2


def check_cut(outline, src_cages, dst_cages, result) -> None:
    """Every property cut_ring promises, checked independently of how it got there."""
    sv, dv, faces = result
    outline = np.asarray(outline, dtype=float)
    sizes = [len(c) for c in src_cages]
    n_cage = sum(sizes)
    # Vertices: the cage loops in order, then the outline's points, identical on both sides.
    assert np.array_equal(sv[:n_cage], np.concatenate(src_cages))
    assert np.array_equal(dv[:n_cage], np.concatenate(dst_cages))
    # Then the outline's points (on it, identical on both sides), then interior points (strictly inside).
    on = _distance_to_outline(sv[n_cage:], outline) <= 1e-12 * np.abs(outline).max()
    m = int(np.argmin(on)) if not on.all() else len(on)
    assert not on[m:].any()
    assert np.array_equal(sv[n_cage : n_cage + m], dv[n_cage : n_cage + m])
    ring = sv[n_cage : n_cage + m]
    for side in (sv, dv):
        inner = side[n_cage + m :]
        assert inside_polygon(inner, outline).all()
        assert (_distance_to_outline(inner, outline) > 0).all()
    # The outline's vertices are among its points, in order, and every other point lies on its edges.
    for v in outline:
        assert (np.abs(ring - v).max(axis=1) == 0).any()
    sign = math.copysign(1.0, float(exact_area(src_cages[0])))
    for f in faces:
        assert len(f) >= 3 and len(set(f)) == len(f)
        for side in (sv, dv):
            validate_points(side[list(f)], "face")  # simple, with clearance
            assert math.copysign(1.0, float(exact_area(side[list(f)]))) == sign
    # Points inserted on the outline's edges lie on them (exactly on axis-parallel edges; within
    # rounding of a + t (b - a) on others), so the ring's outer polygon is the outline.
    a, b = outline, np.roll(outline, -1, axis=0)
    axis_parallel = bool(((a[:, 0] == b[:, 0]) | (a[:, 1] == b[:, 1])).all())
    assert exact_area(ring) == exact_area(outline) or not axis_parallel
    # Tiling: faces and cages cover the ring's outer polygon's area exactly, on both sides.
    for side, cages in ((sv, src_cages), (dv, dst_cages)):
        total = sum((abs(exact_area(side[list(f)])) for f in faces), Fraction(0))
        total += sum((abs(exact_area(c)) for c in cages), Fraction(0))
        assert total == abs(exact_area(ring))
    # Every directed edge once; an edge between two faces (or a face and a cage) once each way;
    # the outline's edges once, in the faces' direction.
    directed: dict[tuple[int, int], int] = {}
    loops = [list(f) for f in faces]
    start = 0
    for n in sizes:
        loops.append(list(range(start, start + n)))
        start += n
    for loop in loops:
        for j in range(len(loop)):
            e = (loop[j], loop[(j + 1) % len(loop)])
            directed[e] = directed.get(e, 0) + 1
    assert max(directed.values()) == 1
    m = len(ring)
    outline_edges = {(n_cage + j, n_cage + (j + 1) % m) for j in range(m)}  # the outline's points in order
    if float(exact_area(ring)) * sign < 0:
        outline_edges = {(b, a) for a, b in outline_edges}
    for u, v in directed:
        if (v, u) not in directed:
            assert (u, v) in outline_edges
    assert outline_edges <= set(directed)


def _distance_to_outline(points, outline):
    a, b = outline, np.roll(outline, -1, axis=0)
    d = b - a
    p = np.asarray(points, dtype=float).reshape(-1, 1, 2)
    t = np.clip(((p - a) * d).sum(axis=2) / (d * d).sum(axis=1), 0, 1)
    return np.hypot(*(a + t[..., None] * d - p).transpose(2, 0, 1)).min(axis=1)


def _star(draw, cx, cy, radius, n_min=3, n_max=12, least=0.4, gap=0.3):
    n = draw(st.integers(n_min, n_max))
    gaps = np.array(draw(st.lists(st.floats(gap, 1.0), min_size=n, max_size=n)))
    angles = np.cumsum(gaps) / gaps.sum() * 2 * math.pi
    shape = draw(st.sampled_from(["convex", "star"]))
    radii = np.ones(n) if shape == "convex" else np.array(draw(st.lists(st.floats(least, 1.0), min_size=n, max_size=n)))
    return np.stack([cx + radius * radii * np.cos(angles), cy + radius * radii * np.sin(angles)], axis=1)


@st.composite
def rings(draw):
    """An outline (rectangle, convex or concave), one or two star-shaped cages and their small moves."""
    kind = draw(st.sampled_from(["rectangle", "convex", "concave"]))
    if kind == "rectangle":
        outline = np.array([[0.0, 0.0], [128.0, 0.0], [128.0, 96.0], [0.0, 96.0]])
    else:
        # Every edge at least 0.62 * 0.75 * 80 = 37 px from the centre: room for the cages (35 px out).
        outline = _star(draw, 64.0, 48.0, 80.0, n_min=6, n_max=16, least=0.75 if kind == "concave" else 1.0, gap=0.5)
    count = draw(st.integers(1, 2))
    centres = [(64.0, 48.0)] if count == 1 else [(48.0, 48.0), (80.0, 48.0)]
    radius = 14.0 if count == 1 else 9.0
    src, dst = [], []
    for cx, cy in centres:
        cage = _star(draw, cx, cy, radius)
        # Small moves: the whole cage by up to 3 px, each vertex by up to 15 % of the cage's radius more
        # (large against the cage's pockets: those cuts need interior points).
        shift = np.array(draw(st.tuples(st.floats(-3, 3), st.floats(-3, 3))))
        wobble = 0.15 * radius
        noise = np.array(draw(st.lists(st.floats(-wobble, wobble), min_size=2 * len(cage), max_size=2 * len(cage))))
        src.append(cage)
        dst.append(cage + shift + noise.reshape(-1, 2))
    for c in src + dst:
        try:
            Polygon(c)
        except PolygonError:
            assume(False)
    return outline, src, dst


@settings(max_examples=12, deadline=None)
@given(rings())
def test_random_rings_are_cut_into_faces_simple_on_both_sides(case):
    outline, src, dst = case
    result = cut_ring(outline, src, dst)
    check_cut(outline, src, dst, result)


@pytest.mark.parametrize("count", [1, 2])
def test_rectangle_within_image_gives_few_faces(count):
    outline = outline_polygon("image", (128, 96), [])
    t = np.linspace(0, 2 * math.pi, 11)[:-1]
    cages = [np.c_[40 + 48 * k + 12 * np.cos(t), 48 + 10 * np.sin(t)] for k in range(count)]
    moved = [c + [2.0, -1.5] for c in cages]
    result = cut_ring(outline, cages, moved)
    check_cut(outline, cages, moved, result)
    # Few faces: the ring around k cages needs at least 2 (no face may surround a cage), rarely more than k + 2.
    assert 2 <= len(result[2]) <= count + 2


def test_moves_that_fold_every_triangulation_of_the_boundary_get_interior_points(monkeypatch):
    # Two concave cages whose vertices move by up to 17 % of their size (a case hypothesis found): no
    # triangulation of the cages' and the outline's points alone keeps its orientation on both sides;
    # a mesh with interior points, carried to the target harmonically, does.
    from warpcli.polygon import outline as module

    src = [
        np.array([[55.0, 50.4], [53.7, 52.6], [48.8, 57.0], [46.3, 52.2], [44.9, 52.1], [40.0, 52.1], [43.1, 47.4],
                  [41.2, 44.7], [45.9, 43.1], [49.5, 43.7], [55.4, 43.7], [57.0, 48.0]]),
        np.array([[87.3, 53.2], [80.7, 52.9], [77.8, 50.8], [71.5, 51.0], [75.5, 47.8], [73.5, 42.4], [78.9, 44.6],
                  [81.2, 41.9], [83.5, 41.0], [83.5, 44.8], [84.5, 48.0]]),
    ]  # fmt: skip
    dst = [
        np.array([[56.6, 50.1], [56.2, 49.6], [50.3, 54.7], [49.3, 49.7], [45.6, 49.1], [42.0, 50.4], [46.1, 46.4],
                  [43.4, 43.5], [47.8, 40.5], [52.8, 42.0], [56.3, 42.1], [59.0, 47.0]]),
        np.array([[85.0, 51.1], [78.9, 51.8], [76.9, 48.8], [69.3, 48.8], [72.7, 45.7], [72.6, 38.8], [78.0, 41.3],
                  [79.4, 41.0], [80.6, 38.8], [81.0, 44.0], [82.8, 46.7]]),
    ]  # fmt: skip
    outline = outline_polygon("image", (128, 96), [])
    meshed = []
    real = module._steiner_triangles
    monkeypatch.setattr(module, "_steiner_triangles", lambda *a: meshed.append(a[-1]) or real(*a))
    result = cut_ring(outline, src, dst)
    check_cut(outline, src, dst, result)
    assert meshed  # the boundary's points alone did not do
    assert len(result[2]) <= 4


def test_identity_moves_keep_the_cut_valid_and_clockwise_cages_work():
    outline = [[0.0, 0.0], [50.0, 0.0], [50.0, 40.0], [0.0, 40.0]]
    cage = np.array([[20.0, 15.0], [20.0, 25.0], [30.0, 25.0], [30.0, 15.0]])  # the other orientation
    check_cut(outline, [cage], [cage], cut_ring(outline, [cage], [cage]))


def one_line(err) -> str:
    text = str(err.value)
    assert "\n" not in text
    return text


def test_a_vertex_moved_outside_the_outline_is_named():
    outline = [[0.0, 0.0], [50.0, 0.0], [50.0, 40.0], [0.0, 40.0]]
    cage = np.array([[20.0, 15.0], [30.0, 15.0], [30.0, 25.0], [20.0, 25.0]])
    moved = cage.copy()
    moved[2] = [55.0, 25.0]
    with pytest.raises(PolygonError) as err:
        cut_ring(outline, [cage], [moved], dst_names=["eye.json"])
    assert one_line(err).startswith("eye.json: vertex 2 at (55.0, 25.0) lies outside")


def test_a_cage_crossing_a_concave_outline_is_named():
    # A U-shaped outline; the cage's vertices are inside its two arms, its edge crosses the notch.
    outline = [[0.0, 0.0], [60.0, 0.0], [60.0, 40.0], [40.0, 40.0], [40.0, 10.0], [20.0, 10.0], [20.0, 40.0], [0.0, 40.0]]
    cage = np.array([[5.0, 2.0], [55.0, 2.0], [55.0, 8.0], [5.0, 8.0]])
    moved = cage.copy()
    moved[2:] += [0.0, 10.0]  # the bottom edge now runs through the notch
    with pytest.raises(PolygonError) as err:
        cut_ring(outline, [cage], [moved])
    assert "target cage 0: vertex" in one_line(err) and "crosses" in one_line(err)


def test_cages_overlapping_in_the_target_are_named():
    outline = [[0.0, 0.0], [100.0, 0.0], [100.0, 60.0], [0.0, 60.0]]
    a = np.array([[10.0, 20.0], [30.0, 20.0], [30.0, 40.0], [10.0, 40.0]])
    b = a + [40.0, 0.0]
    with pytest.raises(PolygonError) as err:
        cut_ring(outline, [a, b], [a + [25.0, 0.0], b])
    assert "vertex" in one_line(err) and "crosses" in one_line(err)
    with pytest.raises(PolygonError) as err:  # nested
        cut_ring(outline, [a, b], [a, (a - [20.0, 30.0]) * 0.2 + [20.0, 30.0]])
    assert "lies inside" in one_line(err)


def test_a_vertex_moved_too_far_is_named():
    outline = [[0.0, 0.0], [100.0, 0.0], [100.0, 80.0], [0.0, 80.0]]
    t = np.linspace(0, 2 * math.pi, 9)[:-1]
    cage = np.c_[50 + 20 * np.cos(t), 40 + 15 * np.sin(t)]
    turned = np.c_[50 - 20 * np.cos(t), 40 - 15 * np.sin(t)]  # half a turn: the ring would have to twist
    with pytest.raises(PolygonError) as err:
        cut_ring(outline, [cage], [turned])
    assert one_line(err).startswith("target cage 0: vertex ") and "moved" in one_line(err)


def test_a_cage_running_the_other_way_is_refused():
    outline = [[0.0, 0.0], [100.0, 0.0], [100.0, 60.0], [0.0, 60.0]]
    a = np.array([[10.0, 20.0], [30.0, 20.0], [30.0, 40.0], [10.0, 40.0]])
    with pytest.raises(PolygonError) as err:
        cut_ring(outline, [a, a[::-1] + [40.0, 0.0]], [a, a[::-1] + [40.0, 0.0]])
    assert one_line(err).startswith("source cage 1: vertex 0: the cage runs the other way round")


def test_outline_polygon_margin_and_file(tmp_path):
    cages = [np.array([[10.0, 10.0], [20.0, 10.0], [20.0, 30.0]]), np.array([[12.0, 8.0], [22.0, 12.0], [20.0, 31.0]])]
    box = outline_polygon("5", (25, 100), cages)
    assert box.min(axis=0).tolist() == [5.0, 3.0] and box.max(axis=0).tolist() == [25.0, 36.0]  # clipped at x = 25
    assert signed_sign(box) == signed_sign(cages[0])
    path = tmp_path / "o.json"
    path.write_text("[[0, 0], [40, 0], [40, 40], [0, 40]]")
    assert outline_polygon(str(path), (100, 100), cages).tolist() == [[0, 0], [40, 0], [40, 40], [0, 40]]
    for bad in ("0", "-3", "nan"):
        with pytest.raises(PolygonError):
            outline_polygon(bad, (100, 100), cages)


def signed_sign(points) -> float:
    return math.copysign(1.0, float(exact_area(points)))
