"""scipy's compiled extension modules, loaded from their files without importing the packages around them.

Importing ``scipy.linalg`` or ``scipy.sparse.linalg`` imports much more than
the one extension a warp calls (numpy.testing, unittest, importlib.metadata:
0.17 s of a 1 MP MFS warp for scipy.linalg alone). The extension is loaded
from its file under its own name and registered so, and a later import of
the package finds this module rather than another copy.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys
import threading
from types import ModuleType

__all__ = ["scipy_extension"]

_LOCK = threading.Lock()


def scipy_extension(name: str) -> ModuleType:
    """The extension module ``name`` of scipy (``"scipy.linalg._flapack"``), loaded once.

    Parameters
    ----------
    name : str
        Its full dotted name.

    Returns
    -------
    module

    Raises
    ------
    ImportError
        If scipy or the extension's file is not found, or it cannot be loaded.
    """
    with _LOCK:
        module = sys.modules.get(name)
        if module is not None:
            return module
        spec = importlib.util.find_spec("scipy")
        if spec is None or not spec.origin:
            raise ImportError("scipy not found")
        package, _, base = name.partition(".")[2].rpartition(".")
        folder = os.path.join(os.path.dirname(spec.origin), *package.split(".")) if package else os.path.dirname(spec.origin)
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = os.path.join(folder, base + suffix)
            if os.path.isfile(path):
                break
        else:
            raise ImportError(f"no {base} extension in {folder}")
        loader = importlib.machinery.ExtensionFileLoader(name, path)
        module_spec = importlib.util.spec_from_file_location(name, path, loader=loader)
        if module_spec is None:
            raise ImportError(f"cannot load {path}")
        module = importlib.util.module_from_spec(module_spec)
        loader.exec_module(module)
        sys.modules[name] = module
        return module
