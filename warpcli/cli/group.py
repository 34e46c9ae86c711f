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
