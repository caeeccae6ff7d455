"""Numbers from text and from parsed documents, by value: decimal ASCII only, never a boolean.

Python's ``float()`` and ``int()`` read any Unicode decimal digit (``float('١٢')`` is 12.0,
``int('１２')`` is 12) and underscores (``float('1_0')`` is 10.0); a CSV cell or a flag written
that way is almost always a mistake (a file from a tool set to another locale, a pasted value),
not a number. A JSON or YAML ``true`` is not a number either, though NumPy and pydantic read it
as 1. The readers and the command-line flags take their numbers through these.
"""

import numpy as np

__all__ = ["number_array"]


def _walk(value, depth=0):
    if isinstance(value, bool):
        raise TypeError("a boolean")
    if isinstance(value, int | float):
        return
    if isinstance(value, list | tuple) and depth < 8:
        for v in value:
            _walk(v, depth + 1)
        return
    raise TypeError(type(value).__name__)


def number_array(value, what: str, error, *, finite: bool = False) -> np.ndarray:
    """``value`` (a number or nested lists of numbers from JSON/YAML) as a float64 array.

    Parameters
    ----------
    value : object
        The parsed value.
    what : str
        ``FILE: key`` for the message.
    error : type
        The PosekitError subclass to raise.
    finite : bool
        Also refuse NaN and infinity.

    Raises
    ------
    error
        A boolean, text or any other non-number inside, ragged lists, or (``finite``) a
        non-finite number: ``what: expected numbers, got a boolean``.
    """
    try:
        _walk(value)
        arr = np.array(value, dtype=np.float64)
    except TypeError as exc:
        raise error(f"{what}: expected numbers, got {exc}") from None
    except ValueError:                    # ragged nesting
        raise error(f"{what}: expected numbers in a regular array (rows of equal length)") from None
    if finite and not np.all(np.isfinite(arr)):
        raise error(f"{what}: expected finite numbers, found NaN or infinity")
    return arr

