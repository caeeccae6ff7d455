"""Densities of §II-C: eq. (7)/(8) plateau (normalisation, Gaussian limit), transition (eq. 3),
robot measurement (eq. 5) with the fast FK/Jacobian, laser (eq. 9) against a NumPy reference."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm

from posekit.geometry import rotation_vector_from_matrix, se3_exp
from posekit.robots import puma560
from posekit.seam.engine.densities import (
    angle_loglik,
    ball_volume,
    joint_compliance,
    laser_loglik,
    plateau_logpdf,
    plateau_pdf_1d,
    robot_loglik,
    robot_measurement,
    transition,
)
from posekit.seam.engine.seamline import SeamLine


@pytest.mark.parametrize("d, sigma", [(0.0, 1.0), (1.0, 0.5), (3.0, 2.0), (0.2, 0.01)])
def test_eq7_integrates_to_one(d, sigma):
    x = np.linspace(-d - 12 * sigma, d + 12 * sigma, 400001) + 0.3
    p = plateau_pdf_1d(x, 0.3, d, sigma)
    assert np.trapezoid(p, x) == pytest.approx(1.0, abs=1e-6)
    # flat top C = 1 / (sqrt(2 pi) sigma + 2 d) inside the plateau
    assert plateau_pdf_1d(0.3 + 0.5 * d, 0.3, d, sigma) == pytest.approx(1 / (np.sqrt(2 * np.pi) * sigma + 2 * d))


def test_eq8_reduces_to_gaussian_when_d_is_zero():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3))
    S = A @ A.T + 0.5 * np.eye(3)
    delta = rng.normal(size=(50, 3))
    np.testing.assert_allclose(plateau_logpdf(delta, 0.0, S), multivariate_normal(np.zeros(3), S).logpdf(delta),
                               rtol=1e-12)
    x = np.linspace(-3, 3, 11)
    np.testing.assert_allclose(plateau_pdf_1d(x, 0.0, 0.0, 0.7), norm(0, 0.7).pdf(x), rtol=1e-12)


def test_eq8_plateau_and_shifted_tails():
    S = np.diag([4.0, 1.0])
    d = 3.0
    logD = -np.log(2 * np.pi * 2.0 + np.pi * 9.0)
    inside = np.array([[0.0, 0.0], [2.9, 0.0], [0.0, -2.0]])
    np.testing.assert_allclose(plateau_logpdf(inside, d, S), logD)
    # outside: delta shrunk by d along its direction, then the Gaussian exponent
    out = np.array([[5.0, 0.0], [0.0, -4.0]])
    np.testing.assert_allclose(plateau_logpdf(out, d, S), [logD - 0.5 * 4 / 4, logD - 0.5 * 1 / 1])
    assert ball_volume(2.0, 2) == pytest.approx(np.pi * 4) and ball_volume(1.0, 3) == pytest.approx(4 / 3 * np.pi)
    assert ball_volume(0.0, 3) == 0.0


def test_transition_mean_and_noise():
    rng = np.random.default_rng(0)
    T0 = se3_exp([100.0, 50.0, 20.0, 0.1, 0.2, -0.3])
    Ts = np.repeat(T0[None], 6000, axis=0)
    inc = se3_exp([1.0, 0.5, 0.0, 0.0, 0.0, 0.01])
    exact = transition(Ts[:3], inc, 0.0, 0.0, rng)
    np.testing.assert_allclose(exact, np.repeat((inc @ T0)[None], 3, axis=0), atol=1e-12)
    out = transition(Ts, inc, 0.2, 0.003, rng)
    # offsets in the tool frame of the mean T+ T0: zero mean, std (0.2 mm, 0.003 rad)
    ref = inc @ T0
    dp = (out[:, :3, 3] - ref[:3, 3]) @ ref[:3, :3]
    dr = rotation_vector_from_matrix(ref[:3, :3].T @ out[:, :3, :3])
    np.testing.assert_allclose(dp.std(axis=0), 0.2, rtol=0.05)
    np.testing.assert_allclose(dr.std(axis=0), 0.003, rtol=0.05)
    np.testing.assert_allclose(dp.mean(axis=0), 0.0, atol=0.01)
    np.testing.assert_allclose(np.linalg.det(out[:, :3, :3]), 1.0, atol=1e-12)
    # one width per tool axis (filter.axis_scale_*): the offsets' std follows each axis
    out = transition(Ts, inc, [0.2, 0.05, 0.0], [0.0, 0.003, 0.001], rng)
    dp = (out[:, :3, 3] - ref[:3, 3]) @ ref[:3, :3]
    dr = rotation_vector_from_matrix(ref[:3, :3].T @ out[:, :3, :3])
    np.testing.assert_allclose(dp.std(axis=0), [0.2, 0.05, 0.0], rtol=0.05, atol=1e-9)
    np.testing.assert_allclose(dr.std(axis=0), [0.0, 0.003, 0.001], rtol=0.05, atol=1e-9)


def test_robot_density_matches_numpy_reference():
    tool = np.eye(4)
    tool[2, 3] = 150.0
    chain = puma560().with_tool(tool)
    q = np.deg2rad([10.0, 70.0, -200.0, 5.0, -50.0, 20.0])
    f = np.array([100.0, -500.0, -3000.0])
    meas = robot_measurement(chain, q, f, joint_sigma_rad=1e-4, floor_t_mm=0.1, floor_r_rad=1e-4,
                             d0_mm=1.0, kd_mm_per_n=1e-4, d0_rad=1e-3, kd_rad_per_n=1e-7)
    np.testing.assert_allclose(meas.T_mean, chain.forward_kinematics(q), atol=1e-10)
    assert meas.d_t_mm == pytest.approx(1.0 + 1e-4 * np.linalg.norm(f))
    J = chain.geometric_jacobian(q)
    np.testing.assert_allclose(meas.Sigma_t, 1e-8 * (J @ J.T)[:3, :3] + 0.01 * np.eye(3), rtol=1e-10)
    rng = np.random.default_rng(2)
    Ts = meas.T_mean @ se3_exp(rng.normal(size=(300, 6)) * [1, 1, 1, 2e-3, 2e-3, 2e-3])
    dt = Ts[:, :3, 3] - meas.T_mean[:3, 3]
    dr = rotation_vector_from_matrix(Ts[:, :3, :3] @ meas.T_mean[:3, :3].T)
    ref = plateau_logpdf(dt, meas.d_t_mm, meas.Sigma_t) + plateau_logpdf(dr, meas.d_r_rad, meas.Sigma_r)
    np.testing.assert_allclose(robot_loglik(Ts, meas), ref, rtol=1e-10, atol=1e-9)
    # the compliance hook moves the mean: Fk(q + Cj(tau)) with tau = J_v^T f (N mm)
    cj = joint_compliance(2e-6)
    meas2 = robot_measurement(chain, q, f, joint_sigma_rad=1e-4, floor_t_mm=0.1, floor_r_rad=1e-4,
                              d0_mm=1.0, kd_mm_per_n=0.0, d0_rad=1e-3, kd_rad_per_n=0.0, compliance=cj)
    dq = 2e-6 * 1e-3 * (J[:3].T @ f)
    np.testing.assert_allclose(meas2.T_mean, chain.forward_kinematics(q + dq), atol=1e-10)
    assert np.linalg.norm(meas2.T_mean[:3, 3] - meas.T_mean[:3, 3]) > 0.1


def test_bending_plateau_is_narrow_about_the_force():
    """bending=True: the force-dependent part of the rotation plateau lies across the force. A
    rotation of 0.5 deg about the force leaves the plateau (d0 = 0.2 deg), the same rotation
    across the force stays on it; the density equals eq. 8 evaluated on A Δr (NumPy reference)."""
    chain = puma560().with_tool(np.diag([1.0, 1.0, 1.0, 1.0]))
    q = np.deg2rad([10.0, 70.0, -200.0, 5.0, -50.0, 20.0])
    f = np.array([0.0, 0.0, -5000.0])
    kw = dict(joint_sigma_rad=1e-5, floor_t_mm=0.1, floor_r_rad=1e-4, d0_mm=1.0, kd_mm_per_n=0.0,
              d0_rad=np.deg2rad(0.2), kd_rad_per_n=np.deg2rad(2e-4))
    ball = robot_measurement(chain, q, f, **kw)
    bend = robot_measurement(chain, q, f, bending=True, **kw)
    assert ball.A_r is None and bend.d_r_rad == ball.d_r_rad == pytest.approx(np.deg2rad(1.2))
    T0 = bend.T_mean
    Ts = np.stack([T0, T0, T0])  # turned about the tool centre point, in the base frame:
    Ts[1, :3, :3] = se3_exp(np.r_[0, 0, 0, np.deg2rad([0.0, 0.0, 0.5])])[:3, :3] @ T0[:3, :3]  # about f
    Ts[2, :3, :3] = se3_exp(np.r_[0, 0, 0, np.deg2rad([0.5, 0.0, 0.0])])[:3, :3] @ T0[:3, :3]  # across f
    ll_bend, ll_ball = robot_loglik(Ts, bend), robot_loglik(Ts, ball)
    assert ll_bend[2] == pytest.approx(ll_bend[0]) and ll_ball[1] == pytest.approx(ll_ball[0])
    assert ll_bend[0] - ll_bend[1] > 50.0  # 0.3 deg beyond the plateau, tails of 1e-4 rad
    # the same numbers from eq. 8 on A Δr, A = I + (d/d0 - 1) u uᵀ, with the |det A| Jacobian
    u = f / np.linalg.norm(f)
    A = np.eye(3) + (1.2 / 0.2 - 1.0) * np.outer(u, u)
    dr = rotation_vector_from_matrix(Ts[:, :3, :3] @ T0[:3, :3].T)
    ref = (plateau_logpdf(Ts[:, :3, 3] - T0[:3, 3], bend.d_t_mm, bend.Sigma_t)
           + plateau_logpdf(dr @ A.T, bend.d_r_rad, A @ bend.Sigma_r @ A.T) + np.log(np.linalg.det(A)))
    np.testing.assert_allclose(ll_bend, ref, rtol=1e-10, atol=1e-9)


def _straight_seam():
    """A seam along base y at x = 5, z = 0 mm, with a kink at y = 60 (x grows after it)."""
    y = np.array([-50.0, 0.0, 30.0, 60.0, 100.0, 150.0])
    x = np.where(y > 60.0, 5.0 + 0.5 * (y - 60.0), 5.0)
    return np.c_[x, y, np.zeros_like(y)]


def test_laser_density_matches_numpy_intersection():
    seam = SeamLine(_straight_seam())
    rng = np.random.default_rng(3)
    # tool frame = base frame shifted; particles perturbed around it
    Ts = se3_exp(rng.normal(size=(400, 6)) * [1.0, 3.0, 1.0, 0.02, 0.02, 0.02])
    m = np.array([4.0, 0.5])
    for dist in (20.0, 40.0, 70.0):
        got = laser_loglik(Ts, m, dist, seam, (0, 5), 0.1, 10.0)
        # reference: m-hat, the particle's laser plane, the general NumPy intersection
        R = Ts[:, :3, :3]
        m_hat = Ts[:, :3, 3] + R @ np.array([m[0], dist, m[1]])
        hit = seam.intersect(m_hat, R[:, :, 1])
        e = m_hat - hit.point
        e2 = (e * R[:, :, 0]).sum(1) ** 2 + (e * R[:, :, 2]).sum(1) ** 2
        ref = -0.5 * e2 / 0.01 - np.log(2 * np.pi * 0.01)
        assert hit.found.all()
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9)


def test_laser_density_peaks_at_the_true_pose_and_penalises_misses():
    seam = SeamLine(_straight_seam())
    T_true = se3_exp([1.0, 10.0, -0.5, 0.0, 0.0, 0.0])
    # the true measurement: seam at x = 5, z = 0 seen from the sensor 20 mm ahead
    m = np.array([5.0 - 1.0, 0.0 + 0.5])
    candidates = np.stack([T_true, se3_exp([1.5, 10.0, -0.5, 0.0, 0.0, 0.0]), se3_exp([1.0, 10.0, -0.5, 0, 0, 0.05])])
    ll = laser_loglik(candidates, m, 20.0, seam, (0, 5), 0.1, 10.0)
    assert ll[0] == pytest.approx(-np.log(2 * np.pi * 0.01))
    assert ll[1] == pytest.approx(ll[0] - 0.5 * 0.5 ** 2 / 0.01)
    assert ll[2] < ll[0] - 10
    # translation along the featureless part of the seam (y) is invisible (Fig. 7 / §III-B)
    slid = laser_loglik(se3_exp([[1.0, 10.0 + s, -0.5, 0, 0, 0] for s in (-3.0, 0.0, 4.0)]), m, 20.0, seam,
                        (0, 5), 0.1, 10.0)
    np.testing.assert_allclose(slid, ll[0])
    # a window with no crossing charges the miss error
    miss = laser_loglik(candidates[:1], m, 20.0, seam, (3, 5), 0.1, 10.0)
    assert miss[0] == pytest.approx(ll[0] - 0.5 * 100 / 0.01)
    none = laser_loglik(candidates[:1], m, 20.0, seam, (-1, -1), 0.1, 10.0)
    assert none[0] == pytest.approx(miss[0])


def test_angle_density():
    nu = np.array([0.0, 0.0, 1.0])
    Ts = se3_exp([[0, 0, 0, 0, a, 0] for a in (0.0, 0.01, -0.02)])
    # rotation about the laser-plane normal (y) by a: the surface normal appears at atan2(-sin a, cos a)
    ll = angle_loglik(Ts, -0.01, nu, 0.005)
    assert np.argmax(ll) == 1
    assert ll[1] == pytest.approx(-np.log(np.sqrt(2 * np.pi) * 0.005), abs=1e-9)


def test_seam_line_search_window_and_intersections():
    from posekit.errors import GeometryError

    seam = SeamLine(_straight_seam())  # knots at y = -50, 0, 30, 60, 100, 150
    y_axis = np.array([0.0, 1.0, 0.0])
    # planes y = const through the seam: the crossing is on the seam, the segment is the right one
    origins = np.array([[0.0, -10.0, 3.0], [9.0, 45.0, 0.0], [0.0, 80.0, 0.0]])
    hit = seam.intersect(origins, np.repeat(y_axis[None], 3, axis=0))
    np.testing.assert_allclose(hit.point, [[5.0, -10.0, 0.0], [5.0, 45.0, 0.0], [15.0, 80.0, 0.0]])
    assert hit.segment.tolist() == [0, 2, 3] and hit.found.all()
    # beyond the ends: no crossing
    miss = seam.intersect(np.array([[0.0, 200.0, 0.0]]), y_axis[None])
    assert not miss.found[0] and miss.segment[0] == -1 and np.isnan(miss.point).all()
    # the search window around y = 45: only the segments reaching within 10 mm of the plane
    assert seam.candidates([5.0, 45.0, 0.0], y_axis, 10.0).tolist() == [2]
    assert seam.candidates([5.0, 55.0, 0.0], y_axis, 10.0).tolist() == [2, 3]
    assert seam.window([5.0, 55.0, 0.0], y_axis, 10.0) == (2, 4)
    assert seam.window([5.0, 500.0, 0.0], y_axis, 10.0) == (-1, -1)
    with pytest.raises(GeometryError, match=r"seam polyline: expected shape \(K >= 2, 3\), got \(1, 3\)"):
        SeamLine(np.zeros((1, 3)))
    with pytest.raises(GeometryError, match="seam polyline: non-finite vertices"):
        SeamLine(np.full((3, 3), np.nan))
