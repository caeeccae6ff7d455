"""Robot flange simulator: exact second-order dynamics, Table IV open loop, resonance, seeds."""

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.profiler.loop.control import OpenLoop
from posekit.profiler.loop.loop_sim import simulate_impulse, simulate_step, table4
from posekit.profiler.loop.response import impulse_resonance, peak_frequency_magnitude
from posekit.profiler.loop.robotsim import GP12_LINEAR, RobotSimulator

# Table IV, open loop (paper §IV-C): Mp (%) mean and std, zeta mean and std, 1 mm and 2 mm steps.
TABLE4_OPEN = {
    ("x", 1.0): (5.39, 1.34, 0.68, 0.03), ("x", 2.0): (4.86, 1.22, 0.70, 0.03),
    ("y", 1.0): (65.88, 2.27, 0.13, 0.01), ("y", 2.0): (39.48, 2.69, 0.28, 0.02),
    ("z", 1.0): (13.98, 0.91, 0.53, 0.01), ("z", 2.0): (8.06, 1.03, 0.63, 0.02),
}
T = 0.012


def analytic_step(t, zeta, f_n):
    """Unit step response of w²/(s² + 2ζws + w²), underdamped."""
    w = 2 * np.pi * f_n
    s, wd = zeta * w, w * np.sqrt(1 - zeta ** 2)
    return 1 - np.exp(-s * t) * (np.cos(wd * t) + s / wd * np.sin(wd * t))


def test_step_is_the_exact_second_order_response():
    robot = RobotSimulator()
    ends, inside = [], []
    for _ in range(40):
        ends.append(robot.step([1.0, 1.0, 1.0]))
        inside.append(robot.position_at(robot.time_s - np.array([0.009, 0.004, 0.0])))
    t_end = T * np.arange(1, 41)
    t_in = (t_end[:, None] - np.array([0.009, 0.004, 0.0])).ravel()
    for i, z in enumerate(GP12_LINEAR.zeta):
        np.testing.assert_allclose(np.array(ends)[:, i], analytic_step(t_end, z, 10.0), atol=1e-12)
        np.testing.assert_allclose(np.concatenate(inside)[:, i], analytic_step(t_in, z, 10.0), atol=1e-12)


def test_closed_form_transition_covers_overdamped_and_critical():
    from scipy.linalg import expm
    for z in (1.0, 1.6):
        robot = RobotSimulator(zeta=z, f_n_hz=7.0)
        w = 2 * np.pi * 7.0
        A = np.array([[0, 1], [-w * w, -2 * z * w]])
        phi = robot._phi(np.array([0.003, 0.012]))
        np.testing.assert_allclose(phi[1, 0], expm(A * 0.012), atol=1e-12)
        np.testing.assert_allclose(phi[0, 2], expm(A * 0.003), atol=1e-12)


def test_nonlinear_integrator_agrees_with_exact_linear_propagation():
    lin = RobotSimulator(zeta=0.2)
    nl = RobotSimulator(zeta=0.2, damping_gain=1e-12)          # RK4 path, negligible nonlinearity
    assert nl.nonlinear and not lin.nonlinear
    for k in range(30):
        u = [1.0, -2.0, 0.5] if k < 15 else [0.0, 0.0, 0.0]
        np.testing.assert_allclose(nl.step(u), lin.step(u), atol=1e-7)      # RK4, h = 0.5 ms
    np.testing.assert_allclose(nl.position_at(nl.time_s - 0.005), lin.position_at(lin.time_s - 0.005), atol=1e-7)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_open_loop_1mm_matches_table4(axis):
    runs = [simulate_step(axis, 1.0, OpenLoop(), seed=s) for s in range(4)]
    (row,) = table4(runs)
    mp, mp_std, zeta, zeta_std = TABLE4_OPEN[(axis, 1.0)]
    assert row["Mp_pct"] == pytest.approx(mp, abs=mp_std)
    assert row["zeta"] == pytest.approx(zeta, abs=max(zeta_std, 0.01))
    assert row["mode"] == "open" and row["n"] == 4


@pytest.mark.parametrize("step", [1.0, 2.0])
@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_nonlinear_model_matches_table4_at_both_step_sizes(axis, step):
    robot = RobotSimulator.gp12(nonlinear=True)
    m = simulate_step(axis, step, OpenLoop(), robot=robot, seed=0).metrics("truth")[axis]
    mp, mp_std, zeta, zeta_std = TABLE4_OPEN[(axis, step)]
    assert m["Mp_pct"] == pytest.approx(mp, abs=0.3 * mp_std)
    assert m["zeta"] == pytest.approx(zeta, abs=zeta_std)


def test_open_loop_y_spectrum_peaks_at_the_10hz_mode():
    r = simulate_step("y", 1.0, OpenLoop(), seed=0)
    m = r.metrics("measured", band_hz=(3.0, 30.0))["y"]
    assert m["f_peak_hz"] == pytest.approx(10.0, abs=1.0)
    # the same peak in the 250 Hz ground truth ("VICON")
    f, _ = peak_frequency_magnitude(r.t_truth_s, r.truth_mm[:, 1], y_final_mm=1.0, t_start_s=0.2,
                                    band_hz=(3.0, 30.0))
    assert f == pytest.approx(10.0, abs=1.0)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_impulse_response_finds_the_10hz_resonance(axis):
    r = simulate_impulse(axis, 0.5, seed=3)
    i = "xyz".index(axis)
    res = impulse_resonance(r.t_s, r.measured_mm[:, i], t_free_s=r.t_step_s + T)
    assert res["f_natural_hz"] == pytest.approx(10.0, abs=1.0)
    truth = impulse_resonance(r.t_truth_s, r.truth_mm[:, i], t_free_s=r.t_step_s + T)
    assert truth["f_natural_hz"] == pytest.approx(10.0, abs=1e-3)
    assert truth["zeta"] == pytest.approx(GP12_LINEAR.zeta[i], abs=1e-3)
    if axis == "y":                      # lightly damped: the spectrum itself peaks at the mode
        assert truth["f_peak_hz"] == pytest.approx(10.0, abs=1.0)


def test_same_seed_same_run_and_process_noise():
    def run(seed):
        robot = RobotSimulator(process_noise_um=2.0, seed=seed)
        return np.array([robot.step([0.1 * k, 0.0, 0.0]) for k in range(20)])
    np.testing.assert_array_equal(run(7), run(7))
    assert not np.allclose(run(7), run(8))
    a = simulate_step("xyz", 1.0, OpenLoop(), seed=5, robot=RobotSimulator(process_noise_um=1.0))
    b = simulate_step("xyz", 1.0, OpenLoop(), seed=5, robot=RobotSimulator(process_noise_um=1.0))
    np.testing.assert_array_equal(a.measured_mm, b.measured_mm)
    np.testing.assert_array_equal(a.truth_mm, b.truth_mm)


def test_truth_log_is_250hz_and_matches_the_cycle_samples():
    r = simulate_step("z", 1.0, OpenLoop(), seed=0, duration_s=0.6)
    np.testing.assert_allclose(np.diff(r.t_truth_s), 0.004)
    # every third 250 Hz sample is a cycle start
    np.testing.assert_allclose(r.truth_mm[: 3 * len(r.t_s):3], r.position_mm, atol=1e-12)


def test_reset_and_state_accessors():
    robot = RobotSimulator(x0_mm=[1.0, 2.0, 3.0])
    np.testing.assert_array_equal(robot.position_at(0.0), [1.0, 2.0, 3.0])
    robot.step([2.0, 2.0, 3.0])
    assert robot.time_s == pytest.approx(T) and robot.cycle == 1
    assert robot.velocity_mm_s[0] > 0
    robot.reset()
    assert robot.time_s == 0.0
    np.testing.assert_array_equal(robot.position_mm, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(robot.velocity_mm_s, 0.0)


def test_bad_input():
    with pytest.raises(ConfigError, match="zeta must be > 0"):
        RobotSimulator(zeta=(0.5, 0.0, 0.5))
    with pytest.raises(ConfigError, match="f_n_hz must be a finite scalar or 3 values"):
        RobotSimulator(f_n_hz=(10.0, 10.0))
    with pytest.raises(ConfigError, match="period_s must be > 0"):
        RobotSimulator(period_s=0.0)
    with pytest.raises(ConfigError, match="x0_mm must be 3 finite values"):
        RobotSimulator(x0_mm=[0.0, np.nan, 0.0])
    with pytest.raises(ConfigError, match="damping_gain must be >= 0"):
        RobotSimulator(damping_gain=-1.0)
    robot = RobotSimulator()
    with pytest.raises(ConfigError, match="command_mm must be 3 finite values"):
        robot.step([1.0, 2.0])
    robot.step([0.0, 0.0, 0.0])
    with pytest.raises(ConfigError, match=r"times must lie in the last cycle \[0.000000, 0.012000\]"):
        robot.position_at(0.02)
    with pytest.raises(ConfigError, match="axis must be one of"):
        simulate_step("w", 1.0, OpenLoop())
    with pytest.raises(ConfigError, match="at least one cycle into the run"):
        simulate_step("x", 1.0, OpenLoop(), t_step_s=0.0)
