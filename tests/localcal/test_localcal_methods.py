"""Orientation adjustment (eq. 7-8), line-equation (eq. 10-16) and trajectory-matching (eq. 17-22)
range adjustment, and the simulated VO, on exact synthetic geometry."""

import numpy as np
import pytest

from posekit.errors import ConfigError, EstimationError, GeometryError, TrajectoryError
from posekit.geometry import (
    invert_transform,
    matrix_from_rotation_vector,
    rotation_angle_between,
    transform_from,
)
from posekit.localcal.methods.line_method import (
    circle_path,
    line_range_adjustment,
    line_reference,
    planar_distance_error,
)
from posekit.localcal.methods.orientation import (
    orientation_reference,
    rotation_difference,
    rotation_errors_deg,
)
from posekit.localcal.methods.trajectory_method import asymmetric_path, trajectory_reference
from posekit.localcal.sim.vo import simulate_vo

# A TCP pose in the base frame, a camera mount (camera z along -z_F, like a camera looking out
# along the torsion axis) and a tool marker in front of the camera, facing it.
T_B_F = transform_from(matrix_from_rotation_vector([0.3, -1.2, 0.4]), [3200.0, 450.0, 1100.0])
R_F_C = np.diag([1.0, -1.0, -1.0])
T_F_C = transform_from(R_F_C, [0.0, 120.0, -80.0])
T_F_M = transform_from(matrix_from_rotation_vector([0.02, -0.03, 0.05]), [0.0, 60.0, -450.0])


def _camera_view(T_B_F_, T_B_O):
    """Exact T_C_O and T_C_M for a TCP pose and an OOI pose."""
    T_C_B = invert_transform(T_B_F_ @ T_F_C)
    return T_C_B @ T_B_O, T_C_B @ T_B_F_ @ T_F_M


# --------------------------------------------------------------------------- orientation (eq. 7-8)

def test_rotation_difference_is_the_quaternion_product_of_eq7():
    T_C_O = transform_from(matrix_from_rotation_vector([0.1, 0.2, -0.3]), [0, 0, 900.0])
    T_C_M = transform_from(matrix_from_rotation_vector([-0.05, 0.1, 0.2]), [0, 0, 400.0])
    R = rotation_difference(T_C_O, T_C_M)
    np.testing.assert_allclose(R, T_C_O[:3, :3] @ T_C_M[:3, :3].T, atol=1e-12)


@pytest.mark.parametrize("rotvec", [[0.05, -0.08, 0.2], [0.0, 0.0, 0.0], [0.3, 0.1, -0.6]])
def test_orientation_adjustment_makes_the_tool_marker_parallel_to_the_ooi(rotvec):
    R_B_M = (T_B_F @ T_F_M)[:3, :3]
    T_B_O = transform_from(R_B_M @ matrix_from_rotation_vector(rotvec), [3400.0, 700.0, 300.0])
    T_C_O, T_C_M = _camera_view(T_B_F, T_B_O)
    assert rotation_errors_deg(T_C_O, T_C_M).max() == pytest.approx(
        np.degrees(np.abs(rotvec)).max(), rel=0.2, abs=1e-9)
    T_ref = orientation_reference(T_B_F, T_C_O, T_C_M, R_F_C=R_F_C)
    np.testing.assert_allclose(T_ref[:3, 3], T_B_F[:3, 3], atol=1e-12)   # position held
    T_C_O2, T_C_M2 = _camera_view(T_ref, T_B_O)
    assert rotation_errors_deg(T_C_O2, T_C_M2).max() < 1e-9
    assert float(rotation_angle_between((T_ref @ T_F_M)[:3, :3], T_B_O[:3, :3])) < 1e-12


def test_orientation_adjustment_as_printed_assumes_uniform_frames():
    """Eq. (8) verbatim (R_F_C = I) is exact when the camera frame is aligned with the TCP frame."""
    T_F_C_uniform = transform_from(np.eye(3), [0.0, 120.0, 80.0])
    T_B_O = transform_from((T_B_F @ T_F_M)[:3, :3] @ matrix_from_rotation_vector([0.1, -0.05, 0.15]),
                           [3400.0, 700.0, 300.0])
    T_C_B = invert_transform(T_B_F @ T_F_C_uniform)
    T_ref = orientation_reference(T_B_F, T_C_B @ T_B_O, T_C_B @ T_B_F @ T_F_M)
    assert float(rotation_angle_between((T_ref @ T_F_M)[:3, :3], T_B_O[:3, :3])) < 1e-12


def test_orientation_adjustment_residual_follows_the_mount_misalignment():
    """A camera mounted 1.5° off its nominal rotation leaves about that much tilt."""
    T_B_O = transform_from((T_B_F @ T_F_M)[:3, :3] @ matrix_from_rotation_vector([0.1, -0.05, 0.15]),
                           [3400.0, 700.0, 300.0])
    T_C_O, T_C_M = _camera_view(T_B_F, T_B_O)
    R_nominal = R_F_C @ matrix_from_rotation_vector([np.radians(1.5), 0.0, 0.0])
    T_ref = orientation_reference(T_B_F, T_C_O, T_C_M, R_F_C=R_nominal)
    residual = np.degrees(float(rotation_angle_between((T_ref @ T_F_M)[:3, :3], T_B_O[:3, :3])))
    assert 0.05 < residual < 1.5


def test_orientation_reference_rejects_a_non_rigid_transform():
    with pytest.raises(GeometryError, match="T_C_O"):
        orientation_reference(np.eye(4), np.zeros((4, 4)), np.eye(4))


# --------------------------------------------------------------------------- line method (eq. 10-16)

def test_circle_path_has_18_points_with_the_centre_first_and_last():
    path = circle_path(T_B_F)
    assert path.shape == (18, 4, 4)
    p = T_B_F[:3, 3]
    np.testing.assert_allclose(path[0], T_B_F, atol=1e-12)
    np.testing.assert_allclose(path[-1], T_B_F, atol=1e-12)
    np.testing.assert_allclose(path[:, :3, :3], np.broadcast_to(T_B_F[:3, :3], (18, 3, 3)), atol=1e-12)
    ring = path[1:-1, :3, 3] - p
    np.testing.assert_allclose(np.linalg.norm(ring, axis=1), 200.0, atol=1e-9)
    np.testing.assert_allclose(ring @ T_B_F[:3, 2], 0.0, atol=1e-9)          # in the n-s plane
    np.testing.assert_allclose(ring[0], 200.0 * T_B_F[:3, 0], atol=1e-9)     # phi = 0 along n
    np.testing.assert_allclose(ring[-1], ring[0], atol=1e-9)                  # phi = 2 pi closes it
    phi = 2.0 * np.pi * np.arange(16) / 15                                   # 15 steps of 24 degrees
    np.testing.assert_allclose(ring, 200.0 * (np.cos(phi)[:, None] * T_B_F[:3, 0]
                                              + np.sin(phi)[:, None] * T_B_F[:3, 1]), atol=1e-9)


def _executed_circle(T_init, samples_per_segment=40):
    """Dense TCP positions along the straight segments of the circular path."""
    way = circle_path(T_init)[:, :3, 3]
    s = np.linspace(0.0, 1.0, samples_per_segment, endpoint=False)
    seg = way[:-1, None, :] + s[None, :, None] * (way[1:] - way[:-1])[:, None, :]
    return np.concatenate([seg.reshape(-1, 3), way[-1:]])


@pytest.mark.parametrize("k, distance_mm", [(3, 450.0), (11, 700.0)])
def test_line_reference_recovers_the_ooi_on_a_noise_free_circle(k, distance_mm):
    """OOI straight out from a circle vertex: eq. (16) lands exactly on it."""
    phi = 2.0 * np.pi * k / 15
    n, s, p0 = T_B_F[:3, 0], T_B_F[:3, 1], T_B_F[:3, 3]
    direction = np.cos(phi) * n + np.sin(phi) * s
    depth = 700.0 * T_B_F[:3, 2]
    p_O = p0 + distance_mm * direction + depth      # the OOI, in front of the plane of motion
    p_B = _executed_circle(T_B_F)
    # the camera frame moves with the TCP (orientation held): C = F rotated by R_F_C
    R_C_B = (T_B_F[:3, :3] @ R_F_C).T
    p_C_O = (p_O - p_B) @ R_C_B.T
    p_C_M = np.broadcast_to(np.array([0.0, 60.0, 450.0]), p_C_O.shape)
    p_C_O = p_C_O + p_C_M                                       # tool marker at the TCP's point
    adj = line_range_adjustment(T_B_F, p_B, p_C_O, p_C_M)
    assert adj.d_eps_min_mm == pytest.approx(distance_mm - 200.0, abs=1e-6)
    np.testing.assert_allclose(adj.T_B_ref[:3, 3], p0 + distance_mm * direction, atol=1e-6)
    np.testing.assert_allclose(adj.p_u, direction, atol=1e-9)
    np.testing.assert_allclose(adj.T_B_ref[:3, :3], T_B_F[:3, :3], atol=1e-12)


def test_line_reference_between_vertices_is_off_by_the_chord():
    """Between two vertices the 15-gon's chord biases the direction: a few mm at 0.5 m."""
    phi = 2.0 * np.pi * 3.5 / 15
    n, s, p0 = T_B_F[:3, 0], T_B_F[:3, 1], T_B_F[:3, 3]
    p_O = p0 + 500.0 * (np.cos(phi) * n + np.sin(phi) * s)
    p_B = _executed_circle(T_B_F, 200)
    R_C_B = (T_B_F[:3, :3] @ R_F_C).T
    p_C_O = (p_O - p_B) @ R_C_B.T
    adj = line_range_adjustment(T_B_F, p_B, p_C_O, np.zeros_like(p_C_O))
    error = np.linalg.norm(adj.T_B_ref[:3, 3] - p_O)
    chord_sag = 200.0 * (1.0 - np.cos(np.pi / 15))             # 4.4 mm
    assert error == pytest.approx(chord_sag, abs=0.5)


def test_planar_distance_error_is_eq13():
    assert float(planar_distance_error([30.0, 40.0, 900.0], [0.0, 0.0, 400.0])) == pytest.approx(50.0)
    assert np.isnan(planar_distance_error([np.nan] * 3, [0.0, 0.0, 0.0]))


def test_line_reference_at_the_centre_is_an_error():
    with pytest.raises(EstimationError, match=r"^line equation: the smallest distance error was measured at "
                                              r"the circle's centre, so the direction to the OOI is undefined "
                                              r"\(is the OOI inside the circle\?\)$"):
        line_reference(T_B_F, T_B_F[:3, 3], 10.0)


def test_line_range_adjustment_without_the_ooi_is_an_error():
    p_B = _executed_circle(T_B_F, 2)
    nan = np.full_like(p_B, np.nan)
    with pytest.raises(EstimationError, match=r"^line equation: the OOI \(markers 1, 2, 3\) was never seen "
                                              r"during the circular path$"):
        line_range_adjustment(T_B_F, p_B, nan, np.zeros_like(p_B))
    with pytest.raises(EstimationError, match="the tool marker"):
        line_range_adjustment(T_B_F, p_B, np.ones_like(p_B), nan)


def test_circle_path_rejects_bad_options():
    with pytest.raises(ConfigError, match="radius"):
        circle_path(T_B_F, radius_mm=0.0)
    with pytest.raises(ConfigError, match="at least 5 points"):
        circle_path(T_B_F, n_points=3)


# --------------------------------------------------------------------------- trajectory method (eq. 17-22)

def test_asymmetric_path_follows_eq17_to_19():
    path = asymmetric_path(T_B_F, [300.0, 200.0, -100.0])
    n, s, p0 = T_B_F[:3, 0], T_B_F[:3, 1], T_B_F[:3, 3]
    expected = [p0, p0 + 300 * n, p0 + 300 * n + 200 * (n + s) / np.sqrt(2),
                p0 + 200 * n + 200 * (n + s) / np.sqrt(2)]
    np.testing.assert_allclose(path[:, :3, 3], expected, atol=1e-9)
    np.testing.assert_allclose(path[:, :3, :3], np.broadcast_to(T_B_F[:3, :3], (4, 3, 3)), atol=1e-12)


def test_asymmetric_path_rejects_degenerate_input():
    with pytest.raises(TrajectoryError, match=r"^calibration path is degenerate: all waypoints lie on one "
                                              r"straight line"):
        asymmetric_path(T_B_F, [300.0, 200.0, -100.0], xi=[0.0])
    with pytest.raises(TrajectoryError, match=r"^calibration path: too few segments: expected at least 2, got 1$"):
        asymmetric_path(T_B_F, [300.0])


def test_trajectory_reference_recovers_a_known_offset():
    """With the exact R_B_W the tool marker ends b = 100 mm in front of the OOI, on its axis."""
    T_B_O = transform_from((T_B_F @ T_F_M)[:3, :3], [0.0, 0.0, 0.0])
    T_B_O[:3, 3] = (T_B_F @ T_F_M)[:3, 3] + [150.0, -320.0, 480.0]
    T_C_O, T_C_M = _camera_view(T_B_F, T_B_O)
    R_B_W = (T_B_F @ T_F_C)[:3, :3]           # W = camera frame at the start
    T_ref = trajectory_reference(T_B_F, R_B_W, np.eye(3), T_C_O[:3, 3] - T_C_M[:3, 3])
    T_C_O2, T_C_M2 = _camera_view(T_ref, T_B_O)
    np.testing.assert_allclose(T_C_O2[:3, 3] - T_C_M2[:3, 3], [0.0, 0.0, 100.0], atol=1e-9)
    np.testing.assert_allclose(T_ref[:3, :3], T_B_F[:3, :3], atol=1e-12)


def test_trajectory_reference_uses_the_current_camera_rotation():
    R_W_C = matrix_from_rotation_vector([0.0, 0.0, np.pi / 2])
    T_ref = trajectory_reference(np.eye(4), np.eye(3), R_W_C, [10.0, 0.0, 100.0], b_mm=100.0)
    np.testing.assert_allclose(T_ref[:3, 3], [0.0, 10.0, 0.0], atol=1e-12)


def test_trajectory_reference_rejects_nan():
    with pytest.raises(ConfigError, match=r"^delta_C: expected 3 finite numbers \(mm\)"):
        trajectory_reference(np.eye(4), np.eye(3), np.eye(3), [np.nan, 0.0, 0.0])


# --------------------------------------------------------------------------- simulated VO

def _camera_path(n=90):
    way = asymmetric_path(T_B_F)
    s = np.linspace(0.0, len(way) - 1, n)
    i = np.minimum(s.astype(int), len(way) - 2)
    T = np.broadcast_to(T_B_F, (n, 4, 4)).copy()
    T[:, :3, 3] = way[i, :3, 3] + (s - i)[:, None] * (way[i + 1, :3, 3] - way[i, :3, 3])
    return T @ T_F_C, np.arange(n) * 0.01


def test_simulated_vo_without_noise_is_the_camera_path_in_its_first_frame():
    T_B_C, t = _camera_path()
    vo = simulate_vo(T_B_C, t, 0, noise_mm=0, noise_rad=0, drift_mm_per_sqrt_m=0, drift_rad_per_sqrt_m=0,
                     stride=3, time_offset_s=0.5)
    np.testing.assert_allclose(vo.T, invert_transform(T_B_C[0]) @ T_B_C[::3], atol=1e-9)
    np.testing.assert_allclose(vo.t_s, t[::3] + 0.5)
    np.testing.assert_allclose(vo.T[0], np.eye(4), atol=1e-12)


def test_simulated_vo_noise_and_drift_have_the_requested_size_and_seed():
    T_B_C, t = _camera_path(3000)
    truth = invert_transform(T_B_C[0]) @ T_B_C
    a = simulate_vo(T_B_C, t, 7, stride=1, drift_mm_per_sqrt_m=0, drift_rad_per_sqrt_m=0, noise_mm=2.0)
    b = simulate_vo(T_B_C, t, 7, stride=1, drift_mm_per_sqrt_m=0, drift_rad_per_sqrt_m=0, noise_mm=2.0)
    np.testing.assert_array_equal(a.T, b.T)
    err = a.T[1:, :3, 3] - truth[1:, :3, 3]
    assert np.std(err) == pytest.approx(2.0, rel=0.05)
    drift = simulate_vo(T_B_C, t, 7, stride=1, noise_mm=0, noise_rad=0, drift_rad_per_sqrt_m=0,
                        drift_mm_per_sqrt_m=3.0)
    assert np.abs(drift.T[0, :3, 3]).max() == 0.0
    assert 0.0 < np.abs(drift.T[-1, :3, 3] - truth[-1, :3, 3]).max() < 5 * 3.0 * np.sqrt(1.6)


def test_simulated_vo_rejects_too_few_poses():
    T_B_C, t = _camera_path(5)
    with pytest.raises(TrajectoryError, match=r"^simulate_vo: too few poses: expected at least 3 VO frames, got 2$"):
        simulate_vo(T_B_C, t, 0, stride=3)


# --------------------------------------------------------------------------- local calibration from TUM files

def test_calibration_from_tum_files_recovers_the_camera_rotation(tmp_path):
    """VO (noise, no drift) written to / read from TUM files (metres, qx qy qz qw) gives R_B_W
    within 0.2 degrees."""
    from posekit.localcal.methods.trajectory_method import calibrate_trajectories
    from posekit.localcal.model.trajectory import Trajectory
    from posekit.localcal.registration.formats.tum import write_tum

    T_B_C, t = _camera_path(600)
    vo = simulate_vo(T_B_C, t, 3, stride=2, drift_mm_per_sqrt_m=0.0, drift_rad_per_sqrt_m=0.0)
    kinematic = Trajectory(t_s=t, T=T_B_C @ invert_transform(T_F_C))
    write_tum(tmp_path / "vo.tum", vo)
    write_tum(tmp_path / "tcp.tum", kinematic)
    reg = calibrate_trajectories(tmp_path / "vo.tum", str(tmp_path / "tcp.tum"))
    R_B_W = T_B_C[0, :3, :3]
    assert np.degrees(float(rotation_angle_between(reg.R, R_B_W))) < 0.2
    np.testing.assert_allclose(reg.mean_abs_err_mm, 0.0, atol=5.0)
    direct = calibrate_trajectories(vo, kinematic)
    assert np.degrees(float(rotation_angle_between(reg.R, direct.R))) < 0.01


def test_calibration_of_a_straight_line_is_an_error():
    from posekit.localcal.methods.trajectory_method import calibrate_trajectories
    from posekit.localcal.model.trajectory import Trajectory

    T = np.broadcast_to(T_B_F, (50, 4, 4)).copy()
    T[:, :3, 3] += np.linspace(0.0, 400.0, 50)[:, None] * T_B_F[:3, 0]
    line = Trajectory(t_s=np.arange(50) * 0.03, T=T)
    with pytest.raises(TrajectoryError, match="straight line"):
        calibrate_trajectories(line, line)
    with pytest.raises(TrajectoryError, match=r"^camera: expected a Trajectory or a TUM file path, got int$"):
        calibrate_trajectories(3, line)
