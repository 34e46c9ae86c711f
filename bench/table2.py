"""The paper's Table 2 against public peers, on the same inputs and the same measure.

    pip install -e '.[bench]'                   # libigl (MPL-2.0) and scikit-image, for the peers
    python bench/table2.py                      # 8 pairs, every map: a markdown table (25 min on a busy 2-core machine, most of it the optimized Theta)
    python bench/table2.py --pairs star,L       # some pairs (name prefixes)

Progress goes to stderr; the header (machine, load, revision) and the markdown
tables to stdout.

Maps compared, for each polygon pair (vertex i of the source goes to vertex i
of the target, each edge onto the corresponding edge):

- **warpcli**, one row per Theta strategy of `warpcli.maps.registry.THETAS`
  (whatever is registered when this runs), linear boundary; the optimized
  strategy once per energy (``--energy conformal`` and ``isometric``); and
  the paper's quadratic target boundary (§5.2) with the regular Theta. FEM,
  the meshes graded for a warp of the pair's image size.
- **igl composite**: libigl's ``bijective_composite_harmonic_mapping`` (a
  discrete harmonic map composed along a linear morph of the boundary, the
  discrete descendant of Schneider et al. 2013), on the common mesh below.
- **igl harmonic**: libigl's ``harmonic`` (k = 1) straight onto the target
  on the same mesh: the plain discrete harmonic map, which can fold.
- **skimage PWA**: scikit-image's ``PiecewiseAffineTransform`` with the
  polygon vertices as control points (affine on each triangle of their
  Delaunay triangulation, which ignores the polygon's edges), and with
  ``PWA (boundary)``: every boundary vertex of the common mesh as a control
  point, sent to the same place on the target edge as the harmonic maps'.

The measure, one routine for all (`measure`, independent of warpcli's own
`warpcli.distortion` and report): a **common fine mesh** of the source
polygon (`triangle`, quality 30 degrees, triangles of at most ``--area`` px²
(default: the polygon's area / 20000), boundary points included), every
map evaluated at its vertices and measured per triangle by the affine map
that takes the triangle to its image (exact for the libigl maps, which live
on that mesh; the linear interpolant of warpcli's smooth map and of PWA).
Per triangle: the Jacobian J from the triangle's edge vectors, its singular
values by ``numpy.linalg.svd``, conformal distortion ``s1/s2 + s2/s1`` (2
for a similarity) and isometric distortion ``max(s1, 1/s2)`` (1 for a rigid
motion); means weighted by source area, maxima over triangles, and the 99.9th
percentile by area. **flipped**: triangles whose image has the opposite
orientation (or none): the map folds there. **edge off**: the largest
distance, in target px, from the image of a point of source edge i to target
edge i (0 when each edge goes onto its edge). A map with flips or with edges
off the edges is not a bijection between the polygons; its numbers are
shown anyway, and the "fails" column says why.

libigl's composite mapping raises RuntimeError when it finds no map without
flips (the row says "no result"); where the linear morph of the boundary,
(1 - t) src + t dst, stops being a simple polygon (why it can fail) the
"fails" column says for which t, and where it returned the plain harmonic
map, it says so.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

from warpcli import MapOptions, Polygon, build_map, read_polygon  # noqa: E402
from warpcli.maps.registry import THETAS  # noqa: E402

SAMPLES = os.path.join(HERE, "..", "sample_images")


# --------------------------------------------------------------------------------------------
# The pairs: the three sample pairs, the two concave pairs of bench/theta_table.py, and three
# more drawn here (a star onto a star, an L onto a U, a horseshoe onto a ring sector).


def _arc(cx: float, cy: float, r: float, a0: float, a1: float, k: int) -> list[list[float]]:
    return [[cx + r * np.cos(a), cy + r * np.sin(a)] for a in np.linspace(a0, a1, k)]


def pairs():
    """Yield (name, src, dst, (width, height)) for every pair of the table."""
    s = lambda name: read_polygon(os.path.join(SAMPLES, name))  # noqa: E731
    yield "grid: L -> hexagon", s("grid_L.json"), s("grid_hexagon.json"), (512, 512)
    yield "chelsea: ring -> star", s("chelsea_ring.json"), s("chelsea_star.json"), (451, 300)
    yield "chelsea: eye -> wide eye", s("chelsea_eye.json"), s("chelsea_eye_wide.json"), (451, 300)
    # A U onto an irregular convex octagon with very uneven edges (bench/theta_table.py).
    u = [[60, 60], [200, 60], [200, 380], [320, 380], [320, 60], [460, 60], [460, 460], [60, 460]]
    octagon = [[40, 250], [70, 90], [250, 40], [420, 60], [480, 200], [470, 300], [400, 470], [100, 450]]
    yield "U -> uneven octagon", Polygon(u, name="U"), Polygon(octagon, name="octagon"), (512, 512)
    # A comb-like zigzag onto a thin star (bench/theta_table.py).
    k = np.arange(10)
    a = 2 * np.pi * k / 10
    r = np.where(k % 2 == 0, 220.0, 90.0)
    flat = np.stack([256 + r * np.cos(a), 256 + 0.6 * r * np.sin(a)], axis=1)
    zig = [[40, 80], [120, 300], [200, 80], [280, 300], [360, 80], [470, 300], [470, 460], [300, 420], [200, 460], [40, 460]]
    yield "zigzag -> flat star", Polygon(zig, name="zigzag"), Polygon(flat, name="flat star"), (512, 512)
    # A fat 6-point star onto a thin one turned by a third of a point.
    k = np.arange(12)
    a0 = 2 * np.pi * k / 12
    fat = np.stack([256 + np.where(k % 2 == 0, 230.0, 140.0) * np.cos(a0), 256 + np.where(k % 2 == 0, 230.0, 140.0) * np.sin(a0)], axis=1)
    a1 = a0 + 0.35
    thin = np.stack([256 + np.where(k % 2 == 0, 240.0, 70.0) * np.cos(a1), 256 + np.where(k % 2 == 0, 240.0, 70.0) * np.sin(a1)], axis=1)
    yield "star -> thin turned star", Polygon(fat, name="star"), Polygon(thin, name="thin star"), (512, 512)
    # An L (its long edges broken by a slight bend, to have the U's eight vertices) onto a U.
    ell = [[60, 60], [180, 60], [184, 260], [180, 340], [460, 340], [460, 460], [250, 466], [60, 460]]
    yield "L -> U", Polygon(ell, name="L"), Polygon(u, name="U"), (512, 512)
    # A horseshoe (a half annulus on two legs) onto a ring sector of 300 degrees.
    outer = _arc(256, 230, 200, np.pi, 2 * np.pi, 9)
    inner = _arc(256, 230, 90, 2 * np.pi, np.pi, 9)
    shoe = [[56, 470]] + outer + [[456, 470], [346, 470]] + inner + [[166, 470]]
    sector_outer = _arc(256, 256, 230, np.radians(-240), np.radians(60), 11)
    sector_inner = _arc(256, 256, 120, np.radians(60), np.radians(-240), 11)
    yield "horseshoe -> ring sector", Polygon(shoe, name="horseshoe"), Polygon(sector_outer + sector_inner, name="ring sector"), (512, 512)


# --------------------------------------------------------------------------------------------
# The common mesh and the one measure.


def common_mesh(src: np.ndarray, area: float):
    """A quality mesh of the source polygon: vertices, triangles, and (edge, t) of boundary vertices.

    Returns V (N, 2), F (M, 3) counter-clockwise in the plane's orientation of
    ``src``, and ``bnd`` (indices of the vertices on the boundary), ``edge``
    and ``t`` (each boundary vertex is src[edge] + t (src[edge+1] - src[edge])).
    """
    import triangle

    n = len(src)
    seg = np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)
    out = triangle.triangulate({"vertices": np.array(src, dtype=np.float64), "segments": seg.astype(np.int32)}, f"pq30a{area:.6f}")
    V, F = out["vertices"].astype(np.float64), out["triangles"].astype(np.int64)
    # Boundary vertices: those on a source edge (to rounding), with the edge and the parameter.
    a, b = src, np.roll(src, -1, axis=0)
    d = b - a
    t = np.einsum("vij,ij->vi", V[:, None, :] - a[None], d) / np.einsum("ij,ij->i", d, d)
    tc = np.clip(t, 0.0, 1.0)
    dist = np.linalg.norm(V[:, None, :] - (a[None] + tc[..., None] * d[None]), axis=2)
    edge = np.argmin(dist, axis=1)
    on = dist[np.arange(len(V)), edge] < 1e-7 * max(1.0, float(np.abs(src).max()))
    bnd = np.flatnonzero(on)
    return V, F, bnd, edge[bnd], tc[bnd, edge[bnd]]


def on_target(dst: np.ndarray, edge: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The point at parameter t of target edge ``edge``: where the linear boundary sends a source point."""
    a, b = dst[edge], dst[(edge + 1) % len(dst)]
    return a + t[:, None] * (b - a)


def jacobians_p1(V: np.ndarray, F: np.ndarray, U: np.ndarray) -> np.ndarray:
    """Per triangle, the Jacobian of the affine map taking it to the triangle of its vertices' images.

    Exact for a map that is affine on each triangle of (V, F): libigl's maps.
    """
    p0, p1, p2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    q0, q1, q2 = U[F[:, 0]], U[F[:, 1]], U[F[:, 2]]
    S = np.stack([p1 - p0, p2 - p0], axis=2)  # columns: source edge vectors
    T = np.stack([q1 - q0, q2 - q0], axis=2)
    return T @ np.linalg.inv(S)


def jacobians_fd(fn, V: np.ndarray, F: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """Per triangle, the Jacobian of the point map ``fn`` at the triangle's centroid, by central differences.

    ``h`` (px) is far below the common mesh's triangles and warpcli's FEM
    cells, so a stencil rarely straddles a kink of a piecewise-linear map
    (and then gives a blend of its two sides' Jacobians).
    """
    c = V[F].mean(axis=1)
    ex, ey = np.array([h, 0.0]), np.array([0.0, h])
    pts = np.concatenate([c + ex, c - ex, c + ey, c - ey])
    out = fn(pts).reshape(4, len(c), 2)
    dx = (out[0] - out[1]) / (2 * h)
    dy = (out[2] - out[3]) / (2 * h)
    return np.stack([dx, dy], axis=2)


def measure(V, F, J, U_bnd, src, dst, edge_of) -> dict:
    """Distortion per triangle from its Jacobian J; flips; edges off: the one measure, independent of warpcli.

    Parameters
    ----------
    V : (N, 2) array
        Mesh vertices in the source.
    F : (M, 3) int array
    J : (M, 2, 2) array
        The map's Jacobian on each triangle (NaN where the map gave no value).
    U_bnd : (B, 2) array
        Images of the boundary vertices, which lie on source edges ``edge_of``.
    src, dst : (n, 2) arrays
        The polygons' vertices.
    """
    p0, p1, p2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    src_area = 0.5 * np.abs((p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0]))
    missing = ~np.isfinite(J).all(axis=(1, 2))
    J = np.where(missing[:, None, None], 0.0, J)
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    # Orientation the map must keep: source and target orientations agree, or the map mirrors.
    want = np.sign(_signed_area(src) * _signed_area(dst))
    flipped = (det * want <= 0) | missing
    s = np.linalg.svd(J, compute_uv=False)
    s1, s2 = s[:, 0], s[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        conf = np.where(s2 > 0, s1 / s2 + s2 / s1, np.inf)
        iso = np.where(s2 > 0, np.maximum(s1, 1.0 / s2), np.inf)
    w = src_area / src_area.sum()
    # Edges onto edges: distance of each boundary vertex's image to its target edge.
    a, b = dst[edge_of], dst[(edge_of + 1) % len(dst)]
    d = b - a
    tt = np.clip(np.einsum("ij,ij->i", U_bnd - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    off = np.linalg.norm(U_bnd - (a + tt[:, None] * d), axis=1)
    off = np.where(np.isfinite(off), off, np.inf)
    return {
        "conf_mean": float(np.sum(w * conf)), "conf_max": float(conf.max()), "conf_p999": _wquantile(conf, w, 0.999),
        "iso_mean": float(np.sum(w * iso)), "iso_max": float(iso.max()), "iso_p999": _wquantile(iso, w, 0.999),
        "flipped": int(flipped.sum()), "triangles": len(F), "edge_off": float(off.max()), "missing": int(missing.sum()),
    }


def _signed_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _wquantile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    order = np.argsort(x)
    c = np.cumsum(w[order])
    return float(x[order][min(np.searchsorted(c, q * c[-1]), len(x) - 1)])


def _simple(p: np.ndarray) -> bool:
    """Whether the closed polygon p has no two non-adjacent edges that touch (O(n^2), exact enough here)."""
    n = len(p)
    a, b = p, np.roll(p, -1, axis=0)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue
            if _segments_meet(a[i], b[i], a[j], b[j]):
                return False
    return _signed_area(p) != 0


def _segments_meet(p, q, r, s) -> bool:
    def orient(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    o1, o2, o3, o4 = orient(p, q, r), orient(p, q, s), orient(r, s, p), orient(r, s, q)
    if o1 != o2 and o3 != o4:
        return True
    return bool(o1 == 0 and o2 == 0 and max(min(p[0], q[0]), min(r[0], s[0])) <= min(max(p[0], q[0]), max(r[0], s[0]))
                and max(min(p[1], q[1]), min(r[1], s[1])) <= min(max(p[1], q[1]), max(r[1], s[1])))


def morph_not_simple(src: np.ndarray, dst: np.ndarray, steps: int = 200) -> tuple[float, float] | None:
    """The range of t in which the linear morph (1 - t) src + t dst is not a simple polygon, or None."""
    bad = [t for t in np.linspace(0.0, 1.0, steps + 1) if not _simple((1 - t) * src + t * dst)]
    return (min(bad), max(bad)) if bad else None


# --------------------------------------------------------------------------------------------
# The maps.


def warpcli_rows():
    """(label, MapOptions) for every registered Theta strategy, the optimized one per energy, and quadratic."""
    for name in THETAS:
        if name == "optimized":
            yield "warpcli optimized (conformal)", MapOptions(theta=name, energy="conformal")
            yield "warpcli optimized (isometric)", MapOptions(theta=name, energy="isometric")
        else:
            yield f"warpcli {name}", MapOptions(theta=name)
    yield "warpcli regular, quadratic dst", MapOptions(dst_boundary="quadratic")


def warpcli_map(src: Polygon, dst: Polygon, size, opts: MapOptions):
    """warpcli's forward map f (a point function), its meshes graded for a warp at the pair's image size."""
    region = (0.0, 0.0, float(size[0]), float(size[1]))
    return build_map(src, dst, opts, regions=(region, region)).forward


def pwa_map(src: np.ndarray, dst: np.ndarray):
    """scikit-image's PiecewiseAffineTransform from control points src to dst (a point function)."""
    from skimage.transform import PiecewiseAffineTransform

    if hasattr(PiecewiseAffineTransform, "from_estimate"):  # scikit-image >= 0.26
        tf = PiecewiseAffineTransform.from_estimate(src, dst)
    else:
        tf = PiecewiseAffineTransform()
        tf.estimate(src, dst)

    def f(points: np.ndarray) -> np.ndarray:
        U = np.asarray(tf(points), float)
        U[(U == -1).all(axis=1)] = np.nan  # outside its triangulation: no result
        return U

    return f


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", default="", help="only pairs whose name starts with one of these (comma-separated)")
    parser.add_argument("--triangles", type=float, default=20000.0, help="the common mesh: source area / this = largest triangle (px²)")
    args = parser.parse_args(argv)
    try:
        import igl
    except ImportError:
        print("table2: libigl is missing: pip install -e '.[bench]'", file=sys.stderr)
        return 2
    from importlib.metadata import version

    import skimage
    import triangle  # noqa: F401

    wanted = [w for w in args.pairs.split(",") if w]
    rev = subprocess.run(["git", "-C", HERE, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"Machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}, load {os.getloadavg()[0]:.2f}; "
          f"warpcli {rev}, libigl {version('libigl')}, scikit-image {skimage.__version__}, numpy {np.__version__}\n")
    rows, notes = [], []
    for name, src_poly, dst_poly, size in pairs():
        if wanted and not any(name.startswith(w) for w in wanted):
            continue
        src, dst = np.array(src_poly.points, dtype=np.float64), np.array(dst_poly.points, dtype=np.float64)
        area = abs(_signed_area(src)) / args.triangles
        V, F, bnd, edge_of, t_of = common_mesh(src, area)
        bc = on_target(dst, edge_of, t_of)
        print(f"{name}: common mesh {len(V)} vertices, {len(F)} triangles, {len(bnd)} on the boundary", file=sys.stderr, flush=True)

        # Each vertex's way into the polygon: the centroid of a triangle it belongs to.
        inner = np.empty_like(V)
        inner[F.ravel()] = np.repeat(V[F].mean(axis=1), 3, axis=0)

        def at_vertices(f):
            """A point map at the mesh vertices: a boundary vertex that a map finds a rounding error
            outside its domain (NaN) is taken 1e-7 of the way into its triangle instead."""
            U = np.array(f(V), dtype=np.float64)
            bad = ~np.isfinite(U).all(axis=1)
            if bad.any():
                U[bad] = f(V[bad] + 1e-7 * (inner[bad] - V[bad]))
            return U

        def row(label, build, pointwise):
            """Build one map and measure it: ``build()`` gives a point function (pointwise) or vertex images."""
            t0 = time.perf_counter()
            try:
                made = build()
                U = at_vertices(made) if pointwise else made  # seconds: building plus evaluating at the N vertices
            except Exception as exc:  # a peer (or warpcli) that gives no map: its failure, shown
                rows.append((name, label, None, time.perf_counter() - t0, f"no result: {type(exc).__name__}: {str(exc).splitlines()[0][:120]}"))
                print(f"  {label}: no result ({exc})", file=sys.stderr, flush=True)
                return None
            seconds = time.perf_counter() - t0
            J = jacobians_fd(made, V, F) if pointwise else jacobians_p1(V, F, U)
            m = measure(V, F, J, U[bnd], src, dst, edge_of)
            fails = []
            if m["missing"]:
                fails.append(f"no image for {m['missing']} triangles")
            if m["flipped"] > m["missing"]:
                fails.append(f"{m['flipped'] - m['missing']} flipped")
            if m["edge_off"] > 0.01:
                fails.append(f"edges off by up to {m['edge_off']:.1f} px")
            rows.append((name, label, m, seconds, "; ".join(fails)))
            print(f"  {label}: {seconds:.1f} s, conformal {m['conf_mean']:.3f}, flipped {m['flipped']}", file=sys.stderr, flush=True)
            return U

        for label, opts in warpcli_rows():
            row(label, lambda opts=opts: warpcli_map(src_poly, dst_poly, size, opts), True)
        Vc, Fc, bc_c = np.ascontiguousarray(V), np.ascontiguousarray(F), np.ascontiguousarray(bc)
        harm = row("igl harmonic", lambda: igl.harmonic(Vc, Fc, bnd, bc_c, 1), False)
        comp = row("igl composite", lambda: igl.bijective_composite_harmonic_mapping(Vc, Fc, bnd, bc_c, 1, 200, 20, True), False)
        # Whether it gave a map or not: when its linear morph of the boundary is not simple.
        morph = morph_not_simple(src, dst)
        extra = []
        if morph is not None:
            extra.append(f"linear boundary morph not simple for t in [{morph[0]:.3f}, {morph[1]:.3f}]")
        if comp is not None and harm is not None and np.allclose(comp, harm, atol=1e-6 * float(np.abs(dst).max())):
            extra.append("= the plain harmonic map")
        if extra:
            n, lab, m, sec, fails = rows[-1]
            rows[-1] = (n, lab, m, sec, "; ".join(x for x in [fails, *extra] if x))
        row("skimage PWA (vertices)", lambda: pwa_map(src, dst), True)
        row("skimage PWA (boundary)", lambda: pwa_map(V[bnd], bc), True)
        notes.append(f"{name}: {len(F)} triangles of at most {area:.1f} px², {len(bnd)} boundary vertices")

    print("| pair | map | conformal mean | conformal max | conformal p99.9 | isometric mean | isometric max | isometric p99.9 | flipped | seconds | fails |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for name, label, m, seconds, fails in rows:
        if m is None:
            print(f"| {name} | {label} | | | | | | | | {seconds:.1f} | {fails} |")
            continue
        print(f"| {name} | {label} | {m['conf_mean']:.3f} | {m['conf_max']:.4g} | {m['conf_p999']:.4g} | {m['iso_mean']:.3f} | "
              f"{m['iso_max']:.4g} | {m['iso_p999']:.4g} | {m['flipped']} | {seconds:.1f} | {fails} |")
    print()
    print("Common meshes: " + "; ".join(notes) + ".")
    return 0


if __name__ == "__main__":
    sys.exit(main())
