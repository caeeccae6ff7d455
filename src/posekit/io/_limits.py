"""Input size limits shared by every reader, and one-line quoting of offending values.

The defaults fit every real input posekit expects with a wide margin (a batch of 50,000
profiles of 3,200 points is 2.4 GiB of float64 - above the array default, so studies of that
size raise it); a user raises a limit with the CLI's global ``--max-input-mb`` flag or with
:func:`set_limits`. Nothing is allocated from an untrusted size before it is checked against
these numbers.
"""

from dataclasses import dataclass, replace

__all__ = ["Limits", "check_rows", "get_limits", "quote", "set_limits"]


@dataclass(frozen=True)
class Limits:
    """Upper bounds on what a reader accepts.

    Attributes
    ----------
    text_bytes : int
        Largest text file (CSV, YAML, JSON, TUM, URDF), bytes: 256 MiB.
    array_bytes : int
        Largest decoded array (``.npy``, a ``.npz`` member), bytes: 1 GiB.
    image_pixels : int
        Largest image (width × height), read from the header before decoding: 100 MP
        (a 12,000 × 8,000 frame; an 8K video frame is 33 MP).
    nesting : int
        Deepest nesting of YAML/JSON mappings and lists: 64.
    number_digits : int
        Longest integer literal in YAML/JSON, digits: 30 (beyond any count or seed).
    rows : int
        Most lines of a text table (a trajectory's poses, a recorded log's samples, a profile's
        points), counted before any line is parsed: 2,000,000 (a 1 kHz log of 33 minutes; parsing
        that many takes seconds and about a gigabyte). ``--max-input-mb`` raises it in proportion
        (one row per 128 bytes of the text limit).
    """

    text_bytes: int = 256 * 2**20
    array_bytes: int = 2**30
    image_pixels: int = 100_000_000
    nesting: int = 64
    number_digits: int = 30
    rows: int = 2_000_000


_LIMITS = Limits()


def get_limits() -> Limits:
    """The limits in force."""
    return _LIMITS


def set_limits(**changes) -> Limits:
    """Change limits for this process (e.g. ``set_limits(array_bytes=8 * 2**30)``); returns the
    previous ones so a caller can restore them."""
    global _LIMITS
    previous = _LIMITS
    _LIMITS = replace(_LIMITS, **changes)
    return previous


def quote(value, n: int = 80) -> str:
    """``value`` as a one-line quoted string of at most ``n`` characters (newlines and control
    characters escaped, the rest elided), for error messages."""
    text = repr(value) if not isinstance(value, str) else value
    text = text.encode("unicode_escape", errors="backslashreplace").decode("ascii", errors="replace")
    if len(text) > n:
        text = text[: n - 3] + "..."
    return f"'{text}'"


def check_rows(text: str, source: str, what: str, *, error, limit: int | None = None) -> int:
    """Count the lines of ``text`` (in C, before any is parsed); raise ``error`` above the limit.

    Parameters
    ----------
    what : str
        What a line holds, plural, for the message (``"poses"``).
    limit : int, optional
        The reader's own bound when smaller than :attr:`Limits.rows`.

    Returns
    -------
    int
        The number of lines.
    """
    n = text.count("\n") + (0 if text.endswith("\n") or not text else 1)
    rows = get_limits().rows
    bound = rows if limit is None else min(limit, rows)
    if n > bound:
        hint = " (raise it with --max-input-mb)" if bound == rows else ""
        raise error(f"{source}: {n:,} lines; expected at most {bound:,} {what}{hint}")
    return n


def mib(n_bytes: int) -> str:
    """A byte count for messages: ``'1024 MiB'`` or ``'2.5 GiB'``."""
    if n_bytes >= 2**30:
        return f"{n_bytes / 2**30:.3g} GiB"
    return f"{n_bytes / 2**20:.3g} MiB"
