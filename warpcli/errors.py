"""One exception tree for warpcli. The CLI alone decides exit codes (2 for `InputError`, 1 otherwise)."""

from __future__ import annotations


class WarpError(Exception):
    """Base of every error warpcli raises on purpose."""


class InputError(WarpError, ValueError):
    """Bad input or bad arguments: the caller can fix it (the CLI exits with 2).

    Every InputError is a `ValueError`; those about files are also `OSError`s
    (`ImageInputError`).
    """


class PolygonError(InputError):
    """A polygon file is missing, malformed, or describes an invalid polygon."""


class ImageIOError(WarpError, OSError):
    """Reading or writing an image failed."""


class ImageInputError(ImageIOError, InputError):
    """An input image, or an output path, is unusable."""


class MeshingError(WarpError):
    """The polygon could not be meshed."""


class FoldOverError(WarpError):
    """A map is not one-to-one, so warping would fold the image."""


def naming(err: WarpError, name: str) -> WarpError:
    """``err`` with ``name`` (the file it is about) in front, unless its message names it already.

    A check made deep inside (a background with 3 values for a 1-channel
    image) does not know which file of a batch or sequence it is about.

    >>> str(naming(InputError("background has 3 values"), "f.2.png"))
    'f.2.png: background has 3 values'
    """
    if name in str(err):
        return err
    return type(err)(f"{name}: {err}")
