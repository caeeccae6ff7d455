"""``seam tune``'s last step: what the lasers' innovations look like on the training episodes.

The integrity monitor's long window (:mod:`posekit.seam.engine.integrity`) tests each reading component (sensor
k's x and z) for a small inconsistency that persists, such as a latency nobody declared. Under the filter's own
model each step's ``u_j = ē_j² / C_jj`` is χ² with one degree of freedom and the steps are independent; on a real
cell neither holds exactly (the predictive covariance is the particle cloud's plus a modelled noise, and the
robot's unmodelled error is correlated in time), so a test against the textbook χ² is either blind (the
covariance overstates the innovations: on the independent cell of the tests the mean ``u`` is 0.8) or alarmed.
Here the filter, run with the fitted profile on the training episodes, measures per component:

- ``nis_mean`` ``c_j``: the mean of ``u_j`` (1σ: the larger of ``c √(2 / (ρ n))`` and the spread of the
  episodes' means over √episodes);
- ``nis_dof`` ``ρ_j = 2 / (τ var(u_j / c_j))``: the χ² degrees of freedom one reading is worth, from the
  variance (2 for a χ²₁) and the integrated autocorrelation time ``τ`` of the normalised series
  (:func:`posekit._autocorr.autocorrelation_time`, the mean over the episodes); 1σ: the spread of the episodes'
  own values over √episodes (none from one episode). From 3 or more episodes whose means spread wider than
  that ρ predicts (beyond the 95 % point of a χ² with episodes - 1 degrees of freedom), it is what their spread
  says, ``2 mean(1/n_e) / var(m_e / c_j)``: a wander slower than an episode (the robot's unmodelled error), or
  episodes unlike each other (two seam shapes), is not seen by ``τ`` (on posekit's own xy + yz episodes the
  bias statistic's ρ is 0.04-0.07 so, 0.13-0.17 from ``τ``).

The same for the bias test's statistic, the squared mean of the *signed* innovations ``ē_j / √C_jj`` over the
last ``filter.integrity_window`` steps (:func:`posekit.seam.engine.integrity.bias_series`): ``bias_mean`` and
``bias_dof``, and the window is written as the profile's ``bias_window``. A bias that changes slowly with the
motion (a latency nobody declared) is diluted in a squared innovation but stands out in its short mean.

A component with fewer than :data:`MIN_READINGS` readings keeps 1 and 1 (said so; without the bias calibration
the profile's ``bias_window`` is 0: no bias test). Steps the filter itself
reports ``lost`` are left out (the tests there are the short window's). With one sensor entry for every sensor
(``--share-sensors``) the x components of all sensors are pooled, and the z components.
"""

import math

import numpy as np
from scipy.stats import chi2

from posekit._autocorr import autocorrelation_time
from posekit.seam.engine.integrity import bias_series
from posekit.seam.frontend.tune_filter import run_filter

__all__ = ["BETWEEN_EPISODES", "BETWEEN_LEVEL", "MIN_READINGS", "bias_components", "calibrate_components", "fit_nis", "innovation_components"]

#: Readings a component needs for its innovations to be calibrated (fewer: 1 and 1 are kept).
MIN_READINGS = 100
#: Episodes from which the spread of their means also bounds the degrees of freedom (a variance needs a few).
BETWEEN_EPISODES = 3
#: The level at which that spread is found wider than the within-episode autocorrelation says.
BETWEEN_LEVEL = 0.05


def innovation_components(logs, profile, runs=None) -> list:
    """The particle filter's per-component NIS on each episode, run with ``profile``.

    Parameters
    ----------
    logs : list of EpisodeLog
        Recorded episodes (:func:`posekit.seam.frontend.logs.read_episode_log`); each is run with its own filter
        settings and seed.
    profile : posekit.seam.model.Profile
        The fitted profile.
    runs : list of FilterRun, optional
        The filter already run with ``profile`` over ``logs`` (:func:`~posekit.seam.frontend.tune_filter.run_filter`;
        the reported spread's factor may differ: it does not change the filter's path); run here when None.

    Returns
    -------
    list of ndarray, shape (T, 2 S)
        Per episode and step, sensor k's x (column ``2k``) and z (``2k + 1``) ``ē² / C`` (NaN: no reading, or a
        step reported ``lost``).
    """
    out = []
    for run in (runs if runs is not None else [run_filter(log, profile) for log in logs]):
        U = run.components.copy()
        U[np.asarray(run.status) == "lost"] = np.nan
        out.append(U)
    return out


def calibrate_components(series) -> tuple[float, float, float, float, int]:
    """``nis_mean`` and ``nis_dof`` with their 1σ and the readings used, from one component's series of every
    episode.

    Parameters
    ----------
    series : list of ndarray, shape (T,)
        Per episode the component's ``u`` in time order (NaN: no reading; left out).

    Returns
    -------
    mean, mean_std, dof, dof_std, n : float, float, float, float, int
        ``nan`` for the first four when there are fewer than 2 readings; ``dof_std`` is the spread of the episodes'
        own ``2 / (τ var)`` over √episodes (``nan`` with one episode).
    """
    eps = [np.asarray(s, dtype=np.float64) for s in series]
    eps = [s[np.isfinite(s)] for s in eps]
    eps = [s for s in eps if s.size]
    n = int(sum(s.size for s in eps))
    if n < 2:
        return math.nan, math.nan, math.nan, math.nan, n
    allu = np.concatenate(eps)
    c = float(allu.mean())
    if not c > 0.0:
        return math.nan, math.nan, math.nan, math.nan, n
    var = float(np.var(allu / c, ddof=1))
    tau = float(np.average([autocorrelation_time(s / c) for s in eps], weights=[s.size for s in eps]))
    rho = 2.0 / (tau * var) if var > 0.0 else math.nan
    std = c * math.sqrt(2.0 / (rho * n)) if math.isfinite(rho) else math.nan
    rho_std = math.nan
    if len(eps) >= 2:
        std = max(std, float(np.std([s.mean() for s in eps], ddof=1)) / math.sqrt(len(eps)))
        own = [2.0 / (autocorrelation_time(s / c) * float(np.var(s / c, ddof=1))) for s in eps if s.size >= 8]
        own = [r for r in own if math.isfinite(r)]
        if len(own) >= 2:
            rho_std = float(np.std(own, ddof=1)) / math.sqrt(len(own))
    # the episodes' own means must fit it too: under the model an episode's mean of n readings varies by
    # 2 / (ρ n) (relative variance). A wander slower than an episode, or episodes unlike each other, show as a
    # larger spread of the means than the autocorrelation within them predicts; where that spread is beyond its
    # 95 % point under the model (E - 1 degrees of freedom), ρ is what the spread says (1σ: a variance from E
    # episodes, √(2 / (E - 1)) relative)
    big = [s for s in eps if s.size >= 8]
    if len(big) >= BETWEEN_EPISODES and math.isfinite(rho):
        v = float(np.var([s.mean() / c for s in big], ddof=1))
        expected = 2.0 * float(np.mean([1.0 / s.size for s in big])) / rho
        k = len(big) - 1
        if v > expected * chi2.isf(BETWEEN_LEVEL, k) / k:
            rho = rho * expected / v
            rho_std = rho * math.sqrt(2.0 / k)
            std = max(std, c * math.sqrt(2.0 / (rho * n)))
    return c, std, rho, rho_std, n


def bias_components(runs, window: int) -> list:
    """Per episode the bias test's statistic (:func:`posekit.seam.engine.integrity.bias_series` of the signed
    innovations over ``window`` steps), shape (T, 2 S); NaN where the stretch has too few readings, and at steps
    reported ``lost`` (the monitor's own runs of that statistic go on through them; their tests are the short
    window's)."""
    out = []
    for run in runs:
        B = bias_series(run.innovations, window)
        B[np.asarray(run.status) == "lost"] = np.nan
        out.append(B)
    return out


def fit_nis(logs, profile, share: bool, put, runs=None) -> int:
    """Calibrate every sensor's ``nis_mean_x/z`` and ``nis_dof_x/z`` (see the module docstring), and the bias
    test's ``bias_mean_x/z`` and ``bias_dof_x/z`` over the episodes' ``filter.integrity_window`` steps, with
    ``put`` (:func:`posekit.seam.frontend.tune.tune_profile`'s); ``runs``: the filter already run with ``profile``.
    Returns the bias test's window (the profile's ``bias_window``; 0 when nothing was calibrated)."""
    from posekit.seam.frontend.tune_fit import _sensor_key

    runs = runs if runs is not None else [run_filter(log, profile) for log in logs]
    window = int(logs[0].config.filter.integrity_window) if logs else 0
    U = innovation_components(logs, profile, runs)
    B = bias_components(runs, window) if window else []
    S = U[0].shape[1] // 2 if U else 0
    entries = 1 if share else S
    calibrated = True
    for i in range(entries):
        for a, axis in enumerate("xz"):
            cols = [2 * k + a for k in (range(S) if share else (i,))]
            for name, stats in (("nis", U), ("bias", B)):
                c, c_std, rho, rho_std, n = calibrate_components([u[:, j] for u in stats for j in cols])
                if n < MIN_READINGS or not (math.isfinite(c) and math.isfinite(rho)):
                    why = f"{n} readings (at least {MIN_READINGS} needed): the model's own chi2 is kept"
                    put(_sensor_key(i, f"{name}_mean_{axis}"), 1.0, None, False, why)
                    put(_sensor_key(i, f"{name}_dof_{axis}"), 1.0, None, False, why)
                    calibrated = calibrated and name == "nis"     # no bias test without its calibration
                    continue
                put(_sensor_key(i, f"{name}_mean_{axis}"), c, c_std, True)
                put(_sensor_key(i, f"{name}_dof_{axis}"), rho, rho_std, True)
    return window if calibrated else 0
