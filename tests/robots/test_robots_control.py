"""Resolved-rate control with a quaternion orientation error (eq. 4-6)."""

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.geometry import matrix_from_rotation_vector, rotation_angle_between
from posekit.robots import RateGains, hiab033, pose_error, puma560, resolved_rate_step

CASES = {
    # model, start q (rad), joint offset of the reachable target (rad)
    "puma560": (
        puma560,
        [0.2, 0.6, -0.9, 0.3, 0.7, -0.4],
        [0.25, -0.2, 0.3, -0.3, 0.25, 0.4],
    ),
    "hiab033": (
        hiab033,
        [0.3, 0.4, -0.8, 0.2, 0.6, 0.1],
        [-0.2, 0.15, -0.25, 0.3, -0.3, 0.35],
    ),
}


@pytest.mark.parametrize("name", CASES)
def test_converges_to_reachable_target(name):
    make, q0, dq = CASES[name]
    chain = make()
    q0 = np.asarray(q0)
    T_target = chain.forward_kinematics(q0 + np.asarray(dq))
    q = q0
    dt = 0.01
    for step in range(200):
        q, err = resolved_rate_step(
            chain, q, T_target, RateGains(60.0, 60.0), dt, damping=1e-4
        )
        if np.all(np.abs(err) < 1e-9):
            break
    T = chain.forward_kinematics(q)
    assert step < 100
    assert np.linalg.norm(T[:3, 3] - T_target[:3, 3]) < 1e-6  # mm
    assert rotation_angle_between(T[:3, :3], T_target[:3, :3]) < 1e-6  # rad
    assert chain.within_limits(q)


def test_first_step_error_and_direction():
    chain = puma560()
    q = np.array([0.1, 0.5, -0.8, 0.2, 0.6, 0.0])
    T = chain.forward_kinematics(q)
    T_target = T.copy()
    T_target[:3, 3] += [5.0, -3.0, 2.0]
    T_target[:3, :3] = matrix_from_rotation_vector([0.0, 0.0, 0.01]) @ T[:3, :3]
    q_new, err = resolved_rate_step(chain, q, T_target, (1.0, 1.0), 0.5, damping=0.0)
    np.testing.assert_allclose(err[:3], [5.0, -3.0, 2.0], atol=1e-9)
    # 2 δr = 2 sin(θ/2) axis for a rotation θ about the base z axis
    np.testing.assert_allclose(err[3:], [0.0, 0.0, 2 * np.sin(0.005)], atol=1e-12)
    # One step with k·dt = 0.5 removes about half of the error (up to second-order terms).
    err_new = pose_error(chain.forward_kinematics(q_new), T_target)
    np.testing.assert_allclose(err_new, 0.5 * err, atol=1e-2 * np.abs(err).max())


def test_quaternion_sign_is_canonical():
    # A 359° error is a -1° error: δr must not flip the long way around.
    R = matrix_from_rotation_vector([0.0, 0.0, np.deg2rad(359.0)])
    T_d = np.eye(4)
    T_d[:3, :3] = R
    err = pose_error(np.eye(4), T_d)
    np.testing.assert_allclose(
        err[3:], [0.0, 0.0, -2 * np.sin(np.deg2rad(0.5))], atol=1e-12
    )


def test_joint_limits_clamp():
    chain = puma560()
    q = chain.q_max - 1e-3
    T_far = chain.forward_kinematics(np.zeros(6))
    q_new, _ = resolved_rate_step(chain, q, T_far, (1e3, 1e3), 1.0, damping=1e-3)
    assert chain.within_limits(q_new)


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ({"q": np.zeros(5)}, r"q must have shape \(6,\) or \(\.\.\., 6\), got shape \(5,\)"),
        (
            {"q": [0.0, np.nan, 0, 0, 0, 0]},
            "q must be finite, found NaN or inf at index",
        ),
        ({"q": np.zeros((2, 6))}, r"q must have shape \(6,\), got shape \(2, 6\)"),
        ({"dt": 0.0}, "dt must be a finite number > 0 s, got 0.0"),
        ({"dt": -0.01}, "dt must be a finite number > 0 s"),
        ({"dt": float("nan")}, "dt must be a finite number > 0 s"),
        ({"damping": -1.0}, "damping must be a finite number >= 0"),
        (
            {"T_target": np.full((4, 4), np.nan)},
            r"T_target must be a finite \(4, 4\) transform",
        ),
        ({"T_target": np.eye(3)}, r"T_target must be a finite \(4, 4\) transform"),
        (
            {"T_target": 2 * np.eye(4)},
            "T_target: rotation block is not a rotation matrix",
        ),
        ({"gains": (1.0, -1.0)}, "gains.k_theta: expected finite non-negative"),
        ({"gains": 3.0}, "gains: expected RateGains or"),
    ],
)
def test_bad_input(override, match):
    args = {
        "chain": puma560(),
        "q": np.zeros(6),
        "T_target": np.eye(4),
        "gains": (1.0, 1.0),
        "dt": 0.01,
        "damping": 1e-3,
    } | override
    with pytest.raises(ConfigError, match=match) as info:
        resolved_rate_step(**args)
    assert "\n" not in str(info.value)
