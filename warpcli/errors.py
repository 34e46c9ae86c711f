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
