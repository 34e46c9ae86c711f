"""Cage meshes (issue 21, parts 1 and 5): planar partitions, one map per face, glued into one bijection.

The properties are checked against what they must be, not against outputs
of the code: a partition's faces tile its outline; FEM's face maps meet on
every shared edge to rounding; dst == src is the identity; a triangle mesh
is scikit-image's PiecewiseAffineTransform; fuzzed meshes never fold
(Jacobians' signs, and f(f^-1(y)) = y on every pixel centre).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import read_pixels, run_cli, write_png, write_polygon
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from warpcli.errors import PolygonError
from warpcli.grid import inside_polygon, pixel_centres
from warpcli.maps.cage import build_cage_map, face_labels
from warpcli.options import MapOptions
from warpcli.polygon import signed_area
from warpcli.polygon.partition import Partition, read_shape, validate_pair, welded

#: Coarse FEM meshes: the properties tested hold at any density, and this keeps the tests fast.
COARSE = MapOptions(max_area=16.0)


def grid_mesh(n: int, cell: float, origin: float = 4.0, merges: int = 0, rng=None):
    """An n x n grid of quadrilateral cells (clockwise on screen), with ``merges`` L-shaped
    triples of cells merged into one non-convex hexagon (octagon, with its mid-edge vertices)."""
    verts = np.array([[origin + x * cell, origin + y * cell] for y in range(n + 1) for x in range(n + 1)])
    cells = {(x, y): [y * (n + 1) + x, y * (n + 1) + x + 1, (y + 1) * (n + 1) + x + 1, (y + 1) * (n + 1) + x]
             for y in range(n) for x in range(n)}  # fmt: skip
    faces = []
    taken: set = set()
    rng = rng or np.random.default_rng(0)
    for _ in range(merges if n > 1 else 0):
        x, y = (int(v) for v in rng.integers(0, n - 1, 2))
        trio = [(x, y), (x + 1, y), (x, y + 1)]
        if any(c in taken for c in trio):
            continue
        taken.update(trio)
        faces.append(_merge([cells[c] for c in trio]))
    faces += [cells[c] for c in sorted(cells, key=lambda c: (c[1], c[0])) if c not in taken]
    return verts, faces


def _merge(quads):
    """The boundary loop of adjacent faces (their edges minus the shared ones)."""
    edges = {(f[j], f[(j + 1) % len(f)]) for f in quads for j in range(len(f))}
    nxt = {a: b for a, b in edges if (b, a) not in edges}
    start = min(nxt)
    loop = [start]
    while nxt[loop[-1]] != start:
        loop.append(nxt[loop[-1]])
    return loop


def interior(verts, n):
    return [i for i in range(len(verts)) if 0 < i % (n + 1) < n and 0 < i // (n + 1) < n]


# ------------------------------------------------------------------ the partition


@settings(max_examples=15, deadline=None)
@given(n=st.integers(1, 4), jitter=st.floats(0.0, 0.3), merges=st.integers(0, 2), seed=st.integers(0, 10**6))
def test_generated_partitions_tile_their_outline(n, jitter, merges, seed):
    rng = np.random.default_rng(seed)
    verts, faces = grid_mesh(n, 10.0, merges=merges, rng=rng)
    inner = interior(verts, n)
    verts[inner] += rng.uniform(-jitter, jitter, (len(inner), 2)) * 10.0
    mesh = Partition(verts, faces, "m.json")
    # The faces' areas add up to the outline's (a partition), all of one sign.
    areas = [signed_area(mesh.face_points(k)) for k in range(mesh.n_faces)]
    assert all(a > 0 for a in areas)
    assert sum(areas) == pytest.approx(mesh.outline.signed_area, rel=1e-12)
    # Every pixel centre inside the outline is in exactly one face; none outside.
    w = h = int(10 * n + 8)
    labels = face_labels(mesh, w, h, (0, h), (0, w))
    centres = pixel_centres(w, h)
    inside = inside_polygon(centres, mesh.outline.points).reshape(h, w)
    assert np.array_equal(labels >= 0, inside)
    for k in range(mesh.n_faces):
        own = inside_polygon(centres, mesh.face_points(k)).reshape(h, w)
        assert np.array_equal(labels == k, own)


def test_centres_on_shared_edges_go_to_exactly_one_face():
    # Vertices on pixel centres: whole rows and columns of centres lie on shared edges.
    verts, faces = grid_mesh(4, 6.0, origin=2.5)
    mesh = Partition(verts, faces)
    labels = face_labels(mesh, 32, 32, (0, 32), (0, 32))
    # Half-open spans [left, right), rows half-open in y: the outline's
    # left and top edges' centres are in, its right and bottom edges' out.
    expected = np.zeros((32, 32), dtype=bool)
    expected[2:26, 2:26] = True
    assert np.array_equal(labels >= 0, expected)
    # Each interior edge's centres go to the face right of / below it: 6 x 6 centres per face.
    assert np.bincount(labels[labels >= 0]).tolist() == [36] * 16


def _fails(vertices, faces, *words):
    with pytest.raises(PolygonError) as err:
        Partition(np.asarray(vertices, dtype=float), faces, "bad.json")
    message = str(err.value)
    assert "\n" not in message and message.startswith("bad.json: ")
    for word in words:
        assert word in message, message
    return message


def test_invalid_partitions_are_refused_naming_the_face_or_vertex():
    verts, faces = grid_mesh(2, 10.0)  # faces 0..3, vertex 4 in the middle
    reversed_face = [faces[0], faces[1], faces[2], faces[3][::-1]]
    _fails(verts, reversed_face, "faces", "both run along the edge")
    apart = [[0, 0], [10, 0], [0, 10], [20, 20], [30, 20], [20, 30]]
    _fails(apart, [[0, 1, 2], [3, 4, 5]], "separate pieces", "face 1")
    _fails(verts, faces + [[0, 1, 9]], "names vertex 9")
    _fails(verts, [faces[0], faces[1], [3, 4, 6]], "vertex 7 belongs to no face")
    _fails(verts, [faces[0], faces[3]], "vertex 2 belongs to no face")
    _fails(verts, [[0, 1, 1, 3]] + faces[1:], "face 0 passes through vertex 1 twice")
    # Two triangles meeting at one vertex only: the outline passes through it twice.
    tri = [[0, 0], [10, 0], [5, 5], [10, 10], [0, 10]]
    _fails(tri, [[0, 1, 2], [2, 3, 4]], "vertex 2 twice")
    # A ring of four quadrilaterals round a hole.
    ring = [[0, 0], [30, 0], [30, 30], [0, 30], [10, 10], [20, 10], [20, 20], [10, 20]]
    _fails(ring, [[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]], "hole")
    # Moving the middle vertex out of the square flips the faces next to it.
    moved = verts.copy()
    moved[4] = [30.0, 30.0]
    message = _fails(moved, faces, "flipped over")
    k = int(message.split("face ")[1].split(" ")[0])
    assert signed_area(moved[faces[k]]) < 0  # the face named is flipped indeed


def test_validate_pair_names_the_face():
    verts, faces = grid_mesh(2, 10.0)
    src = Partition(verts, faces, "src.json")
    other = Partition(verts, [faces[0], faces[1], faces[2], faces[3][1:] + faces[3][:1]], "dst.json")
    with pytest.raises(PolygonError, match=r"^dst.json: face 3 is \[5, 8, 7, 4\] but src.json's face 3"):
        validate_pair(src, other)
    fewer = Partition(verts[:6], [faces[0], faces[1]], "dst.json")
    with pytest.raises(PolygonError, match="^dst.json: cage mesh has 6 vertices but src.json has 9"):
        validate_pair(src, fewer)


def test_labelme_and_geojson_polygons_are_welded(tmp_path):
    verts, faces = grid_mesh(2, 10.0)
    rings = [(verts[f] + np.where(np.arange(len(f))[:, None] == 0, 0.004, 0.0)).tolist() for f in faces]
    rings[2] = rings[2][::-1]  # drawn the other way round: turned like the first
    labelme = tmp_path / "cage_labelme.json"
    labelme.write_text(json.dumps({"shapes": [{"label": f"f{k}", "points": r} for k, r in enumerate(rings)]}))
    geo = tmp_path / "cage.geojson"
    geo.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [r + [r[0]]]}}
        for r in rings]}))  # fmt: skip
    for path in (labelme, geo):
        mesh = read_shape(path)
        assert isinstance(mesh, Partition) and mesh.n == 9 and mesh.n_faces == 4
        gaps = np.hypot(*(mesh.vertices[None, :, :] - verts[:, None, :]).transpose(2, 0, 1)).min(axis=1)
        assert gaps.max() <= 0.01
    # A label still picks one polygon.
    assert not isinstance(read_shape(labelme, "f1"), Partition)
    # Farther apart than the tolerance: not welded, and the faces then do not join.
    with pytest.raises(PolygonError, match="separate pieces|belongs to no face|outline"):
        welded([verts[f] + 0.05 * k for k, f in enumerate(faces)], "far.json")


# ------------------------------------------------------------------ the map


def _skewed(n=3, seed=1, jitter=0.3, cell=12.0):
    rng = np.random.default_rng(seed)
    verts, faces = grid_mesh(n, cell, merges=1, rng=rng)
    src = Partition(verts, faces, "src.json")
    moved = verts.copy()
    inner = interior(verts, n)
    moved[inner] += rng.uniform(-jitter, jitter, (len(inner), 2)) * cell
    return src, Partition(moved, faces, "dst.json")


def _shared_edges(mesh):
    """(a, b, k, other): each interior edge once, a -> b in face k, b -> a in face ``other``."""
    where = {}
    for k, f in enumerate(mesh.faces):
        for j in range(len(f)):
            where[(f[j], f[(j + 1) % len(f)])] = k
    return [(a, b, k, where[(b, a)]) for (a, b), k in where.items() if where.get((b, a), -1) > k]


def _across(mesh, a, b, k):
    """Points along edge a -> b and the unit normal pointing into face k."""
    p, q = mesh.vertices[a], mesh.vertices[b]
    d = q - p
    normal = np.array([-d[1], d[0]]) / np.hypot(*d)
    pts = p + np.linspace(0.05, 0.95, 13)[:, None] * d
    if not inside_polygon((pts[6] + 0.05 * normal)[None], mesh.face_points(k))[0]:
        normal = -normal
    return pts, normal


def edge_jump(fmap, mesh, delta=0.01):
    """The largest jump of f^-1 across the shared edges of ``mesh``: each face's limit at the
    edge, extrapolated from points delta and 2 delta inside it (to O(delta^2) for smooth maps)."""
    worst = 0.0
    for a, b, k, other in _shared_edges(mesh):
        pts, normal = _across(mesh, a, b, k)
        limits = []
        for face, s in ((k, 1.0), (other, -1.0)):
            near = fmap.face_maps[face].inverse(pts + s * delta * normal)
            far = fmap.face_maps[face].inverse(pts + s * 2 * delta * normal)
            limits.append(2 * near - far)
        worst = max(worst, float(np.abs(limits[0] - limits[1]).max()))
    return worst


def test_fem_faces_meet_on_every_shared_edge():
    src, dst = _skewed()
    fmap = build_cage_map(src, dst, COARSE)
    for a, b, k, other in _shared_edges(dst):
        pts, normal = _across(dst, a, b, k)
        # On the edge both faces' maps give the source edge's point of the same parameter...
        t = np.linspace(0.05, 0.95, 13)[:, None]
        exact = src.vertices[a] + t * (src.vertices[b] - src.vertices[a])
        for face in (k, other):
            assert np.abs(fmap.face_maps[face].inverse(pts) - exact).max() <= 1e-9
        # ... and 1e-10 px to either side of it, the two faces' values differ by less than 1e-9 px.
        one = fmap.face_maps[k].inverse(pts + 1e-10 * normal)
        two = fmap.face_maps[other].inverse(pts - 1e-10 * normal)
        assert np.abs(one - two).max() <= 1e-9
    # Vertices go to vertices, through whichever face holds them (points API).
    assert np.abs(fmap.forward(src.vertices) - dst.vertices).max() <= 1e-9
    assert np.abs(fmap.inverse(dst.vertices) - src.vertices).max() <= 1e-9
    # Along each edge of the outline the map is linear too: vertex to vertex, parameter to parameter.
    t = np.linspace(0, 1, 7)
    for i in range(dst.outline.n):
        got = fmap.inverse_boundary(np.full(7, i), t)
        a, b = src.outline.points[i], src.outline.points[(i + 1) % src.outline.n]
        assert np.allclose(got, a + t[:, None] * (b - a), atol=1e-9)


@pytest.mark.parametrize("method, bound", [("bem", 2e-3), ("mfs", 5e-3)])
def test_meshless_faces_meet_to_the_accuracy_of_their_fit(method, bound):
    # Measured on this mesh with 96 nodes per face: BEM 5.6e-4 px, MFS 1.6e-3 px; with the
    # default nodes both 1e-4 px (the boundary fit's error; docs/cages.md). FEM's: none.
    src, dst = _skewed(n=2)
    # (check=False: the sampled certificates cost seconds and are not what is tested here.)
    fmap = build_cage_map(src, dst, MapOptions(method=method, nodes=96, check=False))
    assert edge_jump(fmap, dst) <= bound


def test_a_mesh_that_does_not_move_is_the_identity():
    src, _ = _skewed()
    fmap = build_cage_map(src, src, COARSE)
    pull = fmap.pull_back(48, 48, jacobian=True)
    pts = pull.full_points()
    inside = np.isfinite(pts[..., 0])
    assert inside.sum() >= 0.95 * abs(src.outline.signed_area)
    centres = pixel_centres(48, 48).reshape(48, 48, 2)
    assert np.abs(pts[inside] - centres[inside]).max() <= 1e-9
    jac = pull.spread(pull.jacobian)[inside]
    assert np.abs(jac - np.eye(2)).max() <= 1e-9


def _delaunay_pair(seed):
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    g = np.array([[x, y] for y in np.linspace(6, 58, 3) for x in np.linspace(6, 58, 4)])
    inner = [5, 6]
    g[inner] += rng.uniform(-5, 5, (2, 2))
    faces = Delaunay(g).simplices.tolist()
    dst = Partition(g, [f if signed_area(g[f]) > 0 else f[::-1] for f in faces], "dst.json")
    moved = g.copy()
    moved[inner] += rng.uniform(-4, 4, (2, 2))
    return Partition(moved, dst.faces, "src.json"), dst


def piecewise_affine(src, dst):
    """scikit-image's PiecewiseAffineTransform estimated from src to dst (before and after 0.26's API)."""
    from skimage.transform import PiecewiseAffineTransform

    make = getattr(PiecewiseAffineTransform, "from_estimate", None)
    if make is not None:
        tform = make(src, dst)
    else:
        tform = PiecewiseAffineTransform()
        tform.estimate(src, dst)
    assert tform
    return tform


@pytest.mark.parametrize("seed", [3])
def test_a_triangle_mesh_is_piecewise_affine(seed):
    from skimage.transform import warp

    src, dst = _delaunay_pair(seed)
    fmap = build_cage_map(src, dst, MapOptions(max_area=1e6))
    # scikit-image triangulates its first argument (here dst) by Delaunay: the same triangles.
    tform = piecewise_affine(dst.vertices, src.vertices)
    pull = fmap.pull_back(64, 64, jacobian=False)
    ours = pull.full_points()
    centres = pixel_centres(64, 64)
    theirs = tform(centres).reshape(64, 64, 2)
    both = np.isfinite(ours[..., 0]) & (theirs[..., 0] >= 0)
    assert both.sum() > 0.9 * abs(dst.outline.signed_area)
    assert np.abs(ours[both] - theirs[both]).max() <= 1e-9
    # And the image: scikit-image's warp (pixel centres at integers) against ours, bilinear.
    rng = np.random.default_rng(seed)
    image = rng.random((64, 64))
    shifted = piecewise_affine(dst.vertices - 0.5, src.vertices - 0.5)
    expected = warp(image, shifted, order=1, cval=np.nan)
    from warpcli import warp_image

    got = warp_image(image, src, dst, interp="linear", antialias=False, warp_map=fmap).pixels[..., 0]
    inner = both & np.isfinite(expected)
    inner[[0, -1], :] = inner[:, [0, -1]] = False
    assert np.abs(got[inner] - expected[inner]).max() <= 1e-6


@pytest.mark.parametrize("seed", [3, 8])
def test_a_triangle_mesh_that_folds_is_refused_naming_the_face(seed):
    _, dst = _delaunay_pair(seed)
    for vertex in (5, 6):  # the interior vertices
        for f in (list(face) for face in dst.faces if vertex in face):
            # The vertex reflected through the midpoint of the triangle's far edge: that triangle flips.
            v = dst.vertices.copy()
            a, b = (x for x in f if x != vertex)
            v[vertex] = v[a] + v[b] - v[vertex]
            with pytest.raises(PolygonError) as err:
                Partition(v, dst.faces, "dst.json")
            message = str(err.value)
            assert message.startswith("dst.json: face ") and "flipped over" in message and "\n" not in message
            named = int(message.split("face ")[1].split(" ")[0])
            assert signed_area(v[list(dst.faces[named])]) < 0  # the face named is flipped indeed
            assert signed_area(v[f]) < 0  # and so is the one reflected


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(n=st.integers(2, 3), jitter=st.floats(0.05, 0.3), merges=st.integers(0, 1), seed=st.integers(0, 10**6))
def test_fuzzed_cage_meshes_never_fold(n, jitter, merges, seed):
    rng = np.random.default_rng(seed)
    cell = 40.0 / n
    verts, faces = grid_mesh(n, cell, merges=merges, rng=rng)
    inner = interior(verts, n)
    a, b = verts.copy(), verts.copy()
    a[inner] += rng.uniform(-jitter, jitter, (len(inner), 2)) * cell
    b[inner] += rng.uniform(-jitter, jitter, (len(inner), 2)) * cell
    try:
        src, dst = Partition(a, faces, "src.json"), Partition(b, faces, "dst.json")
    except PolygonError:
        assume(False)
    fmap = build_cage_map(src, dst, COARSE)
    assert fmap.certified
    pull = fmap.pull_back(48, 48, jacobian=True)
    ok = np.isfinite(pull.points[..., 0])
    jac = pull.jacobian[ok]
    det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
    assert (det > 0).all()
    # f(f^-1(y)) = y on every pixel centre the map covers: f^-1 is one-to-one there.
    r, c = np.nonzero(ok)
    centres = np.stack([c + pull.origin[1] + 0.5, r + pull.origin[0] + 0.5], axis=1)
    back = fmap.forward(pull.points[ok])
    assert np.abs(back - centres).max() <= 1e-6


# ------------------------------------------------------------------ through the CLI


def _write_mesh(path, mesh):
    path.write_text(json.dumps({"vertices": mesh.vertices.tolist(), "faces": [list(f) for f in mesh.faces]}))
    return str(path)


@pytest.fixture
def files(tmp_path):
    rng = np.random.default_rng(5)
    image = write_png(tmp_path / "in.png", (rng.random((48, 48, 3)) * 255).astype(np.uint8))
    src, dst = _skewed(n=2, cell=18.0)
    return tmp_path, image, _write_mesh(tmp_path / "src.json", src), _write_mesh(tmp_path / "dst.json", dst), dst


def test_warp_a_cage_mesh_with_report_figures_and_maps(files):
    tmp, image, src, dst, dst_mesh = files
    out = tmp / "out.png"
    code, err = run_cli([image, "--src", src, "--dst", dst, out, "--max-area", "16", "--report", tmp / "r.json",
                         "--grid", tmp / "g.png", "--heatmap", tmp / "h.png", "--save-map", tmp / "m.exr",
                         "--save-forward-map", tmp / "f.exr"])  # fmt: skip
    assert code == 0, err
    report = json.loads((tmp / "r.json").read_text())
    assert report["certified"] is True and report["flipped_triangles"] == 0
    assert [f["face"] for f in report["faces"]] == list(range(report["cage_faces"]))
    assert sum(f["pixels"] for f in report["faces"]) >= 0.9 * abs(dst_mesh.outline.signed_area)
    assert all(f["certified"] and f["min_jacobian_det"] > 0 for f in report["faces"])
    for name in ("g.png", "h.png", "m.exr", "f.exr"):
        assert (tmp / name).exists()
    # In strips: the same bytes.
    code, err = run_cli([image, "--src", src, "--dst", dst, tmp / "tiled.png", "--max-area", "16", "--tiled"])
    assert code == 0, err
    assert (tmp / "tiled.png").read_bytes() == out.read_bytes()


def test_a_one_face_mesh_is_the_polygon_warp(files):
    tmp, image, _, _, _ = files
    a = [[5.0, 6.0], [40.0, 4.0], [43.0, 40.0], [8.0, 38.0]]
    b = [[8.0, 4.0], [44.0, 9.0], [36.0, 44.0], [4.0, 33.0]]
    for name, pts in (("a", a), ("b", b)):
        write_polygon(tmp / f"{name}.json", pts)
        (tmp / f"{name}_mesh.json").write_text(json.dumps({"vertices": pts, "faces": [[0, 1, 2, 3]]}))
    assert run_cli([image, "--src", tmp / "a.json", "--dst", tmp / "b.json", tmp / "p.png"])[0] == 0
    assert run_cli([image, "--src", tmp / "a_mesh.json", "--dst", tmp / "b_mesh.json", tmp / "c.png"])[0] == 0
    assert (tmp / "p.png").read_bytes() == (tmp / "c.png").read_bytes()


def test_a_keyframed_cage_mesh(files):
    tmp, image, src, dst, _ = files
    keys = tmp / "anim.json"
    keys.write_text(json.dumps({"frames": {"1": json.loads(Path(src).read_text()), "3": json.loads(Path(dst).read_text())}}))
    code, err = run_cli([image, "--src", src, "--dst", keys, tmp / "k.png", "--frame", "3", "--max-area", "16"])
    assert code == 0, err
    assert run_cli([image, "--src", src, "--dst", dst, tmp / "d.png", "--max-area", "16"])[0] == 0
    assert (tmp / "k.png").read_bytes() == (tmp / "d.png").read_bytes()
    assert run_cli([image, "--src", src, "--dst", keys, tmp / "k2.png", "--frame", "2", "--max-area", "16"])[0] == 0


def test_what_a_cage_mesh_cannot_take_is_refused_in_one_line(files, tmp_path):
    tmp, image, src, dst, dst_mesh = files
    folded = dst_mesh.vertices.copy()
    folded[4] = [60.0, 60.0]
    bad = tmp / "folded.json"
    bad.write_text(json.dumps({"vertices": folded.tolist(), "faces": [list(f) for f in dst_mesh.faces]}))
    poly = write_polygon(tmp / "poly.json", [[5, 5], [40, 5], [40, 40]])
    cases = [
        (["--dst", bad], "folded.json: "),
        (["--dst", poly], "holds one polygon but"),
        (["--dst", dst, "--conditions", "mixed"], "mixed boundary conditions"),
        (["--dst", dst, "--boundary", "quadratic"], "same boundary behaviour"),
        (["--dst", dst, "--save-theta", tmp / "t.json"], "one per face"),
    ]
    for extra, words in cases:
        out = tmp / "never.png"
        code, err = run_cli([image, "--src", src, out, *extra])
        assert code == 2, err
        assert words in err and err.count("\n") == 1, err
        assert not out.exists()


def test_the_editor_refuses_a_cage_mesh_in_one_line(files):
    from warpcli.edit.session import EditSession

    _, _, src, _, _ = files
    with pytest.raises(PolygonError, match=r"^.*src.json: holds a cage mesh \(2 faces\); warp edit draws one polygon"):
        EditSession._existing(src)
    with pytest.raises(PolygonError, match="holds a cage mesh"):
        EditSession.load({"name": "src.json", "text": Path(src).read_text()})


def test_keypoints_through_a_cage_mesh(files):
    from warpcli import warp_points

    _, _, src, dst, dst_mesh = files
    src_mesh = read_shape(src)
    got = warp_points(src_mesh.vertices, src, dst, max_area=16.0)
    assert got.inside.all() and np.abs(got.points - dst_mesh.vertices).max() <= 1e-9


def test_batches_sequences_and_retouches_take_a_cage_mesh(files):
    tmp, image, src, dst, dst_mesh = files
    opts = ["--max-area", "16"]
    assert run_cli([image, "--src", src, "--dst", dst, tmp / "one.png", *opts])[0] == 0
    (tmp / "batch").mkdir()
    code, err = run_cli([image, "--src", src, "--dst", dst, "--out-dir", tmp / "batch", *opts])
    assert code == 0, err
    assert (tmp / "batch" / "in.png").read_bytes() == (tmp / "one.png").read_bytes()
    # A sequence whose target mesh is keyframed: frame 3 is the target mesh itself.
    for f in (2, 3):
        (tmp / f"f.000{f}.png").write_bytes(Path(image).read_bytes())
    keys = tmp / "anim.json"
    keys.write_text(json.dumps({"frames": {"1": json.loads(Path(src).read_text()), "3": json.loads(Path(dst).read_text())}}))
    code, err = run_cli([tmp / "f.#.png", tmp / "o.#.png", "--frames", "2-3", "--src", src, "--dst", keys,
                         "--save-map", tmp / "m.#.exr", *opts])  # fmt: skip
    assert code == 0, err
    assert (tmp / "o.0003.png").read_bytes() == (tmp / "one.png").read_bytes()
    assert (tmp / "o.0002.png").read_bytes() != (tmp / "one.png").read_bytes() and (tmp / "m.0002.exr").exists()
    # A retouch: outside the target mesh's outline (a pixel away) the input's bytes.
    code, err = run_cli([image, "--src", src, "--dst", dst, tmp / "r.png", "--outside", "input", *opts])
    assert code == 0, err
    before, after = read_pixels(image), read_pixels(tmp / "r.png")
    centres = pixel_centres(48, 48)
    near = inside_polygon(centres, dst_mesh.outline.points)
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1), (1, -1), (-1, 1)):
        near |= inside_polygon(centres + [dx, dy], dst_mesh.outline.points)
    away = ~near.reshape(48, 48)
    assert away.sum() > 0 and np.array_equal(before[away], after[away])
