"""`warp volume` from the command line: the library's checks become exit statuses and one line."""

from __future__ import annotations


import numpy as np
import pytest

from test_volume_surface import write_obj
from helpers import run_cli
from warpcli.volume.examples import box

tifffile = pytest.importorskip("tifffile")



def test_warp_volume_identity_and_a_shear(tmp_path):
    data = np.random.default_rng(2).integers(0, 255, (32, 32, 32), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    v, f = box(2, (4.0, 4.0, 4.0), (28.0, 28.0, 28.0))
    write_obj(tmp_path / "cube.obj", v, f)
    w = v.copy()
    w[:, 0] = 4.0 + (w[:, 0] - 4.0) * (1.0 + 0.01 * (w[:, 2] - 4.0))
    write_obj(tmp_path / "sheared.obj", w, f)
    code, err = run_cli(["volume", tmp_path / "in.tif", tmp_path / "same.tif", "--src", tmp_path / "cube.obj", "--dst", tmp_path / "cube.obj", "--interp", "nearest"])
    assert code == 0, err
    assert np.array_equal(tifffile.imread(tmp_path / "same.tif")[4:28, 4:28, 4:28], data[4:28, 4:28, 4:28])
    code, err = run_cli(["volume", tmp_path / "in.tif", tmp_path / "out.tif", "--src", tmp_path / "cube.obj", "--dst", tmp_path / "sheared.obj", "--report", tmp_path / "r.json"])
    assert code == 0, err
    assert (tmp_path / "r.json").exists() and tifffile.imread(tmp_path / "out.tif").dtype == np.uint8


def test_warp_volume_bad_cage_is_one_line_and_exit_2(tmp_path):
    tifffile.imwrite(tmp_path / "in.tif", np.zeros((8, 8, 8), dtype=np.uint8), photometric="minisblack")
    v, f = box(1, (1, 1, 1), (7, 7, 7))
    write_obj(tmp_path / "a.obj", v, f)
    write_obj(tmp_path / "open.obj", v, f[1:])
    code, err = run_cli(["volume", tmp_path / "in.tif", tmp_path / "out.tif", "--src", tmp_path / "a.obj", "--dst", tmp_path / "open.obj"])
    assert code == 2 and err.count("\n") == 1 and "open.obj: is not closed" in err, err
    assert not (tmp_path / "out.tif").exists()


def test_warp_volume_bytes_do_not_depend_on_the_thread_count(tmp_path):
    import os
    import subprocess
    import sys

    data = np.random.default_rng(6).integers(0, 255, (24, 24, 24), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    v, f = box(2, (3.0, 3.0, 3.0), (21.0, 21.0, 21.0))
    write_obj(tmp_path / "cube.obj", v, f)
    w = v.copy()
    w[:, 0] = 3.0 + (w[:, 0] - 3.0) * (1.0 + 0.015 * (w[:, 2] - 3.0))
    write_obj(tmp_path / "sheared.obj", w, f)
    # Tetrahedra with edges of 1.6 voxels: every kernel that threads (the solve, locating and
    # resampling all 24^3 voxels) still has work for each of 4 threads; edges of 0.8 cost
    # 4.7 s of CPU per process against 1.3 s.
    outs = []
    for k, threads in enumerate(("1", "2", "4")):
        env = {key: val for key, val in os.environ.items() if not key.endswith("_NUM_THREADS")}
        env.update({"OMP_NUM_THREADS": threads, "OPENBLAS_NUM_THREADS": threads, "NUMBA_NUM_THREADS": threads})
        out = tmp_path / f"out{k}.tif"
        done = subprocess.run(
            [sys.executable, "-m", "warpcli", "volume", str(tmp_path / "in.tif"), str(out), "--src", str(tmp_path / "cube.obj"), "--dst", str(tmp_path / "sheared.obj"), "--edge", "1.6"],
            env=env, capture_output=True, text=True,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2]


def test_a_folded_volume_is_refused_unless_folds_are_allowed(tmp_path, monkeypatch):
    # A map that stays folded after untangling (forced here: no untangling,
    # and a certificate that reports one inverted tetrahedron) is not
    # written, exit 1; --allow-folds writes it with a warning.
    from warpcli.volume import compose

    data = np.random.default_rng(3).integers(0, 255, (16, 16, 16), dtype=np.uint8)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    v, f = box(1, (2.0, 2.0, 2.0), (14.0, 14.0, 14.0))
    write_obj(tmp_path / "cube.obj", v, f)
    import dataclasses

    real = compose.TetMap.certify
    monkeypatch.setattr(compose.TetMap, "certify", lambda self: dataclasses.replace(real(self), flipped=1))
    w = v * 0.9 + 1.0
    write_obj(tmp_path / "small.obj", w, f)
    args = ["volume", tmp_path / "in.tif", tmp_path / "out.tif", "--src", tmp_path / "cube.obj", "--dst", tmp_path / "small.obj"]
    code, err = run_cli(args)
    assert code == 1 and "fold the volume" in err and "--allow-folds" in err and err.count("\n") == 1, err
    assert not (tmp_path / "out.tif").exists()
    code, err = run_cli(args + ["--allow-folds"])
    assert code == 0 and "folds the volume there" in err, err
    assert (tmp_path / "out.tif").exists()


def test_the_docs_example_is_one_to_one(tmp_path):
    # docs/volumes.md's own example: a box twisted and bent (sample_images/make_volume.py). It was
    # accepted with 58 "flattened slivers" that sent interior points onto a face of Theta; finite
    # differences found 14 points with det <= 0 and round trips off by 0.34 voxel.
    pytest.importorskip("nibabel")
    import json
    import runpy
    from pathlib import Path

    make = runpy.run_path(str(Path(__file__).resolve().parents[1] / "sample_images" / "make_volume.py"))
    make["main"](str(tmp_path))
    code, err = run_cli(["volume", tmp_path / "ct.nii.gz", tmp_path / "out.nii.gz", "--src", tmp_path / "cube.obj", "--dst", tmp_path / "bent.obj", "--report", tmp_path / "r.json"])
    assert code == 0, err
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["flipped_tetrahedra"] == {"source": 0, "target": 0}
    assert report["distortion"]["inverted_samples"] == 0 and report["distortion"]["min_jacobian_det"] > 0
    assert report["maps"]["target"]["split_edges"] > 0
    from warpcli.volume import build_map, read_surface

    vm = build_map(read_surface(tmp_path / "cube.obj"), read_surface(tmp_path / "bent.obj"))
    # Finite differences of f^-1 on a grid of target points (not the certificate's test): no
    # orientation lost, and every pre-image goes back to its point.
    step, h = 0.7, 1e-3
    ax = [np.arange(v0 + step / 2, v1, step) for v0, v1 in zip(*(vm.dst.vertices.min(0), vm.dst.vertices.max(0)))]
    p = np.stack(np.meshgrid(*ax, indexing="ij"), -1).reshape(-1, 3)
    pre = vm.inverse(p)
    p, pre = p[np.isfinite(pre[:, 0])], pre[np.isfinite(pre[:, 0])]
    jac = np.empty((len(p), 3, 3))
    for d in range(3):
        e = np.zeros(3)
        e[d] = h
        jac[:, :, d] = (vm.inverse(p + e) - vm.inverse(p - e)) / (2 * h)
    det = np.linalg.det(jac)
    det = det[np.isfinite(det)]
    assert len(det) > 30000 and det.min() > 0
    assert np.abs(vm.forward(pre) - p).max() < 1e-9


@pytest.mark.parametrize(
    ("dtype", "value", "ok"),
    [("uint8", "nan", False), ("uint8", "300", False), ("uint8", "255", True), ("uint16", "-1", False),
     ("int16", "-32768", True), ("uint8", "inf", False), ("float32", "nan", True), ("float32", "-inf", True),
     ("float32", "1e30", True)],
)  # fmt: skip
def test_the_background_must_be_a_value_of_the_volumes_type(tmp_path, dtype, value, ok):
    data = (np.arange(8**3).reshape(8, 8, 8) % 50).astype(dtype)
    tifffile.imwrite(tmp_path / "in.tif", data, photometric="minisblack")
    v, f = box(1, (1.0, 1.0, 1.0), (7.0, 7.0, 7.0))
    write_obj(tmp_path / "a.obj", v, f)
    write_obj(tmp_path / "b.obj", v * 0.8 + 1.0, f)
    code, err = run_cli(["volume", tmp_path / "in.tif", tmp_path / "out.tif", "--src", tmp_path / "a.obj", "--dst", tmp_path / "b.obj", "--background", value])
    if not ok:
        assert code == 2 and err.count("\n") == 1 and "in.tif" in err and "--background" in err and dtype in err, err
        assert not (tmp_path / "out.tif").exists()
        return
    assert code == 0, err
    out = tifffile.imread(tmp_path / "out.tif")
    assert out.dtype == np.dtype(dtype)
    corner = out[0, 0, 0]  # outside the target
    want = np.array(float(value)).astype(dtype)
    assert (np.isnan(corner) and np.isnan(want)) or corner == want
