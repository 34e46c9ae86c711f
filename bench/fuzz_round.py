#!/usr/bin/env python
"""Issue 27's fuzz round, from outside through the CLI: one or two generated cases per class.

    python bench/fuzz_round.py              # every case (~5 min on a busy 2-core machine)
    python bench/fuzz_round.py -k points    # the cases whose name holds a word
    python bench/fuzz_round.py --list

Each case makes its inputs in a fresh temporary directory, runs ``python -m
warpcli ...`` there (the code of this checkout) with its address space capped
at 2 GB (``RLIMIT_AS``) and 60 s of wall time, and checks what a user is
promised: the exit status (2 for bad input, 1 for a failure, 0 where the run
should succeed), no traceback, at most one ``error`` line on stderr, no
temporary file left behind, the inputs' bytes and modes untouched, and
whatever else the case asks (a file written, a message naming the culprit, a
mode, a time). It prints one row per case (``ok`` or what failed, with the
command) and exits 1 if any case failed.

The machine is shared: cases run one at a time; the bombs are small bounded
versions of the issue's (a few MB declared as GB, not GB written).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import resource
import shlex
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
PYTHON = sys.executable
MEMORY = 2 << 30
TIMEOUT = 60.0


# --------------------------------------------------------------------------- inputs


def write_png(path: str, img: np.ndarray) -> None:
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(np.ascontiguousarray(img))
    if not buf.write(path):
        raise RuntimeError(buf.geterror())


def image(h: int = 64, w: int = 64, channels: int = 3) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    planes = [x * 255 // max(w - 1, 1), y * 255 // max(h - 1, 1), (x + y) * 127 // max(h + w - 2, 1), 255 + 0 * x]
    return np.stack(planes[:channels], axis=-1).astype(np.uint8)


IRREGULAR = [[10.0, 8.0], [40.0, 6.0], [56.0, 20.0], [50.0, 54.0], [24.0, 58.0], [6.0, 30.0]]
SRC = [[8.0, 8.0], [56.0, 8.0], [56.0, 56.0], [8.0, 56.0]]
DST = [[10.0, 6.0], [58.0, 12.0], [50.0, 58.0], [6.0, 50.0]]


def basic(d: str, h: int = 64, w: int = 64, channels: int = 3) -> None:
    write_png(os.path.join(d, "in.png"), image(h, w, channels))
    dump(d, "src.json", SRC)
    dump(d, "dst.json", DST)


def dump(d: str, name: str, obj) -> None:
    with open(os.path.join(d, name), "w") as fh:
        json.dump(obj, fh)


def text(d: str, name: str, body: str | bytes) -> None:
    with open(os.path.join(d, name), "wb") as fh:
        fh.write(body.encode() if isinstance(body, str) else body)


def regular(n: int, r: float = 24.0, c: float = 32.0, sx: float = 1.0, phase: float = 0.0) -> list:
    a = phase + 2 * np.pi * np.arange(n) / n
    return np.stack([c + sx * r * np.cos(a), c + r * np.sin(a)], axis=1).tolist()


def comb(teeth: int, size: float = 60.0) -> list:
    """A comb polygon with ``teeth`` teeth (4 * teeth vertices), inside a size x size image."""
    w = size / (2 * teeth)
    top = []
    for k in range(teeth):
        x0 = 2 + 2 * k * w
        top += [[x0, 2.0], [x0 + w, 2.0], [x0 + w, size * 0.6], [x0 + 2 * w, size * 0.6]]
    return top[:-1] + [[size - 2, size * 0.6], [size - 2, size - 2], [2.0, size - 2]]


def tiff_stack(path: str, pages: list[np.ndarray]) -> None:
    import tifffile

    with tifffile.TiffWriter(path) as tw:
        for p in pages:
            tw.write(p, contiguous=False)


def cube_obj(d: str, name: str, lo: float, hi: float, bend: float = 0.0) -> None:
    v = [[x, y, z] for x in (lo, hi) for y in (lo, hi) for z in (lo, hi)]
    v = [[x + bend * (z - lo) / (hi - lo), y, z] for x, y, z in v]
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4),
             (1, 5, 7), (1, 7, 3)]  # fmt: skip
    body = "".join(f"v {x} {y} {z}\n" for x, y, z in v) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    text(d, name, body)


def volume_cages(d: str, n: int = 16) -> None:
    cube_obj(d, "a.obj", 3.0, n - 3.0)
    cube_obj(d, "b.obj", 3.0, n - 3.0, bend=2.0)


# --------------------------------------------------------------------------- running


@dataclass
class Outcome:
    rc: int | None
    stdout: str
    stderr: str
    seconds: float


def run(d: str, args: list[str], *, env: dict | None = None, timeout: float = TIMEOUT, fsize: int | None = None,
        stdin=None, term_after: float | None = None, cpu: int | None = None, umask: int | None = None) -> Outcome:  # fmt: skip
    """``python -m warpcli ARGS`` in ``d``, capped at 2 GB and ``timeout`` s (wall; ``cpu``: CPU seconds too)."""

    def limits() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))
        if cpu is not None:
            resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu))
        if umask is not None:
            os.umask(umask)
        if fsize is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
        os.setsid()

    full_env = dict(os.environ, PYTHONPATH=REPO, **(env or {}))
    t0 = time.perf_counter()
    proc = subprocess.Popen([PYTHON, "-m", "warpcli", *args], cwd=d, env=full_env, stdin=stdin or subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=limits, text=True)  # fmt: skip
    if term_after is not None:
        threading.Timer(term_after, lambda: proc.poll() is None and proc.send_signal(signal.SIGTERM)).start()
    try:
        out, err = proc.communicate(timeout=timeout)
        rc = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        rc = None
    return Outcome(rc, out, err, time.perf_counter() - t0)


def snapshot(d: str) -> dict[str, tuple[str, int]]:
    out = {}
    for root, _, files in os.walk(d):
        for f in files:
            p = os.path.join(root, f)
            if stat.S_ISREG(os.lstat(p).st_mode):
                with open(p, "rb") as fh:
                    out[os.path.relpath(p, d)] = (hashlib.sha256(fh.read()).hexdigest(), stat.S_IMODE(os.stat(p).st_mode))
            else:
                out[os.path.relpath(p, d)] = ("special", 0)
    return out


@dataclass
class Case:
    name: str
    klass: str
    setup: Callable[[str], None]
    args: list[str]
    rc: tuple[int, ...] = (2,)
    outputs: tuple[str, ...] = ()  # files that must exist afterwards (rc 0)
    says: str | None = None  # a regex stderr must match
    check: Callable[[str, Outcome], str | None] | None = None  # more checks: None or what failed
    run_kw: dict = field(default_factory=dict)
    allow_lines: int = 1  # error lines allowed on stderr
    partial: bool = False  # a batch: the other inputs' outputs stay when one fails
    replaced: tuple[str, ...] = ()  # existing files the run replaces (their bytes may change, not their mode)

    def __call__(self) -> tuple[bool, str, Outcome | None]:
        with tempfile.TemporaryDirectory(prefix="fuzz27-") as d:
            self.setup(d)
            before = snapshot(d)
            out = run(d, self.args, **self.run_kw)
            after = snapshot(d)
            problems = []
            if out.rc not in self.rc:
                problems.append(f"exit {out.rc} (want {'/'.join(map(str, self.rc))})")
            if "Traceback" in out.stderr or "Traceback" in out.stdout:
                problems.append("traceback")
            errors = [line for line in out.stderr.splitlines() if "error" in line.lower()]
            if len(errors) > self.allow_lines:
                problems.append(f"{len(errors)} error lines")
            if out.rc not in (0, None) and out.rc > 0 and not any(line.startswith("warp") for line in out.stderr.splitlines()):
                problems.append("no message")
            for name, (digest, mode) in before.items():
                now = after.get(name)
                if now is None:
                    problems.append(f"input {name} removed")
                elif now[0] != digest and name not in self.replaced:
                    problems.append(f"input {name} changed")
                elif now[1] != mode:
                    problems.append(f"input {name} mode {oct(mode)} -> {oct(now[1])}")
            new = sorted(set(after) - set(before))
            if out.rc != 0 and new and not (self.partial and all(n.startswith("out/") for n in new)):
                problems.append(f"left behind: {', '.join(new)}")
            leftovers = [n for n in new if re.search(r"(^|/)\.|\.tmp|\.partial|~$|\.warp-", n)]
            if out.rc == 0 and leftovers:
                problems.append(f"temporaries left: {', '.join(leftovers)}")
            for o in self.outputs:
                if out.rc == 0 and o not in after:
                    problems.append(f"{o} not written")
            if self.says and not re.search(self.says, out.stderr, re.I | re.S):
                problems.append(f"stderr does not say /{self.says}/")
            if self.check is not None:
                extra = self.check(d, out)
                if extra:
                    problems.append(extra)
            return not problems, "; ".join(problems), out


# --------------------------------------------------------------------------- cases


def mode_of(name: str, want: int = 0o644):
    def check(d: str, out: Outcome) -> str | None:
        p = os.path.join(d, name)
        if not os.path.exists(p):
            return f"{name} missing"
        m = stat.S_IMODE(os.stat(p).st_mode)
        return None if m == want else f"{name} mode {oct(m)}, want {oct(want)}"

    return check


def tall_thin(d: str, out: Outcome) -> str | None:
    """Ten times the rows (image and polygons) should cost about ten times the warp's time (startup aside)."""

    def work(h: int) -> float:
        sub = os.path.join(d, f"h{h}")
        os.mkdir(sub)
        write_png(os.path.join(sub, "in.png"), image(h, 16))
        dump(sub, "s.json", [[2, 2], [14, 2], [14, h - 2], [2, h - 2]])
        dump(sub, "t.json", [[3, 1], [15, 3], [13, h - 1], [1, h - 3]])
        o = run(sub, ["in.png", "--src", "s.json", "--dst", "t.json", "--tiled", "o.png", "-v"])
        if o.rc != 0:
            raise RuntimeError(o.stderr)
        return sum(float(m) for m in re.findall(r"warp: \w+\s+([0-9.]+) s", o.stderr))

    small, big = work(2000), work(20000)
    ratio = big / max(small, 1e-3)
    return None if ratio < 20 else f"10x the rows took {ratio:.0f}x the time ({small:.2f} s -> {big:.2f} s)"


def seconds_below(limit: float):
    return lambda d, out: None if out.seconds < limit else f"took {out.seconds:.1f} s (limit {limit} s)"


def sequence_setup(d: str) -> None:
    basic(d)
    for k in (1, 11):
        write_png(os.path.join(d, f"f.{k}.png"), image())


def points_setup(d: str, body: str | bytes, name: str = "p.csv") -> None:
    basic(d)
    text(d, name, body)


def csv_check(d: str, out: Outcome) -> str | None:
    rows = open(os.path.join(d, "q.csv"), encoding="utf-8-sig").read().splitlines()
    if len(rows) != 3:
        return f"{len(rows)} rows written, want 3: {rows}"
    first = rows[0].split(",")
    if len(first) != 3 or first[2].strip() != "a":
        return f"extra column lost: {rows[0]!r}"
    if abs(float(first[0]) - 20.0) < 1e-9 and abs(float(first[1]) - 20.0) < 1e-9:
        return "first point written back unmapped"
    return None


def obj_check(d: str, out: Outcome) -> str | None:
    vts = [line for line in open(os.path.join(d, "q.obj"), encoding="utf-8-sig") if line.startswith("vt ")]
    return None if len(vts) == 3 else f"{len(vts)} vt lines written, want 3"


def nifti(d: str, name: str, data: np.ndarray, affine=None, big_endian: bool = False, header_shape=None) -> None:
    import nibabel as nib

    img = nib.Nifti1Image(data, np.eye(4) if affine is None else affine)
    if big_endian:
        hdr = img.header.as_byteswapped(">")
        img = nib.Nifti1Image(data.astype(data.dtype.newbyteorder(">")), img.affine, hdr)
    nib.save(img, os.path.join(d, name))
    if header_shape is not None:  # a header that declares another size than the data holds
        p = os.path.join(d, name)
        raw = bytearray(open(p, "rb").read())
        dims = np.frombuffer(bytes(raw[40:56]), dtype="<i2").copy()
        dims[1 : 1 + len(header_shape)] = header_shape
        raw[40:56] = dims.astype("<i2").tobytes()
        open(p, "wb").write(bytes(raw))


def vol_setup(kind: str):
    def setup(d: str) -> None:
        volume_cages(d)
        x = np.arange(16 ** 3, dtype=np.uint8).reshape(16, 16, 16)
        if kind == "big-endian":
            nifti(d, "v.nii", x.astype(np.int16), big_endian=True)
        elif kind == "zero-dim":
            nifti(d, "v.nii", np.zeros((16, 0, 16), np.uint8))
        elif kind == "complex":
            nifti(d, "v.nii", x.astype(np.complex64))
        elif kind in ("float128", "rgb24"):
            nifti(d, "v.nii", x.astype(np.float32))
            p = os.path.join(d, "v.nii")
            raw = bytearray(open(p, "rb").read())
            code, bits = {"float128": (1536, 128), "rgb24": (128, 24)}[kind]
            raw[70:74] = np.array([code, bits], "<i2").tobytes()  # datatype, bitpix
            open(p, "wb").write(bytes(raw))
        elif kind == "declares-4GB":
            nifti(d, "v.nii", x, header_shape=(2048, 2048, 1024))
        elif kind == "nan-affine":
            nifti(d, "v.nii", x)
            p = os.path.join(d, "v.nii")
            raw = bytearray(open(p, "rb").read())
            raw[252:256] = np.array([0, 1], "<i2").tobytes()  # qform_code 0, sform_code 1
            raw[280:292] = np.array([np.nan, 0, 0], "<f4").tobytes()  # srow_x
            open(p, "wb").write(bytes(raw))
        elif kind == "tiff-mixed":
            pages = [x[k] for k in range(16)]
            pages[2] = pages[2].astype(np.uint16) * 300
            tiff_stack(os.path.join(d, "v.tif"), pages)
        elif kind == "tiff-shapes":
            pages = [x[k] for k in range(16)]
            pages[5] = np.zeros((8, 16), np.uint8)
            tiff_stack(os.path.join(d, "v.tif"), pages)
        elif kind == "page-by-page":
            import tifffile

            with tifffile.TiffWriter(os.path.join(d, "v.tif")) as tw:
                for k in range(16):
                    tw.write(x[k], contiguous=False)
        elif kind == "good":
            import tifffile

            tifffile.imwrite(os.path.join(d, "v.tif"), x)

    return setup


def silent_server(d: str, answer: bytes | None) -> None:
    """A TCP server on a free port that answers ``answer`` (or nothing, ever) to every connection; port in ``port``."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(8)
    text(d, "port", str(s.getsockname()[1]))

    def serve() -> None:
        conns = []
        s.settimeout(70)
        try:
            while True:
                c, _ = s.accept()
                conns.append(c)
                if answer is not None:
                    c.sendall(answer)
        except OSError:
            pass

    threading.Thread(target=serve, daemon=True).start()


def with_port(args: list[str]):
    """args with {port} filled from the directory's ``port`` file, at run time."""
    return args


def exr_bomb(d: str) -> None:
    """A small EXR (zip, constant) that decodes to about 1.2 GB of float pixels: 20000 x 15000 x 1 float."""
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(20000, 15000, 2, "float")
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(os.path.join(d, "bomb.exr"))
    out.open(os.path.join(d, "bomb.exr"), spec)
    line = np.full((20000, 2), 0.5, np.float32)
    for y in range(15000):
        out.write_scanline(y, 0, line)
    out.close()
    basic(d)


def cases() -> list[Case]:
    C = []
    add = C.append
    cage = {"vertices": [[8, 8], [56, 8], [56, 56], [8, 56], [32, 32]],
            "faces": [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]}  # fmt: skip
    cage_bad = {"vertices": [[8, 8], [56, 8], [56, 56], [8, 56], [70, 32]],
                "faces": [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]}  # fmt: skip

    # -- data loss and silent wrong results
    add(Case("tiled output above OIIO's size limit is kept", "data loss", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--size", "3000x2000", "--tiled", "big.png"],
             rc=(0,), outputs=("big.png",), run_kw={"env": {"OPENIMAGEIO_OPTIONS": "limits:imagesize_MB=5"}}))  # fmt: skip
    add(Case("sequence output frame is another input frame", "data loss", sequence_setup,
             ["f.@.png", "--src", "src.json", "--dst", "dst.json", "f.1@.png", "--frames", "1,11"],
             says=r"f\.11\.png|input|overwrite"))  # fmt: skip
    add(Case("points OUT is the --src file", "data loss", lambda d: points_setup(d, "20,20\n30,30\n"),
             ["points", "p.csv", "src.json", "--src", "src.json", "--dst", "dst.json"]))  # fmt: skip
    add(Case("--report names the --theta input", "data loss", lambda d: (basic(d), dump(d, "t.json", regular(4, 20))),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--theta", "t.json", "--report", "t.json", "o.png"]))  # fmt: skip
    add(Case("--save-theta names the --theta input", "data loss", lambda d: (basic(d), dump(d, "t.json", regular(4, 20))),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--theta", "t.json", "--save-theta", "t.json", "o.png"]))  # fmt: skip
    add(Case("--save-map names the input image", "data loss", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--save-map", "in.png", "o.exr"]))  # fmt: skip
    for ext in ("tga", "fits", "png"):
        add(Case(f"--tiled {ext} on a full disk (RLIMIT_FSIZE 20 kB)", "data loss", basic,
                 ["in.png", "--src", "src.json", "--dst", "dst.json", "--size", "1500x1000", "--tiled", f"o.{ext}"],
                 rc=(1,), run_kw={"fsize": 20_000}))  # fmt: skip
    add(Case("points output on a full disk", "data loss",
             lambda d: points_setup(d, "".join(f"{20 + i % 20},{20 + i // 200 % 20}\n" for i in range(20000))),
             ["points", "p.csv", "q.csv", "--src", "src.json", "--dst", "dst.json"], rc=(1,),
             run_kw={"fsize": 50_000}))  # fmt: skip
    for method in ("bem", "mfs"):
        add(Case(f"{method} with a 7-gon Theta flattened 1e9 in x", "silent wrong",
                 lambda d: (basic(d), dump(d, "t.json", regular(7, 1.0, 0.0, sx=1e9)), dump(d, "s7.json", regular(7, 24)),
                            dump(d, "d7.json", regular(7, 22, phase=0.2))),
                 ["in.png", "--src", "s7.json", "--dst", "d7.json", "--method", method, "--theta", "t.json",
                  "--report", "r.json", "o.png"], rc=(0, 1, 2),
                 check=lambda d, out: None if out.rc != 0 or None not in json.load(open(os.path.join(d, "r.json"))
                                                                                  ).get("conformal", {}).values()
                 else "exit 0 with null distortion"))  # fmt: skip
    add(Case("volume: uint16 page among uint8 pages", "silent wrong", vol_setup("tiff-mixed"),
             ["volume", "v.tif", "o.tif", "--src", "a.obj", "--dst", "b.obj"], says=r"page"))  # fmt: skip
    add(Case("points CSV with a BOM, no header, extra column", "silent wrong",
             lambda d: points_setup(d, "\ufeff20,20,a\n30,30,b\n40,40,c\n".encode()),
             ["points", "p.csv", "q.csv", "--src", "src.json", "--dst", "dst.json"], rc=(0,), check=csv_check))  # fmt: skip
    add(Case("OBJ with a BOM keeps its first vt", "silent wrong",
             lambda d: points_setup(d, "\ufeffvt 0.3 0.3\nvt 0.5 0.5\nvt 0.6 0.4\n".encode(), "p.obj"),
             ["points", "p.obj", "q.obj", "--src", "src.json", "--dst", "dst.json", "--texture-size", "64x64"],
             rc=(0,), check=obj_check))  # fmt: skip
    add(Case("report mode follows the umask (0644)", "silent wrong", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--report", "r.json", "--save-theta", "t.json", "o.png"],
             rc=(0,), check=lambda d, o: mode_of("r.json")(d, o) or mode_of("t.json")(d, o)))  # fmt: skip
    add(Case("points output mode follows the umask", "silent wrong", lambda d: points_setup(d, "20,20\n"),
             ["points", "p.csv", "q.csv", "--src", "src.json", "--dst", "dst.json"], rc=(0,), check=mode_of("q.csv")))  # fmt: skip
    add(Case("volume: a TIFF stack written page by page", "message", vol_setup("page-by-page"),
             ["volume", "v.tif", "o.tif", "--src", "a.obj", "--dst", "b.obj"], rc=(0,), outputs=("o.tif",)))  # fmt: skip
    add(Case("volume output mode follows the umask", "silent wrong", vol_setup("good"),
             ["volume", "v.tif", "o.tif", "--src", "a.obj", "--dst", "b.obj", "--report", "r.json"], rc=(0,),
             check=lambda d, o: mode_of("o.tif")(d, o) or mode_of("r.json")(d, o)))  # fmt: skip

    # -- tracebacks
    for kind in ("big-endian", "zero-dim", "complex", "float128", "rgb24", "tiff-shapes", "nan-affine"):
        name = "v.tif" if kind.startswith("tiff") else "v.nii"
        add(Case(f"volume: {kind}", "traceback", vol_setup(kind),
                 ["volume", name, "o" + name[1:], "--src", "a.obj", "--dst", "b.obj"],
                 rc=(0, 2) if kind in ("big-endian", "rgb24") else (2,),
                 says=r"affine" if kind == "nan-affine" else None))  # fmt: skip
    for method in ("bem", "mfs"):
        add(Case(f"--nodes below the vertex count ({method})", "traceback",
                 lambda d: (basic(d), dump(d, "s8.json", regular(8)), dump(d, "d8.json", regular(8, 20))),
                 ["in.png", "--src", "s8.json", "--dst", "d8.json", "--method", method, "--nodes", "5", "o.png"]))  # fmt: skip
        add(Case(f"--nodes 100000 ({method})", "traceback", basic,
                 ["in.png", "--src", "src.json", "--dst", "dst.json", "--method", method, "--nodes", "100000", "o.png"],
                 rc=(1, 2), check=seconds_below(30)))  # fmt: skip
    add(Case("points with a 401-digit integer", "traceback", lambda d: points_setup(d, "1" + "0" * 400 + ",20\n"),
             ["points", "p.csv", "q.csv", "--src", "src.json", "--dst", "dst.json"]))  # fmt: skip
    add(Case("points JSON with a 401-digit integer", "traceback",
             lambda d: points_setup(d, "[[" + "1" + "0" * 400 + ", 20]]", "p.json"),
             ["points", "p.json", "q.json", "--src", "src.json", "--dst", "dst.json"]))  # fmt: skip
    add(Case("--size 3000000000x1", "traceback", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--size", "3000000000x1", "o.png"]))  # fmt: skip
    for sched in ("foo", "", "xyz://h:1"):
        add(Case(f"--scheduler {sched!r}", "traceback", lambda d: (basic(d), os.mkdir(os.path.join(d, "out"))),
                 ["in.png", "--src", "src.json", "--dst", "dst.json", "--out-dir", "out", "--scheduler", sched]))  # fmt: skip

    # -- memory and time bombs
    add(Case("sequence of 100,000 missing frames, keyframed target", "bomb",
             lambda d: (basic(d), dump(d, "k.json", {"frames": {"0": DST, "99999": SRC}})),
             ["f.@.png", "--src", "src.json", "--dst", "k.json", "o.@.png", "--frames", "0-99999"],
             rc=(1, 2), allow_lines=6, check=lambda d, o: seconds_below(50)(d, o) or (
                 None if len(o.stderr.splitlines()) <= 7 else f"{len(o.stderr.splitlines())} stderr lines")))  # fmt: skip
    add(Case("apply-map with a small EXR that decodes to 2.4 GB", "bomb", exr_bomb,
             ["apply-map", "bomb.exr", "in.png", "o.png"], rc=(1, 2), check=seconds_below(40)))  # fmt: skip
    add(Case("MFS on a 52-vertex comb", "bomb", lambda d: (basic(d, 64, 64), dump(d, "c.json", comb(13)),
                                                           dump(d, "d.json", comb(13))),
             ["in.png", "--src", "c.json", "--dst", "d.json", "--method", "mfs", "o.png"], rc=(0, 1, 2),
             run_kw={"cpu": 60, "timeout": 180}))  # fmt: skip
    add(Case("BEM on a 600-vertex polygon", "bomb",
             lambda d: (basic(d, 128, 128), dump(d, "s.json", regular(600, 50, 64)), dump(d, "d.json", regular(600, 45, 64, sx=1.2))),
             ["in.png", "--src", "s.json", "--dst", "d.json", "--method", "bem", "o.png"], rc=(0, 1, 2),
             run_kw={"cpu": 60, "timeout": 180}))  # fmt: skip
    add(Case("--tiled on a tall thin image scales linearly", "bomb", lambda d: None, ["--version"], rc=(0,),
             check=tall_thin))  # fmt: skip
    add(Case("volume: NIfTI declaring 4 GB", "bomb", vol_setup("declares-4GB"),
             ["volume", "v.nii", "o.nii", "--src", "a.obj", "--dst", "b.obj"], check=seconds_below(20)))  # fmt: skip
    add(Case("scheduler that accepts and never answers", "bomb",
             lambda d: (basic(d), os.mkdir(os.path.join(d, "out")), silent_server(d, None)),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--out-dir", "out", "--scheduler", "tcp://127.0.0.1:{port}"],
             rc=(1, 2), check=seconds_below(50)))  # fmt: skip
    add(Case("scheduler where an HTTP server answers", "traceback",
             lambda d: (basic(d), os.mkdir(os.path.join(d, "out")), silent_server(d, b"HTTP/1.0 200 OK\r\n\r\nhello" * 50)),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--out-dir", "out", "--scheduler", "tcp://127.0.0.1:{port}"],
             rc=(1, 2), check=seconds_below(50)))  # fmt: skip
    add(Case("a FIFO among batch inputs", "bomb",
             lambda d: (basic(d), os.mkfifo(os.path.join(d, "fifo.png")), os.mkdir(os.path.join(d, "out"))),
             ["in.png", "fifo.png", "--src", "src.json", "--dst", "dst.json", "--out-dir", "out"], rc=(1, 2),
             says=r"fifo\.png", check=seconds_below(30), partial=True))  # fmt: skip

    # -- unclear messages
    add(Case("one-channel frame among RGB frames with --background r,g,b", "message",
             lambda d: (basic(d), write_png(os.path.join(d, "g.png"), image(channels=1)), os.mkdir(os.path.join(d, "out"))),
             ["in.png", "g.png", "--src", "src.json", "--dst", "dst.json", "--out-dir", "out", "--background", "1,2,3"],
             rc=(1, 2), says=r"g\.png", partial=True, check=lambda d, o: None if os.path.exists(os.path.join(d, "out", "in.png")) else "in.png's output lost"))  # fmt: skip
    add(Case("an @ in a batch file name", "message",
             lambda d: (basic(d), write_png(os.path.join(d, "photo@2x.png"), image()), os.mkdir(os.path.join(d, "out"))),
             ["photo@2x.png", "in.png", "--src", "src.json", "--dst", "dst.json", "--out-dir", "out"], rc=(0,),
             outputs=("out/photo@2x.png",)))  # fmt: skip
    add(Case("output pattern with a single input", "message", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "o.@.png"], rc=(0, 2),
             check=lambda d, o: None if o.rc == 0 or "in.png" not in o.stderr.split("error:")[-1][:40] else "blames the input"))  # fmt: skip
    add(Case("a 1.0 px edge", "message", lambda d: (basic(d), dump(d, "e.json", [[8, 8], [9, 8], [56, 56], [8, 56]])),
             ["in.png", "--src", "e.json", "--dst", "dst.json", "o.png"], rc=(0, 2),
             check=lambda d, o: "too short (the minimum is 1.0 px)" in o.stderr and "1.0 px edge said too short than 1.0"))  # fmt: skip
    add(Case("a 1e300-scaled Theta", "message", lambda d: (basic(d), dump(d, "t.json", (np.array(regular(4)) * 1e300).tolist())),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--theta", "t.json", "o.png"], rc=(0, 2),
             check=lambda d, o: "not strictly convex" in o.stderr and "says not strictly convex"))  # fmt: skip
    add(Case("a 1e300 cage mesh", "message", lambda d: (basic(d), dump(d, "c.json", {**cage, "vertices": (np.array(cage["vertices"]) * 1e300).tolist()})),
             ["in.png", "--src", "c.json", "--dst", "c.json", "o.png"],
             check=lambda d, o: "degenerate face" in o.stderr and "says degenerate face"))  # fmt: skip
    add(Case("rotated start vertex warns", "message",
             lambda d: (basic(d), dump(d, "s.json", IRREGULAR), dump(d, "d.json", IRREGULAR[2:] + IRREGULAR[:2])),
             ["in.png", "--src", "s.json", "--dst", "d.json", "o.png"], rc=(0,), says=r"warn|rotat|relabel|start"))  # fmt: skip
    add(Case("normalised coordinates warn", "message",
             lambda d: (basic(d), dump(d, "s.json", (np.array(SRC) / 64).tolist()), dump(d, "d.json", (np.array(DST) / 64).tolist())),
             ["in.png", "--src", "s.json", "--dst", "d.json", "o.png"], rc=(0, 2), says=r"normali|0\.\.1|pixel"))  # fmt: skip
    add(Case("alpha dropped writing JPEG warns", "message", lambda d: basic(d, channels=4),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "o.jpg"], rc=(0,), says=r"alpha"))  # fmt: skip
    add(Case("README cleanup command has its parentheses", "message", lambda d: None, ["--version"], rc=(0,),
             check=lambda d, o: None if not re.search(r"find [^\n]*-name [^\n(]*-o -name [^\n]*-delete",
                                                      open(os.path.join(REPO, "README.md")).read()) else "README find without parentheses"))  # fmt: skip

    # -- signals
    for delay in (0.2, *np.round(np.arange(0.30, 0.51, 0.02), 2), 0.8, 1.5):
        add(Case(f"SIGTERM after {delay} s", "signal", basic,
                 ["in.png", "--src", "src.json", "--dst", "dst.json", "o.png"], rc=(0, 1, 143, -15),
                 run_kw={"term_after": delay, "timeout": 20},
                 check=lambda d, o: None if o.rc != 0 or os.path.exists(os.path.join(d, "o.png")) else "exit 0, no output"))  # fmt: skip

    # -- surfaces added since
    add(Case("texture: garbage OBJ", "new surface", lambda d: (text(d, "a.obj", "v 1 2\nf 1 2 9\n"), text(d, "b.obj", "vt 0 0\n")),
             ["texture", "a.obj", "b.obj", "o.png"]))  # fmt: skip
    add(Case("texture: OUT is the SRC mesh", "new surface",
             lambda d: [text(d, n, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n") for n in ("a.obj", "b.obj")],
             ["texture", "a.obj", "b.obj", "a.obj"]))  # fmt: skip
    add(Case("--within with a missing file", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--within", "nope.json", "o.png"]))  # fmt: skip
    add(Case("--within -5", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--within", "-5", "o.png"]))  # fmt: skip
    add(Case("cage mesh that folds", "new surface", lambda d: (basic(d), dump(d, "c.json", cage), dump(d, "f.json", cage_bad)),
             ["in.png", "--src", "c.json", "--dst", "f.json", "o.png"]))  # fmt: skip
    add(Case("cage mesh with a face index out of range", "new surface",
             lambda d: (basic(d), dump(d, "c.json", cage), dump(d, "f.json", {**cage, "faces": [[0, 1, 9]]})),
             ["in.png", "--src", "c.json", "--dst", "f.json", "o.png"]))  # fmt: skip
    add(Case("cage mesh with NaN / huge index / wrong types", "new surface",
             lambda d: (basic(d), text(d, "c.json", '{"vertices": [[0, NaN], [1, 2], [3, 4]], "faces": [[0, 1, 2]]}'),
                        dump(d, "f.json", {"vertices": cage["vertices"], "faces": [[0, 1, 10**30]]})),
             ["in.png", "--src", "c.json", "--dst", "f.json", "o.png"]))  # fmt: skip
    add(Case("--theta none that folds", "new surface",
             lambda d: (basic(d), dump(d, "s.json", regular(8, 24)),
                        dump(d, "d.json", [[32 + (24 if k % 2 == 0 else 3) * np.cos(k * np.pi / 4), 32 + (24 if k % 2 == 0 else 3) * np.sin(k * np.pi / 4)] for k in range(8)])),
             ["in.png", "--src", "s.json", "--dst", "d.json", "--theta", "none", "o.png"], rc=(0, 2)))  # fmt: skip
    add(Case("--theta none with --method bem", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--theta", "none", "--method", "bem", "o.png"], rc=(0, 2)))  # fmt: skip
    add(Case("--compression 10", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--compression", "10", "o.png"]))  # fmt: skip
    add(Case("--compression with a TIFF output", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--compression", "5", "o.tif"], rc=(0, 2)))  # fmt: skip
    add(Case("--feather nan", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--outside", "input", "--feather", "nan", "o.png"]))  # fmt: skip
    add(Case("--feather 1e308", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--outside", "input", "--feather", "1e308", "o.png"], rc=(0, 2)))  # fmt: skip
    add(Case("--feather without --outside input", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--feather", "3", "o.png"], rc=(0, 2)))  # fmt: skip
    add(Case("apply-map --map-scale refuse on another size", "new surface",
             lambda d: (basic(d), write_png(os.path.join(d, "big.png"), image(96, 80)),
                        run(d, ["in.png", "--src", "src.json", "--dst", "dst.json", "--save-map", "m.exr", "o.png"])),
             ["apply-map", "m.exr", "big.png", "q.png", "--map-scale", "refuse"], says=r"big\.png|size"))  # fmt: skip
    add(Case("apply-map --map-scale stretch", "new surface",
             lambda d: (basic(d), write_png(os.path.join(d, "big.png"), image(96, 80)),
                        run(d, ["in.png", "--src", "src.json", "--dst", "dst.json", "--save-map", "m.exr", "o.png"])),
             ["apply-map", "m.exr", "big.png", "q.png", "--map-scale", "stretch"], rc=(0,), outputs=("q.png",)))  # fmt: skip
    add(Case("apply-map with a map holding NaN and inf", "new surface",
             lambda d: (basic(d), write_png(os.path.join(d, "m.png"), image()), ),
             ["apply-map", "in.png", "in.png", "q.png"], rc=(0, 2)))  # fmt: skip
    add(Case("keyframed cage meshes with different faces", "new surface",
             lambda d: (basic(d), dump(d, "c.json", cage),
                        dump(d, "k.json", {"frames": {"0": cage, "5": {**cage, "faces": [[0, 1, 2, 3]]}}})),
             ["in.png", "--src", "c.json", "--dst", "k.json", "--frame", "2", "o.png"]))  # fmt: skip
    add(Case("keyframes with a negative / non-integer frame", "new surface",
             lambda d: (basic(d), dump(d, "k.json", {"frames": {"-1": DST, "2.5": DST}})),
             ["in.png", "--src", "src.json", "--dst", "k.json", "--frame", "1", "o.png"]))  # fmt: skip
    def texture_setup(d: str, bom: bool = False) -> None:
        import shutil

        for f in ("texture_square.obj", "texture_square.mtl", "texture_cat.png", "texture_arch.obj"):
            shutil.copy(os.path.join(REPO, "sample_images", f), d)
        if bom:
            p = os.path.join(d, "texture_square.obj")
            body = open(p, "rb").read()
            open(p, "wb").write(b"\xef\xbb\xbf" + body)

    tex = ["texture", "texture_square.obj", "texture_arch.obj", "t.png", "--src-corners", "0,8,80,72",
           "--dst-corners", "16,0,102,118", "--size", "128x128"]  # fmt: skip
    add(Case("texture: the sample runs", "new surface", texture_setup, tex, rc=(0,), outputs=("t.png",)))  # fmt: skip
    add(Case("texture: SRC OBJ starting with a BOM", "silent wrong", lambda d: texture_setup(d, bom=True), tex,
             rc=(0,), outputs=("t.png",)))  # fmt: skip
    add(Case("texture: output on a full disk", "data loss", texture_setup, tex[:-1] + ["1024x1024"], rc=(1,),
             run_kw={"fsize": 20_000}))  # fmt: skip
    add(Case("texture: corners out of range", "new surface", texture_setup,
             ["texture", "texture_square.obj", "texture_arch.obj", "t.png", "--src-corners", "0,8,80,72000",
              "--dst-corners", "16,0,102,118"]))  # fmt: skip
    add(Case("volume: output on a full disk", "data loss", vol_setup("good"),
             ["volume", "v.tif", "o.tif", "--src", "a.obj", "--dst", "b.obj"], rc=(1,), run_kw={"fsize": 2_000}))  # fmt: skip
    add(Case("report on a full disk", "data loss", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--report", "r.json", "--grid", "g.png", "o.png"],
             rc=(1,), run_kw={"fsize": 1_000}))  # fmt: skip
    add(Case("volume: truncated TIFF (tifffile's own log)", "message",
             lambda d: (vol_setup("good")(d), open(os.path.join(d, "v.tif"), "r+b").truncate(3000)),
             ["volume", "v.tif", "o.tif", "--src", "a.obj", "--dst", "b.obj"],
             check=lambda d, o: None if all(line.startswith("warp") for line in o.stderr.splitlines())
             else "a line not from warp: " + o.stderr.splitlines()[0][:80]))  # fmt: skip
    for delay in (1.2, 1.6, 2.0):
        add(Case(f"SIGTERM mid-write of a --tiled output ({delay} s)", "signal", basic,
                 ["in.png", "--src", "src.json", "--dst", "dst.json", "--size", "6000x6000", "--tiled", "o.tif"],
                 rc=(0, 1, 143, -15), run_kw={"term_after": delay, "timeout": 60},
                 check=lambda d, o: None if o.rc != 0 or os.path.exists(os.path.join(d, "o.tif")) else "exit 0, no output"))  # fmt: skip
    # -- more of each class, generated the same way
    for flag, name in (("--grid", "src.json"), ("--heatmap", "dst.json"), ("--save-forward-map", "in.png")):
        add(Case(f"{flag} naming an input", "data loss", basic,
                 ["in.png", "--src", "src.json", "--dst", "dst.json", flag, name, "o.png"]))  # fmt: skip
    add(Case("--labels OUT naming the image input", "data loss", lambda d: (basic(d), write_png(os.path.join(d, "l.png"), image(channels=1))),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--labels", "l.png", "in.png", "o.png"]))  # fmt: skip
    add(Case("points OUT is IN", "data loss", lambda d: points_setup(d, "20,20\n"),
             ["points", "p.csv", "p.csv", "--src", "src.json", "--dst", "dst.json"]))  # fmt: skip
    add(Case("apply-map OUTPUT is MAP", "data loss",
             lambda d: (basic(d), run(d, ["in.png", "--src", "src.json", "--dst", "dst.json", "--save-map", "m.exr", "o.png"])),
             ["apply-map", "m.exr", "in.png", "m.exr"]))  # fmt: skip
    add(Case("volume --report naming --src", "data loss", vol_setup("good"),
             ["volume", "v.tif", "o.tif", "--src", "a.obj", "--dst", "b.obj", "--report", "a.obj"]))  # fmt: skip
    add(Case("volume OUT is IN", "data loss", vol_setup("good"),
             ["volume", "v.tif", "v.tif", "--src", "a.obj", "--dst", "b.obj"]))  # fmt: skip
    add(Case("texture --texture is OUT", "data loss", texture_setup,
             ["texture", "texture_square.obj", "texture_arch.obj", "texture_cat.png", "--src-corners", "0,8,80,72",
              "--dst-corners", "16,0,102,118"]))  # fmt: skip
    add(Case("output into a missing directory", "message", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "no/such/dir/o.png"], says=r"no/such/dir"))  # fmt: skip
    add(Case("input is a directory", "message", lambda d: (basic(d), os.mkdir(os.path.join(d, "dir.png"))),
             ["dir.png", "--src", "src.json", "--dst", "dst.json", "o.png"], says=r"dir\.png"))  # fmt: skip
    add(Case("existing 0644 report kept 0644 under umask 077", "silent wrong",
             lambda d: (basic(d), text(d, "r.json", "{}"), os.chmod(os.path.join(d, "r.json"), 0o644)),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--report", "r.json", "o.png"], rc=(0,),
             check=mode_of("r.json"), run_kw={"umask": 0o077}, replaced=("r.json",)))  # fmt: skip
    add(Case("new output under umask 077 is 0600", "silent wrong", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--report", "r.json", "o.png"], rc=(0,),
             check=lambda d, o: mode_of("r.json", 0o600)(d, o) or mode_of("o.png", 0o600)(d, o), run_kw={"umask": 0o077}))  # fmt: skip
    add(Case("--size 100000x100000 (30 GB) on a 1 MB disk", "bomb", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--size", "100000x100000", "o.png"], rc=(1, 2),
             check=seconds_below(50), run_kw={"fsize": 1 << 20}))  # fmt: skip
    add(Case("--frames 0-999999999", "bomb", basic,
             ["f.@.png", "--src", "src.json", "--dst", "dst.json", "o.@.png", "--frames", "0-999999999"], rc=(1, 2),
             allow_lines=6, check=seconds_below(30)))  # fmt: skip
    add(Case("a polygon of 200,000 vertices", "bomb",
             lambda d: (basic(d), dump(d, "s.json", regular(200_000, 24)), dump(d, "t.json", regular(200_000, 22))),
             ["in.png", "--src", "s.json", "--dst", "t.json", "o.png"], rc=(0, 1, 2), check=seconds_below(50)))  # fmt: skip
    add(Case("Theta file with NaN", "message", lambda d: (basic(d), text(d, "t.json", "[[0, 0], [1, NaN], [1, 1], [0, 1]]")),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--theta", "t.json", "o.png"], says=r"t\.json"))  # fmt: skip
    for body, why in (("", "empty"), ("x,y\n", "header only"), ('{"points": [[1, 2, 3]]}', "triples"),
                      ("\ufeffx,y,name\r\n20,20,a\r\n30,30,b\r\n", "BOM, header and CRLF")):
        name = "p.json" if body.startswith("{") else "p.csv"
        add(Case(f"points: {why}", "message", lambda d, body=body, name=name: points_setup(d, body.encode(), name),
                 ["points", name, "q" + name[1:], "--src", "src.json", "--dst", "dst.json"],
                 rc=(0,) if "CRLF" in why else (0, 2)))  # fmt: skip
    add(Case("--compression with a JPEG output", "new surface", basic,
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--compression", "3", "o.jpg"], rc=(0, 2)))  # fmt: skip
    add(Case("--within garbage JSON", "new surface", lambda d: (basic(d), text(d, "w.json", "{not json")),
             ["in.png", "--src", "src.json", "--dst", "dst.json", "--within", "w.json", "o.png"], says=r"w\.json"))  # fmt: skip
    add(Case("keyframed cage meshes through a sequence", "new surface",
             lambda d: (sequence_setup(d), dump(d, "c.json", cage),
                        dump(d, "k.json", {"frames": {"1": cage, "11": {**cage, "vertices": [[10, 6], [58, 12], [50, 58], [6, 50], [30, 34]]}}})),
             ["f.@.png", "--src", "c.json", "--dst", "k.json", "o.@.png", "--frames", "1,11"], rc=(0,),
             outputs=("o.1.png", "o.11.png")))  # fmt: skip
    add(Case("edit with a missing image", "new surface", basic,
             ["edit", "nope.png", "--src", "src.json"], rc=(2,)))  # fmt: skip
    return C


def expand(c: Case) -> Case:
    return c


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("-k", default=None, help="only cases whose name or class holds this")
    parser.add_argument("--list", action="store_true")
    parser.add_argument("-v", action="store_true", help="print stderr of every case")
    args = parser.parse_args()
    os.umask(0o022)
    failed = 0
    for c in cases():
        if args.k and args.k.lower() not in (c.name + " " + c.klass).lower():
            continue
        if args.list:
            print(f"{c.klass:12} {c.name}")
            continue
        c = _with_port(c)
        ok, why, out = c()
        failed += not ok
        cmd = "warp " + " ".join(shlex.quote(a) for a in c.args)
        last = (out.stderr.strip().splitlines() or [""])[-1][:160] if out else ""
        print(f"{'ok  ' if ok else 'FAIL'} {c.klass:12} {c.name}: {why or 'exit ' + str(out.rc)} "
              f"({out.seconds:.1f} s) | {cmd} | {last}", flush=True)  # fmt: skip
        if args.v and out:
            print(out.stderr)
    sys.exit(1 if failed else 0)


def _with_port(c: Case) -> Case:
    """Cases whose arguments name {port}: filled in after setup."""
    if not any("{port}" in a for a in c.args):
        return c
    setup = c.setup

    def new_setup(d: str) -> None:
        setup(d)
        port = open(os.path.join(d, "port")).read()
        c.args[:] = [a.replace("{port}", port) for a in c.args]

    c.setup = new_setup
    return c


if __name__ == "__main__":
    main()
