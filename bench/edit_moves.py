#!/usr/bin/env python
"""warp edit: the server's cost of one drag move, in process (no browser, no HTTP).

    python bench/edit_moves.py                                  # 1 MP, star12 and wavy48, within none, image, 20
    python bench/edit_moves.py --sizes 1,12 --moves 40 --repeat 3
    python bench/edit_moves.py --pairs wavy48 --within image --profile 25   # cProfile: the 25 costliest calls
    python bench/edit_moves.py --within 20 --vertex outer      # the rightmost vertex outwards: the margin's box moves
    python bench/edit_moves.py --within image,20 --cut 5       # also within_pair alone (the CLI's cut of the ring)

The same drag as `bench/edit_latency.py` (one target vertex around a small circle,
``--moves`` positions), sent straight to `warpcli.edit.session.EditSession.preview_map`
as the page sends it (``drag: "dst"`` while the pointer is down), then the release (the
same polygons at the full preview density). Reported per case: median and 95th percentile of
a move (milliseconds, over ``--repeat`` drags), and the release. A preview that fails (its
header says ``ok: false``) is counted and its first error shown.

This is the server's share of the browser's latency (which adds the request's round trip
and the drawing): the per-move budget is well under the browser's 100 ms target at 1 MP.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import math
import os
import platform
import pstats
import statistics
import struct
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.dirname(HERE))
import run as bench_run  # noqa: E402  bench/run.py: the images and polygon pairs


def header(data: bytes) -> dict:
    (n,) = struct.unpack("<I", data[:4])
    return json.loads(data[4 : 4 + n])


def drag(session, src, dst, within, moves, radius, profile=None, index=0, outward=False):
    """One drag of target vertex ``index``: ``moves`` previews with ``drag="dst"``, then the release;
    (move seconds, release seconds, errors). ``outward``: round a circle to the vertex's right instead of its left."""
    options = {"within": None if within == "none" else within}
    vertex = dst[index].copy()
    times, errors = [], []
    for i in range(moves):
        a = 2 * math.pi * (i + 1) / moves
        moved = dst.copy()
        moved[index] = vertex + radius * np.array([(1.0 - math.cos(a)) if outward else (math.cos(a) - 1.0), math.sin(a)])
        doc = {"src": src.tolist(), "dst": moved.tolist(), "options": options, "drag": "dst"}
        t0 = time.perf_counter()
        if profile is not None:
            profile.enable()
        out = session.preview_map(doc)
        if profile is not None:
            profile.disable()
        times.append(time.perf_counter() - t0)
        h = header(out)
        if not h["ok"]:
            errors.append(h["error"])
    doc = {"src": src.tolist(), "dst": dst.tolist(), "options": options, "drag": None}
    t0 = time.perf_counter()
    out = session.preview_map(doc)
    release = time.perf_counter() - t0
    if not header(out)["ok"]:
        errors.append(header(out)["error"])
    return times, release, errors


def time_cut(pair, within, size, count):
    """Median seconds of ``within_pair`` (refused or not) for the pair's polygons."""
    from warpcli.errors import PolygonError
    from warpcli.polygon import Polygon
    from warpcli.within import within_pair

    src, dst = Polygon(pair.src, name="a.json"), Polygon(pair.dst, name="b.json")
    times = []
    for _ in range(count):
        t0 = time.perf_counter()
        try:
            within_pair(src, dst, within, size)
        except PolygonError:
            pass
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1", help="megapixels [1]")
    ap.add_argument("--pairs", default="star12,wavy48")
    ap.add_argument("--within", default="none,image,20", help="comma-separated: none, image, a margin [none,image,20]")
    ap.add_argument("--moves", type=int, default=40, help="pointer moves per drag [40]")
    ap.add_argument("--repeat", type=int, default=3, help="drags per case [3]")
    ap.add_argument("--profile", type=int, default=0, help="print cProfile's N costliest calls (cumulative) per case")
    ap.add_argument("--vertex", default="0", help="the target vertex dragged: an index, or 'outer': the rightmost "
                    "vertex of both polygons, dragged to its right (a margin's box follows it) [0]")  # fmt: skip
    ap.add_argument("--cut", type=int, default=0, help="also time N calls of within_pair per case (the command "
                    "line's cut of the ring, as on release), without the editor")  # fmt: skip
    ap.add_argument("--out", help="also write the table (markdown) there")
    args = ap.parse_args(argv)
    from warpcli.edit.session import EditPaths, EditSession

    rows = []
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        for mp in (float(s) for s in args.sizes.split(",")):
            w, h = bench_run.image_dims(mp)
            image = os.path.join(tmp, f"img{mp:g}.png")
            bench_run.write_png(image, bench_run.make_image(w, h))
            for pair in bench_run.make_pairs(w, h):
                if pair.name not in args.pairs.split(","):
                    continue
                for within in args.within.split(","):
                    print(f"edit_moves: {mp:g} MP ({w}x{h}), {pair.name}, within {within}...", file=sys.stderr, flush=True)
                    outward = args.vertex == "outer"
                    if outward:  # the rightmost vertex of both, made the target's
                        both = np.concatenate([pair.src, pair.dst])
                        index = int(np.argmax(both[:, 0])) % len(pair.dst)
                        pair = bench_run.Pair(pair.name, pair.src, pair.dst.copy())
                        pair.dst[index, 0] = both[:, 0].max()
                    else:
                        index = int(args.vertex)
                    session = EditSession(EditPaths.defaults(image, os.path.join(tmp, "a.json"), os.path.join(tmp, "b.json")))
                    session.preview_map({"src": pair.src.tolist(), "dst": pair.dst.tolist(),
                                         "options": {"within": None if within == "none" else within}})  # fmt: skip
                    prof = cProfile.Profile() if args.profile else None
                    moves, releases, errors = [], [], []
                    for _ in range(args.repeat):
                        t, r, e = drag(session, pair.src, pair.dst, within, args.moves, 0.03 * min(w, h), prof, index, outward)
                        moves += t
                        releases.append(r)
                        errors += e
                    if prof is not None:
                        print(f"--- cProfile of the moves: {mp:g} MP, {pair.name}, within {within}", file=sys.stderr)
                        pstats.Stats(prof, stream=sys.stderr).sort_stats("cumulative").print_stats(args.profile)
                    cut = float("nan")
                    if args.cut and within != "none":
                        cut = time_cut(pair, within, (w, h), args.cut)
                    name = pair.name if within == "none" else f"{pair.name}, within {within}"
                    name += "" if args.vertex == "0" else f", vertex {index}" + (" outwards" if outward else "")
                    rows.append((mp, w, h, name, moves, releases, errors, cut))
    lines = [
        f"warp edit: server time per drag move, in process ({platform.node()}, {os.cpu_count()} CPUs, load average "
        f"{load_before:.1f} before and {os.getloadavg()[0]:.1f} after; {args.moves} moves x {args.repeat} drags)",
        "",
        "| image | cage | moves | median ms | p95 ms | max ms | release ms (median) | failed |"
        + (" within_pair ms (median) |" if args.cut else ""),
        "|---|---|---|---|---|---|---|---|" + ("---|" if args.cut else ""),
    ]
    for mp, w, h, name, moves, releases, errors, cut in rows:
        ms = np.array(moves) * 1000
        lines.append(
            f"| {mp:g} MP ({w}x{h}) | {name} | {len(ms)} | {np.median(ms):.1f} | {np.percentile(ms, 95):.1f} | "
            f"{ms.max():.1f} | {statistics.median(releases) * 1000:.0f} | {len(errors)} |"
            + (f" {cut * 1000:.1f} |" if args.cut else "")
        )
        if errors:
            lines.append(f"|  | first error: {errors[0]} |")
    text = "\n".join(lines)
    print(text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
