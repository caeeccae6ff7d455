"""The cloud kept at least as wide as a share of the spread bound (issue 15, ``filter.cloud_floor``).

A cloud narrower than the covariance the data support cannot move where new information puts the
pose: under 25 kN (seed 5) the rx/ry cloud fell to 0.36 of the bound and the estimate stayed 3σ
off for a hundred steps. The floor adds Gaussian noise of covariance ``(c P - Σ_cloud)+`` in the
tangent space at the cloud's mean (:func:`floor_factor`): nothing where the cloud is already wider.
"""

import numpy as np
import pytest

from posekit.geometry import invert_transform, matrix_from_rotation_vector, se3_log, transform_from
from posekit.seam.engine.filter import SeamParticleFilter, StepInputs, floor_factor
from posekit.seam.engine.particles import weighted_mean_se3
from posekit.seam.frontend.config import apply_overrides, config_from_dict
from posekit.seam.frontend.simulate import seam_knots, simulate_data
from posekit.seam.frontend.trajectories import nominal_trajectory


def _pf(n):
    cfg = config_from_dict({"trajectory": {"kind": "line", "steps": 20}, "sensors": {"count": 0},
                            "filter": {"particles": n}})
    nt = nominal_trajectory(cfg.trajectory, cfg.robot)
    return SeamParticleFilter(cfg, nt.seam, 0, T_init=nt.T_nominal[0])


def _floor(pf, P):
    """The step's floor move on its own: the cloud's covariance, the missing factor, one move (weights kept)."""
    w = pf.weights
    cloud = pf._cloud(pf.T, w / w.sum())
    B = floor_factor(P, cloud[4])
    if B is not None:
        pf.T = pf._move(cloud, np.arange(pf.n), 1.0, B)


def _offsets(T, T0):
    """Tangent offsets ``[R0ᵀ (p - p0), log(R0ᵀ R)]`` of the poses T (N, 4, 4) from T0 (the filter's convention),
    with the library's SE(3) log on the rotation part only (an independent path)."""
    rel = np.einsum("ij,njk->nik", invert_transform(T0), T)
    xi = se3_log(rel)
    out = np.empty_like(xi)
    out[:, :3] = rel[:, :3, 3]
    out[:, 3:] = xi[:, 3:]
    return out


def test_floor_widens_a_narrow_cloud_to_the_covariance_and_keeps_its_mean():
    rng = np.random.default_rng(3)
    pf = _pf(40000)
    T0 = transform_from(matrix_from_rotation_vector(np.array([0.1, -0.2, 0.3])), np.array([400.0, 20.0, -5.0]))
    s = np.array([0.05, 0.05, 0.05, 1e-4, 1e-4, 1e-4])  # the cloud: narrow on every axis
    xi = rng.standard_normal((pf.n, 6)) * s
    pf.T = np.stack([T0 @ transform_from(matrix_from_rotation_vector(v[3:]), v[:3]) for v in xi])
    pf.logw = np.full(pf.n, -np.log(pf.n))
    A = np.array([[0.4, 0.0, 0.0, 0.0, 0.0, 0.0], [0.1, 0.3, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.02, 0.0, 0.0, 0.0],
                  [0.0, 0.0, 0.0, 2e-3, 0.0, 0.0], [0.0, 0.0, 0.0, 1e-3, 3e-3, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 5e-5]])
    P = A @ A.T  # correlated; z and rz narrower than the cloud already is
    _floor(pf, P)
    got = _offsets(pf.T, T0)
    C = np.cov(got.T)
    want = np.diag(s ** 2)
    # where P exceeds the cloud, the cloud now has P's variance (and its correlations); where it does not, its own
    for j in (0, 1, 3, 4):
        assert C[j, j] == pytest.approx(P[j, j], rel=0.05)
    assert C[0, 1] == pytest.approx(P[0, 1], rel=0.1) and C[3, 4] == pytest.approx(P[3, 4], rel=0.1)
    for j in (2, 5):
        assert C[j, j] == pytest.approx(want[j, j], rel=0.05)
    assert (np.abs(got.mean(0)) <= 4 * np.sqrt(np.diag(C) / pf.n)).all()
    # a covariance the cloud already covers leaves every particle where it was
    before = pf.T.copy()
    _floor(pf, 1e-3 * np.diag(s ** 2))
    np.testing.assert_array_equal(pf.T, before)
    _floor(pf, np.full((6, 6), np.nan))  # a bound that is not finite is ignored
    np.testing.assert_array_equal(pf.T, before)


def test_the_cloud_stays_at_least_root_c_of_the_bound_under_25_kN():
    # the episode whose rx/ry cloud collapsed to 0.36 of the bound (seed 5, 25 kN, the force-range verdict off; with
    # the seam model, the bound and the robot model of the time, trend_eps_mm 0.02, bound_inflation 0, no particle
    # noise in the bound, no compliance model and its plateau: the mechanism under test)
    def run(c):
        cfg = apply_overrides(config_from_dict({}), {"process.force_n": [490.0, -4900.0, -24500.0],
                                                      "filter.plateau_max_force_n": 0.0, "filter.cloud_floor": c,
                                                      "filter.trend_eps_mm": 0.02, "filter.axis_scale_r": [1, 0.8, 0.1],
                                                      "filter.bound_inflation": 0.0, "filter.bound_particle_noise": 0.0,
                                                      "filter.compliance_rad_per_nm": 0.0,
                                                      "filter.kd_mm_per_n": 4.5e-4})
        data = simulate_data(cfg, 5)
        Tn = data.nominal.T_nominal
        pf = SeamParticleFilter(cfg, seam_knots(cfg).polyline, np.random.default_rng(7), T_init=Tn[0],
                                seam_normal=data.nominal.seam_normal)
        ratio = []
        for k in range(80):
            inc = np.eye(4) if k == 0 else Tn[k] @ invert_transform(Tn[k - 1], check=False)
            pf.step(StepInputs(inc, Tn[k], data.q_meas[k], data.force_meas_n[k], data.laser_mm[k], None))
            _, spread = weighted_mean_se3(pf.T, pf.weights)
            ratio.append(spread[3:5] / np.sqrt(np.diag(pf._bound.P))[3:5])
        return np.array(ratio)[1:]

    # sqrt(0.2) = 0.447, less the sampling error of 500 particles (a resampling step keeps the covariance in
    # expectation); c = 0.5 is checked too (sqrt 0.707)
    on, off, wide = run(0.2), run(0.0), run(0.5)
    assert on.min() >= 0.42 and np.median(on) >= 0.52
    assert wide.min() >= 0.64 and np.median(wide) >= 0.72
    assert off.min() < 0.40
