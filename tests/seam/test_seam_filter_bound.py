"""The spread bound (engine/spread_bound.py): a Kalman covariance from the lasers' Jacobian, capped at
the robot plateau, reported where the particle cloud is narrower (issue 15, an honest spread)."""

import math

import numpy as np
import pytest

from posekit.seam.engine.densities import RobotMeasurement
from posekit.seam.engine.spread_bound import InformationBound, laser_jacobian, plateau_covariance
from posekit.seam.frontend.config import apply_overrides, config_from_dict
from posekit.seam.frontend.simulate import integrity_summary, run_episode

# a straight seam along base y through the origin, the tool at the origin looking down (tool = base)
SEAM = np.stack([np.zeros(81), np.linspace(-40.0, 120.0, 81), np.zeros(81)], axis=1)


def _mount(d):
    M = np.eye(4)
    M[1, 3] = d
    return M


def _readings(T, dists):
    """Noise-free readings of sensors on the tool y axis (the seam crossing their x-z plane), by hand."""
    out = []
    for d in dists:
        S = T @ _mount(d)
        # plane through S's origin with normal S's y axis meets the seam x = z = 0 at base y = s:
        n, o = S[:3, 1], S[:3, 3]
        s = (n @ o) / n[1]
        p = np.array([0.0, s, 0.0]) - o
        out.append((float(p @ S[:3, 0]), float(p @ S[:3, 2]), _mount(d), 0, SEAM.shape[0] - 1))
    return out


def _numeric_jacobian(T, dists, h=1e-4):
    """Central differences of the hand-made readings (an independent model of the in-plane error)."""
    def y(Tp):
        return np.concatenate([[-mx, -mz] for mx, mz, *_ in _readings(Tp, dists)])

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


def test_laser_jacobian_matches_an_independent_model_and_sees_no_roll_or_travel():
    T = np.eye(4)
    T[:3, 3] = [0.3, 5.0, -2.0]  # off the seam by 0.3 mm across and 2 mm along the tool axis
    dists = (20.0, 40.0)
    # the readings the filter would get at T itself: the error of T at its own reading is zero
    H = laser_jacobian(T, _readings(T, dists), SEAM)
    assert H.shape == (4, 6)
    # the in-plane error moves with the reading the pose would see (a hand-made model; the sign is
    # the kernel's error convention, irrelevant to the covariance HᵀH)
    np.testing.assert_allclose(H, _numeric_jacobian(T, dists), atol=2e-3)
    # travel along the seam (y) is invisible; the roll (ry) only through the 2 mm offset
    assert np.abs(H[:, 1]).max() < 1e-6
    np.testing.assert_allclose(np.abs(H[::2, 4]), 2.0, atol=1e-3)  # x reading moves by 2 mm per rad


def test_no_reading_leaves_the_plateau_and_the_cap_holds():
    meas = RobotMeasurement(np.eye(4), 0.01 * np.eye(3), 1e-6 * np.eye(3), 3.0, math.radians(0.5))
    C = plateau_covariance(meas, np.eye(3))
    np.testing.assert_allclose(np.diag(C), [9 / 5 + 0.01] * 3 + [math.radians(0.5) ** 2 / 5 + 1e-6] * 3)
    b = InformationBound(0.05)
    for _ in range(50):  # the random walk would grow beyond the plateau: the cap keeps it there
        s = b.update(np.eye(4), meas, 10.0, 1.0, [], SEAM)
    np.testing.assert_allclose(s, np.sqrt(np.diag(C)), rtol=1e-12)


def test_lasers_shrink_what_they_see_and_leave_travel_at_the_plateau():
    meas = RobotMeasurement(np.eye(4), 0.01 * np.eye(3), 1e-6 * np.eye(3), 3.0, math.radians(0.5))
    T = np.eye(4)
    b = InformationBound(0.05)
    for _ in range(20):
        s = b.update(T, meas, 0.0, 0.0, _readings(T, (20.0, 40.0)), SEAM)
    C = np.sqrt(np.diag(plateau_covariance(meas, np.eye(3))))
    assert s[1] == C[1]  # y: never seen
    # x, z, rx, rz: 4 readings per step, 20 steps, noise 0.05: far below the plateau
    assert s[0] < 0.03 and s[2] < 0.03 and s[3] < math.radians(0.05) and s[5] < math.radians(0.05)
    # one step of a linear Gaussian model by hand: the Kalman covariance
    H = laser_jacobian(T, _readings(T, (20.0, 40.0)), SEAM)
    P0 = plateau_covariance(meas, np.eye(3))
    P1 = np.linalg.inv(np.linalg.inv(P0) + H.T @ H / 0.05 ** 2)
    b.reset()
    s1 = b.update(T, meas, 0.0, 0.0, _readings(T, (20.0, 40.0)), SEAM)
    np.testing.assert_allclose(s1, np.sqrt(np.diag(P1)), rtol=1e-6)


def test_reported_spread_is_at_least_the_cloud_and_helps_a_wrong_start():
    # (the cloud floor off: it widens the cloud to a share of the bound, so the bound would change the estimate)
    base = {"trajectory.steps": 120, "filter.particles": 300, "filter.init_offset_mm": [8.0, 8.0, 8.0],
            "filter.init_offset_deg": [3.0, 3.0, 3.0], "filter.cloud_floor": 0.0}
    on = run_episode(apply_overrides(config_from_dict({}), base), 0)
    off = run_episode(apply_overrides(config_from_dict({}), {**base, "filter.spread_bound": 0.0}), 0)
    # same data and the same random draws: the estimate is the same, only the reported spread grows
    np.testing.assert_allclose(on.estimate, off.estimate)
    assert np.all(on.spread >= off.spread - 1e-12)
    cov_on = integrity_summary([on])[0]
    cov_off = integrity_summary([off])[0]
    assert np.all(cov_on >= cov_off) and cov_on.mean() > cov_off.mean()


def test_compiled_step_equals_the_numpy_reference():
    rng = np.random.default_rng(4)
    A = np.diag([1.0, 1.0, 3.0])
    meas = RobotMeasurement(np.eye(4), 0.04 * np.eye(3), 2e-6 * np.eye(3), 4.0, math.radians(0.8), A_r=A)
    a, b = InformationBound(0.05), InformationBound(0.05)
    for k in range(15):
        T = np.eye(4)
        T[:3, 3] = rng.normal(0.0, 1.0, 3)
        rd = _readings(T, (20.0, 40.0)) if k % 4 else []
        sa = a.update(T, meas, 0.02, 1e-3, rd, SEAM)
        sb = b.update_numpy(T, meas, 0.02, 1e-3, rd, SEAM)
        np.testing.assert_allclose(sa, sb, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(a.P, b.P, rtol=1e-6, atol=1e-12)


def test_per_reading_variances_match_the_numpy_reference_and_the_kalman_form():
    # the filter may pass each reading's weighing variance (filter.bound_inflation); compiled = NumPy, and one
    # step from the plateau is the Kalman covariance with R = diag(variances), by hand
    meas = RobotMeasurement(np.eye(4), 0.01 * np.eye(3), 1e-6 * np.eye(3), 3.0, math.radians(0.5))
    T = np.eye(4)
    T[:3, 3] = [0.2, 1.0, -0.5]
    rd = _readings(T, (20.0, 40.0))
    v = [0.05 ** 2 * 1.7, 0.05 ** 2 * 3.0]
    a, b = InformationBound(0.05), InformationBound(0.05)
    sa = a.update(T, meas, 0.0, 0.0, rd, SEAM, v)
    sb = b.update_numpy(T, meas, 0.0, 0.0, rd, SEAM, v)
    np.testing.assert_allclose(sa, sb, rtol=1e-9)
    H1, H2 = laser_jacobian(T, rd[:1], SEAM), laser_jacobian(T, rd[1:], SEAM)
    H = np.vstack([H1, H2])
    R = np.diag([v[0]] * H1.shape[0] + [v[1]] * H2.shape[0])
    P0 = plateau_covariance(meas, np.eye(3))
    np.testing.assert_allclose(a.P, np.linalg.inv(np.linalg.inv(P0) + H.T @ np.linalg.solve(R, H)), rtol=1e-6,
                               atol=1e-12)
    # sigma² for every reading is the default
    c = InformationBound(0.05)
    np.testing.assert_allclose(c.update(T, meas, 0.0, 0.0, rd, SEAM, [0.05 ** 2] * 2),
                               InformationBound(0.05).update(T, meas, 0.0, 0.0, rd, SEAM), rtol=1e-12)
    with pytest.raises(ValueError, match=r"sigma2: expected one variance per reading \(2\), got 1"):
        InformationBound(0.05).update(T, meas, 0.0, 0.0, rd, SEAM, [0.01])


def test_bound_inflation_widens_only_the_report_when_the_floor_is_off():
    base = {"trajectory.steps": 150, "filter.particles": 300, "filter.cloud_floor": 0.0, "filter.bound_inflation": 0.0}
    cfg = apply_overrides(config_from_dict({}), base)
    off = run_episode(cfg, 2)
    on = run_episode(apply_overrides(cfg, {"filter.bound_inflation": 1.0}), 2)
    np.testing.assert_array_equal(on.estimate, off.estimate)
    # the bound at the particles' weighing variance (~1.35 sigma² when converged): wider on every axis on average
    assert np.all(on.spread.mean(axis=0) > off.spread.mean(axis=0))
    assert np.all(on.spread.mean(axis=0) < 1.5 * off.spread.mean(axis=0))


def test_the_bound_takes_the_particles_inflation_only_while_re_acquiring():
    # (the shrink limit off: it too widens the report after a loss, tested below)
    base = {"trajectory.steps": 150, "filter.particles": 300, "filter.cloud_floor": 0.0, "filter.bound_inflation": 0.0,
            "filter.spread_shrink_reacquire": 0.0}
    start = {**base, "filter.init_offset_mm": [8.0, 8.0, 8.0], "filter.init_offset_deg": [3.0, 3.0, 3.0]}
    cfg = apply_overrides(config_from_dict({}), start)
    on = run_episode(cfg, 0)
    off = run_episode(apply_overrides(cfg, {"filter.bound_inflation_reacquire": 0.0}), 0)
    np.testing.assert_array_equal(on.estimate, off.estimate)
    lost = np.flatnonzero(on.status == "lost")
    assert lost.size and lost.max() < 20
    after = slice(lost.max() + 1, 150)  # within bound_reacquire_steps (500) of the loss
    assert np.all(on.spread[after].mean(axis=0) > off.spread[after].mean(axis=0))
    # a run that never lost the track is the same with or without it
    nominal = apply_overrides(config_from_dict({}), base)
    a = run_episode(nominal, 1)
    b = run_episode(apply_overrides(nominal, {"filter.bound_inflation_reacquire": 0.0}), 1)
    assert "lost" not in set(a.status)
    np.testing.assert_array_equal(a.spread, b.spread)


def test_after_a_loss_the_reported_spread_shrinks_at_most_by_the_limit_per_step():
    base = {"trajectory.steps": 150, "filter.particles": 300}
    start = {**base, "filter.init_offset_mm": [8.0, 8.0, 8.0], "filter.init_offset_deg": [3.0, 3.0, 3.0]}
    cfg = apply_overrides(config_from_dict({}), start)
    assert cfg.filter.spread_shrink_reacquire == 0.97 and cfg.filter.bound_reacquire_steps == 500
    on = run_episode(cfg, 0)
    off = run_episode(apply_overrides(cfg, {"filter.spread_shrink_reacquire": 0.0}), 0)
    np.testing.assert_array_equal(on.estimate, off.estimate)  # the report only: the estimate is the same
    lost = np.flatnonzero(on.status == "lost")
    assert lost.size and lost.max() < 20
    after = np.arange(lost.min() + 1, 150)
    ratio = on.spread[after] / on.spread[after - 1]
    assert ratio.min() >= 0.97 - 1e-12
    assert (off.spread[after] / off.spread[after - 1]).min() < 0.9  # without it a step halved part of the spread
    assert np.all(on.spread >= off.spread) and np.any(on.spread[after] > off.spread[after])
    # beyond bound_reacquire_steps after the last loss the limit no longer applies (the report only differs within)
    window = {"filter.bound_reacquire_steps": 40}
    short = run_episode(apply_overrides(cfg, window), 0)
    short_off = run_episode(apply_overrides(cfg, {**window, "filter.spread_shrink_reacquire": 0.0}), 0)
    late = slice(int(lost.max()) + 41, 150)  # steps 1 .. 40 after the last lost one are within
    np.testing.assert_array_equal(short.spread[late], short_off.spread[late])
    assert np.any(short.spread[: late.start] > short_off.spread[: late.start])
    # a run that never lost the track is the same with or without it
    nominal = apply_overrides(config_from_dict({}), base)
    a = run_episode(nominal, 1)
    b = run_episode(apply_overrides(nominal, {"filter.spread_shrink_reacquire": 0.0}), 1)
    assert "lost" not in set(a.status)
    np.testing.assert_array_equal(a.spread, b.spread)
