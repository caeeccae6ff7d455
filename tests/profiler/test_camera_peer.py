"""The OpenCV camera pipeline used as the benchmark peer is honest: it finds the board and
recovers the rendered pose."""

import cv2
import numpy as np

from posekit.profiler.camera_peer import (
    IMAGE_SIZE,
    board_object_points,
    camera_pipeline,
    default_intrinsics,
    random_board_poses,
    render_chessboard,
    time_camera_pipeline,
)


def test_rendered_board_is_found_and_pose_recovered():
    res = time_camera_pipeline(n_images=3, repeats=1, seed=4)
    assert np.all(res["t_err_mm"] < 0.5)          # at 500–900 mm
    assert np.all(res["rot_err_deg"] < 0.1)
    assert res["cd_ms"].shape == (3,) and np.all(res["cd_ms"] > 0)


def test_corner_order_matches_object_points():
    K = default_intrinsics()
    rvec, tvec = random_board_poses(1, rng=2)[0]
    img = render_chessboard(rvec, tvec, K=K, rng=2)
    assert img.shape == (IMAGE_SIZE[1], IMAGE_SIZE[0]) and img.dtype == np.uint8
    obj = board_object_points()
    truth, _ = cv2.projectPoints(obj, rvec, tvec, K, np.zeros(5))
    _, _, corners, _, _ = camera_pipeline(img, K, obj)
    d = min(np.abs(corners - truth.reshape(-1, 2)).max(), np.abs(corners[::-1] - truth.reshape(-1, 2)).max())
    assert d < 0.5                                # px
