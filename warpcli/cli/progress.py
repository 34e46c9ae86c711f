"""The one-line progress display on stderr while a long warp runs: its stage, or frames done of a sequence."""

from __future__ import annotations

import sys
import threading
import time


class Progress:
    """A one-line display on stderr for runs longer than ``delay`` seconds.

    Shown only when the stream is a terminal (never in scripts or logs) and
    not with -q; the line is cleared when the run ends. A single warp shows
    its stage; a batch or sequence shows items done of the total, the rate
    and the time left (`item_done`).

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
    total : int or None
        Items (frames) of a batch or sequence; None: a single warp.
    what : str
        What the items are, for the line ("frames").
    """

    def __init__(
        self, stream, *, enabled: bool = True, delay: float = 1.0, interval: float = 0.2, total: int | None = None,
        what: str = "frames",
    ) -> None:  # fmt: skip
        self._stream = stream
        self._enabled = enabled and _isatty(stream)
        self._delay = delay
        self._interval = interval
        self._stage = "starting"
        self._shown = False
        self._start = 0.0
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()  # the line and the messages printed above it
        self.total = total
        self._what = what
        self._count = 0

    def stage(self, name: str) -> None:
        """Show ``name`` as the stage the run is in from now on."""
        self._stage = name

    def item_done(self) -> None:
        """One more item (frame) of the total is done."""
        self._count += 1

    def clear(self) -> None:
        """Clear the line now, so that a message printed next starts at the left; the next update redraws it."""
        with self._lock:
            if self._shown:
                self._stream.write("\r\x1b[K")
                self._stream.flush()
                self._shown = False

    def line(self, elapsed: float) -> str:
        """The text of the line after ``elapsed`` seconds."""
        if self.total is None:
            return f"warp: {self._stage}{_compiling_note()}... {elapsed:.1f} s"
        done, total = self._count, self.total
        text = f"warp: {self._what} {done}/{total}"
        if done and elapsed > 0:
            rate = done / elapsed
            left = (total - done) / rate
            text += f", {rate:.2f}/s, {_clock(left)} left" if rate < 1 else f", {rate:.1f}/s, {_clock(left)} left"
        return text + f" ({_clock(elapsed)})"

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
            self.clear()

    def _run(self) -> None:
        if self._done.wait(self._delay):
            return
        while True:
            with self._lock:
                self._stream.write("\r\x1b[K" + self.line(time.monotonic() - self._start))
                self._stream.flush()
                self._shown = True
            if self._done.wait(self._interval):
                return


def _compiling_note() -> str:
    """What the line adds while kernels are being compiled (`warpcli._native.compiling`)."""
    native = sys.modules.get("warpcli._native")  # not imported: nothing compiled (and no numpy loaded here)
    compiling = getattr(native, "compiling", None)  # None also while the module is being imported
    if compiling is None or not compiling():
        return ""
    return " (compiling warpcli's kernels for this machine: the first runs only)"


def _clock(seconds: float) -> str:
    """``m:ss``, or ``h:mm:ss`` from an hour."""
    s = int(round(seconds))
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def _isatty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False
