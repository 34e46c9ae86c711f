"""Write a small sample volume and two cages for the README's `warp volume` example.

    python sample_images/make_volume.py [FOLDER]     (default: the current directory)

Writes, into FOLDER: ``ct.nii.gz``, a 32^3 uint8 NIfTI volume of smooth waves
(1 mm voxels, voxel (i, j, k) centred at world (i, j, k) mm); ``cube.obj``, a
box of 3 x 3 quadrilaterals per side from 4 to 28 mm; and ``bent.obj``, the same
box twisted a fifth of a turn and bent by 0.5 rad (like the cages of
``bench/volume.py`` at a smaller size). Needs the volume extra:
``pip install 'warpcli[volume]'``. The same files every run.
"""

from __future__ import annotations

import os
import sys

import numpy as np

SIZE = 32


def volume(n: int = SIZE) -> np.ndarray:
    """(n, n, n) uint8: the smooth pattern bench/volume.py warps."""
    x = np.arange(n, dtype=np.float32)
    return (127.5 + 60 * np.sin(x / 4.0)[None, None, :] + 60 * np.cos(x / 5.0)[None, :, None]
            * np.sin(x / 3.0)[:, None, None]).astype(np.uint8)  # fmt: skip


def write_obj(path: str, vertices: np.ndarray, faces: np.ndarray) -> None:
    with open(path, "w") as fh:
        fh.write("# warpcli sample cage (sample_images/make_volume.py)\n")
        fh.writelines(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in vertices.tolist())
        fh.writelines("f " + " ".join(str(k + 1) for k in face) + "\n" for face in faces.tolist())


def main(folder: str = ".") -> None:
    import nibabel

    from warpcli.volume.examples import bend, box, twist

    os.makedirs(folder, exist_ok=True)
    img = nibabel.Nifti1Image(volume(), np.eye(4))
    img.header.set_xyzt_units("mm")
    nibabel.save(img, os.path.join(folder, "ct.nii.gz"))
    v, f = box(3, (4.0, 4.0, 4.0), (28.0, 28.0, 28.0))
    write_obj(os.path.join(folder, "cube.obj"), v, f)
    write_obj(os.path.join(folder, "bent.obj"), bend(twist(v, 0.2), 0.5), f)


if __name__ == "__main__":
    main(*sys.argv[1:2])
