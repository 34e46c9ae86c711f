"""One exception tree for warpcli; the CLI maps it to exit codes."""

from __future__ import annotations


class WarpError(Exception):
    """Base of every error warpcli raises on purpose.

    ``exit_code`` is what the command-line tool exits with: 1 for a failure
    while processing, 2 for bad input or usage.
    """

    exit_code = 1


class InputError(WarpError):
    """The user's input is unusable (exit status 2)."""

    exit_code = 2


class PolygonError(InputError, ValueError):
    """A polygon file is missing, malformed, or describes an invalid polygon."""


class ImageIOError(WarpError, OSError):
    """Reading or writing an image failed."""


class ImageInputError(ImageIOError, InputError):
    """An input image, or an output path, is unusable (exit status 2)."""


class MeshingError(WarpError):
    """The polygon could not be meshed."""


class FoldOverError(WarpError):
    """A discrete map is not one-to-one, so warping would fold the image."""
