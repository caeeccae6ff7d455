"""The laser likelihood's variance per sensor, ``σ² + min(c Var_w(e), cap σ²)`` (engine/filter.py):
checked against in-plane errors computed here with NumPy (the plane through each particle's sensor,
crossed with the seam polyline) and the robot-density weights; the measurement model of the
integrity test keeps ``σ``."""

import math

import numpy as np
import pytest

from posekit.geometry import se3_exp
from posekit.seam.engine.densities import robot_loglik, robot_measurement
from posekit.seam.engine.filter import SeamParticleFilter, StepInputs
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.frontend.config import config_from_dict
from posekit.seam.frontend.trajectories import nominal_trajectory

SIGMA = 0.05  # mm
OFFSET = np.array([0.3, 0.2, -0.2, 0.001, 0.0, 0.002])  # truth from nominal, tool frame (mm, rad)


def _setup(inflation=0.5):
    cfg = config_from_dict({"trajectory": {"kind": "line", "steps": 20},
                            "sensors": {"count": 2, "distances_mm": [20.0, 100.0]},
                            "filter": {"particles": 400, "laser_sigma_mm": SIGMA, "laser_inflation": inflation}})
    nt = nominal_trajectory(cfg.trajectory, cfg.robot)
    pf = SeamParticleFilter(cfg, nt.seam, 3, T_init=nt.T_nominal[5])
    seam = SeamLine(nt.seam)
    truth = nt.T_nominal[5] @ se3_exp(OFFSET)
    laser = np.empty((2, 2))
    for i, d in enumerate(cfg.sensors.resolved_distances_mm()):
        o = truth[:3, 3] + d * truth[:3, 1]
        e = seam.intersect(o[None], truth[None, :3, 1]).point[0] - o
        laser[i] = e @ truth[:3, 0], e @ truth[:3, 2]
    inputs = StepInputs(np.eye(4), nt.T_nominal[5], nt.q[5], np.zeros(3), laser)
    f = cfg.filter
    deg = math.pi / 180.0
    meas = robot_measurement(pf.chain, nt.q[5], np.zeros(3), joint_sigma_rad=f.joint_sigma_deg * deg,
                             floor_t_mm=f.robot_floor_t_mm, floor_r_rad=f.robot_floor_r_deg * deg, d0_mm=f.d0_mm,
                             kd_mm_per_n=f.kd_mm_per_n, d0_rad=f.d0_deg * deg, kd_rad_per_n=f.kd_deg_per_n * deg,
                             bending=f.bending_plateau)
    return pf, seam, truth, inputs, meas


def _errors_numpy(T, seam, mount, m):
    """In-plane errors (N, 2) of particles T (N, 4, 4) for one reading m (2,), computed independently."""
    R = T[:, :3, :3] @ mount[:3, :3]
    o = T[:, :3, 3] + T[:, :3, :3] @ mount[:3, 3]
    m_hat = o + m[0] * R[:, :, 0] + m[1] * R[:, :, 2]
    p = seam.intersect(m_hat, R[:, :, 1]).point
    e = m_hat - p
    return np.c_[(e * R[:, :, 0]).sum(1), (e * R[:, :, 2]).sum(1)]


@pytest.mark.parametrize("spread_mm, capped", [(0.02, False), (1.0, True)])
def test_laser_variance_is_the_cloud_spread_of_the_errors_capped(spread_mm, capped):
    pf, seam, truth, inputs, meas = _setup()
    rng = np.random.default_rng(0)
    xi = rng.standard_normal((pf.n, 6)) * np.r_[[spread_mm] * 3, [spread_mm * 1e-3] * 3]
    T = np.stack([truth @ se3_exp(x) for x in xi])
    pf.logw = np.full(pf.n, -math.log(pf.n))
    ll, used, ll_robot, E = pf._loglik(T, inputs, meas, errors=True)
    assert used == 2
    w = np.exp(robot_loglik(T, meas) - robot_loglik(T, meas).max())
    w /= w.sum()
    expect_ll = ll_robot.copy()
    for i, mount in enumerate(pf.sensor_mounts):
        e = _errors_numpy(T, seam, mount, inputs.laser_mm[i])
        np.testing.assert_allclose(E[:, 2 * i:2 * i + 2], e, atol=1e-9)
        mu = w @ e
        v = 0.5 * float(w @ ((e - mu) ** 2).sum(1))
        s2 = SIGMA ** 2 + min(0.5 * v, 3.0 * SIGMA ** 2)
        assert (s2 == pytest.approx(SIGMA ** 2 * (1 + 3.0), rel=1e-12)) is capped
        assert pf._sig_eff[i] == pytest.approx(s2, rel=1e-9)
        expect_ll += -math.log(2 * math.pi * s2) - 0.5 * (e * e).sum(1) / s2
    np.testing.assert_allclose(ll, expect_ll, rtol=1e-9, atol=1e-9)


def test_the_integrity_test_keeps_the_laser_sigma():
    """The inflation changes the particle weights only: the innovation statistic (NIS) of a step is
    the same with and without it (it is computed before the lasers weight the cloud, with σ)."""
    pf, seam, truth, inputs, meas = _setup()
    nis_on = pf.step(inputs).nis
    pf2, *_ = _setup(inflation=0.0)
    assert pf2.step(inputs).nis == pytest.approx(nis_on, rel=1e-12)
    assert pf2._sig_eff == {}
