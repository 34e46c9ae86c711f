"""FEM, BEM and MFS side by side, in the style of the paper's Table 1, and how BEM and MFS move with m.

    python bench/methods_table.py            # 4 pairs, m = 128..1024 on 2 pairs (about 8-10 minutes)
    python bench/methods_table.py --quick    # 2 pairs, m = 128, 512, 1024 on 1 pair (about 2-3 minutes)

Progress goes to stderr, the markdown tables to stdout, after a header line
with the machine (usable cores, CPU), the load average and the git revision.

Inputs (deterministic, nothing random): the four pairs of
bench/theta_table.py (L -> hexagon, ring -> star, U -> uneven octagon,
zigzag -> flat star), each polygon scaled uniformly and centred to fill 90 %
of a 1118 x 894 (1 MP) image in both directions it can; an RGB 1 MP image
(colour ramps and an 8 px checker); the regular Theta. Every number below is
at that scale, so "px" are pixels of a 1 MP warp.

What is measured, per pair and method (defaults: ``MapOptions(method=...)``,
so FEM's automatic mesh density, BEM/MFS with the default m and the
certificate on, as a user gets them):

- **warp s**: wall time of `warp_image` on the 1 MP image, in this process
  (no image file I/O, no interpreter start-up): build both maps, pull back
  every output pixel, resample (linear, antialiased). Median of ``--repeat``
  (3) runs, each building the map anew, after one small untimed warp per
  method (numba kernels loaded). ``build s`` (fitting or meshing and solving,
  summed over both maps, which are built on two threads at once) and
  ``compose s`` (pulling back every pixel) are those stages of the last run.
- **error**: the whole warp against a fine FEM reference (FEM with each
  polygon's automatic max_area / 16, about 500k-650k triangles a polygon), in
  both directions: f^-1 at every output pixel centre inside the target (the
  warp's own `inverse_map`; error in source px) and f = phi1^-1 o phi0 at
  every input pixel centre inside the source (`BijectiveMap.forward_grid`;
  error in target px). Pixel centres at least 5 px from their polygon's
  boundary are "interior", the others the "band"; max and mean of the
  distance, the worse of the two directions. ``ref diff there`` is the
  reference's level difference |FEM/4 - FEM/16| at the pixel of the max.
  ``lost`` counts pixel centres the reference maps but the method returns
  NaN for (either direction): holes in the warp.
- **boundary deviation** (the paper's Fig. 4): the map evaluated by its
  closed form just inside the boundary (points every 0.25 px along each
  edge, moved 1e-6 x the polygon's size inward), against the prescribed
  boundary data b there, turned into polygon pixels through the map's own
  Jacobian: |J^-1 (phi(x') - b(x)) - (x' - x)|, the distance from x of the
  point the map actually sends to b(x) (to first order). Max and mean over
  both polygons. FEM is exact on the boundary by construction (~0).
- **folds**: points where det J has the wrong sign (or is 0), for phi0 and
  phi1: on a grid of about 200,000 points inside each polygon, and at the
  boundary points above. FEM's Jacobian is per triangle, so its grid count
  is a sampled version of its exact certificate.

The reference's own uncertainty (second table): the same errors of the
max_area / 4 FEM map against the / 16 one. If the error is a power of the
area bound, ``ratio`` (the automatic map's mean interior error over the / 4
map's, both against / 16) is 5 for O(h^2) and the / 16 map's own mean error
is its difference to / 4 over (ratio - 2). Near reflex corners FEM's
pointwise convergence is slower and not monotone, so the same table gives a
reference-free check: the default MFS warp against the default BEM warp.
Where those two agree much better than either agrees with FEM, the "error"
is the reference's.

The m table: BEM and MFS with ``nodes=m`` for m = 128, 256, 512, 1024 on the
concave pairs (zigzag, U), one warp each (so its seconds are noisier), with
``check=False`` so a map that folds is measured rather than refused.
``build s`` is the sum over both maps of their fit time (they are built on
two threads at once, so it can exceed the wall time).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import statistics
import subprocess
import sys
import time
import traceback

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

from theta_table import pairs as theta_pairs  # noqa: E402  (the same four pairs)

from warpcli import MapOptions, Polygon, build_map, warp_image  # noqa: E402
from warpcli.boundary import edge_points, nearest_edge  # noqa: E402
from warpcli.grid import inside_polygon, pixel_centres  # noqa: E402
from warpcli.maps.base import inv2  # noqa: E402
from warpcli.maps.fem.mesh import auto_max_area  # noqa: E402

WIDTH, HEIGHT = 1118, 894  # 0.9995 MP, 5:4
FILL = 0.9  # each polygon fills this fraction of the image in its tighter direction
BAND = 5.0  # px: pixel centres nearer the boundary than this are the "band"
FINE = 16.0  # the reference: automatic max_area / FINE
CHECK = 4.0  # the reference's check: automatic max_area / CHECK
FOLD_SAMPLES = 200_000  # det J samples per polygon
BOUNDARY_STEP = 0.25  # px between boundary samples
INWARD = 1e-6  # boundary samples move this much (times the polygon's size) inside
METHODS = ("fem", "bem", "mfs")
SWEEP_M = (128, 256, 512, 1024)
SWEEP_PAIRS = ("zigzag", "U")


T0 = time.perf_counter()


def progress(msg: str) -> None:
    print(f"[{time.perf_counter() - T0:6.1f} s] {msg}", file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------
# Inputs


def fitted(poly: Polygon) -> Polygon:
    """The polygon scaled uniformly about its bounding box's centre to fill FILL of the image."""
    p = poly.points
    lo, hi = p.min(axis=0), p.max(axis=0)
    s = FILL * min(WIDTH / (hi - lo)[0], HEIGHT / (hi - lo)[1])
    return Polygon((p - (lo + hi) / 2) * s + [WIDTH / 2, HEIGHT / 2], name=poly.name)


def bench_pairs(names: tuple[str, ...] | None) -> list[tuple[str, Polygon, Polygon]]:
    """The pairs of theta_table.py at 1 MP; only those whose name starts with one of ``names``."""
    out = []
    for name, src, dst, _ in theta_pairs():
        if names is None or any(name.startswith(n) for n in names):
            out.append((name, fitted(src), fitted(dst)))
    return out


def smooth_maps(behaviour: str):
    """BEM's and MFS's maps of every bench pair, with ``behaviour`` (``"linear"``, ``"quadratic"``)
    at both ends: (name, method, src, dst, options, map) in turn, the map the exception where it
    was refused (a refusal is a result)."""
    for name, src, dst in bench_pairs(None):
        for method in ("bem", "mfs"):
            opts = MapOptions(method=method, src_boundary=behaviour, dst_boundary=behaviour)
            try:
                fm = build_map(src, dst, opts)
            except Exception as err:
                fm = err
            yield name, method, src, dst, opts, fm


def test_image() -> np.ndarray:
    """1118 x 894 RGB uint8: colour ramps and an 8 px checker."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    checker = ((x // 8 + y // 8) % 2) * 60
    img = np.stack([x * 195 // WIDTH + checker, y * 195 // HEIGHT + checker, (x + y) * 195 // (WIDTH + HEIGHT) + checker], axis=-1)
    return img.astype(np.uint8)


REGION = (0.0, 0.0, float(WIDTH), float(HEIGHT))


# ----------------------------------------------------------------------------
# Measurements


@dataclasses.dataclass
class Geometry:
    """Per polygon: which pixel centres lie inside, and their distance to the boundary (NaN outside)."""

    distance: np.ndarray  # (H, W)

    @classmethod
    def of(cls, poly: Polygon) -> Geometry:
        c = pixel_centres(WIDTH, HEIGHT)
        inside = inside_polygon(c, poly.points)
        dist = np.full(len(c), np.nan)
        dist[inside] = nearest_edge(c[inside], poly.points)[2]
        return cls(dist.reshape(HEIGHT, WIDTH))


def deviation_stats(approx: np.ndarray, ref: np.ndarray, geo: Geometry, check: np.ndarray | None = None) -> dict:
    """Distance between two (H, W, 2) point grids over pixel centres the reference maps, by region.

    Per region: (max, mean), and where the max is: (x, y, distance to the
    boundary, the reference's own level difference |check - ref| there).
    """
    have = np.isfinite(ref[..., 0]) & np.isfinite(geo.distance)
    ok = have & np.isfinite(approx[..., 0])
    d = np.hypot(*(approx - ref)[ok].T)
    band = geo.distance[ok] < BAND
    lost = have & ~ok
    out = {"lost": int(lost.sum()), "lost_depth": float(geo.distance[lost].max()) if lost.any() else 0.0}
    for region, sel in (("interior", ~band), ("band", band)):
        e = d[sel]
        out[region] = (float(e.max()), float(e.mean())) if e.size else (np.nan, np.nan)
        out[f"{region}_at"] = (np.nan, np.nan, np.nan, np.nan)
        if e.size:
            k = np.flatnonzero(ok.ravel())[np.flatnonzero(sel)[np.argmax(e)]]
            r, c = divmod(int(k), WIDTH)
            delta = float(np.hypot(*(check[r, c] - ref[r, c]))) if check is not None else np.nan
            out[f"{region}_at"] = (c + 0.5, r + 0.5, float(geo.distance[r, c]), delta)
    return out


def worse(a: dict, b: dict) -> dict:
    """Per statistic, the worse of two directions' `deviation_stats` (the max's place goes with it)."""
    out = {"lost": a["lost"] + b["lost"]}
    for region in ("interior", "band"):
        out[region] = tuple(float(np.nanmax([x, y])) for x, y in zip(a[region], b[region]))
        first = not (b[region][0] > a[region][0])
        out[f"{region}_at"] = (a if first else b)[f"{region}_at"]
    return out


@dataclasses.dataclass
class Reference:
    """The fine FEM map in both directions, the check level's, and how far apart they are."""

    grids: dict | None  # "inverse", "forward", "inverse_check", "forward_check": (H, W, 2); dropped once used
    check: dict  # the / CHECK map's worse-of-both-directions deviation_stats against the / FINE map
    areas: tuple[float, float]
    triangles: int
    seconds: float
    cross: dict | None = None  # MFS against BEM (both with defaults), likewise: a reference-free check


def reference(src: Polygon, dst: Polygon, geo_src: Geometry, geo_dst: Geometry) -> Reference:
    """FEM with max_area / FINE (the reference) and / CHECK, both directions at every pixel centre."""
    t0 = time.perf_counter()
    grids = {}
    info = {}
    for div, suffix in ((FINE, ""), (CHECK, "_check")):
        areas = (auto_max_area(src, REGION) / div, auto_max_area(dst, REGION) / div)
        f = build_map(src, dst, MapOptions(max_area=areas), regions=(REGION, REGION))
        if f.phi0.weights != "cotan" or f.phi1.weights != "cotan":
            progress("WARNING: the reference FEM map flipped and was solved with positive weights")
        grids["inverse" + suffix] = f.inverse_grid(WIDTH, HEIGHT)
        grids["forward" + suffix] = f.forward_grid(WIDTH, HEIGHT)
        info[div] = (areas, f.phi0.mesh.n_triangles + f.phi1.mesh.n_triangles)
        del f
    check = worse(
        deviation_stats(grids["inverse_check"], grids["inverse"], geo_dst),
        deviation_stats(grids["forward_check"], grids["forward"], geo_src),
    )
    return Reference(grids, check, info[FINE][0], info[FINE][1], time.perf_counter() - t0)


def sign_of(phi) -> float:
    """+1 where det J must be positive for phi to preserve orientation as it should, else -1."""
    return phi.theta.orientation * np.sign(phi.polygon.signed_area)


def folds_on_grid(phi) -> tuple[int, int]:
    """(wrong-signed det J, samples) on a grid of about FOLD_SAMPLES points inside phi's polygon."""
    poly = phi.polygon
    xmin, ymin, xmax, ymax = poly.bounds
    step = np.sqrt(abs(poly.signed_area) / FOLD_SAMPLES)
    xs, ys = np.arange(xmin + step / 2, xmax, step), np.arange(ymin + step / 2, ymax, step)
    pts = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    pts = pts[inside_polygon(pts, poly.points)]
    # A grid point can land on an edge (to rounding): not inside, and where
    # the closed forms are undefined. Such points are left out.
    pts = pts[nearest_edge(pts, poly.points)[2] > 1e-9 * max(xmax - xmin, ymax - ymin)]
    j = phi.evaluate(pts, jacobian=True).jacobian
    det = (j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]) * sign_of(phi)
    return int((~(det > 0)).sum()), len(pts)


def boundary_deviation(phi) -> tuple[np.ndarray, int]:
    """Per boundary sample: the deviation in polygon px (see the docstring); and the folds there."""
    v = phi.polygon.points
    n = len(v)
    d = np.roll(v, -1, axis=0) - v
    length = np.hypot(d[:, 0], d[:, 1])
    counts = np.maximum(1, np.ceil(length / BOUNDARY_STEP)).astype(np.int64)
    edge = np.repeat(np.arange(n), counts)
    j = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    t = (j + 0.5) / counts[edge]
    x = edge_points(v, edge, t)
    xmin, ymin, xmax, ymax = phi.polygon.bounds
    eps = INWARD * max(xmax - xmin, ymax - ymin)
    inward = np.sign(phi.polygon.signed_area) * np.stack([-d[:, 1], d[:, 0]], axis=1) / length[:, None]
    xi = x + eps * inward[edge]
    m = phi.evaluate(xi, jacobian=True)
    off = m.points - phi.boundary_to_theta(edge, t)  # in Theta
    inv = inv2(m.jacobian)
    dev = np.einsum("kab,kb->ka", inv, off) - (xi - x)
    jac = m.jacobian
    det = (jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]) * sign_of(phi)
    return np.hypot(dev[:, 0], dev[:, 1]), int((~(det > 0)).sum())


@dataclasses.dataclass
class Row:
    pair: str
    method: str
    size: str = ""  # m, or FEM triangles
    warp: list[float] = dataclasses.field(default_factory=list)
    compose: float = np.nan
    build: float = np.nan
    err: dict | None = None
    dev: tuple[float, float] = (np.nan, np.nan)
    folds: str = ""
    folds_boundary: str = ""
    failed: str = ""


def measure(row: Row, result, ref: Reference, geo_src: Geometry, geo_dst: Geometry) -> tuple[np.ndarray, np.ndarray]:
    """Fill in a row's error, boundary deviation and folds from a warp's result; return f^-1's and f's grids."""
    f = result.map
    g = ref.grids
    grids = result.inverse_map, f.forward_grid(WIDTH, HEIGHT)
    inv = deviation_stats(grids[0], g["inverse"], geo_dst, g["inverse_check"])
    fwd = deviation_stats(grids[1], g["forward"], geo_src, g["forward_check"])
    row.err = worse(inv, fwd)
    for label, s in (("f^-1", inv), ("f", fwd)):
        progress(
            f"  {label}: interior max {s['interior'][0]:.4f} mean {s['interior'][1]:.4f} at {where(s['interior_at'])}; "
            f"band max {s['band'][0]:.4f} mean {s['band'][1]:.4f} at {where(s['band_at'])}; "
            f"lost {s['lost']} (up to {s['lost_depth']:.2f} px from the boundary)"
        )
    devs, fb, fg = [], [], []
    for phi in (f.phi0, f.phi1):
        dev, bad = boundary_deviation(phi)
        devs.append(dev)
        fb.append(bad)
        fg.append(folds_on_grid(phi))
        k = int(np.nanargmax(dev)) if np.isfinite(dev).any() else 0
        progress(f"  {os.path.basename(phi.polygon.name)}: boundary deviation max {np.nanmax(dev):.3g} px (sample {k} of {len(dev)}), folds grid {fg[-1][0]} of {fg[-1][1]}, at boundary {bad}")
    dev = np.concatenate(devs)
    row.dev = (float(np.nanmax(dev)), float(np.nanmean(dev)))
    row.folds = f"{fg[0][0]} / {fg[1][0]}"
    row.folds_boundary = f"{fb[0]} / {fb[1]}"
    desc = f.describe()
    if row.method == "fem":
        row.size = f"{desc['source_mesh']['triangles'] + desc['target_mesh']['triangles']:,} tri"
    else:
        m0, m1 = desc["source_nodes"]["m"], desc["target_nodes"]["m"]
        row.size = str(m0) if m0 == m1 else f"{m0} / {m1}"
    return grids


def where(at: tuple) -> str:
    """A max's place, from `deviation_stats`."""
    return f"({at[0]:.1f}, {at[1]:.1f}), {at[2]:.2f} px from the boundary, reference level difference there {at[3]:.4f} px"


def timed_warps(img, src, dst, opts: MapOptions, repeat: int):
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = warp_image(img, src, dst, map=opts)
        times.append(time.perf_counter() - t0)
    return times, result


def warm_up() -> None:
    """One small warp per method: loads (or compiles) the numba kernels before anything is timed."""
    img = np.zeros((100, 120, 3), np.uint8)
    a = [[10.3, 10.1], [110.2, 12.4], [60.1, 50.3], [100.4, 90.2], [12.2, 88.1]]
    b = [[15.1, 5.2], [105.3, 20.1], [95.2, 60.4], [90.1, 95.3], [20.4, 80.2]]
    for method in METHODS:
        warp_image(img, a, b, method=method, check=False)


# ----------------------------------------------------------------------------
# Output


def f3(x: float) -> str:
    if not np.isfinite(x):
        return "-"
    return f"{x:.3f}" if x >= 0.001 else f"{x:.1e}"


def fsec(xs: list[float]) -> str:
    if not xs:
        return "-"
    med = statistics.median(xs)
    return f"{med:.2f}" if len(xs) == 1 else f"{med:.2f} ({min(xs):.2f}-{max(xs):.2f})"


def error_cells(err: dict | None, deltas: bool = True) -> list[str]:
    """Interior max (and the reference's level difference there), mean; band likewise; lost."""
    if err is None:
        return ["-"] * (7 if deltas else 5)
    cells = []
    for region in ("interior", "band"):
        cells.append(f3(err[region][0]))
        if deltas:
            cells.append(f3(err[f"{region}_at"][3]))
        cells.append(f3(err[region][1]))
    return cells + [str(err["lost"])]


def header_line() -> str:
    cpu = "?"
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")), "?")
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    git = ["git", "--no-optional-locks", "-C", os.path.join(HERE, "..")]
    try:
        rev = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run([*git, "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True, timeout=10).stdout.strip()
        rev = (rev or "?") + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        rev = "?"
    threads = " ".join(f"{k}={os.environ[k]}" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS") if k in os.environ)
    return (
        f"machine: {cores} usable cores ({cpu}), load {load()}; git {rev}; "
        f"python {platform.python_version()}, numpy {np.__version__}{'; ' + threads if threads else ''}"
    )


def load() -> str:
    try:
        with open("/proc/loadavg") as fh:
            return " ".join(fh.read().split()[:3])
    except OSError:
        return "?"


def table(headers: list[str], rows: list[list[str]]) -> None:
    print("| " + " | ".join(headers) + " |")
    print("|---|---|" + "---:|" * (len(headers) - 2))
    for cells in rows:
        print("| " + " | ".join(cells) + " |")


def print_tables(rows: list[Row], refs: dict, sweep: list[Row], repeat: int, elapsed: float, head: str) -> None:
    err_heads = ["interior max px", "ref diff there", "interior mean px", "band max px", "ref diff there", "band mean px", "lost px"]
    print(head)
    print()
    print(f"### Methods at 1 MP ({WIDTH}x{HEIGHT}): the warp against FEM with max_area / {FINE:g}, boundary deviation, folds, time")
    print()
    body = []
    for r in rows:
        if r.failed:
            body.append([r.pair, r.method, f"failed: {r.failed}"] + ["-"] * 14)
            continue
        body.append(
            [r.pair, r.method, r.size, *error_cells(r.err), f3(r.dev[0]), f3(r.dev[1]), r.folds, r.folds_boundary, fsec(r.warp),
             f"{r.build:.2f}", f"{r.compose:.2f}"]
        )
    table(
        ["pair", "method", "m / mesh", *err_heads, "boundary dev max px", "boundary dev mean px", "folds grid phi0 / phi1",
         "folds at boundary", f"warp s, median of {repeat} (min-max)", "build s (both maps)", "compose s"],
        body,
    )  # fmt: skip
    print()
    print(f"### The reference: FEM with max_area / {CHECK:g} against / {FINE:g}; and, without FEM, MFS against BEM (defaults)")
    print()
    body = []
    for pair, ref in refs.items():
        c = ref.check
        fem = next((r for r in rows if r.pair == pair and r.method == "fem" and r.err), None)
        ratio = fem.err["interior"][1] / c["interior"][1] if fem and c["interior"][1] > 0 else np.nan
        own = c["interior"][1] / (ratio - 2.0) if ratio > 2.0 else np.nan
        cross = error_cells(ref.cross, deltas=False)[:4] if ref.cross else ["-"] * 4
        body.append(
            [pair, f"{ref.areas[0]:.2f} / {ref.areas[1]:.2f}", f"{ref.triangles:,}", *error_cells(c, deltas=False)[:4],
             f"{ratio:.1f}", f3(own), f"{ref.seconds:.1f}", *cross]
        )  # fmt: skip
    table(
        ["pair", f"max_area / {FINE:g}, src / dst px^2", "triangles", "interior max px", "interior mean px", "band max px",
         "band mean px", f"ratio (auto vs /{FINE:g}) / (/{CHECK:g} vs /{FINE:g}), interior mean",
         f"est. error of /{FINE:g}, interior mean px", "seconds", "BEM vs MFS: interior max px", "interior mean px",
         "band max px", "band mean px"],
        body,
    )  # fmt: skip
    if sweep:
        print()
        print("### BEM and MFS against m (`nodes`), check off, one 1 MP warp each")
        print()
        body = []
        for r in sweep:
            if r.failed:
                body.append([r.pair, r.method, r.size, f"failed: {r.failed}"] + ["-"] * 11)
                continue
            body.append(
                [r.pair, r.method, r.size, *error_cells(r.err), f3(r.dev[0]), r.folds, r.folds_boundary, f"{r.build:.2f}", fsec(r.warp)]
            )
        table(
            ["pair", "method", "m", *err_heads, "boundary dev max px", "folds grid phi0 / phi1", "folds at boundary",
             "build s (both maps)", "warp s"],
            body,
        )  # fmt: skip
    print()
    print(
        f"Errors: the worse of f^-1 at output pixel centres (source px) and f at input pixel centres (target px); "
        f"interior = at least {BAND:g} px from the boundary, band = nearer; ref diff there = |FEM/{CHECK:g} - FEM/{FINE:g}| "
        f"at the pixel of that max (indicative only: near reflex corners FEM's pointwise convergence is not monotone; where "
        f"BEM and MFS agree far better than either agrees with FEM, the error is the reference's); lost = pixels the reference maps and the method returns NaN for (holes in the warp). "
        f"Boundary dev = |J^-1 (phi(x') - b(x)) - (x' - x)| at x' = x moved {INWARD:g} x size inward, every "
        f"{BOUNDARY_STEP:g} px, both polygons. Folds: det J <= 0 at ~{FOLD_SAMPLES:,} grid points per polygon and at "
        f"those boundary points. warp s: in-process warp_image (build + compose + resample, no file I/O). "
        f"est. error of /{FINE:g} = its mean difference to /{CHECK:g} / (ratio - 2), assuming a power law in max_area "
        f"(ratio 5: O(h^2)). Load at the end {load()}; total {elapsed:.0f} s."
    )


# ----------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 pairs, m = 128, 512 and 1024 on one pair")
    parser.add_argument("--repeat", type=int, default=3, help="timed warps per pair and method [3]")
    args = parser.parse_args(argv)
    head = header_line()
    progress(head)
    names = ("grid", "zigzag") if args.quick else None
    sweep_pairs = SWEEP_PAIRS[:1] if args.quick else SWEEP_PAIRS
    sweep_m = (128, 512, 1024) if args.quick else SWEEP_M

    warm_up()
    img = test_image()
    rows: list[Row] = []
    refs: dict[str, Reference] = {}
    sweep: list[Row] = []
    for pair, src, dst in bench_pairs(names):
        progress(f"{pair}: reference FEM (max_area / {FINE:g} and / {CHECK:g})")
        geo_src, geo_dst = Geometry.of(src), Geometry.of(dst)
        ref = refs[pair] = reference(src, dst, geo_src, geo_dst)
        progress(f"  {ref.triangles:,} triangles, {ref.seconds:.1f} s")
        runs = [(method, MapOptions(method=method), args.repeat, rows) for method in METHODS]
        if any(pair.startswith(p) for p in sweep_pairs):
            runs += [
                (method, MapOptions(method=method, nodes=m, check=False), 1, sweep)
                for method in ("bem", "mfs")
                for m in sweep_m
            ]
        meshless = {}  # default BEM's and MFS's grids, for the cross-check
        for method, opts, repeat, dest in runs:
            row = Row(pair, method, str(opts.nodes or ""))
            result = None
            dest.append(row)
            progress(f"{pair}: {method}{'' if opts.nodes is None else f' m={opts.nodes}'}, {repeat} warp(s)")
            try:
                row.warp, result = timed_warps(img, src, dst, opts, repeat)
                row.compose = result.timings.get("compose", np.nan)
                row.build = result.timings.get("solve", 0.0) + result.timings.get("mesh", 0.0)
                progress(f"  warps {', '.join(f'{t:.2f}' for t in row.warp)} s; stages {result.timings}")
                grids = measure(row, result, ref, geo_src, geo_dst)
                if dest is rows and method != "fem":
                    meshless[method] = grids
            except Exception as err:  # a failure is a result: record it and go on
                row.failed = f"{type(err).__name__}: {err}".replace("|", "/")[:160]
                progress(f"  FAILED: {row.failed}\n{traceback.format_exc()}")
            del result
            if len(meshless) == 2:
                (bem_inv, bem_fwd), (mfs_inv, mfs_fwd) = meshless.pop("bem"), meshless.pop("mfs")
                ref.cross = worse(deviation_stats(mfs_inv, bem_inv, geo_dst), deviation_stats(mfs_fwd, bem_fwd, geo_src))
        ref.grids = None
    print_tables(rows, refs, sweep, args.repeat, time.perf_counter() - T0, head)


if __name__ == "__main__":
    main()
