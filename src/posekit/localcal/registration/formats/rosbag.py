"""Pose topics of ROS 1 bags (``.bag``), ROS 2 bags (a bag folder, ``.db3``, ``.mcap``) through the
``rosbags`` package (extra ``bags``): ``geometry_msgs/PoseStamped``,
``geometry_msgs/PoseWithCovarianceStamped``, ``nav_msgs/Odometry`` and
``geometry_msgs/TransformStamped``, in metres, timed by their header stamps; and the transform
between two frames of ``/tf`` + ``/tf_static`` (:mod:`.tf`)."""

from pathlib import Path

import numpy as np

from posekit._extras import require
from posekit.errors import InputFileError, PosekitError
from posekit.io import get_limits, quote
from posekit.io._limits import mib

from ..tum import Trajectory  # noqa: F401  (the return type)
from ._rows import trajectory_from_rows

__all__ = ["POSE_TYPES", "BAG_SUFFIXES", "read_rosbag", "is_bag"]

#: Message types with a pose, and how to reach it: (pose or transform path, position, orientation).
POSE_TYPES = {
    "geometry_msgs/msg/PoseStamped": ("pose", "position", "orientation"),
    "geometry_msgs/msg/PoseWithCovarianceStamped": ("pose.pose", "position", "orientation"),
    "nav_msgs/msg/Odometry": ("pose.pose", "position", "orientation"),
    "geometry_msgs/msg/TransformStamped": ("transform", "translation", "rotation"),
}
#: File suffixes of bag files (a ROS 2 bag folder is recognised by its metadata.yaml).
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
#: Bytes one pose costs while reading (stamps, position, quaternion, 4x4 pose).
_BYTES_PER_POSE = 8 * (2 + 3 + 4 + 16)
_EXPECTED = ("a ROS bag (.bag, .db3, .mcap or a ROS 2 bag folder) with a PoseStamped, Odometry "
             "or TransformStamped topic")


def is_bag(path) -> bool:
    """Whether ``path`` names a bag: a ``.bag``/``.db3``/``.mcap`` file or a folder with metadata.yaml."""
    path = Path(path)
    return path.suffix.lower() in BAG_SUFFIXES or (path.is_dir() and (path / "metadata.yaml").is_file())


def _short(name: str) -> str:
    return name.replace("/msg/", "/")


def _get(obj, dotted: str):
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


def _open(path: Path):
    highlevel = require("rosbags.highlevel", "bags", f"reading the ROS bag {path}")
    typesys = require("rosbags.typesys", "bags", f"reading the ROS bag {path}")
    store = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in store.fielddefs:     # not bundled: for bags that carry no definitions
        store.register(typesys.get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                  "tf2_msgs/msg/TFMessage"))
    return highlevel.AnyReader([path], default_typestore=store)


#: Most entries of a ROS 2 bag folder looked at (a bag has its metadata and a few storage files).
_MAX_BAG_ENTRIES = 10_000


def _check_entries(path: Path) -> None:
    """Every entry of a bag folder is a regular file or a folder: a named pipe would block the
    reader forever, a link to /dev/zero would grow without end (both refused in one line)."""
    from posekit.io import check_input_file

    for k, entry in enumerate(path.iterdir()):
        if k >= _MAX_BAG_ENTRIES:
            raise InputFileError(f"{path}: more than {_MAX_BAG_ENTRIES} entries; expected a ROS 2 bag folder "
                                 "(metadata.yaml and its storage files)")
        if not entry.is_dir():
            check_input_file(entry, expected="a file of a ROS 2 bag folder (metadata.yaml, .db3 or .mcap)")


def _check_path(path: Path) -> None:
    if not path.exists():
        raise InputFileError(f"{path}: no such file or folder; expected {_EXPECTED}")
    if not path.is_dir():      # a regular file: not a named pipe (which would block forever) or a device
        from posekit.io import check_input_file

        check_input_file(path, expected=_EXPECTED)
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise InputFileError(f"{path}: a folder without metadata.yaml; expected {_EXPECTED}")
    if path.is_dir():          # size, encoding and YAML structure checked here, before rosbags parses it
        _check_entries(path)
        from posekit.io import load_yaml
        meta = path / "metadata.yaml"
        doc = load_yaml(meta, expected="the metadata of a ROS 2 bag folder")
        if not isinstance(doc, dict) or not isinstance(doc.get("rosbag2_bagfile_information"), dict):
            raise InputFileError(f"{meta}: no 'rosbag2_bagfile_information' mapping; expected the metadata of a "
                                 "ROS 2 bag folder")
    if path.is_file() and path.suffix.lower() not in BAG_SUFFIXES:
        raise InputFileError(f"{path}: suffix '{path.suffix}' is not a bag; expected {_EXPECTED}")


def _pick_topic(path: Path, topics: dict, topic: str | None) -> str:
    from .tf import TF_TYPES

    poses = {name: info.msgtype for name, info in topics.items() if info.msgtype in POSE_TYPES}
    listing = ", ".join(f"{n} ({_short(t)})" for n, t in sorted(poses.items())) or "none"
    has_tf = any(info.msgtype in TF_TYPES for info in topics.values())
    if topic is None:
        if len(poses) == 1:
            return next(iter(poses))
        tf_hint = "; or give --tf-parent FRAME --tf-child FRAME to read /tf" if has_tf else ""
        raise InputFileError(f"{path}: {len(poses)} pose topics ({listing}); name one with --topic{tf_hint}")
    if topic in topics and topics[topic].msgtype in TF_TYPES:
        raise InputFileError(f"{path}: topic {topic} holds {_short(str(topics[topic].msgtype))}, a frame tree: give "
                             "--tf-parent FRAME --tf-child FRAME for the transform to read")
    if topic not in topics:
        raise InputFileError(f"{path}: no topic {quote(topic)}; pose topics: {listing}")
    if topic not in poses:
        raise InputFileError(f"{path}: topic {topic} holds {_short(str(topics[topic].msgtype))}, not a pose; "
                             f"expected PoseStamped, PoseWithCovarianceStamped, Odometry or TransformStamped "
                             f"(pose topics: {listing})")
    return topic


def read_rosbag(path, topic: str | None = None, tf_parent: str | None = None,
                tf_child: str | None = None) -> Trajectory:
    """Read the poses of one topic of a ROS 1 or ROS 2 bag, or a transform of its frame tree.

    Parameters
    ----------
    path : str or Path
        A ROS 1 ``.bag``, a ROS 2 bag folder (with ``metadata.yaml``), or a single ROS 2 storage
        file ``.db3`` / ``.mcap``.
    topic : str, optional
        The topic; may be left out when the bag has exactly one pose topic (or, with the tf
        frames, names the dynamic tf topic).
    tf_parent, tf_child : str, optional
        Read ``T_parent_child`` from ``/tf`` and ``/tf_static`` instead of a pose topic
        (:func:`.tf.read_tf`); both or neither.

    Returns
    -------
    Trajectory
        Timestamps from the header stamps, s (the bag's record times when every header stamp is
        zero), sorted by time (a bag stores messages in arrival order); poses
        ``T_frame_child`` (the message's ``header.frame_id`` frame to the body) in mm.

    Raises
    ------
    InputFileError
        Not a readable bag, no such topic (the pose topics are listed), a topic that is not a
        pose, more poses than the size limit allows, or a message with a NaN, a non-unit
        quaternion or a zero header stamp among non-zero ones: ``FILE: message K on TOPIC: ...``
        (K counts the topic's messages from 1).
    MissingExtraError
        If the ``rosbags`` package is not installed (``pip install "posekit[bags]"``).
    """
    path = Path(path)
    if (tf_parent is None) != (tf_child is None):
        raise InputFileError(f"{path}: --tf-parent and --tf-child go together; give both frames")
    _check_path(path)
    try:
        reader = _open(path)
        if tf_parent is not None:
            from .tf import read_tf
            with reader:
                return read_tf(reader, path, reader.topics, tf_parent, tf_child, topic)
        return _read(reader, path, topic)
    except PosekitError:
        raise
    except Exception as exc:    # rosbags raises many kinds on a damaged file: one line for all
        why = " ".join(str(exc).split())[:160] or type(exc).__name__
        raise InputFileError(f"{path}: not a readable ROS bag ({why}); expected {_EXPECTED}") from None


def _read(reader, path: Path, topic: str | None) -> Trajectory:
    with reader:
        topics = reader.topics
        name = _pick_topic(path, topics, topic)
        info = topics[name]
        n = int(info.msgcount)
        limit = get_limits().array_bytes
        if n * _BYTES_PER_POSE > limit:
            raise InputFileError(f"{path}: topic {name} holds {n} messages ({mib(n * _BYTES_PER_POSE)} as poses), "
                                 f"above the {mib(limit)} limit (raise it with --max-input-mb)")
        if n == 0:
            raise InputFileError(f"{path}: topic {name} holds no messages; expected poses")
        pose_path, pos, rot = POSE_TYPES[info.msgtype]
        stamp = np.empty((n, 2))
        rec = np.empty(n)
        p = np.empty((n, 3))
        q = np.empty((n, 4))
        k = 0
        for conn, t_ns, raw in reader.messages(connections=info.connections):
            if k >= n:
                raise InputFileError(f"{path}: topic {name} holds more messages than its index says ({n})")
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as exc:
                why = " ".join(str(exc).split())[:120] or type(exc).__name__
                raise InputFileError(f"{path}: message {k + 1} on {name}: cannot decode ({why})") from None
            st = msg.header.stamp
            stamp[k] = st.sec, st.nanosec
            rec[k] = t_ns
            pose = _get(msg, pose_path)
            v, o = getattr(pose, pos), getattr(pose, rot)
            p[k] = v.x, v.y, v.z
            q[k] = o.w, o.x, o.y, o.z
            k += 1
    stamp, rec, p, q = stamp[:k], rec[:k], p[:k], q[:k]
    zero = (stamp[:, 0] == 0) & (stamp[:, 1] == 0)
    t_s = rec / 1e9 if zero.all() else stamp[:, 0] + stamp[:, 1] * 1e-9
    order = np.argsort(t_s, kind="stable")
    records = [f" message {j + 1} on {name}" for j in order]
    return trajectory_from_rows(path, t_s[order], p[order], q[order], records, check_order=False)
