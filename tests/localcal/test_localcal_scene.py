"""Work cell: default layout, observation of the four markers, OOI from any one marker."""

import numpy as np
import pytest

from posekit.errors import ConfigError, GeometryError
from posekit.geometry import rotation_angle_between
from posekit.localcal.model.camera import zed2_720p
from posekit.localcal.sim.arm import LongReachArm
from posekit.localcal.sim.marker_detector import MarkerDetector
from posekit.localcal.sim.scene import (
    Workcell,
    default_workcell,
    ground_truth_errors,
    observe,
    ooi_pose,
)

INTR = zed2_720p()


@pytest.fixture(scope="module")
def setup():
    arm = LongReachArm(seed=11)
    cell = default_workcell(arm, 11)
    return arm, cell, MarkerDetector(INTR, cell.sizes_mm)


def _angle_deg(A, B):
    return float(np.rad2deg(rotation_angle_between(A[:3, :3], B[:3, :3])))


def test_nominal_layout_reference_numbers():
    arm = LongReachArm(seed=0)
    cell = default_workcell(arm)  # rng=None: the documented layout, no perturbation
    np.testing.assert_allclose(cell.T_C_M[:3, 3], [-180.0, 100.0, 420.0], atol=1e-9)
    np.testing.assert_allclose(cell.T_C_M[:3, :3], [[0, -1, 0], [-1, 0, 0], [0, 0, -1]], atol=1e-12)
    np.testing.assert_allclose(cell.T_F_M, np.eye(4), atol=1e-12)
    gt = ground_truth_errors(cell, arm.true_pose())
    np.testing.assert_allclose(gt.e_C_mm, [350.0, -180.0, 580.0], atol=1e-6)
    np.testing.assert_allclose(gt.rot_C_rad, 0.0, atol=1e-9)
    assert sorted(cell.T_O_markers) == [1, 2, 3]
    np.testing.assert_allclose(cell.T_O_markers[1][:3, 3], [170.0, 0.0, 0.0])
    assert cell.sizes_mm == {0: 70.0, 1: 80.0, 2: 80.0, 3: 80.0}


def test_ground_truth_follows_the_tcp(setup):
    arm, cell, _ = setup
    T0 = arm.true_pose()
    gt0 = ground_truth_errors(cell, T0)
    assert 0.5 < np.rad2deg(np.linalg.norm(gt0.rot_C_rad)) < 10.0  # the OOI's extra tilt
    # move the TCP by the error (minus a 100 mm stand-off) in camera coordinates
    d_C = gt0.e_C_mm - [0.0, 0.0, 100.0]
    T_goal = T0.copy()
    T_goal[:3, 3] += (T0 @ cell.T_F_C)[:3, :3] @ d_C
    gt = ground_truth_errors(cell, np.stack([T0, T_goal]))
    assert gt.e_C_mm.shape == (2, 3) and gt.T_C_O.shape == (2, 4, 4)
    np.testing.assert_allclose(gt.e_C_mm[1], [0.0, 0.0, 100.0], atol=1e-6)
    np.testing.assert_allclose(gt.rot_C_rad[1], gt0.rot_C_rad, atol=1e-12)
    # there, all markers are still seen and the image-based error is close to the truth
    obs = observe(cell, T_goal, setup[2], 5)
    assert obs.seen == (0, 1, 2, 3)
    np.testing.assert_allclose(obs.T_C_O[:3, 3] - obs.T_C_M[:3, 3], [0.0, 0.0, 100.0], atol=3.0)


def test_observe_start_pose_measures_truth(setup):
    arm, cell, detector = setup
    T = arm.true_pose()
    obs = observe(cell, T, detector, 0, keep_image=True)
    gt = ground_truth_errors(cell, T)
    assert obs.seen == (0, 1, 2, 3)
    assert obs.image.shape == (720, 1280)
    np.testing.assert_allclose(obs.T_C_M[:3, 3], gt.T_C_M[:3, 3], atol=4.0)
    np.testing.assert_allclose(obs.T_C_O[:3, 3], gt.T_C_O[:3, 3], atol=10.0)
    assert _angle_deg(obs.T_C_M, gt.T_C_M) < 1.5
    assert _angle_deg(obs.T_C_O, gt.T_C_O) < 1.0
    # same seed, same numbers
    again = observe(cell, T, detector, 0)
    np.testing.assert_array_equal(again.T_C_O, obs.T_C_O)
    assert again.image is None


def test_all_markers_visible_during_20cm_circle(setup):
    arm, cell, detector = setup
    T0 = arm.true_pose()
    for k, phi in enumerate(np.linspace(0.0, 2 * np.pi, 6, endpoint=False)):
        T = T0.copy()
        T[:3, 3] += 200.0 * (np.cos(phi) * T0[:3, 0] + np.sin(phi) * T0[:3, 1])  # n, s plane
        assert observe(cell, T, detector, k).seen == (0, 1, 2, 3), phi


def test_ooi_from_any_one_marker(setup):
    arm, cell, detector = setup
    T = arm.true_pose()
    truth = ground_truth_errors(cell, T).T_C_O
    image = observe(cell, T, detector, 1, keep_image=True).image
    corners = detector.detect_corners(image)
    for keep in (1, 2, 3):
        occluded = image.copy()
        for i in {1, 2, 3} - {keep}:  # paint grey over the other two OOI markers
            (u0, v0), (u1, v1) = corners[i].min(axis=0) - 12, corners[i].max(axis=0) + 12
            occluded[int(v0) : int(v1), int(u0) : int(u1)] = 128
        seen = detector.detect_corners(occluded)
        assert sorted(seen) == [0, keep]
        T_C_O = ooi_pose(cell, detector, seen)
        # one 80 mm marker (~42 px) at 1 m: IPPE's rotation is good to a few degrees
        # (up to ~9 deg), which moves the OOI centre 0.2 m away by up to ~25 mm in depth
        np.testing.assert_allclose(T_C_O[:2, 3], truth[:2, 3], atol=10.0)
        assert abs(T_C_O[2, 3] - truth[2, 3]) < 35.0
        assert _angle_deg(T_C_O, truth) < 10.0
    # all three together (one PnP over 12 corners) is much better
    T_C_O = ooi_pose(cell, detector, corners)
    np.testing.assert_allclose(T_C_O[:3, 3], truth[:3, 3], atol=10.0)
    assert _angle_deg(T_C_O, truth) < 1.0
    assert ooi_pose(cell, detector, {0: corners[0]}) is None


def test_bad_input_messages(setup):
    arm, cell, detector = setup
    with pytest.raises(ConfigError, match=r"^sizes_mm: unknown marker size for marker 3$"):
        Workcell(cell.T_F_C, cell.T_F_M, cell.T_B_O, cell.T_O_markers, {0: 70.0, 1: 80.0, 2: 80.0})
    with pytest.raises(ConfigError, match=r"^detector: unknown marker size for marker 2$"):
        observe(cell, arm.true_pose(), MarkerDetector(INTR, {0: 70.0, 1: 80.0}), 0)
    T = arm.true_pose()
    T[3, 3] = 2.0
    with pytest.raises(
        GeometryError,
        match=r"^T_B_F_true: expected last row \[0, 0, 0, 1\] within 1e-06, found \[0\. 0\. 0\. 2\.\]$",
    ):
        observe(cell, T, detector, 0)
    with pytest.raises(GeometryError, match=r"^T_B_F_true: expected last row \[0, 0, 0, 1\]"):
        ground_truth_errors(cell, T)
    with pytest.raises(ConfigError, match=r"^distance_mm must be between 500 and 2000 mm, got 100.0$"):
        default_workcell(arm, distance_mm=100.0)
