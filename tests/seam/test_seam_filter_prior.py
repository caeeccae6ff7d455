"""The filter's prior and walk: the first cloud drawn from the robot density (uniform plateau + tails, moved by a
start offset), the walk the profile's per tool axis over the step's time and reacquire_walk_scale times wider
after a step that was not tracking, and the kinematic pose as the estimate before any laser reading."""

import math

import numpy as np
import pytest

from posekit.geometry import matrix_from_rotation_vector, rotation_vector_from_matrix, transform_from
from posekit.seam.engine import filter as filt
from posekit.seam.engine.densities import RobotMeasurement
from posekit.seam.engine.step import StepInputs
from posekit.seam.frontend.trajectories import nominal_trajectory
from tests.seam.helpers import config, make_filter


def _pf(n=4000, sensors=0, T_offset=None, **over):
    cfg = config({"trajectory": {"kind": "line", "steps": 20},
                  "cell": {"sensors": {"count": sensors, "distances_mm": [20.0, 40.0][:sensors]}},
                  "filter": {"particles": n}}, **over)
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    return cfg, nt, make_filter(cfg, nt.seam, 0, T_init=nt.T_nominal[0], T_offset=T_offset)


def test_first_cloud_fills_the_robot_plateau():
    _, _, pf = _pf()
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


def test_a_start_offset_moves_the_first_cloud():
    off = transform_from(matrix_from_rotation_vector(np.array([0.0, 0.0, math.radians(2.0)])), np.array([3.0, 0, 0]))
    _, _, pf = _pf(T_offset=off)
    meas = RobotMeasurement(np.eye(4), 1e-6 * np.eye(3), 1e-12 * np.eye(3), 0.5, 0.001)
    T = pf._draw_from_robot(meas)
    np.testing.assert_allclose(T[:, :3, 3].mean(0), [3.0, 0.0, 0.0], atol=0.02)
    rv = rotation_vector_from_matrix(T[:, :3, :3]).mean(0)
    np.testing.assert_allclose(rv, [0.0, 0.0, math.radians(2.0)], atol=2e-4)


def test_transition_width_is_the_walk_times_root_travel_and_wider_after_a_failed_step(monkeypatch):
    seen = []
    real = filt.transition

    def spy(Ts, inc, st, sr, rng, **kw):
        seen.append(np.r_[np.broadcast_to(st, 3), np.broadcast_to(sr, 3)])
        return real(Ts, inc, st, sr, rng, **kw)

    monkeypatch.setattr(filt, "transition", spy)
    walk = {"x_mm": 0.1, "y_mm": 0.2, "z_mm": 0.3, "rx_deg": 0.01, "ry_deg": 0.02, "rz_deg": 0.03}
    cfg, nt, pf = _pf(n=100, **{f"profile.walk.{k}": v for k, v in walk.items()},
                      **{"filter.reacquire_walk_scale": 4.0})
    w = np.r_[[walk[k] for k in ("x_mm", "y_mm", "z_mm")], np.radians([walk[k] for k in ("rx_deg", "ry_deg",
                                                                                          "rz_deg")])]
    expect = []
    for k in range(4):
        if k == 3:
            pf._last_status = "degraded"  # the last step's data did not agree with the model
        inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
        pf.step(StepInputs(inc, nt.T_nominal[k], nt.q[k], np.zeros(3), 0.01 * k, nt.q[k]))
        s = float(np.linalg.norm(inc[:3, 3]))
        expect.append((4.0 if k == 3 else 1.0) * w * math.sqrt(s))
    assert np.linalg.norm(inc[:3, 3]) > 0.3  # the line program travels 0.4 mm per step
    np.testing.assert_allclose(seen, expect, rtol=1e-9, atol=1e-15)


def test_without_lasers_the_estimate_is_the_kinematic_pose():
    # the symmetric robot density's mean is its centre: no wandering inside the plateau
    cfg, nt, pf = _pf(n=200, sensors=0)
    for k in range(10):
        inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
        est = pf.step(StepInputs(inc, nt.T_nominal[k], nt.q[k] + 1e-4, np.zeros(3), 0.01 * k, nt.q[k]))
        np.testing.assert_allclose(est.T, est.T_kinematic, atol=1e-12)
        assert est.status == "tracking" and est.spread[0] > 0.5  # the plateau, not a point
