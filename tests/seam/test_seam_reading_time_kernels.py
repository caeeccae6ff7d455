"""The compiled kernels of a reading's time and of the pose jitter a reading sees: the same bits as NumPy's
``interp`` and ``cross`` (the filter's steps must not change by being made faster), and the filter's history of
the program's joints that they read."""

import numpy as np
import pytest

from posekit.seam.engine._kernels import interp_columns, sensor_axes_levers
from posekit.seam.engine.filter import _HISTORY
from posekit.seam.engine.step import StepInputs
from tests.seam.test_seam_filter import config, make_filter, nominal_trajectory


def _xp(rng, n):
    xp = np.sort(rng.normal(size=n) * rng.choice([1e-3, 1.0, 300.0]))
    if rng.random() < 0.3:                       # repeated times
        xp[rng.integers(1, n)] = xp[rng.integers(0, n)]
        xp.sort()
    return xp


def test_interp_columns_is_numpy_s_interp_to_the_bit():
    rng = np.random.default_rng(7)
    for _ in range(3000):
        n = int(rng.integers(2, _HISTORY + 1))
        xp = _xp(rng, n)
        fp = rng.normal(size=(n, 7)) * rng.choice([1e-6, 1.0, 1e6])
        if rng.random() < 0.05:
            fp[rng.integers(0, n)] = rng.choice([np.inf, -np.inf])
        span = float(np.ptp(xp)) + 1.0
        for x in (xp[rng.integers(0, n)], xp[0], xp[-1], xp[0] - span, xp[-1] + span, rng.uniform(xp[0], xp[-1])):
            out = np.full(7, -1.0)
            assert interp_columns(float(x), xp, fp, out)
            want = np.array([np.interp(x, xp, fp[:, c]) for c in range(7)])
            np.testing.assert_array_equal(out, want)


def test_interp_columns_declines_times_that_go_back():
    out = np.full(2, -1.0)
    assert not interp_columns(0.5, np.array([0.0, 1.0, 0.5]), np.ones((3, 2)), out)
    assert np.all(out == -1.0)


def test_sensor_axes_and_levers_are_numpy_s_cross_to_the_bit():
    rng = np.random.default_rng(3)
    for _ in range(500):
        S = int(rng.integers(1, 5))
        M = rng.normal(size=(S, 4, 4)) * rng.choice([1e-3, 1.0, 1e4])
        axes, lever = np.empty((S, 2, 3)), np.empty((S, 2, 3))
        sensor_axes_levers(M, axes, lever)
        want = np.stack([M[:, :3, 0], M[:, :3, 2]], axis=1)
        np.testing.assert_array_equal(axes, want)
        np.testing.assert_array_equal(lever, np.cross(M[:, None, :3, 3], want))


def _filter_with_latency(latency_s):
    cfg = config({"trajectory": {"steps": 100}, "cell": {"sensors": {"count": 1, "latency_s": [latency_s]}}},
                 **{"profile.sensors": [{"latency_s": 0.0, "sigma_mm": 0.05, "angle_sigma_deg": 0.2}]})
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    return nt, make_filter(cfg, nt.seam, 0, T_init=nt.T_nominal[0])


def _inputs(nt, k, t):
    inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
    return StepInputs(inc, nt.T_nominal[k], nt.q[k], np.zeros(3), t, nt.q[k])


def test_the_filter_keeps_the_last_steps_joints_and_a_reading_older_than_them_takes_the_oldest():
    # 80 steps of 10 ms: the history holds the last 64 (0.63 s); a reading 1 s late is evaluated at the oldest
    nt, pf = _filter_with_latency(1.0)
    for k in range(80):
        inp = _inputs(nt, k, 0.01 * k)
        pf.step(inp)
    assert pf._hist_n == _HISTORY
    np.testing.assert_array_equal(pf._hist_t, 0.01 * np.arange(80 - _HISTORY, 80))
    np.testing.assert_array_equal(pf._hist_q, nt.q[80 - _HISTORY:80])
    want = np.linalg.inv(nt.T_nominal[79]) @ pf.chain.forward_kinematics(nt.q[80 - _HISTORY]) @ pf.mounts[0]
    np.testing.assert_allclose(pf._reading_mounts(inp)[0], want, atol=1e-9)
    pf.reset(nt.T_nominal[0])
    assert pf._hist_n == 0


@pytest.mark.parametrize("times", [[0.0, 0.01, 0.02, 0.015, 0.03], [0.0, 0.01, 0.01, 0.02, 0.03]],
                         ids=["going back", "repeated"])
def test_times_an_online_caller_sends_out_of_order_are_interpolated_as_numpy_does(times):
    nt, pf = _filter_with_latency(0.004)
    for k, t in enumerate(times):
        inp = _inputs(nt, k, t)
        pf.step(inp)
    xp, fp = np.asarray(times), nt.q[:len(times)]
    q = np.array([np.interp(times[-1] - 0.004, xp, fp[:, j]) for j in range(fp.shape[1])])
    want = np.linalg.inv(nt.T_nominal[len(times) - 1]) @ pf.chain.forward_kinematics(q) @ pf.mounts[0]
    np.testing.assert_allclose(pf._reading_mounts(inp)[0], want, rtol=0, atol=1e-12)
