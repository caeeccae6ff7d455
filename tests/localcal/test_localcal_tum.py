"""TUM trajectory files: reading real TUM RGB-D data, round trips, and malformed input."""

import numpy as np
import pytest
from pytransform3d.rotations import (
    matrix_from_quaternion as pt3d_matrix_from_quaternion,
)

from posekit.errors import InputFileError, TrajectoryError
from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.formats.tum import read_tum, write_tum
from tests.localcal.synth_trajectories import TUM_DATA as DATA

FR1_SLAM = DATA / "freiburg1_xyz-rgbdslam.txt"
# first data line of freiburg1_xyz-rgbdslam.txt (line 2, after one comment line)
FR1_FIRST = (1305031102.160407, 1.344379, 0.627206, 1.661754, 0.658249, 0.611043, -0.294444, -0.326553)


def test_read_real_tum_file_converts_to_mm_and_wxyz():
    traj = read_tum(FR1_SLAM)
    assert len(traj) == 788
    t, x, y, z, qx, qy, qz, qw = FR1_FIRST
    assert traj.t_s[0] == t
    np.testing.assert_allclose(traj.positions[0], [x * 1000, y * 1000, z * 1000], atol=1e-9)
    # independent conversion: pytransform3d takes (w, x, y, z)
    q = np.array([qw, qx, qy, qz])
    np.testing.assert_allclose(traj.rotations[0], pt3d_matrix_from_quaternion(q / np.linalg.norm(q)), atol=1e-12)
    assert np.all(np.diff(traj.t_s) > 0)


def test_ground_truth_with_duplicate_stamps_and_header_comments_reads():
    traj = read_tum(DATA / "fr2_desk_groundtruth.txt")
    assert len(traj) == 20957
    assert np.sum(np.diff(traj.t_s) == 0) > 0          # the file repeats some stamps: kept, not dropped


def test_write_read_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    traj = read_tum(FR1_SLAM)
    sub = Trajectory(traj.t_s[:50] + rng.uniform(0, 1e-3), traj.T[:50])
    path = tmp_path / "t.tum"
    write_tum(path, sub)
    back = read_tum(path)
    np.testing.assert_allclose(back.t_s, sub.t_s, atol=1e-6)
    np.testing.assert_allclose(back.T, sub.T, atol=1e-6)       # 1e-9 m = 1e-6 mm in the file


def test_comments_blank_lines_and_commas_are_accepted(tmp_path):
    p = tmp_path / "c.tum"
    p.write_text("# header\n\n0.0 0 0 0 0 0 0 1\n  # indented comment\n1.0,0.001,0.002,0.003,0,0,0,1\n")
    traj = read_tum(p)
    np.testing.assert_allclose(traj.positions, [[0, 0, 0], [1, 2, 3]])
    np.testing.assert_allclose(traj.t_s, [0.0, 1.0])


@pytest.mark.parametrize(("text", "message"), [
    ("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n",
     "bad.tum:2: expected 8 numbers 'timestamp tx ty tz qx qy qz qw', found 7 fields"),
    ("# c\n0 0 0 0 0 0 0 1\n1 0 zero 0 0 0 0 1\n",
     "bad.tum:3: expected 8 numbers 'timestamp tx ty tz qx qy qz qw', found 'zero'"),
    ("0 0 0 0 0 0 0 1\n1 0 " + "x" * 60 + " 0 0 0 0 1\n",      # a long field shortened, as every reader does
     r"bad.tum:2: expected 8 numbers 'timestamp tx ty tz qx qy qz qw', found 'x{37}\.\.\.'$"),
    ("0 0 0 0 0 0 0 1\n1 0 nan 0 0 0 0 1\n", "bad.tum:2: expected finite numbers, found NaN or infinity"),
    ("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 2\n",
     "bad.tum:2: expected a unit quaternion qx qy qz qw, found norm 2"),
    ("1 0 0 0 0 0 0 1\n0.5 0 0 0 0 0 0 1\n",
     r"bad.tum:2: timestamps must not decrease: 0.500000 s after 1.000000 s \(line 1\)"),
    ("", r"bad.tum: no poses found \(expected lines 'timestamp tx ty tz qx qy qz qw'\)"),
    ("# only a comment\n\n", r"bad.tum: no poses found"),
])
def test_malformed_files_name_file_and_line(tmp_path, text, message):
    p = tmp_path / "bad.tum"
    p.write_text(text)
    with pytest.raises(InputFileError, match=message) as info:
        read_tum(p)
    assert "\n" not in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputFileError, match=r"nope.tum: no such file; expected a TUM trajectory file"):
        read_tum(tmp_path / "nope.tum")


def test_trajectory_validates_shapes_and_order():
    with pytest.raises(TrajectoryError, match=r"t_s of shape \(N,\) and T of shape \(N, 4, 4\)"):
        Trajectory(np.zeros(3), np.zeros((2, 4, 4)))
    T = np.broadcast_to(np.eye(4), (2, 4, 4))
    with pytest.raises(TrajectoryError, match="pose 1 has t=0.000000 s after t=1.000000 s"):
        Trajectory(np.array([1.0, 0.0]), T)
