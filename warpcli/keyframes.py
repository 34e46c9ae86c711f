"""Animated polygons (paper section 6): keyframed polygon files, interpolated linearly frame by frame."""

from __future__ import annotations

import bisect
import itertools
import json
import math
import numbers
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .errors import InputError, PolygonError
from .files import read_small_file
from .polygon import MAX_FILE_BYTES, Polygon, read_polygon
from .polygon.formats import parse_int, parse_json, points_of
from .polygon.partition import Cages, Partition, cages_of, is_partition_document, partition_of
from .polygon.messages import short_value
from .sequence import FRAME_LIMIT

__all__ = ["Keyframes", "read_animated", "read_keyframes", "read_polygon_at", "read_shape_at"]

# A keyframe's key: a whole number, optionally negative, in ASCII digits
# ("1001", "-5", "0042"). Not "+5", "1.0", "1e3", " 7" or other scripts' digits.
_KEY = re.compile(r"-?[0-9]+")

# What makes a JSON object a plain, labelme or GeoJSON polygon file (as
# polygon.formats.points_of decides); beside "frames" it would leave it ambiguous.
_POLYGON_MEMBERS = ("points", "shapes")
_GEOJSON_TYPES = ("Polygon", "Feature", "FeatureCollection", "MultiPolygon")


# eq=False: equality by identity. Comparing the polygons field by field would
# compare arrays, which has no single truth value; use `same` for the shapes.
@dataclass(frozen=True, eq=False)
class Keyframes:
    """A polygon animated by keyframes: linear between them, held before the first and after the last.

    Every keyframe has the same number of vertices, in corresponding order,
    running the same way round (the same sign of `Polygon.signed_area`):
    vertex ``i`` moves in a straight line from keyframe to keyframe. Between
    keyframes ``a < b`` the polygon at frame ``f`` is
    ``P_a + (f - a) / (b - a) * (P_b - P_a)``; at a keyframe it is that
    keyframe, exactly.

    Parameters
    ----------
    frames : sequence of int
        The keyframes' frame numbers, strictly increasing.
    polygons : sequence of Polygon or Partition
        The polygon at each keyframe; or the cage mesh
        (`warpcli.polygon.partition.Partition`, the same faces in every
        keyframe: its vertices move, `at` gives a `Partition`).
    name : str
        How error messages refer to the animation, usually its file name.

    Raises
    ------
    PolygonError
        If there is no keyframe, the frames and polygons differ in number, the
        frames do not increase, two keyframes differ in vertex count, or two
        consecutive keyframes run opposite ways round (somewhere between them
        the polygon would have zero area).

    Examples
    --------
    >>> a = Polygon([[0, 0], [10, 0], [0, 10]])
    >>> b = Polygon([[0, 0], [20, 0], [0, 20]])
    >>> kf = Keyframes((1, 11), (a, b), name="tri.json")
    >>> kf.at(6).points.tolist()
    [[0.0, 0.0], [15.0, 0.0], [0.0, 15.0]]
    >>> kf.at(-100) is a, kf.at(11) is b, kf.same(11, 500), kf.same(5, 6)
    (True, True, True, False)
    """

    frames: tuple[int, ...]
    polygons: tuple[Polygon, ...]
    name: str = field(default="polygon")

    def __post_init__(self) -> None:
        for f in self.frames:
            if isinstance(f, bool) or not isinstance(f, numbers.Integral):
                raise TypeError(f"keyframe numbers must be integers, not {type(f).__name__}")
        frames = tuple(int(f) for f in self.frames)
        polygons = tuple(self.polygons)
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "polygons", polygons)
        if not frames:
            raise PolygonError(f"{self.name}: no keyframes")
        if len(frames) != len(polygons):
            raise PolygonError(f"{self.name}: {len(frames)} keyframe numbers but {len(polygons)} polygons")
        for f in frames:
            if abs(f) > FRAME_LIMIT:
                raise PolygonError(f"{self.name}: keyframe {f} is out of range (frame numbers must be within +-{FRAME_LIMIT})")
        for a, b in itertools.pairwise(frames):
            if not a < b:
                raise PolygonError(f"{self.name}: keyframes must increase, but {b} follows {a}")
        first = polygons[0]
        for f, poly in zip(frames[1:], polygons[1:]):
            # A cage mesh (`Partition`) moves its vertices; its faces stay. Several
            # cages (`Cages`) keep their number, vertex counts and faces.
            if (
                isinstance(poly, Partition) != isinstance(first, Partition)
                or isinstance(poly, Cages) != isinstance(first, Cages)
                or (isinstance(first, Partition) and poly.faces != first.faces)
                or (isinstance(first, Cages) and poly.structure != first.structure)
            ):
                raise PolygonError(
                    f"{self.name}: keyframe {f} has other faces than keyframe {frames[0]}; every keyframe of a "
                    "cage mesh needs the same faces (and a polygon file only polygons)"
                )
            if poly.n != first.n:
                raise PolygonError(
                    f"{self.name}: keyframe {f} has {poly.n} vertices but keyframe {frames[0]} has {first.n}; "
                    "every keyframe needs the same vertices, in the same order"
                )
        for (fa, pa), (fb, pb) in itertools.pairwise(zip(frames, polygons)):
            # Linear motion from one orientation to the other passes through
            # zero signed area: some frame between would be no polygon at all.
            if _turns(pa) != _turns(pb):
                what = "keyframe"
                if isinstance(pa, Cages):
                    k = next(i for i, (x, y) in enumerate(zip(_turns(pa), _turns(pb))) if x != y)
                    pa, pb, what = pa.shapes[k], pb.shapes[k], f"cage {k} of keyframe"
                raise PolygonError(
                    f"{self.name}: {what} {fb} runs {_turn(pb)} but {what} {fa} runs {_turn(pa)} "
                    "(are its vertices listed in reverse?); every keyframe must list corresponding "
                    "vertices the same way round"
                )

    @classmethod
    def still(cls, polygon: Polygon) -> Keyframes:
        """A polygon that does not move: one keyframe, at frame 0, held at every frame.

        Parameters
        ----------
        polygon : Polygon

        Returns
        -------
        Keyframes
            Named as ``polygon`` is.
        """
        return cls((0,), (polygon,), name=polygon.name)

    @property
    def n(self) -> int:
        """Number of vertices (the same in every keyframe)."""
        return self.polygons[0].n

    @property
    def animated(self) -> bool:
        """Whether the polygon moves at all: two keyframes differ."""
        first = self.polygons[0].points
        return any(not np.array_equal(p.points, first) for p in self.polygons[1:])

    def at(self, frame: float) -> Polygon:
        """The polygon at ``frame``.

        At a keyframe, before the first, after the last and between two equal
        keyframes, this is the keyframe's own `Polygon` object (the same
        object for every frame of a hold). Between keyframes it is a new `Polygon`, validated as usual: a
        linear blend of two simple polygons may cross itself, or come too
        close to itself, even though both keyframes are fine.

        Parameters
        ----------
        frame : int or float
            Any frame number; a fractional one (a sub-frame, for motion blur)
            is interpolated the same way.

        Returns
        -------
        Polygon
            Named ``"<file> (keyframe K)"`` or
            ``"<file> (frame F, between keyframes A and B)"``, so its errors
            say where they come from.

        Raises
        ------
        PolygonError
            If the interpolated polygon is invalid (see `Polygon`); the
            message names the file, the frame and the two keyframes.
        InputError
            If ``frame`` is not finite.
        TypeError
            If ``frame`` is not a real number.
        """
        i, t = self._locate(frame)
        if t == 0.0 or np.array_equal(self.polygons[i].points, self.polygons[i + 1].points):
            return self.polygons[i]
        a, b = self.frames[i], self.frames[i + 1]
        name = f"{self.name} (frame {_fmt_frame(frame)}, between keyframes {a} and {b})"
        if isinstance(self.polygons[i], (Partition, Cages)):
            return self.polygons[i].moved(self._blend(i, t), name)
        return Polygon(self._blend(i, t), name=name)

    def same(self, a: float, b: float) -> bool:
        """Whether the polygon is exactly the same at frames ``a`` and ``b``.

        True within a hold (before the first keyframe, after the last, or
        between two equal keyframes) and for equal polygons anywhere (a
        shape that moves away and comes back to the same vertices); False as
        soon as any vertex moved. A caller that warps a sequence can keep a
        map computed for frame ``a`` for every later frame ``b`` with
        ``same(a, b)``. Validates nothing: ``at`` does.

        Parameters
        ----------
        a, b : int or float
            Frame numbers.

        Returns
        -------
        bool

        Raises
        ------
        InputError
            If a frame is not finite.
        TypeError
            If a frame is not a real number.
        """
        (i, s), (j, t) = self._locate(a), self._locate(b)
        if (i, s) == (j, t):
            return True
        return bool(np.array_equal(self._vertices(i, s), self._vertices(j, t)))

    def _locate(self, frame: float) -> tuple[int, float]:
        """(i, t): the polygon at ``frame`` is keyframe i blended a fraction t towards keyframe i + 1."""
        if isinstance(frame, bool) or not isinstance(frame, numbers.Real):
            raise TypeError(f"a frame number must be a real number, not {type(frame).__name__}")
        # (math.isfinite would overflow on a huge int; an int is finite.)
        if not isinstance(frame, numbers.Integral) and not math.isfinite(frame):
            raise InputError(f"{self.name}: frame {frame} is not a finite number")
        keys = self.frames
        if frame <= keys[0]:
            return 0, 0.0
        if frame >= keys[-1]:
            return len(keys) - 1, 0.0
        i = bisect.bisect_right(keys, frame) - 1
        if frame == keys[i]:
            return i, 0.0
        # Frames are within +-2**31 (sequence.FRAME_LIMIT), so exact as floats.
        return i, (float(frame) - keys[i]) / (keys[i + 1] - keys[i])

    def _blend(self, i: int, t: float) -> NDArray[np.float64]:
        p = self.polygons[i].points
        q = self.polygons[i + 1].points
        # p + t (q - p), not (1 - t) p + t q: between equal keyframes this is p
        # exactly, so `same` sees a hold as one polygon.
        return p + t * (q - p)

    def _vertices(self, i: int, t: float) -> NDArray[np.float64]:
        return self.polygons[i].points if t == 0.0 else self._blend(i, t)


def _turns(poly: Polygon | Partition | Cages) -> tuple[bool, ...]:
    """Which way round the shape runs: each cage's, for several."""
    return poly.turns if isinstance(poly, Cages) else (poly.signed_area > 0,)


def _turn(poly: Polygon) -> str:
    # Positive shoelace area is clockwise on screen (y down), see Polygon.signed_area.
    return "clockwise" if poly.signed_area > 0 else "counter-clockwise"


def _fmt_frame(frame: float) -> str:
    return str(int(frame)) if float(frame).is_integer() else repr(float(frame))


def read_keyframes(path: str | os.PathLike[str], label: str | None = None) -> Keyframes | None:
    """Read a keyframed polygon file; None if it is a plain polygon file.

    A keyframed file is a JSON object with a ``"frames"`` member mapping
    frame numbers to polygons::

        {"frames": {"1001": [[10, 10], [90, 12], [50, 80]],
                    "1050": [[14, 10], [95, 20], [48, 84]]}}

    - Keys are whole frame numbers written in ASCII digits, optionally
      negative (``"-5"``, ``"0042"``), within +-`sequence.FRAME_LIMIT`;
      ``"1.5"``, ``"+5"``, ``"1e3"`` or ``" 7"`` are refused, and so are two
      keys naming one frame (``"7"`` and ``"007"``, or ``"7"`` twice).
    - Values are anything `polygon.read_polygon` reads as a file's content:
      an array of ``[x, y]`` pairs, ``{"points": ...}``, a labelme object or
      GeoJSON (``label`` chooses among several polygons in each).
    - Every keyframe has the same number of vertices, listed the same way
      round; each keyframe is validated as a `Polygon`. Frames between
      keyframes are validated when `Keyframes.at` makes them.
    - Other members of the top object are ignored; ``"frames"`` beside a
      polygon of its own (``"points"``, ``"shapes"``, GeoJSON) is refused.

    The file is read with `polygon.read_polygon`'s safeguards: only regular
    files of at most `polygon.MAX_FILE_BYTES`, UTF-8 JSON, bounded nesting and
    integer size.

    Parameters
    ----------
    path : path-like
        The polygon file.
    label : str or None
        Which polygon to take from each keyframe holding several.

    Returns
    -------
    Keyframes or None
        None when the file holds no ``"frames"`` member (read it with
        `polygon.read_polygon`, or use `read_animated`).

    Raises
    ------
    PolygonError
        If the file cannot be read or parsed, or its keyframes are invalid.
        The message is one line and starts with the file's name.
    """
    name = os.fspath(path)
    doc, text = _load(name)
    if not (isinstance(doc, dict) and "frames" in doc):
        return None
    return _keyframes(doc, text, name, label)


def read_animated(path: str | os.PathLike[str], label: str | None = None) -> Keyframes:
    """Read any polygon file as an animation: a plain polygon is a `Keyframes.still`.

    Reads the file once; the same as ``read_keyframes(path, label)`` for a
    keyframed file and ``Keyframes.still(read_polygon(path, label))`` for
    any other.

    Parameters
    ----------
    path : path-like
    label : str or None

    Returns
    -------
    Keyframes

    Raises
    ------
    PolygonError
        As `read_keyframes` and `polygon.read_polygon`.
    """
    name = os.fspath(path)
    doc, text = _load(name)
    if isinstance(doc, dict) and "frames" in doc:
        return _keyframes(doc, text, name, label)
    return Keyframes.still(_polygon(doc, name, label))


def _load(name: str) -> tuple[object, str]:
    raw = read_small_file(name, "polygon file", PolygonError, max_bytes=MAX_FILE_BYTES)
    try:
        text = raw.decode("utf-8-sig")  # as read_polygon: a BOM is allowed
    except UnicodeDecodeError as err:
        raise PolygonError(f"{name}: not a JSON text file (invalid UTF-8 at byte {err.start})") from err
    return parse_json(text, name), text


def _polygon(doc: object, name: str, label: str | None) -> Polygon | Partition | Cages:
    try:
        cages = cages_of(doc, name)
        if cages is not None:
            return cages
        mesh = partition_of(doc, name, label)
        return mesh if mesh is not None else Polygon(points_of(doc, name, label), name=name)
    except RecursionError as err:  # as read_polygon: arrays nested ~1000 deep
        raise PolygonError(f"{name}: invalid polygon file: arrays nested too deeply") from err


def _keyframes(doc: dict, text: str, name: str, label: str | None) -> Keyframes:
    clash = [k for k in _POLYGON_MEMBERS if k in doc]
    if clash or doc.get("type") in _GEOJSON_TYPES:
        what = f'"{clash[0]}"' if clash else f'GeoJSON "type" {short_value(doc.get("type"))}'
        raise PolygonError(f'{name}: has both "frames" (keyframes) and {what} (a single polygon); keep one')
    table = doc["frames"]
    if not isinstance(table, dict):
        raise PolygonError(
            f'{name}: "frames" must be an object mapping frame numbers to polygons, '
            f'e.g. {{"1001": [[x, y], ...]}}, not {short_value(table)}'
        )
    if not table:
        raise PolygonError(f'{name}: "frames" holds no keyframes')
    _check_repeated_keys(text, name)
    keyed: dict[int, str] = {}
    for key in table:
        frame = _frame_of(key, name)
        if frame in keyed:
            raise PolygonError(f"{name}: keyframes {short_value(keyed[frame])} and {short_value(key)} are both frame {frame}")
        keyed[frame] = key
    frames = sorted(keyed)
    polygons = [_polygon(table[keyed[f]], f"{name} (keyframe {f})", label) for f in frames]
    return Keyframes(tuple(frames), tuple(polygons), name=name)


def _frame_of(key: str, name: str) -> int:
    if _KEY.fullmatch(key) is None:
        raise PolygonError(
            f'{name}: keyframe {short_value(key)} is not a whole frame number; the keys of "frames" must be '
            'integers such as "1001" or "-5"'
        )
    # Length first: int() of thousands of digits is slow, then refused.
    if len(key.lstrip("-")) > 10 or abs(int(key)) > FRAME_LIMIT:
        raise PolygonError(
            f"{name}: keyframe {short_value(key)} is out of range (frame numbers must be within +-{FRAME_LIMIT})"
        )
    return int(key)


class _Members(dict):
    """A parsed JSON object that remembers its first repeated key."""

    repeated: str | None = None


def _members(pairs: Sequence[tuple[str, object]]) -> _Members:
    obj = _Members(pairs)
    if len(obj) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                obj.repeated = key
                break
            seen.add(key)
    return obj


def _check_repeated_keys(text: str, name: str) -> None:
    """Refuse a key repeated in the top object or in "frames": json.loads would keep the last silently.

    A second parse, of a text the first one accepted, made only for keyframed
    files: json.loads has no other way to tell.
    """
    doc = json.loads(text, object_pairs_hook=_members, parse_int=parse_int)
    if doc.repeated == "frames":
        raise PolygonError(f'{name}: "frames" appears twice')
    repeated = doc["frames"].repeated
    if repeated is not None:
        raise PolygonError(f'{name}: keyframe {short_value(repeated)} appears twice in "frames"')


def read_polygon_at(path: str | os.PathLike[str], label: str | None = None, frame: int | None = None) -> Polygon:
    """The polygon of a polygon file for one image: a plain file's, or a keyframed file's at ``frame``.

    Parameters
    ----------
    path : path-like
    label : str or None
        Which polygon of a file holding several (in every keyframe).
    frame : int or None
        The frame of a keyframed file (`Keyframes.at`: linear between
        keyframes, held outside them); a plain file's polygon is the same at
        every frame. None: the file must be a plain polygon file.

    Returns
    -------
    Polygon
        For a plain file, exactly `polygon.read_polygon`'s.

    Raises
    ------
    PolygonError
        As `polygon.read_polygon` and `read_keyframes`; for a keyframed file
        without ``frame``, a message naming the fix (``--frame N``).

    Examples
    --------
    >>> import json, os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "anim.json")
    >>> with open(path, "w") as fh:
    ...     json.dump({"frames": {"1": [[0, 0], [10, 0], [0, 10]], "11": [[0, 0], [20, 0], [0, 20]]}}, fh)
    >>> read_polygon_at(path, frame=6).points.tolist()
    [[0.0, 0.0], [15.0, 0.0], [0.0, 15.0]]
    >>> read_polygon_at(path)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    warpcli.errors.PolygonError: ...anim.json: holds keyframes (frames 1 to 11), not one polygon: choose one frame with --frame N (or warp an image sequence with --frames)
    """
    name = os.fspath(path)
    if frame is None:
        try:
            return read_polygon(name, label)
        except PolygonError:
            try:
                keys = read_keyframes(name, label)
            except PolygonError:
                keys = None
            if keys is None:
                raise
        raise PolygonError(
            f"{name}: holds keyframes (frames {_fmt_frame(keys.frames[0])} to {_fmt_frame(keys.frames[-1])}), "
            "not one polygon: choose one frame with --frame N (or warp an image sequence with --frames)"
        )
    if isinstance(frame, bool) or not isinstance(frame, numbers.Integral):
        raise TypeError(f"a frame number must be an integer, not {type(frame).__name__}")
    keys = read_keyframes(name, label)
    return read_polygon(name, label) if keys is None else keys.at(int(frame))


def read_shape_at(
    path: str | os.PathLike[str], label: str | None = None, frame: int | None = None
) -> Polygon | Partition:
    """`read_polygon_at`, where the file may also hold a cage mesh (or keyframes of one).

    A cage mesh (`warpcli.polygon.partition.read_shape`: ``"faces"``, or a
    labelme or GeoJSON file with several polygons and no ``label``) comes back
    as a `Partition`, a keyframed one at ``frame`` (its vertices blended,
    its faces kept); any other file exactly as `read_polygon_at` reads it.

    Raises
    ------
    PolygonError
        As `read_polygon_at`, and for invalid cage meshes.
    """
    name = os.fspath(path)
    try:
        doc, text = _load(name)
    except PolygonError:
        return read_polygon_at(name, label, frame)  # it says why, as it always did
    if isinstance(doc, dict) and "frames" in doc and isinstance(doc["frames"], dict):
        values = list(doc["frames"].values())
        if values and any(is_partition_document(v, label) for v in values):
            keys = _keyframes(doc, text, name, label)
            if frame is None:
                raise PolygonError(
                    f"{name}: holds keyframes (frames {_fmt_frame(keys.frames[0])} to {_fmt_frame(keys.frames[-1])}), "
                    "not one cage mesh: choose one frame with --frame N (or warp an image sequence with --frames)"
                )
            if isinstance(frame, bool) or not isinstance(frame, numbers.Integral):
                raise TypeError(f"a frame number must be an integer, not {type(frame).__name__}")
            return keys.at(int(frame))
    elif is_partition_document(doc, label):
        mesh = partition_of(doc, name, label)
        assert mesh is not None
        return mesh
    return read_polygon_at(name, label, frame)
