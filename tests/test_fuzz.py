"""Fuzzing the whole command with hostile polygons: never a traceback, never a fold-over.

Each example writes a polygon pair and runs ``warp`` in-process on a small
image, with --report on stdout. Whatever the polygons (slivers, spikes,
near-touching arms, 1e-9 edges, coordinates near 1e6 and 1e9, thousands of
vertices, pairs that miss or cover the image, garbage), the run ends with
exit 0 (a written image and a report with no flipped element) or exit 2 (one
line on stderr naming a file, nothing written), within a time and a memory bound.

CI runs a fixed, derandomized set (the "warpcli" profile) with one far polygon
around the image (`FAR_AROUND_THE_IMAGE`; drawn ones lie beside it); set
WARPCLI_FUZZ=long for the profile of longer local runs (see conftest.py), and
WARPCLI_FUZZ_LOG=FILE to append each example as JSON to FILE (to replay a crash).
"""

from __future__ import annotations

import io
import json
import math
import os
import signal
import time
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from helpers import simple_polygons, write_png, write_polygon
from warpcli.cli import main

#: Seconds one example may take (in-process; the bound catches hangs and blow-ups).
TIME_LIMIT = 60
#: Bytes of resident memory one example may add to the test process at its peak (the
#: issue's cases took 2.9 GB, 8 GB and 24 GB; a 64 x 48 warp needs a few MB).
MEMORY_LIMIT = 1 << 30


class _PeakRSS:
    """The growth of this process's peak resident memory over the block.

    Linux resets the high-water mark (VmHWM) when "5" is written to
    /proc/self/clear_refs; the block's own peak is then VmHWM at its end.
    Where that is not allowed, the growth of the lifetime peak is what shows.
    """

    def __enter__(self):
        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
        except OSError:
            pass
        self.start = self._status("VmRSS")
        return self

    @staticmethod
    def _status(key: str) -> int:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
        raise KeyError(key)

    def __exit__(self, *exc):
        self.peak = self._status("VmHWM")

    @property
    def growth(self) -> int:
        return self.peak - self.start


#: The profile of longer local runs (conftest.py): the far polygons around the image are drawn too.
LONG = os.environ.get("WARPCLI_FUZZ") == "long"

#: The costliest pair of the "far" class, run in every profile: a source 2e6 px wide beside
#: the input, a target 2e9 px wide around the output (its graded mesh is 440k triangles,
#: 650 MB at the peak: the memory bound's case).
FAR_AROUND_THE_IMAGE = (
    [[2e6, 2e6], [4e6, 2e6], [4e6, 4e6], [2e6, 4e6]],
    [[-1e9, -1e9], [1e9, -1e9], [1e9, 1e9], [-1e9, 1e9]],
)


def _scaled(points, scale, offset):
    return np.asarray(points, dtype=float) * scale + offset


@st.composite
def hostile(draw, n: int):
    """One polygon with n vertices (or about n), drawn from a family of hard cases."""
    kind = draw(st.sampled_from(["valid", "sliver", "spike", "arms", "tiny-edge", "far", "garbage", "dense"]))
    if kind == "valid":
        pts = np.asarray(draw(simple_polygons(n)))
        pts = _scaled(pts, draw(st.sampled_from([1e-3, 0.05, 1.0, 40.0, 1e4])), draw(st.sampled_from([0.0, -30.0, 1e6])))
    elif kind == "sliver":
        h = draw(st.sampled_from([1e-12, 1e-9, 1e-6, 1e-4, 1e-2]))
        pts = np.array([[2.0, 20.0], [60.0, 20.0], [31.0, 20.0 + h]])
    elif kind == "spike":
        k = np.arange(n)
        r = np.where(k == 0, draw(st.sampled_from([100.0, 1e4, 1e8])), 15.0)
        a = 2 * math.pi * k / n + np.where(k == 0, 0.0, 0.3)
        pts = np.stack([32 + r * np.cos(a), 24 + r * np.sin(a)], axis=1)
    elif kind == "arms":
        gap = draw(st.sampled_from([1e-9, 1e-6, 1e-3, 0.1]))
        pts = np.array([[4, 4], [60, 4], [60, 20], [10, 20], [10, 20 + gap], [60, 20 + gap], [60, 44], [4, 44]], float)
    elif kind == "tiny-edge":
        pts = np.asarray(draw(simple_polygons(n)), dtype=float) * 0.4
        pts = np.insert(pts, 1, pts[0] + [1e-9, 1e-9], axis=0)
    elif kind == "far":
        s = draw(st.sampled_from([1e6, 1e7, 1e9]))
        # Centred on the image (a graded mesh of 260k-440k triangles, 5-11 s of CPU each) or
        # beside it; the default run draws only the latter and runs one centred pair
        # (`FAR_AROUND_THE_IMAGE`), the long run draws both.
        pts = np.array([[-s, -s], [s, -s], [s, s], [-s, s]]) + draw(st.sampled_from([0.0, 3.0 * s] if LONG else [3.0 * s]))
    elif kind == "garbage":
        pts = np.asarray(draw(st.lists(st.tuples(st.floats(-100, 200), st.floats(-100, 200)), min_size=3, max_size=9)))
    else:  # dense: thousands of vertices on a wavy circle
        m = draw(st.sampled_from([1000, 5000]))
        a = 2 * math.pi * np.arange(m) / m
        r = 20 * (1 + 0.2 * np.sin(7 * a))
        pts = np.stack([32 + r * np.cos(a), 24 + r * np.sin(a)], axis=1)
    return pts


@st.composite
def pairs(draw):
    n = draw(st.integers(3, 12))
    src = draw(hostile(n))
    same_count = draw(st.booleans())
    dst = draw(hostile(len(src))) if same_count else draw(hostile(n))
    if same_count and len(dst) != len(src):
        dst = dst[: len(src)] if len(dst) > len(src) else dst
    return src, dst


class _TimeLimit(Exception):
    pass


def _alarm(signum, frame):
    raise _TimeLimit()


@given(pairs())
@example(FAR_AROUND_THE_IMAGE)
@settings(suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.function_scoped_fixture])
def test_hostile_polygon_pairs(tmp_path_factory, pair):
    d = tmp_path_factory.mktemp("fuzz")
    img = write_png(d / "in.png", np.full((48, 64, 3), 120, dtype=np.uint8))
    src = d / "src.json"
    dst = d / "dst.json"
    with open(src, "w") as fh:
        json.dump(np.asarray(pair[0]).tolist(), fh)
    with open(dst, "w") as fh:
        json.dump(np.asarray(pair[1]).tolist(), fh)
    out = d / "out.png"
    if os.environ.get("WARPCLI_FUZZ_LOG"):
        with open(os.environ["WARPCLI_FUZZ_LOG"], "a") as fh:
            fh.write(json.dumps([np.asarray(p).tolist() for p in pair]) + "\n")
    err, stdout = io.StringIO(), io.StringIO()
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIME_LIMIT)
    t0 = time.monotonic()
    try:
        with redirect_stderr(err), redirect_stdout(stdout), _PeakRSS() as memory:
            code = main([str(img), str(out), "--src", str(src), "--dst", str(dst), "--report", "-"])
    except _TimeLimit:
        pytest.fail(f"more than {TIME_LIMIT} s: {pair}")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    lines = err.getvalue().splitlines()
    assert "Traceback" not in err.getvalue()
    assert all(line.startswith("warp: ") for line in lines), lines
    if code == 0:
        assert out.exists()
        report = json.loads(stdout.getvalue())
        assert report["flipped_triangles"] == 0
    else:
        assert code == 2, (code, lines)
        errors = [line for line in lines if line.startswith("warp: error: ")]
        assert len(errors) == 1 and (str(src) in errors[0] or str(dst) in errors[0] or "vertices" in errors[0]), lines
        assert sorted(os.listdir(d)) == ["dst.json", "in.png", "src.json"]
    assert time.monotonic() - t0 < TIME_LIMIT
    assert memory.growth < MEMORY_LIMIT, (memory.growth >> 20, pair)


# ---------------------------------------------------------------------------
# Every subcommand: an output is never an input of the run, nor private.


def _run(args):
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        code = main([str(a) for a in args])
    return code, err.getvalue()


def _square_run(d, size=16):
    img = write_png(d / "in.png", np.full((size, size, 3), 90, dtype=np.uint8))
    frame = write_polygon(d / "frame.json", [[0, 0], [size, 0], [size, size], [0, size]])
    return img, frame


def _snapshot(d):
    return {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()}


@st.composite
def colliding_sequences(draw):
    """An input pattern, an output pattern and frames where some output frame is another input frame.

    ``f.@.png`` -> ``f.D@.png``: output frame k is input frame int("D" + str(k)) when that is a frame too.
    """
    digit = draw(st.integers(1, 9))
    k = draw(st.integers(0, 9))
    frames = sorted({k, int(f"{digit}{k}")} | set(draw(st.lists(st.integers(0, 99), max_size=3))))
    return "f.@.png", f"f.{digit}@.png", frames


@given(colliding_sequences())
@settings(max_examples=8, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
def test_a_sequence_output_frame_that_is_another_input_frame_is_refused(tmp_path_factory, case):
    inp, out, frames = case
    d = tmp_path_factory.mktemp("seq")
    img, frame = _square_run(d)
    for f in frames:
        (d / inp.replace("@", str(f))).write_bytes(open(img, "rb").read())
    before = _snapshot(d)
    code, err = _run([d / inp, d / out, "--frames", ",".join(map(str, frames)), "--src", frame, "--dst", frame])
    assert code == 2 and err.count("\n") == 1 and "output would overwrite the input" in err, err
    assert _snapshot(d) == before


def test_a_batch_output_that_is_another_input_is_refused(tmp_path):
    img, frame = _square_run(tmp_path)
    other = tmp_path / "in_w.png"
    other.write_bytes(open(img, "rb").read())
    before = _snapshot(tmp_path)
    # in.png -> in_w.png, which is the batch's second input.
    code, err = _run([img, other, "--out-dir", tmp_path, "--out-name", "{stem}_w{ext}", "--src", frame, "--dst", frame])
    assert code == 2 and "output would overwrite the input" in err and err.count("\n") == 1, err
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize("which", ["src", "dst", "theta"])
@pytest.mark.parametrize("command", ["points", "report", "save-theta", "batch-theta"])
def test_no_subcommand_writes_over_a_polygon_or_theta_file(tmp_path, command, which):
    img, _ = _square_run(tmp_path)
    src = write_polygon(tmp_path / "src.json", [[1, 1], [15, 1], [15, 15], [1, 15]])
    dst = write_polygon(tmp_path / "dst.json", [[2, 1], [15, 2], [14, 15], [1, 14]])
    theta = write_polygon(tmp_path / "theta.json", [[0, 0], [1, 0], [1, 1], [0, 1]])
    victim = {"src": src, "dst": dst, "theta": theta}[which]
    (tmp_path / "od").mkdir()
    common = ["--src", src, "--dst", dst, "--theta", theta]
    if command == "points":
        (tmp_path / "p.json").write_text("[[5, 5]]")
        args = ["points", tmp_path / "p.json", victim, *common]
    elif command == "batch-theta":
        if which != "theta":
            pytest.skip("a batch's outputs are images")
        args = [img, "--out-dir", tmp_path, "--out-name", "theta.json", *common]
    else:
        args = [img, tmp_path / "o.png", f"--{command}", victim, *common]
    before = _snapshot(tmp_path)
    code, err = _run(args)
    assert code == 2 and err.count("\n") == 1, err
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002, 0o027])
def test_outputs_get_the_permissions_open_gives(tmp_path, umask):
    img, frame = _square_run(tmp_path)
    (tmp_path / "p.csv").write_text("5,5\n")
    kept = tmp_path / "kept.json"
    kept.write_text("{}")
    kept.chmod(0o640)
    old = os.umask(umask)
    try:
        code, err = _run([img, tmp_path / "o.png", "--src", frame, "--dst", frame, "--report", tmp_path / "r.json",
                          "--save-theta", tmp_path / "t.json", "--save-map", tmp_path / "m.exr"])  # fmt: skip
        assert code == 0, err
        code, err = _run(["points", tmp_path / "p.csv", tmp_path / "q.csv", "--src", frame, "--dst", frame])
        assert code == 0, err
        code, err = _run([img, tmp_path / "o2.png", "--src", frame, "--dst", frame, "--report", kept])
        assert code == 0, err
    finally:
        os.umask(old)
    for name in ("o.png", "r.json", "t.json", "m.exr", "q.csv", "o2.png"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~umask, name
    assert kept.stat().st_mode & 0o777 == 0o640  # a replaced file keeps its mode


@given(st.lists(st.tuples(st.integers(0, 15), st.integers(0, 15)), min_size=1, max_size=5), st.integers(0, 2))
@settings(max_examples=6, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
def test_a_byte_order_mark_is_not_data(tmp_path_factory, points, kind):
    d = tmp_path_factory.mktemp("bom")
    _, frame = _square_run(d)
    bom = b"\xef\xbb\xbf"
    if kind == 0:
        body, name = "".join(f"{x}.5,{y}.25\n" for x, y in points).encode(), "p.csv"
    elif kind == 1:
        body, name = json.dumps([[x + 0.5, y + 0.25] for x, y in points]).encode(), "p.json"
    else:
        body = "".join(f"vt {x / 16:.9g} {1 - y / 16:.9g}\n" for x, y in points).encode() + b"f 1/1 1/1 1/1\n"
        name = "p.obj"
    (d / name).write_bytes(bom + body)
    out = d / ("q" + name[1:])
    code, err = _run(["points", d / name, out, "--src", frame, "--dst", frame, "--texture-size", "16x16"])
    assert code == 0, err
    got = out.read_bytes()
    if kind == 0:
        rows = [tuple(map(float, ln.split(","))) for ln in got.decode("utf-8-sig").splitlines() if ln]
        assert np.allclose(rows, [(x + 0.5, y + 0.25) for x, y in points], atol=1e-6)  # identity: every point mapped
    elif kind == 2:
        assert got.startswith(bom) and got.count(b"vt ") == len(points)
        uv = [tuple(map(float, ln.split()[1:])) for ln in got.lstrip(bom).splitlines() if ln.startswith(b"vt")]
        assert np.allclose(uv, [(x / 16, 1 - y / 16) for x, y in points], atol=1e-6)


@pytest.mark.parametrize("other", ["uint16", "float32", "int8", "shape"])
@pytest.mark.parametrize("where", [0, 1, 3])
def test_a_tiff_stack_with_a_page_unlike_the_others_is_refused(tmp_path, other, where):
    tifffile = pytest.importorskip("tifffile")
    from warpcli.errors import ImageInputError
    from warpcli.volume.volio import read_volume

    with tifffile.TiffWriter(tmp_path / "v.tif") as w:
        for k in range(4):
            page = np.full((8, 10), k + 1, np.uint8)
            if k == where:
                page = np.full((8, 12), k + 1, np.uint8) if other == "shape" else page.astype(other)
            w.write(page, photometric="minisblack", metadata=None)
    with pytest.raises(ImageInputError) as info:
        read_volume(tmp_path / "v.tif")
    msg = str(info.value)
    page = 2 if where == 0 else where + 1  # the first page unlike page 1
    assert msg.startswith(f"{tmp_path / 'v.tif'}: page {page} holds"), msg
    assert "one pixel type and size" in msg and "\n" not in msg


def test_a_tiff_stack_cut_short_is_refused_and_tifffile_says_nothing(tmp_path, capfd):
    tifffile = pytest.importorskip("tifffile")
    from warpcli.errors import ImageInputError
    from warpcli.volume.volio import read_volume

    tifffile.imwrite(tmp_path / "v.tif", np.arange(8 * 8 * 8, dtype=np.uint16).reshape(8, 8, 8), photometric="minisblack")
    data = (tmp_path / "v.tif").read_bytes()
    for cut in (len(data) - 100, len(data) - 300, len(data) // 2):
        (tmp_path / "c.tif").write_bytes(data[:cut])
        with pytest.raises(ImageInputError):
            read_volume(tmp_path / "c.tif")
    assert capfd.readouterr().err == ""


@given(st.sampled_from([1e7, 1e8, 1e9]), st.sampled_from(["bem", "mfs"]), st.integers(4, 9))
@settings(max_examples=6, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
def test_a_theta_too_flat_for_a_smooth_method_or_too_large_is_refused(tmp_path_factory, stretch, method, n):
    d = tmp_path_factory.mktemp("theta")
    img, _ = _square_run(d, 64)
    a = 2 * math.pi * np.arange(n) / n
    poly = write_polygon(d / "p.json", np.stack([32 + 25 * np.cos(a), 32 + 25 * np.sin(a)], axis=1))
    write_polygon(d / "flat.json", np.stack([stretch * np.cos(a), np.sin(a)], axis=1))
    write_polygon(d / "huge.json", np.stack([1e300 * np.cos(a), 1e300 * np.sin(a)], axis=1))
    code, err = _run([img, d / "o.png", "--src", poly, "--dst", poly, "--theta", d / "flat.json", "--method", method])
    assert code == 2 and "flat.json: Theta is too flat" in err and err.count("\n") == 1, err
    code, err = _run([img, d / "o.png", "--src", poly, "--dst", poly, "--theta", d / "huge.json"])
    assert code == 2 and "huge.json: Theta's coordinates are too large" in err, err
    assert not (d / "o.png").exists()


def test_an_at_sign_in_batch_names_is_a_file_name_and_an_output_pattern_after_one_image_is_blamed(tmp_path):
    img, frame = _square_run(tmp_path)
    for name in ("photo@2x.png", "icon@@3x.png"):
        (tmp_path / name).write_bytes(open(img, "rb").read())
    (tmp_path / "od").mkdir()
    code, err = _run([tmp_path / "photo@2x.png", tmp_path / "icon@@3x.png", "--out-dir", tmp_path / "od", "--src", frame, "--dst", frame])
    assert code == 0, err
    assert sorted(os.listdir(tmp_path / "od")) == ["icon@@3x.png", "photo@2x.png"]
    for pattern in ("out.#.png", "out.%04d.png", "o_####.png"):
        code, err = _run([img, tmp_path / pattern, "--src", frame, "--dst", frame])
        assert code == 2 and err.startswith(f"warp: error: {tmp_path / pattern}: OUTPUT is a sequence pattern"), err


def _warnings(args):
    code, err = _run(args)
    assert code == 0, err
    return [line for line in err.splitlines() if line.startswith("warp: ") and not line.startswith("warp: error")]


@given(st.integers(5, 14), st.integers(1, 13), st.integers(0, 2**32 - 1))
@settings(max_examples=6, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
def test_a_target_whose_start_vertex_is_moved_is_warned_about_and_ordinary_pairs_are_not(tmp_path_factory, n, k, seed):
    from helpers import star_shaped

    k = k % n or 1
    rng = np.random.default_rng(seed)
    d = tmp_path_factory.mktemp("relabel")
    img = write_png(d / "in.png", np.full((64, 64, 3), 90, dtype=np.uint8))
    src = np.asarray(star_shaped(rng.uniform(0.2, 1, n), rng.uniform(0.3, 1, n))) * 24 + 32 - 12
    angle, scale = rng.uniform(-0.5, 0.5), rng.uniform(0.8, 1.1)
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    moved = (src - 32) @ rot.T * scale + 32
    ordinary = moved + rng.normal(0, 0.3, moved.shape)  # an ordinary deformation: about 1 % of the size
    write_polygon(d / "src.json", src)
    write_polygon(d / "ordinary.json", ordinary)
    write_polygon(d / "rolled.json", np.roll(moved, k, axis=0))  # src's vertex i onto the target's vertex i + k
    from warpcli.errors import PolygonError
    from warpcli.polygon import read_polygon

    for name in ("src.json", "ordinary.json", "rolled.json"):
        try:
            read_polygon(d / name)
        except PolygonError:
            return  # the noise made it invalid: nothing to warp
    said = _warnings([img, d / "o.png", "--src", d / "src.json", "--dst", d / "ordinary.json", "--interp", "nearest"])
    assert not [w for w in said if "far better" in w], said
    said = _warnings([img, d / "o.png", "--src", d / "src.json", "--dst", d / "rolled.json", "--interp", "nearest"])
    relabel = [w for w in said if "far better" in w]
    assert len(relabel) == 1 and f"vertex i + {k} " in relabel[0] and f"at its vertex {k} " in relabel[0], said


@given(st.integers(3, 40), st.integers(0, 39), st.floats(-3.0, 3.0), st.sampled_from([1e-3, 1.0, 1e4]),
       st.sampled_from([0.0, 1e-9, 1e-4]), st.integers(0, 2**32 - 1))
@settings(max_examples=25, deadline=None)
def test_symmetric_shapes_matched_as_given_are_not_called_twisted(n, k, angle, scale, noise, seed):
    """A regular polygon (every shift of it matches) onto itself, rotated, scaled, moved, slightly noisy, and
    labelled from any vertex: the labelling given is a match, so no warning (it once warned on 0 against 2.2e-16)."""
    from warpcli.polygon import Polygon, cyclic_relabelling

    rng = np.random.default_rng(seed)
    a = 2 * np.pi * np.arange(n) / n
    src = np.stack([np.cos(a), np.sin(a)], axis=1) * 20 * scale + 50 * scale
    b = a + angle
    dst = np.stack([np.cos(b), np.sin(b)], axis=1) * 17 * scale + 40 * scale
    dst = np.roll(dst + rng.normal(0, noise * 17 * scale, dst.shape), k % n, axis=0)
    assert cyclic_relabelling(Polygon(src, name="s"), Polygon(dst, name="d")) is None
    # One vertex pulled halfway in breaks the symmetry: a moved start is then warned about again.
    if 5 <= n <= 10 and k % n:
        src[0] = 0.5 * src[0] + 0.5 * src.mean(axis=0)
        moved = np.roll(src, k % n, axis=0)
        assert cyclic_relabelling(Polygon(src, name="s"), Polygon(moved, name="d"))[0] == k % n


@given(st.integers(32, 200), st.integers(32, 200), st.floats(0.05, 0.4))
@settings(max_examples=5, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
def test_polygons_in_normalised_coordinates_are_warned_about(tmp_path_factory, w, h, margin):
    d = tmp_path_factory.mktemp("norm")
    img = write_png(d / "in.png", np.full((h, w, 3), 90, dtype=np.uint8))
    unit = write_polygon(d / "unit.json", [[margin, margin], [1 - margin, margin], [1 - margin, 1], [margin, 1 - margin / 2]])
    said = _warnings([img, d / "o.png", "--src", unit, "--dst", unit])
    assert sum("lies within 0..1" in line and "not normalised" in line for line in said) == 2, said
    pixels = write_polygon(d / "px.json", [[1, 1], [w - 1, 1], [w - 1, h - 1], [1, h - 1]])
    assert not _warnings([img, d / "o.png", "--src", pixels, "--dst", pixels])


@pytest.mark.parametrize("channels", [2, 4])
def test_an_alpha_dropped_by_jpeg_is_warned_about_naming_the_output(tmp_path, channels):
    img = write_png(tmp_path / "in.png", np.full((16, 16, channels), 90, dtype=np.uint8))
    frame = write_polygon(tmp_path / "frame.json", [[0, 0], [16, 0], [16, 16], [0, 16]])
    said = _warnings([img, tmp_path / "o.jpg", "--src", frame, "--dst", frame])
    assert said == [f"warp: {tmp_path / 'o.jpg'}: JPEG has no alpha channel: the image's alpha is dropped "
                    "(PNG, TIFF and OpenEXR keep it)"]  # fmt: skip
    assert not _warnings([img, tmp_path / "o.png", "--src", frame, "--dst", frame])


@pytest.mark.parametrize("odd", [1, 2, 3])
def test_a_frame_whose_channels_do_not_fit_the_background_is_named(tmp_path, odd):
    frame = write_polygon(tmp_path / "frame.json", [[0, 0], [16, 0], [16, 16], [0, 16]])
    for f in (1, 2, 3):
        write_png(tmp_path / f"s.{f}.png", np.full((16, 16, 1 if f == odd else 3), 90, dtype=np.uint8))
    code, err = _run([tmp_path / "s.@.png", tmp_path / "w.@.png", "--frames", "1-3", "--src", frame, "--dst", frame,
                      "--background", "1,0.5,0"])  # fmt: skip
    errors = [line for line in err.splitlines() if line.startswith("warp: error")]
    assert code == 2 and errors == [f"warp: error: {tmp_path / f's.{odd}.png'}: background has 3 values but the image has 1 channels"]
    assert sorted(p.name for p in tmp_path.glob("w.*")) == [f"w.{f}.png" for f in (1, 2, 3) if f != odd]


def _tetra(path, scale):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float) * scale + 1
    path.write_text("".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in v) + "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    return path


@pytest.mark.parametrize("entry", [(0, 0), (1, 3), (2, 1)])
@pytest.mark.parametrize("value", ["nan", "inf", "zero-row"])
def test_a_volume_with_a_broken_affine_is_blamed_not_the_cages(tmp_path, entry, value):
    nib = pytest.importorskip("nibabel")
    img = nib.Nifti1Image(np.zeros((8, 8, 8), np.uint8), np.eye(4))
    h = img.header
    h["qform_code"], h["sform_code"] = 0, 1
    rows = [list(h["srow_x"]), list(h["srow_y"]), list(h["srow_z"])]
    if value == "zero-row":
        rows[entry[0]] = [0.0, 0.0, 0.0, 0.0]
    else:
        rows[entry[0]][entry[1]] = float(value)
    h["srow_x"], h["srow_y"], h["srow_z"] = rows
    nib.save(nib.Nifti1Image(np.zeros((8, 8, 8), np.uint8), None, header=h), tmp_path / "v.nii")
    cage = _tetra(tmp_path / "c.obj", 5.0)
    code, err = _run(["volume", tmp_path / "v.nii", tmp_path / "o.nii", "--src", cage, "--dst", cage])
    assert code == 2 and err.startswith(f"warp: error: {tmp_path / 'v.nii'}: the header's voxel-to-world affine is"), err
    assert err.count("\n") == 1 and not (tmp_path / "o.nii").exists()


@pytest.mark.parametrize("scale", [1e120, 1e200, 1e300])
def test_a_cage_too_large_is_said_to_be_too_large(tmp_path, scale):
    tifffile = pytest.importorskip("tifffile")
    tifffile.imwrite(tmp_path / "v.tif", np.zeros((8, 8, 8), np.uint8), photometric="minisblack")
    cage = _tetra(tmp_path / "c.obj", scale)
    code, err = _run(["volume", tmp_path / "v.tif", tmp_path / "o.tif", "--src", cage, "--dst", cage])
    assert code == 2 and "c.obj: vertex" in err and "too far out" in err and err.count("\n") == 1, err


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_volume_outputs_get_the_permissions_open_gives(tmp_path, umask):
    tifffile = pytest.importorskip("tifffile")
    from test_volume_surface import write_obj
    from warpcli.volume.examples import box

    tifffile.imwrite(tmp_path / "v.tif", np.zeros((8, 8, 8), np.uint8), photometric="minisblack")
    v, f = box(1, (1, 1, 1), (7, 7, 7))
    write_obj(tmp_path / "c.obj", v, f)
    old = os.umask(umask)
    try:
        code, err = _run(["volume", tmp_path / "v.tif", tmp_path / "o.tif", "--src", tmp_path / "c.obj",
                          "--dst", tmp_path / "c.obj", "--report", tmp_path / "r.json"])  # fmt: skip
    finally:
        os.umask(old)
    assert code == 0, err
    for name in ("o.tif", "r.json"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~umask, name


@st.composite
def garbage_files(draw):
    """Bytes a user might hand any subcommand: empty, text, a cut-off real file, random bytes, with or without a BOM."""
    kind = draw(st.sampled_from(["empty", "text", "cut", "random", "bom"]))
    if kind == "empty":
        return b""
    if kind == "text":
        return draw(st.text(max_size=200)).encode("utf-8", "surrogatepass")
    if kind == "random":
        return draw(st.binary(max_size=600))
    if kind == "bom":
        return b"\xef\xbb\xbf" + draw(st.sampled_from([b"1,2\n3,4\n", b"[[1, 2]]", b"vt 0.5 0.5\n", b"x,y\n1,2,3\n"]))
    return draw(st.sampled_from(["png", "tif", "exr", "nii", "obj"])).encode() + draw(st.binary(max_size=64))


@given(garbage_files(), st.sampled_from(["points-csv", "points-json", "points-obj", "apply-map", "volume-tif",
                                         "volume-nii", "volume-cage", "sequence", "batch", "theta"]))  # fmt: skip
@settings(max_examples=40, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
def test_every_subcommand_takes_garbage_with_one_line_and_leaves_nothing(tmp_path_factory, data, where):
    d = tmp_path_factory.mktemp("garbage")
    img, frame = _square_run(d)
    (d / "od").mkdir()
    ext = {"points-csv": "csv", "points-json": "json", "points-obj": "obj", "apply-map": "exr", "volume-tif": "tif",
           "volume-nii": "nii", "volume-cage": "obj", "sequence": "png", "batch": "png", "theta": "json"}[where]  # fmt: skip
    bad = d / f"bad.1.{ext}" if where == "sequence" else d / f"bad.{ext}"
    bad.write_bytes(data)
    if where.startswith("points"):
        args = ["points", bad, d / f"out.{ext}", "--src", frame, "--dst", frame, "--texture-size", "16x16"]
    elif where == "apply-map":
        args = ["apply-map", bad, img, d / "out.png"]
    elif where == "volume-cage":
        pytest.importorskip("tifffile").imwrite(d / "v.tif", np.zeros((8, 8, 8), np.uint8), photometric="minisblack")
        args = ["volume", d / "v.tif", d / "out.tif", "--src", bad, "--dst", bad]
    elif where.startswith("volume"):
        pytest.importorskip("tifffile")
        cage = _tetra(d / "c.obj", 5.0)
        args = ["volume", bad, d / f"out.{ext}", "--src", cage, "--dst", cage]
    elif where == "sequence":
        args = [d / "bad.@.png", d / "out.@.png", "--frames", "1", "--src", frame, "--dst", frame]
    elif where == "batch":
        args = [bad, img, "--out-dir", d / "od", "--src", frame, "--dst", frame]
    else:
        args = [img, d / "out.png", "--src", frame, "--dst", frame, "--theta", bad]
    before = _snapshot(d)
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIME_LIMIT)
    try:
        code, err = _run(args)
    except _TimeLimit:
        pytest.fail(f"more than {TIME_LIMIT} s: {where} {data[:40]!r}")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    assert "Traceback" not in err and all(line.startswith("warp: ") for line in err.splitlines()), err
    assert code in (0, 1, 2), (code, err)
    if code != 0 and where != "batch":
        assert _snapshot(d) == before and not any(p.name.startswith(".") for p in d.iterdir()), err
    assert not any(".warpcli-" in p.name for p in d.rglob("*"))
