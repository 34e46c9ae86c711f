"""The ``warp`` group: a subcommand's name first, or else the default command's arguments."""

from __future__ import annotations

import click


class DefaultCommand(click.Command):
    """A command whose usage line reads "warp ..." also when it is the group's default."""

    def format_usage(self, ctx, formatter):
        formatter.write_usage(ctx.command_path.strip(), " ".join(self.collect_usage_pieces(ctx)))


class DefaultGroup(click.Group):
    """A group whose first argument is a subcommand's name, or else the default command's."""

    def __init__(self, *args, default: str, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.default = default

    def parse_args(self, ctx, args):
        if not (args and args[0] in self.commands):
            args = [self.default, *args]
        return super().parse_args(ctx, args)

    def resolve_command(self, ctx, args):
        name, cmd, rest = super().resolve_command(ctx, args)
        # The default command's usage and messages read "warp ...", not "warp warp ...".
        return ("" if name == self.default else name), cmd, rest


class LazyCommands(dict):
    """A group's commands by name, each imported from its module when first asked for.

    ``warp`` runs one command: its start-up then imports that command's
    module only, not every subcommand's (click's lazy-group pattern, kept as
    the ``commands`` mapping click and sphinx-click read). Iterating gives
    every name; ``[name]``, ``get``, ``values`` and ``items`` import what they
    return.

    Parameters
    ----------
    where : dict of str to str
        Command name -> ``"module:attribute"`` of the click command.
    """

    def __init__(self, where: dict[str, str]) -> None:
        super().__init__()
        self._where = dict(where)

    def __missing__(self, name: str):
        import importlib

        if name not in self._where:
            raise KeyError(name)
        module, attribute = self._where[name].split(":")
        command = getattr(importlib.import_module(module), attribute)
        super().__setitem__(name, command)
        return command

    def __setitem__(self, name: str, command) -> None:  # click's add_command
        self._where.setdefault(name, "")
        super().__setitem__(name, command)

    def __contains__(self, name: object) -> bool:
        return name in self._where

    def __iter__(self):
        return iter(self._where)

    def __len__(self) -> int:
        return len(self._where)

    def get(self, name: str, default=None):
        return self[name] if name in self._where else default

    def keys(self):
        return self._where.keys()

    def values(self):
        return [self[name] for name in self._where]

    def items(self):
        return [(name, self[name]) for name in self._where]
