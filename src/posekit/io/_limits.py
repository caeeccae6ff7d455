"""Input size limits shared by every reader, and one-line quoting of offending values.

The defaults fit every real input posekit expects with a wide margin (a batch of 50,000
profiles of 3,200 points is 2.4 GiB of float64 - above the array default, so studies of that
size raise it); a user raises a limit with the CLI's global ``--max-input-mb`` flag or with
:func:`set_limits`. Nothing is allocated from an untrusted size before it is checked against
these numbers.
"""

from dataclasses import dataclass, replace

__all__ = ["Limits", "get_limits", "quote", "set_limits"]


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
    """

    text_bytes: int = 256 * 2**20
    array_bytes: int = 2**30
    image_pixels: int = 100_000_000
    nesting: int = 64
    number_digits: int = 30


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


def mib(n_bytes: int) -> str:
    """A byte count for messages: ``'1024 MiB'`` or ``'2.5 GiB'``."""
    if n_bytes >= 2**30:
        return f"{n_bytes / 2**30:.3g} GiB"
    return f"{n_bytes / 2**20:.3g} MiB"
