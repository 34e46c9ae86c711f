"""A retouch within a fixed outline (issue 21, part 2: ``--within``): the cages and the ring as one cage mesh.

Properties checked against what they must be: outside the outline the
output is the input, bit for bit; cages that do not move give the identity;
the face maps meet across every cage edge and cut (FEM, 1e-9 px); fuzzed
cages never fold (det J > 0 at every pixel centre inside the outline,
f(f^-1(y)) = y, and the integral of det J over the outline is its area);
an STMap of the whole retouch reproduces it; what cannot be done is refused
in one line, exit 2, nothing written.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import read_pixels, run_cli, write_png, write_polygon
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from warpcli.errors import PolygonError
from warpcli.grid import inside_polygon, pixel_centres
from warpcli.pipeline import warp_image
from warpcli.polygon import Polygon
from warpcli.polygon.partition import Partition
from warpcli.within import read_cages, within_pair

#: Coarse FEM meshes: the properties hold at any density, and this keeps the tests fast.
COARSE = dict(method="fem", max_area=24.0)
SIZE = 56


def star_cage(rng, centre, radius, n):
    """A star-shaped polygon round ``centre`` (clockwise on screen: angles increasing with y down)."""
    angles = np.sort(rng.uniform(0, 2 * np.pi, n))
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False) * 0.5 + angles * 0.5  # spread out
    r = radius * rng.uniform(0.6, 1.0, n)
    return np.stack([centre[0] + r * np.cos(angles), centre[1] + r * np.sin(angles)], axis=1)


def inside_outline(outline, width, height):
    centres = pixel_centres(width, height)
    return inside_polygon(centres, outline).reshape(height, width)


def _image(rng, channels=1):
    return rng.random((SIZE, SIZE, channels))


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(
    n=st.integers(4, 7), move=st.floats(0.0, 0.35), within=st.sampled_from(["image", "6", "9.5"]),
    seed=st.integers(0, 10**6),
)  # fmt: skip
def test_fuzzed_cages_within_an_outline_never_fold_and_keep_the_input_outside(n, move, within, seed):
    rng = np.random.default_rng(seed)
    src = star_cage(rng, (28.0, 28.0), 12.0, n)
    dst = src + rng.uniform(-move, move, src.shape) * 12.0
    try:
        Polygon(src), Polygon(dst)
        image = _image(rng)
        result = warp_image(image, src, dst, within=within, **COARSE)
    except PolygonError:
        assume(False)
    pair = result.within
    assert result.map.certified
    inside = inside_outline(pair.outline, SIZE, SIZE)
    # Outside the outline: the input's own values, bit for bit.
    assert np.array_equal(result.pixels[~inside], image[~inside])
    # Inside: det J > 0 at every pixel centre, and the map is one-to-one there.
    jac = result.jacobian
    det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
    assert np.isfinite(det[inside]).all() and (det[inside] > 0).all()
    pts = result.inverse_map[inside]
    r, c = np.nonzero(inside)
    back = result.map.forward(pts)
    assert np.abs(back - np.stack([c + 0.5, r + 0.5], axis=1)).max() <= 1e-6
    # The map takes the outline onto itself: the integral of det J over it is its area (a fold counts twice).
    area = abs(Polygon(pair.outline).signed_area)
    assert abs(det[inside].sum() - area) <= 0.08 * area


def test_cages_that_do_not_move_are_the_identity():
    rng = np.random.default_rng(3)
    cages = [star_cage(rng, (16.0, 18.0), 8.0, 5), star_cage(rng, (40.0, 36.0), 9.0, 6)]
    image = _image(rng, 3)
    for within in ("image", "5"):
        near = warp_image(image, cages, cages, within=within, interp="nearest", **COARSE)
        assert np.array_equal(near.pixels, image)
        lin = warp_image(image, cages, cages, within=within, interp="linear", **COARSE)
        assert np.abs(lin.pixels - image).max() <= 1e-9


def _interior_edges(mesh: Partition):
    """Every edge shared by two faces: (a, b, face with a -> b, face with b -> a)."""
    owner = {}
    for k, f in enumerate(mesh.faces):
        for j in range(len(f)):
            owner[(f[j], f[(j + 1) % len(f)])] = k
    return [(a, b, k, owner[(b, a)]) for (a, b), k in owner.items() if (b, a) in owner and a < b]


def test_the_face_maps_meet_across_every_cage_edge_and_cut():
    rng = np.random.default_rng(11)
    src = [star_cage(rng, (16.0, 20.0), 8.0, 5), star_cage(rng, (38.0, 34.0), 9.0, 6)]
    dst = [src[0] + [2.5, -1.5], src[1] + rng.uniform(-2, 2, src[1].shape)]
    result = warp_image(_image(rng), src, dst, within="image", **COARSE)
    pair, fmap = result.within, result.map
    edges = _interior_edges(pair.dst)
    kinds = {"cage": 0, "cut": 0}
    loops = {frozenset((lp[i], lp[(i + 1) % len(lp)])) for lp in pair.cage_loops for i in range(len(lp))}
    for a, b, k, other in edges:
        kinds["cage" if frozenset((a, b)) in loops else "cut"] += 1
        p, q = pair.dst.vertices[a], pair.dst.vertices[b]
        d = q - p
        normal = np.array([-d[1], d[0]]) / np.hypot(*d)
        t = np.linspace(0.05, 0.95, 9)[:, None]
        pts = p + t * d
        if not inside_polygon((pts[4] + 0.01 * normal)[None], pair.dst.face_points(k))[0]:
            normal = -normal
        exact = pair.src.vertices[a] + t * (pair.src.vertices[b] - pair.src.vertices[a])
        for face in (k, other):
            assert np.abs(fmap.face_maps[face].inverse(pts) - exact).max() <= 1e-9
        one = fmap.face_maps[k].inverse(pts + 1e-10 * normal)
        two = fmap.face_maps[other].inverse(pts - 1e-10 * normal)
        assert np.abs(one - two).max() <= 1e-9
    assert kinds["cage"] == sum(len(lp) for lp in pair.cage_loops) and kinds["cut"] == len(pair.cuts) > 0
    # On the outline the map is the identity.
    for i in range(len(pair.outline)):
        a, b = pair.outline[i], pair.outline[(i + 1) % len(pair.outline)]
        pts = a + np.linspace(0, 1, 7)[:, None] * (b - a)
        assert np.abs(fmap.inverse(pts) - pts).max() <= 1e-9


def test_a_cage_mesh_keeps_its_faces_within_the_outline():
    verts = np.array([[18, 18], [28, 18], [38, 18], [18, 34], [28, 34], [38, 34]], dtype=float)
    faces = [[0, 1, 4, 3], [1, 2, 5, 4]]
    src = Partition(verts, faces, "src")
    moved = verts.copy()
    moved[[1, 4]] += [3.0, 1.0]
    pair = within_pair(src, Partition(moved, faces, "dst"), "8", (SIZE, SIZE))
    assert pair.cage_faces == 2 and pair.src.n_faces > 2
    # The cage's faces, reindexed, are the first faces, on both sides, in the same places.
    for k, f in enumerate(faces):
        assert np.array_equal(pair.src.face_points(k), verts[f]) and np.array_equal(pair.dst.face_points(k), moved[f])
    assert np.array_equal(pair.src.outline.points, pair.dst.outline.points)


# ------------------------------------------------------------------ through the CLI


@pytest.fixture
def eyes(tmp_path):
    """An image and two cages in one labelme file per side (they share no vertex: two cages)."""
    rng = np.random.default_rng(7)
    image = write_png(tmp_path / "in.png", (rng.random((SIZE, SIZE, 3)) * 255).astype(np.uint8))
    left = [[10, 14], [22, 14], [22, 26], [10, 26]]
    right = [[32, 14], [44, 14], [44, 26], [32, 26]]
    left_moved = [[10, 14], [25, 12], [22, 26], [10, 26]]
    right_moved = [[32, 14], [44, 14], [46, 29], [32, 26]]

    def labelme(path, polys):
        shapes = [{"label": f"eye{i}", "points": p, "shape_type": "polygon"} for i, p in enumerate(polys)]
        path.write_text(json.dumps({"shapes": shapes}))
        return str(path)

    src = labelme(tmp_path / "src.json", [left, right])
    dst = labelme(tmp_path / "dst.json", [left_moved, right_moved])
    return tmp_path, image, src, dst


def test_two_cages_in_one_outline_report_seams_and_maps(eyes):
    tmp, image, src, dst = eyes
    out = tmp / "out.png"
    code, err = run_cli([image, "--src", src, "--dst", dst, out, "--within", "image", "--max-area", "24",
                         "--report", tmp / "r.json", "--save-map", tmp / "m.exr", "--no-antialias",
                         "--grid", tmp / "g.png", "--heatmap", tmp / "h.png"])  # fmt: skip
    assert code == 0, err
    assert (tmp / "g.png").stat().st_size > 0 and (tmp / "h.png").stat().st_size > 0
    report = json.loads((tmp / "r.json").read_text())
    assert report["certified"] is True
    within = report["within"]
    assert within["cage_faces"] == [0, 1] and len(within["ring_faces"]) >= 1
    assert len(report["faces"]) == 2 + len(within["ring_faces"])
    seams = within["seams"]
    assert seams["values"]["cage_edges_pairs"] > 0 and seams["values"]["cuts_pairs"] > 0
    assert "jacobian" in seams
    # The whole-image map reproduces the retouch (exactly without antialiasing).
    again = tmp / "again.png"
    code, err = run_cli(["apply-map", tmp / "m.exr", image, again])
    assert code == 0, err
    assert np.array_equal(read_pixels(again), read_pixels(out))
    # Strips give the same bytes.
    code, err = run_cli([image, "--src", src, "--dst", dst, tmp / "t.png", "--within", "image", "--max-area", "24",
                         "--no-antialias", "--tiled"])  # fmt: skip
    assert code == 0, err
    assert (tmp / "t.png").read_bytes() == out.read_bytes()


def test_within_a_margin_and_a_file_keep_the_input_outside(eyes):
    tmp, image, src, dst = eyes
    pixels = read_pixels(image)
    outline = write_polygon(tmp / "outline.json", [[4, 6], [52, 4], [50, 40], [6, 42]])
    for within, poly in (("3", [[7, 9], [49, 9], [49, 32], [7, 32]]), (outline, None)):
        out = tmp / "o.png"
        code, err = run_cli([image, "--src", src, "--dst", dst, out, "--within", within, "--max-area", "24"])
        assert code == 0, err
        shape = poly if poly is not None else json.loads((tmp / "outline.json").read_text())
        shape = shape["points"] if isinstance(shape, dict) else shape
        inside = inside_outline(np.array(shape, dtype=float), SIZE, SIZE)
        got = read_pixels(out)
        assert np.array_equal(got[~inside], pixels[~inside])
        assert not np.array_equal(got[inside], pixels[inside])


def test_batches_and_keyframed_sequences_within(eyes):
    tmp, image, src, dst = eyes
    (tmp / "od").mkdir()
    code, err = run_cli([image, "--src", src, "--dst", dst, "--within", "image", "--max-area", "24", "--out-dir", tmp / "od"])
    assert code == 0, err
    code, err = run_cli([image, "--src", src, "--dst", dst, tmp / "single.png", "--within", "image", "--max-area", "24"])
    assert code == 0, err
    assert (tmp / "od" / "in.png").read_bytes() == (tmp / "single.png").read_bytes()
    seq = tmp / "seq"
    seq.mkdir()
    for f in (1, 2):
        (seq / f"f.000{f}.png").write_bytes(open(image, "rb").read())
    cage = [[16, 16], [36, 16], [36, 36], [16, 36]]
    (tmp / "ks.json").write_text(json.dumps({"frames": {"1": cage, "2": cage}}))
    (tmp / "kd.json").write_text(json.dumps({"frames": {"1": cage, "2": [[16, 16], [40, 12], [36, 36], [16, 36]]}}))
    code, err = run_cli([seq / "f.#.png", seq / "o.#.png", "--frames", "1-2", "--src", tmp / "ks.json",
                         "--dst", tmp / "kd.json", "--within", "6", "--max-area", "24"])  # fmt: skip
    assert code == 0, err
    assert np.array_equal(read_pixels(seq / "o.0001.png"), read_pixels(image))  # frame 1 does not move
    assert not np.array_equal(read_pixels(seq / "o.0002.png"), read_pixels(image))


@pytest.mark.parametrize("run", ["image", "report", "grid", "heatmap", "save-map", "save-forward-map", "batch", "points"])
def test_no_output_of_any_run_replaces_the_within_outline_file(eyes, run):
    """The outline file is an input like the polygons: every kind of output naming it is refused
    in one line, exit 2, the file unchanged and nothing written (the report used to replace it)."""
    tmp, image, src, dst = eyes
    outline = write_polygon(tmp / "outline.json", [[4, 6], [52, 4], [50, 40], [6, 42]])
    before = (tmp / "outline.json").read_bytes()
    common = ["--src", src, "--dst", dst, "--within", outline, "--max-area", "24"]
    out = tmp / "o.png"
    if run == "image":
        args = [image, outline, *common]
    elif run in ("report", "grid", "heatmap", "save-map", "save-forward-map"):
        args = [image, out, *common, f"--{run}", outline]
    elif run == "batch":
        args = [image, "--out-dir", tmp, "--out-name", "outline.json", *common]
    else:  # points
        (tmp / "p.json").write_text("[[20, 20]]")
        args = ["points", *common, "--image-size", f"{SIZE}x{SIZE}", tmp / "p.json", outline]
    before_files = sorted(p.name for p in tmp.iterdir())
    code, err = run_cli(args)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, (run, err)
    assert "outline" in err and "input" in err, (run, err)
    assert (tmp / "outline.json").read_bytes() == before
    assert sorted(p.name for p in tmp.iterdir()) == before_files


@pytest.mark.parametrize("sequence", [False, True])
def test_a_within_run_of_images_of_several_sizes_is_refused_before_any_work(eyes, sequence):
    # The outline (the image, a margin clipped to it) is made once, at the first image's size:
    # an image of another size would get another image's outline.
    tmp, image, _, _ = eyes
    other = tmp / "runs"
    other.mkdir()
    write_png(other / "f.0001.png", read_pixels(image))
    write_png(other / "f.0002.png", read_pixels(image)[:40, :50])
    if sequence:
        args = [other / "f.#.png", tmp / "o.#.png", "--frames", "1-2"]
    else:
        (tmp / "od2").mkdir()
        args = [other / "f.0001.png", other / "f.0002.png", "--out-dir", tmp / "od2"]
    cage = write_polygon(tmp / "cage.json", [[16, 16], [36, 16], [36, 36], [16, 36]])
    moved = write_polygon(tmp / "moved.json", [[16, 16], [40, 12], [36, 36], [16, 36]])
    code, err = run_cli([*args, "--src", cage, "--dst", moved, "--within", "image", "--max-area", "24"])
    assert code == 2 and err.count("\n") == 1, err
    assert "f.0002.png: 50x40" in err and "56x56" in err, err
    assert not list(tmp.glob("o.*.png"))
    assert sequence or not list((tmp / "od2").iterdir())


def test_what_within_cannot_take_is_refused_in_one_line(eyes):
    tmp, image, src, dst = eyes
    far = write_polygon(tmp / "far.json", [[10, 14], [22, 14], [22, 26], [10, 70]])
    small = write_polygon(tmp / "small.json", [[12, 16], [40, 16], [40, 24], [12, 24]])
    one = write_polygon(tmp / "one.json", [[10, 14], [22, 14], [22, 26], [10, 26]])
    cases = [
        (["--dst", dst, "--within", "image", "--outside", "background"], "--outside background"),
        (["--dst", dst, "--within", "image", "--size", "40x40"], "--size"),
        (["--dst", dst, "--within", "image", "--feather", "3"], "--feather"),
        (["--dst", dst, "--within", "image", "--vacated", "background"], "--vacated"),
        (["--dst", dst, "--within", "-2"], "margin"),
        (["--dst", dst, "--within", small], "vertex"),
        (["--dst", dst, "--within", "image", "--save-theta", tmp / "t.json"], "Theta"),
        (["--dst", one, "--within", "image"], "cage"),
    ]
    for extra, words in cases:
        out = tmp / "never.png"
        code, err = run_cli([image, "--src", src, out, "--max-area", "24", *extra])
        assert code == 2, (extra, err)
        assert words in err and err.count("\n") == 1, err
        assert not out.exists()
    code, err = run_cli([image, "--src", one, "--dst", far, tmp / "never.png", "--within", "image"])
    assert code == 2 and "vertex 3" in err and err.count("\n") == 1, err
    assert not (tmp / "never.png").exists()


def test_several_cages_read_from_each_form(tmp_path):
    a = [[10, 10], [20, 10], [20, 20], [10, 20]]
    b = [[30, 10], [40, 10], [40, 20], [30, 20]]
    c = [[20, 10], [30, 10], [30, 20], [20, 20]]  # shares an edge with a and with b
    (tmp_path / "cages.json").write_text(json.dumps({"cages": [a, {"points": b}]}))
    got = read_cages(tmp_path / "cages.json")
    assert [type(x).__name__ for x in got] == ["Polygon", "Polygon"]
    feature = lambda p: {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [p + [p[0]]]}}  # noqa: E731
    (tmp_path / "two.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": [feature(a), feature(b)]}))
    assert len(read_cages(tmp_path / "two.geojson")) == 2
    (tmp_path / "mesh.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": [feature(p) for p in (a, c, b)]}))
    (mesh,) = read_cages(tmp_path / "mesh.geojson")
    assert isinstance(mesh, Partition) and mesh.n_faces == 3
    assert len(read_cages(write_polygon(tmp_path / "one.json", a))) == 1


@pytest.mark.parametrize("method", ["bem", "mfs"])
def test_every_method_within_an_outline(method):
    rng = np.random.default_rng(2)
    image = _image(rng)
    cage = [[16, 16], [30, 16], [30, 30], [16, 30]]
    moved = [[16, 16], [33, 14], [30, 30], [16, 30]]
    result = warp_image(image, cage, moved, within="6", method=method)
    assert result.map.certified
    inside = inside_outline(result.within.outline, SIZE, SIZE)
    assert np.array_equal(result.pixels[~inside], image[~inside])
    jac = result.jacobian[inside]
    assert (jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0] > 0).all()


def test_several_cages_keyframed_in_a_sequence_are_each_frame_s_single_warp(eyes):
    # {"frames": {F: {"cages": [...]}}}: both eyes animated at once. Frame 1 does not move (the
    # identity: the input's pixels); frame 3 is its keyframe's single warp; frame 2, halfway, is
    # the single warp of the cages blended vertex by vertex.
    tmp, image, _, _ = eyes
    left = np.array([[10, 14], [22, 14], [22, 26], [10, 26]], dtype=float)
    right = np.array([[32, 14], [44, 14], [44, 26], [32, 26]], dtype=float)
    left_to = left + [[0, 0], [4, -2], [0, 0], [0, 0]]
    right_to = right + [[0, 0], [0, 0], [2, 4], [0, 0]]

    def cages(*polys):
        return {"cages": [p.tolist() for p in polys]}

    (tmp / "ks.json").write_text(json.dumps({"frames": {"1": cages(left, right), "3": cages(left, right)}}))
    (tmp / "kd.json").write_text(json.dumps({"frames": {"1": cages(left, right), "3": cages(left_to, right_to)}}))
    seq = tmp / "seq"
    seq.mkdir()
    for f in (1, 2, 3):
        (seq / f"f.000{f}.png").write_bytes(open(image, "rb").read())  # noqa: SIM115
    common = ["--within", "image", "--max-area", "24"]
    code, err = run_cli([seq / "f.#.png", seq / "o.#.png", "--frames", "1-3", "--src", tmp / "ks.json", "--dst", tmp / "kd.json", *common])
    assert code == 0, err
    assert np.array_equal(read_pixels(seq / "o.0001.png"), read_pixels(image))
    for f, t in ((2, 0.5), (3, 1.0)):
        (tmp / "s.json").write_text(json.dumps(cages(left, right)))
        (tmp / "d.json").write_text(json.dumps(cages(left + t * (left_to - left), right + t * (right_to - right))))
        code, err = run_cli([image, "--src", tmp / "s.json", "--dst", tmp / "d.json", tmp / f"one{f}.png", *common])
        assert code == 0, err
        assert (tmp / f"one{f}.png").read_bytes() == (seq / f"o.000{f}.png").read_bytes()
    # Without an outline, several cages are refused in one line; a cage turned over between keyframes too.
    code, err = run_cli([seq / "f.#.png", seq / "n.#.png", "--frames", "1-3", "--src", tmp / "ks.json", "--dst", tmp / "kd.json"])
    assert code == 2 and "--within" in err and err.count("\n") == 1, err
    (tmp / "kx.json").write_text(json.dumps({"frames": {"1": cages(left, right), "3": cages(left, right[::-1] + [0, 0.5])}}))
    code, err = run_cli([seq / "f.#.png", seq / "n.#.png", "--frames", "1-3", "--src", tmp / "ks.json", "--dst", tmp / "kx.json", *common])
    assert code == 2 and "cage 1" in err and err.count("\n") == 1, err
    assert not list(seq.glob("n.*"))


@pytest.mark.parametrize("seed", range(4))
def test_labels_and_points_follow_a_retouch_as_its_pixels_do(seed):
    # A retouch's result: warp_labels used to leave background outside the outline (8.7 % of a
    # photograph's labels kept) and warp_points NaN there, where the image keeps the input and
    # `warp points --within` keeps the points. Now labels equal the nearest warp of the same
    # array pixel for pixel, and points outside the outline stay put.
    from warpcli.annotations import warp_labels, warp_points

    rng = np.random.default_rng(seed)
    src = star_cage(rng, (28.0, 28.0), 12.0, 5)
    dst = src + rng.uniform(-0.3, 0.3, src.shape) * 12.0
    ids = rng.integers(0, 2**40, (SIZE, SIZE), dtype=np.int64)
    try:
        result = warp_image(ids[..., None].astype(np.float64), src, dst, within="6", interp="nearest", **COARSE)
    except PolygonError:
        pytest.skip("a generated cage the validation refuses")
    labels = warp_labels(ids, result)
    assert np.array_equal(labels, result.pixels[..., 0].astype(np.int64))
    inside = inside_outline(result.within.outline, SIZE, SIZE)
    assert np.array_equal(labels[~inside], ids[~inside]) and (~inside).sum() > 0
    pts = rng.uniform(0, SIZE, (400, 2))
    moved = warp_points(pts, fmap=result)
    assert moved.inside.all()
    mapped = result.map.forward(pts)
    has = np.isfinite(mapped[:, 0])
    assert np.array_equal(moved.points[has], mapped[has]) and np.array_equal(moved.points[~has], pts[~has])
    assert (~has).sum() > 0


def test_warp_labels_with_within_on_the_command_line(tmp_path):
    rng = np.random.default_rng(9)
    ids = rng.integers(0, 65535, (SIZE, SIZE), dtype=np.uint16)
    write_png(tmp_path / "lab.png", ids)
    src = star_cage(rng, (28.0, 28.0), 12.0, 5)
    write_polygon(tmp_path / "a.json", src)
    write_polygon(tmp_path / "b.json", src * 1.05 - 1.4)
    code, err = run_cli([tmp_path / "lab.png", "--src", tmp_path / "a.json", "--dst", tmp_path / "b.json", "--within", "6",
                         "--interp", "nearest", "--labels", tmp_path / "lab.png", tmp_path / "lab_out.png", tmp_path / "out.png"])  # fmt: skip
    assert code == 0, err
    assert np.array_equal(read_pixels(tmp_path / "lab_out.png"), read_pixels(tmp_path / "out.png"))
    # Plain --outside input still refuses labels (they would stay where the polygon moved from).
    code, err = run_cli([tmp_path / "lab.png", "--src", tmp_path / "a.json", "--dst", tmp_path / "b.json", "--outside", "input",
                         "--labels", tmp_path / "lab.png", tmp_path / "lab2.png", tmp_path / "out2.png"])  # fmt: skip
    assert code == 2 and "not with --outside input" in err, err
