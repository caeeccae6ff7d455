"""Lines & planes, RDP and line fitting: reference values and library cross-checks."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rdp import rdp as rdp_reference

from posekit.errors import GeometryError
from posekit.geometry import (
    fit_line_robust,
    fit_line_tls,
    intersect_lines_2d,
    line_plane_intersection,
    plane_intersection,
    point_line_distance,
    rdp,
)


def test_plane_intersection_reference():
    # z = 0 and x = 2 meet in the line x = 2, z = 0 along ±y
    p, d = plane_intersection([0, 0, 1], 0.0, [1, 0, 0], 2.0)
    np.testing.assert_allclose(p, [2, 0, 0], atol=1e-12)
    np.testing.assert_allclose(np.abs(d), [0, 1, 0], atol=1e-12)
    with pytest.raises(GeometryError, match="planes are parallel"):
        plane_intersection([0, 0, 1], 0.0, [0, 0, 2], 5.0)


def test_intersect_lines_and_distances():
    np.testing.assert_allclose(intersect_lines_2d([1, 0], 3.0, [0, 1], -2.0), [3, -2])
    with pytest.raises(GeometryError, match="lines are parallel"):
        intersect_lines_2d([1, 1], 0.0, [2, 2], 1.0)
    d = point_line_distance([[0, 3, 4], [1, 0, 0]], [0, 0, 0], [1, 0, 0])
    np.testing.assert_allclose(d, [5, 0])
    p, lam = line_plane_intersection([0, 0, 10], [0, 0, -2], [0, 0, 1], 4.0)
    np.testing.assert_allclose(p, [0, 0, 4])
    assert lam == pytest.approx(3.0)


@settings(max_examples=60, deadline=None)
@given(st.integers(3, 400), st.floats(0.001, 2.0), st.integers(0, 2**31))
def test_rdp_matches_reference_implementation(n, eps, seed):
    rng = np.random.default_rng(seed)
    pts = np.cumsum(rng.normal(size=(n, 2)), axis=0)
    expected = np.flatnonzero(rdp_reference(pts, epsilon=eps, return_mask=True))
    np.testing.assert_array_equal(rdp(pts, eps), expected)


def test_rdp_long_profile_is_iterative():
    """100,000 points of a sawtooth: no recursion limit, every tooth kept."""
    x = np.linspace(0, 1000, 100_001)
    z = np.abs((x % 20) - 10)
    keep = rdp(np.c_[x, z], 0.1)
    assert len(keep) == 2 * 50 + 1
    np.testing.assert_allclose(x[keep][1:-1:2], np.arange(10, 1000, 20), atol=0.01)


def test_rdp_bad_input():
    with pytest.raises(GeometryError, match=r"expected points of shape \(N, 2\)"):
        rdp(np.zeros((4, 3)), 1.0)
    with pytest.raises(GeometryError, match="points must be finite"):
        rdp([[0, 0], [np.nan, 1]], 1.0)
    with pytest.raises(GeometryError, match="epsilon must be a finite number >= 0"):
        rdp([[0, 0], [1, 1]], -1)


@settings(max_examples=40, deadline=None)
@given(st.floats(-np.pi, np.pi), st.floats(-50, 50), st.integers(0, 2**31))
def test_tls_matches_opencv_fitline(angle, offset, seed):
    rng = np.random.default_rng(seed)
    d = np.array([np.cos(angle), np.sin(angle)])
    n = np.array([-d[1], d[0]])
    t = rng.uniform(-30, 30, 300)
    pts = offset * n + t[:, None] * d + rng.normal(0, 0.01, (300, 2))
    normal, c, centroid = fit_line_tls(pts)
    vx, vy, x0, y0 = cv2.fitLine(pts.astype(np.float32), cv2.DIST_L2, 0, 1e-7, 1e-7).ravel()
    assert abs(normal @ [vx, vy]) < 1e-4                      # same direction
    np.testing.assert_allclose(centroid, [x0, y0], atol=1e-3)
    # and the SVD definition of TLS
    u, s, vt = np.linalg.svd(pts - pts.mean(0))
    assert abs(abs(normal @ vt[1]) - 1) < 1e-9
    assert c == pytest.approx(abs(vt[1] @ pts.mean(0)), abs=1e-6)


def test_robust_fit_ignores_spikes_where_least_squares_does_not():
    rng = np.random.default_rng(1)
    x = np.linspace(0, 20, 400)
    pts = np.c_[x, 0.3 * x + 2 + rng.normal(0, 0.005, 400)]
    spiky = pts.copy()
    spiky[rng.choice(400, 12, replace=False), 1] += rng.uniform(0.1, 0.3, 12)
    n_true = np.array([-0.3, 1.0]) / np.hypot(0.3, 1.0)
    normal, c, _, inliers, rms = fit_line_robust(spiky)
    plain, c_plain, _ = fit_line_tls(spiky)
    assert abs(c - 2 * n_true[1]) < 1e-3
    assert abs(c_plain - 2 * n_true[1]) > 3e-3
    assert inliers.sum() == 400 - 12
    assert rms == pytest.approx(0.005, rel=0.15)
    # OpenCV's Huber M-estimator agrees on the line
    vx, vy, x0, y0 = cv2.fitLine(spiky.astype(np.float32), cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
    assert abs(normal @ [vx, vy]) < 2e-3


def test_fit_bad_input():
    with pytest.raises(GeometryError, match="a line needs at least 2 points, got 1"):
        fit_line_tls([[0, 0]])
    with pytest.raises(GeometryError, match="points must be finite"):
        fit_line_robust([[0, 0], [1, np.nan], [2, 2]])
