"""The one verdict every estimate and every track step carries (DESIGN.md "Trust").

A pose is only useful with a word on whether to believe it. Every system reports the same
three things — a ``status`` word, the ``reasons`` behind it, and a standard deviation per
component — in one shape, :class:`Verdict`, that the CSV/JSON writers and the CLI's exit rule
read. Each system keeps its own status words (users and files rely on them), and every word
belongs to one of three :class:`Level` s:

=======================  ==========  ==============================================================
word (system)            level       meaning
=======================  ==========  ==============================================================
``ok`` (estimators,      OK          an estimate exists and the data agree with the model within
ceiling)                             the system's consistency test
``tracking`` (seam)      OK          the filter's measurements agree with its prediction
``suspect``              SUSPECT     an estimate exists but a consistency test failed; the numbers
(estimators)                         are kept and ``reasons`` says why
``predicted`` (ceiling)  SUSPECT     no measurement this frame: the motion model's prediction
``degraded`` (seam)      SUSPECT     the measurements only partly agree (integrity monitor)
``error`` (estimators)   FAILED      no estimate: ``reasons`` says why (scikit-image's
                                     ``FailedEstimation``)
``lost`` (trackers)      FAILED      no trustworthy estimate this step
=======================  ==========  ==============================================================

Exit rule (DESIGN.md): a batch command exits 0 only if every item's level is OK
(:func:`batch_exit_code`); a track command exits 0 when its input was read whole, whatever the
statuses (:func:`track_exit_code`) — statuses are data there.

Examples
--------
>>> v = Verdict("suspect", ("fit: chi2 41.2 > 22.5 (dof 6)",), {"tx_um": 3.1})
>>> v.level, v.is_ok
(<Level.SUSPECT: 1>, False)
>>> v.reason
'fit: chi2 41.2 > 22.5 (dof 6)'
>>> Verdict.failed("3 corners found, 5 expected").to_dict()
{'status': 'error', 'reasons': ['3 corners found, 5 expected'], 'std': None}
>>> batch_exit_code(["ok", "ok", "suspect"])
1
"""

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from types import MappingProxyType

__all__ = ["Level", "STATUS_LEVELS", "Verdict", "level_of", "status_counts", "batch_exit_code", "track_exit_code"]


class Level(IntEnum):
    """How far an estimate may be trusted, ordered from best to worst."""

    OK = 0
    SUSPECT = 1
    FAILED = 2


#: Every status word any system writes, and its level (the table in the module docstring).
STATUS_LEVELS: Mapping[str, Level] = MappingProxyType({
    "ok": Level.OK,
    "tracking": Level.OK,
    "suspect": Level.SUSPECT,
    "predicted": Level.SUSPECT,
    "degraded": Level.SUSPECT,
    "error": Level.FAILED,
    "lost": Level.FAILED,
})


def level_of(status: str) -> Level:
    """The :class:`Level` of a status word.

    Raises
    ------
    ValueError
        For a word no system writes (a programming error, not a user's).
    """
    try:
        return STATUS_LEVELS[status]
    except KeyError:
        raise ValueError(f"unknown status {status!r}; expected one of {', '.join(STATUS_LEVELS)}") from None


@dataclass(frozen=True)
class Verdict:
    """Status, reasons and per-component standard deviations of one estimate.

    Attributes
    ----------
    status : str
        A word of :data:`STATUS_LEVELS` (the system's own vocabulary).
    reasons : tuple of str
        Why the status is not the best one (empty when it is); each a short sentence.
    std : mapping of str to float, or None
        1σ of each component, the unit in the key (``"tx_um"``, ``"rz_deg"``, ``"x_mm"``);
        None when the estimator cannot compute one (e.g. no estimate).
    """

    status: str
    reasons: tuple[str, ...] = ()
    std: Mapping[str, float] | None = field(default=None)

    def __post_init__(self):
        level_of(self.status)  # refuses an unknown word
        if isinstance(self.reasons, str):
            raise TypeError("reasons must be a sequence of str, not one str")
        object.__setattr__(self, "reasons", tuple(self.reasons))

    @classmethod
    def failed(cls, reason: str, status: str = "error") -> "Verdict":
        """The verdict of an estimate that could not be made (no numbers, one reason)."""
        if level_of(status) is not Level.FAILED:
            raise ValueError(f"a failed estimate needs a FAILED status, not {status!r}")
        return cls(status, (reason,), None)

    @property
    def level(self) -> Level:
        """The :class:`Level` of :attr:`status`."""
        return STATUS_LEVELS[self.status]

    @property
    def is_ok(self) -> bool:
        """True when the estimate may be trusted (level OK)."""
        return self.level is Level.OK

    @property
    def reason(self) -> str:
        """The reasons joined by ``"; "`` (the CSV's ``reason`` field); empty when there are none."""
        return "; ".join(self.reasons)

    def to_dict(self) -> dict:
        """``{"status", "reasons", "std"}`` for JSON (``std`` a plain dict or None)."""
        return {"status": self.status, "reasons": list(self.reasons),
                "std": None if self.std is None else {k: float(v) for k, v in self.std.items()}}


def status_counts(statuses: Iterable[str], vocabulary: Iterable[str] | None = None) -> dict[str, int]:
    """How many times each status word occurs, in the vocabulary's order.

    Parameters
    ----------
    statuses : iterable of str
        One word per item or step.
    vocabulary : iterable of str, optional
        The system's words, listed (with 0) even when absent, in this order; words outside
        it follow in order of first appearance. Default: only the words present.
    """
    counts = {w: 0 for w in (vocabulary or ())}
    for s in statuses:
        level_of(s)
        counts[s] = counts.get(s, 0) + 1
    return counts


def batch_exit_code(statuses: Iterable[str]) -> int:
    """0 when every item's level is OK, else 1 (an empty batch is 0)."""
    return int(any(level_of(s) is not Level.OK for s in statuses))


def track_exit_code(read_whole: bool) -> int:
    """0 when the track's input was read whole (statuses are data), else 1."""
    return 0 if read_whole else 1
