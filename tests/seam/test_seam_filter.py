"""The particle filter: converges on the measurable directions, recovers from vanishing weights,
resamples by name below the ESS threshold, is deterministic per seed."""

import numpy as np
import pytest

from posekit.geometry import rotation_vector_from_matrix, se3_exp
from posekit.seam.engine.filter import SeamParticleFilter, StepInputs
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.frontend.config import config_from_dict
from posekit.seam.frontend.trajectories import nominal_trajectory

STEPS = 60
#: The true tool sits at this constant offset from the nominal pose (tool frame): x, y, z mm, rx, ry, rz rad.
OFFSET = np.array([0.8, 0.5, -0.6, 0.002, 0.0, 0.004])


def _cfg(**filter_kw):
    # this generator's truth keeps one offset along the whole seam (no error that changes with the
    # configuration): the transition's travel terms are off
    f = {"particles": 300, "d0_mm": 2.0, "d0_deg": 0.5, "init_sigma_t_mm": 1.0, "init_sigma_r_deg": 0.3,
         "laser_sigma_mm": 0.05, "k_travel_t_mm_per_mm": 0.0, "k_travel_r_deg_per_mm": 0.0}
    f.update(filter_kw)
    # a long baseline between the sensors makes the rotations well determined within 60 steps
    return config_from_dict({"trajectory": {"kind": "line", "steps": STEPS},
                             "sensors": {"count": 2, "distances_mm": [20.0, 100.0]}, "filter": f})


def _inputs(cfg, *, q_nan_at=None):
    """Exact lasers from the offset truth; joints = the reference (kinematic pose = nominal); no force."""
    nt = nominal_trajectory(cfg.trajectory, cfg.robot)
    Tn = nt.T_nominal
    truth = Tn @ se3_exp(OFFSET)
    seam = SeamLine(nt.seam)
    dists = cfg.sensors.resolved_distances_mm()
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
        out.append(StepInputs(inc, Tn[k], q, np.zeros(3), laser[k] if len(dists) else None))
    return nt, truth, out


def _run(cfg, seed=0, **kw):
    nt, truth, inputs = _inputs(cfg, **kw)
    pf = SeamParticleFilter(cfg, nt.seam, seed, T_init=nt.T_nominal[0])
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
    np.testing.assert_allclose(ests[-1].T_kinematic, nominal_trajectory(cfg.trajectory, cfg.robot).T_nominal[-1])


def test_vanishing_weights_are_recovered_not_a_crash():
    cfg = _cfg()
    pf, truth, ests = _run(cfg, q_nan_at=30)
    assert pf.recoveries == 1
    assert ests[30].recovered and not ests[29].recovered and not ests[31].recovered
    assert all(np.all(np.isfinite(e.T)) for e in ests)
    # and the filter still tracks afterwards
    assert abs(_offset_error(ests[-1].T, truth[-1])[2]) < 0.1


@pytest.mark.parametrize("name", ["systematic", "stratified", "residual"])
def test_resampling_by_name_and_threshold(name):
    always = _cfg(resampler=name, ess_threshold=1.0)
    pf, truth, ests = _run(always)
    assert pf.resamplings == STEPS and all(e.resampled for e in ests)
    assert abs(_offset_error(ests[-1].T, truth[-1])[0]) < 0.1
    rarely = _cfg(resampler=name, ess_threshold=1e-6)
    pf, _, ests = _run(rarely)
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
    """The kernel of the regularised resampling: the offsets and the Cholesky factor of their
    weighted covariance match NumPy, and the resampled cloud keeps the weighted mean and the
    6-D covariance (correlations included), to sampling error."""
    cfg = _cfg(particles=4000)
    pf = SeamParticleFilter(cfg, nominal_trajectory(cfg.trajectory, cfg.robot).seam, 1)
    rng = np.random.default_rng(4)
    C = np.diag([1.0, 2.0, 0.5, 3e-3, 2e-3, 4e-3]) ** 2
    C[0, 5] = C[5, 0] = 0.8 * 1.0 * 4e-3  # an across-position / yaw correlation
    xi0 = rng.multivariate_normal(np.zeros(6), C, size=4000)
    T = se3_exp(xi0)
    w = np.exp(-0.5 * (xi0[:, 1] / 1.5) ** 2)
    w /= w.sum()
    T_mean, spread, xi, mu, L = pf._cloud(T, w)
    # offsets in the mean's frame: R̄ᵀ (p - p̄) and log(R̄ᵀ R)
    np.testing.assert_allclose(xi[:50, :3], (T[:50, :3, 3] - T_mean[:3, 3]) @ T_mean[:3, :3], atol=1e-12)
    np.testing.assert_allclose(xi[:50, 3:], rotation_vector_from_matrix(T_mean[:3, :3].T @ T[:50, :3, :3]),
                               atol=1e-12)
    np.testing.assert_allclose(mu, w @ xi, atol=1e-15)
    cov = ((xi - mu) * w[:, None]).T @ (xi - mu)
    np.testing.assert_allclose(L @ L.T, cov, rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(spread, np.sqrt(np.diag(cov)), rtol=1e-9)
    out = pf._kernel_resample(T, w, 0.5, shrink=True)
    u = np.full(4000, 1 / 4000)
    T2, _, _, _, L2 = pf._cloud(out, u)
    off = _offset_error(T2, T_mean)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(off) < 0.08 * sd)
    cov2 = L2 @ L2.T
    np.testing.assert_allclose(np.sqrt(np.diag(cov2)), sd, rtol=0.08)
    corr = cov[0, 5] / (sd[0] * sd[5])
    assert cov2[0, 5] / np.sqrt(cov2[0, 0] * cov2[5, 5]) == pytest.approx(corr, abs=0.05)
