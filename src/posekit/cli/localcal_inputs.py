"""Trajectory input flags shared by the ``localcal`` verbs that read two trajectories.

``--format tum|kitti|euroc|rosbag``, ``--topic TOPIC``, ``--rate-hz HZ`` and ``--tf-parent`` /
``--tf-child`` apply to both inputs; ``--camera-format``/``--kinematic-format``,
``--camera-topic``/``--kinematic-topic``, ``--camera-rate-hz``/``--kinematic-rate-hz`` and
``--camera-tf-parent``/``--kinematic-tf-parent`` (``-tf-child`` likewise) override them for one
input (e.g. two topics of the same bag, or a KITTI camera file beside a TUM kinematic log). The
format defaults to the file's content (TUM, KITTI and EuRoC rows tell themselves apart) and its
suffix.
"""

from ._common import add_deprecated
from ._flags import bounded_float, check_flags

__all__ = ["ROLES", "add_pair_args", "add_trajectory_args", "print_result", "read_options", "read_trajectory_args"]

#: The positional arguments the per-input flags are named after.
ROLES = ("camera", "kinematic")
_FORMATS = ("tum", "kitti", "euroc", "rosbag")


def add_trajectory_args(parser, roles=ROLES) -> None:
    """Add the trajectory-format flags to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The verb's parser; its positional arguments are named after ``roles``.
    roles : sequence of str
        Names of the inputs that get per-input overrides (``--<role>-format`` etc.).
    """
    g = parser.add_argument_group(
        "trajectory formats",
        "TUM (.tum/.txt: timestamp tx ty tz qx qy qz qw, s, m), KITTI (3x4 [R|t] per line, m, no time), "
        "EuRoC ground-truth CSV (.csv: ns, m, qw qx qy qz), ROS 1/2 bags (.bag/.db3/.mcap or a bag folder)")
    g.add_argument("--format", choices=_FORMATS, default=None,
                   help="format of both inputs (default: from each file's suffix)")
    g.add_argument("--topic", default=None, metavar="TOPIC",
                   help="pose topic of a bag input: PoseStamped, Odometry or TransformStamped "
                        "(default: the bag's only pose topic)")
    rate = bounded_float(0.0, 1e6, "Hz", lo_open=True, flag="--rate-hz")
    g.add_argument("--rate-hz", dest="rate", type=rate, default=None, metavar="HZ",
                   help="frame rate of a KITTI input (which carries no time), (0, 1e6] Hz")
    add_deprecated(g, "--rate", "--rate-hz", "rate", rate)
    g.add_argument("--tf-parent", default=None, metavar="FRAME",
                   help="bag input: read the transform FRAME -> --tf-child from /tf and /tf_static "
                        "(composed along the frame tree at each stamp) instead of a pose topic")
    g.add_argument("--tf-child", default=None, metavar="FRAME", help="bag input: the child frame (with --tf-parent)")
    for role in roles:
        g.add_argument(f"--{role}-format", choices=_FORMATS, default=None, help=f"format of {role.upper()} only")
        g.add_argument(f"--{role}-topic", default=None, metavar="TOPIC", help=f"bag topic of {role.upper()} only")
        rate = bounded_float(0.0, 1e6, "Hz", lo_open=True, flag=f"--{role}-rate-hz")
        g.add_argument(f"--{role}-rate-hz", dest=f"{role}_rate", type=rate, default=None, metavar="HZ",
                       help=f"KITTI frame rate of {role.upper()} only")
        add_deprecated(g, f"--{role}-rate", f"--{role}-rate-hz", f"{role}_rate", rate)
        g.add_argument(f"--{role}-tf-parent", default=None, metavar="FRAME", help=f"tf parent frame of {role.upper()} only")
        g.add_argument(f"--{role}-tf-child", default=None, metavar="FRAME", help=f"tf child frame of {role.upper()} only")


def _role(args, path, role):
    if role is not None:
        return role
    matches = [r for r in ROLES if getattr(args, r, None) is not None and str(getattr(args, r)) == str(path)]
    if len(matches) > 1:               # one bag for both inputs: camera first, then kinematic
        done = getattr(args, "_trajectory_roles_read", set())
        matches = [r for r in matches if r not in done] or matches
    return matches[0] if matches else None


def read_options(args, role: str | None) -> dict:
    """``read_trajectory``'s keyword arguments for the input ``role`` (``camera``/``kinematic``): its
    own ``--<role>-format`` etc. where given, else the shared ``--format`` etc. (only those with
    ``role`` None)."""
    def pick(name):
        own = getattr(args, f"{role}_{name}", None) if role else None
        return own if own is not None else getattr(args, name, None)

    return {"fmt": pick("format"), "topic": pick("topic"), "rate_hz": pick("rate"), "tf_parent": pick("tf_parent"),
            "tf_child": pick("tf_child")}


def read_trajectory_args(args, path, role: str | None = None):
    """Read ``path`` with the format flags in ``args``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed by a parser that :func:`add_trajectory_args` extended.
    path : str or Path
        The input.
    role : str, optional
        Which input this is (``"camera"``/``"kinematic"``), for the per-input overrides;
        found by comparing ``path`` with ``args.camera``/``args.kinematic`` by default; when both
        name the same file (two topics of one bag), the first call reads CAMERA and the second
        KINEMATIC — pass ``role`` to make it explicit.

    Returns
    -------
    posekit.localcal.model.trajectory.Trajectory
        Timestamps in s, poses in mm. What the reader decided for the user (a format the rows
        chose against the suffix) is appended to ``args._input_notes``.
    """
    from ..localcal.registration.formats import read_trajectory

    check_flags(args)
    role = _role(args, path, role)

    notes = []
    traj = read_trajectory(path, **read_options(args, role), notes=notes)
    args._input_notes = getattr(args, "_input_notes", []) + notes
    if role is not None:
        args._trajectory_roles_read = getattr(args, "_trajectory_roles_read", set()) | {role}
    return traj


def add_pair_args(parser, *, kinematic_help: str, out_metavar: str) -> None:
    """Add the two trajectory inputs CAMERA and KINEMATIC and ``--out`` to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The verb's parser.
    kinematic_help : str
        Help of the KINEMATIC positional (which robot frame it holds).
    out_metavar : str
        Metavar of ``--out`` (the result file).
    """
    parser.add_argument("camera", metavar="CAMERA", help="camera poses in the VO/SLAM world frame")
    parser.add_argument("kinematic", metavar="KINEMATIC", help=kinematic_help)
    parser.add_argument("--out", required=True, metavar=out_metavar, help="result file to write")


def print_result(path, result, summary: list[str], what: str) -> int:
    """Print ``summary`` and ``wrote PATH``; ``posekit: suspect WHAT: reasons`` on stderr and exit
    code 1 unless ``result`` is ok (:func:`posekit.verdict.batch_exit_code`)."""
    import sys

    from ..verdict import batch_exit_code

    for line in summary:
        print(line)
    print(f"wrote {path}")
    code = batch_exit_code([result.status])
    if code:
        print(f"posekit: suspect {what}: {'; '.join(result.reasons)}", file=sys.stderr)
    return code
