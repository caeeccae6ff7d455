"""The seam filter judged on a cell posekit's simulator did not make (tests/seam/independent_cell.py: its own
UR10-like arm, seam, deflection, drift and two lasers 13 / 17 ms late).

``posekit seam tune --with-truth`` on three of its episodes fits the cell's profile (latencies included); on
held-out episodes the filter's 2-sigma coverage, tracking share and confident-wrong share (tracking while beyond
3 sigma on some axis) are scored against the generator's own truth. The larger Monte-Carlo of these scenarios
(more episodes, encoder offsets, force biases) is benchmarks/seam_validation.py, written to
benchmarks/data/seam_validation.json.
"""

import numpy as np
import pytest

from posekit.seam.frontend.logs import read_episode_log
from posekit.seam.frontend.profile import merge_profile, write_profile
from posekit.seam.frontend.tracker import track_log
from posekit.seam.frontend.tune import tune_profile
from tests.seam import independent_cell as ic

TRAIN = (0, 1, 2)
HELD_OUT = (100, 101, 102)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """The cell, a folder, and the profile ``seam tune --with-truth`` fits on three training episodes."""
    cell = ic.Cell()
    root = tmp_path_factory.mktemp("independent")
    train = [ic.write_episode(root / f"train{s}", cell, ic.episode(cell, s), declare_latency=False) for s in TRAIN]
    result = tune_profile(train, with_truth=True)
    write_profile(root / "fitted.yaml", result.profile, "seam tune --with-truth on the independent cell")
    return cell, root, result


def _track(cell, root, seed, profile, name, **kw):
    ep = ic.episode(cell, seed, **kw)
    folder = ic.write_episode(root / f"{name}{seed}", cell, ep, declare_latency=False)
    r = track_log(read_episode_log(folder, profile=profile))
    return ic.scores(r.estimate, r.spread, r.status, ep)


def test_tune_recovers_each_sensor_s_latency_within_3_ms(fitted):
    cell, _, result = fitted
    got = {v.key: v for v in result.values}
    for i, true in enumerate(cell.latency_s):
        v = got[f"sensors[{i}].latency_s"]
        # measured: 12.48 +- 0.40 ms and 16.94 +- 0.16 ms for the true 13 and 17 ms
        assert v.pinned and abs(v.value - true) < 0.003, (i, v)
        assert v.std is not None and 0.0 < v.std < 0.0015
    # and the laser noise to within a tenth of the generator's (0.03 / 0.04 mm plus the jitter the sensors see)
    for i, noise in enumerate(cell.laser_sigma_mm):
        assert noise < got[f"sensors[{i}].sigma_mm"].value < 1.5 * noise


def test_held_out_episodes_are_tracked_with_an_honest_spread(fitted):
    cell, root, _ = fitted
    runs = [_track(cell, root, s, root / "fitted.yaml", "held") for s in HELD_OUT]
    cov = np.mean([r["coverage"] for r in runs], axis=0)
    # 3 episodes x 400 steps, errors autocorrelated over tens of steps: a few dozen independent samples per axis,
    # so the per-axis coverage is known to a few percent. The roll about the travel (ry) is the axis the lasers
    # barely see: its spread is the robot plateau's, wider than its error (measured 0.999)
    assert np.all(cov >= 0.85), cov
    assert np.all(np.delete(cov, 4) <= 0.995), cov
    for r in runs:
        assert r["tracking"] >= 0.9, r
        assert r["confident_wrong"] <= 0.05, r


@pytest.mark.xfail(strict=True, reason="not met (issue 26): with two sensors the lateral error of an undeclared "
                                       "13/17 ms latency is absorbed by the estimate's x and yaw; the laser NIS tests "
                                       "flag it only after 100-300 steps (see docs/notes/issue-26.md)")
def test_a_latency_nobody_declared_is_not_reported_tracking(fitted):
    cell, root, result = fitted
    zero = merge_profile(result.profile, {"sensors": [{"latency_s": 0.0}] * len(cell.mounts)})
    write_profile(root / "zero-latency.yaml", zero)
    runs = [_track(cell, root, s, root / "zero-latency.yaml", "undeclared") for s in HELD_OUT]
    for r in runs:
        assert r["tracking"] <= 0.2 and r["confident_wrong"] <= 0.05, r
