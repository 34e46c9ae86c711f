"""Image sequences and animated polygons through the CLI and `warp_sequence` (issue 12)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import read_pixels, star, write_png, write_polygon, run_cli



def _frames(tmp_path, numbers, pattern="shot.{:04d}.png"):
    rng = np.random.default_rng(2)
    (tmp_path / "in").mkdir()
    for f in numbers:
        write_png(tmp_path / "in" / pattern.format(f), rng.integers(0, 256, (96, 128, 3), dtype=np.uint8))


def _keyframes(tmp_path, keys):
    path = tmp_path / "anim.json"
    path.write_text(json.dumps({"frames": {str(k): np.asarray(v).tolist() for k, v in keys.items()}}))
    return str(path)


SRC = star(cx=64, cy=48, r_in=14, r_out=40)


@pytest.mark.parametrize("wild", ["#", "@@@@", "%04d"])
def test_a_still_pair_warps_every_frame_with_one_map_and_a_missing_frame_is_one_line(tmp_path, wild, monkeypatch):
    _frames(tmp_path, [1001, 1002, 1004])
    src = write_polygon(tmp_path / "s.json", SRC)
    dst = write_polygon(tmp_path / "d.json", star(cx=64, cy=48, r_in=10, r_out=42, phase=0.2))
    from warpcli.maps.compose import BijectiveMap

    built = []
    original = BijectiveMap.between.__func__
    monkeypatch.setattr(BijectiveMap, "between", classmethod(lambda cls, *a, **k: built.append(1) or original(cls, *a, **k)))
    code, err = run_cli([tmp_path / "in" / f"shot.{wild}.png", tmp_path / f"out.{wild}.png", "--src", src, "--dst", dst, "--frames", "1001-1004"])
    assert code == 2
    lines = err.splitlines()
    assert [line for line in lines if line.startswith("warp: error:")] == [f"warp: error: {tmp_path / 'in' / 'shot.1003.png'}: no such file"]
    assert sorted(p.name for p in tmp_path.glob("out.*")) == ["out.1001.png", "out.1002.png", "out.1004.png"]
    assert len(built) == 1
    # each frame is the single warp of that frame
    single = tmp_path / "single.png"
    assert run_cli([tmp_path / "in" / "shot.1002.png", single, "--src", src, "--dst", dst])[0] == 0
    assert (tmp_path / "out.1002.png").read_bytes() == single.read_bytes()


def test_keyframed_polygons_give_each_frame_its_interpolated_warp_and_maps_only_where_they_change(tmp_path, monkeypatch):
    _frames(tmp_path, range(1, 7))
    a, b = star(cx=64, cy=48, r_in=10, r_out=42, phase=0.0), star(cx=64, cy=48, r_in=18, r_out=36, phase=0.3)
    dst = _keyframes(tmp_path, {2: a, 4: b})  # held before 2 and after 4
    src = write_polygon(tmp_path / "s.json", SRC)
    from warpcli.maps.compose import BijectiveMap

    built = []
    original = BijectiveMap.between.__func__
    monkeypatch.setattr(BijectiveMap, "between", classmethod(lambda cls, *a, **k: built.append(1) or original(cls, *a, **k)))
    # --jobs 1: the maps are built in this process, where they are counted (not in forked builders)
    code, err = run_cli([tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", dst, "--frames", "1-6", "--jobs", 1])
    assert code == 0, err
    # frames 1-2 share keyframe a, 3 is between, 4-6 share b: three maps
    assert len(built) == 3
    for frame, points in ((1, a), (3, 0.5 * (a + b)), (6, b)):
        d = write_polygon(tmp_path / f"d{frame}.json", points)
        single = tmp_path / f"single{frame}.png"
        assert run_cli([tmp_path / "in" / f"shot.{frame:04d}.png", single, "--src", src, "--dst", d])[0] == 0
        np.testing.assert_array_equal(read_pixels(tmp_path / f"out.{frame:04d}.png"), read_pixels(single))


def test_keyframes_that_self_intersect_between_frames_are_refused_before_any_work(tmp_path):
    _frames(tmp_path, range(1, 4))
    sq = np.array([[20.0, 20.0], [100.0, 20.0], [100.0, 80.0], [20.0, 80.0]])
    twisted = sq[[0, 1, 2, 3]].copy()
    twisted[0], twisted[1] = [100.0, 20.0], [20.0, 20.0]  # a bow-tie halfway: an edge collapses
    src = write_polygon(tmp_path / "s.json", sq)
    dst = _keyframes(tmp_path, {1: sq, 3: sq[[1, 0, 3, 2]][::-1]})
    code, err = run_cli([tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", dst, "--frames", "1-3"])
    assert code == 2 and err.count("\n") == 1 and "anim.json" in err
    assert not list(tmp_path.glob("out.*"))


@pytest.mark.parametrize(
    "args, message",
    [
        (["in/shot.#.png", "in/shot.#.png", "--frames", "1"], "overwritten"),
        (["in/shot.#.png", "out.png", "--frames", "1"], "sequence patterns"),
        (["in/none.#.png", "out.#.png"], "--frames"),  # no --frames, and no frame on disk
        (["in/shot.#.png", "out.#.png", "--frames", "1-0x0"], "--frames"),
        (["in/shot.#.png", "out.#.png", "--frames", "1-999999999999"], "--frames"),
    ],
)
def test_bad_sequences_are_one_line_and_exit_2(tmp_path, args, message, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _frames(tmp_path, [1])
    src = write_polygon(tmp_path / "s.json", SRC)
    code, err = run_cli([*args, "--src", src, "--dst", src])
    assert code == 2, err
    assert err.count("\n") == 1 and message in err, err
    assert not list(tmp_path.glob("out*"))


def test_warp_sequence_library_api(tmp_path):
    from warpcli import parse_frames, warp_sequence

    _frames(tmp_path, [5, 6])
    src = write_polygon(tmp_path / "s.json", SRC)
    items = warp_sequence(str(tmp_path / "in" / "shot.#.png"), str(tmp_path / "o_%03d.png"), parse_frames("5-6"), src, src)
    assert [i.error for i in items] == [None, None]
    assert sorted(p.name for p in tmp_path.glob("o_*")) == ["o_005.png", "o_006.png"]


# -- missing frames: no map for them, no map kept for failures, a summary (issue 27) --


def _present_pattern(seed, n):
    rng = np.random.default_rng(seed)
    return sorted(int(f) for f in np.flatnonzero(rng.random(n) < rng.uniform(0.0, 0.6)) + 1)


@pytest.mark.parametrize("seed", range(6))
def test_maps_are_built_only_for_frames_with_images_and_missing_ones_are_summarised(tmp_path, monkeypatch, seed):
    import importlib

    cli_warp = importlib.import_module("warpcli.cli.warp")
    from warpcli.maps.compose import BijectiveMap

    n = 24
    present = _present_pattern(seed, n)
    _frames(tmp_path, present)
    src = write_polygon(tmp_path / "s.json", SRC)
    dst = _keyframes(tmp_path, {1: star(cx=64, cy=48, r_in=10, r_out=42), n: star(cx=64, cy=48, r_in=12, r_out=40, phase=0.2)})
    built = []
    original = BijectiveMap.between.__func__
    monkeypatch.setattr(BijectiveMap, "between", classmethod(lambda cls, *a, **k: built.append(1) or original(cls, *a, **k)))
    # --jobs 1: the maps are built in this process, where they are counted (not in forked builders)
    code, err = run_cli([tmp_path / "in" / "shot.#.png", tmp_path / "out.#.png", "--src", src, "--dst", dst, "--frames", f"1-{n}", "--jobs", 1])
    missing = n - len(present)
    assert len(built) == len(present)  # one map per frame that has an image (the target moves every frame)
    assert code == (2 if missing else 0), err
    lines = [ln for ln in err.splitlines() if ln.startswith("warp: error:")]
    shown = min(missing, cli_warp.MISSING_SHOWN)
    assert len(lines) == shown + (missing > shown)
    if missing > shown:
        assert lines[-1] == f"warp: error: ... and {missing - shown} more missing frame{'s' if missing - shown > 1 else ''}"
    assert sorted(p.name for p in tmp_path.glob("out.*.png")) == [f"out.{f:04d}.png" for f in present]


@pytest.mark.forks  # the frames' maps are built by the pipelined builders, as `warp` builds them
def test_the_maps_of_failed_frames_are_not_kept(tmp_path, monkeypatch):
    # Frames whose image exists but cannot be read fail in warp_one: their
    # items (errors) outlive the run, the maps must not.
    import gc
    import weakref

    from warpcli.batch import warp_sequence
    from warpcli.maps.compose import BijectiveMap

    # Three frames, each its own map (keyframed): a map kept by the run, whichever and however
    # many, is one of them (six frames took twice the CPU and could show nothing more).
    (tmp_path / "in").mkdir()
    for f in range(1, 4):
        (tmp_path / "in" / f"shot.{f:04d}.png").write_bytes(b"not a png")
    src = write_polygon(tmp_path / "s.json", SRC)
    dst = _keyframes(tmp_path, {1: star(cx=64, cy=48, r_in=10, r_out=42), 3: star(cx=64, cy=48, r_in=12, r_out=40, phase=0.2)})
    maps = []
    original = BijectiveMap.between.__func__

    def between(cls, *a, **k):
        m = original(cls, *a, **k)
        maps.append(weakref.ref(m))
        return m

    monkeypatch.setattr(BijectiveMap, "between", classmethod(between))
    items = warp_sequence(str(tmp_path / "in" / "shot.#.png"), str(tmp_path / "out.#.png"), range(1, 4), src, dst)
    gc.collect()
    assert len(maps) == 3 and all(i.error is not None for i in items)
    assert [m() for m in maps] == [None] * 3
