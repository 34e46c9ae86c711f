"""Output stability: the CLI's output on committed inputs against what an earlier version wrote.

This catches change, not error: the stored images in ``tests/golden/`` were
written by warpcli itself (``python tests/golden/rewrite_stored.py``), so a
bug present when they were written passes here. Whether the pixels are right
is checked against independent computations in ``tests/test_golden.py``.

The comparison is OpenImageIO's testsuite rule (fail if more than 0.02 % of
values differ by more than 0.004, or any by more than 0.012, values scaled to
0..1), which lets a rounding flip from another CPU's floating point through;
on one machine the output is byte-identical run after run (checked in
``tests/test_determinism.py``). When a change of output is intended, rewrite
the stored images with the script, look at them, and say why in the commit.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import read_pixels

GOLDEN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "golden")
sys.path.insert(0, GOLDEN)

import rewrite_stored  # noqa: E402


def close_enough(a: np.ndarray, b: np.ndarray) -> tuple[bool, str]:
    """OpenImageIO testsuite rule: fail if more than 0.02 % of values differ by
    more than 0.004, or any by more than 0.012 (values scaled to 0..1)."""
    if a.shape != b.shape:
        return False, f"shapes differ: {a.shape} vs {b.shape}"
    scale = float(np.iinfo(a.dtype).max) if np.issubdtype(a.dtype, np.integer) else 1.0
    d = np.abs(a.astype(np.float64) - b.astype(np.float64)) / scale
    frac = float((d > 0.004).mean())
    worst = float(d.max())
    return frac <= 0.0002 and worst <= 0.012, f"{frac:.4%} of values beyond 0.004, worst {worst:.4f}"


@pytest.mark.parametrize("name", sorted(rewrite_stored.CASES))
def test_cli_output_is_what_an_earlier_version_wrote(name, tmp_path):
    rewrite_stored.write_inputs(str(tmp_path))
    out = tmp_path / "out.png"
    subprocess.run(rewrite_stored.warp_command(str(tmp_path), name, str(out)), check=True)
    ok, why = close_enough(read_pixels(out), read_pixels(os.path.join(GOLDEN, f"{name}.png")))
    assert ok, why


def test_committed_inputs_are_what_the_script_draws(tmp_path):
    rewrite_stored.write_inputs(str(tmp_path))
    np.testing.assert_array_equal(read_pixels(tmp_path / "grid.png"), read_pixels(os.path.join(GOLDEN, "grid.png")))
