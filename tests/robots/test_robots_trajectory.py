"""Quintic point-to-point joint trajectories."""

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.robots import quintic_trajectory

Q0 = np.array([0.1, -1.2, 2.5, 0.0, 1e-3, 750.0])
Q1 = np.array([-0.7, 0.4, 2.5, 3.0, -2.0, -120.0])


def test_boundary_conditions_exact():
    s = quintic_trajectory(Q0, Q1, 2.5, [0.0, 2.5], t_start=0.0)
    np.testing.assert_array_equal(s.q[0], Q0)
    np.testing.assert_array_equal(s.q[1], Q1)
    np.testing.assert_array_equal(s.qd, 0.0)
    np.testing.assert_array_equal(s.qdd, 0.0)


def test_holds_end_points_outside_interval():
    s = quintic_trajectory(Q0, Q1, 2.0, [-1.0, 1.0, 3.0], t_start=0.0)
    np.testing.assert_array_equal(s.q[0], Q0)
    np.testing.assert_array_equal(s.q[2], Q1)
    np.testing.assert_array_equal(s.qd[[0, 2]], 0.0)


def test_midpoint_and_peak_velocity():
    T = 4.0
    s = quintic_trajectory(Q0, Q1, T, T / 2 + 10.0, t_start=10.0)
    assert s.q.shape == (6,)
    np.testing.assert_allclose(s.q, (Q0 + Q1) / 2, atol=1e-12)
    np.testing.assert_allclose(
        s.qd, 1.875 * (Q1 - Q0) / T, atol=1e-12
    )  # s'(1/2) = 15/8
    np.testing.assert_allclose(s.qdd, 0.0, atol=1e-12)


def test_derivatives_match_finite_differences():
    t = np.linspace(0.05, 2.95, 40)
    h = 1e-6
    s, sp, sm = (quintic_trajectory(Q0, Q1, 3.0, t + e) for e in (0.0, h, -h))
    assert s.q.shape == s.qd.shape == s.qdd.shape == (40, 6)
    np.testing.assert_allclose(s.qd, (sp.q - sm.q) / (2 * h), atol=1e-5 * 900)
    np.testing.assert_allclose(s.qdd, (sp.qd - sm.qd) / (2 * h), atol=1e-5 * 900)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"q_end": Q1[:5]}, r"q_end: expected shape \(6,\)"),
        ({"q_start": np.r_[Q0[:5], np.nan]}, "q_start: expected finite"),
        ({"duration": 0.0}, "duration must be a finite number > 0"),
        ({"duration": -1.0}, "duration must be a finite number > 0"),
        ({"t": [0.0, np.nan]}, "t must be a finite"),
    ],
)
def test_bad_input(kwargs, match):
    args = {"q_start": Q0, "q_end": Q1, "duration": 1.0, "t": [0.0, 0.5]} | kwargs
    with pytest.raises(ConfigError, match=match) as info:
        quintic_trajectory(**args)
    assert "\n" not in str(info.value)
