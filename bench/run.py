#!/usr/bin/env python
"""Benchmark of the ``warp`` command against its peers, per image size and polygon pair.

    python bench/run.py                 # sizes 0.25,1,4,12 MP, 3 runs each (~15 min)
    python bench/run.py --quick         # sizes 0.25,1 MP, 3 runs each (~2 min)
    python bench/run.py --out bench/results/latest.md

What is measured (see bench/README.md):

* the whole ``warp -q IN --src A.json --dst B.json OUT`` command as a subprocess:
  median wall time and peak RSS;
* the stages of `warpcli.pipeline.warp_file` called in this process (medians);
* two peers, each a whole subprocess on the same files: scikit-image's
  PiecewiseAffineTransform estimated from the polygon vertices, and an affine
  ``skimage.transform.warp`` (the cost of reading, resampling and writing alone);
* the map's error in pixels against a map built on a 4x finer mesh;
* the start-up table of bench/startup.py: ``warp --help``, a bad-input error,
  the fixed cost (``warp`` on a 1 x 1 image) and the floor (numpy and
  OpenImageIO reading, resampling with a precomputed map and writing 1 MP).

Peak RSS of a child is taken from GNU ``/usr/bin/time -f %M`` when it works,
else from ``os.wait4`` in a small launcher process. It is *not* taken from
``os.wait4`` on a child of this process: Linux carries the parent's resident
set into a forked (or vforked) child's ``ru_maxrss`` at exec, so every child
of a benchmark that has itself warped a 12 MP image would report gigabytes.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

import startup  # bench/startup.py, beside this file

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STAGES = ("read", "mesh", "solve", "compose", "resample", "write")
DEFAULT_SIZES = "0.25,1,4,12"
QUICK_SIZES = "0.25,1"
ASPECT = 5 / 4  # width / height: square-ish, but not square, so x/y mix-ups show
AFFINE_ROTATION = 0.05  # radians, about the image centre

# ----------------------------------------------------------------------------
# Peers: one small script, run as a whole process like the warp command.

PEER_SCRIPT = r'''
"""Peers of `warp` for bench/run.py.

    python peer.py pwa    IN.png SRC.json DST.json OUT.png
    python peer.py affine IN.png SRC.json DST.json OUT.png

Reads and writes 8-bit PNG with OpenImageIO (the codec `warp` uses), so the
ratios compare the warps, not PNG libraries.
"""
import json
import sys

import numpy as np
import OpenImageIO as oiio
from skimage.transform import AffineTransform, PiecewiseAffineTransform, warp


def read(path):
    inp = oiio.ImageInput.open(path)
    if inp is None:
        sys.exit(f"peer: cannot read {path}: {oiio.geterror()}")
    px = inp.read_image(oiio.UINT8)
    inp.close()
    px = np.asarray(px)
    return px if px.ndim == 3 else px[:, :, None]


def write(path, px):
    h, w, c = px.shape
    out = oiio.ImageOutput.create(path)
    if out is None or not out.open(path, oiio.ImageSpec(w, h, c, "uint8")) or not out.write_image(px):
        sys.exit(f"peer: cannot write {path}: {oiio.geterror()}")
    out.close()


def load(path):
    with open(path) as fh:
        doc = json.load(fh)
    if isinstance(doc, dict):
        doc = doc["points"]
    # warpcli puts pixel centres at +0.5, skimage at integers.
    return np.asarray(doc, dtype=np.float64) - 0.5


mode, inp, src, dst, outp = sys.argv[1:6]
img = read(inp)
h, w = img.shape[:2]
if mode == "pwa":
    s, d = load(src), load(dst)
    # warp() takes the output -> input map, so estimate dst -> src.
    if hasattr(PiecewiseAffineTransform, "from_estimate"):
        tform = PiecewiseAffineTransform.from_estimate(d, s)
        if not tform:
            sys.exit(f"peer: PiecewiseAffineTransform estimation failed: {tform}")
    else:
        tform = PiecewiseAffineTransform()
        if not tform.estimate(d, s):
            sys.exit("peer: PiecewiseAffineTransform estimation failed")
elif mode == "affine":
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    c, s_ = np.cos(ROTATION), np.sin(ROTATION)
    m = np.array([[c, -s_, cx - c * cx + s_ * cy], [s_, c, cy - s_ * cx - c * cy], [0.0, 0.0, 1.0]])
    tform = AffineTransform(matrix=m)
else:
    sys.exit(f"peer: unknown mode {mode!r}")
out = warp(img, tform, order=1)  # float64 in [0, 1]
write(outp, np.clip(np.rint(out * 255.0), 0, 255).astype(np.uint8))
'''.replace("ROTATION", repr(AFFINE_ROTATION))

#: What the warp command and the peers import before any work (the start-up floors):
#: the default warp loads its kernels with llvmlite and imports neither scipy nor numba.
WARP_IMPORTS = "import warpcli.cli, warpcli.pipeline, OpenImageIO, triangle, llvmlite.binding"
PEER_IMPORTS = "import numpy, OpenImageIO, skimage.transform"

# ----------------------------------------------------------------------------
# Inputs


def image_dims(megapixels: float) -> tuple[int, int]:
    """(width, height) of a 5:4 image of about ``megapixels`` million pixels."""
    n = megapixels * 1e6
    h = max(8, round(math.sqrt(n / ASPECT)))
    w = max(8, round(n / h))
    return w, h


def make_image(w: int, h: int) -> np.ndarray:
    """A deterministic 8-bit RGB test image: a smooth colour ramp plus a fine pattern."""
    x = (np.arange(w, dtype=np.float32) + 0.5)[None, :]
    y = (np.arange(h, dtype=np.float32) + 0.5)[:, None]
    u, v = x / w, y / h
    # Fine pattern: an 8 px checker and a slanted grating of ~5 px period.
    checker = (((x // 8) + (y // 8)) % 2) * np.float32(2) - np.float32(1)
    grating = np.sin(np.float32(2 * np.pi / 5.3) * (0.8 * x + 0.6 * y))
    fine = np.float32(0.06) * checker + np.float32(0.05) * grating
    img = np.empty((h, w, 3), dtype=np.uint8)
    for c, base in enumerate(
        (
            0.15 + 0.7 * u,
            0.15 + 0.7 * v,
            0.5 + 0.3 * np.sin(np.float32(2 * np.pi) * (u + v)),
        )
    ):
        img[:, :, c] = np.clip(np.rint((base + fine) * 255), 0, 255).astype(np.uint8)
    return img


def write_png(path: str, px: np.ndarray) -> None:
    import OpenImageIO as oiio

    h, w, c = px.shape
    out = oiio.ImageOutput.create(path)
    if out is None or not out.open(path, oiio.ImageSpec(w, h, c, "uint8")) or not out.write_image(px):
        raise RuntimeError(f"cannot write {path}: {oiio.geterror()}")
    out.close()


def read_png(path: str) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise RuntimeError(f"cannot read {path}: {oiio.geterror()}")
    px = np.asarray(inp.read_image(oiio.UINT8))
    inp.close()
    return px


def star(cx, cy, r_in, r_out, points=6, phase=-math.pi / 2):
    k = np.arange(2 * points)
    r = np.where(k % 2 == 0, r_out, r_in)
    a = phase + np.pi * k / points
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)


def radial(cx, cy, n, radius, phase=0.0, sx=1.0, sy=1.0):
    """Star-shaped polygon r(a) sampled at n equal angles (simple if r > 0)."""
    a = phase + 2 * np.pi * np.arange(n) / n
    r = radius(a)
    return np.stack([cx + sx * r * np.cos(a), cy + sy * r * np.sin(a)], axis=1)


@dataclass(frozen=True)
class Pair:
    name: str
    src: np.ndarray
    dst: np.ndarray


def make_pairs(w: int, h: int) -> list[Pair]:
    """The polygon pairs for a w x h image (both polygons cover most of the image)."""
    cx, cy, s = w / 2.0, h / 2.0, float(min(w, h))
    big = 0.5 * s
    return [
        Pair(
            "star12",
            star(cx, cy, 0.25 * s, 0.48 * s),
            star(cx, cy, 0.18 * s, 0.47 * s, phase=-math.pi / 2 + 0.3),
        ),
        Pair(
            "wavy48",
            radial(cx, cy, 48, lambda a: big * (0.75 + 0.2 * np.sin(5 * a))),
            # A different wavy shape: 7 lobes, phase-shifted, squashed a little vertically.
            radial(cx, cy, 48, lambda a: big * (0.72 + 0.23 * np.sin(7 * a + 0.6)), phase=0.05, sy=0.96),
        ),
    ]


def write_polygon(path: str, pts: np.ndarray) -> None:
    with open(path, "w") as fh:
        json.dump([[float(x), float(y)] for x, y in pts], fh)


# ----------------------------------------------------------------------------
# Running children


class ChildFailed(RuntimeError):
    pass


LAUNCHER = r"""
import os, sys
pid = os.fork()
if pid == 0:
    try:
        os.execv(sys.argv[2], sys.argv[2:])
    finally:
        os._exit(127)
_, status, ru = os.wait4(pid, 0)
with open(sys.argv[1], "w") as fh:
    fh.write(f"{ru.ru_maxrss}\n")
sys.exit(os.waitstatus_to_exitcode(status) & 0xFF)
"""


class Runner:
    """Runs a command as a child, returning (wall seconds, peak RSS in KiB)."""

    def __init__(self, workdir: str) -> None:
        self.workdir = workdir
        self.rss_file = os.path.join(workdir, "maxrss.txt")
        self.time_bin = shutil.which("time", path="/usr/bin:/bin")
        self.method = ""
        if self.time_bin and self._probe_time():
            self.method = f"GNU {self.time_bin} -f %M"
        else:
            self.time_bin = None
            self.launcher = os.path.join(workdir, "launcher.py")
            with open(self.launcher, "w") as fh:
                fh.write(LAUNCHER)
            self.method = "os.wait4 in a launcher process (floor: the launcher's own ~10 MB)"

    def _probe_time(self) -> bool:
        try:
            r = subprocess.run(
                [self.time_bin, "-f", "%M", "-o", self.rss_file, sys.executable, "-c", "pass"],
                capture_output=True,
                timeout=60,
            )
            kib = self._read_rss()
        except (OSError, ValueError, subprocess.SubprocessError):
            return False
        return r.returncode == 0 and 1000 < kib < 200_000

    def _read_rss(self) -> int:
        with open(self.rss_file) as fh:
            lines = [ln.strip() for ln in fh if ln.strip()]
        return int(lines[-1])

    def run(self, cmd: list[str]) -> tuple[float, int]:
        if os.path.exists(self.rss_file):
            os.unlink(self.rss_file)
        if self.time_bin:
            full = [self.time_bin, "-f", "%M", "-o", self.rss_file, *cmd]
        else:
            exe = shutil.which(cmd[0]) or cmd[0]
            full = [sys.executable, "-I", "-S", "-c", LAUNCHER, self.rss_file, exe, *cmd[1:]]
        err_path = os.path.join(self.workdir, "child_stderr.txt")
        with open(err_path, "wb") as err:
            t0 = time.perf_counter()
            r = subprocess.run(full, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err)
            wall = time.perf_counter() - t0
        if r.returncode != 0:
            with open(err_path, "rb") as fh:
                tail = fh.read()[-2000:].decode("utf-8", "replace")
            raise ChildFailed(f"exit status {r.returncode}: {shlex.join(cmd)}\n{tail}")
        return wall, self._read_rss()


# ----------------------------------------------------------------------------
# Accuracy


def mesh_triangles(fmap) -> int:
    """Triangles of both FEM meshes of a map, from what the method reports."""
    info = fmap.describe()
    return info["source_mesh"]["triangles"] + info["target_mesh"]["triangles"]


def map_accuracy(src_path: str, dst_path: str, w: int, h: int) -> dict:
    """Error of the default map against one on a mesh 4x finer (max area / 4), in pixels."""
    from warpcli.grid import pixel_centres
    from warpcli.maps.compose import BijectiveMap
    from warpcli.maps.fem.mesh import auto_max_area
    from warpcli.polygon import read_polygon

    # The very polygons the warp command reads.
    src = read_polygon(src_path)
    dst = read_polygon(dst_path)
    t0 = time.perf_counter()
    coarse = BijectiveMap.between(src, dst, max_area=None)
    fine = BijectiveMap.between(src, dst, max_area=(auto_max_area(src) / 4.0, auto_max_area(dst) / 4.0))
    tri = mesh_triangles
    note = ""
    t_build = time.perf_counter() - t0
    pts = pixel_centres(w, h)
    a = coarse.inverse(pts)
    b = fine.inverse(pts)
    del pts
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    d = np.hypot(*(a[ok] - b[ok]).T)
    return {
        "area": (auto_max_area(src), auto_max_area(dst)),
        "tri_coarse": tri(coarse),
        "tri_fine": tri(fine),
        "pixels": int(ok.sum()),
        "mean": float(d.mean()) if d.size else math.nan,
        "p99": float(np.percentile(d, 99)) if d.size else math.nan,
        "max": float(d.max()) if d.size else math.nan,
        "seconds": time.perf_counter() - t0,
        "build": t_build,
        "note": note,
    }


# ----------------------------------------------------------------------------
# Results and tables


@dataclass
class Row:
    mp: float
    dims: tuple[int, int]
    pair: str
    warp: list = field(default_factory=list)  # (wall, rss KiB)
    pwa: list = field(default_factory=list)
    affine: list = field(default_factory=list)  # shared by the pairs of a size
    stages: dict = field(default_factory=dict)  # stage -> [seconds]
    triangles: int = 0
    cli_matches: bool | None = None
    accuracy: dict | None = None
    accuracy_skipped: str = ""
    errors: list = field(default_factory=list)


def med(xs):
    return statistics.median(xs) if xs else math.nan


def fsec(x: float) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    if x < 0.1:
        return f"{x:.3f}"
    if x < 100:
        return f"{x:.2f}"
    return f"{x:.0f}"


def fmb(kib) -> str:
    return "-" if kib is None or not math.isfinite(kib) else f"{kib / 1024:.0f}"


def fratio(a: float, b: float) -> str:
    if not (math.isfinite(a) and math.isfinite(b)) or b <= 0:
        return "-"
    return f"{a / b:.2f}"


def fpx(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.4f}" if x < 1 else f"{x:.2f}"


def size_label(row: Row) -> str:
    return f"{row.mp:g} MP {row.dims[0]}x{row.dims[1]}"


def render(title: str, headers: list[str], rows: list[list[str]], md: bool, left: int = 2) -> str:
    """An aligned plain-text table (or a markdown one); the first ``left`` columns left-aligned."""
    if md:
        out = [f"### {title}", "", "| " + " | ".join(headers) + " |"]
        out.append("|" + "|".join("---" if i < left else "---:" for i in range(len(headers))) + "|")
        out += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(out) + "\n"
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells):
        return "  ".join(c.ljust(wd) if i < left else c.rjust(wd) for i, (c, wd) in enumerate(zip(cells, widths)))

    rule = "-" * len(line(headers))
    return "\n".join([title, rule, line(headers), rule, *(line(r) for r in rows), rule]) + "\n"


def tables(rows: list[Row], args, md: bool) -> str:
    n = args.repeat
    t1 = []
    for r in rows:
        ww = [x[0] for x in r.warp]
        pw = [x[0] for x in r.pwa]
        aw = [x[0] for x in r.affine]
        t1.append(
            [
                size_label(r),
                r.pair,
                fsec(med(ww)),
                f"{fsec(min(ww))}-{fsec(max(ww))}" if ww else "-",
                fmb(med([x[1] for x in r.warp])),
                fsec(med(pw)),
                fmb(med([x[1] for x in r.pwa])),
                fsec(med(aw)),
                fmb(med([x[1] for x in r.affine])),
                fratio(med(ww), med(pw)),
                fratio(med(ww), med(aw)),
            ]
        )
    out = [
        render(
            f"Whole commands, each a subprocess: median wall seconds of {n} runs, peak RSS in MB",
            [
                "size",
                "pair",
                "warp s",
                "warp min-max",
                "warp MB",
                "PWA s",
                "PWA MB",
                "affine s",
                "affine MB",
                "warp/PWA",
                "warp/affine",
            ],
            t1,
            md,
        )
    ]
    t2 = []
    for r in rows:
        meds = {k: med(r.stages.get(k, [])) for k in STAGES}
        total = sum(v for v in meds.values() if math.isfinite(v))
        wall = med([x[0] for x in r.warp])
        dom = max(STAGES, key=lambda k: meds[k] if math.isfinite(meds[k]) else -1)
        share = meds[dom] / total if total > 0 else math.nan
        t2.append(
            [
                size_label(r),
                r.pair,
                f"{r.triangles:,}" if r.triangles else "-",
                *(fsec(meds[k]) for k in STAGES),
                fsec(total) if r.stages else "-",
                fsec(wall - total) if r.stages and math.isfinite(wall) else "-",
                f"{dom} {share:.0%}" if r.stages else "-",
                {True: "yes", False: "NO", None: "-"}[r.cli_matches],
            ]
        )
    out.append(
        render(
            f"warp stages, in-process warp_file(): median seconds of {n} calls",
            ["size", "pair", "triangles", *STAGES, "sum", "wall-sum", "largest", "CLI=inproc"],
            t2,
            md,
        )
    )
    t3 = []
    for r in rows:
        a = r.accuracy
        if a is None:
            t3.append([size_label(r), r.pair, r.accuracy_skipped or "-", *["-"] * 7])
            continue
        t3.append(
            [
                size_label(r),
                r.pair,
                f"{a['area'][0]:.3g} / {a['area'][1]:.3g}",
                f"{a['tri_coarse']:,}",
                f"{a['tri_fine']:,}",
                f"{a['pixels']:,}",
                fpx(a["mean"]),
                fpx(a["p99"]),
                fpx(a["max"]),
                fsec(a["seconds"]) + (f" ({a['note']})" if a["note"] else ""),
            ]
        )
    out.append(
        render(
            "Map accuracy: |inverse(p) - inverse_4x_finer(p)| in px over output pixel centres inside the target "
            f"(sizes <= {args.accuracy_max_mp:g} MP{'; disabled by --no-accuracy' if args.no_accuracy else ''})",
            [
                "size",
                "pair",
                "auto max_area src/dst px^2",
                "triangles",
                "triangles 4x finer",
                "pixels",
                "mean px",
                "p99 px",
                "max px",
                "seconds",
            ],
            t3,
            md,
        )
    )
    errs = [f"{size_label(r)} {r.pair}: {e}" for r in rows for e in r.errors]
    if errs:
        out.append("Errors:\n" + "\n".join("  " + e.replace("\n", "\n    ") for e in errs) + "\n")
    return "\n".join(out)


# ----------------------------------------------------------------------------
# Machine


def _version(mod: str) -> str:
    try:
        from importlib.metadata import version

        return version(mod)
    except Exception:
        return "?"


def machine_lines(runner: Runner, argv: list[str]) -> list[str]:
    cpu = "?"
    try:
        with open("/proc/cpuinfo") as fh:
            for ln in fh:
                if ln.startswith("model name"):
                    cpu = ln.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    mem = "?"
    try:
        with open("/proc/meminfo") as fh:
            for ln in fh:
                if ln.startswith("MemTotal:"):
                    mem = f"{int(ln.split()[1]) / 1024**2:.1f} GB"
                    break
    except OSError:
        pass
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count()
    try:
        rev = subprocess.run(
            ["git", "-C", REPO, "describe", "--always", "--dirty"], capture_output=True, text=True, timeout=10
        ).stdout.strip() or "?"
    except (OSError, subprocess.SubprocessError):
        rev = "?"
    import hashlib

    import warpcli

    pkg = os.path.dirname(warpcli.__file__)
    digest = hashlib.sha1()
    for name in sorted(f for f in os.listdir(pkg) if f.endswith(".py")):
        with open(os.path.join(pkg, name), "rb") as fh:
            digest.update(name.encode() + b"\0" + fh.read())
    try:
        with open("/proc/loadavg") as fh:
            load = " ".join(fh.read().split()[:3])
    except OSError:
        load = "?"
    threads = " ".join(
        f"{k}={os.environ[k]}" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS") if k in os.environ
    )
    return [
        f"command:  {shlex.join(getattr(sys, 'orig_argv', [sys.executable, *argv]))}  (cwd {os.getcwd()})",
        f"date:     {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}",
        f"machine:  nproc {usable} (of {os.cpu_count()}), {cpu}, {mem} RAM, {platform.platform()}",
        f"python:   {platform.python_version()}  numpy {np.__version__}  scipy {_version('scipy')}  "
        f"scikit-image {_version('scikit-image')}  OpenImageIO {_version('OpenImageIO')}  triangle {_version('triangle')}",
        f"warpcli:  {warpcli.__version__} at git {rev}, sources sha1 {digest.hexdigest()[:12]} ({pkg})",
        f"load:     {load} (1/5/15-min load average at start; other work on the machine skews the seconds)",
        f"peak RSS: {runner.method}" + (f"; {threads}" if threads else ""),
    ]


# ----------------------------------------------------------------------------


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", default=None, help=f"image sizes in megapixels, comma-separated [{DEFAULT_SIZES}]")
    p.add_argument("--repeat", type=int, default=3, help="runs per measurement; medians are reported [3]")
    p.add_argument("--quick", action="store_true", help=f"sizes {QUICK_SIZES} only")
    p.add_argument("--pairs", default="star12,wavy48", help="polygon pairs to run [star12,wavy48]")
    p.add_argument("--out", metavar="FILE.md", help="also write the tables as markdown to this file")
    p.add_argument("--no-accuracy", action="store_true", help="skip the accuracy measurement")
    p.add_argument(
        "--accuracy-max-mp", type=float, default=4.0, help="measure accuracy only up to this size in MP [4]"
    )
    p.add_argument("--keep", metavar="DIR", help="keep the generated images, polygons and outputs in DIR")
    p.add_argument("--no-startup", action="store_true", help="skip the start-up table (fixed cost, floor)")
    args = p.parse_args(argv)
    if args.quick and args.sizes is None:
        args.sizes = QUICK_SIZES
    try:
        args.size_list = [float(s) for s in (args.sizes or DEFAULT_SIZES).split(",") if s.strip()]
    except ValueError:
        p.error(f"--sizes: expected numbers separated by commas, got {args.sizes!r}")
    if not args.size_list or any(not (s > 0) for s in args.size_list):
        p.error("--sizes: need positive sizes")
    known = ("star12", "wavy48")
    bad = [x for x in args.pairs.split(",") if x.strip() and x.strip() not in known]
    if bad or not args.pairs.strip():
        p.error(f"--pairs: choose from {','.join(known)}, got {args.pairs!r}")
    if args.repeat < 1:
        p.error("--repeat must be at least 1")
    return args


def progress(msg: str) -> None:
    print(f"[bench {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    warp_exe = os.path.join(os.path.dirname(sys.executable), "warp")
    if not os.access(warp_exe, os.X_OK):
        sys.exit(f"bench: no warp executable next to {sys.executable} (pip install -e .)")
    # warpcli's bytecode, as an installation has it: a shell with
    # PYTHONDONTWRITEBYTECODE would otherwise make every warp compile its modules.
    startup.compile_bytecode()
    from warpcli.pipeline import warp_file

    if args.keep:
        os.makedirs(args.keep, exist_ok=True)
        tmp_ctx = None
        work = os.path.abspath(args.keep)
    else:
        tmp_ctx = tempfile.TemporaryDirectory(prefix="warpbench-")
        work = tmp_ctx.name
    try:
        runner = Runner(work)
        header = machine_lines(runner, sys.argv[1:] if argv is None else argv)
        print("\n".join(header), flush=True)
        peer = os.path.join(work, "peer.py")
        with open(peer, "w") as fh:
            fh.write(PEER_SCRIPT)
        # Start-up floors: what each contender pays before it touches a pixel.
        progress("measuring start-up floors")
        floors = {
            "python -c pass": [sys.executable, "-c", "pass"],
            "warp's imports": [sys.executable, "-c", WARP_IMPORTS],
            "peers' imports": [sys.executable, "-c", PEER_IMPORTS],
        }
        floor_text = []
        for label, cmd in floors.items():
            try:
                runs = [runner.run(cmd) for _ in range(args.repeat)]
                floor_text.append(f"{label} {fsec(med([r[0] for r in runs]))} s / {fmb(med([r[1] for r in runs]))} MB")
            except ChildFailed as e:
                floor_text.append(f"{label} failed ({str(e).splitlines()[0]})")
        header.append("start-up: " + "; ".join(floor_text) + f" (subprocess, median of {args.repeat})")
        print(header[-1], flush=True)
        # What warp pays before the first pixel, against the floor of any warp
        # (bench/startup.py; its own untimed first run compiles any missing kernel).
        startup_text = ""
        if not args.no_startup:
            progress("measuring the fixed cost and the floor (bench/startup.py)")
            try:
                startup_text = startup.run(repeat=args.repeat, megapixels=1.0, progress=progress)
            except RuntimeError as e:
                startup_text = f"start-up table failed: {e}\n"
            print("\n" + startup_text, flush=True)
        # Warm up in-process: the lazy imports inside warp_file (OpenImageIO, triangle,
        # llvmlite and the kernels) and first-call costs stay out of the stage timings.
        progress("warming up warp_file() in-process")
        ww, wh = image_dims(0.01)
        write_png(os.path.join(work, "warmup.png"), make_image(ww, wh))
        warm = make_pairs(ww, wh)[0]
        write_polygon(os.path.join(work, "warmup_src.json"), warm.src)
        write_polygon(os.path.join(work, "warmup_dst.json"), warm.dst)
        warp_file(
            os.path.join(work, "warmup.png"),
            os.path.join(work, "warmup_out.png"),
            os.path.join(work, "warmup_src.json"),
            os.path.join(work, "warmup_dst.json"),
        )
        wanted = [s.strip() for s in args.pairs.split(",") if s.strip()]
        rows: list[Row] = []
        t_start = time.perf_counter()
        for mp in args.size_list:
            w, h = image_dims(mp)
            tag = f"{mp:g}mp"
            img_path = os.path.join(work, f"in_{tag}.png")
            progress(f"{mp:g} MP: generating {w}x{h} image")
            write_png(img_path, make_image(w, h))
            pairs = [p for p in make_pairs(w, h) if p.name in wanted]
            size_rows = []
            for pair in pairs:
                src = os.path.join(work, f"{pair.name}_{tag}_src.json")
                dst = os.path.join(work, f"{pair.name}_{tag}_dst.json")
                write_polygon(src, pair.src)
                write_polygon(dst, pair.dst)
                size_rows.append((pair, src, dst, Row(mp, (w, h), pair.name)))
            affine_runs = []
            affine_errors = []
            # Interleave the repeats, so slow drift of a noisy machine hits every contender alike.
            for rep in range(args.repeat):
                for pair, src, dst, row in size_rows:
                    base = os.path.join(work, f"out_{pair.name}_{tag}")
                    progress(f"{mp:g} MP {pair.name} run {rep + 1}/{args.repeat}: warp, PWA, in-process")
                    try:
                        row.warp.append(runner.run([warp_exe, "-q", img_path, "--src", src, "--dst", dst, base + "_cli.png"]))
                    except ChildFailed as e:
                        row.errors.append(f"warp: {e}")
                    try:
                        row.pwa.append(runner.run([sys.executable, peer, "pwa", img_path, src, dst, base + "_pwa.png"]))
                    except ChildFailed as e:
                        row.errors.append(f"PWA peer: {e}")
                    try:
                        res = warp_file(img_path, base + "_inproc.png", src, dst)
                        for k, v in res.timings.items():
                            row.stages.setdefault(k, []).append(v)
                        row.triangles = mesh_triangles(res.map)
                        del res
                        if rep == 0 and os.path.exists(base + "_cli.png"):
                            row.cli_matches = bool(
                                np.array_equal(read_png(base + "_cli.png"), read_png(base + "_inproc.png"))
                            )
                    except Exception as e:  # report, keep benchmarking the rest
                        row.errors.append(f"in-process warp_file: {type(e).__name__}: {e}")
                progress(f"{mp:g} MP run {rep + 1}/{args.repeat}: affine floor")
                try:
                    affine_runs.append(
                        runner.run([sys.executable, peer, "affine", img_path, src, dst, os.path.join(work, f"out_affine_{tag}.png")])
                    )
                except ChildFailed as e:
                    affine_errors.append(f"affine peer: {e}")
            for pair, src, dst, row in size_rows:
                row.affine = list(affine_runs)
                row.errors += affine_errors[:1]
                if args.no_accuracy:
                    row.accuracy_skipped = "skipped (--no-accuracy)"
                elif mp > args.accuracy_max_mp:
                    row.accuracy_skipped = f"skipped (> {args.accuracy_max_mp:g} MP)"
                else:
                    progress(f"{mp:g} MP {pair.name}: accuracy against a 4x finer mesh")
                    try:
                        row.accuracy = map_accuracy(src, dst, w, h)
                    except Exception as e:
                        row.errors.append(f"accuracy: {type(e).__name__}: {e}")
                        row.accuracy_skipped = "failed"
                rows.append(row)
        elapsed = time.perf_counter() - t_start
        notes = [
            "warp = `warp -q IN --src A.json --dst B.json OUT` (default options: linear, max-area auto), 8-bit RGB PNG.",
            "PWA = skimage PiecewiseAffineTransform from the polygon vertices (dst -> src) + skimage.transform.warp "
            "order 1; affine = skimage.transform.warp order 1 with a rotation (pair-independent: one set of runs per "
            "size). Peers read and write PNG with OpenImageIO, as warp does.",
            "Ratios are of medians; > 1 means warp is slower. wall-sum = whole-command median minus the in-process "
            "stage sum (interpreter start-up, imports, polygon checks). CLI=inproc: the command's output equals "
            "warp_file()'s, pixel for pixel.",
            "pairs: star12 = 6-point stars r 0.25/0.48 -> 0.18/0.47 of min(W,H), rotated 0.3 rad; wavy48 = "
            "r(a) = R(0.75 + 0.2 sin 5a) -> R(0.72 + 0.23 sin(7a + 0.6)), 48 vertices, R = min(W,H)/2.",
            f"total benchmark time {elapsed:.0f} s.",
        ]
        text = tables(rows, args, md=False)
        print()
        print(text)
        if startup_text:
            print(startup_text)
        print("\n".join("note: " + n for n in notes))
        if args.out:
            md = ["# warp benchmark", "", "```", *header, "```", "", tables(rows, args, md=True), ""]
            if startup_text:
                md += ["```", startup_text.rstrip(), "```", ""]
            md += ["- " + n for n in notes]
            os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
            with open(args.out, "w") as fh:
                fh.write("\n".join(md) + "\n")
            progress(f"wrote {args.out}")
        return 1 if any(r.errors for r in rows) else 0
    finally:
        if tmp_ctx is not None:
            tmp_ctx.cleanup()


if __name__ == "__main__":
    sys.exit(main())
