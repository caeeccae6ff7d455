"""Pose trajectories and the TUM RGB-D trajectory file format.

A TUM file holds one pose per line, ``timestamp tx ty tz qx qy qz qw``: seconds, metres, and a
unit quaternion scalar last; blank lines and lines starting with ``#`` are ignored. Inside posekit
a trajectory is a :class:`Trajectory` in millimetres with 4x4 poses (the quaternion converted).
The other formats (KITTI, EuRoC, ROS bags) are read by :mod:`.formats`.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posekit.errors import InputFileError, TrajectoryError
from posekit.geometry import quaternion_from_matrix, transform_from_quaternion
from posekit.io import check_rows, parse_number, read_text

__all__ = ["Trajectory", "read_tum", "write_tum"]

#: Largest accepted deviation of a file quaternion's norm from 1 (files keep 4-9 decimals).
QUATERNION_NORM_TOL = 1e-2


@dataclass(frozen=True)
class Trajectory:
    """A timed sequence of rigid poses of one body.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Timestamps, s, non-decreasing.
    T : ndarray, shape (N, 4, 4)
        Poses ``T_world_body``: the body frame expressed in the trajectory's world frame, mm.
    """

    t_s: np.ndarray
    T: np.ndarray

    def __post_init__(self):
        t = np.asarray(self.t_s, dtype=np.float64)
        T = np.asarray(self.T, dtype=np.float64)
        if t.ndim != 1 or T.shape != (t.size, 4, 4):
            raise TrajectoryError(f"a trajectory needs t_s of shape (N,) and T of shape (N, 4, 4), "
                                  f"got {t.shape} and {T.shape}")
        if not (np.isfinite(t).all() and np.isfinite(T).all()):
            raise TrajectoryError("a trajectory must be finite: found NaN or infinite timestamps or poses")
        if t.size > 1 and np.any(np.diff(t) < 0):
            k = int(np.flatnonzero(np.diff(t) < 0)[0]) + 1
            raise TrajectoryError(f"trajectory timestamps must not decrease: pose {k} has "
                                  f"t={t[k]:.6f} s after t={t[k - 1]:.6f} s")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "T", T)

    def __len__(self) -> int:
        return self.t_s.size

    @property
    def positions(self) -> np.ndarray:
        """Body origins in the world frame, shape (N, 3), mm."""
        return self.T[:, :3, 3]

    @property
    def rotations(self) -> np.ndarray:
        """Body orientations ``R_world_body``, shape (N, 3, 3)."""
        return self.T[:, :3, :3]


#: Largest position a trajectory file may hold, m (as the other formats' readers: beyond it the
#: numbers are not metres, and squaring them overflows).
MAX_POSITION_M = 1e9


def _fail(path, line: int, what: str) -> InputFileError:
    return InputFileError(f"{path}:{line}: {what}")


def read_tum(path) -> Trajectory:
    """Read a TUM trajectory file (``timestamp tx ty tz qx qy qz qw``, s, m).

    Parameters
    ----------
    path : str or Path
        The file. ``#`` comment lines and blank lines are skipped.

    Returns
    -------
    Trajectory
        Timestamps in s, poses ``T_world_body`` in mm (metres x 1000).

    Raises
    ------
    InputFileError
        If the file is missing or unreadable, has no pose, or a row is malformed: not 8 numbers,
        a NaN or infinite value, a quaternion whose norm is not 1, a position beyond
        :data:`MAX_POSITION_M`, or a timestamp earlier than the previous one. The message names
        ``file:line``.
    """
    path = Path(path)
    text = read_text(path, expected="a TUM trajectory file ('timestamp tx ty tz qx qy qz qw' per line)")
    check_rows(text, str(path), "poses (one per line)", error=InputFileError)
    fast = _read_tum_fast(text)
    if fast is not None:
        return fast
    rows, lines = [], []
    for number, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        fields = s.replace(",", " ").split()
        if len(fields) != 8:
            hint = ("; 12 numbers per line look like a KITTI pose file: give --format kitti --rate HZ"
                    if len(fields) == 12 else "")
            raise _fail(path, number, f"expected 8 numbers 'timestamp tx ty tz qx qy qz qw', "
                                      f"found {len(fields)} fields{hint}")
        try:
            rows.append([parse_number(f) for f in fields])
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise _fail(path, number, f"expected 8 numbers 'timestamp tx ty tz qx qy qz qw', "
                                      f"found '{bad}'") from None
        lines.append(number)
    if not rows:
        raise InputFileError(f"{path}: no poses found (expected lines 'timestamp tx ty tz qx qy qz qw')")
    a = np.asarray(rows)
    lines = np.asarray(lines)
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise _fail(path, lines[k], "expected finite numbers, found NaN or infinity")
    norm = np.linalg.norm(a[:, 4:8], axis=1)
    bad = np.abs(norm - 1.0) > QUATERNION_NORM_TOL
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise _fail(path, lines[k], f"expected a unit quaternion qx qy qz qw, found norm {norm[k]:.4g}")
    big = np.abs(a[:, 1:4]).max(axis=1) > MAX_POSITION_M
    if big.any():
        k = int(np.flatnonzero(big)[0])
        raise _fail(path, lines[k], f"position {np.abs(a[k, 1:4]).max():.3g} m is implausible; expected metres")
    back = np.diff(a[:, 0]) < 0
    if back.any():
        k = int(np.flatnonzero(back)[0]) + 1
        raise _fail(path, lines[k], f"timestamps must not decrease: {a[k, 0]:.6f} s after "
                                    f"{a[k - 1, 0]:.6f} s (line {lines[k - 1]})")
    return Trajectory(a[:, 0], transform_from_quaternion(a[:, [7, 4, 5, 6]], a[:, 1:4] * 1000.0))


def _read_tum_fast(text: str):
    """A well-formed TUM text parsed in C (``np.loadtxt``, 1e6 rows in ~1 s and ~250 MB instead of
    ~10 s and ~1 GB); None when anything is unusual (a comma, a ``#`` after data, a bad row), so that
    the line-by-line reader of :func:`read_tum` names the line."""
    import io
    import re
    import warnings

    if "," in text or text.count("#") != len(re.findall(r"^[ \t]*#", text, re.M)):
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a = np.loadtxt(io.BytesIO(text.encode()), comments="#", ndmin=2, dtype=np.float64, encoding="utf-8")
    except ValueError:
        return None
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] != 8 or not np.isfinite(a).all():
        return None
    if (np.any(np.abs(np.linalg.norm(a[:, 4:8], axis=1) - 1.0) > QUATERNION_NORM_TOL)
            or np.any(np.diff(a[:, 0]) < 0) or np.any(np.abs(a[:, 1:4]) > MAX_POSITION_M)):
        return None
    return Trajectory(a[:, 0], transform_from_quaternion(a[:, [7, 4, 5, 6]], a[:, 1:4] * 1000.0))


def _is_float(text: str) -> bool:
    try:
        parse_number(text)
    except ValueError:
        return False
    return True


def write_tum(path, traj: Trajectory) -> None:
    """Write ``traj`` as a TUM file (s, m, ``qx qy qz qw``) with a header comment.

    Parameters
    ----------
    path : str or Path
        Output file (overwritten).
    traj : Trajectory
        Timestamps in s and poses ``T_world_body`` in mm.
    """
    q = quaternion_from_matrix(traj.rotations)
    data = np.column_stack([traj.t_s, traj.positions / 1000.0, q[:, 1:4], q[:, :1]])
    from posekit.io import atomic_file

    with atomic_file(path, "w") as fh:
        fh.write("# timestamp tx ty tz qx qy qz qw (s, m)\n")
        np.savetxt(fh, data, fmt=["%.6f"] + ["%.9f"] * 7)
