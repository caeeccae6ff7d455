"""The camera peer of the profiler benchmark (posekit.profiler.loop.camera_peer): rendering and accuracy.

No timing is asserted here; timings live in benchmarks/.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from posekit.profiler.loop import camera_peer as camera
from posekit.profiler.loop import chessboard as board

INNER = (3, 4)
SQUARE_MM = 20.0
# Measured over 60 random views (seeds 100-102): |dt| <= 0.11 mm, rotation <= 0.06 deg,
# detected corners vs true projection RMS <= 0.035 px. Tolerances keep a 2-3x margin.
T_TOL_MM = 0.3
ROT_TOL_DEG = 0.15
RMS_TOL_PX = 0.1


def _rotation_deg(rvec_a, rvec_b) -> float:
    R_a = cv2.Rodrigues(np.asarray(rvec_a, np.float64).reshape(3))[0]
    R_b = cv2.Rodrigues(np.asarray(rvec_b, np.float64).reshape(3))[0]
    return float(np.degrees(np.arccos(np.clip((np.trace(R_a @ R_b.T) - 1) / 2, -1, 1))))


def _detect(image):
    found, corners = cv2.findChessboardCorners(
        image, INNER, flags=camera.DETECTOR_FLAGS
    )
    assert found
    corners = cv2.cornerSubPix(
        image,
        corners,
        camera.SUBPIX_WINDOW,
        camera.SUBPIX_ZERO_ZONE,
        camera.SUBPIX_CRITERIA,
    )
    return corners.reshape(-1, 2)


def _facing_pose(spin_deg: float, tilt_deg: float, depth_mm: float):
    """Board centred on the optical axis, spun about its normal, then tilted about camera y."""
    R_spin = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(spin_deg)]))[0]
    R_tilt = cv2.Rodrigues(np.array([0.0, np.radians(tilt_deg), 0.0]))[0]
    R_C_B = R_tilt @ R_spin
    centre_B = SQUARE_MM * np.array([(INNER[0] - 1) / 2, (INNER[1] - 1) / 2, 0.0])
    t_C_B = np.array([0.0, 0.0, depth_mm]) - R_C_B @ centre_B
    return cv2.Rodrigues(R_C_B)[0].ravel(), t_C_B


def test_default_intrinsics_is_the_table_iii_camera():
    K = board.default_intrinsics()
    f_px = 16.0 / 2.2e-3
    np.testing.assert_allclose(K, [[f_px, 0, 1294.5], [0, f_px, 970.5], [0, 0, 1]])
    assert K[0, 0] == pytest.approx(7272.727, abs=1e-3)


def test_board_object_points_layout():
    points = board.board_object_points(INNER, SQUARE_MM)
    assert points.shape == (12, 3) and points.dtype == np.float32
    np.testing.assert_array_equal(points[0], [0, 0, 0])
    np.testing.assert_array_equal(points[1], [20, 0, 0])  # along the row of 3 corners
    np.testing.assert_array_equal(points[3], [0, 20, 0])  # next row
    np.testing.assert_array_equal(points[11], [40, 60, 0])


@pytest.mark.parametrize("inner", [(3, 3), (4, 4), (3, 5), (4, 6)])
def test_board_object_points_rejects_symmetric_boards(inner):
    with pytest.raises(ValueError, match="ambiguous"):
        board.board_object_points(inner, SQUARE_MM)


def test_render_values_and_determinism():
    # A small camera keeps this fast; the geometry code is the same at full size.
    K = board.default_intrinsics(640, 480, focal_mm=4.0)
    rvec, tvec = _facing_pose(0.0, 0.0, 600.0)
    kwargs = {"width": 640, "height": 480, "K": K}
    a = board.render_chessboard(rvec, tvec, rng=7, **kwargs)
    b = board.render_chessboard(rvec, tvec, rng=7, **kwargs)
    assert a.shape == (480, 640) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, b)

    clean = board.render_chessboard(rvec, tvec, noise_dn=0.0, **kwargs)
    centres_B = SQUARE_MM * np.array(
        [[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0]]
    )  # black, white square
    centres_px = cv2.projectPoints(centres_B, rvec, tvec, K, None)[0].reshape(-1, 2)
    (u0, v0), (u1, v1) = np.rint(centres_px).astype(int)
    assert clean[v0, u0] == 35  # ink, next to corner 0
    assert clean[v1, u1] == 215  # paper
    assert clean[0, 0] == 110  # grey background beyond the sheet
    noise = a.astype(float) - clean
    assert 1.8 < noise[clean == 110].std() < 2.2  # 2 DN sensor noise


@pytest.mark.parametrize("spin_deg", [0.0, 90.0, 180.0, 270.0, 135.0])
def test_object_point_order_matches_detected_corners(spin_deg):
    K = board.default_intrinsics()
    rvec, tvec = _facing_pose(spin_deg, 20.0, 700.0)
    image = board.render_chessboard(rvec, tvec, rng=1)
    corners = _detect(image)
    expected = cv2.projectPoints(
        board.board_object_points(INNER, SQUARE_MM), rvec, tvec, K, None
    )[0]
    rms = np.sqrt(np.mean(np.sum((corners - expected.reshape(-1, 2)) ** 2, axis=1)))
    assert rms < RMS_TOL_PX


@pytest.mark.parametrize("method", ["sqpnp", "ippe"])
def test_pipeline_recovers_the_rendered_pose(method):
    K = board.default_intrinsics()
    points_B = board.board_object_points(INNER, SQUARE_MM)
    rng = np.random.default_rng(2024)
    for rvec_true, tvec_true in board.random_board_poses(3, rng):
        image = board.render_chessboard(rvec_true, tvec_true, rng=rng)
        rvec, tvec, cd_ms, pc_ms = camera.camera_pipeline(
            image, K, None, points_B, INNER, method=method
        )
        assert rvec.shape == (3,) and tvec.shape == (3,)
        assert cd_ms > 0 and pc_ms > 0
        assert np.linalg.norm(tvec - tvec_true) < T_TOL_MM
        assert _rotation_deg(rvec, rvec_true) < ROT_TOL_DEG
        reprojected = cv2.projectPoints(points_B, rvec, tvec, K, None)[0].reshape(-1, 2)
        assert (
            np.sqrt(np.mean(np.sum((reprojected - _detect(image)) ** 2, axis=1)))
            < RMS_TOL_PX
        )


def test_random_board_poses_ranges_and_seed():
    K = board.default_intrinsics()
    poses = board.random_board_poses(200, 5)
    again = board.random_board_poses(200, 5)
    for (r, t), (r2, t2) in zip(poses, again):
        np.testing.assert_array_equal(r, r2)
        np.testing.assert_array_equal(t, t2)
    centre_B = SQUARE_MM * np.array([1.0, 1.5, 0.0])
    outline_B = SQUARE_MM * np.array(
        [[-1.5, -1.5, 0], [3.5, -1.5, 0], [3.5, 4.5, 0], [-1.5, 4.5, 0]]
    )
    for rvec, tvec in poses:
        R_C_B = cv2.Rodrigues(rvec)[0]
        assert 500.0 <= (R_C_B @ centre_B + tvec)[2] <= 900.0
        assert np.degrees(np.arccos(R_C_B[2, 2])) <= 25.0 + 1e-9
        px = cv2.projectPoints(outline_B, rvec, tvec, K, None)[0].reshape(-1, 2)
        assert np.all(px >= 0) and np.all(px[:, 0] <= 2589) and np.all(px[:, 1] <= 1941)


def test_camera_pipeline_bad_input():
    K = board.default_intrinsics(320, 240)
    points_B = board.board_object_points(INNER, SQUARE_MM)
    blank = np.full(
        (240, 320), 128, np.uint8
    )  # tiny and uniform: the detector gives up at once
    with pytest.raises(RuntimeError, match="no 3x4 chessboard found"):
        camera.camera_pipeline(blank, K, None, points_B, INNER)
    with pytest.raises(ValueError, match="2-D uint8"):
        camera.camera_pipeline(
            np.zeros((240, 320, 3), np.uint8), K, None, points_B, INNER
        )
    with pytest.raises(ValueError, match="method"):
        camera.camera_pipeline(blank, K, None, points_B, INNER, method="epnp")


def test_time_camera_pipeline_result():
    result = camera.time_camera_pipeline(n_images=2, repeats=2, seed=3)
    for key in ("cd_ms", "pc_ms", "total_ms", "t_err_mm", "rot_err_deg", "image_index"):
        assert result[key].shape == (4,)
    np.testing.assert_array_equal(result["image_index"], [0, 1, 0, 1])
    np.testing.assert_allclose(result["total_ms"], result["cd_ms"] + result["pc_ms"])
    assert np.all(result["cd_ms"] > 0) and np.all(result["pc_ms"] > 0)
    assert np.all(result["t_err_mm"] < T_TOL_MM)
    assert np.all(result["rot_err_deg"] < ROT_TOL_DEG)
    # The same image gives the same pose on every repeat.
    np.testing.assert_array_equal(result["t_err_mm"][:2], result["t_err_mm"][2:])
