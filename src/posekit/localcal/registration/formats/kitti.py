"""KITTI odometry pose files: one pose per line, the 3x4 matrix ``[R | t]`` row by row
(``r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz``), metres, no time; the time comes from the
frame rate the user gives."""

from pathlib import Path

import numpy as np

from posekit.errors import InputFileError, TrajectoryError
from posekit.geometry import nearest_rotation, transform_from
from posekit.io import read_text
from posekit.localcal.model.trajectory import Trajectory

from ._rows import MAX_POSITION_M, parse_numbers

__all__ = ["ROTATION_TOL", "read_kitti", "write_kitti"]

#: Largest accepted deviation of a file's rotation from orthonormality, max |R^T R - I|
#: (files keep 6-9 significant digits).
ROTATION_TOL = 1e-3
_LAYOUT = "12 numbers 'r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz'"


def read_kitti(path, rate_hz: float, *, t0_s: float = 0.0) -> Trajectory:
    """Read a KITTI pose file; frame ``k`` is at ``t0_s + k / rate_hz``.

    Parameters
    ----------
    path : str or Path
        The file; blank lines and ``#`` comments are skipped.
    rate_hz : float
        Frame rate, Hz (> 0): KITTI files carry no time.
    t0_s : float
        Time of the first pose, s.

    Returns
    -------
    Trajectory
        Poses ``T_world_body`` in mm (metres x 1000), the rotation projected onto SO(3).

    Raises
    ------
    InputFileError
        ``FILE:LINE:`` for a row that is not 12 finite numbers, whose position is beyond 1e9 m,
        or whose rotation is not orthonormal with determinant +1 (within :data:`ROTATION_TOL`).
    TrajectoryError
        If ``rate_hz`` is missing, not finite or not positive.
    """
    path = Path(path)
    if rate_hz is None:
        raise TrajectoryError(f"{path}: a KITTI pose file carries no time; give its frame rate with --rate-hz HZ")
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        raise TrajectoryError(f"{path}: expected a KITTI frame rate > 0 Hz, got {rate_hz:g}")
    text = read_text(path, expected=f"a KITTI pose file ({_LAYOUT} per line)")
    rows, lines = parse_numbers(path, text, 12, _LAYOUT)
    bad = ~np.isfinite(rows).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputFileError(f"{path}:{lines[k]}: expected finite numbers, found NaN or infinity")
    M = rows.reshape(-1, 3, 4)
    big = np.abs(M[:, :, 3]).max(axis=1) > MAX_POSITION_M
    if big.any():
        k = int(np.flatnonzero(big)[0])
        raise InputFileError(f"{path}:{lines[k]}: position {np.abs(M[k, :, 3]).max():.3g} m is implausible; "
                             "expected metres")
    R = M[:, :, :3]
    err = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = (err > ROTATION_TOL) | (det <= 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputFileError(f"{path}:{lines[k]}: expected a rotation matrix in columns 1-3, 5-7, 9-11, "
                             f"found max |R^T R - I| = {err[k]:.3g}, det {det[k]:.4g}")
    T = transform_from(nearest_rotation(R), M[:, :, 3] * 1000.0, check=False)
    return Trajectory(t0_s + np.arange(M.shape[0]) / float(rate_hz), T)


def write_kitti(path, traj: Trajectory) -> None:
    """Write ``traj`` as a KITTI pose file (m; the timestamps are dropped).

    Parameters
    ----------
    path : str or Path
        Output file, written atomically.
    traj : Trajectory
        Poses ``T_world_body`` in mm.
    """
    from posekit.io import atomic_file

    M = traj.T[:, :3, :].copy()
    M[:, :, 3] /= 1000.0
    with atomic_file(path, "w") as fh:
        np.savetxt(fh, M.reshape(-1, 12), fmt="%.12e")
