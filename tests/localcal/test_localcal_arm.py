"""Long-reach arm simulator: nominal vs true kinematics, PT-1 joints, backlash, bending."""

import numpy as np
import pytest

from posekit.errors import ConfigError, GeometryError
from posekit.localcal.sim._arm_kernel import simulate_moves
from posekit.localcal.sim.arm import (
    DEFAULT_Q0,
    LongReachArm,
    NonKinematicErrors,
    sample_nonkinematic_errors,
)
from posekit.robots import hiab033, resolved_rate_step

BENDING_ONLY = NonKinematicErrors(np.zeros(6), np.zeros(6), [1.0e-3, 1.5e-3])


def _shifted(T, dp_mm):
    T = T.copy()
    T[:3, 3] += dp_mm
    return T


def test_compiled_rate_step_equals_robots_resolved_rate_step():
    m = hiab033()
    q = DEFAULT_Q0 + [0.1, -0.05, 0.08, 0.2, -0.1, 0.3]
    T_target = m.forward_kinematics(DEFAULT_Q0)
    twist = np.array([10.0, -20.0, 5.0, 0.01, -0.02, 0.03])
    ref = resolved_rate_step(m, q, T_target, (7.0, 3.0), 0.01, 1e-3, twist_target=twist)
    ones = np.ones(6)
    _, _, q_cmd = simulate_moves(
        *m.kinematic_pack, m.q_min, m.q_max,
        T_target[None, :3, 3].copy(), T_target[None, :3, :3].copy(), twist[None],
        np.array([7.0, 7.0, 7.0, 3.0, 3.0, 3.0]), 1e-3, 0.01,
        ones, 0.5 * ones, ones, 0.0 * ones, np.zeros((1, 6)),
        q.copy(), q.copy(), np.zeros(6), q.copy(), q.copy(),
    )
    np.testing.assert_allclose(q_cmd[0], ref.q, rtol=0, atol=1e-12)


def test_nominal_model_mispredicts_true_tool_by_centimetres():
    rng = np.random.default_rng(0)
    d = []
    for seed in range(12):
        arm = LongReachArm(seed=seed)
        q = DEFAULT_Q0 + rng.uniform(-0.3, 0.3, 6)
        d.append(np.linalg.norm(arm.true_kinematics(q)[:3, 3] - arm.model.forward_kinematics(q)[:3, 3]))
    d = np.array(d)
    assert 20.0 < np.median(d) < 60.0
    assert np.all((d > 10.0) & (d < 100.0))
    zero = LongReachArm(errors=sample_nonkinematic_errors(1, scale=0.0), seed=1)
    np.testing.assert_allclose(zero.true_pose(), zero.model.forward_kinematics(zero.q_measured()), atol=0.5)


def test_move_to_reaches_reference_nominally_but_not_truly():
    arm = LongReachArm(seed=4)
    T0 = arm.nominal_pose()
    # 0.55 m forward along the camera's viewing axis (-z_F) and 0.15 m sideways, as when the
    # tool is driven to an OOI ~1 m in front of the camera
    T_ref = _shifted(T0, -550.0 * T0[:3, 2] + 150.0 * T0[:3, 1])
    log = arm.move_to(T_ref, duration_s=4.0, settle_s=1.5)
    n = len(log.t_s)
    assert n == 1 + 400 + 150
    assert log.q_measured.shape == (n, 6) and log.T_B_F_true.shape == (n, 4, 4)
    np.testing.assert_allclose(np.diff(log.t_s), 0.01, atol=1e-9)
    err_nominal = np.linalg.norm(arm.nominal_pose()[:3, 3] - T_ref[:3, 3])
    err_true = np.linalg.norm(arm.true_pose()[:3, 3] - T_ref[:3, 3])
    assert err_nominal < 1.0
    assert 10.0 < err_true < 100.0
    assert arm.command_residual_mm < 0.01
    R_err = arm.nominal_pose()[:3, :3].T @ T_ref[:3, :3]
    assert np.arccos(np.clip((np.trace(R_err) - 1) / 2, -1, 1)) < 1e-3
    np.testing.assert_array_equal(log.T_B_F_nominal[-1], arm.nominal_pose())
    np.testing.assert_array_equal(log.T_B_F_true[-1], arm.true_pose())


def test_orientation_move_about_fixed_axis():
    arm = LongReachArm(seed=2)
    T0 = arm.nominal_pose()
    R = np.array([[np.cos(0.1), -np.sin(0.1), 0], [np.sin(0.1), np.cos(0.1), 0], [0, 0, 1]])
    T_ref = T0.copy()
    T_ref[:3, :3] = T0[:3, :3] @ R
    arm.move_to(T_ref)
    R_err = arm.nominal_pose()[:3, :3].T @ T_ref[:3, :3]
    assert np.arccos(np.clip((np.trace(R_err) - 1) / 2, -1, 1)) < 1e-3
    assert np.linalg.norm(arm.nominal_pose()[:3, 3] - T0[:3, 3]) < 1.0


def test_pt1_servo_following_error_matches_ramp_error_constant():
    # P servo on a PT-1 (velocity) joint: a ramp of speed v lags by v / K_v in the middle
    # of the move, where the quintic's acceleration is zero.
    dp = np.array([0.0, 300.0, 0.0])
    lags = {}
    for kv in (2.0, 4.0):
        arm = LongReachArm(errors=BENDING_ONLY, kv=kv, tau_s=0.1, encoder_noise_rad=0.0, seed=0)
        T0 = arm.nominal_pose()
        log = arm.move_to(_shifted(T0, dp), duration_s=6.0, settle_s=3.0)
        mid = 300  # t = 3 s, path at 50 %, speed 1.875 * 300 / 6 mm/s
        lag = (T0[:3, 3] + 0.5 * dp - log.T_B_F_nominal[mid, :3, 3])[1]
        lags[kv] = lag
        assert lag == pytest.approx(1.875 * 300.0 / 6.0 / kv, rel=0.15)
        assert np.linalg.norm(log.T_B_F_nominal[-1, :3, 3] - (T0[:3, 3] + dp)) < 0.05
    assert lags[2.0] > 1.8 * lags[4.0]


def test_bending_droops_tip_by_lever_arm():
    # Stretched out (q = 0), TCP at x = 5250 mm: lift axis at x = 300 (lever 4950 mm), tilt
    # axis at x = 300 + 2400 (lever 2550 mm; a3 is vertical there); droop angles
    # 1.0e-3 * 4.95 and 1.5e-3 * 2.55 rad lower the tip by ~24.5 + 9.8 mm.
    arm = LongReachArm(errors=BENDING_ONLY, q0=np.zeros(6), seed=0)
    q = np.zeros(6)
    dz = arm.true_kinematics(q)[2, 3] - arm.model.forward_kinematics(q)[2, 3]
    assert dz == pytest.approx(-(1.0e-3 * 4.95 * 4950 + 1.5e-3 * 2.55 * 2550), rel=0.01)
    # booms raised: shorter horizontal levers, less droop (configuration-dependent)
    q_up = np.array([0.0, 1.2, -0.4, 0.0, 0.0, 0.0])
    dz_up = arm.true_kinematics(q_up)[2, 3] - arm.model.forward_kinematics(q_up)[2, 3]
    assert -0.6 * abs(dz) < dz_up < 0.0


def test_backlash_makes_error_depend_on_approach_direction():
    def approach_difference(backlash):
        errors = NonKinematicErrors(np.zeros(6), np.full(6, backlash), [0.0, 0.0])
        arm = LongReachArm(errors=errors, encoder_noise_rad=0.0, seed=0)
        A = arm.nominal_pose()
        arm.move_to(_shifted(A, [0.0, 0.0, 200.0]), duration_s=2.0, settle_s=0.5)
        arm.move_to(A, duration_s=2.0, settle_s=1.5)
        from_above = arm.true_pose()[:3, 3]
        arm.move_to(_shifted(A, [0.0, 0.0, -200.0]), duration_s=2.0, settle_s=0.5)
        arm.move_to(A, duration_s=2.0, settle_s=1.5)
        from_below = arm.true_pose()[:3, 3]
        assert np.linalg.norm(arm.nominal_pose()[:3, 3] - A[:3, 3]) < 0.1
        return from_above[2] - from_below[2]

    # lift and tilt joints each lag by half the dead band in opposite directions
    assert approach_difference(2e-3) > 5.0
    assert abs(approach_difference(0.0)) < 0.05


def test_follow_visits_waypoints_and_ends_at_the_last():
    arm = LongReachArm(seed=5)
    T0 = arm.nominal_pose()
    path = np.stack([_shifted(T0, [0.0, 100.0 * np.cos(a), 100.0 * np.sin(a)]) for a in (0.0, 2.0, 4.0)])
    log = arm.follow(path, segment_s=1.0, settle_s=1.0)
    assert len(log.t_s) == 1 + 300 + 100
    assert np.all(np.diff(log.t_s) > 0)
    for k, step in ((100, 0), (200, 1)):  # end of each segment: the joints still lag
        closest = np.linalg.norm(log.T_B_F_nominal[:, :3, 3] - path[step, :3, 3], axis=1).min()
        assert closest < 10.0
        assert np.linalg.norm(log.T_B_F_nominal[k, :3, 3] - path[step, :3, 3]) < 40.0
    assert np.linalg.norm(arm.nominal_pose()[:3, 3] - path[-1, :3, 3]) < 1.0


def test_unreachable_reference_is_reported():
    arm = LongReachArm(seed=1)
    T0 = arm.nominal_pose()
    arm.move_to(_shifted(T0, -2000.0 * T0[:3, 2]), duration_s=3.0, settle_s=0.5)  # beyond reach
    assert arm.command_residual_mm > 100.0


def test_same_seed_same_numbers():
    logs = []
    for seed in (7, 7, 8):
        arm = LongReachArm(seed=seed)
        logs.append(arm.move_to(_shifted(arm.nominal_pose(), [50.0, 0.0, 0.0]), duration_s=1.0, settle_s=0.2))
    np.testing.assert_array_equal(logs[0].q_measured, logs[1].q_measured)
    np.testing.assert_array_equal(logs[0].T_B_F_true, logs[1].T_B_F_true)
    assert not np.array_equal(logs[0].T_B_F_true, logs[2].T_B_F_true)


def test_bad_input_messages():
    arm = LongReachArm(seed=0)
    T = arm.nominal_pose()
    T[:3, :3] *= 2.0
    with pytest.raises(
        GeometryError,
        match=r"^T_B_ref\[\.\.\., :3, :3\]: expected rotation matrices \(R\^T R = I within 1e-06, det \+1\), "
        r"found max \|R\^T R - I\| = 3, det = 8$",
    ):
        arm.move_to(T)
    with pytest.raises(GeometryError,
                       match=r"^T_B_ref: expected an array of shape \(\.\.\., 4, 4\), got shape \(3, 4\)$"):
        arm.move_to(np.eye(4)[:3])
    with pytest.raises(GeometryError, match=r"^T_B_ref: expected one \(4, 4\) transform, got shape \(2, 4, 4\)$"):
        arm.move_to(np.stack([np.eye(4)] * 2))
    with pytest.raises(GeometryError, match=r"^T_B_path: expected finite values, found NaN or inf"):
        arm.follow(np.stack([np.eye(4), np.full((4, 4), np.nan)]))
    with pytest.raises(ConfigError, match=r"^duration_s must be a finite number > 0 s, got -1.0$"):
        arm.move_to(arm.nominal_pose(), duration_s=-1.0)
    with pytest.raises(ConfigError, match=r"^backlash_rad: expected 6 finite values >= 0, got \[-0.001, 0.0"):
        NonKinematicErrors(np.zeros(6), [-1e-3, 0, 0, 0, 0, 0], [0.0, 0.0])
    with pytest.raises(ConfigError, match=r"^hiab033: q0 must have shape \(6,\) or \(\.\.\., 6\), got shape \(5,\)$"):
        LongReachArm(q0=np.zeros(5))
    with pytest.raises(ConfigError, match=r"^rate_gains: expected 0 < gain <= 1/dt_s = 100 1/s, got \[500.0, 10.0\]$"):
        LongReachArm(rate_gains=(500.0, 10.0))
