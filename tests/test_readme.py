"""Every warp command and Python example of the README and of the docs pages runs as written."""

from __future__ import annotations

import os
import re
import subprocess
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
DOCS = os.path.join(ROOT, "docs")


def pages() -> list[str]:
    """The README, then every Markdown page of the docs (sorted; generated pages excluded)."""
    out = [os.path.join(ROOT, "README.md")]
    for dirpath, dirnames, files in sorted(os.walk(DOCS)):
        dirnames[:] = sorted(d for d in dirnames if d not in ("_build", "gallery", "api", "_ext", "examples"))
        out += [os.path.join(dirpath, f) for f in sorted(files) if f.endswith(".md")]
    return out


def commands(path: str) -> list[str]:
    text = open(path).read()
    lines = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        # pip lines are the reader's set-up (the tests run with the test extra installed).
        lines += [ln for ln in block.splitlines() if ln.startswith(("warp ", "mkdir ", "python sample_images/"))]
    return lines


def python_blocks(path: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", open(path).read(), flags=re.S)


def _first_of_each(pairs: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """Each command once, named by the first page that shows it (a page repeating the README's
    command as written would run the same thing again, to the same file)."""
    seen: set[str] = set()
    return [(p, c) for p, c in pairs if not (c in seen or seen.add(c))]


COMMANDS = _first_of_each([(os.path.relpath(p, ROOT), c) for p in pages() for c in commands(p)])


def test_the_readme_has_examples():
    readme = commands(os.path.join(ROOT, "README.md"))
    assert len([c for c in readme if c.startswith("warp ")]) >= 3
    assert len([c for _, c in COMMANDS if c.startswith("warp ")]) >= 12
    # The retouch and volume examples are among those run.
    assert any("--outside input" in c for _, c in COMMANDS)
    assert any(c.startswith("warp volume ") for _, c in COMMANDS)


def test_the_readme_stays_short_and_links_into_the_docs():
    text = open(os.path.join(ROOT, "README.md")).read()
    assert len(text.splitlines()) <= 150
    for page in re.findall(r"\]\((docs/[^)#]+)", text):
        assert os.path.isfile(os.path.join(ROOT, page)), page
    assert "<!-- quickstart-command -->" in text and "<!-- test-command -->" in text


def test_readme_and_docs_commands_run_in_order(tmp_path, monkeypatch):
    """Each command as written: the first ``warp`` line by the shell and the installed ``warp``
    executable (the console script, its exit path included), the other ``warp`` lines through
    the same command-line code in this process (`warpcli.cli.main`, what the executable calls:
    the same parsing, defaults and exit status, without an interpreter start for each), the
    other lines (``mkdir``, ``python sample_images/...``) by the shell."""
    import contextlib
    import io
    import shlex

    from warpcli.cli import main

    os.symlink(os.path.join(ROOT, "sample_images"), tmp_path / "sample_images")
    env = dict(os.environ, PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    monkeypatch.chdir(tmp_path)
    first = True
    for page, command in COMMANDS:  # later ones may use earlier outputs (apply-map on a saved map)
        if command.startswith("warp ") and not first:
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                code = main(shlex.split(command, comments=True)[1:])
            assert code == 0, f"{page}: {command}\n{err.getvalue()}"
            continue
        first = first and not command.startswith("warp ")
        done = subprocess.run(command, shell=True, cwd=tmp_path, env=env, capture_output=True, text=True)
        assert done.returncode == 0, f"{page}: {command}\n{done.stderr}"


def test_readme_and_docs_python_examples_run(tmp_path, monkeypatch):
    found = [(p, b) for p in pages() for b in python_blocks(p)]
    assert len(found) >= 3
    os.symlink(os.path.join(ROOT, "sample_images"), tmp_path / "sample_images")
    monkeypatch.chdir(tmp_path)
    for path, block in found:
        exec(compile(block, os.path.relpath(path, ROOT), "exec"), {})
