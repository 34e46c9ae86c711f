"""The documentation builds with warnings as errors, runs every gallery example, and names every public name.

The build needs the ``docs`` extra (sphinx, sphinx-click, myst-parser,
scikit-image for one example), which the ``test`` extra includes; without it
the build is skipped, and the checks that read the pages still run.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import time

import pytest

import warpcli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOCS = os.path.join(ROOT, "docs")
NEEDED = ("sphinx", "sphinx_click", "myst_parser", "skimage")


def _pages() -> list[str]:
    out = []
    for dirpath, dirnames, files in os.walk(DOCS):
        dirnames[:] = sorted(d for d in dirnames if d not in ("_build", "gallery", "api", "_ext"))
        out += [os.path.join(dirpath, f) for f in sorted(files) if f.endswith(".md")]
    return out


def test_the_api_reference_lists_every_public_name():
    text = open(os.path.join(DOCS, "api.md")).read()
    listed = set(re.findall(r"^   ([A-Za-z_]\w*)$", text, flags=re.M))
    missing = sorted(set(warpcli.__all__) - {"__version__"} - listed)
    assert not missing, f"add them to docs/api.md: {', '.join(missing)}"
    assert not listed - set(warpcli.__all__), "docs/api.md lists names warpcli does not export"


def test_every_page_is_in_a_table_of_contents():
    index = open(os.path.join(DOCS, "index.md")).read()
    for page in _pages():
        name = os.path.relpath(page, DOCS)[:-3].replace(os.sep, "/")
        if name != "index":
            assert re.search(rf"^{re.escape(name)}$", index, flags=re.M), f"{name} is in no toctree of docs/index.md"


def test_every_gallery_example_has_a_title_and_text():
    examples = os.path.join(DOCS, "examples")
    scripts = [f for f in os.listdir(examples) if f.endswith(".py")]
    assert len(scripts) >= 3
    for script in scripts:
        source = open(os.path.join(examples, script)).read()
        assert re.match(r'"""[^\n]+\n\n\S', source), f"{script}: start with a docstring: a title, a blank line, text"


@pytest.mark.skipif(
    any(importlib.util.find_spec(m) is None for m in NEEDED), reason="the docs extra is not installed"
)
def test_the_docs_build_with_warnings_as_errors(tmp_path):
    """sphinx-build -W: broken references, bad docstrings and failing gallery examples all fail it."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]))
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", "-d", str(tmp_path / "doctrees"),
         DOCS, str(tmp_path / "html")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    seconds = time.perf_counter() - t0
    assert done.returncode == 0, done.stderr[-4000:]
    html = tmp_path / "html"
    for page in ("index", "api", "cli", "gallery/index", "results/methods", "results/theta", "guide/scikit-image"):
        assert (html / f"{page}.html").is_file(), page
    # Every example ran and its pictures are in the pages.
    gallery = (html / "gallery" / "index.html").read_text()
    for script in os.listdir(os.path.join(DOCS, "examples")):
        if script.endswith(".py"):
            assert script[:-3] in gallery
    assert len(list((html / "_images").glob("*.png"))) >= 8
    # The CLI reference is click's own: every option of warp is there.
    cli = (html / "cli.html").read_text()
    for option in ("--labels", "--save-map", "--stmap-t", "--frames"):
        assert option in cli
    print(f"docs built in {seconds:.1f} s")
