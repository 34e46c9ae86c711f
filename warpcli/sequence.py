"""Image sequences: frame-number wildcards in paths and frame specs, in oiiotool's conventions."""

from __future__ import annotations

import glob
import numbers
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass

from .errors import InputError

__all__ = [
    "FRAME_LIMIT",
    "MAX_FRAMES",
    "MAX_PADDING",
    "SequencePattern",
    "describe_frames",
    "expand",
    "find_frames",
    "frames_from_disk",
    "frame_path",
    "is_pattern",
    "missing_frames_error",
    "nuke_reading",
    "other_reading_hint",
    "output_reading_warning",
    "parse_frames",
    "parse_pattern",
]

#: Most frames one frame spec may select. Far beyond any shot (a million
#: frames is 11.5 hours at 24 fps), and small enough that the list of frames
#: and of file names stays a few tens of MB. ``1-999999999999`` is refused
#: before a single number is generated.
MAX_FRAMES = 1_000_000

#: Largest frame-number magnitude: oiiotool keeps frame numbers in a C
#: ``int``, so no sequence it reads or writes has frames beyond +-(2**31 - 1).
#: Inside this range a frame number is also exact as a float, which keyframe
#: interpolation relies on.
FRAME_LIMIT = 2**31 - 1

#: Most digits a wildcard may pad to. A 32-bit frame number has at most 10
#: digits and a sign; more than 32 is a typo (or ``%0999999999d``, which would
#: build gigabyte-long names).
MAX_PADDING = 32

# A wildcard group: a run of '#' and '@' (oiiotool's "(#|@)+", so '#@@' is one
# group), or a printf conversion '%d' / '%0Nd' (oiiotool's "%[0-9]*d"; '%Nd'
# without the zero is matched here only to be refused by name).
_WILDCARD = re.compile(r"[#@]+|%([0-9]*)d")

# One item of a frame spec: N, or N-M, or N-MxS, or N-MyS (oiiotool's
# Filesystem::enumerate_sequence). Frame numbers may be negative: '-5--1'.
# [0-9], not \d: \d would accept other scripts' digits ('١').
_ITEM = re.compile(r"(-?[0-9]+)(?:-(-?[0-9]+)(?:([xy])(-?[0-9]+))?)?")


@dataclass(frozen=True)
class SequencePattern:
    """A path holding one frame-number wildcard, split around it.

    Parameters
    ----------
    prefix : str
        The path before the wildcard.
    wildcard : str
        The wildcard as written: ``"#"``, ``"@@@"``, ``"#@@"``, ``"%04d"``, ``"%d"``.
    suffix : str
        The path after the wildcard.
    padding : int
        The least number of characters a frame number takes, zero-padded on
        the left, the minus sign of a negative frame included (as printf's
        ``%0Nd``): 4 per ``#``, 1 per ``@``, N for ``%0Nd``, 0 for ``%d``.

    Examples
    --------
    >>> p = parse_pattern("shots/plate.#.exr")
    >>> p.prefix, p.wildcard, p.suffix, p.padding
    ('shots/plate.', '#', '.exr', 4)
    >>> p.path(1001), p.path(7), p.path(-7), p.path(123456)
    ('shots/plate.1001.exr', 'shots/plate.0007.exr', 'shots/plate.-007.exr', 'shots/plate.123456.exr')
    """

    prefix: str
    wildcard: str
    suffix: str
    padding: int

    @property
    def pattern(self) -> str:
        """The path as given, wildcard included."""
        return self.prefix + self.wildcard + self.suffix

    def path(self, frame: int) -> str:
        """The file name of ``frame``: the wildcard replaced by the padded frame number.

        A frame number wider than the padding is written in full, as printf
        does (``#`` and 12345 give ``12345``); the padding is a minimum.

        Raises
        ------
        TypeError
            If ``frame`` is not an integer.
        """
        return f"{self.prefix}{_pad(frame, self.padding)}{self.suffix}"


def _pad(frame: int, padding: int) -> str:
    # bool is an int subclass in Python; True is not frame 1.
    if isinstance(frame, bool) or not isinstance(frame, numbers.Integral):
        raise TypeError(f"a frame number must be an integer, not {type(frame).__name__}")
    # printf's %0Nd: the sign counts towards the width (-7 in 4 is '-007').
    return str(int(frame)).zfill(padding)


def is_pattern(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` holds a frame-number wildcard: ``#``, ``@``, ``%d`` or ``%0Nd``.

    Anywhere in the path, directories included, as oiiotool looks for them.
    Never raises for a malformed pattern (two wildcards, ``%4d``): it is still
    a pattern, and `parse_pattern` says what is wrong with it.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    bool

    Examples
    --------
    >>> is_pattern("a.#.exr"), is_pattern("a.@@@.png"), is_pattern("a.%04d.tif")
    (True, True, True)
    >>> is_pattern("a.0001.exr"), is_pattern("100%.png"), is_pattern("a.%04x.tif")
    (False, False, False)
    """
    return _WILDCARD.search(os.fspath(path)) is not None


def parse_pattern(path: str | os.PathLike[str]) -> SequencePattern | None:
    """Split a sequence pattern around its wildcard; None for a plain path.

    The wildcards are oiiotool's (its "Frame sequences" documentation and
    ``Filesystem::parse_pattern``):

    - ``#`` pads to 4 digits and ``@`` to 1, and a run of them adds up
      (``##`` is 8, ``@@@`` is 3, ``#@@`` is 6). So ``####`` is 16 digits,
      not 4 as in Nuke or fileseq: write ``#``, ``@@@@`` or ``%04d`` for 4;
    - ``%d`` does not pad, ``%0Nd`` pads to N, as printf.

    The whole path is searched, directories included (``shot.#/beauty.exr``
    is a sequence of directories), as oiiotool does. A ``%`` that does not
    start ``%d`` or ``%0Nd`` is an ordinary character (``100%.png``).

    Where warpcli is stricter than oiiotool:

    - one wildcard per path: oiiotool replaces the first and leaves later
      ones in the name as they are (``a.#.b.#.png`` becomes
      ``a.0001.b.#.png``), which is never what was meant;
    - ``%Nd`` without the zero (space padding, ``a.   7.png``) is refused;
    - digits just before the wildcard are part of the name: oiiotool would
      read ``shot2#.exr`` as frame 2 of ``shot#.exr`` and ``a.1-10#.exr``
      as frames 1 to 10; here frames come only from the frame spec (`parse_frames`).

    There is no escape for a literal ``#``, ``@`` or ``%d`` in a file name
    (oiiotool has ``--wildcardoff``); rename the file or link to it.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    SequencePattern or None
        None when the path has no wildcard.

    Raises
    ------
    InputError
        If the path has more than one wildcard, a space-padded ``%Nd``, or
        pads to more than `MAX_PADDING` digits. The message starts with the path.

    Examples
    --------
    >>> parse_pattern("a.#@@.exr").padding, parse_pattern("a.%d.exr").padding
    (6, 0)
    >>> parse_pattern("plate.1001.exr") is None
    True
    """
    text = os.fspath(path)
    found = list(_WILDCARD.finditer(text))
    if not found:
        return None
    if len(found) > 1:
        shown = ", ".join(f"{m.group()} at character {m.start() + 1}" for m in found[:4])
        more = f", ... ({len(found) - 4} more)" if len(found) > 4 else ""
        raise InputError(
            f"{text}: a sequence pattern may hold only one frame-number wildcard, but this one has "
            f"{len(found)} ({shown}{more}); a literal #, @ or %d cannot be part of a sequence's file name"
        )
    m = found[0]
    wildcard = m.group()
    if wildcard.startswith("%"):
        digits = m.group(1)
        if digits and not digits.startswith("0"):
            raise InputError(
                f"{text}: {wildcard} pads frame numbers with spaces; use %0{digits}d to pad with zeros"
            )
        # int() of a few digits only: a thousand-digit width is refused below.
        padding = 0 if not digits else int(digits) if len(digits) <= 10 else MAX_PADDING + 1
    else:
        padding = 4 * wildcard.count("#") + wildcard.count("@")
    if padding > MAX_PADDING:
        raise InputError(
            f"{text}: the wildcard {_cut(wildcard)} pads frame numbers to more than {MAX_PADDING} digits"
        )
    return SequencePattern(text[: m.start()], wildcard, text[m.end() :], padding)


def _cut(text: str) -> str:
    return text if len(text) <= 20 else text[:17] + "..."


def frame_path(pattern: str | os.PathLike[str], frame: int) -> str:
    """The path of one frame of a sequence pattern.

    Parameters
    ----------
    pattern : str or path-like
        A path with one wildcard (see `parse_pattern`).
    frame : int
        Any integer; one wider than the padding is written in full, as printf
        does, and a negative one keeps its sign inside the padding (``#`` and
        -7 give ``-007``, as oiiotool writes it).

    Returns
    -------
    str

    Raises
    ------
    InputError
        If ``pattern`` has no wildcard or a malformed one.
    TypeError
        If ``frame`` is not an integer.

    Examples
    --------
    >>> frame_path("out.#.exr", 42), frame_path("out.@.exr", 42), frame_path("out.%03d.exr", -4)
    ('out.0042.exr', 'out.42.exr', 'out.-04.exr')
    >>> frame_path("out.##.exr", 42)  # each # is 4 digits: ## is 8
    'out.00000042.exr'
    """
    return _require_pattern(pattern).path(frame)


def expand(pattern: str | os.PathLike[str], frames: Iterable[int] | None, option: str = "--frames") -> list[tuple[int, str]]:
    """The frames of a sequence and their paths, in the order given.

    Parameters
    ----------
    pattern : str or path-like
        A path with one wildcard (see `parse_pattern`).
    frames : iterable of int, or None
        The frame numbers, as `parse_frames` returns them. None (no frames
        were given) is an error: a pattern names no file by itself.
    option : str
        How the error for ``frames=None`` names the option that gives frames.

    Returns
    -------
    list of (int, str)
        ``(frame, path)`` for every frame.

    Raises
    ------
    InputError
        If ``pattern`` has no wildcard or a malformed one, or ``frames`` is
        None (the message is `missing_frames_error`'s).
    TypeError
        If a frame is not an integer.

    Examples
    --------
    >>> expand("in.#.png", [1, 2, 10])
    [(1, 'in.0001.png'), (2, 'in.0002.png'), (10, 'in.0010.png')]
    """
    seq = _require_pattern(pattern)
    if frames is None:
        raise missing_frames_error(pattern, option)
    if isinstance(frames, str):
        raise TypeError("frames must be frame numbers; parse a frame spec with parse_frames first")
    return [(int(f), seq.path(f)) for f in frames]


def _require_pattern(pattern: str | os.PathLike[str]) -> SequencePattern:
    seq = parse_pattern(pattern)
    if seq is None:
        raise InputError(
            f"{os.fspath(pattern)}: not an image sequence pattern: it has no frame-number wildcard "
            "(#, @, %d or %0Nd)"
        )
    return seq


def missing_frames_error(pattern: str | os.PathLike[str], option: str = "--frames") -> InputError:
    """The error for a sequence pattern given without frames, for the caller to raise.

    Parameters
    ----------
    pattern : str or path-like
    option : str
        The option that gives the frames, as the message should name it.

    Returns
    -------
    InputError

    Examples
    --------
    >>> print(missing_frames_error("in.#.exr"))
    in.#.exr: image sequence pattern (#) given without frames; add --frames, e.g. --frames 1001-1100
    """
    text = os.fspath(pattern)
    m = _WILDCARD.search(text)
    what = f" ({_cut(m.group())})" if m else ""
    return InputError(
        f"{text}: image sequence pattern{what} given without frames; "
        f"add {option}, e.g. {option} 1001-1100"
    )


def parse_frames(spec: str, option: str = "--frames") -> tuple[int, ...]:
    """Parse a frame spec into its frame numbers, in order.

    The syntax is oiiotool's ``--frames`` (its "Frame sequences"
    documentation and ``Filesystem::enumerate_sequence``): comma-separated
    items, each

    - ``N``: one frame;
    - ``N-M``: N to M inclusive, forwards (``1-5``) or backwards (``5-1``);
    - ``N-MxS``: every S-th frame from N towards M (``1-10x3`` is 1, 4, 7, 10;
      ``10-1x3`` is 10, 7, 4, 1);
    - ``N-MyS``: the complement, the frames ``N-MxS`` skips (``1-5y2`` is 2, 4).

    Frame numbers may be negative (``-5--1``, ``-2-2``). Spaces around items
    are ignored. A frame listed twice is kept once, where it first appears
    (oiiotool would process it twice, writing the same file again).

    Stricter than oiiotool, which reads what it can and ignores the rest
    (``1-5abc`` is 1-5 there, an empty item is frame 1, step 0 is step 1 and a
    negative step counts down): anything but the syntax above is an error,
    the step must be at least 1 (write the range backwards to count down),
    and every item must select at least one frame.

    Parameters
    ----------
    spec : str
        The frame spec: ``"1001-1100"``, ``"1-100x2"``, ``"1,5,10-12"``, ``"7"``.
    option : str
        How messages name the spec's source.

    Returns
    -------
    tuple of int
        At least one frame, at most `MAX_FRAMES`.

    Raises
    ------
    InputError
        If the spec is empty or malformed, a step is below 1, a frame number
        is beyond +-`FRAME_LIMIT`, an item selects no frame, or the spec
        selects more than `MAX_FRAMES` frames (checked before any frame is
        generated). The message starts with ``option`` and the spec.

    Examples
    --------
    >>> parse_frames("1-5"), parse_frames("5-1x2"), parse_frames("1-5y2")
    ((1, 2, 3, 4, 5), (5, 3, 1), (2, 4))
    >>> parse_frames("1,5,10-12"), parse_frames("-2-1"), parse_frames("1-4,3-6")
    ((1, 5, 10, 11, 12), (-2, -1, 0, 1), (1, 2, 3, 4, 5, 6))
    """
    if not isinstance(spec, str):
        raise TypeError(f"a frame spec must be a string, not {type(spec).__name__}")
    where = f"{option} {_quote(spec)}"
    if not spec.strip():
        raise InputError(f"{where}: no frames given; expected frames such as 1001-1100, 1-100x2 or 1,5,10-12")
    items = []
    total = 0
    for raw in spec.split(","):
        item = raw.strip()
        if not item:
            raise InputError(f"{where}: empty item between commas")
        m = _ITEM.fullmatch(item)
        if m is None:
            raise InputError(
                f"{where}: {_quote(item)} is not a frame, a range or a stepped range "
                "(expected N, N-M, N-MxS or N-MyS with whole numbers, e.g. 1001-1100x2)"
            )
        first = _frame_number(m.group(1), where)
        last = first if m.group(2) is None else _frame_number(m.group(2), where)
        kind = m.group(3) or "x"
        step = 1
        if m.group(4) is not None:
            digits = m.group(4).lstrip("-")
            # A step beyond any range selects the first frame alone; its size
            # only needs bounding, not parsing in full.
            step = int(digits) if len(digits) <= 10 else FRAME_LIMIT + 1
            step = -step if m.group(4).startswith("-") else step
            if step < 1:
                raise InputError(
                    f"{where}: the step in {_quote(item)} must be at least 1, got {_cut(m.group(4))}"
                    + (f" (to count down, write the range backwards: {last}-{first}{kind}{_cut(digits)})" if step < 0 else "")
                )
        span = abs(last - first) + 1
        taken = (span - 1) // step + 1  # frames first, first +- step, ... up to last
        count = taken if kind == "x" else span - taken
        if count == 0:
            raise InputError(f"{where}: {_quote(item)} selects no frames")
        total += count
        if total > MAX_FRAMES:
            raise InputError(
                f"{where}: selects more than {MAX_FRAMES:,} frames"
                + (f" ({_quote(item)} alone selects {count:,})" if count > MAX_FRAMES else "")
            )
        items.append((first, last, step, kind))
    frames: dict[int, None] = {}  # insertion-ordered set
    for first, last, step, kind in items:
        sign = 1 if last >= first else -1
        if kind == "x":
            frames.update(dict.fromkeys(range(first, last + sign, sign * step)))
        else:
            frames.update(dict.fromkeys(f for f in range(first, last + sign, sign) if (f - first) % step))
    return tuple(frames)


def _frame_number(digits: str, where: str) -> int:
    # Length first: int() of thousands of digits is slow, then refused.
    if len(digits.lstrip("-")) > 10 or abs(int(digits)) > FRAME_LIMIT:
        raise InputError(
            f"{where}: frame {_cut(digits)} is out of range (frame numbers must be within +-{FRAME_LIMIT}, as in oiiotool)"
        )
    return int(digits)


def _quote(text: str) -> str:
    """A piece of a spec for a message: quoted, and cut to 40 characters."""
    return repr(text if len(text) <= 40 else text[:37] + "...")


def find_frames(pattern: str | os.PathLike[str]) -> tuple[int, ...]:
    """The frames of a sequence that exist on disk, in increasing order.

    A file counts when its name is exactly what the pattern gives for its
    frame number: with ``#`` (4 digits) ``a.0007.exr`` is frame 7 but
    ``a.7.exr`` and ``a.00007.exr`` are not frames of it; a number wider than
    the padding counts (``a.12345.exr``). Only regular files (or links to
    them) count, and frame numbers within +-`FRAME_LIMIT`.

    Parameters
    ----------
    pattern : str or path-like
        A path with one wildcard (see `parse_pattern`).

    Returns
    -------
    tuple of int
        At most `MAX_FRAMES`; empty when no file matches.

    Raises
    ------
    InputError
        If ``pattern`` has no wildcard or a malformed one, or more than
        `MAX_FRAMES` files match.
    """
    seq = _require_pattern(pattern)
    found = _scan(seq)
    if len(found) > MAX_FRAMES:
        raise InputError(f"{seq.pattern}: more than {MAX_FRAMES:,} frames on disk; choose some with --frames")
    return found


def _scan(seq: SequencePattern, most: int = MAX_FRAMES) -> tuple[int, ...]:
    """The frames of ``seq`` on disk, sorted; stops after ``most`` + 1."""
    found: set[int] = set()
    head, tail = len(seq.prefix), len(seq.suffix)
    for name in glob.iglob(glob.escape(seq.prefix) + "*" + glob.escape(seq.suffix)):
        digits = name[head : len(name) - tail]
        if _NUMBER.fullmatch(digits) is None or len(digits.lstrip("-")) > 10:
            continue
        frame = int(digits)
        if abs(frame) > FRAME_LIMIT or seq.path(frame) != name or not os.path.isfile(name):
            continue
        found.add(frame)
        if len(found) > most:
            break
    return tuple(sorted(found))


_NUMBER = re.compile(r"-?[0-9]+")


def nuke_reading(pattern: str | os.PathLike[str]) -> SequencePattern | None:
    """The pattern as Nuke, Houdini and fileseq read it, where that differs from oiiotool's.

    There a run of ``#`` pads to one digit per ``#`` (``####`` is 4 digits, ``#``
    is unpadded); in oiiotool's reading, warpcli's, each ``#`` is 4 digits.

    Parameters
    ----------
    pattern : str or path-like

    Returns
    -------
    SequencePattern or None
        None when the pattern has no wildcard made of ``#`` alone.

    Raises
    ------
    InputError
        If the pattern is malformed (`parse_pattern`).

    Examples
    --------
    >>> nuke_reading("shot.####.exr").path(1001), parse_pattern("shot.####.exr").path(1001)
    ('shot.1001.exr', 'shot.0000000000001001.exr')
    >>> nuke_reading("shot.%04d.exr") is None
    True
    """
    seq = parse_pattern(pattern)
    if seq is None or set(seq.wildcard) != {"#"}:
        return None
    return SequencePattern(seq.prefix, seq.wildcard, seq.suffix, len(seq.wildcard))


def other_reading_hint(pattern: str | os.PathLike[str], frames: Iterable[int] | None = None) -> str | None:
    """One line for a pattern that names no existing file when Nuke's reading of ``#`` would.

    Parameters
    ----------
    pattern : str or path-like
    frames : iterable of int, or None
        The frames asked for; None: any frame on disk.

    Returns
    -------
    str or None
        The message, starting with the pattern; None when a frame exists as
        the pattern reads, or none would in Nuke's reading either.

    Raises
    ------
    InputError
        If the pattern is malformed (`parse_pattern`).
    """
    seq = _require_pattern(pattern)
    other = nuke_reading(pattern)
    if other is None or other.padding == seq.padding:
        return None
    if frames is None:
        ours, theirs = _scan(seq, 0), _scan(other, 0)
    else:
        wanted = list(frames)
        ours = [f for f in wanted if os.path.isfile(seq.path(f))]
        theirs = [f for f in wanted if os.path.isfile(other.path(f))]
    if ours or not theirs:
        return None
    example = theirs[0]
    simple = f"{seq.prefix}%0{other.padding}d{seq.suffix}" if other.padding > 1 else f"{seq.prefix}%d{seq.suffix}"
    digits = "digits" if other.padding > 1 else "digit, unpadded"
    return (
        f"{seq.pattern}: no frame found: each # is 4 digits here, as in oiiotool "
        f"({os.path.basename(seq.path(example))}), but {os.path.basename(other.path(example))} exists, as Nuke "
        f"reads {seq.wildcard}; for {other.padding} {digits} write {simple}"
    )


def describe_frames(frames: Iterable[int]) -> str:
    """Frames as a frame spec of ranges, for a message: ``1-10,12-24``.

    Examples
    --------
    >>> describe_frames([1, 2, 3, 5, 7, 8])
    '1-3,5,7-8'
    """
    ordered = sorted(set(frames))
    pieces = []
    k = 0
    while k < len(ordered):
        j = k
        while j + 1 < len(ordered) and ordered[j + 1] == ordered[j] + 1:
            j += 1
        pieces.append(str(ordered[k]) if j == k else f"{ordered[k]}-{ordered[j]}")
        k = j + 1
    return ",".join(pieces)


def frames_from_disk(pattern: str | os.PathLike[str], option: str = "--frames") -> tuple[tuple[int, ...], str]:
    """The frames of a sequence given without a frame spec: those on disk, and a line saying which.

    Parameters
    ----------
    pattern : str or path-like
        The input pattern.
    option : str
        The option that gives frames, as messages name it.

    Returns
    -------
    frames : tuple of int
        `find_frames`: at least one.
    message : str
        How many were taken, their ranges and the gaps between them, for the log.

    Raises
    ------
    InputError
        If no frame exists (with `other_reading_hint`'s advice when Nuke's
        reading of ``#`` finds some).

    Examples
    --------
    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> for f in (1, 2, 3, 5):
    ...     open(os.path.join(d, f"a.{f:04d}.png"), "w").close()
    >>> frames, message = frames_from_disk(os.path.join(d, "a.#.png"))
    >>> frames, message.split(": ", 1)[1]
    ((1, 2, 3, 5), 'no --frames given: taking the 4 frames on disk, 1-3,5 (1 missing between them: 4)')
    """
    text = os.fspath(pattern)
    frames = find_frames(text)
    if not frames:
        hint = other_reading_hint(text)
        if hint is not None:
            raise InputError(hint)
        raise InputError(f"{text}: no frame of this sequence on disk, and no {option} given")
    missing = frames[-1] - frames[0] + 1 - len(frames)
    gaps = ""
    if missing:
        holes = sorted(set(range(frames[0], frames[-1] + 1)) - set(frames)) if missing <= 10_000 else []
        shown = describe_frames(holes) if holes else "..."
        gaps = f" ({missing} missing between them: {_cut_text(shown, 60)})"
    many = "the frame" if len(frames) == 1 else f"the {len(frames)} frames"
    return frames, f"{text}: no {option} given: taking {many} on disk, {_cut_text(describe_frames(frames), 60)}{gaps}"


def _cut_text(text: str, most: int) -> str:
    return text if len(text) <= most else text[: most - 3] + "..."


def output_reading_warning(pattern: str | os.PathLike[str], frame: int) -> str | None:
    """A line for an output pattern whose ``##``... would be read otherwise in Nuke (None for any other).

    A run of two or more ``#`` is 4 digits per ``#`` here (``####``: 16), where
    Nuke writes one digit per ``#``: worth saying before a shot is written
    under names no compositor expects.

    Examples
    --------
    >>> print(output_reading_warning("out.####.exr", 1001))
    out.####.exr: each # is 4 digits, as in oiiotool, so frames are written as out.0000000000001001.exr; for 4 digits write out.%04d.exr
    >>> output_reading_warning("out.#.exr", 1001) is None
    True
    """
    seq = _require_pattern(pattern)
    other = nuke_reading(pattern)
    if other is None or len(seq.wildcard) < 2:
        return None
    return (
        f"{seq.pattern}: each # is 4 digits, as in oiiotool, so frames are written as "
        f"{os.path.basename(seq.path(frame))}; for {other.padding} digits write {seq.prefix}%0{other.padding}d{seq.suffix}"
    )
