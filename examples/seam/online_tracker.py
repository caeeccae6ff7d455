"""Feed the seam tracker one sample at a time, as a cell's control loop would.

Usage (a recorded episode, e.g. from `posekit seam simulate --save-log LOGDIR --out RUN`)::

    python examples/seam/online_tracker.py LOGDIR

Here the samples come from the log's rows; in a cell they come from the robot controller (reference
and measured joints), the wrist force sensor and the laser seam trackers, within the sensor period.
"""

import sys

import numpy as np

from posekit.seam import SeamTracker, read_episode_log


def main(logdir: str) -> None:
    log = read_episode_log(logdir)                      # setup.yaml + seam.csv + log.csv (checked)
    tracker = SeamTracker(log.config, log.seam_mm, seed=log.setup.seed, seam_normal=log.setup.seam_normal)
    worst = 0.0
    for k in range(len(log.time_s)):                    # one call per sample
        est = tracker.step(log.time_s[k], log.qref[k], log.q[k], log.force_tool_n[k],
                           laser_mm=log.laser_mm[k] if log.laser_mm.shape[1] else None)
        worst = max(worst, est.step_ms)
        if k % 100 == 0:
            p = est.T_base_tool[:3, 3]
            print(f"t={est.time_s:6.2f} s  tool at ({p[0]:8.2f}, {p[1]:8.2f}, {p[2]:7.2f}) mm  "
                  f"±{np.linalg.norm(est.spread[:3]):.3f} mm  {est.status}")
    print(f"{tracker.steps} samples, slowest filter step {worst:.2f} ms")


if __name__ == "__main__":
    main(sys.argv[1])
