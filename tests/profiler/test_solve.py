"""Pose solver: exact recovery, calibrated covariance, n = 4, reversed mounting, cross-checks."""

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from posekit.errors import EstimationError
from posekit.geometry import invert_transform, se3_exp, transform_from
from posekit.profiler import (
    NoiseModel,
    bundled_gauge,
    closed_form,
    detect_corners,
    evaluate,
    render_profiles,
    sample_poses,
    solve_pose,
)
from posekit.profiler.estimate.refine import normal_equations as _normal_equations
from posekit.profiler.studies.evaluate import pose_errors

NOISELESS = NoiseModel(sigma_x_um=0.0, sigma_z_um=0.0)


def _piercing_points(gauge, T_G_F):
    """Where each ridge crosses F's plane y = 0: the exact corners, (n, 2) in F."""
    T_F_G = invert_transform(T_G_F)
    q = gauge.ridge_q @ T_F_G[:3, :3].T + T_F_G[:3, 3]
    s = gauge.ridge_s @ T_F_G[:3, :3].T
    p = q - (q[:, 1] / s[:, 1])[:, None] * s
    return p[:, [0, 2]]


@pytest.mark.parametrize("name", ["demo-4", "demo-5", "demo-7", "demo-10"])
@pytest.mark.parametrize("method", ["cf", "mle"])
def test_zero_noise_recovers_truth(name, method):
    gauge = bundled_gauge(name)
    if method == "cf" and gauge.n_corners < 5:
        pytest.skip("closed form needs n >= 5 (tested below)")
    Ts = sample_poses(gauge, 25, rng=11)
    profiles = render_profiles(gauge, Ts, NOISELESS, rng=0)
    for T, prof in zip(Ts, profiles):
        est = solve_pose(detect_corners(prof, gauge.n_corners), gauge, method=method)
        err = pose_errors(est.T_G_F, T)
        assert np.abs(err[:3]).max() < 1e-6        # mm
        assert np.abs(err[3:]).max() < 1e-7        # rad
        assert est.reprojection_um < 1e-3
        assert not est.reversed


def test_corners_are_the_ridge_piercing_points(gauge5):
    Ts = sample_poses(gauge5, 10, rng=3)
    profiles = render_profiles(gauge5, Ts, NOISELESS, rng=0)
    for T, prof in zip(Ts, profiles):
        c = detect_corners(prof, 5)
        np.testing.assert_allclose(c.points, _piercing_points(gauge5, T), atol=1e-9)


def test_noise_rmse_matches_predicted_std(gauge5):
    """5 µm noise, 250 poses: RMSE of each component within 1.5x of the predicted std."""
    ev = evaluate(gauge5, 250, NoiseModel(), seed=5)
    assert not ev.failures
    ratio = ev.rmse / ev.rms_predicted_std
    assert np.all(ratio > 1 / 1.5) and np.all(ratio < 1.5), ratio
    # normalised errors too: each error measured in its own predicted std
    assert np.all(np.abs(ev.normalized_rms - 1) < 0.5), ev.normalized_rms
    # sub-µm reprojection error, yet y and rx are weakly observable: the covariance says so
    assert np.mean(ev.reprojection_um) < 2.0
    assert ev.rms_predicted_std[1] > 5 * ev.rms_predicted_std[0]


def test_mle_beats_closed_form(gauge5):
    cf = evaluate(gauge5, 60, NoiseModel(), seed=2, method="cf")
    mle = evaluate(gauge5, 60, NoiseModel(), seed=2, method="mle")
    assert np.all(mle.rmse < cf.rmse)
    assert np.mean(mle.reprojection_um) < 0.1 * np.mean(cf.reprojection_um)


def test_closed_form_fails_cleanly_at_four_corners(gauge4):
    T = sample_poses(gauge4, 1, rng=1)[0]
    corners = detect_corners(render_profiles(gauge4, T, NoiseModel(), rng=1), 4)
    with pytest.raises(EstimationError, match=r"closed form needs at least 5 corners \(with 4, eq\. \(10\) has "
                                              r"8 equations for 9 unknowns\); use method 'mle'"):
        solve_pose(corners, gauge4, method="cf")
    with pytest.raises(EstimationError, match="at least 5 corners"):
        closed_form(corners.points, gauge4)
    est = solve_pose(corners, gauge4, method="mle")
    err = pose_errors(est.T_G_F, T)
    std = np.sqrt(np.diag(est.cov))
    assert np.all(np.abs(err) < 5 * std)


def test_reversed_mounting_is_detected(gauge5):
    """A sensor turned 180° about its z-axis sees the ridges in reverse scan order."""
    flip = transform_from(Rotation.from_euler("z", 180, degrees=True).as_matrix(), np.zeros(3))
    Ts = sample_poses(gauge5, 8, rng=4) @ flip
    profiles = render_profiles(gauge5, Ts, NoiseModel(), rng=4)
    for T, prof in zip(Ts, profiles):
        corners = detect_corners(prof, 5)
        est = solve_pose(corners, gauge5)
        assert est.reversed
        err = pose_errors(est.T_G_F, T)
        assert np.all(np.abs(err) < 5 * np.sqrt(np.diag(est.cov)))
        forced = solve_pose(corners, gauge5, mounting="reversed")
        np.testing.assert_allclose(forced.T_G_F, est.T_G_F, atol=1e-9)
        wrong = solve_pose(corners, gauge5, mounting="normal")
        assert wrong.cost > 1e3 * est.cost


def test_start_from_previous_pose(gauge5):
    Ts = sample_poses(gauge5, 2, rng=8)
    prof = render_profiles(gauge5, Ts[1], NoiseModel(), rng=8)
    corners = detect_corners(prof, 5)
    ref = solve_pose(corners, gauge5)
    streamed = solve_pose(corners, gauge5, T_init=Ts[0])
    np.testing.assert_allclose(streamed.T_G_F, ref.T_G_F, atol=1e-7)


def _residual(xi, T0_F_G, corners, gauge, L_inv):
    """Whitened reprojection residual for T_F_G = exp(xi^) T0_F_G (a NumPy re-derivation)."""
    T = se3_exp(xi) @ T0_F_G
    q = gauge.ridge_q @ T[:3, :3].T + T[:3, 3]
    s = gauge.ridge_s @ T[:3, :3].T
    p = q - (q[:, 1] / s[:, 1])[:, None] * s
    r = (corners - p[:, [0, 2]]).ravel()
    return L_inv @ r


def test_refinement_matches_scipy_least_squares(gauge5):
    """The dedicated Gauss-Newton kernel agrees with scipy's LM on the same ML problem."""
    T = sample_poses(gauge5, 1, rng=21)[0]
    corners = detect_corners(render_profiles(gauge5, T, NoiseModel(sigma_x_um=20, sigma_z_um=10), rng=21), 5)
    est = solve_pose(corners, gauge5)
    T_cf = closed_form(corners.points, gauge5)
    L_inv = np.linalg.inv(np.linalg.cholesky(corners.cov))
    T0 = invert_transform(T_cf)
    sol = least_squares(_residual, np.zeros(6), args=(T0, corners.points, gauge5, L_inv), method="lm",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    T_ls = invert_transform(se3_exp(sol.x) @ T0)
    # Same optimum: the kernel's cost is no higher, the poses differ by < 1e-3 predicted std
    # (scipy stops earlier along the weakly observable y / rx direction).
    assert est.cost <= 2 * sol.cost * (1 + 1e-9)
    assert est.cost == pytest.approx(2 * sol.cost, rel=1e-6)
    err = pose_errors(est.T_G_F, T_ls)
    assert np.all(np.abs(err) < 1e-3 * np.sqrt(np.diag(est.cov)))


def test_analytic_jacobian_matches_finite_differences(gauge5):
    T = sample_poses(gauge5, 1, rng=22)[0]
    corners = detect_corners(render_profiles(gauge5, T, NoiseModel(), rng=22), 5)
    T0 = invert_transform(closed_form(corners.points, gauge5))
    W = np.linalg.inv(corners.cov)
    H = np.empty((6, 6))
    g = np.empty(6)
    ok, cost = _normal_equations(T0[:3, :3].copy(), T0[:3, 3].copy(), corners.points, W,
                                 gauge5.ridge_q, gauge5.ridge_s, H, g)
    assert ok
    eye = np.eye(len(W))
    r0 = _residual(np.zeros(6), T0, corners.points, gauge5, eye)
    J = np.empty((len(r0), 6))
    h = 1e-6
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        J[:, k] = -(_residual(d, T0, corners.points, gauge5, eye) - _residual(-d, T0, corners.points, gauge5, eye)) / (2 * h)
    np.testing.assert_allclose(H, J.T @ W @ J, rtol=1e-5, atol=1e-6 * np.abs(H).max())
    np.testing.assert_allclose(g, J.T @ W @ r0, rtol=1e-5, atol=1e-6 * np.abs(g).max())
    assert cost == pytest.approx(r0 @ W @ r0, rel=1e-12)


def test_bad_method_and_mounting(gauge5):
    T = sample_poses(gauge5, 1, rng=1)[0]
    corners = detect_corners(render_profiles(gauge5, T, NoiseModel(), rng=1), 5)
    with pytest.raises(EstimationError, match="unknown method 'lsq'; expected one of cf, mle"):
        solve_pose(corners, gauge5, method="lsq")
    with pytest.raises(EstimationError, match="unknown mounting 'upside'"):
        solve_pose(corners, gauge5, mounting="upside")
    with pytest.raises(EstimationError, match="expected 7 corners for gauge 'demo-7', got 5"):
        solve_pose(corners, bundled_gauge("demo-7"))


def test_assumed_noise_changes_the_verdict_not_the_pose(gauge5):
    """The fit is weighted by the line fits (as the real-time server); the assumed noise sets χ² and the std."""
    T = sample_poses(gauge5, 1, rng=23)[0]
    corners = detect_corners(render_profiles(gauge5, T, NoiseModel(), rng=23), 5)
    plain = solve_pose(corners, gauge5)
    model = solve_pose(corners, gauge5, noise=NoiseModel(scale_sigma_ppm=0.0))
    twice = solve_pose(corners, gauge5, noise=NoiseModel(20, 10, scale_sigma_ppm=0.0))
    np.testing.assert_array_equal(model.T_G_F, plain.T_G_F)
    np.testing.assert_array_equal(twice.T_G_F, plain.T_G_F)
    assert plain.chi2 == plain.cost and model.cost == plain.cost
    assert twice.chi2 == pytest.approx(model.chi2 / 4, rel=1e-9)      # 2x the noise: 1/4 of chi2
    np.testing.assert_allclose(twice.cov, 4 * model.cov, rtol=1e-9)
    # the sensor's unknown scale (default 100 ppm) enters as the tolerance does: the fit's weights (a GLS
    # fit: the pose moves by a fraction of its std), χ² (lower) and a wider covariance
    scaled = solve_pose(corners, gauge5, noise=NoiseModel())
    moved = np.abs(pose_errors(scaled.T_G_F, plain.T_G_F)) / np.sqrt(np.diag(scaled.cov))
    assert np.all(moved < 0.5) and scaled.chi2 <= model.chi2 and scaled.status == model.status
    assert np.linalg.eigvalsh(scaled.cov - model.cov).min() > -1e-3 * np.abs(model.cov).max()
    assert np.all(scaled.std_rot_deg >= model.std_rot_deg) and scaled.std_rot_deg[2] > 1.5 * model.std_rot_deg[2]
    assert (plain.dof, plain.status, plain.reason) == (4, "ok", None)
