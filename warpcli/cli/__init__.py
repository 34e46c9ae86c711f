"""Command-line interface: the ``warp`` command and its subcommands, a thin click layer over the library.

One module per command (`warp`, `apply_map`, `points`, `texture`, `volume`), the options
they share (`options`), the progress line (`progress`), the group
(`group`), exit statuses (`exits`) and running it all (`run`). click is
imported here and nowhere else in warpcli.

Note that the names ``warp``, ``apply_map``, ``points``, ``texture`` and ``volume`` of this
package are the click commands, not the modules that define them: reach a
module through ``sys.modules`` or ``from warpcli.cli.warp import ...``.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING

from .exits import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_TERMINATED, exit_code
from .progress import Progress
from .run import cli, main, run

if TYPE_CHECKING:
    from .apply_map import apply_map
    from .points import points
    from .texture import texture
    from .volume import volume
    from .warp import warp

#: The commands this package names, each imported from its module when first asked for
#: (`warpcli.cli.run.COMMANDS`: a ``warp`` run imports its own command's module only).
_COMMANDS = ("apply_map", "points", "texture", "volume", "warp")


def __getattr__(name: str):
    if name in _COMMANDS:
        value = getattr(importlib.import_module(f"{__name__}.{name}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class _Package(types.ModuleType):
    """This package, whose command names stay the commands' when their modules are imported.

    Importing a submodule sets it as an attribute of its package: ``warp``
    would then name the module ``warpcli.cli.warp``, not the command, in
    whichever order the modules happen to be imported. Such a setting is
    ignored here (the module stays in ``sys.modules``).
    """

    def __setattr__(self, name: str, value) -> None:
        if name in _COMMANDS and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_FAILURE",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_TERMINATED",
    "Progress",
    "apply_map",
    "cli",
    "exit_code",
    "main",
    "points",
    "run",
    "texture",
    "volume",
    "warp",
]
