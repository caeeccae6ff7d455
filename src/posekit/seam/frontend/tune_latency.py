"""``seam tune`` without a reference, a latency it cannot pin: what that latency may do to the pose, in the
reported spread.

From the lasers alone a latency is often not pinned (its 95 % profile-likelihood interval touches 0 or is wide,
:mod:`.tune_intervals`): the base profile's value is kept and the sensor's noise widened. Widening the noise does not
make the pose's spread honest: a wrong latency puts an error on the readings that is the same for many steps (it
follows the reading's rate), the filter averages it into the pose, and the pose is then confidently wrong (on the
independent cell of the tests, 13 ms kept as 0: 31 % of the held-out steps ``tracking`` while beyond 3σ).

What the tuner does instead is a sensitivity analysis on the training episodes themselves: the particle filter is
run with the kept latencies and again with each unpinned latency at the end of its interval farther from the kept
value; the difference of the two estimates, ``Δ`` per tool axis and step (in the seam frame, each unpinned sensor's
added in quadrature), is the pose shift that latency would make. The ``spread`` factor per axis is the least
``f >= 1`` with ``f s >= √(s² + (Δ/2)²)`` on 90 % of the steps of every episode (``s`` the filter's spread; its 1σ
the spread of the episodes' own factors over √episodes): the
reported 2σ then reaches the estimate a latency at that end would give, as the factor fitted with a reference
covers 90 % of the errors of every episode (:mod:`.tune_truth`). A latency that is pinned, declared or stamped
changes nothing here.
"""

from dataclasses import replace

import numpy as np

from posekit.seam.frontend.seam_frame import seam_frame_errors
from posekit.seam.frontend.tune_filter import run_filter

__all__ = ["latency_spread"]

#: The spread factor's axes, in the profile's order.
_AXES = ("x", "y", "z", "rx", "ry", "rz")
#: The largest spread factor a profile holds (:class:`posekit.seam.frontend.profile.SpreadProfile`'s range).
_MAX_FACTOR = 100.0


def latency_spread(logs, profile, values, put, stage=None) -> bool:
    """Widen the profile's ``spread`` factors for the latencies ``values`` left unpinned (see the module docstring).

    Parameters
    ----------
    logs : list of EpisodeLog
        The training episodes.
    profile : ProfileModel
        The profile fitted so far (its latencies the kept values).
    values : list of TunedValue
        The tuner's values so far: each ``sensors[i].latency_s`` that is not pinned and has an ``interval``.
    put : callable
        :func:`posekit.seam.frontend.tune.tune_profile`'s.
    stage : callable, optional
        ``stage(text)`` when the work starts (there is an unpinned latency).

    Returns
    -------
    bool
        Whether a latency was unpinned (and the factors fitted).
    """
    loose = [(int(v.key[len("sensors["):v.key.index("]")]), v) for v in values
             if v.key.startswith("sensors[") and v.key.endswith("].latency_s") and not v.pinned and v.interval]
    if not loose:
        return False
    if stage is not None:
        stage("a latency is not pinned: the particle filter with it at its interval's end, for the reported spread")
    base = profile.to_model()
    kept = np.asarray(base.latency_s, dtype=np.float64).copy()
    runs = [run_filter(log, base) for log in logs]
    shift2 = [np.zeros((len(log.time_s), 6)) for log in logs]
    ends = []
    for i, v in loose:
        lo, hi = v.interval
        far = hi if abs(hi - v.value) >= abs(lo - v.value) else lo
        ends.append(f"sensors[{i}] at {far * 1e3:.1f} ms")
        lat = kept.copy()
        lat[i] = far
        moved = replace(base, latency_s=lat)
        for e, log in enumerate(logs):
            d = seam_frame_errors(run_filter(log, moved).estimate, runs[e].estimate, runs[e].nominal)
            shift2[e] += d * d
    per = np.array([np.percentile(np.sqrt(1.0 + d2 / (4.0 * r.spread ** 2)), 90.0, axis=0)
                    for d2, r in zip(shift2, runs)])          # (episodes, 6): what each episode needs
    need = per.max(axis=0)
    # 1σ: the spread of the episodes' own factors over √episodes (none from one episode)
    std = np.std(per, axis=0, ddof=1) / np.sqrt(len(per)) if len(per) >= 2 else np.full(6, np.nan)
    for a, name in enumerate(_AXES):
        f = float(min(max(1.0, need[a]), _MAX_FACTOR))
        put(f"spread.{name}", f, float(std[a]) if np.isfinite(std[a]) else None, True,
            f"covers the pose shift of the unpinned latency ({', '.join(ends)}) on 90 % of every episode's steps"
            if f < _MAX_FACTOR else f"the unpinned latency ({', '.join(ends)}) moves the pose by more than "
            f"{_MAX_FACTOR:g} x its spread: capped; declare the latency")
    return True
