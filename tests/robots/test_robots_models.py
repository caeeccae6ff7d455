"""Named models and DHChain validation."""

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.robots import MODEL_NAMES, REVOLUTE, DHChain, robot_model


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_models_are_six_revolute_axes(name):
    chain = robot_model(name)
    assert chain.n_joints == 6
    assert chain.joint_types == (REVOLUTE,) * 6
    assert np.all(chain.q_min < chain.q_max)
    assert chain.within_limits(np.zeros(6))


def test_unknown_model():
    with pytest.raises(
        ConfigError,
        match=r"unknown robot model 'ur5', expected one of \['puma560', 'hiab033', 'abb_irb6640', 'ur10'\]",
    ):
        robot_model("ur5")


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ({"d": [0.0]}, r"bad: d: expected shape \(2,\), got shape \(1,\)"),
        ({"alpha": [0.0, np.nan]}, "bad: alpha must be finite"),
        ({"joint_types": ("revolute", "helical")}, "bad: unknown joint type 'helical'"),
        ({"joint_types": ("revolute",)}, "bad: expected 2 joint types, got 1"),
        ({"q_min": [1.0, 0.0], "q_max": [0.0, 1.0]}, "bad: expected q_min <= q_max"),
        (
            {"T_flange_tool": 2 * np.eye(4)},
            "bad: T_flange_tool: not a rigid transform",
        ),
    ],
)
def test_bad_chain(override, match):
    args = {
        "a": [1.0, 2.0],
        "alpha": [0.0, 0.0],
        "d": [0.0, 0.0],
        "theta": [0.0, 0.0],
        "joint_types": ("revolute", "prismatic"),
        "name": "bad",
    } | override
    with pytest.raises(ConfigError, match=match) as info:
        DHChain(**args)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("q", "match"),
    [
        (
            np.zeros(5),
            r"puma560: q must have shape \(6,\) or \(\.\.\., 6\), got shape \(5,\)",
        ),
        (np.zeros((3, 7)), r"got shape \(3, 7\)"),
        (np.full(6, np.inf), "q must be finite, found NaN or inf at index \\[0\\]"),
        ("abc", "q must be numeric"),
    ],
)
def test_fk_and_jacobian_bad_q(q, match):
    chain = robot_model("puma560")
    for fn in (chain.forward_kinematics, chain.geometric_jacobian):
        with pytest.raises(ConfigError, match=match):
            fn(q)
