"""Tool-pose errors and pose coordinates in the nominal seam frame (the seam contract's frame).

Errors are in the nominal seam frame (DESIGN/SEAM contract): translation
``R_nomᵀ (p_est - p_true)`` in mm, rotation vector of ``R_trueᵀ R_est`` in radians (the library's
unit); the metrics, the CSV tables, the plots and the printed tables show degrees (:func:`to_degrees`).
"""

import numpy as np

from posekit.geometry import rotation_vector_from_matrix

__all__ = ["AXES", "pose_coords", "seam_frame_errors", "to_degrees"]

AXES = ("x", "y", "z", "rx", "ry", "rz")


def seam_frame_errors(T_est: np.ndarray, T_true: np.ndarray, T_nom: np.ndarray) -> np.ndarray:
    """Tool-pose errors in the nominal seam frame (the errors of the paper's Fig. 8; see
    :func:`~posekit.seam.frontend.episode_metrics.metrics`).

    Parameters
    ----------
    T_est, T_true, T_nom : ndarray, shape (T, 4, 4)
        Estimated, true and nominal tool poses ``T_base_tool`` per step, mm.

    Returns
    -------
    ndarray, shape (T, 6)
        ``[x, y, z]`` = ``R_nomᵀ (p_est - p_true)`` in mm (x across, y along the seam, z along the
        tool axis), then ``[rx, ry, rz]`` = rotation vector of ``R_trueᵀ R_est`` in **radians**
        (the library's unit, as in :class:`~posekit.seam.frontend.episode.EpisodeResult`; the reports show degrees).
    """
    dp = np.matmul(np.swapaxes(T_nom[:, :3, :3], 1, 2), (T_est[:, :3, 3] - T_true[:, :3, 3])[..., None])[..., 0]
    dr = rotation_vector_from_matrix(np.matmul(np.swapaxes(T_true[:, :3, :3], 1, 2), T_est[:, :3, :3]), check=False)
    return np.concatenate([dp, dr], axis=-1)


def pose_coords(Ts: np.ndarray, T_nom: np.ndarray) -> np.ndarray:
    """Offsets of poses from nominal poses, in the nominal frame (Fig. 5 coordinates).

    Parameters
    ----------
    Ts : ndarray, shape (..., 4, 4)
        Tool poses ``T_base_tool`` (particles, truth or estimate), mm.
    T_nom : ndarray, shape (..., 4, 4)
        Nominal tool poses, broadcastable against ``Ts``, mm.

    Returns
    -------
    ndarray, shape (..., 6)
        ``R_nomᵀ (p - p_nom)`` in mm, then the rotation vector of ``R_nomᵀ R`` in **radians**.
    """
    Rn_t = np.swapaxes(T_nom[..., :3, :3], -1, -2)
    dp = np.matmul(Rn_t, (Ts[..., :3, 3] - T_nom[..., :3, 3])[..., None])[..., 0]
    dr = rotation_vector_from_matrix(np.matmul(Rn_t, Ts[..., :3, :3]), check=False)
    return np.concatenate([dp, dr], axis=-1)


def to_degrees(a: np.ndarray) -> np.ndarray:
    """A copy of ``[mm, mm, mm, rad, rad, rad]`` rows as ``[mm, mm, mm, deg, deg, deg]`` (the report edge).

    Parameters
    ----------
    a : array_like, shape (..., 6)
        Seam-frame errors, spreads or pose coordinates in the library's units (mm, rad).

    Returns
    -------
    ndarray, shape (..., 6)
        The same values with the last three (rotations) in degrees; float64, a new array.
    """
    a = np.array(a, dtype=np.float64, copy=True)
    a[..., 3:] = np.degrees(a[..., 3:])
    return a
