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

from .apply_map import apply_map
from .exits import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_TERMINATED, exit_code
from .points import points
from .progress import Progress
from .run import cli, main, run
from .texture import texture
from .volume import volume
from .warp import warp

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
