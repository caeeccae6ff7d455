"""Checks and conversions of the arguments of :meth:`~posekit.ceiling.track.Tracker.step`."""

import numpy as np

from ...errors import GeometryError

__all__ = ["_as_candidates", "_as_eligible", "_as_covariances"]


def _as_candidates(value, colour: str) -> np.ndarray:
    """(K, 2) float array of candidate world positions (K may be 0)."""
    if value is None:
        return np.zeros((0, 2))
    z = np.asarray(value, dtype=float)
    if z.ndim == 1 and z.shape == (2,):
        z = z[None, :]
    if z.ndim != 2 or z.shape[1] != 2:
        raise GeometryError(f"Tracker.step: dots_world[{colour!r}] must have shape (2,) or (K, 2) "
                            f"(x, y in mm), got shape {np.shape(value)}")
    return z[np.all(np.isfinite(z), axis=1)]


def _as_eligible(value, raw, k: int) -> np.ndarray:
    """(K,) bool flags of the finite candidates (all True by default)."""
    if value is None:
        return np.ones(k, bool)
    e = np.asarray(value, dtype=bool).reshape(-1)
    if raw is not None:
        zr = np.asarray(raw, dtype=float).reshape(-1, 2)
        if e.shape[0] == zr.shape[0]:
            e = e[np.all(np.isfinite(zr), axis=1)]
    if e.shape[0] != k:
        raise GeometryError(f"Tracker.step: eligible flags for {e.shape[0]} candidate(s), expected {k}")
    return e


def _as_covariances(value, k: int, colour: str, default_std: float, floor: float) -> np.ndarray:
    """(K, 2, 2) measurement covariances (default isotropic), floored at ``floor²``."""
    if value is None:
        R = np.broadcast_to(default_std ** 2 * np.eye(2), (k, 2, 2)).copy()
    else:
        R = np.asarray(value, dtype=float)
        if R.shape == (2, 2):
            R = np.broadcast_to(R, (k, 2, 2)).copy()
        if R.shape != (k, 2, 2) or not np.all(np.isfinite(R)):
            raise GeometryError(f"Tracker.step: meas_cov[{colour!r}] must be finite with shape (2, 2) "
                                f"or ({k}, 2, 2) (mm²), got shape {np.shape(value)}")
    return R + floor ** 2 * np.eye(2)
