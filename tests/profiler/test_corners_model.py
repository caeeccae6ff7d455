"""The model-based corner detector (detect_corners with a gauge): exactness, covariance,
extra and missing segments resolved by the gauge's cross-section, failures that say why."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.errors import ConfigError, ProfileError
from posekit.geometry import transform_from
from posekit.profiler import (
    NoiseModel,
    bundled_gauge,
    detect_corners,
    nominal_pose,
    render_profiles,
    sample_poses,
    solve_pose,
)
from posekit.profiler.estimate.corner_params import CornerParams
from posekit.profiler.estimate.corners import detect_corners_unchecked, gauge_turns
from posekit.profiler.estimate.segments import expected_turns
from posekit.profiler.sim.realism import RealismModel
from posekit.profiler.sim.realism_render import true_corners

NOISELESS = NoiseModel(0.0, 0.0)


def in_scan_order(truth, points):
    return truth[::-1] if (points[0, 0] > points[-1, 0]) != (truth[0, 0] > truth[-1, 0]) else truth


def test_exact_on_noise_free_profiles(any_gauge):
    Ts = sample_poses(any_gauge, 10, rng=1)
    profiles = render_profiles(any_gauge, Ts, NOISELESS, rng=1)
    truth = true_corners(any_gauge, Ts)
    for prof, t in zip(profiles, truth):
        c = detect_corners(prof, any_gauge)
        np.testing.assert_allclose(c.points, in_scan_order(t, c.points), atol=1e-9)


def test_the_interface_is_the_rdp_detectors(gauge5):
    prof = render_profiles(gauge5, sample_poses(gauge5, 1, rng=2)[0], NoiseModel(), rng=2)
    a = detect_corners(prof, gauge5)
    b = detect_corners(prof, 5, gauge=gauge5)
    status, info, corners, cov, lines, sig, npts, cand = detect_corners_unchecked(prof, 5, CornerParams(),
                                                                                  gauge_turns(gauge5))
    assert status == 0
    for x in (b.points, corners):
        np.testing.assert_array_equal(x, a.points)
    np.testing.assert_array_equal(cov, a.cov)
    assert a.points.shape == (5, 2) and a.cov.shape == (10, 10) and a.lines.shape == (6, 3)
    assert a.sigma.shape == (6,) and a.n_points.shape == (6,) and np.all(a.n_points > 50)
    np.testing.assert_allclose(a.cov, a.cov.T)
    assert np.all(np.linalg.eigvalsh(a.cov) > 0)
    # the solver takes it as it is
    assert solve_pose(a, gauge5).status == "ok"


def test_expected_turns_alternate_for_the_bundled_gauges(any_gauge):
    t = np.degrees(expected_turns(any_gauge))
    assert np.all(np.abs(t) > 20) and np.all(np.sign(t[:-1]) != np.sign(t[1:]))
    np.testing.assert_array_equal(gauge_turns(any_gauge), expected_turns(any_gauge))


def test_corner_covariance_matches_the_scatter(gauge5):
    """Over 300 noise draws at one pose, the corners scatter as their covariance predicts."""
    T = nominal_pose(gauge5)
    profiles = render_profiles(gauge5, np.repeat(T[None], 300, axis=0), NoiseModel(), rng=9)
    res = [detect_corners(p, gauge5) for p in profiles]
    pts = np.array([r.points.ravel() for r in res])
    emp = np.cov(pts.T)
    pred = np.mean([r.cov for r in res], axis=0)
    ratio = np.diag(emp) / np.diag(pred)
    assert np.all((ratio > 0.7) & (ratio < 1.4)), ratio           # ±~16 % at 2σ from 300 samples
    corr_pred = pred[0, 2] / np.sqrt(pred[0, 0] * pred[2, 2])
    corr_emp = emp[0, 2] / np.sqrt(emp[0, 0] * emp[2, 2])
    assert abs(corr_emp - corr_pred) < 0.2


def test_more_accurate_than_rdp_on_ideal_profiles(any_gauge):
    """No trim of 10 % per segment, only a band at the ridges: more returns, smaller errors."""
    Ts = sample_poses(any_gauge, 150, rng=3)
    profiles = render_profiles(any_gauge, Ts, NoiseModel(), rng=3)
    truth = true_corners(any_gauge, Ts)
    err_model, err_rdp = [], []
    for prof, t in zip(profiles, truth):
        a = detect_corners(prof, any_gauge).points
        b = detect_corners(prof, any_gauge.n_corners).points
        err_model.append(a - in_scan_order(t, a))
        err_rdp.append(b - in_scan_order(t, b))
    rms_model = np.sqrt(np.mean(np.square(err_model)))
    rms_rdp = np.sqrt(np.mean(np.square(err_rdp)))
    assert rms_model < 0.95 * rms_rdp, (rms_model, rms_rdp)


def test_noisier_sensor_still_detected_with_honest_covariance(gauge5):
    Ts = sample_poses(gauge5, 100, rng=4)
    profiles = render_profiles(gauge5, Ts, NoiseModel(sigma_x_um=40, sigma_z_um=20, outlier_rate=0.005,
                                                      dropouts_per_profile=2), rng=4)
    truth = true_corners(gauge5, Ts)
    z = []
    for prof, t in zip(profiles, truth):
        c = detect_corners(prof, gauge5)
        z.append((c.points - in_scan_order(t, c.points)).ravel() / np.sqrt(np.diag(c.cov)))
    assert 0.85 < np.sqrt(np.mean(np.square(z))) < 1.2


def test_an_object_on_a_face_is_left_out(gauge5):
    """A 5 mm bump on face 2: the RDP detector reports an extra corner, the model skips it."""
    T = sample_poses(gauge5, 1, rng=3)[0]
    prof = render_profiles(gauge5, T, NOISELESS, rng=3)
    truth = true_corners(gauge5, T)
    x_mid = 0.5 * (truth[1, 0] + truth[2, 0])
    bumped = prof.copy()
    bumped[np.abs(bumped[:, 0] - x_mid) < 2.0, 1] -= 5.0
    with pytest.raises(ProfileError, match="extra corner"):
        detect_corners(bumped, 5)
    c = detect_corners(bumped, gauge5)
    np.testing.assert_allclose(c.points, in_scan_order(truth, c.points), atol=1e-9)


def test_plate_and_fixture_in_view_are_background(gauge5):
    Ts = sample_poses(gauge5, 10, rng=5)
    rm = RealismModel(plate_depth_mm=8.0, fixture_height_mm=(3.0, 14.0))
    profiles = render_profiles(gauge5, Ts, NOISELESS, rng=5, realism=rm)
    truth = true_corners(gauge5, Ts)
    for prof, t in zip(profiles, truth):
        c = detect_corners(prof, gauge5)
        np.testing.assert_allclose(c.points, in_scan_order(t, c.points), atol=1e-9)


def test_sensor_mounted_the_other_way_round(gauge5):
    """Yawed 180°: the faces come in reverse order; the corners are found, in scan order."""
    T0 = nominal_pose(gauge5)
    R = T0[:3, :3] @ Rotation.from_euler("z", 180, degrees=True).as_matrix()
    T = transform_from(R, T0[:3, 3])
    prof = render_profiles(gauge5, T, NoiseModel(), rng=6)
    c = detect_corners(prof, gauge5)
    truth = true_corners(gauge5, T)
    assert truth[0, 0] > truth[-1, 0]                      # the ridges run against the scan
    assert np.abs(c.points - truth[::-1]).max() < 0.01
    assert solve_pose(c, gauge5).reversed


def test_a_profile_handed_over_backwards(gauge5):
    prof = render_profiles(gauge5, nominal_pose(gauge5), NOISELESS, rng=0)
    a = detect_corners(prof, gauge5).points
    b = detect_corners(prof[::-1], gauge5).points
    np.testing.assert_allclose(b[::-1], a, atol=1e-9)


def test_missing_corner_says_which(gauge5):
    prof = render_profiles(gauge5, nominal_pose(gauge5), NoiseModel(), rng=0)
    cut = prof.copy()
    cut[: int(0.6 * len(cut))] = np.nan
    with pytest.raises(ProfileError, match=r"expected 5 corners for gauge 'demo-5', found \d \(at x = .*\); "
                                           r"missing corner\(s\): the returns span"):
        detect_corners(cut, gauge5)
    with pytest.raises(ProfileError, match=r"^profile has no valid points \(every return is NaN\)$"):
        detect_corners(np.full((3200, 2), np.nan), gauge5)


def test_a_gauge_with_more_faces_than_the_file_is_refused():
    """demo-7's profile read with demo-5's file: a face continues past the outer face."""
    g7, g5 = bundled_gauge("demo-7"), bundled_gauge("demo-5")
    for prof in render_profiles(g7, sample_poses(g7, 10, rng=7), NoiseModel(), rng=7):
        with pytest.raises(ProfileError, match=r"expected 5 corners for gauge 'demo-5', found an extra corner at "
                                               r"x = -?\d+\.\d\d mm, z = \d+\.\d\d mm \(a face turning \d+ deg"):
            detect_corners(prof, g5)


def test_faces_that_turn_the_wrong_way_do_not_match(gauge5):
    """Depth mirrored: every ridge becomes a valley; no assignment fits the gauge."""
    prof = render_profiles(gauge5, nominal_pose(gauge5), NoiseModel(), rng=8)
    flipped = prof.copy()
    flipped[:, 1] = 2 * np.nanmean(prof[:, 1]) - prof[:, 1]
    with pytest.raises(ProfileError, match=r"no 6 of the profile's \d+ straight segments turn like the gauge's "
                                           r"faces"):
        detect_corners(flipped, gauge5)


def test_noise_is_not_a_gauge(gauge5):
    rng = np.random.default_rng(9)
    junk = np.column_stack([np.linspace(-80, 80, 3200), 440 + rng.normal(0, 3.0, 3200)])
    with pytest.raises(ProfileError, match="expected 5 corners for gauge 'demo-5'"):
        detect_corners(junk, gauge5)


def test_scale_tolerance_adds_a_common_term(gauge5):
    prof = render_profiles(gauge5, nominal_pose(gauge5), NoiseModel(), rng=10)
    a = detect_corners(prof, gauge5)
    b = detect_corners(prof, gauge5, CornerParams(scale_tolerance_ppm=100.0))
    p = a.points
    jx = np.zeros(10)
    jz = np.zeros(10)
    jx[0::2] = p[:, 0]
    jz[1::2] = p[:, 1] - 442.5
    np.testing.assert_allclose(b.cov - a.cov, 1e-8 * (np.outer(jx, jx) + np.outer(jz, jz)), atol=1e-15)
    c = detect_corners(prof, gauge5, CornerParams(face_tilt_tolerance_deg=0.01))
    assert np.all(np.diag(c.cov) > np.diag(a.cov))


@pytest.mark.parametrize("kwargs", [{"band_mm": -1.0}, {"min_segment_points": 1}, {"seg_tol_mm": np.nan}])
def test_bad_parameters(kwargs):
    with pytest.raises(ConfigError, match="corner parameters"):
        CornerParams(**kwargs)


def test_params_do_not_change_the_rdp_detector(gauge5):
    """The model's parameters leave the RDP path alone (the paper's pipeline, unchanged)."""
    prof = render_profiles(gauge5, nominal_pose(gauge5), NoiseModel(), rng=11)
    a = detect_corners(prof, 5).points
    b = detect_corners(prof, 5, replace(CornerParams(), band_mm=3.0, seg_tol_mm=0.2)).points
    np.testing.assert_array_equal(a, b)
