"""The pair table of docs/notes/issue-27.md (not a timing benchmark): ``localcal match`` against evo
on every real pair of evo's test data.

Usage::

    python benchmarks/localcal_evo_table.py EVO_TEST_DATA     # the folder test/data of MichaelGrupp/evo

For each pair: posekit's default match (status, clock offset used, pairs, RMSE over all / kept
pairs), posekit with evo's settings (nearest stamps within 10 ms, offset 0, no outlier gate) and
evo itself (``sync.associate_trajectories(max_diff=0.01)``, Umeyama ``align``, APE translation
RMSE); KITTI files at 10 Hz.
"""

import sys
from pathlib import Path


def pairs(D):
    k = {"rate_hz": 10.0}
    return [
        ("fr1/xyz RGB-D SLAM", D / "freiburg1_xyz-rgbdslam.txt", {}, D / "freiburg1_xyz-groundtruth.txt", {}, False),
        ("fr1/xyz RGB-D SLAM drift", D / "freiburg1_xyz-rgbdslam_drift.txt", {}, D / "freiburg1_xyz-groundtruth.txt",
         {}, False),
        ("fr1/xyz drift short", D / "freiburg1_xyz-rgbdslam_drift_short.txt", {}, D / "freiburg1_xyz-groundtruth.txt",
         {}, False),
        ("fr2/desk ORB-SLAM2", D / "fr2_desk_ORB.txt", {}, D / "fr2_desk_groundtruth.txt", {}, False),
        ("fr1/xyz ORB mono (Sim3)", D / "freiburg1_xyz-ORB_kf_mono.txt", {}, D / "freiburg1_xyz-groundtruth.txt", {},
         True),
        ("fr2/desk ORB mono (Sim3)", D / "fr2_desk_ORB_kf_mono.txt", {}, D / "fr2_desk_groundtruth.txt", {}, True),
        ("KITTI 00 ORB", D / "KITTI_00_ORB.txt", k, D / "KITTI_00_gt.txt", k, False),
        ("KITTI 00 S-PTAM", D / "KITTI_00_SPTAM.txt", k, D / "KITTI_00_gt.txt", k, False),
        ("EuRoC V1_02", D / "V102.txt", {}, D / "V102_groundtruth.csv", {}, False),
        ("bag ORB-SLAM", D / "ROS_example.bag", {"topic": "ORB-SLAM"}, D / "ROS_example.bag", {"topic": "groundtruth"},
         False),
        ("bag S-PTAM", D / "ROS_example.bag", {"topic": "S-PTAM"}, D / "ROS_example.bag", {"topic": "groundtruth"}, False),
        ("nav2 amcl vs odom", D / "nav2_turtlebot.mcap", {"topic": "/amcl_pose"}, D / "nav2_turtlebot.mcap",
         {"topic": "/odom"}, False),
    ]


def _evo(traj):
    from evo.core.trajectory import PoseTrajectory3D
    T = traj.T.copy()
    T[:, :3, 3] /= 1000.0
    return PoseTrajectory3D(poses_se3=list(T), timestamps=traj.t_s.copy())


def main(folder):
    from evo.core import metrics, sync

    from posekit.errors import PosekitError
    from posekit.localcal.registration.formats import read_trajectory
    from posekit.localcal.registration.match import match_trajectories

    print("| pair | posekit default: status, offset ms, pairs, rmse all / kept mm | posekit with evo's settings: "
          "pairs, rmse all mm | evo: pairs, rmse mm |")
    print("|---|---|---|---|")
    for name, a, ka, b, kb, scale in pairs(Path(folder)):
        src, dst = read_trajectory(a, **ka), read_trajectory(b, **kb)
        try:
            r = match_trajectories(src, dst, with_scale=scale)
            ours = (f"{r.status}, {r.time_offset_s * 1000:+.1f} ({r.time_offset_source}), {r.n_pairs}, "
                    f"{r.rmse_all_mm:.2f} / {r.rmse_mm:.2f}")
        except PosekitError as exc:
            ours = f"error: {str(exc)[:80]}"
        e = match_trajectories(src, dst, with_scale=scale, max_dt_s=0.01, time_offset_s=0.0, outlier_fraction=0.0)
        rr, ee = sync.associate_trajectories(_evo(dst), _evo(src), max_diff=0.01)
        ee.align(rr, correct_scale=scale)
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((rr, ee))
        print(f"| {name} | {ours} | {e.n_pairs}, {e.rmse_all_mm:.2f} | {rr.num_poses}, "
              f"{ape.get_statistic(metrics.StatisticsType.rmse) * 1000:.2f} |")


if __name__ == "__main__":
    main(sys.argv[1])
