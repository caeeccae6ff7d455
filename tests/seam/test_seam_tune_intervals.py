"""Honest intervals of ``posekit seam tune`` without a reference (src/posekit/seam/frontend/tune_intervals.py):
the joint 1σ against the inverse of a known information matrix, the profile-likelihood interval of a latency
against the closed form, the verdict when the walk moves a latency, and the readings' rate."""

import math

import numpy as np
import pytest

from posekit.seam.frontend.tune_intervals import (
    CHI2_1_95,
    WALK_SCALE,
    LatencyInterval,
    joint_std,
    latency_interval,
    reading_rate_rms,
    uniform_rms,
)


def test_joint_std_is_the_inverse_information_not_the_conditional_curvature():
    """Two correlated parameters (correlation 0.9): the marginal 1σ is √(A⁻¹)ᵢᵢ, 2.3 times the conditional
    1/√Aᵢᵢ; the episodes' gradients are zero at the optimum, so the sandwich adds nothing."""
    C = np.array([[1.0, 0.9 * 0.5], [0.9 * 0.5, 0.25]])
    A = np.linalg.inv(C)

    def fe(x):
        return np.array([0.125 * x @ A @ x, 0.375 * x @ A @ x])

    std = joint_std(fe, np.zeros(2), np.array([1e-3, 1e-3]), [0, 1])
    assert std == pytest.approx(np.sqrt(np.diag(C)), rel=1e-4)
    assert std[0] > 2.0 / math.sqrt(A[0, 0])
    # a held parameter gets no 1σ; a flat direction leaves its parameters unpinned
    assert np.isinf(joint_std(fe, np.zeros(2), np.array([1e-3, 1e-3]), [0])[1])
    flat = joint_std(lambda x: np.array([0.5 * (x[0] + x[1]) ** 2]), np.zeros(2), np.array([1e-3, 1e-3]), [0, 1])
    assert np.all(np.isinf(flat))


def test_joint_std_takes_the_episodes_disagreement_when_it_is_larger():
    """Two episodes with optima at ±1 (curvature 1 each): the curvature says 1/√2, their gradients at the pooled
    optimum (±1) say √2 / 2 = 0.71 too; with optima at ±3 the sandwich's 3/√2 = 2.1 wins."""
    for c, want in ((1.0, 1.0 / math.sqrt(2.0)), (3.0, 3.0 / math.sqrt(2.0))):
        std = joint_std(lambda x, c=c: np.array([0.5 * (x[0] - c) ** 2, 0.5 * (x[0] + c) ** 2]), np.zeros(1),
                        np.array([1e-3]), [0])
        assert std[0] == pytest.approx(want, rel=1e-4)


def _quadratic(centre_of_walk, s=0.002):
    """A likelihood ``x = (latency, log walk, log noise)``: the latency a Gaussian of 1σ ``s`` about
    ``centre_of_walk(log walk)``, the walk a Gaussian about 0 (1σ 0.1), the noise about 0 (1σ 0.1)."""
    def f(x):
        if x[0] < 0.0 or x[0] > 0.2:
            return np.inf
        return 0.5 * ((x[0] - centre_of_walk(x[1])) / s) ** 2 + 0.5 * (x[1] / 0.1) ** 2 + 0.5 * (x[2] / 0.1) ** 2
    return f


def test_a_latency_the_likelihood_pins_gets_the_likelihood_ratio_interval():
    """Not confounded: the profile is ½((L - 20 ms)/2 ms)², so the 95 % interval is 20 ± 1.96 × 2 ms under
    both walks, and it is pinned."""
    f = _quadratic(lambda lw: 0.020)
    x = np.array([0.020, 0.0, 0.0])
    iv = latency_interval(f, x, 0, [0], [1], bisect=6)
    half = math.sqrt(CHI2_1_95) * 0.002
    for lo, hi in iv.by_walk.values():
        assert lo == pytest.approx(0.020 - half, abs=2e-4) and hi == pytest.approx(0.020 + half, abs=2e-4)
    assert iv.pinned and iv.reason == "" and iv.std == pytest.approx(0.002, rel=0.1)


def test_a_latency_the_walk_moves_is_not_pinned_and_the_reason_says_so():
    """Confounded: the latency the data favour is 10 ms + 5 ms × log(walk): 10 ms as fitted, 21.5 ms with the walk
    ten times larger. The two intervals (± 2 ms each) do not overlap: not pinned, the union reported."""
    f = _quadratic(lambda lw: 0.010 + 0.005 * lw, s=0.001)
    iv = latency_interval(f, np.array([0.010, 0.0, 0.0]), 0, [0], [1], bisect=6)
    shifted = 0.010 + 0.005 * math.log(WALK_SCALE)
    half = math.sqrt(CHI2_1_95) * 0.001
    assert iv.by_walk[1.0] == pytest.approx((0.010 - half, 0.010 + half), abs=2e-4)
    assert iv.by_walk[WALK_SCALE] == pytest.approx((shifted - half, shifted + half), abs=2e-4)
    assert (iv.lo, iv.hi) == pytest.approx((0.010 - half, shifted + half), abs=2e-4)
    assert not iv.pinned
    assert "confounded with the lateral and yaw walk" in iv.reason and "wider than ±5 ms" in iv.reason


def test_a_latency_at_zero_is_not_pinned():
    f = _quadratic(lambda lw: 0.0)
    iv = latency_interval(f, np.zeros(3), 0, [0], [1])
    assert iv.lo == 0.0 and not iv.pinned and "touches 0" in iv.reason


class _Ep:
    def __init__(self, laser, t):
        self.laser = laser

        class D:
            time_s = t
        self.data = D()


def test_reading_rate_is_the_derivative_s_rms():
    """Readings ``a sin(ω t)`` (and a second sensor twice as fast): rms rate a ω / √2, NaN dropouts skipped."""
    t = np.arange(0.0, 4.0, 0.01)
    w = 2.0 * math.pi * 0.25
    laser = np.zeros((t.size, 2, 2))
    laser[:, 0, 0] = 3.0 * np.sin(w * t)
    laser[:, 1, 0] = 3.0 * np.sin(2.0 * w * t)
    laser[::37, 0] = np.nan
    got = reading_rate_rms([_Ep(laser, t)], 0)
    assert got == pytest.approx(3.0 * w / math.sqrt(2.0), rel=0.02)
    assert reading_rate_rms([_Ep(laser, t)], 1) == pytest.approx(2.0 * got, rel=0.03)
    assert uniform_rms(0.0, 0.02) == pytest.approx(0.02 / math.sqrt(3.0))
    assert uniform_rms(-0.01, 0.01) == pytest.approx(0.02 / math.sqrt(12.0))


def test_a_latency_that_moves_with_an_unpinned_one_carries_its_range():
    """Sensor 2's own interval is 15-16 ms, but along sensor 1's unpinned 0-21 ms it takes 15.3-20 ms: its interval
    becomes 15-20 ms (still pinned: ±2.5 ms), then 9.5-20 ms is wider than ±5 ms and it is not pinned."""
    iv = LatencyInterval(
        {1.0: (0.015, 0.016), WALK_SCALE: (0.0152, 0.0158)}, {}, 0.05)
    assert iv.pinned
    assert iv.carry(0.0153, 0.020, "along sensors[0]'s unpinned latency")
    assert (iv.lo, iv.hi) == (0.015, 0.020) and iv.pinned
    assert not iv.carry(0.016, 0.019, "inside")
    assert iv.carry(0.0095, 0.020, "along sensors[0]'s unpinned latency it is 9.5-20 ms")
    assert not iv.pinned and "wider than ±5 ms" in iv.reason and "it is 9.5-20 ms" in iv.reason
