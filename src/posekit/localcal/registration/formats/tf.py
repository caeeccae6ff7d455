"""Poses from ROS ``/tf`` and ``/tf_static``: the transform between two named frames, composed
along the frame tree at each stamp (what ``tf2``'s ``lookupTransform(parent, child, t)`` gives).

A ``tf2_msgs/TFMessage`` carries ``geometry_msgs/TransformStamped`` entries, each the pose of a
``child_frame_id`` in its ``header.frame_id`` (``T_parent_child``). Every such edge is a time
series; an edge from a ``tf_static`` topic holds for all time. The transform ``T_A_B`` between two
frames of the tree is ``T_root_A⁻¹ T_root_B`` along their paths to the common ancestor.

Stamps of the result: those of the busiest dynamic edge on the path, inside the time span every
dynamic edge on the path covers (tf2 does not extrapolate either). The other dynamic edges are
interpolated at them (positions linearly, rotations along the geodesic). A path of static edges
only is one pose; that is not a trajectory and is refused.
"""

import numpy as np

from posekit.errors import InputFileError
from posekit.geometry import invert_transform
from posekit.io import get_limits, quote
from posekit.io._limits import mib
from posekit.localcal.model.trajectory import Trajectory

from ..handeye_time import PoseInterpolator
from ._rows import trajectory_from_rows

__all__ = ["TF_TYPES", "read_tf"]

#: Message types of transform-tree topics (ROS 2 / ROS 1 tf2, and the old ROS 1 tf).
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
#: Bytes one transform costs while reading (stamp, translation, quaternion, frame ids).
_BYTES_PER_TF = 8 * (1 + 3 + 4) + 16
#: Frame names listed in one message, at most.
_LISTED = 12


def _frame(name: str) -> str:
    """A frame id without the leading '/' of ROS 1 (``/base_link`` is ``base_link``)."""
    return str(name).lstrip("/")


def _listing(frames, limit: int = 120) -> str:
    """Sorted names joined by ', ' up to about ``limit`` characters (and at most ``_LISTED``), then 'and N more'."""
    frames = sorted(frames)
    out, used = [], 0
    for k, f in enumerate(frames):
        if out and (used + len(f) > limit or k >= _LISTED):
            return ", ".join(out) + f" and {len(frames) - k} more"
        out.append(f)
        used += len(f) + 2
    return ", ".join(out)


def _collect(reader, path, connections, limit):
    """``{(parent, child): [stamps s, xyz m, q wxyz, static]}`` of every transform on ``connections``."""
    edges = {}
    count = 0
    for conn, t_ns, raw in reader.messages(connections=connections):
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as exc:                    # noqa: BLE001 - rosbags raises many kinds
            why = " ".join(str(exc).split())[:120] or type(exc).__name__
            raise InputFileError(f"{path}: a message on {conn.topic}: cannot decode ({why})") from None
        static = "static" in conn.topic
        for tr in msg.transforms:
            count += 1
            if count * _BYTES_PER_TF > limit:
                raise InputFileError(f"{path}: more than {count - 1} transforms on the tf topics, above the "
                                     f"{mib(limit)} limit (raise it with --max-input-mb)")
            key = (_frame(tr.header.frame_id), _frame(tr.child_frame_id))
            st = tr.header.stamp
            t_s = st.sec + st.nanosec * 1e-9 if (st.sec or st.nanosec) else t_ns / 1e9
            v, o = tr.transform.translation, tr.transform.rotation
            rows = edges.setdefault(key, ([], [], [], [static]))
            rows[0].append(t_s)
            rows[1].append((v.x, v.y, v.z))
            rows[2].append((o.w, o.x, o.y, o.z))
            rows[3][0] = rows[3][0] and static
    return edges


def _tree(path, edges):
    """``parent_of[child] = parent``, or an error for a frame with two parents."""
    parent_of = {}
    for parent, child in edges:
        if child in parent_of and parent_of[child] != parent:
            raise InputFileError(f"{path}: frame {quote(child)} has two parents on the tf topics "
                                 f"({quote(parent_of[child])} and {quote(parent)}); expected a tree")
        parent_of[child] = parent
    return parent_of


def _to_root(frame, parent_of):
    """``[frame, parent, grandparent, ..., root]`` (a loop is cut where it closes)."""
    chain, seen = [frame], {frame}
    while chain[-1] in parent_of and parent_of[chain[-1]] not in seen:
        chain.append(parent_of[chain[-1]])
        seen.add(chain[-1])
    return chain


def read_tf(reader, path, topics: dict, tf_parent: str, tf_child: str, topic: str | None = None):
    """``T_parent_child`` over time from the tf topics of an open bag reader.

    Parameters
    ----------
    reader : rosbags.highlevel.AnyReader
        The open bag.
    path : Path
        The bag, for messages.
    topics : dict
        ``reader.topics``.
    tf_parent, tf_child : str
        The two frames (a leading '/' is ignored).
    topic : str, optional
        The dynamic tf topic (``/tf`` by default: every TFMessage topic is read; a named one is
        read with the ``tf_static`` topics).

    Returns
    -------
    Trajectory
        ``T_parent_child`` in mm at the stamps of the busiest dynamic edge on the path.

    Raises
    ------
    InputFileError
        No tf topic, an unknown frame (the frames are listed), frames not connected, a frame with
        two parents, only static transforms between the two frames, more transforms than the
        size limit, a non-unit quaternion or NaN (naming the edge and message).
    """
    tf_topics = {name: info for name, info in topics.items() if info.msgtype in TF_TYPES}
    if not tf_topics:
        raise InputFileError(f"{path}: no tf topic (tf2_msgs/TFMessage); --tf-parent and --tf-child read /tf and "
                             "/tf_static")
    if topic is not None:
        if topic not in tf_topics:
            raise InputFileError(f"{path}: topic {quote(topic)} is not a tf topic; tf topics: {_listing(tf_topics)}")
        tf_topics = {n: i for n, i in tf_topics.items() if n == topic or "static" in n}
    connections = [c for info in tf_topics.values() for c in info.connections]
    edges = _collect(reader, path, connections, get_limits().array_bytes)
    parent_of = _tree(path, edges)
    frames = set(parent_of) | set(parent_of.values())
    a, b = _frame(tf_parent), _frame(tf_child)
    for role, f in (("--tf-parent", a), ("--tf-child", b)):
        if f not in frames:
            raise InputFileError(f"{path}: {role} {quote(f)} is not a frame of the tf tree; frames: {_listing(frames)}")
    up_a, up_b = _to_root(a, parent_of), _to_root(b, parent_of)
    common = next((f for f in up_a if f in set(up_b)), None)
    if common is None:
        raise InputFileError(f"{path}: frames {quote(a)} and {quote(b)} are not connected in the tf tree "
                             f"(roots {quote(up_a[-1])} and {quote(up_b[-1])})")
    # edges from the common ancestor down to a (inverted) and down to b
    down_a = [(parent_of[f], f) for f in up_a[:up_a.index(common)]][::-1]
    down_b = [(parent_of[f], f) for f in up_b[:up_b.index(common)]][::-1]
    series = {}
    for key in down_a + down_b:
        stamps, xyz, q, (static,) = edges[key]
        order = np.argsort(np.asarray(stamps), kind="stable")
        t = np.asarray(stamps)[order]
        label = f"transform {key[0]} -> {key[1]}"
        traj = trajectory_from_rows(path, t, np.asarray(xyz)[order], np.asarray(q)[order],
                                    [f" {label}, message {k + 1}" for k in order], check_order=False)
        series[key] = (traj, static)
    dynamic = [k for k, (_, static) in series.items() if not static]
    if not dynamic:
        raise InputFileError(f"{path}: only static transforms between {quote(a)} and {quote(b)}: one pose, not a "
                             "trajectory")
    lo = max(series[k][0].t_s[0] for k in dynamic)
    hi = min(series[k][0].t_s[-1] for k in dynamic)
    main = max(dynamic, key=lambda k: len(series[k][0]))
    t_out = series[main][0].t_s
    t_out = np.unique(t_out[(t_out >= lo) & (t_out <= hi)])
    if t_out.size == 0:
        raise InputFileError(f"{path}: the dynamic transforms between {quote(a)} and {quote(b)} never overlap in time")

    def at(key):
        traj, static = series[key]
        if static or len(traj) == 1:
            return np.broadcast_to(traj.T[-1], (t_out.size, 4, 4))
        return PoseInterpolator(traj.t_s, traj.T)(t_out)

    T_common_a = np.broadcast_to(np.eye(4), (t_out.size, 4, 4))
    for key in down_a:
        T_common_a = T_common_a @ at(key)
    T_common_b = np.broadcast_to(np.eye(4), (t_out.size, 4, 4))
    for key in down_b:
        T_common_b = T_common_b @ at(key)
    return Trajectory(t_out, invert_transform(T_common_a) @ T_common_b)
