"""Ranges of the numeric command-line flags: argparse ``type=`` factories and the check that turns
a value out of its range into posekit's one-line error (exit 1).

Every numeric flag is declared with its range and unit::

    p.add_argument("--particles", type=bounded_int(1, 1_000_000), ...)
    p.add_argument("--threshold-px", type=bounded_float(0.01, 1e4, "px"), ...)

Text that is no number at all (``--count x``) is a usage error (argparse, exit 2). A number out of
the range (or not finite, or not whole for an integer flag) parses into a value that remembers
it, and :func:`check_flags`, called by the verb before it reads, allocates or writes anything,
raises :class:`~posekit.errors.ConfigError`
``--particles: expected an integer in 1..1000000, got 1e30`` (exit 1). Such a value compares and
formats as the number it holds, so a verb's own older check of the same flag
(``--runs: expected an integer >= 1, got 0``) may run first and keep its message.
"""

import argparse
import math

from .._numbers import parse_int, parse_number
from ..errors import ConfigError

__all__ = ["MAX_NOISE_UM", "MAX_PROFILES", "MAX_WORKERS", "SEED_MAX", "bounded_float", "bounded_int", "check_flags", "check_range", "seed", "workers"]

#: Largest seed: NumPy's SeedSequence takes any integer >= 0; 2**63 - 1 fits every int64 column
#: (the seam configuration's ``seed`` has the same range).
SEED_MAX = 2**63 - 1
#: Most worker processes of a local Dask cluster.
MAX_WORKERS = 256
#: Most profiles one profiler verb simulates (3,200 points each: 0.5 GiB of float64 at the limit).
MAX_PROFILES = 10_000
#: Largest profiler noise, µm (10 mm; the LJ-X8400's is 5-10 µm).
MAX_NOISE_UM = 1e4
#: Longest offending text quoted in a message.
_SHOWN = 80


def _fmt(x) -> str:
    """A bound for messages: ``10000`` (not ``10000.0`` or ``1e+04``), ``1e-05``, ``0.5``."""
    if isinstance(x, float):
        return str(int(x)) if x.is_integer() and abs(x) < 1e16 else f"{x:g}"
    return str(x)


def _shown(text) -> str:
    """The offending text as typed, on one line, at most 80 characters."""
    text = " ".join(str(text).split())
    return text if len(text) <= _SHOWN else text[: _SHOWN - 3] + "..."


def _range_text(lo, hi, unit: str, lo_open: bool = False, hi_open: bool = False) -> str:
    if lo is not None and not lo_open and not hi_open:
        text = f"{_fmt(lo)}..{_fmt(hi)}"
    else:
        parts = [f"{'>' if lo_open else '>='} {_fmt(lo)}"] if lo is not None else []
        text = " and ".join([*parts, f"{'<' if hi_open else '<='} {_fmt(hi)}"])
    return f"{text} {unit}" if unit else text


class _OutOfRange:
    """A parsed flag value out of its range; ``message`` says what was expected and what arrived,
    ``flag`` names the flag when its destination does not (``--runs`` stored as ``repeats``)."""

    message = ""
    flag = None


class _OutOfRangeInt(int, _OutOfRange):
    pass


class _OutOfRangeFloat(float, _OutOfRange):
    pass


def _reject(value, text, expected: str, flag: str | None):
    out = (_OutOfRangeInt if isinstance(value, int) else _OutOfRangeFloat)(value)
    out.message = f"expected {expected}, got {_shown(text)}"
    out.flag = flag
    return out


def _number(text: str, expected: str) -> float:
    try:
        return parse_number(text)          # plain ASCII: not '١٢' or '1_0
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {_shown(text)!r}") from None


def bounded_int(lo: int, hi: int, unit: str = "", *, flag: str | None = None):
    """An argparse ``type=`` for an integer flag in ``lo..hi`` (``unit`` for the message).

    ``1e3`` is read as 1000; a value out of the range, a fraction or a non-finite number makes
    :func:`check_flags` raise ``--flag: expected an integer in lo..hi unit, got TEXT``. ``flag``
    names the flag when its ``dest`` does not (default: ``--`` + dest with ``-`` for ``_``).
    """
    expected = f"an integer in {_range_text(lo, hi, unit)}"

    def parse(text: str):
        try:
            value = parse_int(text)
        except ValueError:
            number = _number(text, expected)
            if not (math.isfinite(number) and number.is_integer() and abs(number) <= 2**53):
                return _reject(number, text, expected, flag)
            value = int(number)
        return value if lo <= value <= hi else _reject(value, text, expected, flag)

    parse.__name__ = "integer"
    parse.bounds = (lo, hi, unit)
    return parse


def bounded_float(lo: float | None, hi: float, unit: str = "", *, lo_open: bool = False, hi_open: bool = False,
                  flag: str | None = None):
    """An argparse ``type=`` for a finite number flag in ``lo..hi`` (either end open).

    ``lo=None`` leaves the lower end to the library the value goes to (it has its own message).
    A value out of the range or not finite makes :func:`check_flags` raise
    ``--flag: expected a number in lo..hi unit, got TEXT``; ``flag`` as in :func:`bounded_int`.
    """
    expected = f"a number in {_range_text(lo, hi, unit, lo_open, hi_open)}"
    if lo is None or lo_open or hi_open:
        expected = f"a number {_range_text(lo, hi, unit, lo_open, hi_open)}"

    def parse(text: str):
        value = _number(text, expected)
        ok = math.isfinite(value) and (value < hi if hi_open else value <= hi)
        if lo is not None:
            ok = ok and (value > lo if lo_open else value >= lo)
        return value if ok else _reject(value, text, expected, flag)

    parse.__name__ = "number"
    parse.bounds = (lo, hi, unit)
    return parse


#: ``type=`` of every ``--seed``.
seed = bounded_int(0, SEED_MAX)
#: ``type=`` of every ``--workers`` (processes of a local Dask cluster).
workers = bounded_int(1, MAX_WORKERS, "processes")


def check_flags(args, names=None) -> None:
    """Raise a one-line :class:`ConfigError` for the first flag of ``args`` out of its range.

    ``names``: only these destinations (default: all). The flag is named from its destination
    (``threshold_px`` -> ``--threshold-px``) unless its type was given ``flag=``.
    """
    for dest, value in vars(args).items():
        if isinstance(value, _OutOfRange) and (names is None or dest in names):
            raise ConfigError(f"{value.flag or '--' + dest.replace('_', '-')}: {value.message}")


def check_range(flag: str, value, lo, hi, unit: str = "", *, integer: bool = False, what: str | None = None,
                shown=None) -> None:
    """A one-line :class:`ConfigError` unless ``lo <= value <= hi`` (finite): for values that come
    out of a list flag (``--tilts-deg -75:75:2.5``) or from two flags together.

    ``what`` names the expected values (default "an integer" / "a number"); ``shown`` is the text
    quoted as what arrived (default the value)."""
    if isinstance(value, (int, float)) and math.isfinite(value) and lo <= value <= hi:
        return
    what = what or ("an integer" if integer else "a number")
    raise ConfigError(f"{flag}: expected {what} in {_range_text(lo, hi, unit)}, "
                      f"got {_shown(value if shown is None else shown)}")
