"""A small example gallery for Sphinx: every script of a folder is run when the docs build, and its pictures shown.

sphinx-gallery does this with matplotlib's figures; warpcli's examples write
image files (PNG) with warpcli itself, so this extension is much smaller: at
``builder-inited`` each ``*.py`` of ``warpgallery_examples`` runs in its own
directory under ``warpgallery_out``, and a page is written for it, with the
title and text of its docstring, its code, what it printed and every picture
it wrote, plus an index page of thumbnails. An example that raises fails the
build: every example in the docs runs.

Options (``conf.py``): ``warpgallery_examples`` (folder of scripts) and
``warpgallery_out`` (inside the source folder; generated, not committed).
"""

from __future__ import annotations

import ast
import contextlib
import io
import os
import runpy
import shutil
import time

from sphinx.application import Sphinx
from sphinx.errors import ExtensionError
from sphinx.util import logging

log = logging.getLogger(__name__)

PICTURES = (".png", ".jpg", ".jpeg", ".gif", ".svg")


def _docstring(path: str) -> tuple[str, str, int]:
    """(title, the rest of the docstring, the line the code starts at, 1-based)."""
    with open(path, encoding="utf-8") as fh:
        tree = ast.parse(fh.read())
    doc = ast.get_docstring(tree)
    if not doc or not tree.body or not isinstance(tree.body[0], ast.Expr):
        raise ExtensionError(f"{path}: a gallery example starts with a docstring: its title, a blank line, its text")
    title, _, rest = doc.partition("\n")
    return title.strip().rstrip("."), rest.strip(), tree.body[0].end_lineno + 1


def _run(path: str, workdir: str) -> tuple[str, list[str], float]:
    """Run one example in ``workdir``: (what it printed, the pictures it wrote, seconds)."""
    if os.path.isdir(workdir):
        shutil.rmtree(workdir)
    os.makedirs(workdir)
    out = io.StringIO()
    here = os.getcwd()
    t0 = time.perf_counter()
    try:
        os.chdir(workdir)
        with contextlib.redirect_stdout(out):
            runpy.run_path(path, run_name="__main__")
    except BaseException as err:  # a failing example fails the build, with its error
        raise ExtensionError(f"gallery example {os.path.basename(path)} failed: {type(err).__name__}: {err}") from err
    finally:
        os.chdir(here)
    pictures = sorted(name for name in os.listdir(workdir) if name.lower().endswith(PICTURES))
    return out.getvalue(), pictures, time.perf_counter() - t0


def _page(name: str, path: str, out_dir: str, title: str, text: str, first_code_line: int, printed: str,
          pictures: list[str]) -> str:  # fmt: skip
    rel = os.path.relpath(path, out_dir).replace(os.sep, "/")
    lines = [f".. _gallery-{name}:", "", title, "=" * len(title), "", text, "", f".. literalinclude:: {rel}",
             "   :language: python", f"   :lines: {first_code_line}-", ""]  # fmt: skip
    if printed.strip():
        lines += ["It prints:", "", ".. code-block:: text", ""]
        lines += ["   " + ln for ln in printed.rstrip().splitlines()] + [""]
    for picture in pictures:
        lines += [f".. figure:: {name}/{picture}", f"   :alt: {picture}", "", f"   ``{picture}``", ""]
    lines += [f"Download the script: :download:`{os.path.basename(path)} <{rel}>`", ""]
    return "\n".join(lines)


def build_gallery(app: Sphinx) -> None:
    """Run every example and write its page and the gallery's index."""
    src = app.config.warpgallery_examples
    out = app.config.warpgallery_out
    if not src or not os.path.isdir(src):
        raise ExtensionError(f"warpgallery_examples is not a folder: {src!r}")
    os.makedirs(out, exist_ok=True)
    scripts = sorted(name for name in os.listdir(src) if name.endswith(".py") and not name.startswith("_"))
    index = ["Gallery", "=======", "",
             "Each example below is a script in ``docs/examples``; it ran when these pages were built, and the",
             "pictures are what it wrote.", "", ".. toctree::", "   :hidden:", ""]  # fmt: skip
    index += [f"   {script[:-3]}" for script in scripts] + [""]
    for script in scripts:
        name = script[:-3]
        path = os.path.join(src, script)
        title, text, first = _docstring(path)
        printed, pictures, seconds = _run(path, os.path.join(out, name))
        log.info("gallery: %s ran in %.1f s, %d picture(s)", script, seconds, len(pictures))
        with open(os.path.join(out, f"{name}.rst"), "w", encoding="utf-8") as fh:
            fh.write(_page(name, path, out, title, text, first, printed, pictures))
        index += [f":doc:`{name}`", "   " + (text.split("\n\n")[0].replace("\n", " ") or title), ""]
        if pictures:
            index += [f".. image:: {name}/{pictures[0]}", "   :width: 320px", f"   :alt: {title}",
                      f"   :target: {name}.html", ""]  # fmt: skip
    with open(os.path.join(out, "index.rst"), "w", encoding="utf-8") as fh:
        fh.write("\n".join(index))


def setup(app: Sphinx) -> dict:
    app.add_config_value("warpgallery_examples", "", "env")
    app.add_config_value("warpgallery_out", "", "env")
    app.connect("builder-inited", build_gallery)
    return {"version": "1.0", "parallel_read_safe": True, "parallel_write_safe": True}
