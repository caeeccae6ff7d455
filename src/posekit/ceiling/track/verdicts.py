"""When an accepted dot is not ``ok``: the verdict rules of one tracked dot, and the honest 1σ of a
track whose identity is in doubt. One implementation for every tracker: :class:`~posekit.ceiling.track.Tracker`
applies them to its dots, and :class:`~posekit.ceiling.track.MultiRobotTracker` through the
tracker of each robot (the other robots' dots are ``claimed``: neither associated nor rivals).

Rules (each row of a dot that was measured and accepted this frame):

* **rival** — another eligible spot that a test over several frames found moving is in view
  outside the gate of the accepted one, and no other track claims it: which of the two is the
  laser cannot be told, the row is ``suspect``;
* **probation** — the dot was re-acquired away from where the track was predicted (after
  ``reinit_after`` frames whose candidates were all gated out): for ``max_predict_s`` the
  previous dot may only be hidden, the rows are ``suspect``; if during that time the previous
  dot is seen again (a candidate inside the gate of the previous track's prediction), or a
  rival is seen, the identity stays in doubt for the rest of the track.

While the identity is in doubt the track carries the **alternative** — the previous track,
predicted on at constant velocity (its covariance grown by the process noise fitted from the
track's own measurements, :func:`~posekit.ceiling.track.motion_noise.fitted_accel_psd`) and updated by the candidates
that fall inside its gate. Every row (``suspect`` or ``predicted``) then reports the 1σ of the
two-hypothesis mixture about the reported position: ``σ² = σ_main² + d²/2``, ``d`` the
distance between the two hypotheses — an error of ``d`` (the other hypothesis was the laser)
stays within 1.5σ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._kalman import _mahalanobis2, cv_predict, kf_update

__all__ = ["Alternative", "rival", "open_alternative", "follow_alternative", "mixture_std", "doubt_reason", "why_not"]


@dataclass
class Alternative:
    """The other hypothesis of a dot whose identity is in doubt (mm, mm/s, s).

    Attributes
    ----------
    x, P : ndarray
        State ``[x, y, vx, vy]`` and covariance at ``t_s``.
    t_s, t_meas_s : float
        Time of the state, and of its last measurement.
    q_extra : float
        Process noise (mm²/s³ per axis) the previous track's data add to the filter's.
    seen : bool
        A candidate was found in its gate since it was opened (the previous dot is back).
    """

    x: np.ndarray
    P: np.ndarray
    t_s: float
    t_meas_s: float
    q_extra: float = 0.0
    seen: bool = False


def rival(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray, moving, accepted_z: np.ndarray,
          gate_chi2: float, gate_floor_mm: float) -> np.ndarray | None:
    """An eligible candidate found moving outside the gate of the accepted one (or None).

    Parameters
    ----------
    x, P : ndarray
        The dot's state (4,) and covariance (4, 4) after the update, mm.
    z, R : ndarray
        The frame's candidates (K, 2) mm and their covariances (K, 2, 2) mm².
    moving : ndarray of bool, shape (K,), or None
        Eligible candidates found moving that no other track claims.
    accepted_z : ndarray, shape (2,)
        The candidate that was accepted.
    gate_chi2, gate_floor_mm : float
        The gate (:class:`~posekit.ceiling.track.TrackerConfig`).
    """
    if moving is None or not np.any(moving):
        return None
    d2 = _mahalanobis2(z - x[:2], P[:2, :2] + R)
    far = moving & (d2 > gate_chi2) & (np.hypot(*(z - accepted_z).T) > gate_floor_mm)
    if not far.any():
        return None
    return z[int(np.flatnonzero(far)[0])]


def open_alternative(x: np.ndarray, P: np.ndarray, t_s: float, t_meas_s: float, q_extra: float = 0.0) -> Alternative:
    """The previous track as the alternative hypothesis (copies)."""
    return Alternative(np.array(x, float), np.array(P, float), float(t_s), float(t_meas_s), float(q_extra))


def _coast_var(alt: Alternative, t_s: float) -> float:
    since = t_s - alt.t_meas_s
    return alt.q_extra * since ** 3 / 3.0 if since > 0 else 0.0


def follow_alternative(alt: Alternative, t_s: float, z: np.ndarray, R: np.ndarray, usable, q: float,
                       gate_chi2: float) -> bool:
    """Predict the alternative to ``t_s`` and update it with the nearest usable candidate inside
    its gate (the χ² gate of its prediction widened by the unseen manoeuvre); True if one was."""
    alt.x, alt.P = cv_predict(alt.x, alt.P, max(t_s - alt.t_s, 0.0), q)
    alt.t_s = t_s
    if len(z) == 0 or usable is None or not np.any(usable):
        return False
    d2 = _mahalanobis2(z - alt.x[:2], alt.P[:2, :2] + R + _coast_var(alt, t_s) * np.eye(2))
    d2 = np.where(usable, d2, np.inf)
    k = int(np.argmin(d2))
    if not d2[k] <= gate_chi2:
        return False
    alt.x, alt.P = kf_update(alt.x, alt.P, z[k], R[k])
    alt.t_meas_s = t_s
    alt.seen = True
    return True


def mixture_std(std_main: float, main_xy: np.ndarray, alt: Alternative | None, t_s: float) -> float:
    """1σ (mm) about the reported position ``main_xy`` when ``alt`` may be the laser instead:
    ``sqrt(σ_main² + (d² + σ_alt²) / 2)``, ``d`` the distance to the alternative's prediction and
    ``σ_alt`` its own 1σ (the unseen manoeuvre included); ``std_main`` without one."""
    if alt is None:
        return std_main
    d = float(np.hypot(*(np.asarray(main_xy, float) - alt.x[:2])))
    s_alt2 = float(np.linalg.eigvalsh(alt.P[:2, :2])[-1]) + _coast_var(alt, t_s)
    return float(np.sqrt(std_main ** 2 + 0.5 * (d * d + s_alt2)))


def doubt_reason(jump_mm: float, conflicted: bool, probation_s: float) -> str:
    """The reason of a row whose identity is in doubt after a re-acquisition ``jump_mm`` away."""
    if conflicted:
        return (f"re-acquired {jump_mm:.0f} mm from where the track was predicted; another moving laser-like "
                "spot, or the previous dot, was seen since: which is the laser cannot be told")
    return (f"re-acquired {jump_mm:.0f} mm from where the track was predicted ({probation_s:g} s of probation: "
            "the previous dot may only be hidden)")


def why_not(st, t_s: float, n: int, had: bool, eligible, moving, alive: bool, cfg) -> tuple:
    """The reason of a row without an accepted dot (``st`` a DotState, ``n`` candidates, ``had``:
    the track was alive before this frame, ``alive``: it still is, ``cfg`` the TrackerConfig)."""
    if alive:
        since = t_s - st.t_meas_s
        if n == 0:
            return (f"no dot seen this frame; predicted {since:.2f} s after the last one",)
        if st.pending is not None:
            return (f"a candidate near the prediction waits to be seen moving with the track ({since:.2f} s "
                    "coasted)",)
        return (f"{n} candidate(s), none inside the gate of the prediction ({since:.2f} s coasted)",)
    if had:
        return (f"no dot accepted for more than {cfg.max_predict_s:g} s",)
    if n == 0:
        return ("no dot seen",)
    k = int(np.count_nonzero(eligible))
    if moving is not None:
        m = int(np.count_nonzero(moving))
        if m > 1:
            return (f"{m} moving laser-like spots: which is the laser cannot be told",)
        return (f"{n} candidate(s), {k} laser-like, none seen moving yet (static lights are never acquired)",)
    return (f"{n} candidate(s), {k} laser-like, none seen moving by {cfg.min_move_mm:g} mm yet",)
