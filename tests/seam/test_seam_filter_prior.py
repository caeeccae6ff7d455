"""The filter's prior and transition width (issue 15): the first cloud drawn from the robot density
(uniform plateau + tails, offset by init_offset), the transition width from the force rate (paper
eq. 3, f-dot) or its magnitude, and no worse than kinematics without a laser reading."""

import math

import numpy as np
import pytest

from posekit.geometry import rotation_vector_from_matrix
from posekit.seam.engine import filter as filt
from posekit.seam.engine.densities import RobotMeasurement
from posekit.seam.engine.filter import SeamParticleFilter, StepInputs
from posekit.seam.frontend.config import config_from_dict
from posekit.seam.frontend.trajectories import nominal_trajectory


def _pf(n=4000, sensors=0, **f):
    cfg = config_from_dict({"trajectory": {"kind": "line", "steps": 20},
                            "sensors": {"count": sensors, "distances_mm": [20.0, 40.0][:sensors]},
                            "filter": {"particles": n, **f}})
    nt = nominal_trajectory(cfg.trajectory, cfg.robot)
    return cfg, nt, SeamParticleFilter(cfg, nt.seam, 0, T_init=nt.T_nominal[0])


def test_first_cloud_fills_the_robot_plateau():
    _, _, pf = _pf(init_offset_mm=(0.0, 0.0, 0.0))
    mu = np.eye(4)
    mu[:3, 3] = [400.0, 10.0, -5.0]
    meas = RobotMeasurement(mu, 1e-6 * np.eye(3), 1e-12 * np.eye(3), 2.0, 0.01)
    T = pf._draw_from_robot(meas)
    r = np.linalg.norm(T[:, :3, 3] - mu[:3, 3], axis=1)
    # a uniform ball of radius 2 (tails 1 µm): all inside, a fraction (1/2)^3 inside radius 1
    assert r.max() <= 2.0 + 1e-2
    assert np.mean(r < 1.0) == pytest.approx(0.125, abs=0.02)
    np.testing.assert_allclose(T[:, :3, 3].mean(0), mu[:3, 3], atol=0.05)
    ang = np.linalg.norm(rotation_vector_from_matrix(T[:, :3, :3]), axis=1)
    assert ang.max() <= 0.01 + 1e-5 and np.mean(ang < 0.005) == pytest.approx(0.125, abs=0.02)


def test_init_offset_moves_the_first_cloud():
    _, _, pf = _pf(init_offset_mm=(3.0, 0.0, 0.0), init_offset_deg=(0.0, 0.0, 2.0))
    meas = RobotMeasurement(np.eye(4), 1e-6 * np.eye(3), 1e-12 * np.eye(3), 0.5, 0.001)
    T = pf._draw_from_robot(meas)
    np.testing.assert_allclose(T[:, :3, 3].mean(0), [3.0, 0.0, 0.0], atol=0.02)
    rv = rotation_vector_from_matrix(T[:, :3, :3]).mean(0)
    np.testing.assert_allclose(rv, [0.0, 0.0, math.radians(2.0)], atol=2e-4)


@pytest.fixture
def transition_widths(monkeypatch):
    """The ``(sigma_t (3,), sigma_r (3,))`` each filter step passes to the transition (mm, rad), in order."""
    seen = []
    real = filt.transition

    def spy(Ts, inc, st, sr, rng, **kw):
        seen.append((np.broadcast_to(st, 3).copy(), np.broadcast_to(sr, 3).copy()))
        return real(Ts, inc, st, sr, rng, **kw)

    monkeypatch.setattr(filt, "transition", spy)
    return seen


_ISOTROPIC = {"axis_scale_t": (1.0, 1.0, 1.0), "axis_scale_r": (1.0, 1.0, 1.0),
              "load_axis_scale_t": (1.0, 1.0, 1.0), "load_axis_scale_r": (1.0, 1.0, 1.0)}


def _iso(widths):
    """``(sigma_t, sigma_r)`` pairs as the same width on all three axes, shape (K, 2, 3)."""
    return np.repeat(np.asarray(widths, dtype=np.float64)[..., None], 3, axis=-1)


@pytest.mark.parametrize("mode", ["rate", "magnitude"])
def test_transition_width_follows_the_force_rate_or_magnitude(mode, transition_widths):
    seen = transition_widths
    cfg, nt, pf = _pf(n=50, transition_force=mode, sigma_t_mm=0.01, sigma_r_deg=0.005, k_rate_t_mm_per_n=1e-3,
                      k_rate_r_deg_per_n=2e-3, k_force_t=1e-5, k_force_r=2e-5, force_rate_smoothing=0.0,
                      k_travel_t_mm_per_mm=0.0, k_travel_r_deg_per_mm=0.0, k_load_travel_t=0.0, k_load_travel_r=0.0,
                      **_ISOTROPIC)
    forces = [np.array([0.0, 0.0, -1000.0]), np.array([0.0, 0.0, -1000.0]), np.array([30.0, 0.0, -1040.0])]
    for k, f in enumerate(forces):
        inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
        pf.step(StepInputs(inc, nt.T_nominal[k], nt.q[k], f))
    deg = math.pi / 180
    if mode == "rate":  # |Δf| = 0, 0, 50 N
        expect = [(0.01, 0.005 * deg), (0.01, 0.005 * deg), (0.01 + 0.05, (0.005 + 0.1) * deg)]
    else:  # |f| = 1000, 1000, 1040.4 N
        fn = np.linalg.norm(forces[2])
        expect = [(0.02, 0.025 * deg)] * 2 + [(0.01 + 1e-5 * fn, (0.005 + 2e-5 * fn) * deg)]
    np.testing.assert_allclose(seen, _iso(expect), rtol=1e-12)


def test_transition_smoothed_rate_travel_and_reacquire_terms(transition_widths):
    # sigma = sigma0 + k_rate |EMA step of f| + travel (k_travel + k_load |f|), times reacquire_transition_scale
    # after a step that was not tracking
    seen = transition_widths
    cfg, nt, pf = _pf(n=50, sigma_t_mm=0.01, sigma_r_deg=0.005, k_rate_t_mm_per_n=1e-3, k_rate_r_deg_per_n=2e-3,
                      force_rate_smoothing=4.0, k_travel_t_mm_per_mm=0.02, k_travel_r_deg_per_mm=0.01,
                      k_load_travel_t=1e-6, k_load_travel_r=2e-7, reacquire_transition_scale=5.0, **_ISOTROPIC)
    forces = [np.array([0.0, 0.0, -1000.0]), np.array([0.0, 0.0, -1000.0]), np.array([30.0, 0.0, -1040.0])]
    travel = []
    for k, f in enumerate(forces):
        inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
        travel.append(np.linalg.norm(inc[:3, 3]))
        est = pf.step(StepInputs(inc, nt.T_nominal[k], nt.q[k], f))
        assert est.status == "tracking"  # no laser reading, the kinematic pose: nothing to contradict
    deg = math.pi / 180
    fn = [1000.0, 1000.0, np.linalg.norm(forces[2])]
    # the EMA moves by (f - f_prev) / (1 + 4): |(6, 0, -8)| = 10 N at the third step
    df = [0.0, 0.0, 10.0]
    expect = [(0.01 + 1e-3 * d + s * (0.02 + 1e-6 * n), (0.005 + 2e-3 * d + s * (0.01 + 2e-7 * n)) * deg)
              for d, s, n in zip(df, travel, fn)]
    np.testing.assert_allclose(seen, _iso(expect), rtol=1e-12)
    assert travel[1] > 0.1
    # a step that was not tracking widens the next transition five times (the EMA moves 8 N here)
    pf._last_status = "degraded"
    inc = nt.T_nominal[3] @ np.linalg.inv(nt.T_nominal[2])
    pf.step(StepInputs(inc, nt.T_nominal[3], nt.q[3], forces[2]))
    s3, n3 = np.linalg.norm(inc[:3, 3]), fn[2]
    np.testing.assert_allclose(seen[3], _iso([5.0 * (0.01 + 1e-3 * 8.0 + s3 * (0.02 + 1e-6 * n3)),
                                              5.0 * (0.005 + 2e-3 * 8.0 + s3 * (0.01 + 2e-7 * n3)) * deg]),
                               rtol=1e-12)


def test_transition_width_per_tool_axis(transition_widths):
    # filter.axis_scale_* multiply the unloaded width per tool axis, load_axis_scale_* the load's part
    # (k_load_travel_*); the bound runs the same walk; after a lost step the walk is isotropic (and
    # reacquire_transition_scale wider) for reacquire_isotropic_steps steps
    seen = transition_widths
    cfg, nt, pf = _pf(n=50, sigma_t_mm=0.01, sigma_r_deg=0.005, k_rate_t_mm_per_n=0.0, k_rate_r_deg_per_n=0.0,
                      k_travel_t_mm_per_mm=0.02, k_travel_r_deg_per_mm=0.01, k_load_travel_t=1e-6,
                      k_load_travel_r=2e-7, axis_scale_t=(0.5, 0.25, 2.0), axis_scale_r=(1.0, 0.0, 0.1),
                      load_axis_scale_t=(1.0, 3.0, 0.0), load_axis_scale_r=(0.5, 1.0, 2.0),
                      reacquire_isotropic_steps=2, reacquire_transition_scale=5.0, integrity_recovery=0)
    q_seen = []
    real = pf._bound.update

    def spy(T, meas, q_t, q_r, *a, **kw):
        q_seen.append((np.broadcast_to(q_t, 3).copy(), np.broadcast_to(q_r, 3).copy()))
        return real(T, meas, q_t, q_r, *a, **kw)

    pf._bound.update = spy
    force = np.array([0.0, 0.0, -1000.0])
    travel = []
    for k in range(6):
        inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
        travel.append(np.linalg.norm(inc[:3, 3]))
        if k == 2:
            # as a lost step leaves them (no degraded hold after it: integrity_recovery 0)
            pf._last_status, pf.integrity._since_lost = "lost", 0
        pf.step(StepInputs(inc, nt.T_nominal[k], nt.q[k], force))
        if k == 2:
            assert pf.integrity.since_lost == 1  # this step tracked (no laser to contradict): one step since the loss
    deg = math.pi / 180
    sc_t, sc_r = np.array([0.5, 0.25, 2.0]), np.array([1.0, 0.0, 0.1])
    lsc_t, lsc_r = np.array([1.0, 3.0, 0.0]), np.array([0.5, 1.0, 2.0])
    expect = []
    for k, s in enumerate(travel):
        base_t, base_r = 0.01 + 0.02 * s, (0.005 + 0.01 * s) * deg
        load_t, load_r = 1e-6 * 1000.0 * s, 2e-7 * 1000.0 * s * deg
        if k == 2:  # the step after a lost one: isotropic, five times wider
            expect.append([np.full(3, 5.0 * (base_t + load_t)), np.full(3, 5.0 * (base_r + load_r))])
        elif k == 3:  # within reacquire_isotropic_steps of the loss: isotropic
            expect.append([np.full(3, base_t + load_t), np.full(3, base_r + load_r)])
        else:
            expect.append([base_t * sc_t + load_t * lsc_t, base_r * sc_r + load_r * lsc_r])
    assert travel[1] > 0.1
    np.testing.assert_allclose(seen, expect, rtol=1e-12)
    np.testing.assert_allclose(q_seen, expect, rtol=1e-12)


def test_without_lasers_the_estimate_is_the_kinematic_pose():
    # the symmetric robot density's mean is its centre: no wandering inside the plateau
    cfg, nt, pf = _pf(n=200, sensors=0)
    for k in range(10):
        inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
        q = nt.q[k] + 1e-4
        est = pf.step(StepInputs(inc, nt.T_nominal[k], q, np.zeros(3)))
        np.testing.assert_allclose(est.T, est.T_kinematic, atol=1e-12)
        assert est.status == "tracking" and est.spread[0] > 0.5  # the plateau, not a point


def test_walk_adapts_to_the_innovations(monkeypatch):
    # covariance matching (filter.walk_adapt_*): per tracking step with readings the walk is multiplied by
    # exp(rate (a - walk_adapt_nis)), a the NIS per degree of freedom averaged over walk_adapt_window steps (one
    # step counts at most 3), within 1 .. walk_adapt_max times the configured width
    from posekit.seam.frontend.simulate import simulate_data

    data = simulate_data(config_from_dict({"trajectory": {"kind": "line", "steps": 60}}), 0)
    nt = data.nominal
    level = {"v": 1.5}
    real = filt.innovation_nis

    def nis(E, w, sigma):
        _, dof = real(E, w, sigma)
        return level["v"] * dof, dof

    monkeypatch.setattr(filt, "innovation_nis", nis)
    widths = []
    spy = filt.transition

    def record(Ts, inc, st, sr, rng, **kw):
        widths.append(np.r_[st, sr])
        return spy(Ts, inc, st, sr, rng, **kw)

    monkeypatch.setattr(filt, "transition", record)
    runs = {}
    for rate in (0.5, 0.0):
        cfg = config_from_dict({"trajectory": {"kind": "line", "steps": 60},
                                "filter": {"particles": 200, "walk_adapt_rate": rate, "walk_adapt_window": 4.0,
                                           "walk_adapt_max": 2.0}})
        pf = SeamParticleFilter(cfg, nt.seam, 0, T_init=nt.T_nominal[0])
        widths.clear()
        gains = []
        for k in range(60):
            level["v"] = 1.5 if k < 30 else (9.0 if k == 30 else 0.2)  # k = 30: one huge reading, then small ones
            inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
            est = pf.step(StepInputs(inc, nt.T_nominal[k], data.q_meas[k], data.force_meas_n[k], data.laser_mm[k]))
            assert est.status == "tracking"
            gains.append(pf._walk_gain)
        runs[rate] = (np.array(gains), np.array(widths))
    g, w = runs[0.5]
    a, expect = 1.0, []
    for k in range(60):
        x = 1.5 if k < 30 else (3.0 if k == 30 else 0.2)  # the huge reading counts 3
        a += (x - a) / 4.0
        expect.append(min(max((expect[-1] if expect else 1.0) * math.exp(0.5 * (a - 1.0)), 1.0), 2.0))
    np.testing.assert_allclose(g, expect, rtol=1e-12)
    assert g[:30].max() == 2.0 and g[-1] == 1.0  # capped at walk_adapt_max, never below the configured width
    g0, w0 = runs[0.0]
    assert (g0 == 1.0).all()  # off
    # the transition of step k is the configured one times the gain after step k - 1
    np.testing.assert_allclose(w[1:], w0[1:] * g[:-1, None], rtol=1e-12)
