"""Running ``warp``: the group of commands, signals, and every way a run ends as an exit status."""

from __future__ import annotations

import os
import sys
import threading

import click

from ..capture import stderr_apart, stderr_fd
from ..errors import WarpError
from ..outputs import end_when_consistent, remove_temporaries
from .exits import EXIT_BAD_INPUT, EXIT_HUNG_UP, EXIT_INTERRUPTED, EXIT_OK, EXIT_TERMINATED, exit_code
from .group import DefaultGroup, LazyCommands
from .options import CONTEXT

#: Each command's name and where it is defined: a run imports the module of its own command only.
COMMANDS = {
    "warp": "warpcli.cli.warp:warp", "apply-map": "warpcli.cli.apply_map:apply_map", "edit": "warpcli.cli.edit:edit",
    "points": "warpcli.cli.points:points", "texture": "warpcli.cli.texture:texture",
    "volume": "warpcli.cli.volume:volume",
}  # fmt: skip

#: The ``warp`` command line: ``warp ...`` warps, ``warp apply-map|edit|points|texture|volume ...`` the others.
cli = DefaultGroup("warp", commands=LazyCommands(COMMANDS), default="warp", context_settings=CONTEXT)


class Terminated(BaseException):
    """SIGTERM arrived (kept for callers that catch it; `main` now ends the process at once)."""


def _kill_children() -> None:
    """Kill the children this run forked: a map or a frame computed in one is not wanted any more."""
    forks = sys.modules.get("warpcli._fork")  # not imported: no child (and no import in a signal handler)
    if forks is not None:
        forks.kill_children()


def _terminate(signum, frame):
    """End the run now: temporary and pending files removed, one line, exit 143 (SIGHUP, a closed
    terminal: 129, the same end).

    Raising an exception here, to unwind like Ctrl-C, is not safe: SIGTERM
    can arrive while a module is imported (OpenImageIO's nanobind module
    aborts the process with "Critical nanobind error" when its import is
    interrupted), while the import or logging lock is held (the unwinding
    then waits on it for ever), or inside code that catches the exception
    and goes on to exit 0. So nothing is unwound: the children it forked are
    killed (`warpcli._fork.kill_children`: a ``kill PID`` reaches this process
    alone), the files it created are removed
    (`warpcli.outputs.remove_temporaries`), and the line
    goes straight to file descriptor 2, without Python's stream locks. Pending
    outputs being renamed into place finish first, so that a run leaves all
    of them or none.
    """
    import signal

    hung_up = signum == getattr(signal, "SIGHUP", None)

    def end():
        _kill_children()
        remove_temporaries()
        try:
            # Not plain 2: a C library's output may be being captured right now (warpcli.capture).
            os.write(stderr_fd(), b"warp: hung up\n" if hung_up else b"warp: terminated\n")
        finally:
            os._exit(EXIT_HUNG_UP if hung_up else EXIT_TERMINATED)

    end_when_consistent(end)


def main(argv: list[str] | None = None) -> int:
    """Run the ``warp`` command; return its exit status instead of raising."""
    import signal
    import warnings

    # SIGTERM (a job scheduler, `kill`) is handled like Ctrl-C: outputs are
    # written to temporary files and renamed at the end, and unwinding removes them.
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate)
        if hasattr(signal, "SIGHUP"):  # the terminal closed: the same end (its default left every file behind)
            signal.signal(signal.SIGHUP, _terminate)
    # Nothing but warpcli's own lines on stderr: numpy's and other libraries'
    # warnings are not for the user of a command-line tool.
    warnings.simplefilter("ignore")
    args = list(sys.argv[1:] if argv is None else argv)
    if not args:
        warp = cli.commands["warp"]
        ctx = warp.make_context("warp", ["--help"], resilient_parsing=True)
        click.echo(warp.get_usage(ctx), err=True)
        click.echo("Try 'warp --help' for help; 'warp apply-map --help' for saved maps.", err=True)
        return EXIT_BAD_INPUT
    prog = f"warp {args[0]}" if args[0] in cli.commands and args[0] != cli.default else "warp"
    from ..cores import explicit, set_jobs

    budget = explicit()  # --jobs sets the process's core budget for this run: put back after it
    try:
        # Without standalone mode click returns an Exit's code instead of raising it.
        code = cli.main(args=args, prog_name="warp", standalone_mode=False)
    except click.exceptions.Exit as done:  # --help, --version, a batch's status
        return done.exit_code
    except click.ClickException as err:
        click.echo(f"warp: error: {err.format_message()} (see '{prog} --help')", err=True)
        return EXIT_BAD_INPUT if err.exit_code == 2 else err.exit_code
    except (click.exceptions.Abort, KeyboardInterrupt):
        _kill_children()  # Ctrl-C reaches them too; ``kill -INT PID`` this process alone
        click.echo("warp: interrupted", err=True)
        return EXIT_INTERRUPTED
    except Terminated:
        click.echo("warp: terminated", err=True)
        return EXIT_TERMINATED
    except WarpError as err:
        click.echo(f"warp: error: {err}", err=True)
        return exit_code(err)
    finally:
        set_jobs(budget)
    return code if isinstance(code, int) else EXIT_OK


def run() -> None:
    """The command, with its process set up: what `warpcli._entry.run` (the console script and
    ``python -m warpcli``) calls once it has raised the collector's threshold."""
    one_blas_thread()
    stderr_apart()  # a line for one input must reach the terminal while a worker's C library is quieted
    code = main()
    _exit_now(code)
    sys.exit(code)


def one_blas_thread() -> None:
    """OpenBLAS on one thread in this process, unless ``OPENBLAS_NUM_THREADS`` says otherwise.

    Set before numpy loads OpenBLAS (which reads it then). warpcli's BLAS calls
    are tiny (numpy's 2x2 products per triangle, SuperLU's dense blocks) or
    limited to one thread already (`warpcli.maps.closed_form.lstsq`), so
    OpenBLAS's pool only spun: its second thread took about 50 ms of a core in
    a 1-megapixel FEM warp, from the forked child building the other map. The
    results are the same bits: one thread is what those calls ran on anyway.
    """
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def _exit_now(code: int) -> None:
    """End the process without the interpreter's teardown, once the work is done.

    Python's finalization frees every module and object one by one: about
    35 ms after a 1-megapixel warp, a twentieth of the run, for memory the OS
    takes back at once anyway. So the exit handlers run (logging, temporary
    files, whatever a library registered), the standard streams are flushed,
    and the process ends with ``os._exit``. Not while another thread runs that
    may still matter: then Python's own exit waits for it, as usual. Work
    nobody waits for any more (``warpcli_task`` threads: the map of a run that
    bad input stopped) is dropped.
    """
    import atexit
    import os

    for t in threading.enumerate():
        if t is not threading.main_thread() and t.is_alive() and not t.daemon and not getattr(t, "warpcli_task", False):
            return
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):
            code = code or 120  # what Python's own exit reports for a stream it cannot flush
    os._exit(code)
