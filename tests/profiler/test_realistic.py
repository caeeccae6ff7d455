"""The model-based corner detector on the simulator's realistic profiles, defect by defect.

Each defect of :class:`~posekit.profiler.sim.realism.RealismModel` (its realistic magnitude,
alone) and all of them together, over the bundled gauges and random ones: the share of
profiles estimated, the corners' errors against the as-built truth in units of their own
standard deviation, and the pose errors in units of the solver's predicted standard
deviation. The estimator is told what a user would know: the gauge's tolerance
(``Gauge.tolerance_um``, the faces' offsets), the faces' tilt tolerance and the sensor's
scale tolerance (:class:`CornerParams`).
"""

from dataclasses import dataclass, replace

import numpy as np
import pytest

from posekit.errors import PosekitError
from posekit.profiler import NoiseModel, render_profiles, sample_poses, solve_pose
from posekit.profiler.estimate.corner_params import CornerParams
from posekit.profiler.estimate.corners import detect_corners
from posekit.profiler.sim.realism import DEFECTS, RealismModel, build_as_built
from posekit.profiler.sim.realism_render import true_corners
from posekit.profiler.studies.evaluate import pose_errors
from tests.profiler.test_realistic_generator import measurement_gauges

REALISTIC = RealismModel.realistic()


@dataclass
class Measured:
    """What a batch of profiles gave."""

    estimated: int = 0
    total: int = 0
    corner_z: list = None        # corner error / its std, every coordinate
    pose_z: list = None          # pose error / predicted std, (k, 6)
    failures: list = None

    @property
    def rate(self) -> float:
        return self.estimated / self.total

    @property
    def corner_rms(self) -> float:
        return float(np.sqrt(np.mean(np.concatenate(self.corner_z) ** 2)))

    @property
    def pose_rms(self) -> np.ndarray:
        return np.sqrt(np.mean(np.array(self.pose_z) ** 2, axis=0))


def in_scan_order(truth, points):
    """The truth (ridge order) in the detector's scan order."""
    return truth[::-1] if (points[0, 0] > points[-1, 0]) != (truth[0, 0] > truth[-1, 0]) else truth


def estimate_one(profile, gauge, tolerant, params, truth, T_true, out: Measured):
    """Detect, solve and score one profile into ``out``."""
    out.total += 1
    try:
        corners = detect_corners(profile, gauge, params)
        est = solve_pose(corners, tolerant)
    except PosekitError as exc:
        out.failures.append(f"{gauge.name}: {exc}")
        return
    out.estimated += 1
    # corners against the truth (what the sensor, scale error and all, should report) with
    # their noise-only covariance
    plain = detect_corners(profile, gauge)
    std = np.sqrt(np.diag(plain.cov)).reshape(-1, 2)
    out.corner_z.append(((plain.points - in_scan_order(truth, plain.points)) / std).ravel())
    out.pose_z.append(pose_errors(est.T_G_F, T_true) / np.sqrt(np.diag(est.cov)))


def told(realism: RealismModel):
    """The corner parameters of an estimator told the sensor's and the gauge's tolerances."""
    return CornerParams(face_tilt_tolerance_deg=realism.face_tilt_deg,
                        scale_tolerance_ppm=max(abs(realism.scale_x_ppm), abs(realism.scale_z_ppm)))


def measure_simulator(realism: RealismModel, builds: int, poses: int, seed: int) -> Measured:
    """``builds`` as-built gauges of each measurement gauge, ``poses`` profiles of each."""
    rng = np.random.default_rng(seed)
    out = Measured(corner_z=[], pose_z=[], failures=[])
    params = told(realism)
    for gauge in measurement_gauges():
        tolerant = replace(gauge, tolerance_um=realism.face_offset_um)
        for _ in range(builds):
            Ts = sample_poses(gauge, poses, rng)
            scene = build_as_built(gauge, realism, rng)
            profiles = render_profiles(gauge, Ts, NoiseModel(), rng, realism=scene)
            truth = true_corners(scene.gauge, Ts)
            # the sensor's scale error moves what it measures: the corners it should report
            s_x, s_z = 1 + realism.scale_x_ppm * 1e-6, 1 + realism.scale_z_ppm * 1e-6
            truth = np.stack([truth[..., 0] * s_x, 442.5 + (truth[..., 1] - 442.5) * s_z], axis=-1)
            for k in range(poses):
                estimate_one(profiles[k], gauge, tolerant, params, truth[k], Ts[k], out)
    return out


# Machining error is one draw per gauge: its cases need many gauges, few poses each.
CASES = {d: (REALISTIC.only(d), 3, 12) for d in DEFECTS}
CASES["machining"] = (REALISTIC.only("machining"), 16, 2)
CASES["all"] = (REALISTIC, 16, 2)


@pytest.mark.parametrize("defect", list(CASES))
def test_detection_and_honest_uncertainty_per_defect(defect):
    realism, builds, poses = CASES[defect]
    m = measure_simulator(realism, builds, poses, seed=11)
    assert m.total >= 256
    assert m.rate >= 0.99, m.failures[:3]
    # corners: unbiased at their own noise level (χ with many dof: RMS 1 ± a few %)
    assert 0.85 < m.corner_rms < 1.15, m.corner_rms
    # poses: the predicted std is honest (neither optimistic nor inflated)
    assert np.all(m.pose_rms < 1.2), m.pose_rms
    assert np.all(m.pose_rms > 0.7), m.pose_rms


def test_the_rdp_detector_fails_on_the_same_profiles(gauge5):
    """What the defects do to the paper's pipeline: the realistic set breaks it."""
    rng = np.random.default_rng(3)
    Ts = sample_poses(gauge5, 40, rng)
    profiles = render_profiles(gauge5, Ts, NoiseModel(), rng, realism=REALISTIC)
    rdp_ok = model_ok = 0
    for prof in profiles:
        try:
            detect_corners(prof, gauge5.n_corners)
            rdp_ok += 1
        except PosekitError:
            pass
        model_ok += len(detect_corners(prof, gauge5).points) == 5
    assert rdp_ok <= 4 and model_ok == 40


def test_realistic_detection_matches_the_truth_to_micrometres(gauge5):
    """Corner by corner on the realistic set: a few µm off the as-built truth, not more."""
    rng = np.random.default_rng(4)
    Ts = sample_poses(gauge5, 30, rng)
    scene = build_as_built(gauge5, REALISTIC.only("rounded", "chamfer", "fixture", "multipath", "dropouts"), rng)
    profiles = render_profiles(gauge5, Ts, NoiseModel(), rng, realism=scene)
    truth = true_corners(scene.gauge, Ts)
    err = np.array([np.abs(c.points - in_scan_order(t, c.points)).max()
                    for c, t in ((detect_corners(p, gauge5), t) for p, t in zip(profiles, truth))])
    assert np.median(err) < 0.006 and err.max() < 0.02, err.max()
