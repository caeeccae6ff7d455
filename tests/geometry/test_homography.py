"""Planar homographies: reference values, OpenCV cross-checks, properties, degenerate input."""

import re

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from posekit.errors import CalibrationError, GeometryError
from posekit.geometry import (
    apply_homography,
    check_correspondences,
    homography_dlt,
    homography_ransac,
    normalize_homography,
    refine_homography,
)
from tests.strategies import FAST

# A perspective homography with dyadic entries and 18 points on the lines 2X + Y = -4096, 0,
# 8192, where w = 1 + (2X + Y) / 8192 is 0.5, 1 or 2: every coordinate is an exact float32,
# so OpenCV (which works on float32 points) sees exactly the same, exactly consistent data.
H_REF = np.array([[0.125, 1 / 64, 400.0], [-1 / 128, 0.0625, 100.0], [1 / 4096, 1 / 8192, 1.0]])
SRC = np.array([((c - y) / 2, y) for c in (-4096, 0, 8192) for y in (-1024, 0, 1024, 2048, 3072, 4096)], float)
DST = np.array([
    [384, 96], [288, 232], [192, 368], [96, 504], [0, 640], [-96, 776],
    [448, 32], [400, 100], [352, 168], [304, 236], [256, 304], [208, 372],
    [480, 0], [456, 34], [432, 68], [408, 102], [384, 136], [360, 170]], float)


def camera_homography(yaw=0.2, tilt=0.6, f=560.0, height=2400.0):
    """H_image_world (mm -> px) of a pinhole camera 2.4 m below a ceiling, looking up obliquely."""
    cy, sy, ct, st_ = np.cos(yaw), np.sin(yaw), np.cos(tilt), np.sin(tilt)
    R = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, ct, -st_], [0, st_, ct]])
    K = np.array([[f, 0, 431.5], [0, f, 239.5], [0, 0, 1]])
    C = np.array([3000.0, -500.0, -height])
    R_cam_world = R.T
    t = -R_cam_world @ C
    return normalize_homography(K @ np.c_[R_cam_world[:, 0], R_cam_world[:, 1], t])


def image_points(rng, H, n=18):
    """n world points (mm) whose images fall inside an 864 x 480 image, in general position."""
    while True:
        uv = rng.uniform([20, 20], [844, 460], size=(n, 2))
        world = apply_homography(np.linalg.inv(H), uv)
        try:
            check_correspondences(world, uv)
            return world
        except CalibrationError:          # 3 of 4 random points nearly on a line: draw again
            continue


def rms(H, src, dst):
    return float(np.sqrt(np.mean(np.sum((apply_homography(H, src) - dst) ** 2, axis=1))))


# --------------------------------------------------------------------------- reference values
def test_dlt_recovers_the_reference_and_agrees_with_opencv():
    assert np.all(np.float32(SRC) == SRC) and np.all(np.float32(DST) == DST)
    assert_allclose(apply_homography(H_REF, SRC), DST, rtol=0, atol=1e-12)
    H = homography_dlt(SRC, DST)
    H_cv, _ = cv2.findHomography(SRC, DST, 0)
    assert H[2, 2] == 1.0
    assert np.abs((H - H_REF) / H_REF).max() < 1e-12
    assert np.abs((H - H_cv) / H_cv).max() < 1e-9            # entry by entry, same scale H[2,2] = 1
    assert_allclose(refine_homography(H, SRC, DST), H_REF, rtol=1e-12)


def test_dlt_scaling_reference():
    src = [[0, 0], [1, 0], [1, 1], [0, 1]]
    assert_allclose(homography_dlt(src, [[0, 0], [2, 0], [2, 2], [0, 2]]), np.diag([2.0, 2.0, 1.0]), atol=1e-14)
    assert_allclose(homography_dlt(src, src, normalize=False), np.eye(3), atol=1e-14)


def test_noisy_dlt_close_to_opencv_and_refined_equal_to_it():
    """cv2.findHomography (method 0) is DLT + Levenberg-Marquardt on float32 points."""
    rng = np.random.default_rng(3)
    H_true = camera_homography()
    src = np.float32(image_points(rng, H_true)).astype(float)
    dst = np.float32(apply_homography(H_true, src) + rng.normal(0, 0.5, (18, 2))).astype(float)
    H_cv, _ = cv2.findHomography(src, dst, 0)
    H = homography_dlt(src, dst)
    H_ref = refine_homography(H, src, dst)
    grid = image_points(np.random.default_rng(4), H_true, 200)
    assert np.abs(apply_homography(H, grid) - apply_homography(H_cv, grid)).max() < 0.25       # px, half the noise
    assert np.abs(apply_homography(H_ref, grid) - apply_homography(H_cv, grid)).max() < 1e-5   # px
    assert rms(H_ref, src, dst) <= rms(H_cv, src, dst) + 1e-9


# --------------------------------------------------------------------------- properties
@FAST
@given(st.integers(0, 2**32 - 1), st.floats(-0.6, 0.6), st.floats(0.2, 0.9))
def test_exact_recovery_and_round_trip(seed, yaw, tilt):
    rng = np.random.default_rng(seed)
    H_true = camera_homography(yaw, tilt)
    src = image_points(rng, H_true, int(rng.integers(4, 40)))
    dst = apply_homography(H_true, src)
    H = homography_dlt(src, dst)
    assert_allclose(apply_homography(H, src), dst, atol=1e-7)                      # px
    assert_allclose(H, H_true, rtol=1e-6, atol=1e-9 * np.abs(H_true).max())
    back = apply_homography(np.linalg.inv(H), apply_homography(H, src))
    assert_allclose(back, src, atol=1e-6)                                          # mm


@FAST
@given(st.integers(0, 2**32 - 1), st.floats(0.05, 3.0), st.integers(5, 30))
def test_refinement_never_increases_the_rms(seed, noise_px, n):
    rng = np.random.default_rng(seed)
    H_true = camera_homography(rng.uniform(-0.5, 0.5), rng.uniform(0.2, 0.9))
    src = image_points(rng, H_true, n)
    dst = apply_homography(H_true, src) + rng.normal(0, noise_px, (n, 2))
    H = homography_dlt(src, dst)
    assert rms(refine_homography(H, src, dst), src, dst) <= rms(H, src, dst) * (1 + 1e-12)
    H_bad = H @ np.array([[1.01, 0, 2], [0, 0.99, -3], [0, 0, 1]])                  # a poor start too
    assert rms(refine_homography(H_bad, src, dst), src, dst) <= rms(H_bad, src, dst)


def test_ransac_flags_exactly_the_mis_clicked_point():
    rng = np.random.default_rng(7)
    H_true = camera_homography()
    src = image_points(rng, H_true, 18)
    dst = apply_homography(H_true, src) + rng.normal(0, 0.3, (18, 2))
    dst[11] += [14.0, -9.0]                                        # clicked the wrong pixel
    for seed in range(5):
        H, inliers = homography_ransac(src, dst, 3.0, rng=seed)
        assert_array_equal(np.flatnonzero(~inliers), [11])
        assert rms(H, src[inliers], dst[inliers]) < 0.5
    assert rms(homography_dlt(src, dst), src, dst) > 2.0           # the plain DLT is pulled off


def test_ransac_exhaustive_is_deterministic_and_all_inliers_on_clean_data():
    src, dst = SRC[:8], DST[:8]
    H1, in1 = homography_ransac(src, dst, 1.0, rng=1)
    H2, in2 = homography_ransac(src, dst, 1.0, rng=2)
    assert in1.all() and in2.all()
    assert_array_equal(H1, H2)
    assert_allclose(H1, H_REF, rtol=1e-10)


def test_apply_homography_batches_and_nan_mode():
    assert_allclose(apply_homography(H_REF, SRC.reshape(3, 6, 2)), DST.reshape(3, 6, 2), atol=1e-12)
    out = apply_homography(H_REF, [[-4096.0, 0.0], [0.0, 0.0]], invalid="nan")   # w = 1 + (2X + Y)/8192 = 0
    assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()


# --------------------------------------------------------------------------- degenerate input
SQUARE = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0], [50.0, 30.0]])

DEGENERATE = [
    (SQUARE[:3], SQUARE[:3], "homography: need at least 4 point correspondences, got 3"),
    (SQUARE, SQUARE[:4], "homography: 5 src points but 4 dst points; expected one per correspondence"),
    (SQUARE[:, :1], SQUARE, "homography: expected src points of shape (N, 2), got (5, 1)"),
    (np.r_[SQUARE[:4], [[np.nan, 1.0]]], SQUARE,
     "homography: src point 4 is not finite (nan, 1); expected finite coordinates"),
    (SQUARE, np.r_[SQUARE[:4], [[100.0, 100.0]]],
     "homography: dst points 2 and 4 coincide at (100, 100); expected distinct points"),
    (np.c_[np.arange(6.0), 2 * np.arange(6.0)], np.r_[SQUARE, [[20.0, 70.0]]],
     ("homography: all 6 src points lie on one line (or within 0.1 % of one); expected points spread over "
      "the plane, at least 4 of them with no 3 on a line")),
    (np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [5.0, 8.0]]), SQUARE[:4],
     ("homography: 3 of the 4 src points lie on one line (all but point 3); expected at least 4 points "
      "with no 3 on a line")),
    (SQUARE, np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0], [4.0, 4.0 + 1e-6]]),
     ("homography: all 5 dst points lie on one line (or within 0.1 % of one); expected points spread over "
      "the plane, at least 4 of them with no 3 on a line")),
]


@pytest.mark.parametrize("src, dst, message", DEGENERATE)
def test_degenerate_input_raises_the_exact_message(src, dst, message):
    for fn in (lambda: homography_dlt(src, dst), lambda: homography_ransac(src, dst, 3.0, rng=0),
               lambda: refine_homography(np.eye(3), src, dst), lambda: check_correspondences(src, dst)):
        with pytest.raises(CalibrationError, match=f"^{re.escape(message)}$"):
            fn()


def test_check_correspondences_names_the_sets():
    with pytest.raises(CalibrationError,
                       match=r"^homography: 3 of the 4 world points lie on one line \(all but point 3\)"):
        check_correspondences([[0, 0], [10, 0], [20, 0], [5, 8]], SQUARE[:4], names=("world", "image"))


def test_ransac_and_refine_bad_arguments():
    with pytest.raises(CalibrationError,
                       match=r"^homography_ransac: threshold must be a finite number > 0 \(dst units\), got 0$"):
        homography_ransac(SRC, DST, 0)
    with pytest.raises(CalibrationError, match=r"^homography_ransac: confidence must be in \(0, 1\), got 1$"):
        homography_ransac(SRC, DST, 1.0, confidence=1)
    line = np.c_[np.arange(8.0), np.zeros(8)]
    with pytest.raises(CalibrationError, match=r"^homography_ransac: all 70 4-point samples had 3 points on a line; "
                                               r"expected points in general position$"):
        homography_ransac(line, line, 1.0, check=False)
    H_inf = np.array([[1.0, 0, 0], [0, 1, 0], [1 / 50, 1 / 50, -2]])   # sends the centroid (50, 50) to infinity
    with pytest.raises(CalibrationError, match="^refine_homography: the initial homography maps the centroid"):
        refine_homography(H_inf, SQUARE[:4], SQUARE[:4])


def test_apply_homography_errors():
    with pytest.raises(GeometryError, match=re.escape(
            "apply_homography: point 1 (-4096, 0) maps to infinity (it lies on the line the homography sends "
            "to infinity); expected points away from it")):
        apply_homography(H_REF, [[0.0, 0.0], [-4096.0, 0.0]])
    with pytest.raises(GeometryError, match=r"expected a 3x3 homography, got shape \(2, 3\)"):
        apply_homography(np.eye(3)[:2], [[0.0, 0.0]])
    with pytest.raises(GeometryError, match=r"expected points of shape \(\.\.\., 2\), got \(4, 3\)"):
        apply_homography(np.eye(3), np.zeros((4, 3)))


def test_normalize_homography():
    assert_allclose(normalize_homography(2 * H_REF), H_REF)
    H0 = np.array([[1.0, 0, 0], [0, 1, 0], [1, 0, 0]])
    assert_allclose(normalize_homography(3 * H0), H0 / np.sqrt(3))
    batch = normalize_homography(np.stack([2 * H_REF, 3 * H0]))
    assert_allclose(batch, np.stack([H_REF, H0 / np.sqrt(3)]))
