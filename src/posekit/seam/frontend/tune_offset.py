"""``seam tune``: the offset test's calibration — how far the filter's estimate sits from the kinematic pose.

Along the axes the lasers see, the filter's estimate settles at some offset from the kinematic pose
``Fk(q + Cj(τ))``: the robot's own unmodelled error (a deflection the compliance model lacks, its geometry). The
profile's spread along the axes the lasers do not see (the roll about the travel) rests on that error being what
it was on the training episodes. An encoder offset, or a tool that moved, after the profile was fitted changes
it: the lasers pull the estimate to another offset along the axes they see, while along the others the estimate
follows the kinematics and their new error (on the independent cell of the tests a 0.05° offset of joint 2 moves
the offset along z by 0.5 mm and leaves the roll 0.05° off, beyond the 3σ the profile allows there).

The integrity monitor's offset test (:mod:`posekit.seam.engine.integrity`, :mod:`posekit.seam.engine.offset_test`) averages the step's offset
(:func:`~posekit.seam.engine.integrity.kinematic_offset`, tool frame, mm and rad) over its long window
(:func:`~posekit.seam.engine.integrity.offset_means`). Here that statistic is computed on the training episodes,
run with the fitted profile, and per axis:

- ``mean``: its mean over every tested step of every episode (1σ: ``sd / √samples``);
- ``sd``: its standard deviation over those steps (within and between the episodes);
- ``samples``: the effective number of independent values ``sd`` rests on, by Welch–Satterthwaite from its two
  parts: within the episodes (``Σ n_e / τ_e - E`` degrees of freedom, ``τ_e`` the integrated autocorrelation
  time of the episode's series) and between them (``E - 1``: the part of the episodes' means' variance the
  within-episode wander does not explain). A spread that rests on three episodes that differ is known to a few
  degrees of freedom only, and the test's Student t bound is then wide: the smallest change it flags is printed,
  and it falls as episodes are added.

Steps the filter reports ``lost`` are left out. From fewer than two episodes, or fewer than
:data:`MIN_STEPS` tested steps, there is no offset test (said so).
"""

import math

import numpy as np

from posekit._autocorr import autocorrelation_time
from posekit.seam.engine.offset_test import OFFSET_AXES, kinematic_offset, offset_limits, offset_means
from posekit.seam.frontend.profile import AXES

__all__ = ["MIN_STEPS", "calibrate_offset", "fit_offset", "offset_series", "projected_limits"]

#: Tested steps (over every episode) the offset test needs to be calibrated.
MIN_STEPS = 100


def offset_series(runs, window_long: int, window: int) -> list:
    """Per filter run (:class:`~posekit.seam.frontend.tune_filter.FilterRun`) the offset test's statistic,
    ``(T, 6)`` mm and rad, NaN where it is not tested and at steps reported ``lost``."""
    out = []
    for run in runs:
        M = offset_means(kinematic_offset(run.estimate, run.kinematic), window_long, window)
        M[np.asarray(run.status) == "lost"] = np.nan
        out.append(M)
    return out


def calibrate_offset(series) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``mean``, ``sd`` and ``samples`` per axis (see the module docstring) and the tested steps used.

    Parameters
    ----------
    series : list of ndarray, shape (T, 6)
        Per episode the statistic of :func:`offset_series` (rows with a NaN are left out).

    Returns
    -------
    mean, sd, samples : ndarray, shape (6,)
        NaN when fewer than two episodes have at least 8 tested steps.
    n : int
    """
    eps = [np.asarray(s, dtype=np.float64).reshape(-1, 6) for s in series]
    eps = [s[np.isfinite(s).all(axis=1)] for s in eps]
    eps = [s for s in eps if len(s) >= 8]
    n = int(sum(len(s) for s in eps))
    nan = np.full(6, np.nan)
    if len(eps) < 2:
        return nan, nan, nan, n
    allx = np.concatenate(eps)
    mean = allx.mean(axis=0)
    sd = allx.std(axis=0, ddof=1)
    samples = np.empty(6)
    E = len(eps)
    for a in range(6):
        if not sd[a] > 0.0:
            samples[a] = 0.0
            continue
        tau = np.array([autocorrelation_time(s[:, a] / sd[a]) for s in eps])
        sizes = np.array([len(s) for s in eps], dtype=np.float64)
        within = float(np.mean([np.var(s[:, a], ddof=1) for s in eps]))
        dof_w = max(float(np.sum(sizes / tau)) - E, 1.0)
        # the episodes' means vary by the within-episode wander over τ_e / n_e each; the rest is between them
        between = max(float(np.var([s[:, a].mean() for s in eps], ddof=1)) - within * float(np.mean(tau / sizes)),
                      0.0)
        total = within + between
        samples[a] = 1.0 + total * total / (within * within / dof_w + between * between / (E - 1))
    # a series without a wander (a constant offset within each episode) has no autocorrelation time: its spread
    # then rests on nothing this can count, and the axis is not tested
    return mean, sd, np.where(np.isfinite(samples), samples, 0.0), n


def projected_limits(sd, samples, episodes: int, more: int, alpha: float) -> np.ndarray:
    """``(6,)``: the smallest change the offset test would flag (the units of ``sd``) were the profile fitted on
    ``more`` episodes like these ``episodes``: the same ``sd``, its ``samples`` in proportion to the episodes
    (both its parts grow so: the windows within the episodes and the differences between them). A planning
    figure: the spread of more episodes is not known before they are recorded (on the independent cell of the
    tests, three episodes projected to nine came within a factor 2.2 of what nine gave, where the three alone were up
    to 19 times too wide). ``inf`` on an axis without a test."""
    n = np.asarray(samples, dtype=np.float64) * (float(more) / float(episodes))
    return offset_limits(n, alpha) * np.asarray(sd, dtype=np.float64)


def _limits_text(limit) -> str:
    return ", ".join(f"{name} {limit[a] * k:.2g} {unit}" if math.isfinite(limit[a]) else f"{name} not tested"
                     for a, (name, unit, k) in enumerate(OFFSET_AXES))


def fit_offset(logs, runs, data: dict, put, say) -> None:
    """Calibrate the offset test on ``runs`` (the filter run with the fitted profile over ``logs``) with the
    episodes' ``filter.integrity_window_long`` and ``integrity_window``: the profile's ``offset`` block goes into
    ``data`` (the profile being written; left out when there is no offset test, and ``say`` tells why), each value
    is reported with ``put`` (:func:`posekit.seam.frontend.tune.tune_profile`'s) and the smallest change the test
    flags with ``say``."""
    data.pop("offset", None)
    settings = logs[0].config.filter
    window_long, window = int(settings.integrity_window_long), int(settings.integrity_window)
    if window_long <= 0:
        say("no offset test: filter.integrity_window_long is 0 (no long window to average the offset over)")
        return
    if any(run.kinematic is None for run in runs):
        say("no offset test: the filter runs kept no kinematic pose")
        return
    mean, sd, samples, n = calibrate_offset(offset_series(runs, window_long, window))
    if n < MIN_STEPS or not np.isfinite(mean).all():
        say(f"no offset test: {n} tested steps from {len(runs)} episode(s) (at least {MIN_STEPS} from 2 episodes "
            "needed)")
        return
    # in the profile's units (mm, deg); tune's put adds each value's 1σ to its entry
    data["offset"] = block = {"mean": {}, "sd": {}, "samples": {name: round(float(samples[a]), 3)
                                                               for a, (name, _, _) in enumerate(OFFSET_AXES)}}
    for a, key in enumerate(AXES):
        k = OFFSET_AXES[a][2]
        block["mean"][key] = {"value": float(mean[a] * k)}
        block["sd"][key] = {"value": float(sd[a] * k)}
        std_mean = sd[a] * k / math.sqrt(samples[a]) if samples[a] > 0 else None
        std_sd = sd[a] * k / math.sqrt(2.0 * max(samples[a] - 1.0, 1.0))
        put(f"offset.mean.{key}", float(mean[a] * k), std_mean, True)
        put(f"offset.sd.{key}", float(sd[a] * k), std_sd, True)
    alpha = float(settings.integrity_alpha_degraded)
    say(f"the offset test over {window_long} steps flags a change of the kinematics' offset of at least: "
        f"{_limits_text(offset_limits(samples, alpha) * sd)} (more episodes make it smaller)")
    E = len(runs)
    say("with more episodes like these it would flag about (projected: the same spread, its samples in proportion): "
        + "; ".join(f"{m} episodes: {_limits_text(projected_limits(sd, samples, E, m, alpha))}" for m in (2 * E, 3 * E)))
