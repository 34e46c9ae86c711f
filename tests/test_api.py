"""The public API: discoverable names, docstrings, the error rule, and one tested copy."""

from __future__ import annotations

import inspect
import os
import subprocess
import sys

import numpy as np
import pytest

import warpcli
from conftest import REPO
from warpcli import InputError, MapOptions, WarpOptions, warp_image


def test_every_public_name_resolves_and_is_listed():
    for name in warpcli.__all__:
        assert getattr(warpcli, name) is not None
    assert set(dir(warpcli)) == set(warpcli.__all__)


def test_type_checkers_see_every_public_name():
    """The TYPE_CHECKING block imports exactly what __getattr__ exports (a stub for IDEs)."""
    source = open(warpcli.__file__).read()
    block = source[source.index("if TYPE_CHECKING:") : source.index("def __getattr__")]
    for name in warpcli.__all__:
        if name != "__version__":
            assert name in block, name
    assert os.path.exists(os.path.join(os.path.dirname(warpcli.__file__), "py.typed"))


@pytest.mark.parametrize("name", [n for n in warpcli.__all__ if n != "__version__"])
def test_public_callables_have_numpydoc(name):
    obj = getattr(warpcli, name)
    doc = inspect.getdoc(obj) or ""
    assert doc, name
    if inspect.isfunction(obj) and inspect.signature(obj).parameters:
        assert "Parameters\n----------" in doc, name
        if inspect.signature(obj).return_annotation not in (None, "None"):
            assert "Returns\n-------" in doc, name


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"size": (0, 5)}, "positive"),
        ({"size": (10,)}, "width, height"),
        ({"max_area": -1}, "positive"),
        ({"max_area": float("nan")}, "positive"),
        ({"weights": "foo"}, "weights"),
        ({"interp": "bicubic"}, "interpolation"),
        ({"method": "magic"}, "method"),
        ({"theta": "square"}, "Theta"),
        ({"src_boundary": "cubic"}, "boundary"),
        ({"background": float("inf")}, "finite"),
        ({"dtype": "int7"}, "dtype"),
        ({"no_such_option": 1}, "unknown option"),
    ],
)
def test_bad_arguments_are_input_errors_and_value_errors(kwargs, match):
    img = np.zeros((16, 16), dtype=np.uint8)
    tri = [[1, 1], [14, 1], [1, 14]]
    with pytest.raises(InputError, match=match) as info:
        warp_image(img, tri, tri, **kwargs)
    assert isinstance(info.value, ValueError)


def test_bad_images_are_input_errors():
    tri = [[1, 1], [14, 1], [1, 14]]
    for img in (np.zeros((0, 5)), np.zeros((2, 2, 2, 2)), np.array([["a"]])):
        with pytest.raises(InputError):
            warp_image(img, tri, tri)


def test_file_errors_are_also_os_errors(tmp_path):
    from warpcli import ImageInputError, read_image

    with pytest.raises(ImageInputError) as info:
        read_image(tmp_path / "missing.png")
    assert isinstance(info.value, OSError) and isinstance(info.value, InputError)


def test_options_are_typed_and_checked_once():
    opts = WarpOptions().changed(interp="cubic", max_area=4, method="fem")
    assert opts.interp == "cubic" and opts.map == MapOptions(max_area=4.0)
    assert MapOptions(max_area=(2, 3)).areas() == (2.0, 3.0)


def test_cli_choices_come_from_the_registry():
    from warpcli.cli import warp
    from warpcli.maps.registry import METHODS, THETAS

    params = {p.name: p for p in warp.params}
    assert tuple(params["method"].type.choices) == tuple(METHODS)
    for name in THETAS:  # --theta also takes a file, so its choices are listed in the help
        assert name in params["theta"].metavar and name in params["theta"].help


def test_the_registry_implements_exactly_the_names_options_accept():
    """`options` (base layer) lists the names; `maps.registry` (above the maps it names) implements them."""
    from warpcli import options
    from warpcli.maps import registry

    assert tuple(registry.METHODS) == options.METHODS
    assert tuple(registry.THETAS) == options.THETAS
    for entry in (*registry.METHODS.values(), *registry.THETAS.values()):
        assert callable(getattr(entry.load(), "build", None)) or callable(entry.load())


def test_one_copy_is_tested_in_process_and_in_subprocesses(tmp_path):
    """In-process imports and the CLI's subprocesses use this checkout's warpcli."""
    assert os.path.dirname(os.path.abspath(warpcli.__file__)) == os.path.join(REPO, "warpcli")
    done = subprocess.run(
        [sys.executable, "-c", "import warpcli, os; print(os.path.abspath(warpcli.__file__))"],
        cwd=tmp_path, capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert done.stdout.strip() == os.path.abspath(warpcli.__file__)
    duplicates = [
        m for m, mod in sys.modules.items()
        if getattr(mod, "__file__", None) and os.path.abspath(mod.__file__).startswith(os.path.join(REPO, "warpcli"))
        and not (m == "warpcli" or m.startswith("warpcli."))
    ]  # fmt: skip
    assert duplicates == []


def test_the_shared_seam_is_base_layer():
    """What 2D and 3D share (the map seam, P1 maps, distortion) imports numpy and warpcli.errors, nothing more."""
    import ast

    allowed = {"__future__", "dataclasses", "typing", "numpy", "numpy.typing", "errors"}
    for name in ("mapping.py", "simplicial.py", "distortion.py"):
        tree = ast.parse(open(os.path.join(REPO, "warpcli", name)).read())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                assert {a.name for a in node.names} <= allowed, (name, [a.name for a in node.names])
            elif isinstance(node, ast.ImportFrom):
                assert (node.module or "") in allowed, (name, node.module)
