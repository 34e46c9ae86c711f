"""How values from polygon files and coordinates are written in one-line messages."""

from __future__ import annotations

import json

__all__ = ["LongInteger", "format_below", "format_number", "format_point", "one_line", "short_value"]


class LongInteger:
    """A JSON integer too long for int() (Python refuses more than 4300 digits).

    The JSON reader (`formats.parse_int`) leaves one in place of such a
    literal; `Polygon` refuses it as out of range and `short_value` names it.
    It lives here, below both, because its one use is to be named in a
    message.

    Parameters
    ----------
    text : str
        The literal's digits, with an optional minus sign.

    Attributes
    ----------
    digits : int
        How many digits the literal has.
    """

    def __init__(self, text: str) -> None:
        self.digits = len(text.lstrip("-"))

    def __repr__(self) -> str:
        return f"<a {self.digits}-digit integer>"


def format_point(p) -> str:
    """A point as ``(x, y)``, each coordinate as `format_number` writes it.

    Parameters
    ----------
    p : (2,) array_like of float

    Returns
    -------
    str

    Examples
    --------
    >>> format_point([2, 2 / 3])
    '(2.0, 0.666667)'
    """
    return f"({format_number(p[0])}, {format_number(p[1])})"


def format_number(v: float) -> str:
    """Six significant digits, always with a decimal point or exponent: 2.0, 0.666667, 1e+08.

    Parameters
    ----------
    v : float

    Returns
    -------
    str
    """
    text = f"{float(v):.6g}"
    return text if any(ch in text for ch in ".en") else text + ".0"


def format_below(v: float, limit: float) -> str:
    """``v`` (< ``limit``) with enough digits to show that it is below ``limit``: 0.000999999, not 0.001.

    Parameters
    ----------
    v : float
        The value, less than ``limit``.
    limit : float

    Returns
    -------
    str

    Examples
    --------
    >>> format_below(0.000999999, 1e-3)
    '0.000999999'
    """
    for digits in (6, 9, 12, 17):
        text = f"{float(v):.{digits}g}"
        if float(text) < limit:
            break
    return text if any(ch in text for ch in ".en") else text + ".0"


def short_value(value: object) -> str:
    """A value from a file in at most 40 characters, on one line (JSON where it can be).

    Parameters
    ----------
    value : object
        A value as `json.loads` returns it (or a `LongInteger`).

    Returns
    -------
    str
        Cut to 37 characters and ``...`` if longer than 40.

    Examples
    --------
    >>> short_value([1, "a"]), short_value(LongInteger("9" * 5000))
    ('[1, "a"]', 'an integer of 5000 digits')
    """
    if isinstance(value, float):
        text = repr(value)
    elif isinstance(value, LongInteger):
        text = f"an integer of {value.digits} digits"
    else:
        try:
            text = json.dumps(value, default=repr)
        except (ValueError, RecursionError):  # an int of more digits than str() allows; nesting
            text = f"<{type(value).__name__}>"
    return text if len(text) <= 40 else text[:37] + "..."


def one_line(text: str) -> str:
    """``text`` with every run of white space (newlines too) made one space.

    Parameters
    ----------
    text : str

    Returns
    -------
    str
    """
    return " ".join(text.split())
