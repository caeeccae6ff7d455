"""``match --with-scale`` on drifting monocular trajectories from a generator written here (not the
project's simulator), and on real monocular ORB-SLAM trajectories: the scale's uncertainty is in
the covariance, a scale that drifts is found and the result is ``suspect``.

The generator: a smooth 3D tool path in the base frame B (mm), seen by a monocular VO whose map
has an unknown scale ``s0`` and a world frame W whose origin is at the first camera position
("near") or 5-15 m away ("far"); the VO's scale falls behind the truth linearly along the path by
``drift`` (1-3 %, either sign), plus white position noise. The truth is the Sim(3) ``(R0, t0, s0)``
of the start of the path, where W is defined. Camera and kinematics share one clock here
(``time_offset_s=0``): at 20 mm of noise the offset search's ambiguity check (a tie band of 1.5x
the best median residual) can call the offset ambiguous, which is not what this file tests.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.alignment import umeyama
from posekit.localcal.registration.formats.tum import read_tum
from posekit.localcal.registration.match import match_trajectories
from tests.localcal.synth_trajectories import TUM_DATA


def drifting_monocular(seed, drift, noise_mm, far, *, camera_hz=20.0, duration_s=40.0):
    """(camera in W, kinematic in B, R0, t0, s0): ``p_B = s0 R0 p_W + t0`` at the start of the path."""
    rng = np.random.default_rng(seed)
    f, ph, amp = rng.uniform(0.02, 0.08, (3, 3)), rng.uniform(0, 2 * np.pi, (3, 3)), rng.uniform(200, 600, (3, 3))

    def path(t):
        return (amp * np.sin(2 * np.pi * f * t[:, None, None] + ph)).sum(-1) + [1500.0, 0.0, 800.0]

    wv = rng.uniform(0.05, 0.2, 3)

    def rot(t):
        return Rotation.from_rotvec(0.3 * np.sin(t[:, None] * wv)).as_matrix()

    R0, s0 = Rotation.random(random_state=rng).as_matrix(), rng.uniform(0.5, 3.0)
    t_kin, t_cam = np.arange(0, duration_s, 0.01), np.arange(0.05, duration_s - 0.05, 1 / camera_hz)
    pB = path(t_cam)
    away = rng.normal(size=3)
    pW0 = np.zeros(3) if not far else rng.uniform(5000, 15000) * away / np.linalg.norm(away) / s0
    t0 = pB[0] - s0 * R0 @ pW0
    arc = np.r_[0, np.cumsum(np.linalg.norm(np.diff(pB, axis=0), axis=1))]
    lam = 1.0 + drift * arc / arc[-1]                      # the map's scale error grows along the path
    pW = pW0 + np.r_[np.zeros((1, 3)), np.cumsum((np.diff(pB, axis=0) @ R0) / s0 / lam[1:, None], axis=0)]
    pW = pW + rng.normal(0, noise_mm / s0, pW.shape)
    Tw = np.zeros((len(t_cam), 4, 4))
    Tw[:, :3, :3], Tw[:, :3, 3], Tw[:, 3, 3] = R0.T @ rot(t_cam), pW, 1.0
    Tb = np.zeros((len(t_kin), 4, 4))
    Tb[:, :3, :3], Tb[:, :3, 3], Tb[:, 3, 3] = rot(t_kin), path(t_kin), 1.0
    return Trajectory(t_cam, Tw), Trajectory(t_kin, Tb), R0, t0, s0


def _cases(n, seed0):
    """(drift, noise_mm, far) for n cases: three in four drift, noise 0.5-20 mm, origin near/far alternately."""
    for k in range(n):
        rng = np.random.default_rng(seed0 + k)
        drift = rng.uniform(0.01, 0.03) * rng.choice([-1, 1]) if k % 4 else 0.0
        yield seed0 + k, drift, [0.5, 2.0, 5.0, 10.0, 20.0][k % 5], bool(k % 2)


def _run(n, seed0):
    rows = []
    for seed, drift, noise, far in _cases(n, seed0):
        src, dst, R0, t0, s0 = drifting_monocular(seed, drift, noise, far)
        reg = match_trajectories(src, dst, with_scale=True, time_offset_s=0.0)   # one clock: the scale's test
        z = np.r_[np.abs(reg.t_mm - t0) / reg.std_t_mm,
                  np.abs(np.rad2deg(Rotation.from_matrix(reg.R @ R0.T).as_rotvec())) / reg.std_rot_deg,
                  abs(reg.scale - s0) / reg.std_scale]
        d = reg.scale_drift
        rows.append(dict(drift=drift, noise=noise, far=far, status=reg.status, z=float(z.max()),
                         z_drift=abs(d.relative - drift) / d.std))
    return rows


#: Cases of the study: 15 drifting, 5 without drift (was 40, 11 s of the suite; the bounds below
#: are fractions of N or a binomial tail at this N).
N_CASES = 20


@pytest.fixture(scope="module")
def study():
    return _run(N_CASES, 1000)


def test_ok_cases_are_within_3_sigma_and_drifting_ones_suspect(study):
    """Measured: seeds 1000-1019, 7 ok of 20, all 7 within 3 sigma; 13 of 15 drifting cases
    suspect (the two ok at 10-20 mm of noise); 0 of 5 without drift suspect (seeds 2000-2019 the
    same counts). With 40 cases (seeds 1000-1039): 14 ok, all within 3 sigma; 26 of 30 drifting
    suspect; 0 of 10 false. A 1 % test gives 2 or more false alarms in 5 with probability 1e-3."""
    ok = [r for r in study if r["status"] == "ok"]
    assert {r["status"] for r in study} <= {"ok", "suspect"}
    assert len(ok) >= N_CASES // 5
    assert sum(r["z"] <= 3.0 for r in ok) >= 0.85 * len(ok)
    drifting = [r for r in study if r["drift"]]
    # the drift is found wherever the noise leaves it measurable (<= 5 mm: every case)
    assert all(r["status"] == "suspect" for r in drifting if r["noise"] <= 5.0)
    assert sum(r["status"] == "suspect" for r in drifting) >= 0.8 * len(drifting)
    # without drift: at most one false alarm (the test's level is 1 %)
    assert sum(r["status"] == "suspect" for r in study if not r["drift"]) <= 1


def test_the_drift_is_measured_with_an_honest_sigma(study):
    """|measured - true drift| <= 2 sigma in >= 85 % of the cases (measured: 19 of 20, seeds
    1000-1019 and 2000-2019; of 40: 39 and 37). An honest sigma misses 2 sigma 4.6 % of the
    time: 4 or more misses in 20 then has a probability of about 1.5 %."""
    z = np.array([r["z_drift"] for r in study])
    assert np.mean(z <= 2.0) >= 0.85


def test_translation_std_includes_the_scale_when_the_origin_is_far():
    """A scale error moves t by s R mean(p_W): with W's origin 10 m away, std_t is dominated by the
    scale's std, and the rigid covariance (scale held) would be 10x too small."""
    src, dst, R0, t0, s0 = drifting_monocular(7, 0.0, 2.0, True)
    reg = match_trajectories(src, dst, with_scale=True, time_offset_s=0.0)
    lever = reg.scale * np.linalg.norm(src.positions.mean(0))
    assert np.linalg.norm(reg.std_t_mm) >= 0.5 * lever * reg.std_scale / reg.scale
    assert np.all(np.abs(reg.t_mm - t0) <= 3 * reg.std_t_mm)


# ------------------------------------------------------------------ real monocular ORB-SLAM
def _quarter_scales(src, dst, reg):
    """Independent check: a full Sim(3) (own rotation) Umeyama fit on each quarter of the pairs."""
    i, j = reg.pairs[:, 0], reg.pairs[:, 1]
    return [umeyama(src.positions[i[q]], dst.positions[j[q]], with_scale=True)[2]
            for q in np.array_split(np.arange(len(i)), 4)]


def test_real_monocular_drift_agrees_with_independent_quarter_fits():
    """fr2/desk ORB-SLAM keyframes (monocular, evo's test data): scale 2.228 +- 0.017, falling by
    1.4 % +- 0.5 % along the path (suspect); quarter-by-quarter Umeyama fits fall 2.236 -> 2.215.
    The RGB-D ORB-SLAM of the same sequence: no drift (-0.01 % +- 0.43 %), ok."""
    gt = read_tum(TUM_DATA / "fr2_desk_groundtruth.txt")
    mono = read_tum(TUM_DATA / "fr2_desk_ORB_kf_mono.txt")
    reg = match_trajectories(mono, gt, with_scale=True)
    assert reg.status == "suspect"
    assert any(r.startswith("the scale drifts along the path: -1.") for r in reg.reasons), reg.reasons
    q = _quarter_scales(mono, gt, reg)
    independent = (q[-1] - q[0]) / q[0] * 4 / 3                  # quarter centres 1/8 .. 7/8 of the path
    assert abs(reg.scale_drift.relative - independent) <= 2 * reg.scale_drift.std
    rgbd = read_tum(TUM_DATA / "fr2_desk_ORB.txt")
    reg = match_trajectories(rgbd, gt, with_scale=True)
    assert reg.status == "ok", reg.reasons
    assert abs(reg.scale_drift.relative) <= 2 * reg.scale_drift.std
    assert reg.scale == pytest.approx(0.997, abs=3 * reg.std_scale)
