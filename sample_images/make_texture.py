"""Regenerate the surface samples of ``warp texture`` (docs/texture.md) and their picture.

    python sample_images/make_texture.py

Two disk-shaped patches with different UV layouts: ``texture_square.obj``,
a 9 x 9 grid whose chart is a square (its material's texture is
``texture_cat.png``, a crop of chelsea.png), and ``texture_arch.obj``, a
7 x 17 grid whose chart is an arch (an annulus sector). Their boundaries
have 32 and 44 vertices, so the command names four corners on each. The same
patches as PLY (``texture_square.ply`` with per-vertex colours,
``texture_arch.ply`` without) show the vertex-colour transfer. The picture
``texture_transfer.png`` shows both charts in UV space, side by side: the
texture with SRC's wireframe, and the texture moved by the installed
``warp texture`` with DST's.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SIZE = 256
#: Corners in the order the faces run along each boundary: SRC's bottom-left,
#: bottom-right, top-right, top-left go onto the arch's inner-left, inner-right,
#: outer-right, outer-left ends.
SRC_CORNERS = "0,8,80,72"
DST_CORNERS = "16,0,102,118"


def grid_faces(rows: int, cols: int) -> np.ndarray:
    """Triangles of a rows x cols vertex grid (vertex r * cols + c), counter-clockwise for u along c, v along r."""
    tris = []
    for r in range(rows - 1):
        for c in range(cols - 1):
            a = r * cols + c
            tris += [(a, a + 1, a + cols + 1), (a, a + cols + 1, a + cols)]
    return np.array(tris)


def square_chart() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """UVs, 3D positions (a bump) and triangles of the square patch."""
    s = np.linspace(0.08, 0.92, 9)
    u, v = np.meshgrid(s, s)
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    z = 0.3 * np.exp(-8 * ((uv[:, 0] - 0.5) ** 2 + (uv[:, 1] - 0.5) ** 2))
    return uv, np.column_stack([uv[:, 0], uv[:, 1], z]), grid_faces(9, 9)


def arch_chart() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """UVs, 3D positions (a half cylinder) and triangles of the arch (angle along columns, radius along rows)."""
    radius = np.linspace(0.2, 0.48, 7)
    angle = np.radians(np.linspace(20, 160, 17))
    r, a = np.meshgrid(radius, angle, indexing="ij")
    uv = np.stack([0.5 + r.ravel() * np.cos(a.ravel()), 0.12 + r.ravel() * np.sin(a.ravel())], axis=1)
    xyz = np.column_stack([np.cos(a.ravel()), r.ravel() * 2, np.sin(a.ravel())])
    # Angle grows along a row and radius along a column, clockwise in the grid's order:
    # reversed, so that the faces run counter-clockwise in UV space like the square's.
    tris = grid_faces(7, 17)[:, ::-1]
    return uv, xyz, tris


def write_obj(name: str, uv, xyz, tris, mtl: str | None = None) -> None:
    lines = ["# warpcli sample (sample_images/make_texture.py)"]
    if mtl:
        lines += [f"mtllib {mtl}", "usemtl cat"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in xyz]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv]
    lines += ["f " + " ".join(f"{k + 1}/{k + 1}" for k in t) for t in tris]
    with open(os.path.join(HERE, name), "w") as fh:
        fh.write("\n".join(lines) + "\n")


def write_ply(name: str, uv, xyz, tris, rgb=None) -> None:
    head = ["ply", "format ascii 1.0", "comment warpcli sample (sample_images/make_texture.py)",
            f"element vertex {len(uv)}", "property float x", "property float y", "property float z",
            "property float s", "property float t"]  # fmt: skip
    if rgb is not None:
        head += ["property uchar red", "property uchar green", "property uchar blue"]
    head += [f"element face {len(tris)}", "property list uchar int vertex_indices", "end_header"]
    rows = []
    for k in range(len(uv)):
        row = f"{xyz[k, 0]:.6f} {xyz[k, 1]:.6f} {xyz[k, 2]:.6f} {uv[k, 0]:.6f} {uv[k, 1]:.6f}"
        if rgb is not None:
            row += " " + " ".join(str(int(c)) for c in rgb[k])
        rows.append(row)
    rows += ["3 " + " ".join(map(str, t)) for t in tris]
    with open(os.path.join(HERE, name), "w") as fh:
        fh.write("\n".join(head + rows) + "\n")


def read_png(name: str) -> np.ndarray:
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(os.path.join(HERE, name))
    return buf.get_pixels(oiio.UINT8)


def write_png(name: str, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(os.path.join(HERE, name))
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.UINT8)
    out.open(os.path.join(HERE, name), spec)
    out.write_image(np.ascontiguousarray(pixels))
    out.close()


def wireframe(pixels: np.ndarray, uv: np.ndarray, tris: np.ndarray, colour) -> np.ndarray:
    """The mesh's edges drawn over a texture of its chart (v up, as OBJ's): the boundary
    solid, the inner edges blended at a third."""
    img = pixels.astype(np.float64)
    h, w = img.shape[:2]
    xy = np.stack([uv[:, 0] * w, (1 - uv[:, 1]) * h], axis=1)
    count: dict = {}
    for t in tris:
        for i in range(3):
            e = tuple(sorted((int(t[i]), int(t[(i + 1) % 3]))))
            count[e] = count.get(e, 0) + 1
    for (a, b), uses in sorted(count.items(), key=lambda item: -item[1]):
        n = int(np.hypot(*(xy[b] - xy[a])) * 2) + 2
        p = xy[a] + np.linspace(0, 1, n)[:, None] * (xy[b] - xy[a])
        c = np.clip(p[:, 0].astype(int), 0, w - 1)
        r = np.clip(p[:, 1].astype(int), 0, h - 1)
        share = 1.0 if uses == 1 else 0.35
        img[r, c] = (1 - share) * img[r, c] + share * np.asarray(colour, dtype=np.float64)
    return np.round(img).astype(np.uint8)


def main() -> None:
    cat = read_png("chelsea.png")[20 : 20 + SIZE, 120 : 120 + SIZE, :3]
    write_png("texture_cat.png", cat)
    with open(os.path.join(HERE, "texture_square.mtl"), "w") as fh:
        fh.write("# warpcli sample\nnewmtl cat\nmap_Kd texture_cat.png\n")
    suv, sxyz, stri = square_chart()
    duv, dxyz, dtri = arch_chart()
    write_obj("texture_square.obj", suv, sxyz, stri, "texture_square.mtl")
    write_obj("texture_arch.obj", duv, dxyz, dtri)
    rgb = np.round(np.column_stack([suv[:, 0], suv[:, 1], 1 - suv[:, 0]]) * 255).astype(np.uint8)
    write_ply("texture_square.ply", suv, sxyz, stri, rgb)
    write_ply("texture_arch.ply", duv, dxyz, dtri)
    out = os.path.join(HERE, "texture_arch.png")
    subprocess.run(
        [sys.executable, "-m", "warpcli", "texture", os.path.join(HERE, "texture_square.obj"),
         os.path.join(HERE, "texture_arch.obj"), out, "--src-corners", SRC_CORNERS, "--dst-corners", DST_CORNERS],
        check=True,
    )  # fmt: skip
    moved = read_png("texture_arch.png")
    os.remove(out)
    left = wireframe(cat, suv, stri, (255, 255, 0))
    right = wireframe(moved, duv, dtri, (255, 255, 0))
    gap = np.full((SIZE, 8, 3), 255, dtype=np.uint8)
    assert moved.shape == cat.shape
    write_png("texture_transfer.png", np.concatenate([left, gap, right], axis=1))


if __name__ == "__main__":
    main()
