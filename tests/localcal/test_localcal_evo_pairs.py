"""``localcal match`` on every real pair of evo's test data kept in tests/data (TUM RGB-D, KITTI 00,
EuRoC V1_02, a nav2 TurtleBot bag), against evo itself on the same files.

With evo's settings (nearest stamps within 10 ms, no clock offset) posekit gives evo's pairs,
transform and RMSE over all pairs; with its own defaults every pair matches (no "no overlapping
timestamps"), and the JSON says what it decided (offset taken as 0, duplicates dropped).
"""

from pathlib import Path

import numpy as np
import pytest

from posekit.localcal.registration.formats import read_trajectory
from posekit.localcal.registration.match import match_trajectories
from tests.localcal.synth_trajectories import TUM_DATA

evo = pytest.importorskip("evo")
from evo.core import metrics, sync  # noqa: E402
from evo.core.trajectory import PoseTrajectory3D  # noqa: E402

EVO = Path(__file__).resolve().parents[1] / "data" / "evo"

#: name -> (camera file, its read options, reference file, its options, with_scale)
PAIRS = {
    "fr1/xyz RGB-D SLAM": (TUM_DATA / "freiburg1_xyz-rgbdslam.txt", {}, TUM_DATA / "freiburg1_xyz-groundtruth.txt", {},
                           False),
    "fr2/desk ORB-SLAM2": (TUM_DATA / "fr2_desk_ORB.txt", {}, TUM_DATA / "fr2_desk_groundtruth.txt", {}, False),
    "fr1/xyz ORB mono": (TUM_DATA / "freiburg1_xyz-ORB_kf_mono.txt", {}, TUM_DATA / "freiburg1_xyz-groundtruth.txt",
                         {}, True),
    "fr2/desk ORB mono": (TUM_DATA / "fr2_desk_ORB_kf_mono.txt", {}, TUM_DATA / "fr2_desk_groundtruth.txt", {}, True),
    "KITTI 00 S-PTAM": (EVO / "KITTI_00_SPTAM_first2000.txt", {"rate_hz": 10.0}, EVO / "KITTI_00_gt_first2000.txt",
                        {"rate_hz": 10.0}, False),
    "EuRoC V1_02": (EVO / "V102.txt", {}, EVO / "V102_groundtruth_at_estimate_stamps.csv", {}, False),
    "nav2 amcl vs odom": (EVO / "nav2_turtlebot.mcap", {"topic": "/amcl_pose"}, EVO / "nav2_turtlebot.mcap",
                          {"topic": "/odom"}, False),
}


def _read(name):
    cam, kc, ref, kr, scale = PAIRS[name]
    return read_trajectory(cam, **kc), read_trajectory(ref, **kr), scale


def _evo(traj):
    """A posekit trajectory (mm) as an evo trajectory (m)."""
    T = traj.T.copy()
    T[:, :3, 3] /= 1000.0
    return PoseTrajectory3D(poses_se3=list(T), timestamps=traj.t_s.copy())


def _evo_ape(cam, ref, scale):
    """evo's way: nearest stamps within 10 ms (no offset), Umeyama, APE translation RMSE."""
    r, e = sync.associate_trajectories(_evo(ref), _evo(cam), max_diff=0.01)
    R, t, s = e.align(r, correct_scale=scale)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((r, e))
    return r.num_poses, R, t * 1000.0, s, ape.get_statistic(metrics.StatisticsType.rmse) * 1000.0


@pytest.mark.parametrize("name", list(PAIRS))
def test_default_match_succeeds_on_every_real_pair(name):
    cam, ref, scale = _read(name)
    reg = match_trajectories(cam, ref, with_scale=scale, names=("cam", "ref"))
    assert reg.status in ("ok", "suspect")
    assert reg.n_pairs >= 30 and reg.pairs_used + reg.pairs_dropped == reg.n_pairs
    assert np.all(np.isfinite(reg.std_t_mm))
    if reg.time_offset_source == "zero":
        assert reg.time_offset_s == 0.0 and any("does not differ from 0 at the 1% level" in n for n in reg.notes)


@pytest.mark.parametrize("name", list(PAIRS))
def test_evo_settings_give_evos_pairs_transform_and_rmse(name):
    """Same pairs, R, t (and scale) and RMSE over all pairs as evo; V1_02 after its 4 repeated
    stamps (evo pairs both poses of a repeated stamp with one reference pose; posekit keeps the last)."""
    cam, ref, scale = _read(name)
    reg = match_trajectories(cam, ref, with_scale=scale, max_dt_s=0.01, time_offset_s=0.0, outlier_fraction=0.0)
    if name == "EuRoC V1_02":
        assert reg.duplicate_stamps == 4
        assert reg.notes == ("src: 4 poses with a repeated timestamp dropped (the last pose of each stamp kept)",)
        keep = np.r_[cam.t_s[1:] != cam.t_s[:-1], True]
        cam = type(cam)(cam.t_s[keep], cam.T[keep])
    n, R, t, s, rmse = _evo_ape(cam, ref, scale)
    assert reg.n_pairs == n
    if reg.pairs_dropped == 0:                         # evo keeps every pair: the same fit
        np.testing.assert_allclose(reg.R, R, atol=1e-9)
        np.testing.assert_allclose(reg.t_mm, t, atol=1e-6)
        assert reg.scale == pytest.approx(s, rel=1e-9)
    assert reg.rmse_all_mm == pytest.approx(rmse, rel=1e-9)


def test_kitti_sptam_offset_stays_in_its_search_and_pairs_every_frame():
    """At 3.7 m of drift the positions put the clock offset at +0.13-0.2 s, not different from 0
    at the 1 % level: posekit 0.x paired no frame (0.1 s frames, 0.02 s window) and failed."""
    cam, ref, _ = _read("KITTI 00 S-PTAM")
    reg = match_trajectories(cam, ref)
    assert (reg.time_offset_s, reg.time_offset_source, reg.n_pairs) == (0.0, "zero", 2000)
    assert reg.time_offset_std_s > abs(reg.time_offset_estimate_s) / 2.576
    for max_offset in (0.05, 0.3):
        reg = match_trajectories(cam, ref, max_offset_s=max_offset)
        assert abs(reg.time_offset_estimate_s) <= max_offset
        assert reg.n_pairs == 2000
