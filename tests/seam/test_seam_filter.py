"""The particle filter: converges on the measurable directions, recovers from vanishing weights, resamples by name
below the ESS threshold, is deterministic per seed; its walk is the profile's over the step's time, the particles
move with the deflection the compliance model predicts, a reading's latency moves its sensor back along the
program, and each laser reading weighs with sigma^2 + jitter + h^2 x the cloud's spread of errors."""

import math

import numpy as np
import pytest

from posekit.geometry import matrix_from_rotation_vector, rotation_vector_from_matrix, se3_exp
from posekit.seam.engine.densities import joint_compliance, robot_measurement
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.engine.step import StepInputs, jitter_variances
from posekit.seam.frontend.trajectories import nominal_trajectory
from tests.seam.helpers import config, make_filter

STEPS = 60
#: The true tool sits at this constant offset from the nominal pose (tool frame): x, y, z mm, rx, ry, rz rad.
OFFSET = np.array([0.8, 0.5, -0.6, 0.002, 0.0, 0.004])


def _cfg(**over):
    # this generator's truth keeps one offset along the whole seam; a long baseline between the sensors makes the
    # rotations well determined within 60 steps
    base = {"filter.particles": 300, "profile.plateau.d0_mm": 2.0, "profile.plateau.d0_deg": 0.5,
            "profile.walk.x_mm": 0.02, "profile.walk.y_mm": 0.02, "profile.walk.z_mm": 0.02,
            "profile.walk.rx_deg": 0.01, "profile.walk.ry_deg": 0.01, "profile.walk.rz_deg": 0.01}
    base.update(over)
    return config({"trajectory": {"kind": "line", "steps": STEPS},
                   "cell": {"sensors": {"count": 2, "distances_mm": [20.0, 100.0]}}}, **base)


def _inputs(cfg, *, q_nan_at=None):
    """Exact lasers from the offset truth; joints = the reference (kinematic pose = nominal); no force."""
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    Tn = nt.T_nominal
    truth = Tn @ se3_exp(OFFSET)
    seam = SeamLine(nt.seam)
    dists = cfg.cell.sensors.resolved_distances_mm()
    laser = np.full((STEPS, len(dists), 2), np.nan)
    R = truth[:, :3, :3]
    for i, d in enumerate(dists):
        o = truth[:, :3, 3] + d * R[:, :, 1]
        e = seam.intersect(o, R[:, :, 1]).point - o
        laser[:, i] = np.c_[(e * R[:, :, 0]).sum(1), (e * R[:, :, 2]).sum(1)]
    out = []
    for k in range(STEPS):
        q = nt.q[k].copy()
        if k == q_nan_at:
            q[:] = np.nan
        inc = np.eye(4) if k == 0 else Tn[k] @ np.linalg.inv(Tn[k - 1])
        out.append(StepInputs(inc, Tn[k], q, np.zeros(3), float(nt.t_s[k]), nt.q[k], laser[k] if len(dists) else None))
    return nt, truth, out


def _run(cfg, seed=0, **kw):
    nt, truth, inputs = _inputs(cfg, **kw)
    pf = make_filter(cfg, nt.seam, seed, T_init=nt.T_nominal[0])
    ests = [pf.step(x) for x in inputs]
    return pf, truth, ests


def _offset_error(T_est, T_true):
    dp = T_true[:3, :3].T @ (T_est[:3, 3] - T_true[:3, 3])
    dr = rotation_vector_from_matrix(T_true[:3, :3].T @ T_est[:3, :3])
    return np.r_[dp, dr]


def test_two_sensors_find_the_measurable_offset():
    cfg = _cfg()
    pf, truth, ests = _run(cfg)
    err = np.array([_offset_error(e.T, t) for e, t in zip(ests[-10:], truth[-10:])])
    kin = np.abs(OFFSET)
    # x, z and the rotations the two lasers see (rx from z, rz from x at two distances)
    assert np.abs(err[:, 0]).max() < 0.1 * kin[0]
    assert np.abs(err[:, 2]).max() < 0.1 * kin[2]
    assert np.abs(err[:, 3]).max() < 0.3 * kin[3]
    assert np.abs(err[:, 5]).max() < 0.15 * kin[5]
    # y is along the featureless seam: the spread stays wide (about the robot plateau)
    assert np.median([e.spread[1] for e in ests[-10:]]) > 3 * np.median([e.spread[0] for e in ests[-10:]])
    assert pf.recoveries == 0
    # the far sensor runs off the seam's end near the finish: missing measurements are skipped
    used = [e.lasers_used for e in ests]
    assert used[0] == 2 and used[-1] == 1 and set(used) == {1, 2}
    np.testing.assert_allclose(ests[-1].T_kinematic, nominal_trajectory(cfg.trajectory, cfg.cell.robot).T_nominal[-1])


def test_vanishing_weights_are_recovered_not_a_crash():
    cfg = _cfg()
    pf, truth, ests = _run(cfg, q_nan_at=30)
    assert pf.recoveries == 1
    assert ests[30].recovered and not ests[29].recovered and not ests[31].recovered
    assert all(np.all(np.isfinite(e.T)) for e in ests)
    assert abs(_offset_error(ests[-1].T, truth[-1])[2]) < 0.1  # and it still tracks afterwards


@pytest.mark.parametrize("name", ["systematic", "stratified", "residual"])
def test_resampling_by_name_and_threshold(name):
    pf, truth, ests = _run(_cfg(**{"filter.resampler": name, "filter.ess_threshold": 1.0}))
    assert pf.resamplings == STEPS and all(e.resampled for e in ests)
    assert abs(_offset_error(ests[-1].T, truth[-1])[0]) < 0.1
    pf, _, ests = _run(_cfg(**{"filter.resampler": name, "filter.ess_threshold": 1e-6}))
    assert pf.resamplings == 0
    assert all(1.0 <= e.ess <= 300.0 for e in ests)


def test_same_seed_same_particles():
    cfg = _cfg()
    a, _, ea = _run(cfg, seed=5)
    b, _, eb = _run(cfg, seed=5)
    c, _, _ = _run(cfg, seed=6)
    np.testing.assert_array_equal(a.T, b.T)
    np.testing.assert_array_equal(ea[-1].T, eb[-1].T)
    assert not np.array_equal(a.T, c.T)


def test_regularised_resampling_keeps_the_mean_and_the_covariance():
    """The offsets and the Cholesky factor of their weighted covariance match NumPy, and the resampled cloud keeps
    the weighted mean and the 6-D covariance (correlations included), to sampling error."""
    cfg = _cfg(**{"filter.particles": 4000})
    pf = make_filter(cfg, nominal_trajectory(cfg.trajectory, cfg.cell.robot).seam, 1)
    rng = np.random.default_rng(4)
    C = np.diag([1.0, 2.0, 0.5, 3e-3, 2e-3, 4e-3]) ** 2
    C[0, 5] = C[5, 0] = 0.8 * 1.0 * 4e-3  # an across-position / yaw correlation
    xi0 = rng.multivariate_normal(np.zeros(6), C, size=4000)
    T = se3_exp(xi0)
    w = np.exp(-0.5 * (xi0[:, 1] / 1.5) ** 2)
    w /= w.sum()
    T_mean, spread, xi, mu, L = pf._cloud(T, w)
    np.testing.assert_allclose(xi[:50, :3], (T[:50, :3, 3] - T_mean[:3, 3]) @ T_mean[:3, :3], atol=1e-12)
    np.testing.assert_allclose(xi[:50, 3:], rotation_vector_from_matrix(T_mean[:3, :3].T @ T[:50, :3, :3]),
                               atol=1e-12)
    np.testing.assert_allclose(mu, w @ xi, atol=1e-15)
    cov = ((xi - mu) * w[:, None]).T @ (xi - mu)
    np.testing.assert_allclose(L @ L.T, cov, rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(spread, np.sqrt(np.diag(cov)), rtol=1e-9)
    out = pf._kernel_resample(T, w, 0.5, shrink=True)
    T2, _, _, _, L2 = pf._cloud(out, np.full(4000, 1 / 4000))
    off = _offset_error(T2, T_mean)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(off) < 0.08 * sd)
    cov2 = L2 @ L2.T
    np.testing.assert_allclose(np.sqrt(np.diag(cov2)), sd, rtol=0.08)
    corr = cov[0, 5] / (sd[0] * sd[5])
    assert cov2[0, 5] / np.sqrt(cov2[0, 0] * cov2[5, 5]) == pytest.approx(corr, abs=0.05)


def _still_filter(compliance: float, **over):
    """A filter whose particles only move by the transition's mean (no walk, no resampling)."""
    over = {"profile.walk.x_mm": 0.0, "profile.walk.y_mm": 0.0, "profile.walk.z_mm": 0.0,
            "profile.walk.rx_deg": 0.0, "profile.walk.ry_deg": 0.0, "profile.walk.rz_deg": 0.0,
            "filter.ess_threshold": 1e-9, "cell.compliance_rad_per_nm": compliance, **over}
    cfg = config({"trajectory": {"steps": 20}}, **over)
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    return cfg, nt, make_filter(cfg, nt.seam, 0, T_init=nt.T_nominal[0])


def test_particles_move_with_the_deflection_the_measured_force_predicts():
    # no walk: from step 1 to 2 each particle moves by D2 T+ D1^-1, D = Fk(q + c J_v^T f) Fk(q)^-1 computed here from
    # the chain; without a compliance model by T+ alone
    c = 1e-6
    forces = [np.array([0.0, 0.0, -1000.0]), np.array([300.0, -800.0, -6000.0])]
    for comp in (c, 0.0):
        cfg, nt, pf = _still_filter(comp)
        chain = pf.chain

        def defl(q, f):
            J = chain.geometric_jacobian(q, check=False)
            return chain.forward_kinematics(q + c * 1e-3 * (J[:3].T @ f), check=False) @ np.linalg.inv(
                chain.forward_kinematics(q, check=False))

        pf.step(StepInputs(np.eye(4), nt.T_nominal[0], nt.q[0], forces[0], 0.0, nt.q[0]))
        before = pf.T.copy()
        inc = nt.T_nominal[1] @ np.linalg.inv(nt.T_nominal[0])
        pf.step(StepInputs(inc, nt.T_nominal[1], nt.q[1], forces[1], 0.01, nt.q[1]))
        move = defl(nt.q[1], forces[1]) @ inc @ np.linalg.inv(defl(nt.q[0], forces[0])) if comp else inc
        np.testing.assert_allclose(pf.T, move[None] @ before, atol=1e-9)
        if comp:  # the deflection change is not small: 6 kN moves the tool by tenths of a mm
            assert np.linalg.norm((move - inc)[:3, 3]) > 0.05
        # a non-finite force: the increment alone, the last finite deflection kept
        before = pf.T.copy()
        inc2 = nt.T_nominal[2] @ np.linalg.inv(nt.T_nominal[1])
        pf.step(StepInputs(inc2, nt.T_nominal[2], nt.q[2], np.array([np.nan, 0.0, 0.0]), 0.02, nt.q[2]))
        np.testing.assert_allclose(pf.T, inc2[None] @ before, atol=1e-9)


def test_robot_measurement_carries_the_deflection_it_models():
    cfg, nt, pf = _still_filter(1e-6)
    q, f = nt.q[3], np.array([100.0, -1000.0, -5000.0])
    kw = dict(joint_sigma_rad=1e-5, floor_t_mm=0.1, floor_r_rad=1e-4, d0_mm=1.0, kd_mm_per_n=0.0, d0_rad=1e-3,
              kd_rad_per_n=0.0)
    m = robot_measurement(pf.chain, q, f, compliance=joint_compliance(1e-6), **kw)
    np.testing.assert_allclose(m.T_deflection @ pf.chain.forward_kinematics(q, check=False), m.T_mean, atol=1e-9)
    assert robot_measurement(pf.chain, q, f, **kw).T_deflection is None


def test_the_walk_is_the_profiles_over_the_steps_travel():
    # one axis at a time: over a step whose program moves the tool s mm the particles spread by walk * sqrt(s) on
    # that axis alone
    walk = {"x_mm": 0.4, "rz_deg": 0.2}
    cfg, nt, pf = _still_filter(0.0, **{"filter.particles": 20000, "profile.walk.x_mm": walk["x_mm"],
                                         "profile.walk.rz_deg": walk["rz_deg"]})
    pf.reset(nt.T_nominal[0])
    pf._init_pending = False  # every particle at the start pose: only the walk moves them
    s = 4.0
    inc = np.eye(4)
    inc[:3, 3] = [0.0, s, 0.0]  # the program moves the tool 4 mm (base frame)
    pf.step(StepInputs(inc, inc @ nt.T_nominal[0], nt.q[0], np.zeros(3), 0.01, nt.q[0]))
    off = np.array([_offset_error(T, inc @ nt.T_nominal[0]) for T in pf.T[:4000]])
    sd = off.std(axis=0)
    assert sd[0] == pytest.approx(walk["x_mm"] * math.sqrt(s), rel=0.05)
    assert sd[5] == pytest.approx(math.radians(walk["rz_deg"]) * math.sqrt(s), rel=0.05)
    assert sd[1] < 1e-9 and sd[2] < 1e-9 and sd[3] < 1e-12 and sd[4] < 1e-12


def test_a_readings_latency_moves_its_sensor_back_along_the_program():
    # the effective mount of a reading L s old is Fk(q(t))^-1 Fk(q(t - L)) T_tool_sensor, the program's joints
    # interpolated: a latency of a quarter step is a quarter of the way back to the last sample's pose
    cfg = config({"trajectory": {"steps": 20}, "cell": {"sensors": {"count": 2, "latency_s": [0.0025, None]}}},
                 **{"profile.sensors": [{"latency_s": 0.0, "sigma_mm": 0.05, "angle_sigma_deg": 0.2}]})
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    pf = make_filter(cfg, nt.seam, 0, T_init=nt.T_nominal[0])
    for k in range(4):
        inc = np.eye(4) if k == 0 else nt.T_nominal[k] @ np.linalg.inv(nt.T_nominal[k - 1])
        inp = StepInputs(inc, nt.T_nominal[k], nt.q[k], np.zeros(3), float(nt.t_s[k]), nt.q[k])
        pf.step(inp)
    M = pf._reading_mounts(inp)
    q_then = nt.q[3] + 0.25 * (nt.q[2] - nt.q[3])
    chain = pf.chain
    want = np.linalg.inv(nt.T_nominal[3]) @ chain.forward_kinematics(q_then) @ pf.mounts[0]
    np.testing.assert_allclose(M[0], want, atol=1e-9)
    np.testing.assert_array_equal(M[1], pf.mounts[1])  # undeclared and the profile's latency 0: the mount itself
    assert np.linalg.norm(M[0][:3, 3] - pf.mounts[0][:3, 3]) > 0.05  # the tool moved 0.1 mm in a quarter step
    # a reading's own stamp overrides the latency (NaN: the latency)
    inp.reading_lag_s = np.array([np.nan, 0.005])
    M2 = pf._reading_mounts(inp)
    np.testing.assert_allclose(M2[0], M[0], atol=1e-12)
    q_then = nt.q[3] + 0.5 * (nt.q[2] - nt.q[3])
    np.testing.assert_allclose(M2[1], np.linalg.inv(nt.T_nominal[3]) @ chain.forward_kinematics(q_then)
                               @ pf.mounts[1], atol=1e-9)


def test_laser_variance_is_sigma_jitter_and_the_kernels_share_of_the_cloud():
    # the jitter's share along the sensor's x and z: t + r x p for a sensor 40 mm ahead, axes as the tool's
    M = np.eye(4)
    M[1, 3] = 40.0
    j = np.array([0.01, 0.02, 0.03, 1e-4, 2e-4, 3e-4])
    v = jitter_variances(M[None], j)[0]
    # x: t_x + (r x p)_x = t_x + r_y p_z - r_z p_y = t_x - 40 r_z; z: t_z + r_x p_y = t_z + 40 r_x
    np.testing.assert_allclose(v, [0.01 ** 2 + (40 * 3e-4) ** 2, 0.03 ** 2 + (40 * 1e-4) ** 2], rtol=1e-12)
    # any mount: the variance of the sensor's x and z components of t + r x p under independent per-axis jitter,
    # by a million samples
    R = matrix_from_rotation_vector(np.array([0.1, -0.2, 0.5]))
    M2 = np.eye(4)
    M2[:3, :3], M2[:3, 3] = R, [5.0, 40.0, 2.0]
    xi = np.random.default_rng(1).standard_normal((1_000_000, 6)) * j
    d = xi[:, :3] + np.cross(xi[:, 3:], M2[:3, 3])
    np.testing.assert_allclose(jitter_variances(np.stack([M, M2]), j)[1], [np.var(d @ R[:, 0]), np.var(d @ R[:, 2])],
                               rtol=5e-3)
    # the particles weigh a reading with sigma^2 + jitter + h^2 x the cloud's mean in-plane variance
    cfg, nt, pf = _still_filter(0.0, **{"profile.sensors": [{"latency_s": 0.0, "sigma_mm": 0.05,
                                                             "angle_sigma_deg": 0.2}],
                                        "filter.regularize_h": 0.5})
    pf.reset(nt.T_nominal[1])
    pf._init_pending = False
    pf.T = nt.T_nominal[1] @ se3_exp(np.random.default_rng(0).normal(0, [0.3, 0.1, 0.2, 0, 0, 0], (pf.n, 6)))
    seam = SeamLine(nt.seam)
    T = nt.T_nominal[1]
    o = T[:3, 3] + 20.0 * T[:3, 1]
    e = seam.intersect(o[None], T[None, :3, 1]).point[0] - o
    laser = np.array([[e @ T[:3, 0], e @ T[:3, 2]], [np.nan, np.nan]])
    inp = StepInputs(np.eye(4), T, nt.q[1], np.zeros(3), 0.0, nt.q[1], laser)
    meas = robot_measurement(pf.chain, nt.q[1], np.zeros(3), compliance=None, **pf._robot_kw)
    rd, radius, _ = pf._readings(inp, meas, pf.mounts)
    pf._s2, pf._miss2 = np.empty(1), radius ** 2
    _, ll_robot, E = pf._loglik(pf.T, rd, inp, meas, errors=True)
    w = np.exp(ll_robot - ll_robot.max())
    w /= w.sum()
    ok = np.isfinite(E).all(axis=1)
    wk = w[ok] / w[ok].sum()
    var = [np.sum(wk * (E[ok, c] - wk @ E[ok, c]) ** 2) for c in (0, 1)]
    jit = jitter_variances(pf.mounts[:1], pf.profile.jitter)[0].mean()
    assert jit > 0.0  # the default profile has a jitter
    assert pf._s2[0] == pytest.approx(0.05 ** 2 + jit + 0.25 * 0.5 * (var[0] + var[1]), rel=1e-9)
