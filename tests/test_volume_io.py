"""Volume I/O and the whole volume pipeline (warpcli.volume.volio, warpcli.volume.pipeline)."""

from __future__ import annotations

import numpy as np
import pytest

from test_volume_surface import write_obj
from warpcli.errors import ImageInputError, InputError
from warpcli.volume import read_volume, warp_volume_file, write_volume
from warpcli.volume.examples import box, tetrahedron
from warpcli.volume.volio import Volume, tiff_grid

nib = pytest.importorskip("nibabel")

AFFINE = np.array([[0.0, -1.2, 0.0, 30.0], [0.9, 0.0, 0.0, -10.0], [0.0, 0.0, 1.5, 5.0], [0, 0, 0, 1]])


def nifti(path, data, affine=AFFINE):
    img = nib.Nifti1Image(data, affine)
    img.header.set_data_dtype(data.dtype)
    nib.save(img, str(path))
    return path


def world_grid(shape, affine=AFFINE):
    i, j, k = np.meshgrid(*(np.arange(s) for s in shape), indexing="ij")
    idx = np.stack([i, j, k], axis=-1).reshape(-1, 3).astype(float)
    return idx @ affine[:3, :3].T + affine[:3, 3]


@pytest.mark.parametrize("dtype,ext", [(np.int16, ".nii.gz"), (np.float32, ".nii"), (np.uint8, ".nii.gz")])
def test_nifti_round_trip_keeps_affine_dtype_and_values(tmp_path, dtype, ext):
    rng = np.random.default_rng(0)
    data = (rng.random((7, 5, 6)) * 100).astype(dtype)
    vol = read_volume(nifti(tmp_path / f"in{ext}", data))
    assert vol.format == "nifti" and vol.data.dtype == dtype and vol.data.shape == (6, 5, 7, 1)
    assert np.allclose(vol.grid.affine, AFFINE)
    assert np.array_equal(vol.data[2, 3, 4, 0], data[4, 3, 2])
    out = tmp_path / f"out{ext}"
    write_volume(out, vol)
    first = out.read_bytes()
    write_volume(out, vol)
    assert out.read_bytes() == first  # no time stamps: the same bytes
    img = nib.load(str(out))
    assert img.get_data_dtype() == dtype
    assert np.allclose(img.affine, AFFINE)
    assert np.array_equal(np.asanyarray(img.dataobj), data)


def test_tiff_stack_round_trip(tmp_path):
    import tifffile

    data = np.arange(4 * 5 * 6, dtype=np.uint16).reshape(4, 5, 6)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    vol = read_volume(tmp_path / "in.tif")
    assert vol.data.shape == (4, 5, 6, 1) and vol.grid.shape == (6, 5, 4)
    assert np.allclose(vol.grid.to_world(np.array([[0.0, 0, 0]])), 0.5)
    write_volume(tmp_path / "out.tif", vol)
    assert np.array_equal(tifffile.imread(tmp_path / "out.tif"), data)


def test_affine_warp_of_a_linear_field_is_exact(tmp_path):
    """A tetrahedron onto a tetrahedron is affine, and trilinear resampling reproduces linear data."""
    v, f = tetrahedron()
    shape = (24, 20, 22)
    lo = AFFINE[:3, :3] @ np.array([4.0, 4.0, 4.0]) + AFFINE[:3, 3]
    step = np.abs(AFFINE[:3, :3]).sum(axis=0)  # the world size of a voxel along each axis
    src = lo + 0.0 * v
    # A tetrahedron well inside the volume in world coordinates (the axes are permuted by the affine).
    world = world_grid(shape)
    centre = world.mean(axis=0)
    src = centre + (v - 0.25) * 12.0
    a = np.array([[1.1, 0.2, 0.0], [-0.1, 0.9, 0.1], [0.05, 0.0, 1.05]])
    dst = (src - centre) @ a.T + centre + np.array([0.5, -0.3, 0.2])
    write_obj(tmp_path / "a.obj", src, f)
    write_obj(tmp_path / "b.obj", dst, f)
    gradient = np.array([0.7, -0.4, 1.3])
    field = (world @ gradient + 5.0).reshape(shape).astype(np.float32)
    nifti(tmp_path / "in.nii", field)
    result = warp_volume_file(tmp_path / "in.nii", tmp_path / "out.nii", tmp_path / "a.obj", tmp_path / "b.obj",
                              edge=2.0, background=-1.0)  # fmt: skip
    out = nib.load(str(tmp_path / "out.nii"))
    assert out.get_data_dtype() == np.float32 and np.allclose(out.affine, AFFINE)
    got = np.asanyarray(out.dataobj).reshape(-1)
    inside = got != -1.0
    assert result.inside == inside.sum() > 100
    # The source point of a target point y is A^-1 (y - c - t) + c.
    pre = np.linalg.solve(a, (world[inside] - centre - np.array([0.5, -0.3, 0.2])).T).T + centre
    assert np.abs(got[inside] - (pre @ gradient + 5.0)).max() < 1e-3
    del step, src


def cube_files(tmp_path, n=32):
    v, f = box(2, (4.0, 4.0, 4.0), (n - 4.0,) * 3)
    write_obj(tmp_path / "cube.obj", v, f)
    w = v.copy()
    w[:, 0] = 4.0 + (w[:, 0] - 4.0) * (1.0 + 0.02 * (w[:, 2] - 4.0))
    write_obj(tmp_path / "sheared.obj", np.clip(w, 0, n - 1), f)
    return tmp_path / "cube.obj", tmp_path / "sheared.obj"


def test_tiff_identity_warp_keeps_the_inside_and_fills_background(tmp_path):
    import tifffile

    rng = np.random.default_rng(2)
    data = rng.integers(0, 255, (32, 32, 32), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    cube, _ = cube_files(tmp_path)
    warp_volume_file(tmp_path / "in.tif", tmp_path / "out.tif", cube, cube, interpolation="nearest", background=7)
    out = tifffile.imread(tmp_path / "out.tif")
    assert out.dtype == np.uint8
    # Voxel (i, j, k) has its centre at (i + 0.5, ...): inside the cube [4, 28]^3 are indices 4..27.
    assert np.array_equal(out[4:28, 4:28, 4:28], data[4:28, 4:28, 4:28])
    assert (out[:4] == 7).all() and (out[:, :, 28:] == 7).all()


def test_warp_is_deterministic(tmp_path):
    import tifffile

    data = np.random.default_rng(3).random((32, 32, 32)).astype(np.float32)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    cube, sheared = cube_files(tmp_path)
    for name in ("o1.tif", "o2.tif"):
        warp_volume_file(tmp_path / "in.tif", tmp_path / name, cube, sheared, edge=3.0,
                         report=tmp_path / f"{name}.json")  # fmt: skip
    assert (tmp_path / "o1.tif").read_bytes() == (tmp_path / "o2.tif").read_bytes()
    out = tifffile.imread(tmp_path / "o1.tif")
    assert (out != 0).any()


def test_bad_inputs_are_refused_before_writing(tmp_path):
    import tifffile

    tifffile.imwrite(tmp_path / "in.tif", np.zeros((8, 8, 8), dtype=np.uint8), photometric="minisblack")
    v, f = box(1, (1, 1, 1), (7, 7, 7))
    write_obj(tmp_path / "a.obj", v, f)
    write_obj(tmp_path / "open.obj", v, f[1:])
    write_obj(tmp_path / "tri.obj", *tetrahedron())
    cases = [
        (dict(dst=tmp_path / "open.obj"), "open.obj: is not closed"),
        (dict(dst=tmp_path / "tri.obj"), "tri.obj: has 4 vertices but"),
        (dict(dst=tmp_path / "a.obj", output=tmp_path / "in.tif"), "would overwrite the input"),
        (dict(dst=tmp_path / "a.obj", output=tmp_path / "out.png"), "unknown volume format"),
    ]
    for changes, message in cases:
        args = dict(input=tmp_path / "in.tif", output=tmp_path / "out.tif", src=tmp_path / "a.obj") | changes
        with pytest.raises(InputError, match=message):
            warp_volume_file(**args)
    assert not (tmp_path / "out.tif").exists()
    with pytest.raises(ImageInputError, match="no such file"):
        read_volume(tmp_path / "none.nii.gz")


def test_volume_checks_its_shapes():
    with pytest.raises(ValueError, match="grid shape"):
        Volume(np.zeros((2, 3, 4, 1)), tiff_grid((2, 3, 4)))


def test_report_and_picture(tmp_path):
    import json

    import tifffile

    data = np.random.default_rng(4).random((32, 32, 32)).astype(np.float32)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    cube, sheared = cube_files(tmp_path)
    warp_volume_file(tmp_path / "in.tif", tmp_path / "out.tif", cube, sheared, edge=3.0,
                     report=tmp_path / "r.json", picture=tmp_path / "r.png")  # fmt: skip
    report = json.loads((tmp_path / "r.json").read_text())
    d = report["distortion"]
    assert d["samples"] > 1000 and d["min_jacobian_det"] > 0 and d["inverted_samples"] == 0
    assert 3.0 <= d["conformal"]["mean"] < 3.1 and d["isometric"]["max"] >= 1.0
    assert report["flipped_tetrahedra"] == {"source": 0, "target": 0}
    assert (tmp_path / "r.png").read_bytes().startswith(b"\x89PNG")


def test_distortion_of_a_similarity():
    from warpcli.volume.examples import rotation
    from warpcli.volume.report import distortion

    m = distortion(np.array([1.5 * rotation([1, 1, 0], 0.3)]))
    assert m["conformal"][0] == pytest.approx(3.0) and m["isometric"][0] == pytest.approx(1.5)
