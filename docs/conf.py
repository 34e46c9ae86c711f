"""Sphinx configuration: warpcli's documentation, built from the repository (``sphinx-build -W -b html docs OUT``)."""

from __future__ import annotations

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "_ext"))
sys.path.insert(0, os.path.dirname(HERE))  # this checkout's warpcli, not another copy

import warpcli  # noqa: E402

project = "warpcli"
author = "warpcli contributors"
copyright = "warpcli contributors, MIT licence"
release = version = warpcli.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",  # numpydoc docstrings
    "sphinx.ext.mathjax",
    "sphinx_click",  # the CLI reference, from the click commands
    "myst_parser",  # pages in Markdown (moved from the README)
    "warpgallery",  # the gallery: docs/examples/*.py run at build time, their pictures embedded
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "examples", "Thumbs.db", ".DS_Store"]
templates_path = ["_templates"]

# numpydoc docstrings through napoleon; `name` in a docstring links to the object where it can.
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_preprocess_types = False
# Attributes sections as fields, not attribute entries: a NamedTuple's fields are
# documented by autodoc already, and would be described twice.
napoleon_use_ivar = True
# Parameter types such as "(n, 2) array_like" are prose: a word in them that names
# two attributes (Polygon.n, Theta.n) is not a reference to either.
suppress_warnings = ["ref.python"]
default_role = "py:obj"
autosummary_generate = True
autodoc_default_options = {"members": True, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"

myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]

html_theme = "alabaster"
html_title = f"warpcli {release}"
html_static_path: list[str] = []
html_theme_options = {"description": "Smooth bijective image warping between polygons", "page_width": "1100px"}

# The gallery: each docs/examples/*.py script is run once per build, in its own
# directory, and every picture it writes is shown under its code.
warpgallery_examples = os.path.join(HERE, "examples")
warpgallery_out = os.path.join(HERE, "gallery")


def _literal_examples(app, ctx, lines: list[str]) -> None:
    """click's ``\\b`` example blocks become line blocks, where ``frames/*.png`` would start emphasis: escape it."""
    for k, line in enumerate(lines):
        if line.lstrip().startswith("| "):
            lines[k] = line.replace("*", "\\*")


def setup(app) -> None:
    app.connect("sphinx-click-process-description", _literal_examples)
    app.connect("sphinx-click-process-epilog", _literal_examples)
