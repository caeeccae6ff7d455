"""Numbers from text and from parsed documents, by value: decimal ASCII only, never a boolean.

Python's ``float()`` and ``int()`` read any Unicode decimal digit (``float('١٢')`` is 12.0,
``int('１２')`` is 12) and underscores (``float('1_0')`` is 10.0); a CSV cell or a flag written
that way is almost always a mistake (a file from a tool set to another locale, a pasted value),
not a number. A JSON or YAML ``true`` is not a number either, though NumPy and pydantic read it
as 1. The readers and the command-line flags take their numbers through these (standard
library only: the command line imports them before NumPy).
"""

__all__ = ["parse_number", "parse_int"]


def parse_number(text) -> float:
    """``float(text)`` for plain ASCII text (digits, sign, point, exponent, ``nan``, ``inf``).

    Raises
    ------
    ValueError
        Non-ASCII digits or letters, underscores, or anything ``float`` does not read.

    Examples
    --------
    >>> parse_number(" -1.5e3 ")
    -1500.0
    >>> parse_number("١٢")
    Traceback (most recent call last):
    ...
    ValueError: not a plain decimal number: '١٢'
    """
    if not isinstance(text, str) or not text.isascii() or "_" in text:
        raise ValueError(f"not a plain decimal number: {text!r:.40}")
    return float(text)


def parse_int(text) -> int:
    """``int(text)`` for plain ASCII decimal text (``ValueError`` otherwise, as :func:`parse_number`)."""
    if not isinstance(text, str) or not text.isascii() or "_" in text:
        raise ValueError(f"not a plain decimal integer: {text!r:.40}")
    return int(text)
