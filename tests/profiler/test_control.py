"""PD compensation, step-response metrics, and the closed loop of Table IV."""

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.profiler.loop.control import DEFAULT_KD, DEFAULT_KP, OpenLoop, PDController
from posekit.profiler.loop.loop_sim import format_table4, run_table4, simulate_step, table4
from posekit.profiler.loop.response import (
    amplitude_spectrum,
    damping_ratio,
    overshoot_pct,
    peak_frequency_magnitude,
    settling_time,
    step_metrics,
    zeta_from_overshoot,
)
from posekit.profiler.loop.robotsim import RobotSimulator

# Every (Mp %, zeta) pair of Table IV, open and closed loop, 1 mm and 2 mm.
TABLE4_MP_ZETA = [(5.39, 0.68), (4.86, 0.70), (65.88, 0.13), (39.48, 0.28), (13.98, 0.53), (8.06, 0.63),
                  (2.47, 0.76), (3.07, 0.74), (20.51, 0.45), (1.46, 0.81), (2.96, 0.75), (1.07, 0.82)]


def second_order_step(t, zeta, f_n=10.0):
    """Unit step response of w²/(s² + 2ζws + w²) for any ζ > 0 (complex ω_d covers ζ > 1)."""
    w = 2 * np.pi * f_n
    s, wd = zeta * w, w * np.sqrt(1 - zeta ** 2 + 0j)
    return (1 - np.exp(-s * t) * (np.cos(wd * t) + s * t * np.sinc(wd * t / np.pi))).real


# ----------------------------------------------------------------------------- metrics
@pytest.mark.parametrize("mp, zeta", TABLE4_MP_ZETA)
def test_table4_zeta_is_the_overshoot_formula(mp, zeta):
    assert zeta_from_overshoot(mp) == pytest.approx(zeta, abs=0.01)


@pytest.mark.parametrize("zeta", [0.1, 0.13, 0.3, 0.53, 0.68, 0.9])
def test_metrics_of_analytic_second_order_steps(zeta):
    t = np.arange(0.0, 3.0, 1e-4)
    y = 2.0 * second_order_step(t, zeta)                       # a 2 mm step at t = 0
    mp_exact = 100 * np.exp(-np.pi * zeta / np.sqrt(1 - zeta ** 2))
    assert overshoot_pct(t, y, 0.0, 2.0) == pytest.approx(mp_exact, abs=1e-3)   # 0.1 ms sampling
    assert damping_ratio(t, y, 0.0, 2.0) == pytest.approx(zeta, abs=1e-4)
    m = step_metrics(t, y, 2.0, y0_mm=0.0)
    assert m["Mp_pct"] == pytest.approx(mp_exact, abs=1e-3)
    assert m["zeta"] == pytest.approx(zeta, abs=1e-4)
    # 2 % settling of the envelope: ~ -ln(0.02 sqrt(1-ζ²)) / (ζ w), never later
    assert 0 < m["settling_s"] <= -np.log(0.02 * np.sqrt(1 - zeta ** 2)) / (zeta * 2 * np.pi * 10) + 1e-3
    if zeta < 0.6:                                             # a measurable undershoot
        assert damping_ratio(t, y, 0.0, 2.0, method="logdec") == pytest.approx(zeta, abs=2e-3)


def test_metrics_without_overshoot_report_zeta_one():
    t = np.arange(0.0, 2.0, 1e-3)
    for zeta in (1.0, 1.5):
        y = 5.0 - 1.0 * second_order_step(t, zeta)            # a downward step 5 → 4 mm
        assert overshoot_pct(t, y, 5.0, 4.0) == 0.0
        assert damping_ratio(t, y, 5.0, 4.0) == 1.0
        assert damping_ratio(t, y, 5.0, 4.0, method="logdec") == 1.0
    assert zeta_from_overshoot(0.0) == 1.0
    assert zeta_from_overshoot(100.0) == 0.0                   # a sustained oscillation


@pytest.mark.parametrize("f_hz, fs_hz", [(10.0, 1000 / 12), (10.37, 1000 / 12), (9.2, 250.0)])
def test_mf_of_a_pure_sinusoid_is_its_amplitude(f_hz, fs_hz):
    t = np.arange(0.0, 1.5, 1 / fs_hz)
    y = 3.0 + 0.025 * np.sin(2 * np.pi * f_hz * t + 0.7)      # 25 µm about 3 mm
    f, mf = peak_frequency_magnitude(t, y, window_s=None)
    assert f == pytest.approx(f_hz, abs=0.1)
    assert mf == pytest.approx(25.0, rel=0.03)
    # the same over a nominal 1 s window fully covered by the record
    assert peak_frequency_magnitude(t, y, window_s=1.0)[1] == pytest.approx(25.0, rel=0.05)


def test_mf_of_a_step_measures_the_oscillation_about_the_target():
    t = np.arange(0.0, 1.5, 0.004)
    m_ringing = step_metrics(t, second_order_step(t, 0.13), 1.0)
    m_smooth = step_metrics(t, second_order_step(t, 1.0), 1.0)
    assert m_ringing["f_peak_hz"] == pytest.approx(10.0, abs=0.5)
    assert m_ringing["Mf_um"] > 50 * m_smooth["Mf_um"]
    assert m_smooth["Mf_um"] < 1.0                             # no window-edge leakage of the step


def test_metric_bad_input():
    t = np.arange(0.0, 1.0, 0.01)
    with pytest.raises(ConfigError, match="must differ from y0_mm"):
        overshoot_pct(t, t, 1.0, 1.0)
    with pytest.raises(ConfigError, match="same length >= 4"):
        step_metrics(t, t[:-1], 1.0)
    with pytest.raises(ConfigError, match="strictly increasing"):
        settling_time(t[::-1], t, 0.0, 1.0)
    with pytest.raises(ConfigError, match="uniformly sampled"):
        amplitude_spectrum(t ** 2 + t, t)
    with pytest.raises(ConfigError, match="above the Nyquist frequency"):
        peak_frequency_magnitude(t, np.sin(t), band_hz=(60.0, 80.0))
    with pytest.raises(ConfigError, match="method must be 'overshoot' or 'logdec'"):
        damping_ratio(t, t, 0.0, 1.0, method="fit")


# ---------------------------------------------------------------------------- controllers
def test_pd_follows_its_formula_with_saturation_and_timing():
    kp, kd, T = np.array([0.5, -0.2, 1.0]), np.array([0.01, 0.0, 0.002]), 0.012
    limit = np.array([10.0, 10.0, 0.015])
    pd = PDController(kp=kp, kd=kd, period_s=T, limit_mm=limit)
    r = np.array([1.0, 2.0, 3.0])
    y0, y1 = np.array([0.0, 0.5, 2.99]), np.array([0.4, 1.0, 2.98])
    e0, e1 = r - y0, r - y1
    u0 = pd(0.0, r, y0)                                        # first call: no derivative yet
    np.testing.assert_allclose(u0, r + kp * e0)
    u1 = pd(2 * T, r, y1)                                      # a skipped cycle: Δt = 2T
    c1 = kp * e1 + kd * (e1 - e0) / (2 * T)
    assert abs(c1[2]) > limit[2]                               # z saturates
    np.testing.assert_allclose(u1, r + np.clip(c1, -limit, limit))
    np.testing.assert_allclose(pd.last_correction_mm, u1 - r)


def test_pd_missing_measurement_falls_back_to_open_loop_without_kick():
    pd = PDController(kp=0.0, kd=0.01)
    r = np.zeros(3)
    pd(0.0, r, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(pd(0.012, r, [np.nan, 0.0, 0.0]), r)
    np.testing.assert_array_equal(pd(0.024, r, None), r)
    np.testing.assert_array_equal(pd(0.036, r, [1.0, 1.0, 1.0]), r)       # derivative restarted
    assert pd(0.048, r, [1.0, 1.0, 1.0]).tolist() == [0.0, 0.0, 0.0]


def test_filtered_derivative_is_a_first_order_lag_of_the_raw_one():
    T, fc = 0.012, 5.0
    raw = PDController(kp=0.0, kd=1.0, limit_mm=1e6)
    filt = PDController(kp=0.0, kd=1.0, limit_mm=1e6, derivative_filter_hz=fc)
    a = 1 / (2 * np.pi * fc) / (1 / (2 * np.pi * fc) + T)
    d_expected = 0.0
    for k in range(60):                                        # a ramp of the error: slope -2 mm/s
        y = np.full(3, 2.0 * k * T)
        d_raw = raw(k * T, np.zeros(3), y)[0]
        d = filt(k * T, np.zeros(3), y)[0]
        if k >= 1:
            d_expected = a * d_expected + (1 - a) * d_raw
            assert d == pytest.approx(d_expected, rel=1e-12)
    assert d == pytest.approx(-2.0, rel=1e-3)


def test_open_loop_passes_the_reference_through():
    ol = OpenLoop()
    r = np.array([1.0, 2.0, 3.0])
    u = ol(0.0, r, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(u, r)
    assert u is not r and ol.mode == "open" and PDController.mode == "closed"
    ol.reset()


def test_controller_bad_input():
    with pytest.raises(ConfigError, match="kp must be a finite scalar or 3 values"):
        PDController(kp=[1.0, 2.0])
    with pytest.raises(ConfigError, match="limit_mm must be > 0"):
        PDController(limit_mm=0.0)
    with pytest.raises(ConfigError, match="derivative_filter_hz must be > 0 or None"):
        PDController(derivative_filter_hz=-1.0)
    with pytest.raises(ConfigError, match="reference_mm must be 3 finite values"):
        PDController()(0.0, [1.0, 2.0], [0.0, 0.0, 0.0])
    with pytest.raises(ConfigError, match="measured_mm must be 3 values"):
        PDController()(0.0, [1.0, 2.0, 3.0], [0.0, 0.0])


# ------------------------------------------------------------------------ closed loop
@pytest.mark.parametrize("nonlinear", [False, True])
def test_default_pd_improves_every_metric_like_table4(nonlinear):
    results = run_table4({"open": OpenLoop(), "closed": PDController()}, seeds=range(3),
                         robot_factory=lambda: RobotSimulator.gp12(nonlinear=nonlinear))
    rows = {(r["axis"], r["component"], r["step_mm"], r["mode"]): r for r in table4(results)}
    assert len(rows) == 2 * 2 * (3 + 3)
    for (axis, comp, step, mode), closed in rows.items():
        if mode != "closed":
            continue
        opened = rows[(axis, comp, step, "open")]
        where = f"{axis}:{comp} {step} mm"
        assert closed["Mp_pct"] < 0.5 * opened["Mp_pct"], where
        assert closed["zeta"] > opened["zeta"] + 0.05, where
        assert closed["Mf_um"] < 0.75 * opened["Mf_um"], where
    assert "improv." in format_table4(table4(results))


def test_default_gains_are_what_the_docs_say():
    pd = PDController()
    np.testing.assert_array_equal(pd.kp, DEFAULT_KP)
    np.testing.assert_array_equal(pd.kd, DEFAULT_KD)
    assert np.all((-1 < pd.kp) & (pd.kp < 0))


def test_closed_loop_is_deterministic_with_a_seed_and_noise_matters():
    a = simulate_step("xyz", 2.0, PDController(), seed=11)
    b = simulate_step("xyz", 2.0, PDController(), seed=11)
    c = simulate_step("xyz", 2.0, PDController(), seed=12)
    for name in ("position_mm", "command_mm", "measured_mm", "truth_mm"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.command_mm, c.command_mm)


def test_loop_timing_uses_the_previous_cycles_scan():
    seen = []

    class Spy(OpenLoop):
        def __call__(self, t_s, reference_mm, measured_mm=None):
            seen.append(np.array(measured_mm))
            return super().__call__(t_s, reference_mm, measured_mm)

    r = simulate_step("x", 1.0, Spy(), seed=0, duration_s=0.3, delay_cycles=1)
    np.testing.assert_array_equal(np.array(seen[1:]), r.measured_mm[:-1])
    seen.clear()
    r = simulate_step("x", 1.0, Spy(), seed=0, duration_s=0.3, delay_cycles=0)
    np.testing.assert_array_equal(np.array(seen), r.measured_mm)


def test_custom_measurement_and_failed_estimates():
    def measure(t_s, position_mm, rng):
        return np.full(3, np.nan) if 0.3 < t_s < 0.34 else position_mm
    r = simulate_step("y", 1.0, PDController(), measurement=measure, seed=0)
    assert np.isnan(r.measured_mm).any()
    m = r.metrics("measured")["y"]                             # NaN samples are dropped
    assert m["Mp_pct"] < 10.0
