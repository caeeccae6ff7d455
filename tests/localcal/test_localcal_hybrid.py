"""The hybrid-mixture style matcher (orientations + positions, the paper's ref. [31]) against positional CPD.

Print the comparison table on the correspondence-free verdict cases and the real TUM pairs with::

    python -m tests.localcal.test_localcal_hybrid 0 1 2 3 4
"""

import sys
import time

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.localcal.registration.alignment import umeyama
from posekit.localcal.registration.association import associate
from posekit.localcal.registration.formats.tum import read_tum
from posekit.localcal.registration.match import match_trajectories
from tests.localcal.synth_trajectories import TUM_DATA as DATA
from tests.localcal.synth_trajectories import rotation_error_deg
from tests.localcal.test_localcal_verdict import base, good_cases, lever


@pytest.mark.parametrize("seed", [0, 1])
def test_hybrid_recovers_the_transform_on_a_rotating_path(seed):
    src, dst, T, _ = base(seed + 20, "smooth")
    reg = match_trajectories(src, dst, use_timestamps=False, matcher="hybrid")
    assert reg.status == "ok" and reg.matcher == "hybrid"
    assert rotation_error_deg(reg.R, T[:3, :3]) < 0.3
    assert np.linalg.norm(reg.t_mm - T[:3, 3]) < 3.0
    assert reg.to_json()["matcher"] == "hybrid"


def test_hybrid_equals_cpd_quality_with_constant_orientation():
    src, dst, T, _ = base(3, "planar")                 # the paper's planar path: constant orientation
    a = match_trajectories(src, dst, use_timestamps=False, matcher="hybrid")
    b = match_trajectories(src, dst, use_timestamps=False, matcher="cpd")
    assert rotation_error_deg(a.R, T[:3, :3]) < 0.5 and rotation_error_deg(b.R, T[:3, :3]) < 0.5


def test_hybrid_on_the_real_fr2_pair_agrees_with_the_timestamped_match():
    orb, gt = read_tum(DATA / "fr2_desk_ORB.txt"), read_tum(DATA / "fr2_desk_groundtruth.txt")
    i, j = associate(orb.t_s, gt.t_s, max_dt_s=0.01)
    R0, t0, _ = umeyama(orb.positions[i], gt.positions[j])
    reg = match_trajectories(orb, gt, use_timestamps=False, matcher="hybrid")
    assert rotation_error_deg(reg.R, R0) < 0.1 and np.linalg.norm(reg.t_mm - t0) < 3.0


def test_hybrid_still_flags_a_camera_off_the_tool():
    src, dst, T = lever(7)
    reg = match_trajectories(src, dst, use_timestamps=False, matcher="hybrid")
    assert reg.status == "suspect"


def test_unknown_matcher_is_a_config_error():
    src, dst, T, _ = base(0, "smooth")
    with pytest.raises(ConfigError, match=r"^matcher must be one of cpd, hybrid, got 'icp'$"):
        match_trajectories(src, dst, use_timestamps=False, matcher="icp")


def compare(seeds):
    """Rows (case, matcher, rot err deg, t err mm, status, seconds) on the free-mode cases."""
    rows = []
    cases = []
    for nm, a, b in (("real fr1/xyz", "freiburg1_xyz-rgbdslam.txt", "freiburg1_xyz-groundtruth.txt"),
                     ("real fr2/desk", "fr2_desk_ORB.txt", "fr2_desk_groundtruth.txt")):
        s, d = read_tum(DATA / a), read_tum(DATA / b)
        i, j = associate(s.t_s, d.t_s, max_dt_s=0.01)
        R0, t0, _ = umeyama(s.positions[i], d.positions[j])
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R0, t0                      # reference: the timestamped Umeyama
        cases.append((nm + " (vs timestamped)", s, d, T))
    for seed in seeds:
        for name, src, dst, kw, T in good_cases(seed):
            if T is not None and kw.get("use_timestamps", True) is False:
                cases.append((name.replace(" free", ""), src, dst, T))
    for name, src, dst, T in cases:
        for m in ("cpd", "hybrid"):
            t0 = time.perf_counter()
            reg = match_trajectories(src, dst, use_timestamps=False, matcher=m)
            dt = time.perf_counter() - t0
            rows.append((name, m, rotation_error_deg(reg.R, T[:3, :3]), float(np.linalg.norm(reg.t_mm - T[:3, 3])),
                         reg.status, dt))
    return rows


if __name__ == "__main__":
    rows = compare([int(a) for a in sys.argv[1:]] or [0])
    print(f"{'case':45s} {'cpd deg':>8s} {'mm':>6s} {'s':>5s} | {'hybrid deg':>10s} {'mm':>6s} {'s':>5s}")
    for k in range(0, len(rows), 2):
        a, b = rows[k], rows[k + 1]
        print(f"{a[0][:45]:45s} {a[2]:8.3f} {a[3]:6.1f} {a[5]:5.2f} | {b[2]:10.3f} {b[3]:6.1f} {b[5]:5.2f}"
              + ("" if a[4] == b[4] == "ok" else f"  ({a[4]}/{b[4]})"))
    syn = [r for r in rows if not r[0].startswith("real")]
    for m in ("cpd", "hybrid"):
        e = np.array([(r[2], r[3], r[5]) for r in syn if r[1] == m])
        print(f"{m:6s} synthetic ({len(e)} cases): rotation error mean {e[:, 0].mean():.3f} max {e[:, 0].max():.3f} deg, "
              f"translation mean {e[:, 1].mean():.2f} max {e[:, 1].max():.2f} mm, median time {np.median(e[:, 2]):.2f} s")
