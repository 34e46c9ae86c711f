"""Exit statuses of the ``warp`` command: which error ends a run with which, and the help text that lists them."""

from __future__ import annotations

from ..errors import InputError, WarpError

#: Exit statuses; decided here and nowhere else.
EXIT_OK, EXIT_FAILURE, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143
#: A closed terminal (SIGHUP) ends a run as SIGTERM does.
EXIT_HUNG_UP = 129

#: The epilog of every command's help.
EXIT_CODES = """\b
Exit status:
  0    success (in a batch: every input)
  1    failure while processing (for example a write error)
  2    bad input or usage (unreadable or invalid polygon, image or option)
  130  interrupted (Ctrl-C); 143: terminated (SIGTERM); 129: the terminal closed (SIGHUP);
       nothing is left behind
"""

#: The epilog of ``warp edit``: Ctrl-C is how its server is stopped.
EDIT_EXIT_CODES = """\b
Exit status:
  0    stopped (Ctrl-C)
  1    failure while serving
  2    bad input or usage (unreadable image or polygon file, a port that cannot be listened on)
  143  terminated (SIGTERM); 129: the terminal closed (SIGHUP); the page's private file is removed
"""


def exit_code(err: WarpError) -> int:
    """The exit status for an error: 2 for bad input, 1 for a failure while processing."""
    return EXIT_BAD_INPUT if isinstance(err, InputError) else EXIT_FAILURE
