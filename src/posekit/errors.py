"""The one exception tree of posekit.

Every error that bad input can cause is a :class:`PosekitError`; the CLI prints its
message on one line and exits 1. Errors about wrong input are also ``ValueError``.

Every message is made one line of at most :data:`MAX_MESSAGE` characters here, in one place
(:func:`one_line`): line breaks become spaces, other control characters (a terminal escape
sequence in a config value, a bidirectional override) are shown escaped, a long value (a
path, a quoted cell) is abbreviated in its middle, and a message still too long loses its
middle.
"""

import re

__all__ = [
    "PosekitError",
    "GaugeError",
    "ProfileError",
    "EstimationError",
    "ConfigError",
    "MissingExtraError",
    "InputFileError",
    "CalibrationError",
    "TrajectoryError",
    "GeometryError",
    "MAX_MESSAGE",
    "one_line",
]

#: Longest message of a PosekitError, characters.
MAX_MESSAGE = 300
#: A run of non-space characters (a path, a value) is abbreviated down to this length at most.
_MIN_WORD = 40
_BREAKS = re.compile(r"[\t\n\r\v\f\x1c-\x1e\x85\u2028\u2029]+")
_CONTROL = re.compile("[\x00-\x08\x0e-\x1b\x1f\x7f-\x84\x86-\x9f\u200b-\u200f\u202a-\u202e"
                      "\u2060-\u2069\ufeff]")
_WORD = re.compile(r"\S{%d,}" % (_MIN_WORD + 1))


def _escape(m: re.Match) -> str:
    c = ord(m.group())
    return f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}"


def _abbreviate(word: str, n: int) -> str:
    """``word`` cut to ``n`` characters in its middle (a path keeps its start and its file name)."""
    k = n - 3
    return word[: k // 2] + "..." + word[len(word) - (k - k // 2):]


def one_line(text, limit: int = MAX_MESSAGE) -> str:
    """``text`` as one line of at most ``limit`` characters for a message.

    Line breaks and tabs become one space; other control characters (``\\x1b``, ``\\x00``,
    bidirectional overrides) are escaped. A text longer than ``limit`` first has its longest
    runs of non-space characters (paths, quoted values) abbreviated in their middle, down to
    40 characters each; a text still too long keeps its beginning and its last third (where
    "expected ..." usually is) around `` ... ``.

    Examples
    --------
    >>> one_line("cfg.yaml: name: got 'a\\nb\\x1b[2J'")
    "cfg.yaml: name: got 'a b\\\\x1b[2J'"
    >>> len(one_line("x" * 1000 + " " + "y " * 500)) <= 300
    True
    """
    text = str(text)
    if len(text) > 8 * limit:                 # a megabyte of message: only its ends can be shown
        text = text[: 4 * limit] + " ... " + text[-2 * limit:]
    text = _BREAKS.sub(" ", text)
    text = _CONTROL.sub(_escape, text)
    while len(text) > limit:
        words = [(m.end() - m.start(), m.start(), m.end()) for m in _WORD.finditer(text)]
        if not words:
            break
        n, i, j = max(words)
        keep = max(_MIN_WORD, n - (len(text) - limit))
        text = text[:i] + _abbreviate(text[i:j], keep) + text[j:]
    if len(text) > limit:
        tail = limit // 3
        text = text[: limit - tail - 5].rstrip() + " ... " + text[-tail:].lstrip()
        text = text[:limit]
    return text


class PosekitError(Exception):
    """Root of all posekit errors; ``str(err)`` is a one-line message for the user, at most
    :data:`MAX_MESSAGE` characters (made so by :func:`one_line` when it is raised)."""

    def __init__(self, *args):
        if args and isinstance(args[0], str):
            args = (one_line(args[0]), *args[1:])
        super().__init__(*args)


class GaugeError(PosekitError, ValueError):
    """A gauge file or gauge geometry is invalid (too few ridges, parallel faces, ...)."""


class ProfileError(PosekitError, ValueError):
    """A laser profile cannot be used: no points, missing or extra corners, ..."""


class EstimationError(PosekitError):
    """A pose could not be estimated from otherwise valid input (degenerate geometry)."""


class ConfigError(PosekitError, ValueError):
    """A configuration file or option has an unknown, missing or impossible value."""


class MissingExtraError(ConfigError):
    """An optional dependency is not installed; the message names the extra that brings it."""


class InputFileError(PosekitError, ValueError):
    """An input file is missing, unreadable or malformed."""


class CalibrationError(PosekitError, ValueError):
    """A calibration cannot be computed from the given correspondences."""


class TrajectoryError(PosekitError, ValueError):
    """A trajectory file or trajectory is malformed or degenerate."""


class GeometryError(PosekitError, ValueError):
    """Geometric input is malformed: wrong shape, non-finite, not a rotation or rigid transform."""
