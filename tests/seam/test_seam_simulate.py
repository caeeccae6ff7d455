"""Simulation framework: trajectories of §III-B from a robot program, process deflection, sensors
(missing measurements), determinism per seed, the EpisodeResult/metrics contract."""

import numpy as np
import pytest

from posekit.seam.engine.seamline import SeamLine
from posekit.seam.frontend.config import config_from_dict
from posekit.seam.frontend.episode import run_episode, seam_knots
from posekit.seam.frontend.episode_metrics import metrics
from posekit.seam.frontend.simulate import simulate_data
from posekit.seam.frontend.trajectories import nominal_trajectory

SMALL = {"steps": 100}


def _cfg(**sections):
    d = {"trajectory": dict(SMALL), "filter": {"particles": 100}}
    for k, v in sections.items():
        d.setdefault(k, {}).update(v)
    return config_from_dict(d)


def _in_T0(nt, p):
    T0 = nt.T_base_T0
    return (p - T0[:3, 3]) @ T0[:3, :3]


@pytest.mark.parametrize("kind, axis, amplitude", [("xy", 0, 20.0), ("yz", 2, 100.0)])
def test_paper_trajectories_from_the_robot_program(kind, axis, amplitude):
    cfg = _cfg(trajectory={"kind": kind})
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    assert nt.q.shape == (100, 6) and nt.T_nominal.shape == (100, 4, 4)
    assert nt.ik_max_error_mm < 1e-3
    np.testing.assert_allclose(nt.T_nominal, nt.chain.forward_kinematics(nt.q), atol=1e-9)
    p = _in_T0(nt, nt.T_nominal[:, :3, 3])
    # 200 mm along y of the tool, the wave in x (xy) or z (yz), nothing in the third axis
    assert p[0, 1] == pytest.approx(0.0, abs=1e-3) and p[-1, 1] == pytest.approx(200.0, abs=1e-3)
    other = 2 if axis == 0 else 0
    assert np.abs(p[:, other]).max() < 1e-3
    seam = _in_T0(nt, nt.seam)
    assert np.abs(seam[:, axis]).max() == pytest.approx(amplitude, rel=0.05)
    # the tool keeps its orientation (tool axis down, travel along base +y)
    np.testing.assert_allclose(nt.T_nominal[:, :3, :3], np.repeat(nt.T_base_T0[None, :3, :3], 100, 0), atol=1e-6)
    assert seam[-1, 1] == pytest.approx(200.0 + cfg.trajectory.seam_extension_mm)
    np.testing.assert_allclose(nt.t_s[[0, -1]], [0.0, 0.99])


def test_bend_and_line_seams_and_their_knots():
    bend = _cfg(trajectory={"kind": "bend", "bend_deg": 30.0})
    nt = nominal_trajectory(bend.trajectory, bend.cell.robot)
    seam = _in_T0(nt, nt.seam)
    after = seam[seam[:, 1] > 110.0]
    d = np.diff(after, axis=0)
    np.testing.assert_allclose(np.degrees(np.arctan2(d[:, 0], d[:, 1])), 30.0, atol=1e-6)
    k = seam_knots(bend)
    # the ends and the corner (which the solver may cut within eps: two adjacent knots)
    assert 3 <= len(k.knots) <= 4 and k.max_error_mm <= bend.filter.trend_eps_mm * (1 + 1e-6)
    corner = _in_T0(nt, k.polyline)[1:-1, :2]
    assert np.abs(corner - [0.0, 100.0]).max() < 0.6
    assert len(seam_knots(_cfg(trajectory={"kind": "line"})).knots) == 2


def test_same_seed_same_numbers_other_seed_other_numbers():
    cfg = _cfg()
    a = run_episode(cfg, 3)
    b = run_episode(cfg, 3)
    c = run_episode(cfg, 4)
    for name in ("truth", "estimate", "kinematic", "error", "spread", "ess", "laser_mm"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert not np.array_equal(a.error, c.error) and not np.array_equal(a.truth, c.truth)
    assert run_episode(cfg).seed == cfg.seed


def test_episode_result_contract_and_metrics():
    cfg = _cfg()
    r = run_episode(cfg, 0, record_particles=20)
    T = 100
    for name, shape in [("t_s", (T,)), ("truth", (T, 4, 4)), ("estimate", (T, 4, 4)), ("kinematic", (T, 4, 4)),
                        ("nominal", (T, 4, 4)), ("error", (T, 6)), ("kinematic_error", (T, 6)), ("spread", (T, 6)),
                        ("ess", (T,)), ("step_ms", (T,)), ("particles", (T, 20, 6)), ("truth_coords", (T, 6)),
                        ("estimate_coords", (T, 6)), ("laser_mm", (T, 2, 2))]:
        assert getattr(r, name).shape == shape, name
    assert r.seam.shape[1] == 3 and r.knots_kept >= 2 and r.trend_max_error_mm <= 0.02 * (1 + 1e-6)
    assert np.all(np.isfinite(r.error)) and np.all(r.step_ms > 0)
    # coordinates: error = estimate - truth in the nominal frame (small-angle consistent)
    np.testing.assert_allclose(r.estimate_coords[:, :3] - r.truth_coords[:, :3], r.error[:, :3], atol=1e-9)
    # the recorded particles scatter around the estimate
    np.testing.assert_allclose(r.particles.mean(axis=1)[:, [0, 2]], r.estimate_coords[:, [0, 2]], atol=0.3)
    # rotations are radians (issue 15): an independent rotation vector (scipy) of R_trueᵀ R_est and of R_nomᵀ R
    from scipy.spatial.transform import Rotation
    rv = Rotation.from_matrix(np.einsum("nji,njk->nik", r.truth[:, :3, :3], r.estimate[:, :3, :3])).as_rotvec()
    np.testing.assert_allclose(r.error[:, 3:], rv, atol=1e-9)
    rv = Rotation.from_matrix(np.einsum("nji,njk->nik", r.nominal[:, :3, :3], r.truth[:, :3, :3])).as_rotvec()
    np.testing.assert_allclose(r.truth_coords[:, 3:], rv, atol=1e-9)
    m = metrics([r, run_episode(cfg, 1)])
    # metrics.json keeps degrees: the pooled RMSE of the radian errors, converted at the edge
    r1 = run_episode(cfg, 1)
    rz = np.degrees(np.sqrt(np.mean(np.r_[r.error[:, 5], r1.error[:, 5]] ** 2)))
    assert m["rmse_deg"]["rz"] == pytest.approx(rz, abs=2e-6)
    assert m["spread_median_deg"]["rx"] == pytest.approx(np.degrees(np.median(np.r_[r.spread[:, 3], r1.spread[:, 3]])),
                                                         abs=2e-6)
    assert m["runs"] == 2 and m["steps"] == T and m["particles"] == 100 and m["sensors"] == 2
    assert m["trajectory"] == "xy" and m["sensor_distances_mm"] == [20.0, 40.0]
    assert set(m["rmse_mm"]) == {"x", "y", "z"} and set(m["rmse_deg"]) == {"rx", "ry", "rz"}
    assert m["rmse_mm"]["z"] < m["kinematic_rmse_mm"]["z"]
    assert m["step_ms_median"] > 0 and m["laser_missing_fraction"] == 0.0


def test_simulated_lasers_see_the_true_seam():
    cfg = _cfg(sensors={"noise_mm": 0.0})
    data = simulate_data(cfg, 0)
    seam = SeamLine(data.nominal.seam)
    for i, dist in enumerate((20.0, 40.0)):
        R = data.truth[:, :3, :3]
        p = data.truth[:, :3, 3] + R @ np.array([0.0, dist, 0.0]) + (
            R[:, :, 0] * data.laser_mm[:, i, :1] + R[:, :, 2] * data.laser_mm[:, i, 1:])
        hit = seam.intersect(p, R[:, :, 1])
        np.testing.assert_allclose(hit.point, p, atol=1e-9)


def test_process_force_deflects_and_kinematics_miss_it():
    rigid = _cfg(process={"joint_compliance_rad_per_nm": 0.0, "cartesian_compliance_mm_per_n": 0.0,
                          "cartesian_compliance_deg_per_n": 0.0},
                 robot={"kinematic_error_mm": 0.0, "kinematic_error_deg": 0.0, "joint_noise_deg": 0.0})
    d = simulate_data(rigid, 0)
    np.testing.assert_allclose(d.truth, d.nominal.T_nominal, atol=1e-9)
    soft = simulate_data(_cfg(), 0)
    dev = np.linalg.norm(soft.truth[:, :3, 3] - soft.nominal.T_nominal[:, :3, 3], axis=1)
    assert 0.5 < dev.mean() < 5.0  # large process forces: mm-level deflection
    np.testing.assert_allclose(np.linalg.norm(soft.force_n, axis=1).mean(), np.linalg.norm([100, 1000, 5000]), rtol=0.1)


def test_missing_laser_measurements_are_handled():
    out_of_range = _cfg(sensors={"range_mm": 1e-6})
    r = run_episode(out_of_range, 0)
    assert np.isnan(r.laser_mm).all() and np.all(np.isfinite(r.estimate))
    assert metrics([r])["laser_missing_fraction"] == 1.0
    # no lasers: the estimate stays at the kinematics level
    np.testing.assert_allclose(np.sqrt((r.error ** 2).mean(0))[[0, 2]],
                               np.sqrt((r.kinematic_error ** 2).mean(0))[[0, 2]], rtol=0.5)
    half = run_episode(_cfg(sensors={"dropout": 0.5}), 0)
    frac = np.isnan(half.laser_mm[..., 0]).mean()
    assert 0.35 < frac < 0.65
    none = run_episode(_cfg(sensors={"count": 0}), 0)
    assert none.laser_mm.shape == (100, 0, 2)
    # the far end: a sensor beyond the seam's end has no intersection
    short = simulate_data(_cfg(trajectory={"seam_extension_mm": 30.0}), 0)
    assert np.isnan(short.laser_mm[-1, 1]).all() and np.isfinite(short.laser_mm[-1, 0]).all()


def test_program_ik_reproduces_the_program():
    """The joint stream solved with the core's unchecked resolved-rate step puts the tool on the
    programmed poses (position < 1 µm, orientation < 1e-6 rad)."""
    from posekit.geometry import rotation_angle_between

    cfg = _cfg()
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    T = nt.chain.forward_kinematics(nt.q)
    assert np.abs(T[:, :3, 3] - nt.T_program[:, :3, 3]).max() < 1e-3
    assert rotation_angle_between(T[:, :3, :3], nt.T_program[:, :3, :3]).max() < 1e-6


def test_angle_measurement_pins_the_roll():
    """The rotation about the laser-plane normal (roll ry about the travel direction) is what
    the optional angle measurement sees; position-only lasers leave it weakly determined."""
    kw = {"trajectory": {"kind": "xy", "steps": 200}, "filter": {"particles": 300}}
    # two seeds: the roll is weakly seen through the seam's curvature; without the angle it stays near the
    # kinematics' error (measured 0.129 / 0.106 deg against the kinematics' 0.133 / 0.087 deg, seeds 1 / 2), with it
    # 0.031 / 0.037 deg
    plain = [run_episode(config_from_dict(kw), s) for s in (1, 2)]
    angled = [run_episode(config_from_dict({**kw, "sensors": {"angle": True}}), s) for s in (1, 2)]
    assert all(np.isfinite(a.laser_mm).all() for a in angled)
    ry_plain = np.sqrt(np.mean([(p.error[:, 4] ** 2).mean() for p in plain]))
    ry_angle = np.sqrt(np.mean([(a.error[:, 4] ** 2).mean() for a in angled]))
    assert ry_angle < 0.6 * ry_plain  # measured 0.031 deg against 0.059 deg with the default profile
    assert np.degrees(ry_angle) < 0.05  # the errors are in rad; 0.05 deg


def _seam_model_yaw_deg(cfg):
    """Per step, the yaw (deg) the filter would read from the two sensors if its seam model (the knot polyline)
    were the seam: the difference of the two sensors' across-readings on the knot polyline and on the seam itself,
    at the nominal poses, over their baseline (20 mm by default)."""
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot, cfg.trajectory.seam_extension_mm)
    mounts = cfg.cell.sensors.resolved_mounts()
    baseline = float(np.linalg.norm(mounts[1][:3, 3] - mounts[0][:3, 3]))
    dx = []
    for M in mounts:
        S = np.matmul(nt.T_nominal, M)
        o, R = S[:, :3, 3], S[:, :3, :3]
        x = [((SeamLine(p).intersect(o, R[:, :, 1]).point - o) * R[:, :, 0]).sum(1)
             for p in (nt.seam, seam_knots(cfg).polyline)]
        dx.append(x[1] - x[0])
    return np.degrees((dx[1] - dx[0]) / baseline)


def test_the_seam_model_does_not_bias_the_yaw():
    # issue 15: the trend filter (eq. 10) tilts the xy seam's straight runs within its tube; with eps 0.02 mm the
    # two sensors' readings of the knot polyline differ from the seam's by a yaw as large as the filter's own yaw
    # RMSE (0.036 deg), and the nominal yaw error followed it (-1 sigma after every peak). The default 1 um keeps it
    # a few thousandths of a degree (hand-computed crossings, no filter involved)
    yaw = _seam_model_yaw_deg(_cfg())
    assert np.sqrt(np.mean(yaw ** 2)) < 0.003 and np.abs(yaw).max() < 0.004
    old = _seam_model_yaw_deg(_cfg(filter={"trend_eps_mm": 0.02}))
    assert np.sqrt(np.mean(old ** 2)) > 0.03 and np.abs(old).max() > 0.05
