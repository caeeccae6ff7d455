"""Trajectory files in the formats real systems write, read into one :class:`Trajectory` (mm, s).

==========  ====================================================  =========================
format      file                                                  default for
==========  ====================================================  =========================
``tum``     ``timestamp tx ty tz qx qy qz qw`` (s, m)             ``.tum``, ``.txt``
``kitti``   3x4 ``[R | t]`` row by row (m), no time: ``rate_hz``  (``--format kitti``)
``euroc``   EuRoC ground-truth CSV (ns, m, ``qw qx qy qz``)       ``.csv``
``rosbag``  a pose topic of a ROS 1/2 bag (``rosbags`` package)   ``.bag``, ``.db3``,
                                                                  ``.mcap``, a bag folder
==========  ====================================================  =========================

Every reader converts metres to millimetres and checks each record (finite numbers, unit
quaternions or rotation matrices, non-decreasing time), failing in one line that names the file
and the record (``FILE:LINE:`` or ``FILE: message K on TOPIC:``).

Without ``--format`` the rows decide (:mod:`.sniff`: a ``.csv`` of TUM rows is TUM); the suffix
only when the rows do not. When the two disagree, the rows win and a note says so.
"""

from pathlib import Path

from posekit.errors import InputFileError, TrajectoryError
from posekit.localcal.model.trajectory import Trajectory

from .euroc import read_euroc, write_euroc
from .kitti import read_kitti, write_kitti
from .rosbag import BAG_SUFFIXES, POSE_TYPES, is_bag, read_rosbag
from .sniff import sniff_format
from .tum import read_tum, write_tum

__all__ = [
    "FORMATS",
    "BAG_SUFFIXES",
    "POSE_TYPES",
    "Trajectory",
    "detect_format",
    "read_trajectory",
    "read_tum",
    "write_tum",
    "read_kitti",
    "write_kitti",
    "read_euroc",
    "write_euroc",
    "read_rosbag",
    "is_bag",
    "sniff_format",
]

#: Format names accepted by :func:`read_trajectory` (``--format``).
FORMATS = ("tum", "kitti", "euroc", "rosbag")
_SUFFIXES = {".tum": "tum", ".txt": "tum", ".csv": "euroc", ".kitti": "kitti",
             **{s: "rosbag" for s in BAG_SUFFIXES}}
_NAMES = {"tum": "TUM", "kitti": "KITTI", "euroc": "EuRoC"}


def detect_format(path, notes: list | None = None) -> str:
    """The format of a trajectory input: a bag by its suffix or folder, a text file by its rows
    (:func:`.sniff.sniff_format`), else by its suffix.

    Parameters
    ----------
    path : str or Path
    notes : list, optional
        Receives one line when the rows contradict the suffix (the rows win).

    Raises
    ------
    InputFileError
        For a file whose rows and suffix say nothing known, or a folder that is not a ROS 2 bag.
    """
    path = Path(path)
    if path.is_dir():
        if is_bag(path):
            return "rosbag"
        raise InputFileError(f"{path}: a folder without metadata.yaml; expected a trajectory file or a "
                             "ROS 2 bag folder")
    fmt = _SUFFIXES.get(path.suffix.lower())
    if fmt == "rosbag":
        return fmt
    rows = sniff_format(path)
    if rows is not None:
        if fmt is not None and rows != fmt and notes is not None:
            notes.append(f"{path}: {_NAMES[rows]} rows, though the suffix '{path.suffix}' suggests {_NAMES[fmt]}: "
                         f"read as {_NAMES[rows]} (give --format to choose)")
        return rows
    if fmt is None:
        raise InputFileError(f"{path}: cannot tell the trajectory format from the suffix "
                             f"'{path.suffix}'; expected .tum/.txt (TUM), .csv (EuRoC), .bag/.db3/.mcap "
                             "or a bag folder (ROS), or give --format tum|kitti|euroc|rosbag")
    return fmt


def read_trajectory(path, fmt: str | None = None, topic: str | None = None,
                    rate_hz: float | None = None, tf_parent: str | None = None,
                    tf_child: str | None = None, notes: list | None = None) -> Trajectory:
    """Read a trajectory file in any supported format.

    Parameters
    ----------
    path : str or Path
        A file, or a ROS 2 bag folder.
    fmt : {'tum', 'kitti', 'euroc', 'rosbag'}, optional
        The format; from the rows (and the suffix) by default (:func:`detect_format`).
    topic : str, optional
        The pose topic of a bag (may be left out when the bag has one pose topic); ignored by
        the other formats.
    rate_hz : float, optional
        Frame rate of a KITTI file, Hz (required for KITTI; ignored by the formats with time).
    tf_parent, tf_child : str, optional
        A bag's transform ``T_parent_child`` from ``/tf`` + ``/tf_static`` instead of a pose topic.
    notes : list, optional
        Receives what was decided for the user (a format the rows chose against the suffix).

    Returns
    -------
    Trajectory
        Timestamps in s, poses ``T_world_body`` in mm.

    Raises
    ------
    InputFileError
        A bad file, naming the file and the record.
    TrajectoryError
        An unknown format, or KITTI without ``rate_hz``.
    """
    sniffed = fmt is None
    if fmt is None:
        fmt = detect_format(path, notes)
    if fmt == "kitti" and rate_hz is None and sniffed:
        raise TrajectoryError(f"{path}: rows of 12 numbers, a KITTI pose file, which carries no time: give its "
                              "frame rate with --rate-hz HZ")
    if fmt == "tum":
        return read_tum(path)
    if fmt == "kitti":
        return read_kitti(path, rate_hz)
    if fmt == "euroc":
        return read_euroc(path)
    if fmt == "rosbag":
        return read_rosbag(path, topic, tf_parent, tf_child)
    if tf_parent is not None or tf_child is not None:
        raise TrajectoryError(f"{path}: --tf-parent/--tf-child read a ROS bag; this is a {fmt} file")
    raise TrajectoryError(f"unknown trajectory format {fmt!r}; expected one of {', '.join(FORMATS)}")
