"""ROS /tf: ``match``/``handeye`` read the transform between two frames of ``/tf`` + ``/tf_static``.

Bags are written here with the ``rosbags`` writers (ROS 1 noetic and ROS 2 humble type stores): a
frame tree world -> odom (dynamic, 20 Hz) -> base_link (dynamic, 50 Hz) -> camera (static), with
side frames map (static, under world) and lidar (static, under base_link). The composed transform is
checked against one computed here independently (scipy's Slerp and matrix products), and on evo's
real nav2 bag against the bag's own /odom and /amcl_pose topics.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from posekit.cli.main import main
from posekit.errors import InputFileError
from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.formats import read_trajectory
from posekit.localcal.registration.formats.tum import write_tum

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

EVO = Path(__file__).resolve().parents[1] / "data" / "evo"
TF = "tf2_msgs/msg/TFMessage"


def _pose(rng, scale_mm=500.0):
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.uniform(-scale_mm, scale_mm, 3)
    return T


def _motion(rng, t, amp_mm):
    """Smooth poses (mm) at times t."""
    w = rng.uniform(0.2, 0.6, (2, 3))
    ph = rng.uniform(0, 6, (2, 3))
    T = np.zeros((len(t), 4, 4))
    T[:, :3, :3] = Rotation.from_rotvec(0.5 * np.sin(t[:, None] * w[0] + ph[0])).as_matrix()
    T[:, :3, 3] = amp_mm * np.sin(t[:, None] * w[1] + ph[1])
    T[:, 3, 3] = 1.0
    return T


@pytest.fixture(scope="module")
def tree():
    """The frame tree's edges: {(parent, child): (stamps s, T mm (N, 4, 4), static)}."""
    rng = np.random.default_rng(3)
    t_odom = 100.0 + np.arange(0, 12, 0.05)                   # world -> odom, 20 Hz
    t_base = 100.3 + np.arange(0, 11, 0.02)                   # odom -> base_link, 50 Hz, starts later
    return {
        ("world", "odom"): (t_odom, _motion(rng, t_odom - 100, 300.0), False),
        ("odom", "base_link"): (t_base, _motion(rng, t_base - 100, 900.0), False),
        ("base_link", "camera"): (np.array([100.0]), _pose(rng, 200.0)[None], True),
        ("base_link", "lidar"): (np.array([100.0]), _pose(rng, 200.0)[None], True),
        ("world", "map"): (np.array([100.0]), _pose(rng, 5000.0)[None], True),
    }


def _transform(ts, parent, child, t_s, T_mm):
    ty = ts.types
    sec = int(np.floor(t_s))
    stamp = ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((t_s - sec) * 1e9)))
    extra = {"seq": 0} if "seq" in ty["std_msgs/msg/Header"].__dataclass_fields__ else {}
    x, y, z, w = Rotation.from_matrix(T_mm[:3, :3]).as_quat()
    p = T_mm[:3, 3] / 1000.0
    tr = ty["geometry_msgs/msg/Transform"](translation=ty["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]),
                                           rotation=ty["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w))
    return ty["geometry_msgs/msg/TransformStamped"](header=ty["std_msgs/msg/Header"](**extra, stamp=stamp,
                                                                                     frame_id=parent),
                                                    child_frame_id=child, transform=tr)


def _typestore(ros):
    """The rosbags type store of a ROS version, with tf2_msgs/TFMessage registered (not bundled)."""
    ts = get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
    return ts


def write_tf_bag(path, tree, *, ros, slash=False):
    """The tree as /tf (dynamic edges, one transform per message) and /tf_static (one message with
    every static edge) in a ROS 1 bag or a ROS 2 bag folder. ``slash``: ROS 1 frame ids '/odom'."""
    ts = _typestore(ros)
    writer = Writer1(path) if ros == 1 else Writer2(path, version=9)
    name = (lambda f: "/" + f) if slash else (lambda f: f)

    def ser(msg):
        return ts.serialize_ros1(msg, TF) if ros == 1 else ts.serialize_cdr(msg, TF)

    with writer:
        c_tf = writer.add_connection("/tf", TF, typestore=ts)
        c_static = writer.add_connection("/tf_static", TF, typestore=ts)
        statics = [_transform(ts, name(p), name(c), t[0], T[0]) for (p, c), (t, T, s) in tree.items() if s]
        writer.write(c_static, int(99.0 * 1e9), ser(ts.types[TF](transforms=statics)))
        events = sorted((t[k], p, c, k) for (p, c), (t, T, s) in tree.items() if not s for k in range(len(t)))
        for t, p, c, k in events:
            msg = ts.types[TF](transforms=[_transform(ts, name(p), name(c), t, tree[(p, c)][1][k])])
            writer.write(c_tf, int(round(t * 1e9)), ser(msg))
    return path


def _at(tree, key, t):
    """Edge ``key`` at times t, interpolated independently (linear positions, scipy Slerp)."""
    stamps, T, static = tree[key]
    if static:
        return np.broadcast_to(T[0], (len(t), 4, 4))
    out = np.zeros((len(t), 4, 4))
    out[:, :3, :3] = Slerp(stamps, Rotation.from_matrix(T[:, :3, :3]))(t).as_matrix()
    for a in range(3):
        out[:, a, 3] = np.interp(t, stamps, T[:, a, 3])
    out[:, 3, 3] = 1.0
    return out


@pytest.fixture(scope="module", params=[1, 2], ids=["ros1", "ros2"])
def bag(request, tree, tmp_path_factory):
    folder = tmp_path_factory.mktemp(f"tf{request.param}")
    path = folder / ("tree.bag" if request.param == 1 else "tree")
    return write_tf_bag(path, tree, ros=request.param, slash=request.param == 1)


def test_composed_transform_equals_an_independent_composition(bag, tree):
    traj = read_trajectory(bag, tf_parent="world", tf_child="camera")
    t_base = tree[("odom", "base_link")][0]
    t_odom = tree[("world", "odom")][0]
    expected_t = t_base[(t_base >= t_odom[0]) & (t_base <= t_odom[-1])]     # busiest dynamic edge, no extrapolation
    np.testing.assert_allclose(traj.t_s, expected_t, atol=1e-6)
    T = _at(tree, ("world", "odom"), expected_t) @ _at(tree, ("odom", "base_link"), expected_t) \
        @ _at(tree, ("base_link", "camera"), expected_t)
    np.testing.assert_allclose(traj.T[:, :3, 3], T[:, :3, 3], atol=1e-5)     # mm (bags store 1e-9 m floats)
    np.testing.assert_allclose(traj.T[:, :3, :3], T[:, :3, :3], atol=1e-8)


def test_up_and_down_the_tree(bag, tree):
    """lidar -> map goes up to world and down: T_lidar_map = T_world_lidar^-1 T_world_map."""
    traj = read_trajectory(bag, tf_parent="lidar", tf_child="map")
    t = traj.t_s
    T_world_lidar = _at(tree, ("world", "odom"), t) @ _at(tree, ("odom", "base_link"), t) \
        @ _at(tree, ("base_link", "lidar"), t)
    expected = np.linalg.inv(T_world_lidar) @ _at(tree, ("world", "map"), t)
    np.testing.assert_allclose(traj.T, expected, atol=1e-5)


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(tf_parent="world", tf_child="gripper"),
     r"--tf-child 'gripper' is not a frame of the tf tree; frames: base_link, camera, lidar, map, odom, world$"),
    (dict(tf_parent="base_link", tf_child="lidar"),
     r"only static transforms between 'base_link' and 'lidar': one pose, not a trajectory$"),
    (dict(tf_parent="world"), r"--tf-parent and --tf-child go together; give both frames$"),
    (dict(topic="/tf"), r"topic /tf holds tf2_msgs/TFMessage, a frame tree: give --tf-parent FRAME "
                        r"--tf-child FRAME for the transform to read$"),
    (dict(topic="/odom", tf_parent="world", tf_child="odom"), r"topic '/odom' is not a tf topic; tf topics: /tf, /tf_static$"),
])
def test_bad_tf_requests_are_one_line_errors(bag, kwargs, message):
    with pytest.raises(InputFileError, match=message) as info:
        read_trajectory(bag, fmt="rosbag", **kwargs)
    assert "\n" not in str(info.value)


def test_match_reads_tf_from_the_cli_like_a_tum_file(tree, tmp_path, capsys):
    """The camera from /tf (world -> camera), the robot from a TUM file: the same as two TUM files."""
    bag = write_tf_bag(tmp_path / "cell.bag", tree, ros=1)
    cam = read_trajectory(bag, tf_parent="world", tf_child="camera")
    write_tum(tmp_path / "cam.tum", cam)
    rng = np.random.default_rng(8)
    T_B_W = _pose(rng)
    write_tum(tmp_path / "kin.tum", Trajectory(cam.t_s, T_B_W @ cam.T))
    rc = main(["localcal", "match", str(bag), str(tmp_path / "kin.tum"), "--camera-tf-parent", "world",
               "--camera-tf-child", "camera", "--out", str(tmp_path / "a.json")])
    assert rc == 0, capsys.readouterr().err
    rc = main(["localcal", "match", str(tmp_path / "cam.tum"), str(tmp_path / "kin.tum"), "--out", str(tmp_path / "b.json")])
    a, b = (json.loads((tmp_path / f).read_text()) for f in ("a.json", "b.json"))
    np.testing.assert_allclose(a["R"], T_B_W[:3, :3], atol=1e-6)
    np.testing.assert_allclose(a["R"], b["R"], atol=1e-6)        # TUM keeps 9 decimals of a metre
    np.testing.assert_allclose(a["t_mm"], b["t_mm"], atol=1e-3)


# ------------------------------------------------------------------ evo's real bags
def test_real_nav2_bag_tf_agrees_with_its_own_topics():
    """nav2 TurtleBot (evo test data): /tf odom -> base_link is the /odom topic exactly; map ->
    base_link (map -> odom from AMCL composed with odometry) follows /amcl_pose (measured median
    33 mm, 90 % within 77 mm: AMCL dates its map -> odom ahead by its transform tolerance)."""
    bag = EVO / "nav2_turtlebot.mcap"
    tf_odom = read_trajectory(bag, tf_parent="odom", tf_child="base_link")
    odom = read_trajectory(bag, topic="/odom")
    np.testing.assert_array_equal(tf_odom.t_s, odom.t_s)
    np.testing.assert_allclose(tf_odom.T, odom.T, atol=1e-9)
    tf_map = read_trajectory(bag, tf_parent="/map", tf_child="base_link")
    amcl = read_trajectory(bag, topic="/amcl_pose")
    inside = (amcl.t_s >= tf_map.t_s[0]) & (amcl.t_s <= tf_map.t_s[-1])
    j = np.clip(np.searchsorted(tf_map.t_s, amcl.t_s[inside]), 0, len(tf_map) - 1)
    d = np.linalg.norm(tf_map.positions[j] - amcl.positions[inside], axis=1)
    assert inside.sum() >= 130
    assert np.median(d) < 50.0 and np.percentile(d, 90) < 100.0


def test_real_ros1_and_ros2_tf_bags_give_the_same_trajectory():
    """evo's tf_example as a ROS 1 bag and a ROS 2 folder: odom -> base_link through a static
    base_footprint -> base_link."""
    a = read_trajectory(EVO / "tf_example.bag", tf_parent="odom", tf_child="base_link")
    b = read_trajectory(EVO / "tf_example", tf_parent="odom", tf_child="base_link")
    assert len(a) == 517
    np.testing.assert_array_equal(a.t_s, b.t_s)
    np.testing.assert_allclose(a.T, b.T, atol=1e-9)


def test_handeye_takes_the_same_tf_flags(tree, tmp_path):
    """handeye reads its inputs through the same flags: the camera from /tf, the tool from a TUM file."""
    from posekit.cli.localcal_inputs import read_trajectory_args
    from posekit.cli.main import build_parser

    bag = write_tf_bag(tmp_path / "cell.bag", tree, ros=1)
    args = build_parser().parse_args(["localcal", "handeye", str(bag), "kin.tum", "--camera-tf-parent", "world",
                                      "--camera-tf-child", "camera", "--out", "h.json"])
    cam = read_trajectory_args(args, args.camera, role="camera")
    np.testing.assert_allclose(cam.T, read_trajectory(bag, tf_parent="world", tf_child="camera").T)
