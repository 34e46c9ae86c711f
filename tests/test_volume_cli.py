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
