"""Textures and vertex attributes between surface patches (§4.2): charts, correspondences, exact cases, the command."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.ndimage import affine_transform

from warpcli.cli import main
from warpcli.errors import InputError, PolygonError
from warpcli.surface import (
    MeshError,
    UVMesh,
    chart_map,
    chart_of,
    corresponding_loops,
    read_mesh,
    transfer_attributes,
    transfer_texture,
)
from warpcli.surface.chart import uv_to_pixels

SIZE = (64, 64)


# --- meshes built in code -----------------------------------------------------------


def grid(nu: int, nv: int, uv_of=lambda uv: uv, attributes: dict | None = None, name: str = "grid") -> UVMesh:
    """An nu x nv vertex grid over the unit square (counter-clockwise faces), its UVs mapped by ``uv_of``;
    vertex numbers r * nu + c, the same for positions and UVs (as a PLY's)."""
    s, t = np.meshgrid(np.linspace(0, 1, nu), np.linspace(0, 1, nv))
    unit = np.stack([s.ravel(), t.ravel()], axis=1)
    tris = []
    for r in range(nv - 1):
        for c in range(nu - 1):
            a = r * nu + c
            tris += [(a, a + 1, a + nu + 1), (a, a + nu + 1, a + nu)]
    uv = uv_of(unit)
    attrs = {} if attributes is None else {k: f(unit) for k, f in attributes.items()}
    return UVMesh(np.column_stack([unit, np.zeros(len(unit))]), uv, tris, tris, attrs, {k: "float" for k in attrs}, name)


def fan(points, centre=None, name: str = "fan") -> UVMesh:
    """A fan of triangles from an interior point to a convex polygon's vertices (counter-clockwise in UV)."""
    p = np.asarray(points, dtype=float)
    c = p.mean(axis=0) if centre is None else np.asarray(centre, dtype=float)
    uv = np.vstack([p, c])
    n = len(p)
    tris = [(k, (k + 1) % n, n) for k in range(n)]
    return UVMesh(np.zeros((n + 1, 3)), uv, tris, tris, {}, {}, name)


def affine(matrix, offset):
    m = np.asarray(matrix, dtype=float)
    b = np.asarray(offset, dtype=float)
    return lambda uv: uv @ m.T + b


def random_affine(rng, scale=(0.35, 0.6)):
    """A random affine map of the unit square well inside the unit square, orientation preserving."""
    while True:
        m = rng.uniform(-0.25, 0.25, (2, 2)) + np.diag(rng.uniform(*scale, 2))
        if np.linalg.det(m) > 0.08:
            corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]]) @ m.T
            lo, hi = corners.min(axis=0), corners.max(axis=0)
            if (hi - lo).max() < 0.8:
                return m, 0.1 - lo + rng.uniform(0, 0.8 - (hi - lo).max(), 2)


def pixel_affine(mesh_a: UVMesh, size_a, mesh_b: UVMesh, size_b):
    """The affine map taking mesh_a's UVs in texels of size_a to mesh_b's in texels of size_b
    (same vertex numbering, fitted by least squares, exact here): (M, b) with y = M x + b."""
    xa = uv_to_pixels(mesh_a.uv, size_a)
    xb = uv_to_pixels(mesh_b.uv, size_b)
    sol, *_ = np.linalg.lstsq(np.column_stack([xa, np.ones(len(xa))]), xb, rcond=None)
    return sol[:2].T, sol[2]


def reference_affine_resample(texture, m, b, out_shape):
    """scipy's affine_transform (order 1) of a warp whose inverse is x = M^-1 (y - b), pixel centres at +0.5."""
    minv = np.linalg.inv(m)
    swap = np.array([[0.0, 1.0], [1.0, 0.0]])
    matrix = swap @ minv @ swap  # (row, col) indices
    offset = swap @ (minv @ (np.array([0.5, 0.5]) - b) - 0.5)
    return np.stack(
        [affine_transform(texture[..., c], matrix, offset, output_shape=out_shape, order=1) for c in range(texture.shape[2])],
        axis=2,
    )


def interior(mask: np.ndarray, margin: int = 2) -> np.ndarray:
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask, iterations=margin)


# --- charts ---------------------------------------------------------------------------


def test_the_boundary_loop_follows_the_faces():
    mesh = grid(3, 3)
    chart = chart_of(mesh)
    # Counter-clockwise in UV: along v = 0, up u = 1, back along v = 1, down u = 0.
    assert chart.loop.tolist() == [0, 1, 2, 5, 8, 7, 6, 3]


def _mesh(uv, tris, name="bad.obj"):
    return UVMesh(np.zeros((len(uv), 3)), uv, tris, tris, {}, {}, name)


SQUARE_UV = [[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]]


@pytest.mark.parametrize(
    "uv, tris, message",
    [
        # An annulus: a square with a square hole (two boundary loops).
        (
            [[0, 0], [3, 0], [3, 3], [0, 3], [1, 1], [2, 1], [2, 2], [1, 2]],
            [(0, 1, 5), (0, 5, 4), (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)],
            "2 boundary loops",
        ),
        # A tetrahedron's surface: closed.
        ([[0, 0], [1, 0], [0, 1], [1, 1]], [(0, 1, 2), (0, 3, 1), (1, 3, 2), (0, 2, 3)], "closed"),
        # Three triangles on one edge.
        ([[0, 0], [1, 0], [0.5, 1], [0.5, -1], [0.5, 2]], [(0, 1, 2), (1, 0, 3), (0, 1, 4)], "share one edge"),
        # Two triangles running along their shared edge the same way.
        ([[0, 0], [1, 0], [0.5, 1], [0.5, -1]], [(0, 1, 2), (0, 1, 3)], "not consistently oriented"),
        # Two triangles touching at one vertex (a bow tie).
        ([[0, 0], [1, 0], [1, 1], [2, 1], [2, 2]], [(0, 1, 2), (2, 3, 4)], "on the boundary twice"),
        # A face folded over in UV (oriented consistently, but its UVs run clockwise).
        ([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], [(0, 1, 2), (0, 2, 3), (3, 2, 4)], "folds over"),
        ([[0, 0], [1, 0], [2, 0]], [(0, 1, 2)], "no area"),
        ([[0, 0], [1, 0], [1, 1]], [(0, 1, 1)], "one texture coordinate twice"),
    ],
)
def test_charts_that_are_not_disks_are_refused(uv, tris, message):
    with pytest.raises(MeshError, match=message) as err:
        chart_of(_mesh(np.array(uv, float), np.array(tris)))
    assert str(err.value).startswith("bad.obj: ")


def test_a_chart_whose_boundary_crosses_itself_is_refused():
    """A strip wound 1.75 times round: every face counter-clockwise, but the chart overlaps
    itself, so its boundary crosses itself: the polygon check refuses it, naming the file."""
    angles = np.linspace(0, 3.5 * np.pi, 30)
    inner = np.stack([np.cos(angles), np.sin(angles)], axis=1) * (1 + 0.05 * angles)[:, None]
    uv = np.vstack([inner, inner * 1.25]) * 0.1 + 0.5
    n = len(angles)
    tris = np.array([t for k in range(n - 1) for t in ((k, k + 1, n + k + 1), (k, n + k + 1, n + k))])
    spiral = _mesh(uv, tris, "spiral.obj")
    chart = chart_of(spiral)  # a disk, unfolded face by face
    corner = int(chart.loop_vertices[0])
    with pytest.raises(PolygonError, match="^spiral.obj: .*(cross|touch)"):
        chart_map(grid(3, 3, name="g.obj"), spiral, SIZE, SIZE, src_corners=[0], dst_corners=[corner])


# --- the correspondence --------------------------------------------------------------


def test_equal_loops_start_at_the_smallest_vertex_or_the_given_one():
    a = np.array([[0, 0], [4, 0], [4, 3], [0, 3]], float)
    ids_a = np.array([7, 2, 9, 4])
    ids_b = np.array([5, 6, 1, 8])
    pair = corresponding_loops(a, a + 10, ids_a, ids_b)
    assert pair.src.tolist() == np.roll(a, -1, axis=0).tolist()  # vertex 2 first
    assert pair.dst.tolist() == (np.roll(a, -2, axis=0) + 10).tolist()  # vertex 1 first
    pair = corresponding_loops(a, a + 10, ids_a, ids_b, src_start=9, dst_start=8)
    assert pair.src[0].tolist() == [4, 3] and pair.dst[0].tolist() == [10, 13]
    with pytest.raises(MeshError, match="vertex 3 \\(start\\) is not on the chart's boundary"):
        corresponding_loops(a, a, ids_a, ids_b, src_start=3)
    with pytest.raises(MeshError, match="has 3 vertices but src's has 4.*corners"):
        corresponding_loops(a, a[:3], ids_a, ids_b[:3])
    with pytest.raises(MeshError, match="not in the order of the boundary loop"):
        corresponding_loops(a, a, ids_a, ids_b, src_corners=[7, 9, 2], dst_corners=[5, 6, 1])
    with pytest.raises(MeshError, match="one side only"):
        corresponding_loops(a, a, ids_a, ids_b, src_corners=[7])


def _polyline_fraction(poly: np.ndarray, point: np.ndarray) -> float:
    """Arclength fraction of a point lying on an open polyline."""
    seg = np.diff(poly, axis=0)
    lengths = np.hypot(*seg.T)
    best, where = np.inf, 0.0
    for k, (p, d) in enumerate(zip(poly[:-1], seg)):
        t = np.clip((point - p) @ d / (d @ d), 0, 1)
        dist = np.hypot(*(p + t * d - point))
        if dist < best:
            best, where = dist, (lengths[:k].sum() + t * lengths[k]) / lengths.sum()
    assert best < 1e-9
    return where


@settings(max_examples=20)
@given(st.data())
def test_corners_map_the_sides_by_arclength(data):
    """Random sides of different vertex counts: every polygon vertex pair sits at one arclength fraction."""
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    n_corners = data.draw(st.integers(3, 5))
    loops, sides = [], []
    for _ in range(2):
        angles = np.sort(rng.uniform(0, 2 * np.pi, n_corners * 6))
        radius = rng.uniform(20, 30, len(angles))
        pts = np.stack([100 + radius * np.cos(angles), 100 + radius * np.sin(angles)], axis=1)
        keep = np.sort(rng.choice(len(pts), rng.integers(n_corners + 1, len(pts)), replace=False))
        pts = pts[keep]
        loops.append(pts)
        sides.append(np.sort(rng.choice(len(pts), n_corners, replace=False)))
    (a, b), (ca, cb) = loops, sides
    pair = corresponding_loops(a, b, np.arange(len(a)), np.arange(len(b)), src_corners=ca.tolist(), dst_corners=cb.tolist())
    assert len(pair.src) == len(pair.dst) >= max(len(a), len(b)) - 2 * n_corners
    # Every loop vertex is a polygon vertex on its side (nothing here is straight).
    for loop, poly in ((a, pair.src), (b, pair.dst)):
        assert {tuple(p) for p in loop} <= {tuple(p) for p in poly}
    # Corner k of each polygon is corner k of its loop, and between corners the fractions agree.
    ka = [int(np.flatnonzero((pair.src == a[c]).all(axis=1))[0]) for c in ca]
    kb = [int(np.flatnonzero((pair.dst == b[c]).all(axis=1))[0]) for c in cb]
    assert ka == kb
    n = len(pair.src)
    for k in range(n_corners):
        lo, hi = ka[k], ka[(k + 1) % n_corners]
        idx = (lo + np.arange(((hi - lo) % n or n) + 1)) % n
        side_a = a[(ca[k] + np.arange(((ca[(k + 1) % n_corners] - ca[k]) % len(a) or len(a)) + 1)) % len(a)]
        side_b = b[(cb[k] + np.arange(((cb[(k + 1) % n_corners] - cb[k]) % len(b) or len(b)) + 1)) % len(b)]
        fa = np.array([_polyline_fraction(side_a, pair.src[i]) for i in idx])
        fb = np.array([_polyline_fraction(side_b, pair.dst[i]) for i in idx])
        fa[-1] = fb[-1] = 1.0  # the far corner (its fraction 0 is the next side's)
        # Paired vertices within MERGE_PIXELS of each other along a side keep their own places.
        length = min(np.hypot(*np.diff(side_a, axis=0).T).sum(), np.hypot(*np.diff(side_b, axis=0).T).sum())
        np.testing.assert_allclose(fa, fb, atol=0.011 / length + 1e-12)


def test_straight_runs_become_single_edges():
    pair = corresponding_loops(
        np.array([[0, 0], [1, 0], [3, 0], [3, 2], [0, 2]], float), np.array([[0, 0], [2, 0], [6, 0], [6, 4], [0, 4]], float),
        np.arange(5), np.arange(5),
    )  # fmt: skip
    assert len(pair.src) == 4  # vertex 1 is straight on both sides, at one fraction (1/3)
    pair = corresponding_loops(
        np.array([[0, 0], [1, 0], [3, 0], [3, 2], [0, 2]], float), np.array([[0, 0], [3, 0], [6, 0], [6, 4], [0, 4]], float),
        np.arange(5), np.arange(5),
    )  # fmt: skip
    assert len(pair.src) == 5  # at 1/3 on one side, 1/2 on the other: the map bends there


# --- textures: exact cases ------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_affine_images_of_one_square_give_the_affine_resampling(seed):
    """Charts that are affine images of one grid: the map is that affine map (regular Theta
    onto a square: both harmonic maps are affine), so the texture moves as scipy moves it."""
    rng = np.random.default_rng(seed)
    ma, ba = random_affine(rng)
    mb, bb = random_affine(rng, (0.5, 0.7))
    n = 3 + seed
    src = grid(n, n, affine(ma, ba), name="a.obj")
    dst = grid(n, n, affine(mb, bb), name="b.obj")
    texture = rng.random((48, 56, 3)).astype(np.float32)
    size = (60, 52)
    out = transfer_texture(texture, src, dst, antialias=False, size=size, padding=0)
    m, b = pixel_affine(src, (56, 48), dst, size)
    expected = reference_affine_resample(texture.astype(np.float64), m, b, (size[1], size[0]))
    inside = interior(out.chart)
    assert inside.sum() > 300
    np.testing.assert_allclose(out.pixels[inside], expected[inside], atol=2e-5)


def test_affine_images_of_a_convex_quad_with_theta_the_quad(tmp_path):
    """A generic convex quad: with Theta that quad, phi0 and phi1 are affine, so the map is."""
    quad = np.array([[0.1, 0.15], [0.8, 0.1], [0.7, 0.85], [0.2, 0.6]])
    m = np.array([[0.8, 0.15], [-0.1, 0.9]])
    src = fan(quad, name="a.obj")
    dst = fan(quad @ m.T + [0.05, 0.04], name="b.obj")
    theta = tmp_path / "theta.json"
    theta.write_text(json.dumps({"points": uv_to_pixels(quad, SIZE).tolist()}))
    texture = np.random.default_rng(5).random((64, 64, 2))
    out = transfer_texture(texture, src, dst, antialias=False, padding=0, theta=str(theta))
    m, b = pixel_affine(src, SIZE, dst, SIZE)
    expected = reference_affine_resample(texture, m, b, (64, 64))
    inside = interior(out.chart)
    np.testing.assert_allclose(out.pixels[inside], expected[inside], atol=1e-9)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_identical_charts_give_the_texture_back(dtype):
    rng = np.random.default_rng(3)
    bump = lambda uv: 0.15 + 0.7 * uv + 0.05 * np.sin(3 * uv[:, ::-1])
    mesh = grid(6, 5, bump, name="same.obj")
    top = 1.0 if dtype == np.float32 else np.iinfo(dtype).max
    texture = (rng.random((64, 64, 3)) * top).astype(dtype)
    out = transfer_texture(texture, mesh, mesh)
    inside = interior(out.chart, 1)
    assert out.pixels.dtype == dtype and inside.sum() > 1500
    diff = np.abs(out.pixels[inside].astype(float) - texture[inside].astype(float))
    assert diff.max() <= (1e-5 if dtype == np.float32 else 0.5)


def test_padding_repeats_the_edge_texels_and_the_background_lies_beyond():
    mesh = grid(3, 3, affine(np.eye(2) * 0.5, [0.25, 0.25]))
    texture = np.full((64, 64, 1), 200, np.uint8)
    texture[:, 32:] = 100
    out = transfer_texture(texture, mesh, mesh, padding=4, background=0.0)
    from scipy.ndimage import distance_transform_edt

    dist = distance_transform_edt(~out.chart)
    px = out.pixels[..., 0]
    assert set(np.unique(px[out.chart])) <= set(range(95, 206))
    ring = (dist > 0) & (dist <= 4)
    assert ring.sum() > 100 and (px[ring] > 90).all()  # repeated texels, never the background
    assert (px[dist > 4.5] == 0).all()
    none = transfer_texture(texture, mesh, mesh, padding=0)
    assert (none.pixels[~none.chart] == 0).all()


def test_flip_v_is_the_mirror_of_the_texture():
    rng = np.random.default_rng(7)
    ma, ba = random_affine(rng)
    mb, bb = random_affine(rng)
    src, dst = grid(3, 3, affine(ma, ba)), grid(3, 3, affine(mb, bb))
    texture = rng.random((64, 64, 1))
    up = transfer_texture(texture, src, dst, antialias=False, padding=0).pixels
    down = transfer_texture(texture[::-1], src, dst, antialias=False, padding=0, flip_v=True).pixels[::-1]
    np.testing.assert_allclose(up, down, atol=1e-9)
    # Flipping one side only mirrors the layouts against each other: not the same texture.
    one = transfer_texture(texture, src, dst, antialias=False, padding=0, flip_v=(False, True)).pixels
    assert not np.allclose(one, up)


# --- vertex attributes ------------------------------------------------------------------


def test_attributes_between_identical_meshes_are_the_identity():
    rng = np.random.default_rng(0)
    mesh = grid(7, 6, lambda uv: 0.1 + 0.8 * uv + 0.03 * np.cos(5 * uv[:, ::-1]), {"red": lambda uv: rng.random(len(uv))})
    moved = transfer_attributes(mesh, mesh, size=(256, 256))
    np.testing.assert_allclose(moved["red"], mesh.attributes["red"], atol=1e-7)


def _barycentric_reference(mesh: UVMesh, values: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Brute force: every triangle's barycentric coordinates of every point; the containing one's blend."""
    out = np.full(len(points), np.nan)
    for tri in mesh.triangles_uv:
        a, b, c = mesh.uv[tri]
        mat = np.column_stack([b - a, c - a])
        lam = np.linalg.solve(mat, (points - a).T).T
        bary = np.column_stack([1 - lam.sum(axis=1), lam])
        inside = (bary >= -1e-9).all(axis=1) & np.isnan(out)
        out[inside] = bary[inside] @ values[tri]
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_attributes_between_affinely_related_charts_are_barycentric_interpolation(seed):
    rng = np.random.default_rng(seed)
    ma, ba = random_affine(rng)
    mb, bb = random_affine(rng)
    values = rng.random(25)
    src = grid(5, 5, affine(ma, ba), {"q": lambda uv: values})
    # DST: the same square at another resolution, jittered inside (another triangulation).
    def jittered(uv):
        inner = (uv > 0) & (uv < 1)
        return affine(mb, bb)(np.where(inner.all(axis=1)[:, None], uv + rng.uniform(-0.04, 0.04, uv.shape), uv))

    dst = grid(8, 7, jittered)
    moved = transfer_attributes(src, dst, src_corners=[0, 4, 24, 20], dst_corners=[0, 7, 55, 48])
    # Each DST vertex's pre-image: the affine map back (both charts affine images of one square).
    to_unit_b = np.linalg.solve(mb, (dst.uv - bb).T).T
    pre = affine(ma, ba)(to_unit_b)
    expected = _barycentric_reference(src, values, pre)
    np.testing.assert_allclose(moved["q"], expected, atol=1e-7)


def test_corners_with_different_vertex_counts_reproduce_linear_data():
    """Grids of 4 x 4 and 9 x 6 vertices on parallelograms, corners named: a linear attribute arrives exactly."""
    ma, ba = np.array([[0.6, 0.1], [0.05, 0.5]]), np.array([0.15, 0.2])
    mb, bb = np.array([[0.4, -0.1], [0.2, 0.6]]), np.array([0.3, 0.1])
    src = grid(4, 4, affine(ma, ba), {"f": lambda uv: 3 * uv[:, 0] - 2 * uv[:, 1] + 0.5})
    dst = grid(9, 6, affine(mb, bb))
    unit_dst = np.linalg.solve(mb, (dst.uv - bb).T).T
    s, t = unit_dst[:, 0], unit_dst[:, 1]
    moved = transfer_attributes(src, dst, src_corners=[0, 3, 15, 12], dst_corners=[0, 8, 53, 45], size=(256, 256))
    np.testing.assert_allclose(moved["f"], 3 * s - 2 * t + 0.5, atol=1e-8)
    # A quarter turn: DST's (s, t) comes from SRC's (1 - t, s).
    moved = transfer_attributes(src, dst, src_corners=[3, 15, 12, 0], dst_corners=[0, 8, 53, 45], size=(256, 256))
    np.testing.assert_allclose(moved["f"], 3 * (1 - t) - 2 * s + 0.5, atol=1e-8)


def test_unknown_attribute_and_no_attributes():
    mesh = grid(3, 3)
    with pytest.raises(InputError, match="carry no attributes"):
        transfer_attributes(mesh, mesh)
    with pytest.raises(InputError, match="no vertex attribute 'blue'"):
        transfer_attributes(grid(3, 3, attributes={"red": lambda uv: uv[:, 0]}), mesh, ["blue"])


# --- the command -----------------------------------------------------------------------

SAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "sample_images")
CORNERS = ["--src-corners", "0,8,80,72", "--dst-corners", "16,0,102,118"]


def test_cli_moves_a_texture_and_colours(tmp_path):
    import OpenImageIO as oiio

    out = tmp_path / "arch.png"
    args = [os.path.join(SAMPLES, "texture_square.obj"), os.path.join(SAMPLES, "texture_arch.obj"), str(out), *CORNERS]
    assert main(["texture", *args, "--size", "96x80", "--dtype", "uint16"]) == 0
    spec = oiio.ImageInput.open(str(out)).spec()
    assert (spec.width, spec.height, spec.format) == (96, 80, oiio.UINT16)
    ply = tmp_path / "arch.ply"
    ply_args = [os.path.join(SAMPLES, "texture_square.ply"), os.path.join(SAMPLES, "texture_arch.ply"), str(ply), *CORNERS]
    assert main(["texture", *ply_args, "--size", "256x256"]) == 0
    moved = read_mesh(ply)
    assert moved.attribute_types["red"] == "uchar" and set(moved.attributes) == {"red", "green", "blue"}
    # The arch's corners get the square's corner colours exactly.
    square = read_mesh(os.path.join(SAMPLES, "texture_square.ply"))
    for a, b in zip((0, 8, 80, 72), (16, 0, 102, 118)):
        assert moved.attributes["red"][b] == square.attributes["red"][a]
    obj = tmp_path / "arch.obj"
    assert main(["texture", ply_args[0], os.path.join(SAMPLES, "texture_arch.obj"), str(obj), *CORNERS, "--size", "256x256"]) == 0
    colours = read_mesh(obj).attributes
    np.testing.assert_allclose(colours["red"] * 255, moved.attributes["red"], atol=0.51)


@pytest.mark.parametrize(
    "extra, out_name, message",
    [
        ([], "o.png", "the chart's boundary has 44 vertices but"),
        (["--src-corners", "0,8,80", "--dst-corners", "16,0,102,118"], "o.png", "4 corners, but"),
        (["--src-corners", "0,80,8,72", "--dst-corners", "16,0,102,118"], "o.png", "not in the order of the boundary loop"),
        (["--src-corners", "40,8,80,72", "--dst-corners", "16,0,102,118"], "o.png", "vertex 40 (corner) is not on the chart's boundary"),
        ([*CORNERS, "--attribute", "quality"], "o.obj", "an OBJ holds vertex colours only"),
        ([*CORNERS], "o.ply", "a mesh output has DST's format (.obj)"),
        ([*CORNERS, "--texture", "missing.png"], "o.png", "missing.png"),
    ],
)
def test_cli_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, extra, out_name, message):
    out = tmp_path / out_name
    args = ["texture", os.path.join(SAMPLES, "texture_square.obj"), os.path.join(SAMPLES, "texture_arch.obj"), str(out), *extra]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert os.listdir(tmp_path) == []


def test_cli_bad_mesh_names_the_file_and_line(tmp_path, capsys):
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/3\n")
    assert main(["texture", str(bad), str(bad), str(tmp_path / "o.png"), "--texture", os.path.join(SAMPLES, "texture_cat.png")]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: line 5: face refers to texture coordinate 2, but 1 are defined" in err
    assert not (tmp_path / "o.png").exists()
