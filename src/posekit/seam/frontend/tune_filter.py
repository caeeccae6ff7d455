"""The particle filter run over recorded episodes with a candidate profile: what ``seam tune``'s steps that judge
the filter itself (spread factors, the integrity test's calibration, a latency's effect on the pose) share."""

from dataclasses import dataclass

import numpy as np

__all__ = ["FilterRun", "run_filter"]


@dataclass
class FilterRun:
    """The particle filter over one recorded episode.

    Attributes
    ----------
    estimate, nominal : ndarray, shape (T, 4, 4)
        Estimated and nominal tool poses ``T_base_tool`` per step, mm.
    spread : ndarray, shape (T, 6)
        Reported spread: x, y, z (mm), rx, ry, rz (rad).
    status : list of str
        Per step ``tracking`` / ``degraded`` / ``lost``.
    components : ndarray, shape (T, 2 S)
        Per step sensor k's x (column ``2k``) and z (``2k + 1``) normalised squared innovation (NaN: no reading).
    """

    estimate: np.ndarray
    nominal: np.ndarray
    spread: np.ndarray
    status: list
    components: np.ndarray


def run_filter(log, profile) -> FilterRun:
    """Run the particle filter over ``log`` (:func:`posekit.seam.frontend.logs.read_episode_log`) with ``profile``
    (:class:`posekit.seam.model.Profile`) in place of the episode's own, with the episode's filter settings and
    seed and every input the log has (lasers at their stamps, angles, torques)."""
    from posekit.seam.frontend.tracker import SeamTracker

    tr = SeamTracker(log.config, log.seam_mm, seed=log.setup.seed, seam_normal=log.setup.seam_normal)
    tr.profile = profile
    T = len(log.time_s)
    S = log.config.cell.sensors.count
    est, nom = np.empty((T, 4, 4)), np.empty((T, 4, 4))
    spread = np.empty((T, 6))
    comp = np.full((T, 2 * S), np.nan)
    status = []
    for k in range(T):
        r = tr.step(log.time_s[k], log.qref[k], log.q[k], log.force_tool_n[k],
                    laser_mm=log.laser_mm[k] if log.laser_mm.shape[1] else None,
                    angle_rad=None if log.angle_rad is None else log.angle_rad[k],
                    torque_tool_nm=None if log.torque_tool_nm is None else log.torque_tool_nm[k],
                    reading_time_s=None if log.reading_time_s is None else log.reading_time_s[k])
        est[k], nom[k], spread[k] = r.T_base_tool, r.T_nominal, r.spread
        status.append(r.status)
        if r.raw.nis_components is not None:
            comp[k] = r.raw.nis_components
    return FilterRun(est, nom, spread, status, comp)
