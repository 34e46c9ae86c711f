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


# Volumes the warp cannot take are refused from the header with one line
# (exit 2 through the CLI), and byte orders or half floats it can take are
# warped like their native twins.

BYTE_ORDER_TYPES = [np.uint8, np.int16, np.uint16, np.int32, np.float32, np.float64]


@pytest.mark.parametrize("dtype", BYTE_ORDER_TYPES)
@pytest.mark.parametrize("fmt", ["nifti", "tiff"])
def test_big_endian_volumes_warp_like_native_ones(tmp_path, dtype, fmt):
    import tifffile

    rng = np.random.default_rng(int(np.dtype(dtype).itemsize))
    data = rng.integers(0, 100, (12, 10, 8)).astype(dtype)
    v, f = box(1, (1.0, 1.0, 1.0), (7.0, 9.0, 11.0))
    write_obj(tmp_path / "cube.obj", v, f)
    outs = []
    for order in "<>":
        swapped = data.astype(np.dtype(dtype).newbyteorder(order))
        if fmt == "nifti":
            header = nib.Nifti1Header(endianness=order)
            header.set_data_dtype(np.dtype(dtype))
            nib.save(nib.Nifti1Image(swapped, np.eye(4), header=header), str(tmp_path / f"in{order == '>'}.nii"))
            src = tmp_path / f"in{order == '>'}.nii"
        else:
            src = tmp_path / f"in{order == '>'}.tif"
            tifffile.imwrite(src, np.transpose(swapped, (2, 1, 0)), byteorder=order, photometric="minisblack")
        out = tmp_path / f"out{order == '>'}{src.suffix}"
        warp_volume_file(src, out, tmp_path / "cube.obj", tmp_path / "cube.obj", interpolation="nearest")
        outs.append(read_volume(out).data)
    assert outs[0].dtype.newbyteorder("=") == outs[1].dtype.newbyteorder("=") == np.dtype(dtype)
    assert np.array_equal(outs[0], outs[1])


def test_nibabels_own_big_endian_anatomical_volume_is_warped(tmp_path):
    import os

    path = os.path.join(os.path.dirname(nib.__file__), "tests", "data", "anatomical.nii")
    if not os.path.exists(path):
        pytest.skip("nibabel without its test data")
    img = nib.load(path)
    assert not img.get_data_dtype().isnative  # the case: stored big-endian
    volume = read_volume(path)
    assert volume.data.dtype.isnative
    assert np.array_equal(volume.data[..., 0], np.transpose(np.asanyarray(img.dataobj.get_unscaled()), (2, 1, 0)))


def test_half_float_stack_is_warped_in_its_own_type(tmp_path):
    import tifffile

    data = (np.random.default_rng(4).random((8, 10, 12)) * 50).astype(np.float16)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    v, f = box(1, (1.0, 1.0, 1.0), (11.0, 9.0, 7.0))
    write_obj(tmp_path / "cube.obj", v, f)
    warp_volume_file(tmp_path / "in.tif", tmp_path / "out.tif", tmp_path / "cube.obj", tmp_path / "cube.obj", interpolation="nearest")
    out = tifffile.imread(tmp_path / "out.tif")
    assert out.dtype == np.float16 and np.array_equal(out[2:6, 2:8, 2:10], data[2:6, 2:8, 2:10])


def _cli_one_line(args):
    from helpers import run_cli

    code, err = run_cli(args)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("dtype", [np.complex64, np.complex128])
@pytest.mark.parametrize("ext", [".nii", ".nii.gz", ".tif"])
def test_complex_volumes_are_refused_in_one_line(tmp_path, dtype, ext):
    import tifffile

    data = np.ones((6, 5, 4), dtype=dtype)
    path = tmp_path / f"in{ext}"
    if ext == ".tif":
        tifffile.imwrite(path, data, photometric="minisblack")
    else:
        nifti(path, data)
    v, f = box(1, (1, 1, 1), (3, 3, 3))
    write_obj(tmp_path / "a.obj", v, f)
    err = _cli_one_line(["volume", path, tmp_path / f"out{ext}", "--src", tmp_path / "a.obj", "--dst", tmp_path / "a.obj"])
    assert f"in{ext}: complex data" in err
    assert not (tmp_path / f"out{ext}").exists()


@pytest.mark.parametrize("shape", [(0, 4, 4), (4, 0, 4), (4, 4, 0), (4, 4, 4, 0)])
def test_volumes_without_voxels_are_refused_in_one_line(tmp_path, shape):
    path = nifti(tmp_path / "in.nii", np.zeros(shape, dtype=np.float32))
    v, f = box(1, (1, 1, 1), (3, 3, 3))
    write_obj(tmp_path / "a.obj", v, f)
    err = _cli_one_line(["volume", path, tmp_path / "out.nii", "--src", tmp_path / "a.obj", "--dst", tmp_path / "a.obj"])
    assert "in.nii: the volume has no voxels" in err


@pytest.mark.parametrize("page_shapes", [[(8, 8), (8, 8), (6, 8)], [(8, 8), (8, 7)], [(5, 5), (5, 5, 3)]])
def test_tiff_stacks_with_mismatched_pages_are_refused_in_one_line(tmp_path, page_shapes):
    import tifffile

    with tifffile.TiffWriter(tmp_path / "in.tif") as tif:
        for shape in page_shapes:
            tif.write(np.zeros(shape, np.uint8), photometric="rgb" if len(shape) == 3 else "minisblack")
    v, f = box(1, (1, 1, 1), (3, 3, 3))
    write_obj(tmp_path / "a.obj", v, f)
    err = _cli_one_line(["volume", tmp_path / "in.tif", tmp_path / "out.tif", "--src", tmp_path / "a.obj", "--dst", tmp_path / "a.obj"])
    assert "in.tif: " in err


@pytest.mark.parametrize("shape", [(1024, 1024, 1024), (64, 64, 64), (2000, 10, 10, 3)])
@pytest.mark.parametrize("ext", [".nii", ".nii.gz"])
def test_a_header_declaring_more_than_its_file_is_refused_before_reading(tmp_path, monkeypatch, shape, ext):
    # A 33 KB file declaring gigabytes: refused from the header, nothing read
    # (the reader is replaced by one that fails if called).
    import gzip

    header = nib.Nifti1Header()
    header.set_data_shape(shape)
    header.set_data_dtype(np.float32)
    body = header.binaryblock + b"\0" * 4 + b"\1" * 1000
    path = tmp_path / f"bomb{ext}"
    path.write_bytes(gzip.compress(body) if ext.endswith(".gz") else body)
    monkeypatch.setattr(nib.arrayproxy.ArrayProxy, "get_unscaled", lambda self: pytest.fail("data were read"))
    with pytest.raises(ImageInputError, match=r"bomb\.nii(\.gz)?: declares .* in a file of .*refused before reading"):
        read_volume(path)


@pytest.mark.parametrize(("shape", "dtype"), [((5, 7, 9), np.uint8), ((3, 4, 6, 3), np.uint16), ((4, 5, 6), np.float32)])
def test_a_stack_written_page_by_page_reads_as_the_same_volume(tmp_path, shape, dtype):
    """tifffile writing page by page makes each page a series of its own; that stack was refused
    ("got axes YX") though its pages are the volume. Every way of writing the pages reads the same."""
    import tifffile

    data = np.random.default_rng(len(shape)).integers(0, 200, shape).astype(dtype)
    tifffile.imwrite(tmp_path / "one.tif", data, photometric="rgb" if len(shape) == 4 else "minisblack")
    for name, metadata in (("shaped.tif", {}), ("plain.tif", None)):
        with tifffile.TiffWriter(tmp_path / name) as tw:
            for page in data:
                tw.write(page, contiguous=False, metadata=metadata, photometric="rgb" if len(shape) == 4 else None)
    want = read_volume(tmp_path / "one.tif").data
    assert want.shape[:3] == shape[:3]
    for name in ("shaped.tif", "plain.tif"):
        got = read_volume(tmp_path / name)
        assert got.data.dtype == want.dtype and np.array_equal(got.data, want), name
