"""Hostile input to ``localcal match`` and ``localcal handeye`` (issue 14): every trajectory format
(TUM, KITTI, EuRoC, ROS 1/2 bags) malformed, truncated, huge, non-finite or absurd, and bad flags.

Each is one line ``posekit: error: FILE[:LINE]: what was wrong; what was expected``, exit 1, no
traceback and no result file (DESIGN.md "Safe input and output").
"""

import shutil

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.cli_helpers import assert_one_line_error, run_cli

VERBS = ("match", "handeye")
TUM_LAYOUT = "'timestamp tx ty tz qx qy qz qw'"
TUM_WHAT = f"a TUM trajectory file ({TUM_LAYOUT} per line)"
BAG_WHAT = ("a ROS bag (.bag, .db3, .mcap or a ROS 2 bag folder) with a PoseStamped, Odometry or TransformStamped "
            "topic")
N = 60


def _poses():
    """60 poses at 10 Hz of a smooth 3D motion (s, m, quaternions x y z w)."""
    t = 100.0 + 0.1 * np.arange(N)
    p = np.c_[np.sin(t), np.cos(0.7 * t), 0.3 * np.sin(1.3 * t)]
    q = Rotation.from_rotvec(0.5 * np.c_[np.sin(0.5 * t), np.cos(0.3 * t), np.sin(0.2 * t)]).as_quat()
    return t, p, q


def _tum_lines():
    t, p, q = _poses()
    return [f"{a:.6f} " + " ".join(f"{v:.9f}" for v in (*pp, *qq)) + "\n" for a, pp, qq in zip(t, p, q)]


@pytest.fixture()
def pair(tmp_path):
    """A good CAMERA.tum and a KINEMATIC.tum displaced by a fixed offset."""
    t, p, q = _poses()
    cam = tmp_path / "cam.tum"
    cam.write_text("".join(_tum_lines()))
    kin = tmp_path / "kin.tum"
    kin.write_text("".join(f"{a:.6f} " + " ".join(f"{v:.9f}" for v in (*(pp + [0.4, 0.1, 0.2]), *qq)) + "\n"
                           for a, pp, qq in zip(t, p, q)))
    return tmp_path, cam, kin


def _both(capsys, tmp, camera, kinematic, *extra, message, global_args=()):
    """Run match and handeye on the pair; each must fail with exactly ``message`` and write nothing."""
    for verb in VERBS:
        out = tmp / f"{verb}.json"
        rc, o, e = run_cli(capsys, *global_args, "localcal", verb, camera, kinematic, "--out", out, *extra)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: {message}\n", verb
        assert not out.exists() and list(tmp.glob(f".{verb}.json.*")) == []


def _replace(lines, i, text):
    return "".join(lines[:i]) + text + "".join(lines[i + 1:])


# ------------------------------------------------------------------------ TUM

def _tum_cases():
    L = _tum_lines()
    f = L[5].split()
    return [
        ("empty", "", f"no poses found (expected lines {TUM_LAYOUT})"),
        ("comments", "# a\n# b\n", f"no poses found (expected lines {TUM_LAYOUT})"),
        ("nan", _replace(L, 5, " ".join([f[0], "nan"] + f[2:]) + "\n"), "6: expected finite numbers, found NaN or "
                                                                         "infinity"),
        ("inf", _replace(L, 5, " ".join(f[:3] + ["-inf"] + f[4:]) + "\n"), "6: expected finite numbers, found NaN "
                                                                           "or infinity"),
        ("short_row", _replace(L, N - 1, " ".join(L[-1].split()[:4]) + "\n"),
         f"60: expected 8 numbers {TUM_LAYOUT}, found 4 fields"),
        ("cut_mid_number", "".join(L[:-1]) + L[-1][:12], f"60: expected 8 numbers {TUM_LAYOUT}, found 2 fields"),
        ("word", _replace(L, 3, "a b c d e f g h\n"), f"4: expected 8 numbers {TUM_LAYOUT}, found 'a'"),
        ("backwards", _replace(L, 3, L[1]), "4: timestamps must not decrease: 100.100000 s after 100.200000 s "
                                            "(line 3)"),
        ("zero_quat", _replace(L, 3, " ".join(L[3].split()[:4] + ["0", "0", "0", "0"]) + "\n"),
         "4: expected a unit quaternion qx qy qz qw, found norm 0"),
        # fixed here: 1e300 m was read, overflowed to inf/NaN and came out as a NaN message or a JSON of inf
        ("absurd_position", _replace(L, 3, " ".join(L[3].split()[:1] + ["1e300", "0", "0"] + L[3].split()[4:]) + "\n"),
         "4: position 1e+300 m is implausible; expected metres"),
        # the rows decide the format (issue 30): a .txt of KITTI rows is KITTI, which needs a rate
        ("kitti_as_tum", None, "rows of 12 numbers, a KITTI pose file, which carries no time: give its frame rate "
                               "with --rate-hz HZ"),
    ]


@pytest.mark.parametrize(("case", "text", "message"), _tum_cases(), ids=[c[0] for c in _tum_cases()])
def test_bad_tum_camera(capsys, pair, case, text, message):
    tmp, _, kin = pair
    bad = tmp / "bad.txt"
    if text is None:
        t, p, q = _poses()
        R = Rotation.from_quat(q).as_matrix()
        text = "".join(" ".join(f"{v:.9f}" for v in np.c_[R[k], p[k]].ravel()) + "\n" for k in range(N))
    bad.write_text(text)
    sep = ":" if message[0].isdigit() else ": "
    _both(capsys, tmp, bad, kin, message=f"{bad}{sep}{message}")


def test_tum_encoding_size_and_kind(capsys, pair):
    tmp, cam, kin = pair
    binary = tmp / "bin.tum"
    binary.write_bytes(bytes(range(256)) * 4)
    _both(capsys, tmp, binary, kin, message=f"{binary}: binary data (NUL bytes); expected {TUM_WHAT} (UTF-8 text)")
    u16 = tmp / "u16.tum"
    u16.write_bytes(cam.read_text().encode("utf-16"))
    _both(capsys, tmp, u16, kin, message=f"{u16}: UTF-16 (little-endian) text; expected {TUM_WHAT} in UTF-8")
    huge = tmp / "huge.tum"
    huge.write_text(cam.read_text() * 400)                          # 2.2 MiB of valid rows
    _both(capsys, tmp, huge, kin, global_args=("--max-input-mb", 1),
          message=f"{huge}: 2.22 MiB, above the 1 MiB limit for {TUM_WHAT} (raise it with --max-input-mb)")
    missing = tmp / "missing.tum"
    _both(capsys, tmp, missing, kin, message=f"{missing}: no such file; expected {TUM_WHAT}")
    odd = tmp / "poses.xyz"                                  # rows that are no format, an unknown suffix
    odd.write_text(cam.read_text().replace(" ", " 1 ", 1))
    _both(capsys, tmp, odd, kin, message=f"{odd}: cannot tell the trajectory format from the suffix '.xyz'; "
                                         "expected .tum/.txt (TUM), .csv (EuRoC), .bag/.db3/.mcap or a bag folder "
                                         "(ROS), or give --format tum|kitti|euroc|rosbag")
    folder = tmp / "folder"
    folder.mkdir()
    _both(capsys, tmp, folder, kin, message=f"{folder}: a folder without metadata.yaml; expected a trajectory file "
                                            "or a ROS 2 bag folder")


def test_too_few_poses(capsys, pair):
    tmp, cam, kin = pair
    one = tmp / "one.tum"
    one.write_text(_tum_lines()[0])
    rc, o, e = run_cli(capsys, "localcal", "match", one, kin, "--out", tmp / "m.json")
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: {one}: 1 poses, at least 6 are needed for trajectory matching\n"
    rc, o, e = run_cli(capsys, "localcal", "handeye", one, kin, "--out", tmp / "h.json")
    assert_one_line_error(rc, o, e)
    assert e == (f"posekit: error: hand-eye needs >= 3 camera poses and >= 2 kinematic poses, got 1 ({one}) and "
                 f"60 ({kin})\n")


# ------------------------------------------------------------------------ KITTI, EuRoC

def _kitti_text():
    _, p, q = _poses()
    R = Rotation.from_quat(q).as_matrix()
    return "".join(" ".join(f"{v:.9f}" for v in np.c_[R[k], p[k]].ravel()) + "\n" for k in range(N))


def test_kitti(capsys, pair):
    tmp, _, kin = pair
    k = tmp / "poses.kitti"
    k.write_text(_kitti_text())
    no_rate = f"{k}: a KITTI pose file carries no time; give its frame rate with --rate-hz HZ"
    _both(capsys, tmp, k, kin, "--format", "kitti", message=no_rate)
    _both(capsys, tmp, k, kin, "--camera-format", "kitti", "--kinematic-rate-hz", 10, message=no_rate)
    for rate in ("0", "nan", "-5", "1e7"):
        _both(capsys, tmp, k, kin, "--camera-format", "kitti", "--rate-hz", rate,
              message=f"--rate-hz: expected a number > 0 and <= 1000000 Hz, got {rate}")
    lines = _kitti_text().splitlines(keepends=True)
    for text, message in [
        (_replace(lines, 2, " ".join(lines[2].split()[:11]) + "\n"),
         "3: expected 12 numbers 'r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz', found 11 fields"),
        (_replace(lines, 2, "2 0 0 0 0 1 0 0 0 0 1 0\n"),
         "3: expected a rotation matrix in columns 1-3, 5-7, 9-11, found max |R^T R - I| = 3, det 2"),
        (_replace(lines, 2, "1 0 0 nan 0 1 0 0 0 0 1 0\n"), "3: expected finite numbers, found NaN or infinity"),
        # fixed here, as for TUM
        (_replace(lines, 2, "1 0 0 1e300 0 1 0 0 0 0 1 0\n"), "3: position 1e+300 m is implausible; expected metres"),
    ]:
        k.write_text(text)
        _both(capsys, tmp, k, kin, "--camera-format", "kitti", "--camera-rate-hz", 10, message=f"{k}:{message}")


def test_euroc(capsys, pair):
    tmp, _, kin = pair
    e = tmp / "gt.csv"
    layout = "'timestamp_ns, px, py, pz, qw, qx, qy, qz'"
    row = "1403636579758555392,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152"
    for text, message in [
        ("#timestamp,x\n1,2\n", f":2: expected at least 8 comma-separated numbers {layout}, found 2 fields"),
        ("#t\n", f": no poses found (expected lines of at least 8 comma-separated numbers {layout})"),
        ("#t\n" + row + "\n" + row[:30] + "\n", f":3: expected at least 8 comma-separated numbers {layout}, found 3 "
                                               "fields"),
        ("#t\n" + row.replace("4.688319", "1e300") + "\n", ":2: position 1e+300 m is implausible; expected metres"),
    ]:
        e.write_text(text)
        _both(capsys, tmp, e, kin, message=f"{e}{message}")


# ------------------------------------------------------------------------ bags

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

POSE = "geometry_msgs/msg/PoseStamped"


def _pose_msg(ts, k):
    t, p, q = _poses()
    ty = ts.types
    sec = int(t[k])
    extra = {"seq": k} if "seq" in ty["std_msgs/msg/Header"].__dataclass_fields__ else {}
    header = ty["std_msgs/msg/Header"](**extra, stamp=ty["builtin_interfaces/msg/Time"](
        sec=sec, nanosec=int(round((t[k] - sec) * 1e9))), frame_id="world")
    pose = ty["geometry_msgs/msg/Pose"](position=ty["geometry_msgs/msg/Point"](x=p[k, 0], y=p[k, 1], z=p[k, 2]),
                                        orientation=ty["geometry_msgs/msg/Quaternion"](x=q[k, 0], y=q[k, 1],
                                                                                       z=q[k, 2], w=q[k, 3]))
    return ty[POSE](header=header, pose=pose)


def _bag1(path, topics=("/pose",), n=N):
    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(path) as w:
        for topic in topics:
            c = w.add_connection(topic, POSE, typestore=ts)
            for k in range(n):
                w.write(c, 10**9 + k, ts.serialize_ros1(_pose_msg(ts, k), POSE))
    return path


def _bag2(path):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer2(path, version=9) as w:
        c = w.add_connection("/pose", POSE, typestore=ts)
        for k in range(N):
            w.write(c, 10**9 + k, ts.serialize_cdr(_pose_msg(ts, k), POSE))
    return path


def test_ros1_bags(capsys, pair):
    tmp, cam, kin = pair
    two = _bag1(tmp / "two.bag", ("/a", "/b"))
    _both(capsys, tmp, two, kin, message=f"{two}: 2 pose topics (/a (geometry_msgs/PoseStamped), /b "
                                         "(geometry_msgs/PoseStamped)); name one with --topic")
    _both(capsys, tmp, two, kin, "--topic", "/nope", message=f"{two}: no topic '/nope'; pose topics: /a "
                                                             "(geometry_msgs/PoseStamped), /b (geometry_msgs/PoseStamped)")
    zero = _bag1(tmp / "zero.bag", ("/a",), 0)
    _both(capsys, tmp, zero, kin, message=f"{zero}: topic /a holds no messages; expected poses")
    data = _bag1(tmp / "one.bag").read_bytes()
    for name, cut in [("half.bag", data[: len(data) // 2]), ("tail.bag", data[:-7]), ("junk.bag", b"#ROSBAG V2.0\n"
                                                                                                  + bytes(range(256)))]:
        bad = tmp / name
        bad.write_bytes(cut)
        for verb in VERBS:
            rc, o, e = run_cli(capsys, "localcal", verb, bad, kin, "--out", tmp / "r.json")
            assert_one_line_error(rc, o, e)
            assert e.startswith(f"posekit: error: {bad}: not a readable ROS bag (") and e.endswith(
                f"); expected {BAG_WHAT}\n"), e
    _both(capsys, tmp, tmp / "one.bag", kin, "--format", "tum",
          message=f"{tmp / 'one.bag'}: binary data (NUL bytes); expected {TUM_WHAT} (UTF-8 text)")
    _both(capsys, tmp, cam, kin, "--format", "rosbag", message=f"{cam}: suffix '.tum' is not a bag; expected {BAG_WHAT}")


#: A "billion laughs" YAML: 160 characters that expand to 9^4 values.
BOMB = ("a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
        "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n")


def test_ros2_bag_folder_metadata(capsys, pair):
    """Fixed here: metadata.yaml went to rosbags unchecked (no size limit; rosbags' own multi-part
    messages); it is now read through posekit.io first."""
    tmp, _, kin = pair
    good = _bag2(tmp / "r2")
    rc, o, e = run_cli(capsys, "localcal", "match", good, kin, "--out", tmp / "ok.json")
    assert rc == 0, e
    for name, text, message in [
        ("badyaml", "rosbag2_bagfile_information: [\n", "not valid YAML at line 2"),
        ("notbag", "name: x\n", "no 'rosbag2_bagfile_information' mapping; expected the metadata of a ROS 2 bag "
                                "folder"),
        ("bomb", BOMB, f"expands to more than {2 * len(BOMB) + 64} values (YAML aliases); expected a plain "
                       "document"),
    ]:
        bag = tmp / name
        shutil.copytree(good, bag)
        (bag / "metadata.yaml").write_text(text)
        _both(capsys, tmp, bag, kin, message=f"{bag / 'metadata.yaml'}: {message}")
    huge = tmp / "huge"
    shutil.copytree(good, huge)
    (huge / "metadata.yaml").write_text("a: " + "x" * (2 * 2**20) + "\n")
    _both(capsys, tmp, huge, kin, global_args=("--max-input-mb", 1),
          message=f"{huge / 'metadata.yaml'}: 2 MiB, above the 1 MiB limit for the metadata of a ROS 2 bag folder "
                  "(raise it with --max-input-mb)")


# ------------------------------------------------------------------------ flags and --out

def test_flags_and_out(capsys, pair):
    tmp, cam, kin = pair
    folder = tmp / "outdir"
    folder.mkdir()
    for verb in VERBS:
        rc, o, e = run_cli(capsys, "localcal", verb, cam, kin, "--out", folder)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: --out {folder}: is a folder; expected a file name\n"
    for flag, value, message in [
        ("--max-std-mm", "-1", "--max-std-mm: expected a number > 0 and <= 100000 mm, got -1"),
        ("--max-std-mm", "nan", "--max-std-mm: expected a number > 0 and <= 100000 mm, got nan"),
        ("--max-dt", "0", "--max-dt: expected a number > 0 and <= 10 s, got 0"),
        ("--time-offset", "inf", "--time-offset: expected a number in -10000000000..10000000000 s, got inf"),
        ("--noise-deg", "100", "--noise-deg: expected a number > 0 and <= 90 deg, got 100"),
    ]:
        rc, o, e = run_cli(capsys, "localcal", "handeye", cam, kin, "--out", tmp / "h.json", flag, value)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: {message}\n"
    rc, o, e = run_cli(capsys, "localcal", "match", cam, kin, "--out", tmp / "m.json", "--matcher", "icp")
    assert rc == 2 and o == "" and "Traceback" not in e
    assert e.endswith("error: argument --matcher: invalid choice: 'icp' (choose from 'cpd', 'hybrid')\n")
    assert not (tmp / "m.json").exists() and not (tmp / "h.json").exists()
