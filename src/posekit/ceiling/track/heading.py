"""The heading of a two-dot robot (case B of the paper), and the second dot found again at the
robot's fixed separation after a turn on the spot.

The heading is the direction from the red to the green dot, filtered by a circular
constant-turn-rate filter on the unwrapped angle (innovations wrapped to (-π, π]), with its 1σ
(``std_heading_deg``, from the two dots' covariances: ``σθ² = n̂ᵀ(R_red + R_green)n̂ / d²``); a
measured direction more than 3σ from the filter's prediction (a turn on the spot) restarts the
filter on the measurement, so the heading of a frame whose two dots were measured never lies
more than 3σ from what they say.
"""

import numpy as np

from ._inputs import _as_candidates, _as_covariances, _as_eligible
from ._kalman import _wrap, cv_predict, kf_update
from .types import HeadingState, TrackerConfig

__all__ = ["update_heading", "second_dot_at_separation"]


def update_heading(h: HeadingState, cfg: TrackerConfig, t_s: float, measured: dict, states: dict) -> tuple[float, float]:
    """Circular filter of the red→green direction; returns (degrees in (-180, 180], 1σ in
    degrees), NaN without a heading.

    The measured direction's variance is ``n̂ᵀ(R₀ + R₁)n̂ / d²`` (n̂ perpendicular to the
    red→green segment of length d). A measurement more than 3σ from the prediction (the
    robot turned faster than the filter's model) restarts the filter on it: the heading of
    a frame whose two dots were measured is what they say, within its σ.

    Parameters
    ----------
    h : HeadingState
        The filter's state (updated here): ``[θ rad, θ̇ rad/s]``.
    cfg : TrackerConfig
    t_s : float
        Frame time, s.
    measured : dict
        ``{colour: (z (2,) mm, R (2, 2) mm²)}`` accepted this frame.
    states : dict
        ``{colour: DotState}`` of the tracker (no heading while either dot is lost).
    """
    nan = float("nan")
    if len(cfg.dots) < 2:
        return nan, nan
    c0, c1 = cfg.dots[0], cfg.dots[1]
    if h.x is not None and t_s - h.t_meas_s > cfg.max_predict_s + 1e-9:
        h.x = h.P = None
    if h.x is not None:
        h.x, h.P = cv_predict(h.x, h.P, max(t_s - h.t_s, 0.0), cfg.heading_psd_rad2_s3)
    h.t_s = t_s
    if c0 in measured and c1 in measured:
        (z0, R0), (z1, R1) = measured[c0], measured[c1]
        d = z1 - z0
        dist = float(np.hypot(*d))
        if dist > 0:
            theta = float(np.arctan2(d[1], d[0]))
            n = np.array([-d[1], d[0]]) / dist          # perpendicular: the direction of angle error
            var = float(n @ (R0 + R1) @ n) / dist ** 2   # small-angle law: σθ² = σ⊥² / d²
            nu = _wrap(theta - h.x[0]) if h.x is not None else 0.0
            if h.x is None or nu * nu > 9.0 * (h.P[0, 0] + var):
                h.x = np.array([theta, 0.0])
                h.P = np.diag([var, cfg.init_rate_std_rad_s ** 2])
            else:
                h.x, h.P = kf_update(h.x, h.P, np.array([h.x[0] + nu]), np.array([[var]]),
                                     innovation=np.array([nu]))
            h.t_meas_s = t_s
    if h.x is None or any(states[c].x is None for c in (c0, c1)):
        return nan, nan
    deg = float(np.degrees(_wrap(h.x[0])))
    return (180.0 if deg == -180.0 else deg), float(np.degrees(np.sqrt(max(h.P[0, 0], 0.0))))


def second_dot_at_separation(sep: tuple, cfg: TrackerConfig, dots_world, meas_cov, eligible, measured: dict):
    """The two lasers sit on one robot: their distance is fixed. When the first dot was
    accepted and the second was not (a turn on the spot swings it far outside its own gate),
    a lone eligible candidate of the second colour at that distance (within 3σ of the
    separation measured so far, at least ``gate_floor_mm / 2``) is the second dot. The
    separation is learned from the frames where both were accepted.

    Parameters
    ----------
    sep : tuple
        ``(count, mean mm, sum of squares mm²)`` of the separations so far (Welford).
    cfg : TrackerConfig
    dots_world, meas_cov, eligible : mapping
        The frame's candidates per colour (mm, mm², bool), as given to :meth:`Tracker.step`.
    measured : dict
        ``{colour: (z (2,) mm, R (2, 2) mm²)}`` accepted this frame.

    Returns
    -------
    sep : tuple
        The separation statistics, updated when both dots were accepted.
    found : tuple or None
        ``(colour, z (2,) mm, R (2, 2) mm²)`` of the second dot, or None.
    """
    if len(cfg.dots) < 2:
        return sep, None
    c0, c1 = cfg.dots[0], cfg.dots[1]
    if c0 in measured and c1 in measured:
        d = float(np.hypot(*(measured[c1][0] - measured[c0][0])))
        n, m, v = sep
        n += 1
        dm = d - m
        m += dm / n
        return (n, m, v + dm * (d - m)), None
    n, m, v = sep
    if c0 not in measured or c1 in measured or n < 5:
        return sep, None
    z = _as_candidates(dots_world.get(c1), c1)
    if len(z) == 0:
        return sep, None
    el = _as_eligible(None if eligible is None else eligible.get(c1), dots_world.get(c1), len(z))
    R = _as_covariances((meas_cov or {}).get(c1), len(z), c1, cfg.meas_std_mm, cfg.min_meas_std_mm)
    sd = max(3.0 * float(np.sqrt(v / (n - 1))), cfg.gate_floor_mm / 2.0)
    dist = np.hypot(*(z - measured[c0][0]).T)
    at = np.flatnonzero(el & (np.abs(dist - m) <= sd))
    if len(at) != 1:
        return sep, None
    k = int(at[0])
    return sep, (c1, z[k], R[k])
