"""Tests of warpcli._native: kernels run as cached machine code give the numba functions' bits."""

from __future__ import annotations

import importlib
import os
import threading

import numpy as np
import pytest

from conftest import REPO
from helpers import star
from warpcli import _elf, _native
from warpcli._native import Kernels, parallel

RASTER = "warpcli.raster._kernels"
FEM = "warpcli.maps.fem._kernels"
MAPS = "warpcli.maps._kernels"
SPARSE = "warpcli.maps.fem._sparse_kernels"


@pytest.fixture(params=["elf", "mcjit"])
def route(request, monkeypatch):
    """Load kernels in this test by `warpcli._elf` (where it can) or by MCJIT, and check it was so."""
    if request.param == "elf" and not _elf.supported():
        pytest.skip("warpcli._elf loads x86-64 Linux objects only")
    monkeypatch.setattr(_native, "_JIT", None)
    monkeypatch.setattr(_native, "ELF_LOADER", request.param == "elf")
    yield request.param
    assert set(_native._jit().routes.values()) == {request.param}


def _same(module, name, make_args, depends=()):
    """Call kernel ``name`` natively and as the numba function on equal fresh arguments;
    assert the native route was taken and every argument and result is bitwise equal."""
    kernels = Kernels(module, depends)
    a, b = make_args(), make_args()
    got = getattr(kernels, name)(*a)
    want = getattr(importlib.import_module(module), name)(*b)
    assert hasattr(kernels._calls[(name, _native._variant(a))], "_native"), "the native route was not taken"
    assert got == want
    for x, y in zip(a, b):
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes()


def _image(dtype, shape=(23, 31, 3), seed=0):
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind == "u":
        return rng.integers(0, np.iinfo(dtype).max, shape, dtype=dtype)
    return rng.normal(0.5, 0.3, shape).astype(dtype)


def _points(n=4000, seed=1):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-3.0, 34.0, (n, 2))
    xy[::97] = np.nan  # no pre-image
    xy[5] = [0.0, 0.0]  # the image's corner and border exactly
    xy[6] = [31.0, 23.0]
    return xy


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32, np.float64])
@pytest.mark.usefixtures("route")
def test_samplers_match_numba_bitwise(dtype):
    work = np.float64 if dtype == np.float64 else np.float32
    img, xy = _image(dtype), _points()
    bg = np.array([0.25, 7.0, 1e3])
    whole = (0, 0, img.shape[1], img.shape[0])
    _same(RASTER, "sample_linear", lambda: (img, *whole, xy, bg, np.zeros((len(xy), 3), dtype=work)))
    _same(RASTER, "sample_nearest", lambda: (img, *whole, xy, bg, np.zeros((len(xy), 3), dtype=work)))
    rng = np.random.default_rng(2)
    jac = rng.normal(0.0, 2.5, (len(xy), 2, 2))  # shrinking as well: up to 16 x 16 samples
    jac[::13] = np.nan
    _same(
        RASTER, "sample_linear_aa",
        lambda: (img, *whole, xy, jac, 16, bg, np.zeros((len(xy), 3), dtype=work), np.zeros(3)),
    )  # fmt: skip


@pytest.mark.usefixtures("route")
def test_rounding_and_border_kernels_match_numba_bitwise():
    values = np.random.default_rng(3).normal(100.0, 120.0, 5000).astype(np.float32)
    values[::50] = np.float32(0.5)  # ties round to even
    _same(RASTER, "store", lambda: (values, np.zeros(5000, dtype=np.uint8), 0.0, 255.0, True))
    _same(RASTER, "store", lambda: (values.astype(np.float64), np.zeros(5000, dtype=np.uint16), 0.0, 65535.0, True))
    _same(RASTER, "store", lambda: (values.astype(np.float64), np.zeros(5000, dtype=np.float32), 0.0, 0.0, False))
    xy = _points()
    _same(RASTER, "near_border", lambda: (xy, 31.0, 23.0, np.zeros(len(xy), dtype=np.int64)))


@pytest.mark.usefixtures("route")
def test_fem_kernels_match_numba_bitwise():
    from warpcli.maps.compose import BijectiveMap
    from warpcli.polygon import Polygon

    f = BijectiveMap.between(Polygon(star()), Polygon(star(phase=0.3)))
    phi0, phi1 = f.phi0, f.phi1
    tri = phi1._triangles
    size = 40 * 128

    def scan():
        return (
            phi1.mesh.vertices, tri, phi1._domain_coefficients, phi1.values, phi1._coherent_order, 128, 128, 40, 80,
            np.zeros(size, dtype=np.uint8), np.zeros(size, dtype=np.int64), np.zeros((size, 2)),
            np.zeros(size, dtype=np.int32),
        )  # fmt: skip

    _same(FEM, "scan_grid", scan, ("locate.py",))
    args = scan()
    n = importlib.import_module(FEM).scan_grid(*args)
    q = args[11][:n].copy()  # the pixel centres' images in Theta, in scan order

    def walk():
        return (
            q, phi0._triangles, phi0._image_coefficients, phi0._neighbours, phi0.mesh.vertices,
            len(phi0._triangles) + 64, np.full((n, 2), np.nan), np.zeros(n, dtype=np.int32),
        )  # fmt: skip

    _same(FEM, "walk", walk, ("locate.py",))


@pytest.mark.usefixtures("route")
def test_fem_sparse_kernels_match_numba_bitwise():
    from warpcli.maps.fem import sparse
    from warpcli.maps.fem.mesh import mesh_polygon
    from warpcli.polygon import Polygon

    mesh = mesh_polygon(Polygon(star()), 3.0)
    tri = mesh.triangles.astype(np.int64)
    n, halves = mesh.n_vertices, 3 * len(tri)

    def edges():
        return (tri, n, np.zeros(n + 1, dtype=np.int64), *(np.zeros(halves, dtype=np.int64) for _ in range(6)))

    _same(SPARSE, "mesh_edges", edges)
    e = mesh.edges
    count = len(e.lo)
    weight = np.concatenate(sparse._corner_weights(mesh.vertices, mesh.triangles))

    def rows():
        return (
            n, count, *(np.ascontiguousarray(a) for a in e), weight, np.zeros(n, dtype=np.int64),
            np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros(n + 1, dtype=np.int64),
            np.zeros(2 * count, dtype=np.int64), np.zeros(2 * count),
        )  # fmt: skip

    _same(SPARSE, "laplacian_rows", rows)
    args = rows()
    importlib.import_module(SPARSE).laplacian_rows(*args)
    n_down, indptr, cols, data = args[7], args[10], args[11], args[12]
    diag = np.random.default_rng(3).normal(size=n)
    diag[::5] = 0.0  # left out, as exact zeros of the rows are

    def merged():
        return (n, indptr, cols, data, n_down, diag, np.zeros(n + 1, dtype=np.int64),
                np.zeros(2 * count + n, dtype=np.int64), np.zeros(2 * count + n))  # fmt: skip

    _same(SPARSE, "with_diagonal", merged)
    k = sparse.cotan_stiffness(mesh.vertices, mesh.triangles, e)
    rows_kept = np.flatnonzero(np.arange(n) % 3 != 1)
    new_col = np.where(np.arange(n) % 2 == 0, np.arange(n) // 2, -1)

    def sub():
        return (rows_kept, k.indptr, k.indices, k.data, new_col, np.zeros(len(rows_kept) + 1, dtype=np.int64),
                np.zeros(len(k.data), dtype=np.int64), np.zeros(len(k.data)))  # fmt: skip

    _same(SPARSE, "submatrix", sub)


def _band(seed=5, width=37, n=900):
    """A band's grid pixels in columns 4..33 (some twice, some beyond the rows kept), points and Jacobians."""
    rng = np.random.default_rng(seed)
    pixels = rng.integers(10, 30, n) * width + rng.integers(4, 34, n)
    pixels[::11] = pixels[5]  # one pixel reported again: the last one wins
    found = rng.normal(size=(n, 2))
    found[::9] = np.nan
    a, b = rng.normal(size=(n, 2, 2)), rng.normal(size=(n, 2, 2))
    a[::7] = np.nan
    b[3] = np.inf
    return pixels, found, a, b


def _per_pixel(a, b):
    """`scatter_band`'s tables for Jacobians given per pixel: the arrays, indexed 0..n-1."""
    k = np.arange(len(a))
    return a, k, b, k.astype(np.int32)


@pytest.mark.usefixtures("route")
def test_scatter_band_matches_numba_bitwise():
    pixels, found, a, b = _band()
    ww, rows = 30, 12  # the window: columns 4..33, rows 14..25 (a strip cutting the band at 15..25)
    window = lambda: (np.full((rows * ww, 2), np.nan), np.full((rows * ww, 2, 2), np.nan))  # noqa: E731
    for with_jac in (True, False):
        _same(MAPS, "scatter_band", lambda: (pixels, 37, 14, 4, ww, 15, 26, found, *_per_pixel(a, b), with_jac, *window()))
    _same(MAPS, "outside_columns", lambda: (pixels, 37, 6, 30))


@pytest.mark.usefixtures("route")
def test_scatter_band_from_cell_tables_matches_numba_bitwise_and_scatters_the_gathered_products():
    """Jacobians from per-cell tables (the last row NaN, for cell -1) give the bits of
    gathering them first and scattering the products per pixel."""
    pixels, found, _, _ = _band()
    rng = np.random.default_rng(6)
    ta, tb = rng.normal(size=(41, 2, 2)), rng.normal(size=(23, 2, 2))
    ta[5], ta[-1], tb[-1] = np.inf, np.nan, np.nan  # an infinite cell; the NaN rows
    ca = rng.integers(-1, 40, len(pixels))
    cb = rng.integers(-1, 22, len(pixels)).astype(np.int32)
    args = (pixels, 37, 14, 4, 30, 15, 26, found)
    window = lambda: (np.full((12 * 30, 2), np.nan), np.full((12 * 30, 2, 2), np.nan))  # noqa: E731
    _same(MAPS, "scatter_band", lambda: (*args, ta, ca, tb, cb, True, *window()))
    got, want = window(), window()
    Kernels(MAPS).scatter_band(*args, ta, ca, tb, cb, True, *got)
    gathered_a, gathered_b = ta[np.where(ca < 0, 40, ca)], tb[np.where(cb < 0, 22, cb)]
    Kernels(MAPS).scatter_band(*args, *_per_pixel(gathered_a, gathered_b), True, *want)
    assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()


@pytest.mark.parametrize("with_jac", [True, False])
def test_scatter_band_is_the_numpy_scatter(with_jac):
    """What `warpcli.maps.compose._through_theta` did in numpy: rows and columns by divmod, the rows
    start..stop kept, ``points[idx] = found`` (the last of a repeated index wins) and the products."""
    from warpcli.maps import _kernels as kernels

    pixels, found, a, b = _band()
    width, r0, c0, ww, start, stop = 37, 14, 4, 30, 15, 26
    points, jac = np.full((12 * ww, 2), np.nan), np.full((12 * ww, 2, 2), np.nan)
    Kernels(MAPS).scatter_band(pixels, width, r0, c0, ww, start, stop, found, *_per_pixel(a, b), with_jac, points, jac)
    row, col = np.divmod(pixels, width)
    cut = (row >= start) & (row < stop)
    idx = (row[cut] - r0) * ww + (col[cut] - c0)
    want_points, want_jac = np.full((12 * ww, 2), np.nan), np.full((12 * ww, 2, 2), np.nan)
    want_points[idx] = found[cut]
    if with_jac:
        want_jac[idx] = np.einsum("kij,kjl->kil", a[cut], b[cut])
    assert points.tobytes() == want_points.tobytes()
    np.testing.assert_array_equal(jac, want_jac)  # (einsum may sum in another order: equal, NaN where NaN)
    assert kernels.outside_columns(pixels, width, 4, 34) == 0
    assert kernels.outside_columns(pixels, width, 6, 30) == ((pixels % width < 6) | (pixels % width >= 30)).sum() > 0


def test_arguments_the_native_route_does_not_take_go_to_numba_with_the_same_result():
    kernels = Kernels(RASTER)
    img, xy = _image(np.uint8), _points()
    strided = xy[::2]  # not contiguous
    assert _native._variant((img, strided)) is None
    out = np.zeros((len(strided), 3), dtype=np.float32)
    whole = (0, 0, img.shape[1], img.shape[0])
    kernels.sample_linear(img, *whole, strided, np.zeros(3), out)
    want = np.zeros_like(out)
    importlib.import_module(RASTER).sample_linear(img, *whole, np.ascontiguousarray(strided), np.zeros(3), want)
    assert out.tobytes() == want.tobytes()
    assert _native._variant((np.float16(1.0),)) is None
    assert _native._variant((2**70,)) is None
    assert _native._variant((True, 3, 2.5)) == ("b", "i", "f")


def test_a_damaged_cache_entry_is_refused(tmp_path):
    entry = {"format": 9, "symbol": "s", "restype": "void", "externs": [], "object": b"\x7fELF" + bytes(200)}
    _native._write_entry([str(tmp_path)], "k.native", entry)
    path = tmp_path / "k.native"
    assert _native._read_entry(str(path))["object"] == entry["object"]
    data = bytearray(path.read_bytes())
    data[-3] ^= 0xFF  # same size, other bytes
    path.write_bytes(bytes(data))
    assert _native._read_entry(str(path)) is None
    path.write_bytes(bytes(data[:-10]))  # cut short
    assert _native._read_entry(str(path)) is None
    assert _native._read_entry(str(tmp_path / "none.native")) is None


def test_parallel_runs_every_part_once_and_raises_the_first_error(monkeypatch):
    monkeypatch.setattr(_native, "cores", lambda: 3)
    seen, lock = [], threading.Lock()

    def record(k):
        with lock:
            seen.append(k)

    parallel(record, range(10))
    assert sorted(seen) == list(range(10))

    def fail(k):
        if k == 4:
            raise ValueError("part 4")

    with pytest.raises(ValueError, match="part 4"):
        parallel(fail, range(10))


def test_parallel_hands_the_next_part_to_whichever_thread_is_free(monkeypatch):
    # part 0 holds its thread until every other part is done: the other thread must take them all
    # (parts fixed to threads in turn would leave parts 2 and 4 behind part 0, and the wait would fail)
    monkeypatch.setattr(_native, "cores", lambda: 2)
    done, lock, others = [], threading.Lock(), threading.Event()
    waited = []

    def work(k):
        if k == 0:
            waited.append(others.wait(timeout=20))
            return
        with lock:
            done.append(k)
            if len(done) == 5:
                others.set()

    parallel(work, range(6))
    assert waited == [True] and sorted(done) == [1, 2, 3, 4, 5]


@pytest.mark.parametrize("seed", range(5))
def test_bands_are_handed_out_most_work_first(seed):
    from warpcli.grid import inside_polygon, pixel_centres
    from warpcli.maps.compose import _most_work_first

    # a generated triangle, widest at its bottom or top, over several bands of rows
    rng = np.random.default_rng(seed)
    width, height, band = 200, 160, int(rng.integers(12, 40))
    top, bottom = rng.uniform(2, 20), rng.uniform(140, 158)
    apex = rng.uniform(20, 180)
    tri = np.array([[apex, top], [2.0, bottom], [198.0, bottom]])
    if rng.random() < 0.5:
        tri[:, 1] = height - tri[:, 1]
    firsts = range(0, height, band)
    order = _most_work_first(firsts, band, height, 0, width, tri)
    assert sorted(order) == list(firsts)
    # the pixel centres in the polygon per band, counted in full: the order is theirs where they differ by much
    count = {f: int(inside_polygon(pixel_centres(width, height, (f, min(f + band, height))), tri).sum()) for f in firsts}
    for a, b in zip(order, order[1:]):
        assert count[a] >= 0.8 * count[b] - 200
    # a strip's few bands (of the window's): ordered among themselves
    few = range(band, min(4 * band, height), band)
    order = _most_work_first(few, band, height, 0, width, tri)
    assert sorted(order) == list(few)
    for a, b in zip(order, order[1:]):
        assert count[a] >= 0.8 * count[b] - 200


def test_warps_do_not_depend_on_the_number_of_threads(monkeypatch):
    """Compose bands and resample runs are shared out over the cores: same bytes on one."""
    from warpcli.pipeline import warp_image

    rng = np.random.default_rng(6)
    img = rng.integers(0, 256, (300, 260, 4), dtype=np.uint8)
    src, dst = star(6, 130, 150, 50, 120), star(6, 130, 150, 40, 125, 0.3)
    results = []
    for n in (1, 2, 5):
        monkeypatch.setattr(_native, "cores", lambda n=n: n)
        monkeypatch.setattr("warpcli.maps.compose.BAND_PIXELS", 4096)  # many bands
        r = warp_image(img, src, dst, alpha_channel=3)
        results.append((r.pixels.tobytes(), r.inverse_map.tobytes(), r.jacobian.tobytes()))
    assert results[0] == results[1] == results[2]


def test_numba_cache_writes_hold_a_lock_beside_the_index(tmp_path):
    """Every kernel module takes njit from warpcli._jit, which serializes numba's cache-index updates:
    two processes compiling at once must not interleave the read-modify-write of one index."""
    import ast

    import warpcli._jit  # noqa: F401  (installs the lock)
    from numba.core import caching

    assert getattr(caching.IndexDataCacheFile.save, "serialized", False)
    root = os.path.join(REPO, "warpcli")
    for dirpath, _, files in os.walk(root):
        for f in files:
            if f.endswith(".py") and f != "_jit.py":
                tree = ast.parse(open(os.path.join(dirpath, f)).read())
                for node in ast.walk(tree):
                    if isinstance(node, ast.ImportFrom) and node.module == "numba":
                        assert "njit" not in {a.name for a in node.names}, f"{f} takes njit from numba, not warpcli._jit"


def test_a_kernel_compiles_the_kernels_it_calls_once_for_plain_types():
    """A counter started at 0 and carried through a loop reaches the callee as the literal 0 while
    numba is still typing the loop: the callee was compiled for that literal and again for int64
    (BEM's evaluation: 2.2 s of its 11 s). warpcli's functions get the plain types only, and the
    caller's results are those of the same code compiled by numba's own rules."""
    from numba import njit, types

    import warpcli._jit  # noqa: F401  (installs the typing of calls)

    source = (
        "def step(n, x, out):\n"
        "    out[n] = x * 0.1 + n\n"
        "    return n + 1\n"
        "def count(xs, out):\n"
        "    n = 0\n"
        "    for x in xs:\n"
        "        n = step(n, x, out)\n"
        "    return n\n"
    )
    results = []
    for module in ("warpcli._probe", "elsewhere"):  # warpcli's function, and one that numba types itself
        namespace = {"__name__": module}
        exec(source, namespace)  # noqa: S102
        namespace["step"] = njit(namespace["step"])
        count = njit(namespace["count"])
        namespace["count"] = count
        out = np.zeros(5)
        assert count(np.arange(5.0), out) == 5
        results.append(out.tobytes())
        literal = [sig for sig in namespace["step"].signatures if any(isinstance(a, types.Literal) for a in sig)]
        if module == "warpcli._probe":
            assert len(namespace["step"].signatures) == 1 and not literal, namespace["step"].signatures
        else:
            assert literal, "numba no longer compiles a loop's literal start: this typing may go"
    assert results[0] == results[1]


@pytest.mark.usefixtures("route")
def test_mfs_kernel_matches_numba_bitwise():
    rng = np.random.default_rng(9)
    K, m = 500, 64
    p = rng.uniform(-0.5, 0.5, (K, 2))
    th = 2 * np.pi * rng.random(m)
    s = 1.5 * np.stack([np.cos(th), np.sin(th)], axis=1)
    w = rng.normal(size=(m, 2))
    for want in ((True, True, False), (True, False, False), (False, True, False), (False, False, True)):

        def args(want=want):
            return (
                p[:, 0].copy(), p[:, 1].copy(), s[:, 0].copy(), s[:, 1].copy(), w[:, 0].copy(), w[:, 1].copy(),
                *want, np.zeros((K if want[0] else 0, 2)), np.zeros((K if want[1] else 0, 2, 2)),
                np.zeros((K if want[2] else 0, 2, 2, 2)),
            )  # fmt: skip

        _same("warpcli.maps._smooth_kernels", "mfs_evaluate", args)


@pytest.mark.usefixtures("route")
def test_near_boundary_filter_matches_numba_bitwise():
    P = star() * 40.0 + 64.0
    rng = np.random.default_rng(4)
    p = np.concatenate([rng.uniform(0.0, 128.0, (400, 2)), P + rng.normal(0.0, 1e-3, P.shape), [[np.nan, 3.0]]])

    def args():
        return (p[:, 0].copy(), p[:, 1].copy(), P[:, 0].copy(), P[:, 1].copy(), 2.5, np.zeros(len(p), dtype=np.uint8))

    _same("warpcli.maps._smooth_kernels", "near_boundary", args)


@pytest.mark.usefixtures("route")
def test_compiled_mfs_newton_matches_numba_bitwise():
    from warpcli.maps.mfs import fit_mfs

    P = star() * 40.0 + 64.0
    tt = 2 * np.pi * np.arange(len(P)) / len(P)
    sol = fit_mfs(P, np.stack([np.cos(tt), np.sin(tt)], axis=1), m=64)
    rng = np.random.default_rng(2)
    g = P.mean(axis=0) + rng.normal(0.0, 5.0, (300, 2))
    x = sol.value(g[::-1].copy())
    f = sol.frame
    frame = np.array([f.centre[0], f.centre[1], f.scale, f.tcentre[0], f.tcentre[1], f.tscale])
    chain = (np.arange(300) % 3 == 0).astype(np.uint8)  # some points start from their predecessors

    def args():
        return (
            x[:, 0].copy(), x[:, 1].copy(), g[:, 0].copy(), g[:, 1].copy(), chain.copy(), sol.sites[:, 0].copy(),
            sol.sites[:, 1].copy(), sol.weights[:, 0].copy(), sol.weights[:, 1].copy(), sol.affine.copy(), frame,
            P[:, 0].copy(), P[:, 1].copy(), 1e-12, 1e-9, 20, 40, 1e-4, True, np.zeros((300, 2)),
            np.zeros(300, dtype=np.uint8), np.zeros((300, 2, 2)),
        )  # fmt: skip

    _same("warpcli.maps._smooth_kernels", "mfs_invert", args)


BEM = "warpcli.maps._bem_kernels"


@pytest.mark.usefixtures("route")
def test_bem_kernels_match_numba_bitwise():
    """The collocation integrals, the evaluation's block sums (near, Gauss and far fields, all three
    quantities) and the certificate's bounds, natively and as numba's functions."""
    from warpcli.maps.bem import fit_bem
    from warpcli.maps.bem_eval import _FAR, _GAUSS_ORDERS, _ORDER, NEAR, _morton_order, gauss01

    P = star() * 40.0 + 64.0
    sol = fit_bem(P, P[::-1] * 0.5, m=48)
    a = sol.nodes
    b = np.roll(a, -1, axis=0)
    m = len(a)
    rng = np.random.default_rng(12)
    c = a + rng.uniform(0.1, 0.9, (m, 1)) * (b - a)  # on the elements, and beside them
    c = np.concatenate([c, 0.6 * c, c + 1e-4])
    inc_e = np.full((len(c), 2), -1, dtype=np.int64)
    inc_t = np.full((len(c), 2), -1.0)
    inc_e[:m, 0] = np.arange(m)
    inc_t[:m, 0] = np.linalg.norm(c[:m] - a, axis=1) / np.linalg.norm(b - a, axis=1)
    gt, gw = gauss01(16)

    def assemble():
        return (
            c[:, 0].copy(), c[:, 1].copy(), inc_e, inc_t, a[:, 0].copy(), a[:, 1].copy(), b[:, 0].copy(),
            b[:, 1].copy(), gt, gw, NEAR, np.zeros((len(c), m, 2)), np.zeros((len(c), m, 2)),
        )  # fmt: skip

    _same(BEM, "bem_assemble", assemble, ("_smooth_kernels.py",))

    # points of a grid and next to the boundary, in blocks of 64: all three fields of the evaluation
    g = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, 60), np.linspace(-0.5, 0.5, 60)), axis=-1).reshape(-1, 2)
    p = np.concatenate([g, 0.999 * a, 0.98 * c])
    p = p[_morton_order(p)]
    bstart = np.append(np.arange(0, len(p), 64), len(p)).astype(np.int64)
    lo = np.minimum.reduceat(p, bstart[:-1], axis=0)
    hi = np.maximum.reduceat(p, bstart[:-1], axis=0)
    bc = 0.5 * (lo + hi)
    brad = 0.5 * np.hypot(*(hi - lo).T)
    src = sol._sources
    G = m * int(_GAUSS_ORDERS[-1])
    K = len(p)
    rows = rng.permutation(K)  # where each point's results go

    def evaluate():
        return (
            p[:, 0].copy(), p[:, 1].copy(), rows, bstart, bc[:, 0].copy(), bc[:, 1].copy(), brad,
            *src[:7], sol.flux, sol.data, *src[7:], NEAR, _FAR, True, True, True,
            np.zeros((K, 2)), np.zeros((K, 2, 2)), np.zeros((K, 2, 2, 2)),
            np.zeros((5, _ORDER + 1)), np.zeros((9, G)), np.zeros(G, dtype=np.int64), np.zeros((14, 64)),
            np.zeros(G, dtype=np.int64), np.zeros((2, _ORDER + 2), dtype=np.int64), np.zeros((10, G)),
        )  # fmt: skip

    _same(BEM, "bem_evaluate", evaluate, ("_smooth_kernels.py",))
    want = evaluate()
    importlib.import_module(BEM).bem_evaluate(*want)
    assert np.isfinite(want[-8]).all() and np.abs(want[-8]).max() > 0  # every point got its Hessian

    reach = rng.uniform(0.0, 0.05, K)
    ga, gb = sol._poles
    gg = np.concatenate([ga.T, gb.T])
    size = rng.uniform(0.0, 1.0, m)

    def bounds():
        return (
            p[:, 0].copy(), p[:, 1].copy(), reach, a[:, 0].copy(), a[:, 1].copy(), gg.real.copy(),
            gg.imag.copy(), np.abs(gg[:3]).real.copy() + 1.0, (b - a)[:, 0].copy(), (b - a)[:, 1].copy(),
            1.0 / ((b - a) ** 2).sum(axis=1), size, np.zeros((K, 3)),
        )  # fmt: skip

    _same(BEM, "bem_bounds", bounds, ("_smooth_kernels.py",))


def _compiles_of_two_at_once(script: str, tmp_path, printed: str, **env) -> str:
    """Two processes of ``script`` started together, with a cache of their own in ``tmp_path``
    (``NUMBA_CACHE_DIR``) and a log file as argument, in which each compile writes a line: each
    must succeed and print ``printed``. Returns the log."""
    import subprocess
    import sys

    log = tmp_path / "compiles.txt"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), **env}
    runs = [subprocess.Popen([sys.executable, "-c", script, str(log)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]  # fmt: skip
    for run in runs:
        out, err = run.communicate(timeout=300)
        assert run.returncode == 0, err
        assert out.strip() == printed
    return log.read_text()


def test_processes_needing_a_kernel_at_once_compile_it_once(tmp_path):
    """Two processes starting together on an empty cache (a farm, ``pytest -n``) need the same kernel:
    one compiles it (slowed down here, so that the other arrives meanwhile), the other waits for
    its file and loads it; both compute the right thing."""
    import textwrap

    script = textwrap.dedent(
        """
        import sys, time
        import numpy as np
        from warpcli import _native

        compile_ = _native._compile
        def slow_compile(*args):
            with open(sys.argv[1], "a") as fh:
                fh.write("compiled\\n")
            time.sleep(1.0)
            return compile_(*args)
        _native._compile = slow_compile
        k = _native.Kernels("warpcli.raster._kernels")
        out = np.zeros(3)
        k.store(np.array([0.4, 2.5, 300.0]), out, 0.0, 255.0, True)
        assert all(hasattr(f, "_native") for f in k._calls.values())  # the native route, not numba's
        print(out.tolist())
        """
    )
    assert _compiles_of_two_at_once(script, tmp_path, "[0.0, 2.0, 255.0]", WARPCLI_NATIVE="1") == "compiled\n"
    assert len(list((tmp_path / "cache" / "warpcli").glob("*.native"))) == 1


def test_processes_needing_a_numba_function_at_once_compile_it_once(tmp_path):
    """The same for the kernels numba calls itself (``@njit(cache=True)`` from `warpcli._jit`): one
    process compiles (slowed down here), the other waits and loads it from numba's cache."""
    import textwrap

    script = textwrap.dedent(
        """
        import sys, time
        import numpy as np
        import warpcli._jit
        from numba.core import dispatcher

        compile_ = dispatcher._FunctionCompiler.compile
        def slow_compile(self, *args, **kwargs):
            with open(sys.argv[1], "a") as fh:
                fh.write("compiled\\n")
            time.sleep(1.0)
            return compile_(self, *args, **kwargs)
        dispatcher._FunctionCompiler.compile = slow_compile
        from warpcli.raster import _kernels
        out = np.zeros(2, dtype=np.int64)
        _kernels.near_border(np.array([[0.5, 0.5], [40.0, 3.0]]), 31.0, 23.0, out)
        print(out.tolist())
        """
    )
    assert _compiles_of_two_at_once(script, tmp_path, "[0, 1]") == "compiled\n"
