"""EuRoC MAV ground-truth CSV (``state_groundtruth_estimate0/data.csv``, ``vicon0/data.csv``):
``#timestamp [ns], p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [],
q_RS_z []`` and optionally velocities and biases after them (ignored)."""

from pathlib import Path

import numpy as np

from posekit.errors import InputFileError
from posekit.io import check_rows, read_text

from ..tum import Trajectory
from ._rows import parse_numbers, trajectory_from_rows

__all__ = ["read_euroc", "write_euroc"]

_LAYOUT = "at least 8 comma-separated numbers 'timestamp_ns, px, py, pz, qw, qx, qy, qz'"


def read_euroc(path) -> Trajectory:
    """Read a EuRoC ground-truth CSV file (ns, m, quaternion ``w x y z``).

    Parameters
    ----------
    path : str or Path
        The file; ``#`` comment lines (the EuRoC header) and blank lines are skipped, and so is
        a first line of column names without ``#``.

    Returns
    -------
    Trajectory
        Timestamps in s (ns / 1e9), poses ``T_world_body`` in mm (metres x 1000).

    Raises
    ------
    InputFileError
        ``FILE:LINE:`` for the first row that is not 8 finite numbers, has a non-unit
        quaternion or a timestamp earlier than the previous one.
    """
    path = Path(path)
    text = read_text(path, expected=f"a EuRoC ground-truth CSV file ({_LAYOUT} per line)")
    check_rows(text, str(path), "poses (one per line)", error=InputFileError)      # before splitting
    lines = text.splitlines()
    for i, raw in enumerate(lines):            # a header of column names without '#'
        s = raw.strip()
        if s:
            if s[0].isalpha():
                lines[i] = "#" + raw
            break
    rows, numbers = parse_numbers(path, "\n".join(lines), 8, _LAYOUT, at_least=True, separator=",")
    return trajectory_from_rows(path, rows[:, 0] / 1e9, rows[:, 1:4], rows[:, 4:8], [str(n) for n in numbers])


def write_euroc(path, traj: Trajectory) -> None:
    """Write ``traj`` as a EuRoC ground-truth CSV (ns, m, ``w x y z``) with its header line.

    Parameters
    ----------
    path : str or Path
        Output file, written atomically.
    traj : Trajectory
        Timestamps in s, poses ``T_world_body`` in mm.
    """
    from posekit.geometry import quaternion_from_matrix
    from posekit.io import atomic_file

    q = quaternion_from_matrix(traj.rotations)
    ns = np.round(traj.t_s * 1e9).astype(np.int64)
    with atomic_file(path, "w") as fh:
        fh.write("#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n")
        for k in range(len(traj)):
            p = traj.positions[k] / 1000.0
            fh.write(f"{ns[k]:d}," + ",".join(f"{v:.12g}" for v in (*p, *q[k])) + "\n")
