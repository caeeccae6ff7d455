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
    innovations : ndarray, shape (T, 2 S)
        The same signed and not squared.
    kinematic : ndarray, shape (T, 4, 4) or None
        The kinematic poses ``Fk(q + Cj(τ))`` per step, mm.
    """

    estimate: np.ndarray
    nominal: np.ndarray
    spread: np.ndarray
    status: list
    components: np.ndarray
    innovations: np.ndarray
    kinematic: np.ndarray | None = None


def run_filter(log, profile) -> FilterRun:
    """Run the particle filter over ``log`` (:func:`posekit.seam.frontend.logs.read_episode_log`) with ``profile``
    (:class:`posekit.seam.model.Profile`) in place of the episode's own: :func:`~posekit.seam.frontend.tracker.
    track_log` (the episode's filter settings and seed, every input the log has), keeping each step's innovations."""
    from posekit.seam.frontend.tracker import track_log

    comp = np.full((len(log.time_s), 2 * log.config.cell.sensors.count), np.nan)
    signed = comp.copy()

    def keep(k, est):
        if est.raw.nis_components is not None:
            comp[k] = est.raw.nis_components
        if est.raw.innovations is not None:
            signed[k] = est.raw.innovations

    r = track_log(log, on_step=keep, profile=profile)
    return FilterRun(r.estimate, r.nominal, r.spread, r.status, comp, signed, r.kinematic)
