"""Corner detection: exact corners, robustness to spikes and dropouts, covariance, failures."""

import numpy as np
import pytest

from posekit.errors import ProfileError
from posekit.geometry import rdp
from posekit.profiler import NoiseModel, detect_corners, nominal_pose, render_profiles, sample_poses
from posekit.profiler.estimate.corner_params import CornerParams
from posekit.profiler.estimate.corners import detect_corners_unchecked

NOISELESS = NoiseModel(sigma_x_um=0.0, sigma_z_um=0.0)


def test_candidates_match_plain_rdp(gauge5):
    """The deviation-ordered candidates are what RDP keeps at the corner tolerance."""
    Ts = sample_poses(gauge5, 10, rng=2)
    profiles = render_profiles(gauge5, Ts, NoiseModel(), rng=2)
    p = CornerParams()
    for prof in profiles:
        status, info, corners, cov, lines, sig, npts, cand = detect_corners_unchecked(prof, 5, p)
        assert status == 0
        valid = prof[np.all(np.isfinite(prof), axis=1)]
        keep = rdp(valid, p.min_corner_mm)
        assert len(keep) == 5 + 2
        np.testing.assert_array_equal(valid[keep[1:-1]], cand[:5, :2])
        # and the refined corners lie within a few points of them
        assert np.abs(corners - cand[:5, :2]).max() < 0.5


def test_survives_spikes_and_dropouts(gauge5):
    Ts = sample_poses(gauge5, 40, rng=7)
    clean = render_profiles(gauge5, Ts, NoiseModel(), rng=7)
    dirty = render_profiles(gauge5, Ts, NoiseModel(outlier_rate=0.01, dropouts_per_profile=3), rng=7)
    n_spikes = 0
    for a, b in zip(clean, dirty):
        ca = detect_corners(a, 5)
        cb = detect_corners(b, 5)
        n_spikes += np.sum(np.abs(a[:, 1] - b[:, 1]) > 0.25)
        std = np.sqrt(np.diag(ca.cov)).reshape(5, 2)
        # spikes and short gaps move a corner by less than 4 of its own standard deviations
        assert np.all(np.abs(cb.points - ca.points) < 4 * std + 1e-4)
    assert n_spikes > 200       # the test really had spikes in it


def test_a_spike_biases_plain_regression_but_not_the_robust_fit(gauge5):
    T = nominal_pose(gauge5)
    prof = render_profiles(gauge5, T, NOISELESS, rng=0)
    truth = detect_corners(prof, 5).points
    bad = prof.copy()
    valid = np.flatnonzero(np.isfinite(bad[:, 0]))
    # a 0.15 mm bump of 3 points inside face 2: under the spike threshold, over 4 sigma
    i = valid[len(valid) // 2]
    bad[i:i + 3, 1] += 0.15
    got = detect_corners(bad, 5)
    np.testing.assert_allclose(got.points, truth, atol=1e-6)


def test_corner_covariance_matches_the_scatter(gauge5):
    """Over 300 noise draws at one pose, the corners scatter as their covariance predicts."""
    T = nominal_pose(gauge5)
    profiles = render_profiles(gauge5, np.repeat(T[None], 300, axis=0), NoiseModel(), rng=9)
    res = [detect_corners(p, 5) for p in profiles]
    pts = np.array([r.points.ravel() for r in res])
    emp = np.cov(pts.T)
    pred = np.mean([r.cov for r in res], axis=0)
    ratio = np.diag(emp) / np.diag(pred)
    # variance estimates from 300 samples: ±~16 % at 2 sigma
    assert np.all((ratio > 0.7) & (ratio < 1.4)), ratio
    # neighbouring corners share a line: the predicted correlation shows in the scatter
    corr_pred = pred[0, 2] / np.sqrt(pred[0, 0] * pred[2, 2])
    corr_emp = emp[0, 2] / np.sqrt(emp[0, 0] * emp[2, 2])
    assert abs(corr_emp - corr_pred) < 0.2


def test_all_nan_profile():
    with pytest.raises(ProfileError, match=r"profile has no valid points \(every return is NaN\)"):
        detect_corners(np.full((3200, 2), np.nan), 5)


def test_missing_corner_says_which(gauge5):
    T = nominal_pose(gauge5)
    prof = render_profiles(gauge5, T, NoiseModel(), rng=0)
    valid = np.flatnonzero(np.isfinite(prof[:, 0]))
    cut = prof.copy()
    cut[valid[-len(valid) // 4]:] = np.nan          # the right quarter of the gauge is gone
    with pytest.raises(ProfileError, match=r"expected 5 corners for gauge 'demo-5', found 4 \(at x = \[.*\] mm\); "
                                           r"missing corner\(s\): the returns span x = -?\d+\.\d\.\.-?\d+\.\d mm"):
        detect_corners(cut, 5, gauge_name="demo-5")


def test_extra_corner_says_where(gauge5):
    T = nominal_pose(gauge5)
    prof = render_profiles(gauge5, T, NoiseModel(), rng=0)
    valid = np.flatnonzero(np.isfinite(prof[:, 0]))
    bump = prof.copy()
    mid = valid[int(0.1 * len(valid))]                 # inside face 0
    bump[mid:mid + 40, 1] -= np.linspace(0, 2.0, 40)    # a 2 mm ramp: an object on the face
    bump[mid + 40:mid + 80, 1] -= np.linspace(2.0, 0, 40)
    x_bump = prof[mid + 40, 0]
    with pytest.raises(ProfileError, match=r"found an extra corner at x = (-?\d+\.\d\d) mm") as info:
        detect_corners(bump, 5, gauge_name="demo-5")
    x_reported = float(str(info.value).split("x = ")[1].split(" mm")[0])
    assert abs(x_reported - x_bump) < 5.0


def test_bad_shapes():
    with pytest.raises(ProfileError, match=r"expected shape \(N, 2\)"):
        detect_corners(np.zeros((10, 3)), 5)
    with pytest.raises(ProfileError, match="profile is empty"):
        detect_corners(np.zeros((0, 2)), 5)
    with pytest.raises(ProfileError, match="infinite values"):
        detect_corners(np.array([[0.0, np.inf]] * 10), 5)
