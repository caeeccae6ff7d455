"""The filter's robot plateau against the simulated truth (paper eq. 7: d = the largest expected
positioning error): ``plateau_ratio`` by hand, the metrics and the CLI warning when a robot's
truth leaves it, and the bundled arms' examples calibrated so that their spread is honest."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.geometry import matrix_from_rotation_vector
from posekit.seam import config_from_dict, load_config
from posekit.seam.frontend.config import apply_overrides
from posekit.seam.frontend.episode import plateau_ratio, run_episode
from posekit.seam.frontend.episode_metrics import metrics

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "seam"


def _poses(t, r):
    T = np.repeat(np.eye(4)[None], len(t), axis=0)
    T[:, :3, 3] = t
    T[:, :3, :3] = matrix_from_rotation_vector(np.asarray(r, dtype=np.float64))
    return T


def test_plateau_ratio_by_hand():
    cfg = config_from_dict({"profile": {"plateau": {"d0_mm": 2.0, "kd_mm_per_n": 1e-3, "d0_deg": 0.5,
                                                    "kd_deg_per_n": 1e-4}}})
    kin = _poses(np.zeros((4, 3)), np.zeros((4, 3)))
    f = np.array([[0.0, 0.0, -1000.0]] * 4)  # d_t = 3 mm, d_r = 0.6 deg across the force, 0.5 deg along it
    deg = math.pi / 180
    truth = _poses([[1.5, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 6.0, 0.0]],
                   [[0.0, 0.0, 0.0], [0.3 * deg, 0.0, 0.0], [0.0, 0.0, 0.25 * deg], [0.0, 0.0, 0.0]])
    # half the translation radius; 0.3 of 0.6 deg across the force; 0.25 deg along it counts as
    # 0.25 x (0.6 / 0.5) of 0.6: the ellipsoid's short axis; 6 mm = twice the radius
    np.testing.assert_allclose(plateau_ratio(cfg, truth, kin, f), [0.5, 0.5, 0.5, 2.0], rtol=1e-9)
    # without force the rotation plateau is a ball of radius d0
    np.testing.assert_allclose(plateau_ratio(cfg, truth, kin, 0.0 * f)[1:3], [0.3 / 0.5, 0.25 / 0.5], rtol=1e-9)


def test_metrics_report_runs_leaving_the_plateau():
    base = {"trajectory.steps": 100, "filter.particles": 200}
    res = [run_episode(apply_overrides(config_from_dict({}), base), s) for s in (0, 1)]
    m = metrics(res)
    assert m["outside_plateau_runs"] == 0.0 and 0.1 < m["plateau_ratio_max"] < 1.0
    assert m["plateau_ratio_max"] == pytest.approx(max(r.plateau_ratio.max() for r in res), abs=1e-6)
    # a plateau a tenth of the robot's error: every run leaves it
    small = apply_overrides(config_from_dict({}), {**base, "profile.plateau.d0_mm": 0.3, "profile.plateau.kd_mm_per_n": 4.5e-5})
    m = metrics([run_episode(small, s) for s in (0, 1)])
    assert m["outside_plateau_runs"] == 1.0 and m["plateau_ratio_max"] > 3.0


def test_cli_warns_when_the_truth_leaves_the_plateau(tmp_path, capsys):
    cfg = tmp_path / "small.yaml"
    cfg.write_text("profile:\n  plateau:\n    d0_mm: 0.3\n    kd_mm_per_n: 4.5e-5\n")
    rc = main(["seam", "simulate", "--config", str(cfg), "--runs", "1", "--steps", "40", "--particles", "50",
               "--out", str(tmp_path / "o")])
    assert rc == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        "warning: the simulated robot left the filter's robot plateau in 100 % of the runs (up to ")
    assert err[0].endswith("fit the profile's plateau on episodes of this robot (posekit seam tune --with-truth; "
                           "paper eq. 7)")
    assert json.loads((tmp_path / "o" / "metrics.json").read_text())["outside_plateau_runs"] == 1.0
    # the default cell stays inside the default profile's plateau: nothing to warn about (the CLI warns exactly when
    # metrics.json's outside_plateau_runs is above 0, as the first run shows)
    cfg = apply_overrides(config_from_dict({}), {"trajectory.steps": 100, "filter.particles": 100})
    assert metrics([run_episode(cfg, 0)])["outside_plateau_runs"] == 0.0


@pytest.mark.parametrize("example", ["ur10-urdf.yaml", "abb_irb6640.yaml"])
def test_bundled_arms_keep_the_truth_inside_their_own_fitted_plateau(example):
    # each example's profile was fitted on simulated episodes of its arm (the command in the profile's header); on
    # other episodes of that arm the truth stays inside its plateau, which the default (PUMA 560) profile's is not
    # for the IRB 6640 (29 mm of deflection at 5 kN)
    cfg = apply_overrides(load_config(EXAMPLES / example), {"trajectory.steps": 150, "filter.particles": 500})
    res = [run_episode(cfg, s) for s in (11, 12)]
    m = metrics(res)
    assert m["outside_plateau_runs"] == 0.0, m["plateau_ratio_max"]
    # measured (the profiles' 500 particles, seeds 11, 12): UR10 tracking 300/300, confident-wrong 0 %; IRB 6640
    # 253/300 (the rest degraded: one episode's cloud is lost at its start, drawn again and held degraded while it
    # settles), confident-wrong 1.7 %
    assert m["status_counts"]["tracking"] >= 0.75 * 2 * 150
    assert m["confident_wrong"] <= 0.05
