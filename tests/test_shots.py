"""Shots, not frames (issue 23): animated sequences on processes, per-frame maps, compositors' patterns,
frames found on disk, --frame, and points tables."""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from helpers import read_pixels, star, write_png, write_polygon, run_cli
from warpcli import BijectiveMap, MapOptions, Polygon
from warpcli.cli.progress import Progress

SIZE = (72, 96)  # rows, columns


def _frames(directory, numbers, name="shot.{:04d}.png", seed=0):
    rng = np.random.default_rng(seed)
    os.makedirs(directory, exist_ok=True)
    for f in numbers:
        write_png(os.path.join(directory, name.format(f)), rng.integers(0, 256, (*SIZE, 3), dtype=np.uint8))


def _animated(tmp_path, seed, first, last):
    """Keyframed src and dst stars that move, turn and breathe between ``first`` and ``last``."""
    rng = np.random.default_rng(seed)

    def keyed(name, r_in, r_out):
        keys = {}
        for f in (first, last):
            keys[str(f)] = star(
                n=5, cx=48 + rng.uniform(-4, 4), cy=36 + rng.uniform(-3, 3), r_in=r_in + rng.uniform(-2, 2),
                r_out=r_out + rng.uniform(-2, 2), phase=rng.uniform(0, 0.6),
            ).tolist()  # fmt: skip
        path = tmp_path / name
        path.write_text(json.dumps({"frames": keys}))
        return str(path)

    return keyed("src.json", 11, 30), keyed("dst.json", 9, 32)


def _outputs(directory, prefix):
    return {p.name[len(prefix) :]: p.read_bytes() for p in sorted(directory.glob(prefix + "*"))}


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.forks  # batches on forked workers and builders, as `warp` runs them
def test_an_animated_shot_gives_the_same_bytes_and_messages_on_one_or_two_jobs(tmp_path, seed):
    frames = list(range(1, 8))
    _frames(tmp_path / "in", [f for f in frames if f != 4], seed=seed)  # frame 4 missing: one error line, in place
    src, dst = _animated(tmp_path, seed, 1, 7)
    runs = {}
    for jobs in (1, 2):
        code, err = run_cli([
            tmp_path / "in" / "shot.#.png", tmp_path / f"o{jobs}.#.png", "--src", src, "--dst", dst,
            "--frames", "1-7", "--jobs", jobs, "-v", "--save-map", tmp_path / f"m{jobs}.#.exr",
        ])  # fmt: skip
        runs[jobs] = (code, err.replace(f"o{jobs}.", "o.").replace(f"m{jobs}.", "m."), _outputs(tmp_path, f"o{jobs}."), _outputs(tmp_path, f"m{jobs}."))
    assert runs[1] == runs[2]
    code, err, images, maps = runs[1]
    assert code == 2 and err.count("warp: error:") == 1 and "shot.0004.png" in err
    lines = [ln for ln in err.splitlines() if ln.startswith("warp: wrote") or ln.startswith("warp: error")]
    assert [ln.split("o.")[-1][:4] if "wrote" in ln else "4" for ln in lines] == ["0001", "0002", "0003", "4", "0005", "0006", "0007"]
    assert len(images) == 6 and len(maps) == 6


def test_per_frame_maps_reproduce_every_frame_through_apply_map(tmp_path):
    _frames(tmp_path / "in", range(1, 6))
    src, dst = _animated(tmp_path, 5, 2, 4)  # frames 1-2 and 4-5 hold a keyframe: two runs of two, and frame 3
    code, err = run_cli([
        tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", dst, "--frames", "1-5",
        "--save-map", tmp_path / "map.#.exr", "--save-forward-map", tmp_path / "fwd.#.exr", "--no-antialias",
    ])  # fmt: skip
    assert code == 0, err
    ino = {f: os.stat(tmp_path / f"map.{f:04d}.exr").st_ino for f in range(1, 6)}
    # Written once per distinct pair, hard links for the frames that repeat it.
    assert ino[1] == ino[2] and ino[4] == ino[5] and len(set(ino.values())) == 3
    assert os.stat(tmp_path / "fwd.0001.exr").st_ino == os.stat(tmp_path / "fwd.0002.exr").st_ino
    code, err = run_cli(["apply-map", tmp_path / "map.#.exr", tmp_path / "in" / "shot.#.png", tmp_path / "again.#.png", "--frames", "1-5", "--jobs", 2])
    assert code == 0, err
    for f in range(1, 6):
        a = read_pixels(tmp_path / f"out.{f:04d}.png").astype(int)
        b = read_pixels(tmp_path / f"again.{f:04d}.png").astype(int)
        assert np.abs(a - b).max() <= 1 and (a != b).mean() < 0.01  # float32 s, t: at most one level
    # Each map is the single warp's map of its frame, bit for bit (frame 3: halfway between the keyframes).
    keys_s, keys_d = (json.loads(open(p).read())["frames"] for p in (src, dst))
    mid = [write_polygon(tmp_path / f"{n}3.json", (np.array(k["2"]) + np.array(k["4"])) / 2) for n, k in (("s", keys_s), ("d", keys_d))]
    code, err = run_cli([tmp_path / "in" / "shot.0003.png", tmp_path / "one.png", "--src", mid[0], "--dst", mid[1], "--save-map", tmp_path / "one.exr", "--no-antialias"])
    assert code == 0, err
    assert read_pixels(tmp_path / "one.exr").tobytes() == read_pixels(tmp_path / "map.0003.exr").tobytes()
    assert (tmp_path / "one.png").read_bytes() == (tmp_path / "out.0003.png").read_bytes()


def test_one_map_over_a_whole_sequence(tmp_path):
    _frames(tmp_path / "in", range(1, 4))
    src = write_polygon(tmp_path / "s.json", star(n=5, cx=48, cy=36, r_in=11, r_out=30))
    dst = write_polygon(tmp_path / "d.json", star(n=5, cx=48, cy=36, r_in=9, r_out=32, phase=0.3))
    code, err = run_cli([tmp_path / "in" / "shot.0001.png", tmp_path / "x.png", "--src", src, "--dst", dst, "--save-map", tmp_path / "map.exr", "--no-antialias"])
    assert code == 0, err
    code, err = run_cli(["apply-map", tmp_path / "map.exr", tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png"])
    assert code == 0, err
    assert "taking the 3 frames on disk, 1-3" in err
    for f in range(1, 4):
        code, _ = run_cli(["apply-map", tmp_path / "map.exr", tmp_path / "in" / f"shot.{f:04d}.png", tmp_path / f"single{f}.png"])
        assert code == 0 and (tmp_path / f"single{f}.png").read_bytes() == (tmp_path / f"out.{f:04d}.png").read_bytes()


@pytest.mark.parametrize("digits", [1, 2, 3, 4, 5, 6])
@pytest.mark.parametrize("command", ["warp", "apply-map"])
def test_a_pattern_typed_as_in_nuke_gets_a_one_line_hint(tmp_path, digits, command):
    frames = [7, 8, 1001] if digits >= 4 else [7, 8]
    _frames(tmp_path, frames, name=f"shot.{{:0{digits}d}}.png")
    pattern = "#" * digits
    src = write_polygon(tmp_path / "s.json", star(n=5, cx=48, cy=36, r_in=11, r_out=30))
    head = ["apply-map", tmp_path / "m.exr"] if command == "apply-map" else []
    tail = [] if command == "apply-map" else ["--src", src, "--dst", src]
    for spec in (["--frames", "7-8"], []):  # frames given, or looked for on disk
        code, err = run_cli([*head, tmp_path / f"shot.{pattern}.png", tmp_path / "out.#.png", *tail, *spec])
        assert code == 2 and err.count("\n") == 1, err
        found = re.search(r"shot\.([0-9]+)\.png exists", err)
        assert found and found.group(1) in {f"{f:0{digits}d}" for f in frames}, err  # Nuke's # is unpadded
        assert (f"shot.%0{digits}d.png" if digits > 1 else "shot.%d.png") in err, err
        assert not list(tmp_path.glob("out.*"))


@pytest.mark.parametrize("seed", range(4))
def test_frames_are_taken_from_disk_with_their_gaps(tmp_path, seed):
    rng = np.random.default_rng(seed)
    first = int(rng.integers(-3, 1001))
    frames = sorted({first, *(first + rng.choice(12, size=6, replace=False)).tolist()})
    _frames(tmp_path / "in", frames)
    # Not frames of shot.#.png: other paddings and names.
    (tmp_path / "in" / f"shot.{frames[0] + 100}.png").write_bytes(b"")
    (tmp_path / "in" / f"shot.0{abs(frames[0]) + 10000:05d}.png").write_bytes(b"")
    (tmp_path / "in" / "shot.abcd.png").write_bytes(b"")
    src = write_polygon(tmp_path / "s.json", star(n=5, cx=48, cy=36, r_in=11, r_out=30))
    code, err = run_cli([tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", src])
    assert code == 0, err
    missing = frames[-1] - frames[0] + 1 - len(frames)
    assert f"taking the {len(frames)} frames on disk" in err
    assert (f"({missing} missing between them" in err) == (missing > 0)
    assert sorted(p.name for p in tmp_path.glob("out.*")) == [f"out.{f:04d}.png" for f in frames]


def test_frame_picks_one_frame_of_keyframed_files(tmp_path):
    _frames(tmp_path, [1])
    a = star(n=5, cx=48, cy=36, r_in=11, r_out=30)
    b = star(n=5, cx=50, cy=38, r_in=9, r_out=32, phase=0.4)
    (tmp_path / "anim.json").write_text(json.dumps({"frames": {"10": a.tolist(), "20": b.tolist()}}))
    dst = write_polygon(tmp_path / "d.json", star(n=5, cx=48, cy=36, r_in=10, r_out=31, phase=0.1))
    image = tmp_path / "shot.0001.png"
    code, err = run_cli([image, tmp_path / "x.png", "--src", tmp_path / "anim.json", "--dst", dst])
    assert code == 2 and err.count("\n") == 1 and "--frame N" in err and "anim.json" in err
    assert not (tmp_path / "x.png").exists()
    for frame, t in ((10, 0.0), (13, 0.3), (20, 1.0), (99, 1.0)):
        plain = write_polygon(tmp_path / f"p{frame}.json", a + t * (b - a))
        assert run_cli([image, tmp_path / f"k{frame}.png", "--src", tmp_path / "anim.json", "--dst", dst, "--frame", frame])[0] == 0
        assert run_cli([image, tmp_path / f"p{frame}.png", "--src", plain, "--dst", dst])[0] == 0
        assert (tmp_path / f"k{frame}.png").read_bytes() == (tmp_path / f"p{frame}.png").read_bytes()
    pts = tmp_path / "pts.json"
    pts.write_text("[[48, 36], [45, 30]]")
    code, err = run_cli(["points", "--src", tmp_path / "anim.json", "--dst", dst, pts, tmp_path / "q.json"])
    assert code == 2 and "--frame N" in err
    assert run_cli(["points", "--src", tmp_path / "anim.json", "--dst", dst, "--frame", 13, pts, tmp_path / "q.json"])[0] == 0
    f = BijectiveMap.between(Polygon(a + 0.3 * (b - a)), Polygon(json.loads(open(dst).read())))
    np.testing.assert_allclose(json.loads((tmp_path / "q.json").read_text()), f.forward([[48, 36], [45, 30]]), rtol=0, atol=5e-7)


SRC = star(n=5, cx=48, cy=36, r_in=11, r_out=30)
DST = star(n=5, cx=48, cy=36, r_in=9, r_out=32, phase=0.3)


def _table(rng, sep, header, decimal_comma, bom, crlf):
    """A table of points with an id before and a label after, and what x and y are."""
    pts = np.stack([48 + rng.uniform(-6, 6, 5), 36 + rng.uniform(-5, 5, 5)], axis=1)
    end = "\r\n" if crlf else "\n"
    lines = []
    if header:
        lines.append(sep.join(["id", "X", "Y", "label"]) if sep != " " else "id   X  Y label")
    for k, (x, y) in enumerate(pts):
        xs, ys = repr(float(x)), repr(float(y))
        if decimal_comma:
            xs, ys = xs.replace(".", ","), ys.replace(".", ",")
        lines.append(sep.join([f"p{k}", xs, ys, f"name {k}" if sep != " " else f"name{k}"]))
    text = end.join(lines) + end
    return ("\ufeff" if bom else "") + text, pts


@pytest.mark.parametrize("seed", range(12))
def test_points_tables_keep_their_columns_and_round_trip_within_the_precision(tmp_path, seed):
    rng = np.random.default_rng(seed)
    sep = [",", ";", "\t", " "][seed % 4]
    ext = ".txt" if sep == " " else ".csv"
    header = bool(seed % 3) or sep == " "
    decimal_comma = sep in (";", "\t") and seed % 2 == 0
    bom, crlf = bool(seed % 5 == 1), bool(seed % 2)
    precision = int(rng.integers(0, 10))
    text, pts = _table(rng, sep, header, decimal_comma, bom, crlf)
    (tmp_path / f"p{ext}").write_bytes(text.encode())
    a = write_polygon(tmp_path / "a.json", SRC)
    b = write_polygon(tmp_path / "b.json", DST)
    extra = [] if header else ["--columns", "2,3"]
    code, err = run_cli(["points", "--src", a, "--dst", b, "--precision", precision, *extra, tmp_path / f"p{ext}", tmp_path / f"q{ext}"])
    assert code == 0, err
    out = (tmp_path / f"q{ext}").read_bytes().decode("utf-8")
    assert out.startswith("\ufeff") == bom
    old_lines, new_lines = text.lstrip("\ufeff").splitlines(keepends=True), out.lstrip("\ufeff").splitlines(keepends=True)
    assert len(old_lines) == len(new_lines)
    if header:
        assert old_lines[0] == new_lines[0]
    rows = new_lines[1:] if header else new_lines
    expected = BijectiveMap.between(Polygon(SRC), Polygon(DST), MapOptions()).forward(pts)
    for old, new, want in zip(old_lines[-5:], rows, expected):
        assert new.endswith("\r\n" if crlf else "\n")
        of, nf = (ln.rstrip("\r\n").split(sep) if sep != " " else ln.split() for ln in (old, new))
        assert of[0] == nf[0] and of[3:] == nf[3:]  # id and label as they were
        got = [float(v.replace(",", ".")) for v in nf[1:3]]
        assert all(len(v.replace(",", ".").split(".")[-1]) <= max(precision, 1) for v in nf[1:3])
        np.testing.assert_allclose(got, want, rtol=0, atol=0.5 * 10.0**-precision + 1e-9)


def test_points_default_precision_is_six_decimals(tmp_path):
    (tmp_path / "p.csv").write_text("x,y\n47.123456789123,35.987654321987\n")
    a = write_polygon(tmp_path / "a.json", SRC)
    assert run_cli(["points", "--src", a, "--dst", a, tmp_path / "p.csv", tmp_path / "q.csv"])[0] == 0
    x, y = (tmp_path / "q.csv").read_text().splitlines()[1].split(",")
    assert len(x.split(".")[1]) <= 6 and len(y.split(".")[1]) <= 6
    assert abs(float(x) - 47.123456789123) < 1e-6 and abs(float(y) - 35.987654321987) < 1e-6


@pytest.mark.parametrize(
    "content, extra, match",
    [
        ("a,b\n1,2\n", ["--columns", "x,y"], "no column 'x'"),
        ("id,x,y\n1,2\n", [], "line 2 has 2 field(s)"),
        ("x,y\n1,2\n", ["--columns", "1,1"], "same column"),
        ("x,y\n1,abc\n", [], "must be numbers"),
    ],
)
def test_bad_points_tables_are_one_line(tmp_path, content, extra, match):
    (tmp_path / "p.csv").write_text(content)
    a = write_polygon(tmp_path / "a.json", SRC)
    code, err = run_cli(["points", "--src", a, "--dst", a, *extra, tmp_path / "p.csv", tmp_path / "q.csv"])
    assert code == 2 and err.count("\n") == 1 and match in err, err
    assert not (tmp_path / "q.csv").exists()


class _Terminal:
    def __init__(self):
        self.text = ""

    def isatty(self):
        return True

    def write(self, s):
        self.text += s

    def flush(self):
        pass


def test_the_progress_line_shows_frames_done_rate_and_time_left():
    p = Progress(_Terminal(), total=24)
    assert p.line(3.0) == "warp: frames 0/24 (0:03)"
    for _ in range(6):
        p.item_done()
    assert p.line(3.0) == "warp: frames 6/24, 2.0/s, 0:09 left (0:03)"
    for _ in range(18):
        p.item_done()
    assert p.line(4000.0) == "warp: frames 24/24, 0.01/s, 0:00 left (1:06:40)"


def test_the_progress_line_is_drawn_and_cleared_on_a_terminal():
    import time

    term = _Terminal()
    with Progress(term, total=3, delay=0.0, interval=0.01) as p:
        p.item_done()
        time.sleep(0.1)
    assert "frames 1/3" in term.text and term.text.endswith("\r\x1b[K")


@pytest.mark.parametrize("jobs", [1, 3])
@pytest.mark.forks  # batches on forked workers and builders, as `warp` runs them
def test_still_polygons_write_one_map_for_the_whole_sequence_on_any_number_of_threads(tmp_path, jobs):
    _frames(tmp_path / "in", range(1, 6))
    src = write_polygon(tmp_path / "s.json", star(n=5, cx=48, cy=36, r_in=11, r_out=30))
    dst = write_polygon(tmp_path / "d.json", star(n=5, cx=48, cy=36, r_in=9, r_out=32, phase=0.3))
    code, err = run_cli([tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", dst, "--frames", "1-5", "--jobs", jobs, "--save-map", tmp_path / "m.%03d.tif"])
    assert code == 0, err
    assert len({os.stat(tmp_path / f"m.{f:03d}.tif").st_ino for f in range(1, 6)}) == 1
    assert os.stat(tmp_path / "m.001.tif").st_nlink == 5
    code, err = run_cli([tmp_path / "in" / "shot.0001.png", tmp_path / "one.png", "--src", src, "--dst", dst, "--save-map", tmp_path / "one.tif"])
    assert code == 0, err
    assert (tmp_path / "one.tif").read_bytes() == (tmp_path / "m.003.tif").read_bytes()


def test_sequence_maps_must_be_float_patterns_apart_from_the_frames(tmp_path):
    _frames(tmp_path / "in", [1])
    src = write_polygon(tmp_path / "s.json", star(n=5, cx=48, cy=36, r_in=11, r_out=30))
    base = [tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", src, "--frames", "1"]
    for extra, match in (
        (["--save-map", tmp_path / "m.exr"], "must be a pattern"),
        (["--save-map", tmp_path / "m.#.png"], "float OpenEXR"),
        (["--save-map", tmp_path / "out.#.png"], "frames would be overwritten"),
        (["--save-map", tmp_path / "m.#.exr", "--save-forward-map", tmp_path / "m.#.exr"], "frames would be overwritten"),
        (["--report", tmp_path / "r.json"], "not to a sequence"),
    ):
        code, err = run_cli([*base, *extra])
        assert code == 2 and err.count("\n") == 1 and match in err, err
        assert not list(tmp_path.glob("out.*")) and not list(tmp_path.glob("m.*"))


def test_an_output_pattern_with_hash_runs_is_warned_about(tmp_path):
    _frames(tmp_path / "in", [7])
    src = write_polygon(tmp_path / "s.json", star(n=5, cx=48, cy=36, r_in=11, r_out=30))
    code, err = run_cli([tmp_path / "in" / "shot.%04d.png", tmp_path / "out.####.png", "--src", src, "--dst", src, "--frames", "7"])
    assert code == 0 and err.count("\n") == 1 and "out.0000000000000007.png" in err and "out.%04d.png" in err, err
    assert (tmp_path / "out.0000000000000007.png").exists()


@pytest.mark.parametrize("budget, processes", [(600_000, False), (10_000_000, True)])
@pytest.mark.forks  # batches on forked workers and builders, as `warp` runs them
def test_worker_processes_stay_within_the_memory_budget(tmp_path, monkeypatch, budget, processes):
    """A frame of 96 x 72 RGB needs 0.44 MB (its pixels, the output and its map): 0.6 MB holds one at a time."""
    _frames(tmp_path / "in", range(1, 4))
    src, dst = _animated(tmp_path, 3, 1, 3)
    peak = _count_builders(monkeypatch)
    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", str(budget))
    code, err = run_cli([tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", dst, "--frames", "1-3", "--jobs", 2])
    assert code == 0, err
    assert peak == ([2, 3, 3] if processes else [0, 0, 0])  # two workers, the three maps queued on them at once


def test_a_feathered_retouch_of_an_animated_cage_is_each_frame_s_single_retouch(tmp_path):
    # Keyframed polygons, --outside input, --feather and --save-map through a sequence: each frame's
    # output and map are those of the single warp of its polygons (frame 2: between the keyframes).
    _frames(tmp_path / "in", range(1, 4))
    src, dst = _animated(tmp_path, 7, 1, 3)
    common = ["--outside", "input", "--feather", "4", "--vacated", "background"]
    code, err = run_cli([tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", dst,
                         "--frames", "1-3", "--save-map", tmp_path / "map.#.exr", *common])  # fmt: skip
    assert code == 0, err
    keys_s, keys_d = (json.loads(open(p).read())["frames"] for p in (src, dst))
    mid = [write_polygon(tmp_path / f"{n}2.json", (np.array(k["1"]) + np.array(k["3"])) / 2) for n, k in (("s", keys_s), ("d", keys_d))]
    code, err = run_cli([tmp_path / "in" / "shot.0002.png", tmp_path / "one.png", "--src", mid[0], "--dst", mid[1],
                         "--save-map", tmp_path / "one.exr", *common])  # fmt: skip
    assert code == 0, err
    assert (tmp_path / "one.png").read_bytes() == (tmp_path / "out.0002.png").read_bytes()
    assert read_pixels(tmp_path / "one.exr").tobytes() == read_pixels(tmp_path / "map.0002.exr").tobytes()
    assert (read_pixels(tmp_path / "map.0002.exr")[..., 3] == 1).mean() > 0.5  # the whole image, identity outside


def _count_builders(monkeypatch):
    """The most worker processes of a sequence alive at once (`warpcli.batch._pipelined`), the
    most maps queued on them at once, and the maps submitted, as a three-item list."""
    import warpcli._fork as fork

    alive, queued, peak = [0], [0], [0, 0, 0]

    class Counting(fork.Worker):
        def __init__(self, *args):
            super().__init__(*args)
            alive[0] += 1
            peak[0] = max(peak[0], alive[0])

        def submit(self, *args):
            super().submit(*args)
            queued[0] += 1
            peak[1] = max(peak[1], queued[0])
            peak[2] += 1

        def result(self):
            try:
                return super().result()
            finally:
                queued[0] -= 1

        def close(self, kill=False):
            if self._from >= 0:
                alive[0] -= 1
            super().close(kill)

    monkeypatch.setattr(fork, "Worker", Counting)
    return peak


def _failing_between(monkeypatch, fail_x, die_x=None):
    """``BijectiveMap.between`` that refuses the pair whose source starts at x = ``fail_x`` (and kills
    the process building the one at ``die_x``); forked children inherit it."""
    import signal

    from warpcli.errors import FoldOverError
    from warpcli.maps.compose import BijectiveMap as Map

    real = Map.between.__func__

    def between(cls, src, dst, *args, **kwargs):
        x = round(float(src.points[0, 0]), 6)
        if x == fail_x:
            raise FoldOverError(f"{src.name}: refused by the test")
        if x == die_x:
            os.kill(os.getpid(), signal.SIGKILL)
        return real(cls, src, dst, *args, **kwargs)

    monkeypatch.setattr(Map, "between", classmethod(between))


@pytest.mark.parametrize("seed", [3, 4])
@pytest.mark.forks  # batches on forked workers and builders, as `warp` runs them
def test_pipelined_maps_give_the_items_bytes_and_messages_of_one_job(tmp_path, monkeypatch, seed):
    """Generated shots: keyframes at random frames (holds make runs of several frames), missing frames,
    an output size or not, a map that cannot be built: jobs 2 gives jobs 1's items, log and bytes."""
    import logging

    from warpcli.batch import warp_sequence

    rng = np.random.default_rng(seed)
    frames = list(range(1, 9))
    present = [f for f in frames if f in (1, 8) or rng.uniform() > 0.2]
    _frames(tmp_path / "in", present, seed=seed)
    a = int(rng.integers(2, 5))
    keys = [1, a, a + int(rng.integers(1, 3)), 8]
    polys = {}
    for name, r_in, r_out in (("src", 11, 30), ("dst", 9, 32)):
        k = {str(f): star(n=5, cx=48 + rng.uniform(-4, 4), cy=36, r_in=r_in, r_out=r_out, phase=rng.uniform(0, 0.6)).tolist() for f in keys}
        k[str(keys[2])] = k[str(keys[1])]  # a hold: the frames between those keys share one map
        polys[name] = tmp_path / f"{name}.json"
        polys[name].write_text(json.dumps({"frames": k}))
    from warpcli.keyframes import read_animated

    bad = int(rng.choice([f for f in present if not (keys[1] <= f <= keys[2])]))
    _failing_between(monkeypatch, round(float(read_animated(polys["src"]).at(bad).points[0, 0]), 6))
    size = None if seed % 2 else (60, 50)
    peak = _count_builders(monkeypatch)
    runs = {}
    for jobs in (1, 2):
        records = []
        handler = logging.Handler()
        handler.emit = lambda r: records.append(r.getMessage().replace(f"o{jobs}.", "o."))
        log = logging.getLogger("warpcli")
        log.addHandler(handler)
        try:
            items = warp_sequence(tmp_path / "in" / "shot.#.png", str(tmp_path / f"o{jobs}.#.png"), frames, polys["src"],
                                  polys["dst"], jobs=jobs, size=size)  # fmt: skip
        finally:
            log.removeHandler(handler)
        runs[jobs] = ([(os.path.basename(i.input_path), str(i.error).replace(f"o{jobs}.", "o.")) for i in items], records, _outputs(tmp_path, f"o{jobs}."))
    assert peak[0] == 2 and peak[1] > 2  # the pipeline ran: two workers, a map queued behind the one built
    assert runs[1] == runs[2]
    errors = dict(runs[1][0])
    assert "refused by the test" in errors[f"shot.{bad:04d}.png"]
    assert len(runs[1][2]) == sum(e == "None" for e in errors.values()) > 0


@pytest.mark.forks  # batches on forked workers and builders, as `warp` runs them
@pytest.mark.parametrize("large", [3])  # between runs the workers build
def test_a_frame_in_strips_is_warped_here_and_the_rest_pipelined(tmp_path, monkeypatch, large):
    """Headers are read run by run as the runs are queued: a later frame too large for memory
    (warped in strips, which needs the map) has its run built in the main process; jobs 2 gives
    jobs 1's bytes and messages."""
    frames = range(1, 6)
    _frames(tmp_path / "in", [f for f in frames if f != large])
    big = np.random.default_rng(large).integers(0, 256, (SIZE[0] * 3, SIZE[1] * 3, 3), dtype=np.uint8)
    write_png(tmp_path / "in" / f"shot.{large:04d}.png", big)
    src, dst = _animated(tmp_path, large, 1, 5)
    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", "1000000")  # 96 x 72 fits; 288 x 216 goes in strips
    peak = _count_builders(monkeypatch)
    runs = {}
    for jobs in (1, 2):
        code, err = run_cli([tmp_path / "in" / "shot.#.png", tmp_path / f"o{jobs}.#.png", "--src", src, "--dst", dst,
                             "--frames", "1-5", "--jobs", jobs, "-v"])  # fmt: skip
        runs[jobs] = (code, err.replace(f"o{jobs}.", "o."), _outputs(tmp_path, f"o{jobs}."))
    assert runs[1] == runs[2] and runs[1][0] == 0 and len(runs[1][2]) == 5
    assert peak[0] == 2 and peak[2] == 4  # pipelined: the four other frames' maps built by the workers


@pytest.mark.forks  # batches on forked workers and builders, as `warp` runs them
def test_a_builder_that_dies_fails_its_frames_and_the_others_go_on(tmp_path, monkeypatch):
    from warpcli.batch import warp_sequence
    from warpcli.keyframes import read_animated

    _frames(tmp_path / "in", range(1, 6))
    src, dst = _animated(tmp_path, 7, 1, 5)
    _failing_between(monkeypatch, None, round(float(read_animated(src).at(3).points[0, 0]), 6))
    items = warp_sequence(tmp_path / "in" / "shot.#.png", str(tmp_path / "o.#.png"), [1, 2, 3, 4, 5], src, dst, jobs=2)
    assert [i.error is None for i in items] == [True, True, False, True, True]
    assert "shot.0003.png: the process building its map ended: killed by SIGKILL" in str(items[2].error)


@pytest.mark.forks  # batches on forked workers and builders, as `warp` runs them
def test_pipelined_plans_come_through_shared_memory_every_time(tmp_path, monkeypatch):
    """Every map the workers build sends its plans through shared memory (`warpcli._fork.SharedMemory`):
    the main process lets each run's plans go before it lends their region again, so no plan falls back
    to the pipe for want of a free region."""
    import warpcli._fork as fork
    from warpcli.batch import warp_sequence

    lent = []
    real = fork.SharedMemory.lend
    monkeypatch.setattr(fork.SharedMemory, "lend", lambda self: lent.append(real(self)) or lent[-1])
    _frames(tmp_path / "in", range(1, 7))
    src, dst = _animated(tmp_path, 5, 1, 6)
    items = warp_sequence(tmp_path / "in" / "shot.#.png", str(tmp_path / "o.#.png"), range(1, 7), src, dst, jobs=2)
    assert all(i.error is None for i in items)
    assert len(lent) == 6 and None not in lent and len(set(lent)) <= 5  # a region per queued call (2 a worker) and one more
