"""Eye-in-hand camera: ArUco rendering with OpenCV, detection + solvePnP IPPE_SQUARE."""

import numpy as np
import pytest

from posekit.errors import ConfigError, GeometryError, InputFileError
from posekit.geometry import matrix_from_rotation_vector, rotation_angle_between
from posekit.localcal.model.camera import zed2_720p
from posekit.localcal.sim.camera import marker_corners, render_markers
from posekit.localcal.sim.marker_detector import MarkerDetector

INTR = zed2_720p()
FACING = np.diag([1.0, -1.0, -1.0])  # R_C_M of a marker seen head-on


def _pose(rotvec, t_mm):
    T = np.eye(4)
    T[:3, :3] = matrix_from_rotation_vector(rotvec) @ FACING
    T[:3, 3] = t_mm
    return T


def test_zed2_720p_intrinsics():
    assert (INTR.width, INTR.height) == (1280, 720)
    np.testing.assert_array_equal(INTR.K, [[528.0, 0.0, 640.0], [0.0, 528.0, 360.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(INTR.dist, np.zeros(5))
    hfov = np.rad2deg(2 * np.arctan(640.0 / 528.0))
    assert hfov == pytest.approx(100.9, abs=0.1)
    np.testing.assert_allclose(INTR.project([[100.0, -50.0, 1000.0]]), [[692.8, 333.6]])


def test_marker_corner_order_matches_aruco():
    np.testing.assert_array_equal(
        marker_corners(100.0), [[-50, 50, 0], [50, 50, 0], [50, -50, 0], [-50, -50, 0]]
    )


def test_detected_poses_match_rendered_truth():
    truth = {
        0: (70.0, _pose([0.15, -0.25, 0.4], [-120.0, 80.0, 600.0])),
        1: (90.0, _pose([-0.1, 0.2, -0.3], [200.0, -100.0, 1000.0])),
    }
    image = render_markers(INTR, [(i, s, T) for i, (s, T) in truth.items()], 3)
    assert image.shape == (720, 1280) and image.dtype == np.uint8
    found = MarkerDetector(INTR, {i: s for i, (s, _) in truth.items()}).detect(image)
    assert sorted(found) == [0, 1]
    for i, (lateral_mm, depth_mm, angle_deg) in {0: (2.0, 6.0, 2.0), 1: (3.0, 15.0, 5.0)}.items():
        T, T_true = found[i], truth[i][1]
        d = T[:3, 3] - T_true[:3, 3]
        assert np.all(np.abs(d[:2]) < lateral_mm), (i, d)
        assert abs(d[2]) < depth_mm, (i, d)
        assert np.rad2deg(rotation_angle_between(T[:3, :3], T_true[:3, :3])) < angle_deg


def test_pose_noise_grows_with_distance():
    near, far = _pose([0.1, 0.1, 0.0], [-150.0, 0.0, 500.0]), _pose([0.1, 0.1, 0.0], [300.0, 0.0, 1500.0])
    detector = MarkerDetector(INTR, {1: 90.0, 2: 90.0})
    err = {1: [], 2: []}
    for seed in range(5):
        found = detector.detect(render_markers(INTR, [(1, 90.0, near), (2, 90.0, far)], seed))
        err[1].append(found[1][:3, 3] - near[:3, 3])
        err[2].append(found[2][:3, 3] - far[:3, 3])
    std_near, std_far = np.std(err[1], axis=0), np.std(err[2], axis=0)
    # 5 seeds: depth std ~0.35 mm at 0.5 m, ~1.1 mm at 1.5 m; the error (noise + the
    # detector's inward corner bias) ~1.6 mm vs ~19 mm
    assert std_far[2] > 2.0 * std_near[2]
    assert np.linalg.norm(std_far) > 2.0 * np.linalg.norm(std_near)
    assert std_near[2] < 1.0
    rms_near, rms_far = (np.sqrt(np.mean(np.sum(np.square(err[i]), axis=1))) for i in (1, 2))
    assert rms_far > 5.0 * rms_near


def test_markers_out_of_view_behind_or_backwards_are_not_detected():
    markers = [
        (1, 90.0, _pose([0.0, 0.0, 0.0], [1500.0, 0.0, 1000.0])),  # right of the image
        (2, 90.0, _pose([0.0, 0.0, 0.0], [0.0, 0.0, -800.0])),  # behind the camera
        (3, 90.0, _pose([0.0, np.pi, 0.0], [0.0, 0.0, 800.0])),  # seen from its back
    ]
    image = render_markers(INTR, markers, 0)
    assert MarkerDetector(INTR, {1: 90.0, 2: 90.0, 3: 90.0}).detect(image) == {}
    # a nearer marker hides a farther one behind it
    image = render_markers(
        INTR, [(1, 90.0, _pose([0, 0, 0], [0.0, 0.0, 1200.0])), (2, 90.0, _pose([0, 0, 0], [0.0, 0.0, 500.0]))], 0
    )
    assert sorted(MarkerDetector(INTR, {1: 90.0, 2: 90.0}).detect(image)) == [2]


def test_render_is_reproducible_and_noise_level_is_the_same_at_the_markers_and_elsewhere():
    markers = [(1, 90.0, _pose([0.0, 0.0, 0.0], [0.0, 0.0, 1000.0]))]
    image = render_markers(INTR, markers, 7)
    np.testing.assert_array_equal(render_markers(INTR, markers, 7), image)
    assert np.any(render_markers(INTR, markers, 8) != image)
    # without corner jitter the grey-level noise is the only difference to a noiseless frame
    for seed in (0, 1):
        noise = render_markers(INTR, markers, seed, noise_px=0.0).astype(float) - render_markers(
            INTR, markers, seed, noise_px=0.0, noise_gray=0.0
        )
        (u0, v0), (u1, v1) = INTR.project([[-40.0, -40.0, 1000.0], [40.0, 40.0, 1000.0]]).astype(int)
        at_marker, on_wall = noise[v0:v1, u0:u1], noise[:200, :300]  # 42x42 px inside the marker
        for region in (at_marker, on_wall):
            assert 2.7 < np.std(region) < 3.3 and abs(np.mean(region)) < 0.2
    # no noise at all: the seed no longer matters
    quiet = {"noise_px": 0.0, "noise_gray": 0.0}
    np.testing.assert_array_equal(render_markers(INTR, markers, 0, **quiet), render_markers(INTR, markers, 1, **quiet))


def test_markers_close_together_in_the_image_are_both_drawn():
    # the patches rendered around the two markers overlap (one merged patch), the markers do not
    truth = {1: _pose([0.0, 0.0, 0.0], [0.0, 0.0, 1000.0]), 2: _pose([0.0, 0.0, 0.0], [110.0, 0.0, 500.0])}
    found = MarkerDetector(INTR, {1: 90.0, 2: 90.0}).detect(
        render_markers(INTR, [(i, 90.0, T) for i, T in truth.items()], 0)
    )
    assert sorted(found) == [1, 2]
    for i, depth_mm in ((1, 15.0), (2, 5.0)):
        d = found[i][:3, 3] - truth[i][:3, 3]
        assert np.all(np.abs(d[:2]) < 1.0) and abs(d[2]) < depth_mm, (i, d)


def test_given_background():
    flat = np.full((720, 1280), 100.0)
    np.testing.assert_array_equal(render_markers(INTR, [], 0, noise_gray=0.0, background=flat), 100)
    image = render_markers(INTR, [(1, 90.0, _pose([0, 0, 0], [0.0, 0.0, 1000.0]))], 0, background=flat)
    assert sorted(MarkerDetector(INTR, {1: 90.0}).detect(image)) == [1]
    assert 2.7 < np.std(image[:200, :300]) < 3.3 and abs(np.mean(image[:200, :300]) - 100.0) < 0.2
    with pytest.raises(ConfigError, match=r"^background: expected shape \(720, 1280\), got \(10, 10\)$"):
        render_markers(INTR, [], 0, background=np.zeros((10, 10)))


def test_bad_input_messages():
    detector = MarkerDetector(INTR, {1: 90.0})
    with pytest.raises(
        InputFileError,
        match=r"^image: expected a \(H, W\) uint8 grey image or \(H, W, 3\) uint8 BGR image, "
        r"got float64 of shape \(720, 1280\)$",
    ):
        detector.detect(np.zeros((720, 1280)))
    with pytest.raises(ConfigError, match=r"^sizes_mm: marker 2 has size -5.0, expected a finite size > 0 mm$"):
        MarkerDetector(INTR, {1: 90.0, 2: -5.0})
    with pytest.raises(ConfigError, match=r"^markers\[0\]: marker id 77 is not in DICT_4X4_50 \(expected an integer 0-49\)$"):
        render_markers(INTR, [(77, 90.0, np.eye(4))], 0)
    with pytest.raises(ConfigError, match=r"^marker 5 has no known size; known markers: \[1\]$"):
        detector.pose_from_corners(5, np.zeros((4, 2)))
    with pytest.raises(GeometryError,
                       match=r"^markers\[0\] T_C_M: expected an array of shape \(\.\.\., 4, 4\), got shape \(3, 3\)$"):
        render_markers(INTR, [(1, 90.0, np.eye(3))], 0)
    with pytest.raises(ConfigError, match=r"^noise_gray must be a finite number >= 0, got -1.0$"):
        render_markers(INTR, [], 0, noise_gray=-1.0)
