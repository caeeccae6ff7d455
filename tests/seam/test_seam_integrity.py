"""Integrity of the seam track (engine/integrity.py): the NIS is χ² on consistent data (a linear
Gaussian generator written here), the robot test is eq. 8's distance outside the plateau, the
monitor's verdicts and reasons, the laser error kernel against a NumPy plane cut for any mount,
and the filter's status on data the simulator did not make (both failure kinds)."""

import numpy as np
import pytest
from scipy.stats import chi2

from posekit.geometry import matrix_from_rotation_vector, se3_exp, transform_from
from posekit.seam.engine import _cloud_kernels as _ck
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.densities import RobotMeasurement, laser_loglik
from posekit.seam.engine.integrity import IntegrityMonitor, innovation_nis, robot_consistency
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.engine.step import StepInputs
from posekit.seam.frontend.trajectories import nominal_trajectory
from tests.seam.helpers import config, make_filter


def _mon(window=10, alpha_degraded=1e-3, alpha_lost=1e-7, ess_min=0.002, recovery=0, max_force_n=0.0,
         window_long=0, n=500):
    return IntegrityMonitor(n, window, alpha_degraded, alpha_lost, ess_min, recovery, max_force_n, window_long)


def test_nis_is_chi2_on_consistent_linear_gaussian_data():
    # cloud x_i ~ N(0, P) in the laser plane, truth drawn from the same law, reading = truth + noise:
    # the innovation of each particle is e_i = m - x_i, and NIS must be chi2 with 2 dof
    rng = np.random.default_rng(1)
    P = np.array([[0.04, 0.01], [0.01, 0.02]])
    L = np.linalg.cholesky(P)
    sigma = 0.05
    nis = []
    for _ in range(1500):
        x = rng.standard_normal((400, 2)) @ L.T
        m = rng.standard_normal(2) @ L.T + sigma * rng.standard_normal(2)
        v, dof = innovation_nis(m - x, np.full(400, 1 / 400), sigma ** 2)
        assert dof == 2
        nis.append(v)
    nis = np.array(nis)
    assert nis.mean() == pytest.approx(2.0, abs=0.2)
    assert np.mean(nis > chi2.isf(0.01, 2)) == pytest.approx(0.01, abs=0.01)
    # a reading 1 mm off (20 sigma of the predictive spread): far in the tail
    x = rng.standard_normal((400, 2)) @ L.T
    assert innovation_nis(np.array([1.0, 0.0]) - x, np.full(400, 1 / 400), sigma ** 2)[0] > 15


def test_nis_weights_misses_and_no_readings():
    e = np.array([[0.1, 0.0], [np.nan, np.nan], [0.3, 0.0]])
    w = np.array([0.5, 0.25, 0.25])
    # the miss is dropped, weights renormalised to 2/3, 1/3: mean 0.1667, var (2/3·1/3·0.2²) + σ²
    mean = 0.5 / 3
    var = (2 / 3) * (0.1 - mean) ** 2 + (1 / 3) * (0.3 - mean) ** 2 + 0.05 ** 2
    assert innovation_nis(e, w, 0.05 ** 2)[0] == pytest.approx(mean ** 2 / var, rel=1e-12)
    assert innovation_nis(np.full((3, 2), np.nan), w, 0.05 ** 2) == (0.0, 0)  # beyond the seam model: no test
    # a second reading only a particle of weight 1e-4 places on the seam: the cloud cannot explain both
    e2 = np.c_[[[0.1, 0.0], [0.2, 0.0], [0.3, 0.0]], [[np.nan, np.nan], [0.1, 0.0], [np.nan, np.nan]]]
    assert innovation_nis(e2, np.array([0.5, 1e-4, 0.4999]), 0.05 ** 2) == (np.inf, 4)
    assert innovation_nis(np.empty((3, 0)), w, 0.05 ** 2) == (0.0, 0)


def _meas(d_t=2.0, d_r=0.01, s_t=0.3, s_r=1e-3):
    return RobotMeasurement(np.eye(4), s_t ** 2 * np.eye(3), s_r ** 2 * np.eye(3), d_t, d_r)


def test_robot_consistency_is_the_distance_outside_the_plateau():
    T = np.eye(4)
    T[:3, 3] = [1.5, 0.0, 0.0]
    assert robot_consistency(T, np.zeros(6), _meas()) == (0.0, 0.0)  # inside both plateaus
    T[:3, 3] = [0.0, 2.9, 0.0]  # 0.9 mm beyond d = 2 with tails 0.3 mm: (0.9 / 0.3)^2 = 9
    m_t, m_r = robot_consistency(T, np.zeros(6), _meas())
    assert m_t == pytest.approx(9.0, rel=1e-12) and m_r == 0.0
    # the estimate's own spread adds: 0.3² + 0.4² = 0.5²
    assert robot_consistency(T, np.r_[0.4, 0.4, 0.4, 0, 0, 0], _meas())[0] == pytest.approx((0.9 / 0.5) ** 2)
    T = transform_from(matrix_from_rotation_vector(np.array([0.0, 0.0, 0.014])), np.zeros(3))
    assert robot_consistency(T, np.zeros(6), _meas())[1] == pytest.approx((0.004 / 1e-3) ** 2, rel=1e-9)


def test_monitor_levels_window_and_reasons():
    mon = _mon(window=5, ess_min=0.01)
    q_deg, q_lost = chi2.isf(1e-3, 10), chi2.isf(1e-7, 10)
    for _ in range(5):
        r = mon.update(2.0, 2, 0.0, 0.0, 400.0)
    assert r.status == "tracking" and r.reason is None and r.dof_window == 10
    # no single step fails its own test (7 < chi2(2) 1e-3 quantile 13.8), but the window sum lies
    # between the two quantiles: degraded, and the reason gives the numbers
    for _ in range(5):
        r = mon.update(7.0, 2, 0.0, 0.0, 400.0)
    assert r.status == "degraded" and r.reason == f"laser NIS 35 > {q_deg:.4g} (dof 10)"
    r = mon.update(q_lost, 2, 0.0, 0.0, 400.0)  # one step beyond its own lost quantile
    assert r.status == "lost" and r.reason == f"laser NIS {q_lost:.4g} > {chi2.isf(1e-7, 2):.4g} at this step (dof 2)"
    assert mon.update(2.0, 2, 0.0, 0.0, 400.0).status == "degraded"  # 4 x 7 + 13.8 (capped) + 2 = 43.8
    for _ in range(5):  # the window forgets
        r = mon.update(2.0, 2, 0.0, 0.0, 400.0)
    assert r.status == "tracking"
    assert mon.update(2.0, 2, 0.0, 0.0, 4.0).reason == "ESS 4 < 5"
    assert mon.update(2.0, 2, chi2.isf(1e-4, 3), 0.0, 400.0).status == "degraded"
    assert mon.update(2.0, 2, 0.0, chi2.isf(1e-9, 3), 400.0).status == "lost"
    assert mon.update(2.0, 2, 0.0, np.nan, 400.0).status == "lost"
    assert mon.update(2.0, 2, 0.0, 0.0, 400.0, recovered=True).reason == "every particle weight vanished"
    mon.reset()
    assert mon.update(0.0, 0, 0.0, 0.0, 400.0).status == "tracking"  # no reading: no laser test


def test_monitor_holds_degraded_while_re_acquiring_after_lost():
    mon = _mon(window=3, recovery=4)
    assert mon.update(2.0, 2, 0.0, 0.0, 400.0).status == "tracking"  # never lost: no hold
    assert mon.update(2.0, 2, 0.0, chi2.isf(1e-9, 3), 400.0).status == "lost"
    got = [mon.update(2.0, 2, 0.0, 0.0, 400.0) for _ in range(6)]
    assert [r.status for r in got] == ["degraded"] * 4 + ["tracking"] * 2
    assert got[0].reason == "re-acquiring: lost 1 step(s) ago" and got[3].reason == "re-acquiring: lost 4 step(s) ago"
    # a new loss restarts the count; reset forgets it
    assert mon.update(2.0, 2, 0.0, np.nan, 400.0).status == "lost"
    assert mon.update(2.0, 2, 0.0, 0.0, 400.0).status == "degraded"
    mon.reset()
    assert mon.update(2.0, 2, 0.0, 0.0, 400.0).status == "tracking"
    # recovery 0: tracking right after
    mon = _mon(window=3)
    mon.update(2.0, 2, 0.0, np.nan, 400.0)
    assert mon.update(2.0, 2, 0.0, 0.0, 400.0).status == "tracking"


def test_monitor_a_force_beyond_the_plateau_s_measured_range_is_degraded_but_not_for_the_walk():
    mon = _mon(window=3, max_force_n=12000.0)
    r = mon.update(2.0, 2, 0.0, 0.0, 400.0, force_norm_n=11999.0)
    assert r.status == "tracking" and r.tests_status == "tracking"
    r = mon.update(2.0, 2, 0.0, 0.0, 400.0, force_norm_n=24900.0)
    assert r.status == "degraded" and r.tests_status == "tracking"
    assert r.reason == "force 24.9 kN beyond the 12 kN the robot plateau was fitted at (profile plateau.max_force_n)"
    assert mon.update(2.0, 2, 0.0, 0.0, 400.0, force_norm_n=np.nan).status == "degraded"  # an unreadable force
    # a failed test keeps its own level and both reasons are given
    r = mon.update(2.0, 2, 0.0, chi2.isf(1e-9, 3), 400.0, force_norm_n=24900.0)
    assert r.status == "lost" and r.tests_status == "lost" and r.reason.endswith("(profile plateau.max_force_n)")
    # 0: no limit
    assert _mon(window=3).update(2.0, 2, 0.0, 0.0, 400.0, force_norm_n=1e6).status == "tracking"


def test_a_small_inconsistency_that_persists_is_degraded_by_the_long_window_without_widening_the_walk():
    # sensor 2's x component 1.5 x its fitted mean on every step, the others at their mean: no 10-step window fails
    # (chi2(40) at 1e-3 is 73.4 > 54), the long window tests each component against chi2(rho n) / rho at 1e-3 / 4
    # (Bonferroni over the 4 components), scipy's quantile; the walk reacts to the short tests only
    c, rho = np.array([0.8, 0.9, 0.7, 0.85]), np.array([0.8, 0.95, 0.6, 0.9])
    mon = IntegrityMonitor(500, 10, 1e-3, 1e-7, 0.002, 0, 0.0, 300, nis_mean=c, nis_dof=rho)
    short = _mon(window=10)
    u = c * np.array([1.0, 1.0, 1.5, 1.0])
    got = [mon.update(float(u.sum()), 4, 0.0, 0.0, 400.0, components=u) for _ in range(300)]
    assert all(short.update(float(u.sum()), 4, 0.0, 0.0, 400.0).status == "tracking" for _ in range(300))
    first = next(i for i, r in enumerate(got) if r.status == "degraded")
    limit = [chi2.isf(1e-3 / 4, rho[2] * n) / (rho[2] * n) for n in range(1, 301)]
    assert first == next(k for k in range(300) if 1.5 > limit[k] and k + 1 > 10)
    assert all(r.status == "degraded" for r in got[first:]) and all(r.tests_status == "tracking" for r in got)
    assert got[-1].reason == (f"sensor 2's x innovations over the last 300 readings 1.5 x the profile's nis_mean_x "
                              f"(> {limit[-1]:.3g})")
    # the components at their fitted means never trip it, and the long window forgets what left it
    for _ in range(300):
        mon.update(float(c.sum()), 4, 0.0, 0.0, 400.0, components=c)
    assert mon.update(float(c.sum()), 4, 0.0, 0.0, 400.0, components=c).status == "tracking"
    # without a calibration the components are tested against the textbook chi2_1 (mean 1, 1 dof per reading)
    plain = _mon(window=10, window_long=300)
    for _ in range(299):
        plain.update(4.0, 4, 0.0, 0.0, 400.0, components=np.array([1.0, 1.0, 1.0, 1.0]))
    assert plain.update(4.0, 4, 0.0, 0.0, 400.0, components=np.ones(4)).status == "tracking"
    # a missing reading (NaN) is not counted: sensor 2 read on every other step only
    sparse = _mon(window=10, window_long=300)
    for k in range(300):
        sparse.update(4.0, 4, 0.0, 0.0, 400.0, components=np.array([1.0, 1.0, np.nan, np.nan]) if k % 2 else
                      np.array([1.0, 1.0, 1.6, 1.0]))
    assert sparse._long_n.tolist() == [300, 300, 150, 150]
    assert sparse.update(4.0, 4, 0.0, 0.0, 400.0, components=np.ones(4)).reason.startswith(
        "sensor 2's x innovations over the last 150 readings 1.6 x")   # (one of 1.6 left the window, a 1 came)


def test_innovation_components_are_each_reading_s_own_normalised_square():
    rng = np.random.default_rng(4)
    e = rng.normal(0.02, 0.03, (200, 4))
    e[5, 2:] = np.nan                             # a particle whose second plane misses the seam
    w = rng.random(200)
    w /= w.sum()
    nis, dof, u = innovation_nis(e, w, np.array([1e-3, 2e-3, 1e-3, 4e-3]), per_component=True)
    assert (nis, dof) == innovation_nis(e, w, np.array([1e-3, 2e-3, 1e-3, 4e-3]))
    ok = np.isfinite(e).all(axis=1)
    wk = w[ok] / w[ok].sum()
    mean = wk @ e[ok]
    var = wk @ (e[ok] - mean) ** 2 + np.array([1e-3, 2e-3, 1e-3, 4e-3])
    np.testing.assert_allclose(u, mean ** 2 / var, rtol=1e-10)
    # a reading no particle places on the seam: NaN, the others kept
    e[:, 2:] = np.nan
    _, dof, u = innovation_nis(e, w, 1e-3, per_component=True)
    assert dof == 2 and np.isnan(u[2:]).all() and np.isfinite(u[:2]).all()


def _numpy_plane_errors(T, m, M, P):
    """Reference: the sensor frame T M, the nearest crossing of its x-z plane with the polyline P."""
    out = np.full((T.shape[0], 2), np.nan)
    for i, Ti in enumerate(T):
        S = Ti @ M
        mhat = S[:3, 3] + S[:3, 0] * m[0] + S[:3, 2] * m[1]
        n = S[:3, 1]
        s = (P - mhat) @ n
        best = np.inf
        for k in range(1, len(P)):
            if s[k - 1] * s[k] <= 0 and s[k] != s[k - 1]:
                pi = P[k - 1] + s[k - 1] / (s[k - 1] - s[k]) * (P[k] - P[k - 1])
                e = mhat - pi
                if e @ e < best:
                    best = e @ e
                    out[i] = [e @ S[:3, 0], e @ S[:3, 2]]
    return out


def test_laser_error_kernel_any_mount_matches_numpy():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 80, 41)
    P = np.c_[3 * np.sin(t / 15), t, 0.5 * np.cos(t / 9)]
    T = se3_exp(np.c_[rng.normal(0, 0.5, (60, 3)), rng.normal(0, 0.02, (60, 3))])
    M = transform_from(matrix_from_rotation_vector(np.array([0.1, -0.05, 0.3])), np.array([2.0, 30.0, -1.0]))
    m = np.array([0.4, -0.7])
    E = np.empty((60, 2))
    found = _k.laser_error_kernel(T, m[0], m[1], M, P, 0, len(P) - 1, E)
    ref = _numpy_plane_errors(T, m, M, P)
    assert found == np.isfinite(ref[:, 0]).sum() > 50
    np.testing.assert_allclose(E, ref, atol=1e-9)
    # the distance-ahead density is the same cut with M = a shift along y
    Y = np.eye(4)
    Y[1, 3] = 30.0
    _k.laser_error_kernel(T, m[0], m[1], Y, P, 0, len(P) - 1, E)
    ll = laser_loglik(T, m, 30.0, SeamLine(P), (0, len(P) - 1), 0.05, 10.0)
    e2 = np.where(np.isfinite(E[:, 0]), (E ** 2).sum(1), 100.0)
    np.testing.assert_allclose(ll, -np.log(2 * np.pi * 0.05 ** 2) - e2 / (2 * 0.05 ** 2), rtol=1e-10)


STEPS = 80


def _episode(offset, seed=0, d0_mm=2.0):
    """An independent generator: the truth at a constant offset (tool frame) from the nominal line,
    exact lasers plus N(0, 0.05 mm) noise, joints = the program (kinematic pose = nominal), no force."""
    over = {"filter.particles": 300, "profile.plateau.d0_mm": d0_mm, "profile.plateau.d0_deg": 0.5,
            "profile.plateau.tail_mm": 0.3, "profile.plateau.tail_deg": 0.05,
            "profile.sensors": [{"latency_s": 0.0, "sigma_mm": 0.05, "angle_sigma_deg": 0.2}]}
    cfg = config({"trajectory": {"kind": "line", "steps": STEPS},
                  "cell": {"sensors": {"count": 2, "distances_mm": [20.0, 100.0]}}}, **over)
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    Tn = nt.T_nominal
    truth = Tn @ se3_exp(np.asarray(offset, float))
    seam = SeamLine(nt.seam)
    rng = np.random.default_rng(seed)
    pf = make_filter(cfg, nt.seam, seed, T_init=Tn[0])
    out = []
    for k in range(STEPS):
        laser = np.full((2, 2), np.nan)
        R = truth[k, :3, :3]
        for i, d in enumerate((20.0, 100.0)):
            o = truth[k, :3, 3] + d * R[:, 1]
            hit = seam.intersect(o[None], R[None, :, 1])
            if hit.found[0]:
                e = hit.point[0] - o
                laser[i] = [e @ R[:, 0], e @ R[:, 2]] + 0.05 * rng.standard_normal(2)
        inc = np.eye(4) if k == 0 else Tn[k] @ np.linalg.inv(Tn[k - 1])
        out.append(pf.step(StepInputs(inc, Tn[k], nt.q[k], np.zeros(3), float(nt.t_s[k]), nt.q[k], laser)))
    return out


def test_status_tracking_when_the_truth_is_inside_the_plateau():
    ests = _episode([0.8, 0.5, -0.6, 0.002, 0.0, 0.004])
    status = [e.status for e in ests]
    assert status.count("tracking") >= 0.95 * STEPS, status
    assert all(e.nis >= 0.0 for e in ests)


def test_status_not_tracking_when_the_robot_bends_beyond_its_plateau():
    # 6 mm across the seam, 3 mm plateau: the lasers and the robot density cannot both hold
    ests = _episode([6.0, 0.0, -4.0, 0.0, 0.0, 0.0], d0_mm=3.0)
    status = [e.status for e in ests[10:]]
    assert status.count("tracking") == 0, status
    assert any(e.reason and "beyond the robot plateau" in e.reason for e in ests)


def test_one_failed_step_does_not_condemn_the_window():
    mon = _mon(window=10)
    r = mon.update(2.0e4, 4, 0.0, 0.0, 400.0)  # a wrong prior, corrected by the update
    assert r.status == "lost" and r.reason == f"laser NIS 2e+04 > {chi2.isf(1e-7, 4):.4g} at this step (dof 4)"
    assert mon.update(4.0, 4, 0.0, 0.0, 400.0).status == "tracking"
    # a persistent inconsistency adds up over the window although no single step fails
    for _ in range(10):
        r = mon.update(chi2.isf(1e-2, 4), 4, 0.0, 0.0, 400.0)
    assert r.status == "lost"


def test_weighted_moments_kernel_matches_numpy_cov():
    rng = np.random.default_rng(5)
    E = rng.normal(size=(200, 4)) @ rng.normal(size=(4, 4))
    E[7, 2] = np.nan
    w = rng.random(200)
    w /= w.sum()
    mean, C = np.empty(4), np.empty((4, 4))
    total = _ck.weighted_moments_kernel(E, w, mean, C)
    ok = np.isfinite(E).all(1)
    assert total == pytest.approx(w[ok].sum(), rel=1e-12)
    np.testing.assert_allclose(mean, np.average(E[ok], axis=0, weights=w[ok]), rtol=1e-12)
    np.testing.assert_allclose(C, np.cov(E[ok].T, aweights=w[ok], bias=True), rtol=1e-10, atol=1e-14)


def test_robot_consistency_with_a_rotation_plateau_shape_and_rotated_spread():
    # A stretches the plateau's axis x by 4 (radius 0.01 rad there becomes 0.0025 rad of Δr): an
    # error 0.005 rad about x is 0.02 in A-coordinates, 0.01 beyond the plateau; tails σ = 1e-3 rad
    A = np.diag([4.0, 1.0, 1.0])
    meas = RobotMeasurement(np.eye(4), 1e-6 * np.eye(3), 1e-6 * np.eye(3), 1.0, 0.01, A)
    T = transform_from(matrix_from_rotation_vector(np.array([0.005, 0.0, 0.0])), np.zeros(3))
    assert robot_consistency(T, np.zeros(6), meas)[1] == pytest.approx((0.01 / 4e-3) ** 2, rel=1e-6)
    # the estimate's spread is in its own frame: a tool turned 90° about z swaps x and y
    Rz = matrix_from_rotation_vector(np.array([0.0, 0.0, np.pi / 2]))
    T = transform_from(Rz, np.array([0.0, 1.5, 0.0]))
    meas = RobotMeasurement(np.eye(4), 0.01 * np.eye(3), 1e-6 * np.eye(3), 1.0, 10.0, None)
    m_t, _ = robot_consistency(T, np.r_[0.2, 0.0, 0.0, 0, 0, 0], meas)  # tool x = base y
    assert m_t == pytest.approx(0.5 ** 2 / (0.01 + 0.04), rel=1e-9)


def test_window_sum_is_the_sum_over_the_last_rows():
    """The long windows' running sums (engine.window_sum) against summing the last rows again, with unseen
    entries and a change of row size."""
    from posekit.seam.engine.window_sum import WindowSum

    rng = np.random.default_rng(3)
    X = rng.normal(size=(120, 4))
    seen = rng.random((120, 4)) > 0.2
    w = WindowSum(25)
    for t in range(len(X)):
        w.add(np.where(seen[t], X[t], np.nan), seen[t])
        lo = max(0, t - 24)
        np.testing.assert_allclose(w.sum, np.where(seen[lo:t + 1], X[lo:t + 1], 0.0).sum(axis=0), atol=1e-12)
        np.testing.assert_array_equal(w.n, seen[lo:t + 1].sum(axis=0))
    assert len(w) == 25
    w.add([1.0, 2.0], [True, False])          # another size: the window starts again
    assert len(w) == 1 and w.sum.tolist() == [1.0, 0.0] and w.n.tolist() == [1, 0]
    w.clear()
    assert len(w) == 0 and w.sum is None and w.n is None
