"""Rotation output a robot controller can take: quaternion (sign continuous along a batch),
matrix, KUKA A,B,C (intrinsic Z-Y'-X'') and Fanuc/ABB W,P,R (fixed-axis X-Y-Z), checked
against scipy.spatial.transform.Rotation."""

import csv
import json
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.cli.main import main
from posekit.errors import EstimationError
from posekit.geometry import euler_zyx_from_matrix, quaternion_from_matrix
from posekit.profiler import NoiseModel, bundled_gauge, render_profiles, sample_poses
from posekit.profiler.estimate.pipeline import ROTATIONS, estimate_batch, rotation_fields
from posekit.profiler.sim.poses import Workspace
from posekit.profiler.stream.records import RECORD_CSV_COLUMNS

#: A sensor looking straight down at the gauge: 180° about x.
DOWN = np.diag([1.0, -1.0, -1.0])


def test_reference_values():
    assert ROTATIONS == ("quat", "matrix", "euler-zyx", "euler-xyz")
    assert rotation_fields(DOWN, "quat") == {}
    assert rotation_fields(DOWN, "matrix") == {"R": [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]}
    assert rotation_fields(DOWN, "euler-zyx") == {"euler_zyx_deg": [0.0, 0.0, 180.0]}
    assert rotation_fields(DOWN, "euler-xyz") == {"euler_xyz_deg": [180.0, 0.0, 0.0]}
    # A = 90: a quarter turn about z; then B = 30 about the new y
    R = Rotation.from_euler("ZYX", [90, 30, 0], degrees=True).as_matrix()
    np.testing.assert_allclose(rotation_fields(R, "euler-zyx")["euler_zyx_deg"], [90, 30, 0], atol=1e-12)
    np.testing.assert_allclose(rotation_fields(R, "euler-xyz")["euler_xyz_deg"], [0, 30, 90], atol=1e-12)


def test_euler_matches_scipy_on_random_rotations():
    rots = Rotation.random(500, random_state=1)
    for rot in rots:
        R = rot.as_matrix()
        abc = rotation_fields(R, "euler-zyx")["euler_zyx_deg"]
        wpr = rotation_fields(R, "euler-xyz")["euler_xyz_deg"]
        # the convention: intrinsic Z-Y'-X'' (KUKA A, B, C) and extrinsic X-Y-Z (W, P, R)
        np.testing.assert_allclose(Rotation.from_euler("ZYX", abc, degrees=True).as_matrix(), R, atol=1e-12)
        np.testing.assert_allclose(Rotation.from_euler("xyz", wpr, degrees=True).as_matrix(), R, atol=1e-12)
        # ... and the same angles as scipy gives (first and last in (-180, 180], middle in [-90, 90])
        np.testing.assert_allclose(abc, rot.as_euler("ZYX", degrees=True), atol=1e-9)
        np.testing.assert_allclose(wpr, rot.as_euler("xyz", degrees=True), atol=1e-9)
        assert -90 <= abc[1] <= 90


@pytest.mark.parametrize("b", [90.0, -90.0])
def test_gimbal_lock_puts_the_turn_in_the_first_angle(b):
    R = Rotation.from_euler("ZYX", [40, b, 25], degrees=True).as_matrix()
    abc = rotation_fields(R, "euler-zyx")["euler_zyx_deg"]
    assert abc[1] == pytest.approx(b)
    assert abc[2] == 0.0
    np.testing.assert_allclose(Rotation.from_euler("ZYX", abc, degrees=True).as_matrix(), R, atol=1e-9)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                     # scipy warns of the gimbal lock
        np.testing.assert_allclose(abc, Rotation.from_matrix(R).as_euler("ZYX", degrees=True), atol=1e-6)
    np.testing.assert_allclose(euler_zyx_from_matrix(R), np.radians(abc), atol=1e-12)


def test_unknown_rotation_format():
    msg = r"^unknown rotation format 'rpy'; expected one of quat, matrix, euler-zyx, euler-xyz$"
    with pytest.raises(EstimationError, match=msg):
        rotation_fields(DOWN, "rpy")
    with pytest.raises(EstimationError, match=msg):
        next(estimate_batch(np.zeros((1, 10, 2)), bundled_gauge("demo-5"), rotation="rpy"))


def _down_batch(count=40, seed=3):
    """Poses looking nearly straight down, where the canonical quaternion (w >= 0, w ≈ 0) flips."""
    g = bundled_gauge("demo-5")
    Ts = sample_poses(g, count, rng=seed, workspace=Workspace(rotation_deg=(3.0, 3.0, 3.0)))
    return g, Ts, render_profiles(g, Ts, NoiseModel(), rng=seed)


def test_quaternion_sign_is_continuous_along_a_batch():
    g, Ts, profiles = _down_batch()
    profiles[5] = np.nan                                    # an error record in between is skipped
    records = [rec for rec, _ in estimate_batch(profiles, g)]
    assert records[5]["status"] == "error" and records[5]["q_wxyz"] is None
    qs = [np.array(r["q_wxyz"]) for r in records if r["q_wxyz"] is not None]
    assert all(a @ b >= 0 for a, b in zip(qs, qs[1:]))
    canonical = [np.array(r["q_wxyz"]) for r, _ in estimate_batch(profiles, g, continuous=False)
                 if r["q_wxyz"] is not None]
    assert all(q[0] >= 0 for q in canonical)
    assert any(a @ b < 0 for a, b in zip(canonical, canonical[1:]))     # the flips the stream avoids
    for q, c in zip(qs, canonical):                                      # same rotations, sign apart
        assert abs(abs(q @ c) - 1) < 1e-12
    np.testing.assert_array_equal(qs[0], canonical[0])                   # the first is canonical


def run(capsys, *argv):
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.parametrize("rotation, key, columns", [
    ("matrix", "R", ["r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33"]),
    ("euler-zyx", "euler_zyx_deg", ["a_deg", "b_deg", "c_deg"]),
    ("euler-xyz", "euler_xyz_deg", ["w_deg", "p_deg", "r_deg"]),
])
def test_cli_rotation_output(capsys, tmp_path, rotation, key, columns):
    g, Ts, profiles = _down_batch(6, seed=4)
    path = tmp_path / "p.npz"
    np.savez(path, profiles=profiles)
    rc, out, err = run(capsys, "profiler", "estimate", path, "--gauge", "demo-5", "--rotation", rotation)
    assert rc == 0, err
    records = [json.loads(line) for line in out.splitlines()]
    for rec in records:
        R = Rotation.from_quat(np.roll(rec["q_wxyz"], -1)).as_matrix()     # scipy: x, y, z, w
        if rotation == "matrix":
            np.testing.assert_allclose(rec[key], R, atol=1e-12)
        elif rotation == "euler-zyx":
            np.testing.assert_allclose(Rotation.from_euler("ZYX", rec[key], degrees=True).as_matrix(), R, atol=1e-12)
        else:
            np.testing.assert_allclose(Rotation.from_euler("xyz", rec[key], degrees=True).as_matrix(), R, atol=1e-12)
    qs = np.array([r["q_wxyz"] for r in records])
    assert np.all(np.sum(qs[1:] * qs[:-1], axis=1) >= 0)
    out_csv = tmp_path / "p.csv"
    rc, _, err = run(capsys, "profiler", "estimate", path, "--gauge", "demo-5", "--rotation", rotation,
                     "--out", out_csv)
    assert rc == 0, err
    with open(out_csv, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == RECORD_CSV_COLUMNS + columns
    for row, rec in zip(rows[1:], records):
        np.testing.assert_array_equal([float(v) for v in row[len(RECORD_CSV_COLUMNS):]], np.ravel(rec[key]))
        np.testing.assert_array_equal([float(v) for v in row[5:9]], rec["q_wxyz"])


def test_cli_rotation_default_is_the_quaternion_contract(capsys, tmp_path):
    g, Ts, profiles = _down_batch(3, seed=5)
    path = tmp_path / "p.npz"
    np.savez(path, profiles=profiles)
    rc, out, err = run(capsys, "profiler", "estimate", path, "--gauge", "demo-5")
    assert rc == 0, err
    rec = json.loads(out.splitlines()[0])
    assert "R" not in rec and "euler_zyx_deg" not in rec and "euler_xyz_deg" not in rec
    q = np.array(rec["q_wxyz"])
    assert abs(abs(q @ quaternion_from_matrix(Ts[0][:3, :3])) - 1) < 1e-4
    rc, _, err = run(capsys, "profiler", "estimate", path, "--gauge", "demo-5", "--rotation", "rpy")
    assert rc == 2 and "invalid choice: 'rpy'" in err
