"""Warps in strips (`warpcli.tiled`): the in-memory warp's output, in bounded memory."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import warpcli.raster.parts as parts
import warpcli.tiled as tiled
from warpcli.pipeline import warp_file
from warpcli.raster.resample import resample

from .helpers import read_pixels, run_cli, simple_polygons, star, write_png, write_polygon


@pytest.fixture
def small_strips(monkeypatch):
    """Strips of 16 rows and chunks of 24 columns, so that small images cross many of both."""
    monkeypatch.setattr(parts, "TILE", 16)
    monkeypatch.setattr(tiled, "TILE", 16)
    monkeypatch.setattr(tiled, "CHUNK", 24)


def _image(kind: str, rng, h: int = 130, w: int = 150):
    if kind == "rgb8":
        return rng.integers(0, 256, (h, w, 3)).astype(np.uint8), None
    if kind == "rgba16":  # straight alpha, blended premultiplied
        px = rng.integers(0, 65536, (h, w, 4)).astype(np.uint16)
        return px, 3
    if kind == "ids32":  # 32-bit ids, beyond float32's exact integers
        return rng.integers(0, 2**32, (h, w, 1), dtype=np.uint64).astype(np.uint32), None
    return rng.normal(0.5, 0.3, (h, w, 1)).astype(np.float32), None


def _both(tmp, src, dst, px, ext, **options):
    """The outputs of the in-memory warp and of the warp in strips."""
    inp = write_png(os.path.join(tmp, "in.tif" if px.shape[2] == 4 or px.dtype != np.uint8 else "in.png"), px)
    if px.shape[2] == 4:
        import OpenImageIO as oiio

        # A TIFF with a straight alpha channel named as such.
        out = oiio.ImageOutput.create(inp)
        spec = oiio.ImageSpec(px.shape[1], px.shape[0], 4, "uint16")
        spec.alpha_channel = 3
        spec.attribute("oiio:UnassociatedAlpha", 1)
        assert out.open(inp, spec) and out.write_image(px)
        out.close()
    a, b = write_polygon(os.path.join(tmp, "a.json"), src), write_polygon(os.path.join(tmp, "b.json"), dst)
    whole, parts_ = os.path.join(tmp, f"whole.{ext}"), os.path.join(tmp, f"parts.{ext}")
    warp_file(inp, whole, a, b, tiled=False, **options)
    warp_file(inp, parts_, a, b, tiled=True, **options)
    return read_pixels(whole), read_pixels(parts_)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    n=st.integers(5, 8),
    data=st.data(),
    interp=st.sampled_from(["linear", "nearest"]),
    kind=st.sampled_from(["rgb8", "rgba16", "float", "ids32"]),
    ext=st.sampled_from(["png", "tif", "exr"]),
    scale=st.sampled_from([1.0, 0.45, 1.15]),
    size=st.sampled_from([None, (97, 141)]),
)
def test_strips_give_the_in_memory_output_bit_for_bit(small_strips, tmp_path_factory, n, data, interp, kind, ext, scale, size):
    # Random simple polygons of either orientation, the target scaled (0.45:
    # the map shrinks, so pixels average wide footprints) and an output of
    # another size: every strip and chunk boundary, the window's edges, the
    # edge coverage and the footprints must come out as in one piece.
    src = data.draw(simple_polygons(n))
    dst = data.draw(simple_polygons(n))
    dst = 64.0 + (dst - 64.0) * scale
    if kind in ("float", "ids32") and ext == "png":
        ext = "tif"
    px, _ = _image(kind, np.random.default_rng(n))
    whole, strips = _both(str(tmp_path_factory.mktemp("t")), src, dst, px, ext, interp=interp, size=size)
    assert whole.dtype == strips.dtype and whole.shape == strips.shape
    assert whole.tobytes() == strips.tobytes()


def test_cubic_in_strips_agrees_to_rounding(small_strips, tmp_path):
    px, _ = _image("rgb8", np.random.default_rng(5))
    whole, strips = _both(str(tmp_path), star(7), star(7, r_in=30, phase=0.2), px, "png", interp="cubic")
    assert np.abs(whole.astype(int) - strips.astype(int)).max() <= 1


@pytest.fixture
def reads(monkeypatch):
    """The pixel count of every part of the input read, in order."""
    counts = []
    real = parts.PartReader.read

    def read(self, x0, y0, x1, y1):
        counts.append((x1 - x0) * (y1 - y0))
        return real(self, x0, y0, x1, y1)

    monkeypatch.setattr(parts.PartReader, "read", read)
    return counts


def test_a_chunk_that_reaches_too_much_input_is_split_with_the_same_result(small_strips, reads, monkeypatch, tmp_path):
    # A strong shrink: each output pixel averages a wide footprint, so the
    # parts read are large; with a budget of ~1000 RGB pixels chunks halve
    # down to a few pixels, each read on its own.
    monkeypatch.setattr(tiled, "PART_BYTES", 3000)
    px, _ = _image("rgb8", np.random.default_rng(6))
    src = star(6, r_in=40, r_out=62)
    dst = 64.0 + (star(6, r_in=40, r_out=62, phase=0.1) - 64.0) * 0.12
    whole, strips = _both(str(tmp_path), src, dst, px, "png")
    assert whole.tobytes() == strips.tobytes()
    assert len(reads) > 20
    # Only chunks of one pixel may exceed the budget.
    assert sorted(reads)[len(reads) // 2] * 3 <= 3000


def test_parts_read_are_small_beside_the_image(small_strips, reads, tmp_path):
    px, _ = _image("rgb8", np.random.default_rng(7), h=300, w=320)
    src = star(9, cx=160, cy=150, r_in=90, r_out=140)
    dst = star(9, cx=160, cy=150, r_in=100, r_out=145, phase=0.15)
    whole, strips = _both(str(tmp_path), src, dst, px, "png")
    assert whole.tobytes() == strips.tobytes()
    # Strips of 16 rows and 24 columns read about 16 x 24 pixels plus the
    # map's displacement: never more than a small share of the 96,000.
    assert max(reads) < 0.05 * 300 * 320


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    interp=st.sampled_from(["linear", "nearest"]),
    spread=st.sampled_from([0.5, 3.0, 20.0]),
)
def test_resampling_a_part_reads_what_the_whole_image_gives(seed, interp, spread):
    # Points anywhere (inside, on and beyond the border), Jacobians from
    # magnifying to strongly shrinking, some unknown: the part `_reach` picks
    # must give the whole image's samples exactly.
    rng = np.random.default_rng(seed)
    h, w = 40, 55
    img = rng.integers(0, 256, (h, w, 2)).astype(np.uint8)
    centre = rng.uniform([-3, -3], [w + 3, h + 3])
    pts = centre + rng.normal(0, 4, (6, 7, 2))
    jac = rng.normal(0, spread, (6, 7, 2, 2))
    jac[0, :2] = np.nan
    pts[1, 3] = np.nan
    want = resample(img, pts, interp=interp, background=(7, 9), jacobian=jac)
    header = parts.ImageHeader(w, h, 2, np.dtype(np.uint8))
    x0, y0, x1, y1 = tiled._reach(pts, jac if interp == "linear" else None, None, header, 1)
    got = resample(img[y0:y1, x0:x1], pts, interp=interp, background=(7, 9), jacobian=jac, part=(x0, y0, w, h))
    assert got.tobytes() == want.tobytes()


def test_a_warp_too_large_for_memory_goes_to_strips_by_itself(monkeypatch, tmp_path):
    px, _ = _image("rgb8", np.random.default_rng(8))
    inp = write_png(tmp_path / "in.png", px)
    a, b = write_polygon(tmp_path / "a.json", star(6)), write_polygon(tmp_path / "b.json", star(6, phase=0.3))
    code, err = run_cli([inp, "--src", a, "--dst", b, tmp_path / "whole.png", "-q"])
    assert code == 0, err
    # 30 kB of pixels may be held: the image (58 kB) does not fit.
    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", "30000")
    code, err = run_cli([inp, "--src", a, "--dst", b, tmp_path / "strips.png", "-v"])
    assert code == 0, err
    assert "warping in strips" in err
    assert read_pixels(tmp_path / "whole.png").tobytes() == read_pixels(tmp_path / "strips.png").tobytes()


@pytest.mark.parametrize(
    "extra",
    [["--grid", "g.png"], ["--report", "r.json"], ["--save-map", "m.exr"], ["--outside", "input", "--size", "40x30"]],
)
def test_what_needs_the_whole_image_is_refused_in_strips(tmp_path, extra):
    px, _ = _image("rgb8", np.random.default_rng(9))
    inp = write_png(tmp_path / "in.png", px)
    a, b = write_polygon(tmp_path / "a.json", star(6)), write_polygon(tmp_path / "b.json", star(6, phase=0.3))
    extra = [str(tmp_path / e) if e.endswith((".png", ".json", ".exr")) else e for e in extra]
    code, err = run_cli([inp, "--src", a, "--dst", b, tmp_path / "out.png", "--tiled", *extra])
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert sorted(os.listdir(tmp_path)) == ["a.json", "b.json", "in.png"]


@pytest.mark.parametrize(
    ("kind", "options"),
    [
        ("rgba16", {"vacated": "background", "background": (0.2, 0.4, 0.6, 1.0)}),
        ("rgb8", {"feather": 6.0}),
        ("float", {"vacated": "background", "feather": 3.5, "interp": "nearest"}),
    ],
)
def test_a_retouch_in_strips_is_the_in_memory_retouch_bit_for_bit(small_strips, tmp_path, kind, options):
    # --outside input in parts: each strip's input with the warp pasted over it (the vacated source, the
    # feather's band and the untouched pixels cross strip and chunk boundaries).
    px, _ = _image(kind, np.random.default_rng(12))
    src = star(6, 70, 62, 20, 50)
    dst = star(6, 78, 60, 22, 52, phase=0.2)
    whole, strips = _both(str(tmp_path), src, dst, px, "tif", outside="input", **options)
    assert whole.tobytes() == strips.tobytes()
    assert not np.array_equal(whole, px)


def test_jpeg_is_refused_before_any_work(tmp_path):
    px, _ = _image("rgb8", np.random.default_rng(10))
    inp = write_png(tmp_path / "in.png", px)
    a, b = write_polygon(tmp_path / "a.json", star(6)), write_polygon(tmp_path / "b.json", star(6, phase=0.3))
    code, err = run_cli([inp, "--src", a, "--dst", b, tmp_path / "out.jpg", "--tiled"])
    assert code == 2 and "JPEG cannot be written in parts" in err
    assert sorted(os.listdir(tmp_path)) == ["a.json", "b.json", "in.png"]


def test_a_batch_warps_an_image_too_large_for_memory_in_strips(monkeypatch, tmp_path):
    from warpcli.batch import warp_batch

    rng = np.random.default_rng(11)
    small = write_png(tmp_path / "small.png", rng.integers(0, 256, (40, 50, 3)).astype(np.uint8))
    big = write_png(tmp_path / "big.png", rng.integers(0, 256, (130, 150, 3)).astype(np.uint8))
    a, b = write_polygon(tmp_path / "a.json", star(6)), write_polygon(tmp_path / "b.json", star(6, phase=0.3))
    (tmp_path / "whole").mkdir()
    (tmp_path / "strips").mkdir()
    assert all(i.error is None for i in warp_batch([small, big], tmp_path / "whole", a, b))
    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", "30000")  # the big image (58 kB) does not fit
    items = warp_batch([small, big], tmp_path / "strips", a, b)
    assert [i.error for i in items] == [None, None]
    for name in ("small.png", "big.png"):
        assert read_pixels(tmp_path / "whole" / name).tobytes() == read_pixels(tmp_path / "strips" / name).tobytes()


@pytest.mark.parametrize("ext", ["png", "tif", "exr"])
def test_a_file_size_limit_in_strips_is_one_line_naming_the_output_and_leaves_nothing(tmp_path, ext):
    # RLIMIT_FSIZE (ulimit -f) in a subprocess: the write of a strip fails
    # with EFBIG part way through the file.
    import resource
    import subprocess
    import sys

    px = np.random.default_rng(12).integers(0, 256, (256, 256, 3)).astype(np.uint8)
    inp = write_png(tmp_path / "in.png", px)
    frame = write_polygon(tmp_path / "f.json", [[0, 0], [256, 0], [256, 256], [0, 256]])
    (tmp_path / "out").mkdir()
    out = tmp_path / "out" / f"o.{ext}"
    done = subprocess.run(
        [sys.executable, "-m", "warpcli", inp, "--src", frame, "--dst", frame, str(out), "--tiled", "--interp", "nearest"],
        capture_output=True, text=True, timeout=300,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536)),
    )  # fmt: skip
    assert done.returncode == 1
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"warp: error: {out}: cannot write: File too large"), lines
    assert ".warpcli-" not in done.stderr
    assert os.listdir(tmp_path / "out") == []


def test_an_input_cut_short_is_one_line_exit_2_and_leaves_nothing(tmp_path):
    import OpenImageIO as oiio

    px = np.random.default_rng(13).integers(0, 256, (200, 180, 3)).astype(np.uint8)
    whole = str(tmp_path / "whole.tif")
    out = oiio.ImageOutput.create(whole)
    spec = oiio.ImageSpec(180, 200, 3, "uint8")
    spec.tile_width = spec.tile_height = 32
    spec.attribute("compression", "none")
    assert out.open(whole, spec) and out.write_image(px)
    out.close()
    data = (tmp_path / "whole.tif").read_bytes()
    cut = tmp_path / "cut.tif"
    cut.write_bytes(data[: len(data) // 2])
    a = write_polygon(tmp_path / "a.json", [[0, 0], [180, 0], [180, 200], [0, 200]])
    b = write_polygon(tmp_path / "b.json", [[5, 0], [180, 9], [170, 200], [0, 190]])
    (tmp_path / "out").mkdir()
    code, err = run_cli([cut, "--src", a, "--dst", b, tmp_path / "out" / "o.tif", "--tiled"])
    assert code == 2 and err.startswith(f"warp: error: {cut}: cannot read image") and len(err.strip().splitlines()) == 1
    assert os.listdir(tmp_path / "out") == []


def test_a_header_declaring_far_more_pixels_than_its_file_holds_is_refused(tmp_path, monkeypatch):
    # A 30000 x 30000 PNG header with 4 kB after it: too large for memory
    # (the limit lowered to 100 MiB), and not taken into strips unasked,
    # where it would be decoded for minutes: one line, exit 2, no output.
    from .test_imageio import png_of_zeros

    full = png_of_zeros(tmp_path / "full.png", 30000, 30000)
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(open(full, "rb").read()[:4096])
    os.unlink(full)
    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", str(100 * 2**20))
    a = write_polygon(tmp_path / "a.json", star(6))
    code, err = run_cli([bomb, "--src", a, "--dst", a, tmp_path / "out.png"])
    assert code == 2 and "decompression bomb" in err and len(err.strip().splitlines()) == 1
    assert sorted(os.listdir(tmp_path)) == ["a.json", "bomb.png"]


@pytest.mark.parametrize("seed", range(4))
def test_a_band_scans_only_its_own_triangles_and_finds_the_same_pixels(seed):
    # evaluate_grid(rows=) restricted to the triangles that can reach the band
    # (linear in the height, not quadratic) gives what scanning every
    # triangle gives, band by band.
    from helpers import star
    from warpcli import MapOptions, Polygon
    from warpcli.maps.compose import BijectiveMap
    from warpcli.maps.fem import _compiled

    rng = np.random.default_rng(seed)
    h = int(rng.integers(60, 400))
    src = Polygon(star(cx=32, cy=h / 2, r_in=10, r_out=h / 2 - 3, phase=rng.uniform(0, 1)))
    dst = Polygon(star(cx=32, cy=h / 2, r_in=12, r_out=h / 2 - 5, phase=rng.uniform(0, 1)))
    phi = BijectiveMap.between(src, dst, MapOptions()).phi0
    for r0 in range(0, h, int(rng.integers(3, 40))):
        r1 = min(h, r0 + int(rng.integers(1, 40)))
        band = phi.evaluate_grid(64, h, (r0, r1))
        size = (r1 - r0) * 64
        pixels, values, where = np.empty(size, np.int64), np.empty((size, 2)), np.empty(size, np.int32)
        count = _compiled.scan_grid(
            phi.mesh.vertices, phi._triangles, phi._domain_coefficients, phi.values, phi._coherent_order,
            64, h, r0, r1, np.zeros(size, np.uint8), pixels, values, where,
        )  # fmt: skip
        assert np.array_equal(band.pixels, pixels[:count]) and np.array_equal(band.values, values[:count])


@pytest.mark.parametrize("width,height", [(8, 3000), (5, 1200), (40, 2500)])
def test_strips_of_a_thin_image_compute_each_band_once_and_agree_with_the_whole(width, height):
    # A band (BAND_PIXELS / width rows) taller than a strip was computed again
    # for every strip: quadratic in the height. Each band is now evaluated
    # once, and the strips put together are the whole pull-back.
    from warpcli import MapOptions, Polygon
    from warpcli.maps.compose import BijectiveMap

    src = Polygon(np.array([[1, 1], [width - 1, 1], [width - 1, height - 1], [1, height - 1]], float))
    dst = Polygon(np.array([[1, 1], [width - 1, 2], [width - 1.5, height - 1], [1.5, height - 2]], float))
    fmap = BijectiveMap.between(src, dst, MapOptions())
    whole = fmap.pull_back(width, height)
    phi = fmap.phi1
    calls = []
    real = type(phi).grid_cells  # what a pull-back with Jacobians scans a FEM band with

    def counted(self, w, h, rows=None, **k):
        calls.append(rows)
        return real(self, w, h, rows, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(type(phi), "grid_cells", counted)
        strips = [fmap.pull_back(width, height, rows=(r, min(r + 256, height))) for r in range(0, height, 256)]
    assert len(calls) == len(set(calls)) >= 1  # no band twice (and the bands were counted)
    got = np.full((height, width, 2), np.nan)
    for s in strips:
        (r0, c0), pts = s.origin, s.points
        got[r0 : r0 + pts.shape[0], c0 : c0 + pts.shape[1]] = pts
    ref = np.full((height, width, 2), np.nan)
    (r0, c0), pts = whole.origin, whole.points
    ref[r0 : r0 + pts.shape[0], c0 : c0 + pts.shape[1]] = pts
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize(
    "extra, strips",
    [({}, True), ({"interp": "nearest"}, True), ({"method": "mfs"}, True), ({"interp": "cubic"}, False),
     ({"outside": "input"}, False), ({"report_path": "r.json"}, False), ({"output": "o.jpg"}, False)],
)  # fmt: skip
def test_prefer_strips_takes_strips_only_where_they_write_the_same_bytes(tmp_path, monkeypatch, small_strips, extra, strips):
    # The warp command prefers strips for large outputs (issue 24: 0.45 GB instead
    # of 0.8 GB at 12 MP): here every output is "large"; strips must write the
    # whole warp's bytes, and be refused where they would not (cubic, a paste,
    # a report, JPEG).
    import warpcli.pipeline as pipeline

    monkeypatch.setattr(pipeline, "STRIP_PIXELS", 100)
    rng = np.random.default_rng(3)
    inp = write_png(tmp_path / "in.png", rng.integers(0, 256, (70, 90, 3)).astype(np.uint8))
    a = write_polygon(tmp_path / "a.json", star(6, 45, 35, 12, 33))
    b = write_polygon(tmp_path / "b.json", star(6, 45, 35, 10, 33, phase=0.25))
    extra = dict(extra)
    name = extra.pop("output", "o.png")
    if "report_path" in extra:
        extra["report_path"] = tmp_path / extra["report_path"]
    got = warp_file(inp, tmp_path / f"s_{name}", a, b, prefer_strips=True, **extra)
    whole = warp_file(inp, tmp_path / f"w_{name}", a, b, **extra)
    assert isinstance(got, tiled.TiledResult) == strips and not isinstance(whole, tiled.TiledResult)
    assert (tmp_path / f"s_{name}").read_bytes() == (tmp_path / f"w_{name}").read_bytes()


def test_strips_made_ahead_come_in_order_and_an_error_making_one_is_raised_by_the_writer():
    """`warpcli.tiled._Ahead`: strips made on a thread, one ahead of the writer."""
    import itertools

    from warpcli.errors import ImageInputError
    from warpcli.tiled import _Ahead

    made = [int(s[0]) for s in _Ahead(np.full(2, k) for k in range(40))]
    assert made == list(range(40))

    def failing():
        yield np.zeros(1)
        raise ImageInputError("in.png: cannot read image: cut short")

    got = []
    with pytest.raises(ImageInputError, match="cut short"):
        for strip in _Ahead(failing()):
            got.append(strip)
    assert len(got) == 1
    endless = _Ahead(np.full(1, k) for k in itertools.count())
    next(iter(endless))
    endless.stop()  # the writer failed: the thread ends after the strip it is making
    endless._task.result()


def test_strips_made_from_plans_made_ahead_come_in_order_and_stopping_ends_both_threads():
    """Two `warpcli.tiled._Ahead` in a row (plans, then strips, as `warp_file_tiled` makes them): the
    strips in order, an error making a plan raised by the writer, and `stop` ending both threads
    wherever each one is (a thread left waiting would keep the process from exiting)."""
    import itertools
    import time

    from warpcli.errors import ImageInputError
    from warpcli.tiled import _Ahead

    def chain(plans):
        ahead = _Ahead(plans, name="warp-plans")
        return ahead, _Ahead((2 * p for p in ahead), upstream=ahead)

    _, made = chain(np.full(2, k) for k in range(40))
    assert [int(s[0]) for s in made] == [2 * k for k in range(40)]

    def failing():
        yield np.zeros(1)
        raise ImageInputError("in.png: cannot read image: cut short")

    got = []
    with pytest.raises(ImageInputError, match="cut short"):
        for strip in chain(failing())[1]:
            got.append(strip)
    assert len(got) == 1
    def slow():  # plans slower than the strips: the strips' thread waits for the next plan
        for k in itertools.count():
            time.sleep(0.03)
            yield np.full(1, k)

    for taken, plans in itertools.product((0, 1, 2, 5), (lambda: (np.full(1, k) for k in itertools.count()), slow)):
        ahead, made = chain(plans())  # the writer fails after ``taken`` strips
        for _ in itertools.islice(made, taken):
            pass
        made.stop()
        for task in (made._task, ahead._task):
            task._thread.join(timeout=10)
            assert not task._thread.is_alive()


def test_a_strip_that_fails_once_the_writer_has_stopped_does_not_hold_its_thread():
    """The writer fails while the strips' thread waits to hand on the next strip; the strip after
    that fails too (its input is being closed). `stop` returns once the thread has ended, with
    nothing waiting in a queue nobody reads (a thread left waiting kept the process from exiting)."""
    import itertools
    import threading
    import time

    from warpcli.tiled import _Ahead

    for delay in (0.0, 0.02, 0.1):
        closing = threading.Event()

        def strips(closing=closing):
            for k in itertools.count():
                if closing.is_set():
                    raise OSError("the input was closed")
                yield np.full(1, k)

        made = _Ahead(strips())
        first = next(iter(made))
        assert int(first[0]) == 0
        time.sleep(delay)  # the thread has made the next strips and waits to hand one on
        closing.set()
        made.stop()
        assert not made._task._thread.is_alive()


@pytest.mark.parametrize("most, planned_ahead", [(None, True), (0, False)])
def test_plans_are_made_ahead_only_where_they_are_small(tmp_path, monkeypatch, small_strips, most, planned_ahead):
    """A strip's plan is 48 bytes a pixel: an image too wide for `tiled.AHEAD_PLAN_BYTES` plans each
    strip when it is resampled (memory bounded by one plan), with the same bytes."""
    from warpcli.cores import jobs

    made = []
    real = tiled._Ahead.__init__

    def named(self, items, *, name="warp-strips", upstream=None):
        made.append(name)
        real(self, items, name=name, upstream=upstream)

    monkeypatch.setattr(tiled._Ahead, "__init__", named)
    if most is not None:
        monkeypatch.setattr(tiled, "AHEAD_PLAN_BYTES", most)
    px = np.random.default_rng(3).integers(0, 256, (70, 90, 3)).astype(np.uint8)
    inp = write_png(tmp_path / "in.png", px)
    a = write_polygon(tmp_path / "a.json", star(6, 45, 35, 12, 33))
    b = write_polygon(tmp_path / "b.json", star(6, 45, 35, 10, 33, phase=0.25))
    with jobs(2):
        warp_file(inp, tmp_path / "s.png", a, b, tiled=True)
    warp_file(inp, tmp_path / "w.png", a, b)
    assert ("warp-plans" in made) == planned_ahead and "warp-strips" in made
    assert (tmp_path / "s.png").read_bytes() == (tmp_path / "w.png").read_bytes()


@pytest.mark.parametrize("channels, dtype, as_is", [(4, np.uint8, False), (1, np.uint16, True), (3, np.uint8, True)])
def test_strips_of_an_image_decoded_while_the_map_is_built_write_the_bytes_of_strips_read_in_parts(
    tmp_path, monkeypatch, small_strips, channels, dtype, as_is
):
    """Strips preferred for their memory (``prefer_strips``) of a PNG that fits: its pixels are decoded
    while the map is built and cut into parts in memory (`warpcli.tiled._Decoded`), with the bytes of
    strips read from the file in parts (``--tiled``) and of the whole warp, for any PNG's channels and depth.
    Runs of rows are sampled from the decoded image as it is only where the samplers read it as it is:
    a PNG's straight alpha is premultiplied into a copy of what a call samples, which would be the
    whole image for every run (a 10 MP RGBA PNG took 2.9 s instead of 1.2 s), so parts are cut."""
    import warpcli.pipeline as pipeline

    monkeypatch.setattr(pipeline, "STRIP_PIXELS", 100)
    decoded, whole = [], []
    real = tiled._Decoded.__init__
    real_whole = tiled._Sampler._from_whole

    def keep(self, pixels):
        decoded.append(pixels.shape)
        real(self, pixels)

    def spy(self, pixels, *args):
        whole.append(pixels.shape)
        return real_whole(self, pixels, *args)

    monkeypatch.setattr(tiled._Decoded, "__init__", keep)
    monkeypatch.setattr(tiled._Sampler, "_from_whole", spy)
    rng = np.random.default_rng(channels)
    px = rng.integers(0, np.iinfo(dtype).max, (70, 90, channels), endpoint=True).astype(dtype)
    inp = write_png(tmp_path / "in.png", px)
    a = write_polygon(tmp_path / "a.json", star(6, 45, 35, 12, 33))
    b = write_polygon(tmp_path / "b.json", star(6, 45, 35, 10, 33, phase=0.25))
    got = warp_file(inp, tmp_path / "s.png", a, b, prefer_strips=True)
    assert isinstance(got, tiled.TiledResult) and decoded == [(70, 90, channels)]
    assert bool(whole) == as_is
    warp_file(inp, tmp_path / "t.png", a, b, tiled=True)
    warp_file(inp, tmp_path / "w.png", a, b)
    assert len(decoded) == 1  # --tiled reads parts of the file
    assert (tmp_path / "s.png").read_bytes() == (tmp_path / "t.png").read_bytes() == (tmp_path / "w.png").read_bytes()


def test_a_writer_that_cannot_open_stops_the_plans_made_meanwhile(tmp_path, monkeypatch, small_strips):
    """The strips' plans start before the output is opened (its first opening in a process loads
    OpenImageIO's colour configuration): a writer that fails to open stops them, and leaves no
    thread and no output behind."""
    import threading

    from warpcli.errors import ImageIOError

    planned, started = [], threading.Event()
    real_plan = tiled._Sampler.plan

    def plan(self, *args):
        started.set()
        planned.append(args[2])
        return real_plan(self, *args)

    def refuse(self, filename, shown_name, *args):
        assert started.wait(10)  # planning began before the writer opened
        raise ImageIOError(f"{shown_name}: cannot write: refused for the test")

    monkeypatch.setattr(tiled._Sampler, "plan", plan)
    monkeypatch.setattr(tiled, "StripWriter", type("Refusing", (), {"__init__": refuse}))
    _strips_fail_cleanly(tmp_path, ImageIOError, "refused for the test")
    assert planned  # the plans thread ran


def _strips_fail_cleanly(tmp_path, error, match):
    """A strip-by-strip warp on two cores raises ``error``, leaving no plans thread and no file."""
    import threading

    from warpcli.cores import jobs

    px = np.random.default_rng(4).integers(0, 256, (70, 90, 3)).astype(np.uint8)
    inp = write_png(tmp_path / "in.png", px)
    a = write_polygon(tmp_path / "a.json", star(6, 45, 35, 12, 33))
    b = write_polygon(tmp_path / "b.json", star(6, 45, 35, 10, 33, phase=0.25))
    with jobs(2), pytest.raises(error, match=match):
        warp_file(inp, tmp_path / "s.png", a, b, tiled=True)
    assert not [t for t in threading.enumerate() if t.name == "warp-plans" and t.is_alive()]
    assert sorted(os.listdir(tmp_path)) == ["a.json", "b.json", "in.png"]


def test_strips_whose_thread_cannot_start_abandon_the_output_and_stop_the_plans(tmp_path, monkeypatch, small_strips):
    """No thread left for the strips (``can't start new thread``): the plans' thread stops, the
    half-opened output is abandoned, and the error is the run's."""
    real = tiled._Ahead.__init__

    def no_strips_thread(self, items, *, name="warp-strips", upstream=None):
        if name == "warp-strips":
            raise RuntimeError("can't start new thread")
        real(self, items, name=name, upstream=upstream)

    monkeypatch.setattr(tiled._Ahead, "__init__", no_strips_thread)
    _strips_fail_cleanly(tmp_path, RuntimeError, "new thread")
