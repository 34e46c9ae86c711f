"""The one-line progress display on stderr while a long warp runs."""

from __future__ import annotations

import threading
import time


class Progress:
    """A one-line stage display on stderr for runs longer than ``delay`` seconds.

    Shown only when the stream is a terminal (never in scripts or logs) and
    not with -q; the line is cleared when the run ends.

    Parameters
    ----------
    stream : text stream
        Where the line goes (``sys.stderr``).
    enabled : bool
        False shows nothing (-q).
    delay : float
        Seconds before the line first appears: short runs show nothing.
    interval : float
        Seconds between updates of the elapsed time.
    """

    def __init__(self, stream, *, enabled: bool = True, delay: float = 1.0, interval: float = 0.2) -> None:
        self._stream = stream
        self._enabled = enabled and _isatty(stream)
        self._delay = delay
        self._interval = interval
        self._stage = "starting"
        self._shown = False
        self._start = 0.0
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    def stage(self, name: str) -> None:
        """Show ``name`` as the stage the run is in from now on."""
        self._stage = name

    def __enter__(self) -> Progress:
        if self._enabled:
            self._start = time.monotonic()
            self._thread = threading.Thread(target=self._run, name="warp-progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        if self._thread is not None:
            self._done.set()
            self._thread.join()
            if self._shown:
                self._stream.write("\r\x1b[K")
                self._stream.flush()

    def _run(self) -> None:
        if self._done.wait(self._delay):
            return
        while True:
            elapsed = time.monotonic() - self._start
            self._stream.write(f"\r\x1b[Kwarp: {self._stage}... {elapsed:.1f} s")
            self._stream.flush()
            self._shown = True
            if self._done.wait(self._interval):
                return


def _isatty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False
