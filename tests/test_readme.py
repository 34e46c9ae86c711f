"""Every warp command in the README's shell examples runs as written (with the sample-making scripts they use)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def readme_commands() -> list[str]:
    text = open(os.path.join(ROOT, "README.md")).read()
    lines = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        # pip lines are the reader's set-up (the tests run with the test extra installed).
        lines += [ln for ln in block.splitlines() if ln.startswith(("warp ", "mkdir ", "python sample_images/"))]
    return lines


COMMANDS = readme_commands()


def test_the_readme_has_examples():
    assert len([c for c in COMMANDS if c.startswith("warp ")]) >= 6
    # The retouch and volume sections' examples are among those run.
    assert any("--outside input" in c for c in COMMANDS)
    assert any(c.startswith("warp volume ") for c in COMMANDS)


def test_readme_commands_run_in_order(tmp_path):
    os.symlink(os.path.join(ROOT, "sample_images"), tmp_path / "sample_images")
    env = dict(os.environ, PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    for command in COMMANDS:  # later ones may use earlier outputs (apply-map on a saved map)
        done = subprocess.run(command, shell=True, cwd=tmp_path, env=env, capture_output=True, text=True)
        assert done.returncode == 0, f"{command}\n{done.stderr}"


def test_readme_python_examples_run(tmp_path, monkeypatch):
    text = open(os.path.join(ROOT, "README.md")).read()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks
    os.symlink(os.path.join(ROOT, "sample_images"), tmp_path / "sample_images")
    monkeypatch.chdir(tmp_path)
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})
