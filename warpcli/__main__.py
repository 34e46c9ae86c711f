"""``python -m warpcli``: the ``warp`` command."""

from warpcli.cli import run

run()
