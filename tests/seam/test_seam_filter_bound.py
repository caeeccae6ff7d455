"""The spread bound (engine/spread_bound.py) and the linearised filter the tuner uses (engine/ekf.py): a Kalman
covariance from the lasers' Jacobian, capped at the robot plateau; compiled = NumPy; the EKF pass finds a pose
offset on a hand-made seam and its negative log-likelihood is the prediction-error decomposition."""

import math

import numpy as np
import pytest

from posekit.seam.engine import _linear as _l
from posekit.seam.engine.densities import RobotMeasurement
from posekit.seam.engine.spread_bound import InformationBound, Readings, laser_jacobian, plateau_covariance

# a straight seam along base y through the origin, the tool at the origin looking down (tool = base)
SEAM = np.stack([np.zeros(81), np.linspace(-40.0, 120.0, 81), np.zeros(81)], axis=1)


def _mount(d):
    M = np.eye(4)
    M[1, 3] = d
    return M


def _readings(T, dists, var=0.05 ** 2):
    """Noise-free readings of sensors on the tool y axis (the seam crossing their x-z plane), by hand."""
    mx, mz, Ms = [], [], []
    for d in dists:
        S = T @ _mount(d)
        n, o = S[:3, 1], S[:3, 3]
        s = (n @ o) / n[1]  # the plane meets the seam x = z = 0 at base y = s
        p = np.array([0.0, s, 0.0]) - o
        mx.append(float(p @ S[:3, 0]))
        mz.append(float(p @ S[:3, 2]))
        Ms.append(_mount(d))
    k = len(dists)
    return Readings(mx, mz, np.stack(Ms) if k else np.zeros((0, 4, 4)), [0] * k, [SEAM.shape[0] - 1] * k,
                    np.full((k, 2), var))


def _numeric_jacobian(T, dists, h=1e-4):
    """Central differences of the hand-made readings (an independent model of the in-plane error)."""
    def y(Tp):
        r = _readings(Tp, dists)
        return np.concatenate([[-a, -b] for a, b in zip(r.mx, r.mz)])

    J = np.empty((2 * len(dists), 6))
    for j in range(6):
        d = np.zeros(6)
        d[j] = h
        Tp, Tm = T.copy(), T.copy()
        for sgn, Tx in ((1, Tp), (-1, Tm)):
            a = sgn * d
            ang = np.linalg.norm(a[3:])
            R = np.eye(3)
            if ang > 0:
                k = a[3:] / ang
                K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
                R = np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K
            Tx[:3, 3] = T[:3, 3] + T[:3, :3] @ a[:3]
            Tx[:3, :3] = T[:3, :3] @ R
        J[:, j] = (y(Tp) - y(Tm)) / (2 * h)
    return J


def _meas(A=None):
    return RobotMeasurement(np.eye(4), 0.01 * np.eye(3), 1e-6 * np.eye(3), 3.0, math.radians(0.5), A_r=A)


def test_laser_jacobian_matches_an_independent_model_and_sees_no_roll_or_travel():
    T = np.eye(4)
    T[:3, 3] = [0.3, 5.0, -2.0]  # off the seam by 0.3 mm across and 2 mm along the tool axis
    dists = (20.0, 40.0)
    H, e = laser_jacobian(T, _readings(T, dists), SEAM)
    assert H.shape == (4, 6)
    np.testing.assert_allclose(e, 0.0, atol=1e-9)  # the error of T at its own readings is zero
    np.testing.assert_allclose(H, _numeric_jacobian(T, dists), atol=2e-3)
    # travel along the seam (y) is invisible; the roll (ry) only through the 2 mm offset
    assert np.abs(H[:, 1]).max() < 1e-6
    np.testing.assert_allclose(np.abs(H[::2, 4]), 2.0, atol=1e-3)  # x reading moves by 2 mm per rad


def test_no_reading_leaves_the_plateau_and_the_cap_holds():
    meas = _meas()
    C = plateau_covariance(meas, np.eye(3))
    np.testing.assert_allclose(np.diag(C), [9 / 5 + 0.01] * 3 + [math.radians(0.5) ** 2 / 5 + 1e-6] * 3)
    b = InformationBound()
    for _ in range(50):  # the random walk would grow beyond the plateau: the cap keeps it there
        s = b.update(np.eye(4), meas, np.r_[[100.0] * 3, [1.0] * 3], Readings.none(), SEAM)
    np.testing.assert_allclose(s, np.sqrt(np.diag(C)), rtol=1e-12)


def test_lasers_shrink_what_they_see_and_one_step_is_the_kalman_covariance():
    meas = _meas()
    T = np.eye(4)
    b = InformationBound()
    for _ in range(20):
        s = b.update(T, meas, np.zeros(6), _readings(T, (20.0, 40.0)), SEAM)
    C = np.sqrt(np.diag(plateau_covariance(meas, np.eye(3))))
    assert s[1] == C[1]  # y: never seen
    assert s[0] < 0.03 and s[2] < 0.03 and s[3] < math.radians(0.05) and s[5] < math.radians(0.05)
    # one step from the plateau with per-reading variances: the Kalman form by hand
    rd = _readings(T, (20.0, 40.0))
    rd.r2[:] = [[0.05 ** 2 * 1.7, 0.05 ** 2 * 2.0], [0.05 ** 2 * 3.0, 0.05 ** 2]]
    H, _ = laser_jacobian(T, rd, SEAM)
    R = np.diag(rd.r2.reshape(-1))
    P0 = plateau_covariance(meas, np.eye(3))
    b.reset()
    b.update(T, meas, np.zeros(6), rd, SEAM)
    np.testing.assert_allclose(b.P, np.linalg.inv(np.linalg.inv(P0) + H.T @ np.linalg.solve(R, H)), rtol=1e-6,
                               atol=1e-12)


def test_compiled_step_equals_the_numpy_reference():
    rng = np.random.default_rng(4)
    meas = _meas(np.diag([1.0, 1.0, 3.0]))
    a, b = InformationBound(), InformationBound()
    q2 = np.r_[[0.02 ** 2] * 3, [1e-3 ** 2] * 3]
    for k in range(15):
        T = np.eye(4)
        T[:3, 3] = rng.normal(0.0, 1.0, 3)
        rd = _readings(T, (20.0, 40.0)) if k % 4 else Readings.none()
        Q = np.diag(rng.uniform(0, 1e-4, 6))
        sa = a.update(T, meas, q2, rd, SEAM, Q)
        sb = b.update_numpy(T, meas, q2, rd, SEAM, Q)
        np.testing.assert_allclose(sa, sb, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(a.P, b.P, rtol=1e-6, atol=1e-12)


def test_ekf_pass_finds_an_offset_and_its_likelihood_is_the_prediction_error_decomposition():
    # a pose 0.3 mm across and 0.5 mm down off the seam, static (identity motion), exact readings each step: the
    # linearised filter's pose converges on x and z; its NLL is the sum of the innovations' Gaussian terms, here
    # recomputed step by step with the same P in NumPy
    n, S = 30, 2
    T0 = np.eye(4)
    truth = np.eye(4)
    truth[:3, 3] = [0.3, 10.0, -0.5]
    rd = _readings(truth, (20.0, 40.0))
    laser = np.repeat(np.c_[rd.mx, rd.mz][None], n, axis=0)
    Ms = np.repeat(np.stack([_mount(20.0), _mount(40.0)])[None], n, axis=0)
    T0[:3, 3] = [0.0, 10.0, 0.0]
    U = np.repeat(np.eye(4)[None], n, axis=0)
    K = np.repeat(T0[None], n, axis=0)
    St = np.repeat((0.01 * np.eye(3))[None], n, axis=0)
    Sr = np.repeat((1e-6 * np.eye(3))[None], n, axis=0)
    Ai = np.repeat(np.eye(3)[None], n, axis=0)
    r2 = np.full((S, 2), 0.01 ** 2)
    out_T, out_P = np.empty((n, 4, 4)), np.empty((n, 6))
    nll = _l.ekf_pass(U, T0, K, St, Sr, Ai, np.full(n, 3.0), np.full(n, math.radians(0.5)), laser, Ms, r2,
                      np.zeros(6), np.full(n, 0.01), SEAM, np.array([20.0, 40.0]), 1e-3, 1e-5, out_T, out_P)
    np.testing.assert_allclose(out_T[-1][[0, 2], 3], [0.3, -0.5], atol=1e-3)
    assert out_P[-1, 0] < out_P[0, 0] and out_P[-1, 1] == pytest.approx(out_P[0, 1])  # y unseen
    # the same recursion in NumPy: predict (no walk), H and e at the pose, Kalman update, NLL terms
    P = plateau_covariance(RobotMeasurement(T0, St[0], Sr[0], 3.0, math.radians(0.5)), np.eye(3))
    T = T0.copy()
    want = 0.0
    for _ in range(n):
        H, e = laser_jacobian(T, Readings(rd.mx, rd.mz, Ms[0], [0, 0], [SEAM.shape[0] - 1] * 2, r2), SEAM)
        Sm = H @ P @ H.T + np.diag(np.full(H.shape[0], 0.01 ** 2))
        want += 0.5 * (e @ np.linalg.solve(Sm, e) + np.linalg.slogdet(Sm)[1] + H.shape[0] * math.log(2 * math.pi))
        G = P @ H.T @ np.linalg.inv(Sm)
        dx = -G @ e
        P = P - G @ H @ P
        out = np.empty((4, 4))
        _l.exp_right(T, dx, out)
        T = out
    assert nll == pytest.approx(want, rel=1e-6)
