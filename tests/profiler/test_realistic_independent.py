"""The model-based corner detector on profiles posekit's simulator did not make.

The generator of tests/profiler/test_realistic_generator.py cuts the gauge analytically
and adds its own 2D defects; the detector, tuned on the simulator, must do as well here:
every profile estimated, corners within their own noise of the truth, pose errors within
the predicted uncertainty.
"""

from dataclasses import replace

import numpy as np
import pytest

from posekit.errors import PosekitError
from posekit.profiler.estimate.corner_params import CornerParams
from posekit.profiler.estimate.corners import detect_corners
from tests.profiler.test_realistic import Measured, estimate_one, in_scan_order
from tests.profiler.test_realistic_generator import (
    ONE_EACH,
    Defects,
    as_built,
    generate,
    measurement_gauges,
    random_pose,
)


def measure_independent(defects: Defects, builds: int, poses: int, seed: int) -> Measured:
    rng = np.random.default_rng(seed)
    out = Measured(corner_z=[], pose_z=[], failures=[])
    params = CornerParams(scale_tolerance_ppm=defects.scale_ppm)
    for gauge in measurement_gauges():
        tolerant = replace(gauge, tolerance_um=defects.offset_um)
        for _ in range(builds):
            built = as_built(gauge, defects.offset_um, rng)
            for _ in range(poses):
                T = random_pose(gauge, rng)
                profile, truth = generate(built, T, defects, rng)
                estimate_one(profile, gauge, tolerant, params, truth, T, out)
    return out


CASES = {name: (d, 3, 12) for name, d in ONE_EACH.items()}
CASES["machining"] = (ONE_EACH["machining"], 16, 2)
CASES["all"] = (ONE_EACH["all"], 16, 2)


@pytest.mark.parametrize("defect", list(CASES))
def test_detection_and_honest_uncertainty_on_independent_profiles(defect):
    defects, builds, poses = CASES[defect]
    m = measure_independent(defects, builds, poses, seed=21)
    assert m.total >= 256
    assert m.rate >= 0.99, m.failures[:3]
    assert 0.85 < m.corner_rms < 1.15, m.corner_rms
    assert np.all(m.pose_rms < 1.2), m.pose_rms
    assert np.all(m.pose_rms > 0.7), m.pose_rms


def test_noise_free_independent_profiles_give_exact_corners():
    """Sharp, noise-free sections: the corners to a fraction of a micrometre."""
    rng = np.random.default_rng(5)
    clean = Defects(noise_x_um=0.0, noise_z_um=0.0)
    for gauge in measurement_gauges():
        for _ in range(3):
            profile, truth = generate(gauge, random_pose(gauge, rng), clean, rng)
            c = detect_corners(profile, gauge)
            assert np.abs(c.points - in_scan_order(truth, c.points)).max() < 1e-6


def test_independent_profiles_in_reverse_scan_order(gauge5):
    """A profile handed over right to left: the same corners, reversed (the data-driven trims
    may keep a return more or less: within a standard deviation of each other)."""
    rng = np.random.default_rng(6)
    for _ in range(5):
        profile, truth = generate(gauge5, random_pose(gauge5, rng), ONE_EACH["all"], rng)
        a = detect_corners(profile, gauge5)
        b = detect_corners(profile[::-1], gauge5)
        std = np.sqrt(np.diag(a.cov)).reshape(-1, 2)
        assert np.all(np.abs(b.points[::-1] - a.points) < std)
        assert np.all(np.abs(a.points - in_scan_order(truth, a.points)) < 5 * std)


def test_the_rdp_detector_fails_on_independent_realistic_profiles(gauge5):
    rng = np.random.default_rng(7)
    failed = 0
    for _ in range(20):
        profile, _ = generate(gauge5, random_pose(gauge5, rng), ONE_EACH["all"], rng)
        try:
            detect_corners(profile, gauge5.n_corners)
        except PosekitError:
            failed += 1
        assert detect_corners(profile, gauge5).points.shape == (5, 2)
    assert failed >= 18


def test_verdict_on_the_independent_generator():
    """Both failure kinds of the verdict on profiles the project's simulator did not make:
    good data almost never suspect (and 2-sigma coverage near 95 %); a wrong gauge file, 3x the
    assumed noise, or faces 30 um off an untoleranced file almost never ok. Measured with 60
    profiles per gauge: good 0 % suspect, coverage 0.946-0.967; wrong file 0 % ok; 3x noise
    0 % ok; faces off 3.1 % ok. The generator's sensor has no scale error here, and the estimator is
    told so (``scale_sigma_ppm=0``)."""
    from posekit.errors import PosekitError
    from posekit.geometry import rotation_vector_from_matrix
    from posekit.profiler import estimate_pose
    from posekit.profiler.gauge.design import random_gauge
    from posekit.profiler.sensor import NoiseModel
    from tests.profiler.test_realistic_generator import Defects, as_built, generate, measurement_gauges, random_pose

    rng = np.random.default_rng(7)
    gauges = measurement_gauges()

    def statuses(pairs, defects, per_gauge=20, truth_out=None, noise=NoiseModel(scale_sigma_ppm=0.0)):
        out = []
        for true, filed in pairs:
            for _ in range(per_gauge):
                T = random_pose(true, rng)
                prof, _ = generate(true, T, defects, rng)
                try:
                    _, est = estimate_pose(prof, filed, noise=noise)
                except PosekitError:
                    out.append("error")
                    continue
                out.append(est.status)
                if truth_out is not None and est.status == "ok":
                    err = np.concatenate([est.T_G_F[:3, 3] - T[:3, 3],
                                          rotation_vector_from_matrix(est.T_G_F[:3, :3] @ T[:3, :3].T)])
                    std = np.concatenate([np.asarray(est.std_t_um) * 1e-3, np.radians(est.std_rot_deg)])
                    truth_out.append(np.abs(err) <= 2 * std)
        return np.array(out)

    inside = []
    good = statuses([(g, g) for g in gauges], Defects(), truth_out=inside)
    assert np.mean(good == "suspect") <= 0.02 and np.all(good != "error")
    cover = np.mean(inside, axis=0)
    assert np.all(np.abs(cover - 0.954) < 4 * np.sqrt(0.954 * 0.046 / len(inside))), cover
    five = [g for g in gauges if g.n_corners == 5]
    assert np.all(statuses([(g, random_gauge(5, 3)) for g in five], Defects()) != "ok")
    assert np.all(statuses([(g, g) for g in gauges], Defects(noise_x_um=30.0, noise_z_um=15.0)) != "ok")
    off = statuses([(as_built(g, 30.0, np.random.default_rng(i)), g) for i, g in enumerate(gauges)], Defects())
    assert np.mean(off == "ok") <= 0.1
    # the default allowance for an uncalibrated sensor's scale (100 ppm) costs the one-profile test a little
    # power (measured 10.6 % ok); a batch of them is caught by the gauge-file test (test_gauge_check.py)
    off = statuses([(as_built(g, 30.0, np.random.default_rng(i)), g) for i, g in enumerate(gauges)], Defects(),
                   noise=NoiseModel())
    assert np.mean(off == "ok") <= 0.2
