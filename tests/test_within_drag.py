"""A drag within an outline (``warp edit --within``) made fast: its shortcuts agree with the exact paths they skip.

- exact orientation signs: the axis-parallel zeros and the one-triangle form
  (`orient_sign_one`) against rational arithmetic;
- the ring's edge flips (`_repair`, one triangle at a time) against the
  numpy form they replaced, flip for flip;
- a cage map reusing an earlier one's face maps (`build_cage_map(kept=)`)
  against one built afresh, value for value;
- the editor's drag keeping the ring's cut (`PreviewMapper.within_pair`): a
  valid cage mesh on both sides, the command line's cut and messages when the
  pointer is released or the kept cut no longer holds.
"""

from __future__ import annotations

import dataclasses
from fractions import Fraction

import numpy as np
import pytest
from edit_helpers import write_smooth_image
from hypothesis import given, settings
from hypothesis import strategies as st

from warpcli.edit.preview import PreviewMapper
from warpcli.edit.session import EditPaths, EditSession
from warpcli.errors import PolygonError
from warpcli.maps.cage import build_cage_map
from warpcli.options import MapOptions
from warpcli.polygon import Polygon
from warpcli.polygon import outline as outline_module
from warpcli.polygon.outline import outline_polygon
from warpcli.polygon.partition import Partition
from warpcli.polygon.predicates import orient_sign, orient_sign_one
from warpcli.within import within_pair


def exact_sign(a, b, c) -> int:
    f = [Fraction(float(v)) for v in (*a, *b, *c)]
    d = (f[2] - f[0]) * (f[5] - f[1]) - (f[3] - f[1]) * (f[4] - f[0])
    return (d > 0) - (d < 0)


# --- exact signs --------------------------------------------------------------------------------------------

coordinate = st.one_of(
    st.floats(-1e9, 1e9, allow_nan=False),
    st.integers(-50, 50).map(float),  # on a grid: many collinear and axis-parallel triples
    st.floats(-1e-300, 1e-300, allow_nan=False),  # tiny and subnormal: products underflow
    st.sampled_from([0.0, -0.0, 0.1, 0.3, 1e-320, 5e-324, 1e9, 1e9 + 1e-7]),
)
point = st.tuples(coordinate, coordinate)


@st.composite
def triples(draw):
    """Three points, often collinear, axis-parallel or nearly so (the cases the float filter cannot decide)."""
    a, b = draw(point), draw(point)
    kind = draw(st.sampled_from(["free", "axis", "on line", "near line"]))
    if kind == "free":
        c = draw(point)
    elif kind == "axis":  # the same x or the same y as a or b
        a = (a[0], draw(st.sampled_from([a[1], b[1]])))
        c = draw(st.sampled_from([(a[0], draw(coordinate)), (draw(coordinate), a[1]), (b[0], draw(coordinate))]))
    else:
        t = draw(st.floats(-2, 2))
        c = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))  # on the line up to rounding
        if kind == "near line":
            c = (np.nextafter(c[0], np.inf), c[1])
        if not all(np.isfinite(c)):
            c = b
    return a, b, c


@settings(max_examples=100, deadline=None)
@given(triples())
def test_orientation_signs_are_exact_one_at_a_time_and_vectorized(case):
    a, b, c = case
    want = exact_sign(a, b, c)
    assert orient_sign_one(a, b, c) == want
    arrays = [np.array([v]) for v in (*a, *b, *c)]
    assert orient_sign(*arrays)[0] == want


def test_axis_parallel_zeros_in_bulk_are_exact():
    """Many axis-parallel triples at once (the outline's sides): all exactly 0; the others as rationals say."""
    rng = np.random.default_rng(5)
    x = rng.choice([0.0, 1e-310, 3.0, 1e9, -7.5], (400, 3))
    y = rng.choice([0.0, 2.0, 1e-300, -1e9], (400, 3))
    y[:200, 1] = y[:200, 0]  # a and b on one horizontal, or c on a's: half of them exact zeros or not
    x[200:, 2] = x[200:, 0]
    got = orient_sign(x[:, 0], y[:, 0], x[:, 1], y[:, 1], x[:, 2], y[:, 2])
    want = [exact_sign((x[i, 0], y[i, 0]), (x[i, 1], y[i, 1]), (x[i, 2], y[i, 2])) for i in range(400)]
    np.testing.assert_array_equal(got, want)


# --- edge flips ---------------------------------------------------------------------------------------------


def repair_reference(sv, dv, tris, seg):
    """`outline._repair` as it was: a numpy call per triangle, every triangle scanned after every flip."""
    tris = [list(t) for t in tris]
    fixed = {frozenset((int(a), int(b))) for a, b in seg}

    def signs(v, arr):
        a, b, c = v[arr[:, 0]], v[arr[:, 1]], v[arr[:, 2]]
        return orient_sign(a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1])

    def badness(t) -> int:
        arr = np.array([t], dtype=np.intp)
        return int(signs(sv, arr)[0] <= 0) + int(signs(dv, arr)[0] <= 0)

    for _ in range(outline_module.FLIPS_PER_TRIANGLE * len(tris)):
        edges = {}
        for i, t in enumerate(tris):
            for j in range(3):
                edges[(t[j], t[(j + 1) % 3])] = i
        arr = np.array(tris, dtype=np.intp)
        folded = np.flatnonzero((signs(sv, arr) <= 0) | (signs(dv, arr) <= 0))
        if not folded.size:
            break
        flipped = False
        for i in folded:
            t = tris[i]
            for j in range(3):
                a, b, c = t[j], t[(j + 1) % 3], t[(j + 2) % 3]
                other = edges.get((b, a))
                if other is None or frozenset((a, b)) in fixed:
                    continue
                u = tris[other]
                d = u[(u.index(a) + 1) % 3]
                new = ([c, a, d], [d, b, c])
                if badness(new[0]) + badness(new[1]) < badness(t) + badness(u):
                    tris[i], tris[other] = new
                    flipped = True
                    break
            if flipped:
                break
        if not flipped:
            break
    return np.array(tris, dtype=np.intp)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(4, 40), shake=st.sampled_from([0.0, 0.3, 1.0, 3.0]),
       grid=st.booleans())  # fmt: skip
def test_edge_flips_one_triangle_at_a_time_are_the_numpy_ones(seed, n, shake, grid):
    """Random point sets, Delaunay-triangulated, their target shaken until triangles fold: the same flips."""
    import triangle as tr

    rng = np.random.default_rng(seed)
    sv = rng.uniform(0, 10, (n, 2))
    if grid:  # integer points: collinear triples, zero-area triangles on a side
        sv = np.unique(np.round(sv), axis=0)
        if len(sv) < 4:
            return
    t = tr.triangulate({"vertices": sv}, "Q")
    if "triangles" not in t or len(t["triangles"]) < 2:
        return
    sv = np.asarray(t["vertices"], dtype=np.float64)
    tris = np.asarray(t["triangles"], dtype=np.intp)
    dv = sv + rng.normal(0, shake, sv.shape)
    if grid:
        dv = np.round(dv)
    hull = tr.triangulate({"vertices": sv}, "cQ")
    seg = np.asarray(hull.get("segments", np.zeros((0, 2), int)), dtype=np.intp)
    got = outline_module._repair(sv, dv, tris, seg)
    np.testing.assert_array_equal(got, repair_reference(sv, dv, tris, seg))


# --- cage maps reusing face maps ----------------------------------------------------------------------------

CAGE = np.array([[40.0, 30.0], [80.0, 30.0], [88.0, 50.0], [80.0, 66.0], [40.0, 66.0], [32.0, 48.0]])
SIZE = (128, 96)
COARSE = MapOptions(max_area=(40.0, 40.0), grade=False)


def test_a_cage_map_reusing_unmoved_faces_is_the_map_built_afresh():
    """Only the faces at the moved vertex are built again; every value is the fresh map's, bit for bit."""
    src, dst = Polygon(CAGE, name="a"), Polygon(CAGE + [2.0, 1.0], name="b")
    pair = within_pair(src, dst, "image", SIZE)
    region = ((0.0, 0.0) + SIZE, (0.0, 0.0) + SIZE)
    first = build_cage_map(pair.src, pair.dst, COARSE, regions=region)
    moved = np.array(pair.dst.vertices)
    moved[2] += [1.5, -1.0]
    dst2 = Partition(moved, pair.dst.faces, pair.dst.name)
    kept = build_cage_map(pair.src, dst2, COARSE, regions=region, kept=first)
    fresh = build_cage_map(pair.src, dst2, COARSE, regions=region)
    touched = [2 in f for f in pair.dst.faces]
    assert any(touched) and not all(touched)
    for k, (a, b) in enumerate(zip(first.face_maps, kept.face_maps)):
        assert b.phi0 is a.phi0  # the source did not move
        assert (b.phi1 is a.phi1) != touched[k]  # the target's faces at vertex 2 are new, the others kept
    pts = np.random.default_rng(1).uniform((0, 0), SIZE, (3000, 2))
    np.testing.assert_array_equal(kept.inverse(pts), fresh.inverse(pts))
    np.testing.assert_array_equal(kept.forward(pts), fresh.forward(pts))
    assert kept.certified == fresh.certified
    # Other options or regions: nothing is taken from it.
    other = build_cage_map(pair.src, dst2, dataclasses.replace(COARSE, max_area=(30.0, 30.0)), regions=region, kept=first)
    assert not any(m.phi0 is f.phi0 for m, f in zip(other.face_maps, first.face_maps))


# --- moving a cage mesh -------------------------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), count=st.integers(1, 3), scale=st.sampled_from([0.5, 3.0, 12.0, 40.0]),
       rename=st.booleans())  # fmt: skip
def test_a_moved_mesh_is_checked_as_a_new_one(seed, count, scale, rename):
    """`Partition.moved` (unmoved faces not checked again) accepts and refuses what `Partition` does, with the
    same message, and keeps the same polygons."""
    base = within_pair(Polygon(CAGE, name="a"), Polygon(CAGE, name="b"), "image", SIZE).dst
    rng = np.random.default_rng(seed)
    vertices = np.array(base.vertices)
    which = rng.choice(len(CAGE) + 2, count, replace=False)  # cage vertices, or an outline point (index 6, 7)
    vertices[which] += rng.normal(0, scale, (count, 2))
    name = "moved" if rename else None
    try:
        want = Partition(vertices, base.faces, name or base.name)
    except PolygonError as err:
        with pytest.raises(PolygonError) as got:
            base.moved(vertices, name)
        assert str(got.value) == str(err)
        return
    got = base.moved(vertices, name)
    assert got.name == want.name and got.faces == want.faces
    np.testing.assert_array_equal(got.vertices, want.vertices)
    assert not got.vertices.flags.writeable
    np.testing.assert_array_equal(got.loops[0], want.loops[0])
    for a, b in zip((got.outline, *got.face_polygons()), (want.outline, *want.face_polygons())):
        assert a.name == b.name
        np.testing.assert_array_equal(a.points, b.points)


# --- the editor's drag --------------------------------------------------------------------------------------


def assert_valid_pair(pair, src, dst, within):
    """What within_pair promises, checked afresh: both sides valid cage meshes on the command line's outline,
    the cages in place."""
    for mesh, polygon in ((pair.src, src), (pair.dst, dst)):
        again = Partition(np.array(mesh.vertices), mesh.faces, "again")  # every check of a cage mesh
        np.testing.assert_array_equal(again.vertices[: polygon.n], polygon.points)
    np.testing.assert_array_equal(pair.outline, outline_polygon(within, SIZE, [src.points, dst.points]))
    np.testing.assert_array_equal(pair.src.outline.points, pair.dst.outline.points)
    assert set(map(tuple, pair.outline)) <= set(map(tuple, pair.src.outline.points))


@settings(max_examples=8, deadline=None)
@given(steps=st.lists(st.tuples(st.integers(0, 5), st.floats(-4, 4), st.floats(-4, 4)), min_size=1, max_size=4),
       within=st.sampled_from(["image", "10"]), side=st.sampled_from(["src", "dst"]))  # fmt: skip
def test_a_drag_keeps_a_valid_cut_and_the_release_is_the_command_lines(steps, within, side):
    """Moves of any vertex, dragging either side: each pair is a valid cage mesh on both sides (the kept cut or
    within_pair's), or within_pair's own error; released, the pair is within_pair's, face for face."""
    mapper = PreviewMapper()
    polys = {"src": CAGE.copy(), "dst": CAGE + [1.0, 0.5]}
    mapper.within_pair(Polygon(polys["src"], name="a"), Polygon(polys["dst"], name="b"), within, SIZE)
    for vertex, dx, dy in steps:
        polys[side][vertex] += [dx, dy]
        try:
            src, dst = Polygon(polys["src"], name="a"), Polygon(polys["dst"], name="b")
        except PolygonError:
            polys[side][vertex] -= [dx, dy]
            continue
        try:
            pair = mapper.within_pair(src, dst, within, SIZE, side)
        except PolygonError as err:
            # No cut kept: the command line's message.
            with pytest.raises(PolygonError) as fresh:
                within_pair(src, dst, within, SIZE)
            assert str(err) == str(fresh.value)
            continue
        assert_valid_pair(pair, src, dst, within)
    try:
        released = mapper.within_pair(src, dst, within, SIZE, None)
    except PolygonError as err:
        with pytest.raises(PolygonError) as fresh:
            within_pair(src, dst, within, SIZE)
        assert str(err) == str(fresh.value)
        return
    want = within_pair(src, dst, within, SIZE)
    assert released.src.faces == want.src.faces
    np.testing.assert_array_equal(released.src.vertices, want.src.vertices)
    np.testing.assert_array_equal(released.dst.vertices, want.dst.vertices)


@pytest.mark.parametrize("where", [(92.0, 8.0), (86.0, 26.0)])
def test_a_drag_that_breaks_the_kept_cut_cuts_the_ring_anew(where):
    """Vertex 0 dragged across the first cut's edge to the outline's top: the kept cut fails its checks, and
    within_pair cuts the ring anew (92, 8), or says what the command line says (86, 26)."""
    mapper = PreviewMapper()
    src = Polygon(CAGE, name="a")
    first = mapper.within_pair(src, Polygon(CAGE, name="b"), "image", SIZE)
    far = CAGE.copy()
    far[0] = where
    dst = Polygon(far, name="b")
    with pytest.raises(PolygonError):  # the first cut does not hold there
        Partition(np.r_[far, first.dst.vertices[len(far) :]], first.dst.faces)
    try:
        want = within_pair(src, dst, "image", SIZE)
    except PolygonError as err:
        with pytest.raises(PolygonError) as got:
            mapper.within_pair(src, dst, "image", SIZE, "dst")
        assert str(got.value) == str(err)
        return
    got = mapper.within_pair(src, dst, "image", SIZE, "dst")
    assert got.dst.faces == want.dst.faces != first.dst.faces
    np.testing.assert_array_equal(got.dst.vertices, want.dst.vertices)


def test_dragging_an_outermost_vertex_stretches_a_margins_box_and_keeps_the_cut():
    """Within a margin the box follows an outermost vertex: the kept cut's outline points go along, on the new
    box (the command line's outline), both sides valid cage meshes."""
    mapper = PreviewMapper()
    src = Polygon(CAGE, name="a")
    first = mapper.within_pair(src, Polygon(CAGE, name="b"), "10", SIZE)
    moved = CAGE.copy()
    for step in range(1, 4):
        moved[2] = CAGE[2] + [2.0 * step, 1.0 * step]  # the rightmost vertex, further right
        dst = Polygon(moved, name="b")
        pair = mapper.within_pair(src, dst, "10", SIZE, "dst")
        assert pair.src.faces == first.src.faces  # the cut kept
        assert_valid_pair(pair, src, dst, "10")
        x0, y0 = pair.outline.min(axis=0)
        x1, y1 = pair.outline.max(axis=0)
        assert x1 == moved[2, 0] + 10
        ring = pair.dst.outline.points
        on_side = (ring[:, 0] == x0) | (ring[:, 0] == x1) | (ring[:, 1] == y0) | (ring[:, 1] == y1)
        assert on_side.all() and ((ring >= [x0, y0]) & (ring <= [x1, y1])).all()


def test_the_drag_preview_is_the_cage_map_of_its_cut(tmp_path):
    """While dragging, the preview's texture is f^-1 of the cage map of the pair it shows (built afresh here)."""
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, *SIZE)
    session = EditSession(EditPaths.defaults(image))
    options = {"within": "image"}
    session.preview_map({"src": CAGE.tolist(), "dst": (CAGE + 1.0).tolist(), "options": options})
    for step in range(1, 4):
        dst = CAGE + 1.0
        dst[1] += [step, -step * 0.5]
        out = session.preview_map({"src": CAGE.tolist(), "dst": dst.tolist(), "options": options, "drag": "dst"})
        (n,) = np.frombuffer(out[:4], "<u4")
        import json

        header = json.loads(out[4 : 4 + n])
        assert header["ok"], header
        assert header["rebuilt"] == ["target"]  # the source's face maps are all kept
        xyuv = np.frombuffer(out[4 + n : 4 + n + 16 * header["vertices"]], "<f4").reshape(-1, 4).astype(float)
        key, pair, _, _ = session.mapper._within
        np.testing.assert_array_equal(pair.dst.vertices[: len(dst)], dst)
        opts = dataclasses.replace(MapOptions(), max_area=tuple(header["max_area"]), grade=False)
        region = (0.0, 0.0) + SIZE
        fresh = build_cage_map(pair.src, pair.dst, opts, regions=(region, region))
        want = fresh.inverse(xyuv[:, :2])
        found = np.isfinite(want).all(axis=1)
        assert found.mean() > 0.95
        np.testing.assert_allclose(xyuv[found, 2:], want[found], atol=1e-3)
