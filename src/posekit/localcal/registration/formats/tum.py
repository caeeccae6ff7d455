"""The TUM RGB-D trajectory file format.

A TUM file holds one pose per line, ``timestamp tx ty tz qx qy qz qw``: seconds, metres, and a
unit quaternion scalar last; blank lines and lines starting with ``#`` are ignored. Inside posekit
a trajectory is a :class:`~posekit.localcal.model.trajectory.Trajectory` in millimetres with 4x4
poses (the quaternion converted). The other formats (KITTI, EuRoC, ROS bags) are read by the
sibling modules of this package.
"""

from pathlib import Path

import numpy as np

from posekit.errors import InputFileError
from posekit.geometry import quaternion_from_matrix, transform_from_quaternion
from posekit.io import check_rows, read_text
from posekit.localcal.model.trajectory import Trajectory

from ._rows import MAX_POSITION_M, QUATERNION_NORM_TOL, parse_lines

__all__ = ["read_tum", "write_tum"]

_LAYOUT = "8 numbers 'timestamp tx ty tz qx qy qz qw'"
_FIELD_HINTS = {12: "; 12 numbers per line look like a KITTI pose file: give --format kitti --rate-hz HZ"}


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
        a NaN or infinite value, a quaternion whose norm is not 1, a position beyond 1e9 m, or a
        timestamp earlier than the previous one. The message names ``file:line``.
    """
    path = Path(path)
    text = read_text(path, expected="a TUM trajectory file ('timestamp tx ty tz qx qy qz qw' per line)")
    check_rows(text, str(path), "poses (one per line)", error=InputFileError)
    fast = _read_tum_fast(text)
    if fast is not None:
        return fast
    a, lines = parse_lines(path, text, 8, _LAYOUT, field_hints=_FIELD_HINTS,
                           expected_lines="'timestamp tx ty tz qx qy qz qw'")
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
