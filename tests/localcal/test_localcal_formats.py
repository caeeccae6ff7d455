"""Trajectory formats: TUM, KITTI, EuRoC CSV and ROS 1/2 bags (.bag, .db3, .mcap, a bag folder)
give the same trajectory and the same match result; bad files fail in one line naming the record.

Bags are written here with the ``rosbags`` writers (ROS 1 noetic and ROS 2 humble type stores),
an implementation independent of posekit's reader, into ``tmp_path``.
"""

import argparse
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.cli.localcal_inputs import add_trajectory_args, read_trajectory_args
from posekit.errors import InputFileError, PosekitError, TrajectoryError
from posekit.io import set_limits
from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.formats import (
    detect_format,
    read_trajectory,
    write_euroc,
    write_kitti,
)
from posekit.localcal.registration.formats.tum import write_tum
from posekit.localcal.registration.match import match_trajectories

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

TS1 = get_typestore(Stores.ROS1_NOETIC)
TS2 = get_typestore(Stores.ROS2_HUMBLE)
RATE_HZ = 25.0


def _trajectory(seed, n=200, t0=1000.0, rate=RATE_HZ, T_B_W=None):
    """A smooth random trajectory (mm, s) sampled at ``rate``; ``T_B_W`` re-expresses it."""
    rng = np.random.default_rng(seed)
    t = t0 + np.arange(n) / rate
    u = (t - t0)[:, None]
    p = 300.0 * np.sin(u * rng.uniform(0.2, 0.6, 3) + rng.uniform(0, 6, 3)) + rng.uniform(-900, 900, 3)
    rv = 0.6 * np.sin(u * rng.uniform(0.2, 0.5, 3) + rng.uniform(0, 6, 3))
    T = np.zeros((n, 4, 4))
    T[:, :3, :3] = (Rotation.random(random_state=rng) * Rotation.from_rotvec(rv)).as_matrix()
    T[:, :3, 3] = p
    T[:, 3, 3] = 1.0
    if T_B_W is not None:
        T = T_B_W @ T
    return Trajectory(t, T)


def _msg(ts, kind, t_s, T_mm, seq=0):
    """One pose message of ``kind`` for type store ``ts`` (pose in m)."""
    ty = ts.types
    sec = int(np.floor(t_s))
    stamp = ty["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((t_s - sec) * 1e9)))
    extra = {"seq": seq} if "seq" in ty["std_msgs/msg/Header"].__dataclass_fields__ else {}
    header = ty["std_msgs/msg/Header"](**extra, stamp=stamp, frame_id="world")
    x, y, z, w = Rotation.from_matrix(T_mm[:3, :3]).as_quat()
    p = T_mm[:3, 3] / 1000.0
    q = ty["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)
    if kind == "TransformStamped":
        tr = ty["geometry_msgs/msg/Transform"](translation=ty["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]),
                                               rotation=q)
        return ty["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id="cam", transform=tr)
    pose = ty["geometry_msgs/msg/Pose"](position=ty["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                                        orientation=q)
    if kind == "PoseStamped":
        return ty["geometry_msgs/msg/PoseStamped"](header=header, pose=pose)
    cov = ty["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36))
    if kind == "PoseWithCovarianceStamped":
        return ty["geometry_msgs/msg/PoseWithCovarianceStamped"](header=header, pose=cov)
    twist = ty["geometry_msgs/msg/TwistWithCovariance"](
        twist=ty["geometry_msgs/msg/Twist"](linear=ty["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                            angular=ty["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
        covariance=np.zeros(36))
    return ty["nav_msgs/msg/Odometry"](header=header, child_frame_id="cam", pose=cov, twist=twist)


TYPES = {"PoseStamped": "geometry_msgs/msg/PoseStamped", "Odometry": "nav_msgs/msg/Odometry",
         "TransformStamped": "geometry_msgs/msg/TransformStamped",
         "PoseWithCovarianceStamped": "geometry_msgs/msg/PoseWithCovarianceStamped"}


def write_bag(path, topics, *, ros=2, storage="sqlite3"):
    """Write ``{topic: (kind, Trajectory)}`` into a ROS 1 bag or ROS 2 bag folder; messages
    interleaved by time as a recorder would store them. Returns the path."""
    path = Path(path)
    ts = TS1 if ros == 1 else TS2
    if ros == 1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
    with writer:
        conns = {name: writer.add_connection(name, TYPES[kind], typestore=ts) for name, (kind, _) in topics.items()}
        events = sorted((t, name, k) for name, (_, traj) in topics.items() for k, t in enumerate(traj.t_s))
        for t, name, k in events:
            kind, traj = topics[name]
            msg = _msg(ts, kind, traj.t_s[k], traj.T[k], seq=k)
            raw = ts.serialize_ros1(msg, TYPES[kind]) if ros == 1 else ts.serialize_cdr(msg, TYPES[kind])
            writer.write(conns[name], int(round(t * 1e9)) + 1000, raw)
    return path


@pytest.fixture(scope="module")
def pair():
    rng = np.random.default_rng(5)
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = [400.0, -250.0, 120.0]
    cam = _trajectory(1)
    kin = Trajectory(cam.t_s, T @ cam.T)
    return cam, kin, T


def _write(fmt, folder: Path, name: str, traj: Trajectory) -> Path:
    if fmt == "tum":
        path = folder / f"{name}.tum"
        write_tum(path, traj)
    elif fmt == "kitti":
        path = folder / f"{name}.kitti"
        write_kitti(path, traj)
    elif fmt == "euroc":
        path = folder / f"{name}.csv"
        write_euroc(path, traj)
    elif fmt == "bag":
        path = write_bag(folder / f"{name}.bag", {"/pose": ("PoseStamped", traj)}, ros=1)
    elif fmt == "db3":
        path = write_bag(folder / f"{name}_db3", {"/pose": ("Odometry", traj)}) / f"{name}_db3.db3"
    elif fmt == "mcap":
        path = write_bag(folder / f"{name}_mcap", {"/pose": ("TransformStamped", traj)}, storage="mcap")
    return path


@pytest.mark.parametrize("fmt", ["kitti", "euroc", "bag", "db3", "mcap"])
def test_every_format_reads_the_same_trajectory_and_match_as_tum(tmp_path, pair, fmt):
    cam, kin, T_true = pair
    ref = read_trajectory(_write("tum", tmp_path, "cam_ref", cam))
    kin_tum = read_trajectory(_write("tum", tmp_path, "kin", kin))
    path = _write(fmt, tmp_path, "cam", Trajectory(cam.t_s - cam.t_s[0], cam.T) if fmt == "kitti" else cam)
    kw = {"fmt": "kitti", "rate_hz": RATE_HZ} if fmt == "kitti" else {}
    got = read_trajectory(path, **kw)
    if fmt == "kitti":     # no time in the file: frame k at k / rate
        np.testing.assert_allclose(got.t_s, np.arange(len(cam)) / RATE_HZ, atol=1e-12)
        got = Trajectory(got.t_s + cam.t_s[0], got.T)
    np.testing.assert_allclose(got.t_s, ref.t_s, atol=1e-6)
    np.testing.assert_allclose(got.T, ref.T, atol=2e-6)        # TUM keeps 1e-9 m = 1e-6 mm
    a = match_trajectories(ref, kin_tum, time_offset_s=0.0)
    b = match_trajectories(got, kin_tum, time_offset_s=0.0)
    np.testing.assert_allclose(b.R, a.R, atol=1e-8)
    np.testing.assert_allclose(b.t_mm, a.t_mm, atol=1e-5)
    np.testing.assert_allclose(b.R, T_true[:3, :3], atol=1e-8)
    np.testing.assert_allclose(b.t_mm, T_true[:3, 3], atol=1e-5)


def test_ros2_bag_folder_and_topic_choice(tmp_path, pair):
    cam, kin, _ = pair
    bag = write_bag(tmp_path / "both", {"/vo/pose": ("PoseStamped", cam), "/robot/tcp": ("TransformStamped", kin)})
    assert detect_format(bag) == "rosbag"
    np.testing.assert_allclose(read_trajectory(bag, topic="/robot/tcp").T, kin.T, atol=1e-9)
    with pytest.raises(InputFileError) as exc:
        read_trajectory(bag)
    assert str(exc.value) == (f"{bag}: 2 pose topics (/robot/tcp (geometry_msgs/TransformStamped), "
                              "/vo/pose (geometry_msgs/PoseStamped)); name one with --topic")
    with pytest.raises(InputFileError) as exc:
        read_trajectory(bag, topic="/nope")
    assert str(exc.value) == (f"{bag}: no topic '/nope'; pose topics: /robot/tcp (geometry_msgs/TransformStamped), "
                              "/vo/pose (geometry_msgs/PoseStamped)")
    # per-input flags: one bag, two topics
    parser = argparse.ArgumentParser()
    parser.add_argument("camera")
    parser.add_argument("kinematic")
    add_trajectory_args(parser)
    args = parser.parse_args([str(bag), str(bag), "--camera-topic", "/vo/pose", "--kinematic-topic", "/robot/tcp"])
    np.testing.assert_allclose(read_trajectory_args(args, args.camera).T, cam.T, atol=1e-9)
    np.testing.assert_allclose(read_trajectory_args(args, args.kinematic).T, kin.T, atol=1e-9)
    args = parser.parse_args([str(bag), str(bag), "--topic", "/vo/pose"])
    np.testing.assert_allclose(read_trajectory_args(args, args.kinematic).T, cam.T, atol=1e-9)


def test_bag_messages_out_of_order_are_sorted_by_header_stamp(tmp_path, pair):
    cam = pair[0]
    order = np.arange(len(cam))
    order[[10, 11]] = order[[11, 10]]
    path = tmp_path / "swap.bag"
    with Writer1(path) as w:
        c = w.add_connection("/p", TYPES["PoseStamped"], typestore=TS1)
        for k, j in enumerate(order):     # arrival order differs from stamp order
            w.write(c, 10**9 + k, TS1.serialize_ros1(_msg(TS1, "PoseStamped", cam.t_s[j], cam.T[j]), TYPES["PoseStamped"]))
    got = read_trajectory(path)
    np.testing.assert_allclose(got.t_s, cam.t_s, atol=1e-6)
    np.testing.assert_allclose(got.T, cam.T, atol=1e-9)


def test_kitti_and_tum_from_the_cli_parser(tmp_path, pair):
    cam, kin, _ = pair
    k = _write("kitti", tmp_path, "cam", cam)
    t = _write("tum", tmp_path, "kin", kin)
    parser = argparse.ArgumentParser()
    parser.add_argument("camera")
    parser.add_argument("kinematic")
    add_trajectory_args(parser)
    args = parser.parse_args([str(k), str(t), "--camera-format", "kitti", "--rate-hz", "25"])
    got = read_trajectory_args(args, args.camera)
    np.testing.assert_allclose(got.t_s, np.arange(len(cam)) / 25.0)
    assert len(read_trajectory_args(args, args.kinematic)) == len(kin)
    args = parser.parse_args([str(k), str(t), "--camera-format", "kitti"])
    with pytest.raises(TrajectoryError) as exc:
        read_trajectory_args(args, args.camera)
    assert str(exc.value) == f"{k}: a KITTI pose file carries no time; give its frame rate with --rate-hz HZ"
    with pytest.raises(TrajectoryError) as exc:
        read_trajectory(k, fmt="kitti", rate_hz=float("nan"))
    assert str(exc.value) == f"{k}: expected a KITTI frame rate > 0 Hz, got nan"
    args = parser.parse_args([str(k), str(t), "--format", "kitti", "--rate-hz", "-3"])
    with pytest.raises(PosekitError, match="^--rate-hz: "):
        read_trajectory_args(args, args.camera)


def test_suffix_detection(tmp_path):
    assert detect_format("a.tum") == detect_format("a.TXT") == "tum"
    assert detect_format("a.csv") == "euroc"
    assert detect_format("a.bag") == detect_format("a.db3") == detect_format("a.mcap") == "rosbag"
    with pytest.raises(InputFileError) as exc:
        detect_format(tmp_path / "a.xyz")
    assert str(exc.value) == (f"{tmp_path / 'a.xyz'}: cannot tell the trajectory format from the suffix '.xyz'; "
                              "expected .tum/.txt (TUM), .csv (EuRoC), .bag/.db3/.mcap or a bag folder (ROS), "
                              "or give --format tum|kitti|euroc|rosbag")
    with pytest.raises(InputFileError) as exc:
        detect_format(tmp_path)
    assert str(exc.value) == (f"{tmp_path}: a folder without metadata.yaml; expected a trajectory file or a "
                              "ROS 2 bag folder")


EUROC_HEAD = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n"
ROW = "1403636579758555392,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152"


def test_euroc_real_row_and_extra_columns(tmp_path):
    p = tmp_path / "gt.csv"
    p.write_text(EUROC_HEAD + ROW + ",0.1,0.2,0.3\n" + ROW.replace("1403636579758555392", "1403636579763555584") + "\n")
    traj = read_trajectory(p)
    assert traj.t_s[0] == pytest.approx(1403636579.758555392, abs=1e-6)
    assert traj.t_s[1] - traj.t_s[0] == pytest.approx(0.005, abs=1e-6)
    np.testing.assert_allclose(traj.positions[0], [4688.319, -1786.938, 783.338], atol=1e-9)
    q = np.array([0.534108, -0.153029, -0.827383, -0.082152])
    R = Rotation.from_quat(np.r_[q[1:], q[0]] / np.linalg.norm(q)).as_matrix()
    np.testing.assert_allclose(traj.rotations[0], R, atol=1e-12)
    p.write_text("timestamp,x,y,z,qw,qx,qy,qz\n" + ROW + "\n")        # named header without '#'
    assert len(read_trajectory(p)) == 1


@pytest.mark.parametrize(("name", "text", "message"), [
    ("a.csv", EUROC_HEAD + ROW + "\n1403636579763555584,1,2\n",
     "a.csv:3: expected at least 8 comma-separated numbers 'timestamp_ns, px, py, pz, qw, qx, qy, qz', "
     "found 3 fields"),
    ("a.csv", EUROC_HEAD + ROW + "\n" + ROW.replace("0.534108", "5.34108") + "\n",
     "a.csv:3: expected a unit quaternion, found norm 5.408"),
    ("a.csv", EUROC_HEAD + ROW + "\n" + ROW.replace("1403636579758555392", "1403636579700000000") + "\n",
     "a.csv:3: timestamps must not decrease: 1403636579.700000 s after 1403636579.758555 s"),
    ("a.csv", EUROC_HEAD + ROW.replace("4.688319", "nan") + "\n",
     "a.csv:2: expected finite numbers, found NaN or infinity"),
    ("a.csv", EUROC_HEAD, "a.csv: no poses found (expected lines of at least 8 comma-separated numbers "
                          "'timestamp_ns, px, py, pz, qw, qx, qy, qz')"),
    ("a.kitti", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n",
     "a.kitti:2: expected 12 numbers 'r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz', found 11 fields"),
    ("a.kitti", "1 0 0 0 0 1 0 0 0 0 1 0\n# c\n1 0 0 0 0 1 0 0 0 0 -1 0\n",
     "a.kitti:3: expected a rotation matrix in columns 1-3, 5-7, 9-11, found max |R^T R - I| = 0, det -1"),
    ("a.kitti", "2 0 0 0 0 1 0 0 0 0 1 0\n",
     "a.kitti:1: expected a rotation matrix in columns 1-3, 5-7, 9-11, found max |R^T R - I| = 3, det 2"),
    ("a.kitti", "1 0 0 x 0 1 0 0 0 0 1 0\n",
     "a.kitti:1: expected 12 numbers 'r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz', found 'x'"),
])
def test_bad_text_files_name_file_and_line(tmp_path, monkeypatch, name, text, message):
    monkeypatch.chdir(tmp_path)
    Path(name).write_text(text)
    with pytest.raises(InputFileError) as exc:
        read_trajectory(name, fmt="kitti" if name.endswith(".kitti") else None, rate_hz=10.0)
    assert str(exc.value) == message


def test_bad_bags_name_file_and_message(tmp_path, monkeypatch, pair):
    monkeypatch.chdir(tmp_path)
    cam = pair[0]
    # a NaN and a non-unit quaternion, message index counted on the topic
    bag = write_bag(Path("nan.bag"), {"/p": ("PoseStamped", Trajectory(cam.t_s[:5], cam.T[:5]))}, ros=1)
    with Writer1(Path("nan2.bag")) as w:
        c = w.add_connection("/p", TYPES["PoseStamped"], typestore=TS1)
        for k in range(5):
            m = _msg(TS1, "PoseStamped", cam.t_s[k], cam.T[k])
            if k == 3:
                m.pose.position.x = float("nan")
            w.write(c, 10**9 + k, TS1.serialize_ros1(m, TYPES["PoseStamped"]))
    with pytest.raises(InputFileError) as exc:
        read_trajectory("nan2.bag")
    assert str(exc.value) == "nan2.bag: message 4 on /p: expected finite numbers, found NaN or infinity"
    with Writer1(Path("q.bag")) as w:
        c = w.add_connection("/p", TYPES["PoseStamped"], typestore=TS1)
        for k in range(3):
            m = _msg(TS1, "PoseStamped", cam.t_s[k], cam.T[k])
            if k == 1:
                m.pose.orientation.w = 0.0
                m.pose.orientation.x = m.pose.orientation.y = m.pose.orientation.z = 0.0
            w.write(c, 10**9 + k, TS1.serialize_ros1(m, TYPES["PoseStamped"]))
    with pytest.raises(InputFileError) as exc:
        read_trajectory("q.bag")
    assert str(exc.value) == "q.bag: message 2 on /p: expected a unit quaternion, found norm 0"
    # a topic that is not a pose
    with Writer1(Path("s.bag")) as w:
        c = w.add_connection("/s", "std_msgs/msg/String", typestore=TS1)
        w.write(c, 1, TS1.serialize_ros1(TS1.types["std_msgs/msg/String"](data="x"), "std_msgs/msg/String"))
    with pytest.raises(InputFileError) as exc:
        read_trajectory("s.bag", topic="/s")
    assert str(exc.value) == ("s.bag: topic /s holds std_msgs/String, not a pose; expected PoseStamped, "
                              "PoseWithCovarianceStamped, Odometry or TransformStamped (pose topics: none)")
    with pytest.raises(InputFileError) as exc:
        read_trajectory("s.bag")
    assert str(exc.value) == "s.bag: 0 pose topics (none); name one with --topic"
    # damaged files: garbage, truncated
    Path("junk.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 4)
    Path("junk.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 100)
    Path("text.db3").write_text("not sqlite\n")
    data = bag.read_bytes()
    Path("cut.bag").write_bytes(data[: len(data) // 2])
    for name in ["junk.bag", "junk.mcap", "text.db3", "cut.bag"]:
        with pytest.raises(InputFileError) as exc:
            read_trajectory(name)
        msg = str(exc.value)
        assert "\n" not in msg, msg
        assert msg.startswith(f"{name}: not a readable ROS bag (") and msg.endswith(
            "; expected a ROS bag (.bag, .db3, .mcap or a ROS 2 bag folder) with a PoseStamped, Odometry or "
            "TransformStamped topic"), msg
    with pytest.raises(InputFileError) as exc:
        read_trajectory("missing.bag")
    assert str(exc.value).startswith("missing.bag: no such file or folder; expected a ROS bag")


def test_sizes_are_bounded_by_the_io_limits(tmp_path, pair):
    cam = pair[0]
    bag = write_bag(tmp_path / "l.bag", {"/p": ("PoseStamped", cam)}, ros=1)
    k = _write("kitti", tmp_path, "l", cam)
    old = set_limits(array_bytes=10_000, text_bytes=1000)
    try:
        with pytest.raises(InputFileError) as exc:
            read_trajectory(bag)
        assert str(exc.value) == (f"{bag}: topic /p holds 200 messages (0.0381 MiB as poses), above the "
                                  "0.00954 MiB limit (raise it with --max-input-mb)")
        with pytest.raises(InputFileError, match=r"above the 0.000954 MiB limit for a KITTI pose file"):
            read_trajectory(k, fmt="kitti", rate_hz=10)
    finally:
        set_limits(**old.__dict__)


def test_a_kitti_file_read_as_tum_says_so(tmp_path, pair):
    k = tmp_path / "poses.txt"
    write_kitti(k, pair[0])
    with pytest.raises(TrajectoryError) as exc:            # the rows say KITTI, whatever the suffix says
        read_trajectory(k)
    assert str(exc.value) == (f"{k}: rows of 12 numbers, a KITTI pose file, which carries no time: give its "
                              "frame rate with --rate-hz HZ")
    with pytest.raises(InputFileError) as exc:              # forced to TUM: the TUM reader names the line
        read_trajectory(k, fmt="tum")
    assert str(exc.value) == (f"{k}:1: expected 8 numbers 'timestamp tx ty tz qx qy qz qw', found 12 fields; "
                              "12 numbers per line look like a KITTI pose file: give --format kitti --rate-hz HZ")


def test_the_rows_decide_the_format_and_a_note_says_so(tmp_path, pair):
    """A .csv of TUM rows is TUM; EuRoC rows in a .txt are EuRoC; KITTI rows are KITTI whatever the
    suffix: the content wins over the suffix, and one line says so."""
    cam = pair[0]
    tum_csv = tmp_path / "cam.csv"
    write_tum(tum_csv, cam)
    euroc_txt = tmp_path / "gt.txt"
    write_euroc(euroc_txt, cam)
    kitti_tum = tmp_path / "poses.tum"
    write_kitti(kitti_tum, cam)
    comma_tum = tmp_path / "commas.dat"
    rows = np.loadtxt(tum_csv)
    comma_tum.write_text("\n".join(",".join(f"{v:.9f}" for v in r) for r in rows) + "\n")
    for path, fmt, kw in ((tum_csv, "TUM", {}), (euroc_txt, "EuRoC", {}), (kitti_tum, "KITTI", {"rate_hz": RATE_HZ}),
                          (comma_tum, "TUM", {})):
        notes = []
        traj = read_trajectory(path, notes=notes, **kw)
        np.testing.assert_allclose(traj.positions, cam.positions, atol=1e-5)
        if path.suffix == ".dat":
            assert notes == []                              # an unknown suffix: nothing to contradict
        else:
            assert notes == [f"{path}: {fmt} rows, though the suffix '{path.suffix}' suggests "
                             f"{dict(csv='EuRoC', txt='TUM', tum='TUM')[path.suffix[1:]]}: read as {fmt} "
                             "(give --format to choose)"]
    assert detect_format(tmp_path / "missing.csv") == "euroc"   # no rows to read: the suffix


def test_handeye_cli_reads_two_topics_of_one_bag_like_two_tum_files(tmp_path):
    import json

    from posekit.cli.main import main
    from tests.localcal.test_localcal_handeye import eye_in_hand

    cam, kin, _, _ = eye_in_hand(60, duration_s=5.0)
    write_tum(tmp_path / "cam.tum", cam)
    write_tum(tmp_path / "kin.tum", kin)
    bag = write_bag(tmp_path / "run.bag", {"/cam": ("PoseStamped", cam), "/tcp": ("TransformStamped", kin)}, ros=1)
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["localcal", "handeye", str(tmp_path / "cam.tum"), str(tmp_path / "kin.tum"), "--out", str(a)]) == 0
    assert main(["localcal", "handeye", str(bag), str(bag), "--camera-topic", "/cam", "--kinematic-topic", "/tcp",
                 "--out", str(b)]) == 0
    ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
    np.testing.assert_allclose(rb["R_tool_camera"], ra["R_tool_camera"], atol=1e-6)
    np.testing.assert_allclose(rb["t_tool_camera_mm"], ra["t_tool_camera_mm"], atol=1e-3)
    np.testing.assert_allclose(rb["t_mm"], ra["t_mm"], atol=1e-3)


def test_pose_with_covariance_topic_in_a_ros1_bag(tmp_path, pair):
    cam = pair[0]
    bag = write_bag(tmp_path / "amcl.bag", {"/amcl_pose": ("PoseWithCovarianceStamped", cam)}, ros=1)
    got = read_trajectory(bag)
    np.testing.assert_allclose(got.t_s, cam.t_s, atol=1e-6)
    np.testing.assert_allclose(got.T, cam.T, atol=1e-9)
