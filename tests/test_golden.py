"""Golden-image tests: the CLI's output on committed inputs, compared with
OpenImageIO's testsuite rule. Regenerate with tests/golden/regenerate.py."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import read_pixels

GOLDEN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "golden")
sys.path.insert(0, GOLDEN)

import regenerate  # noqa: E402


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


@pytest.mark.parametrize("name", sorted(regenerate.CASES))
def test_cli_output_matches_golden(name, tmp_path):
    regenerate.write_inputs(str(tmp_path))
    out = tmp_path / "out.png"
    subprocess.run(regenerate.warp_command(str(tmp_path), name, str(out)), check=True)
    ok, why = close_enough(read_pixels(out), read_pixels(os.path.join(GOLDEN, f"{name}.png")))
    assert ok, why


def test_committed_inputs_are_what_the_script_draws(tmp_path):
    regenerate.write_inputs(str(tmp_path))
    np.testing.assert_array_equal(read_pixels(tmp_path / "grid.png"), read_pixels(os.path.join(GOLDEN, "grid.png")))
