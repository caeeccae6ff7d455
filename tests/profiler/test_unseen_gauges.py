"""`posekit profiler estimate` on random gauges it was never tuned on."""

import json

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.geometry import transform_from_quaternion
from posekit.profiler.gauge.design import random_gauge
from posekit.profiler.gauge.model import gauge_to_yaml, load_gauge
from posekit.profiler.sim.simulate import read_truth_csv
from posekit.profiler.studies.evaluate import pose_errors


@pytest.mark.parametrize("n, seed", [(4, 101), (5, 102), (7, 103), (10, 104)])
def test_cli_recovers_poses_of_random_gauges(tmp_path, capsys, n, seed):
    gauge = random_gauge(n, seed)
    assert gauge.beta_deg >= 50
    path = tmp_path / "g.yaml"
    path.write_text(gauge_to_yaml(gauge))
    assert main(["profiler", "simulate", "--gauge", str(path), "--count", "40", "--seed", str(seed),
                 "--out", str(tmp_path / "sim")]) == 0
    capsys.readouterr()
    assert main(["profiler", "estimate", str(tmp_path / "sim" / "profiles.npz"), "--gauge", str(path)]) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    _, t, q = read_truth_csv(tmp_path / "sim" / "truth.csv")
    z = []
    for rec, t_true, q_true in zip(records, t, q, strict=True):
        assert rec["status"] == "ok"
        err = pose_errors(transform_from_quaternion(rec["q_wxyz"], rec["t_mm"]),
                          transform_from_quaternion(q_true, t_true))
        std = np.r_[np.array(rec["std_t_um"]) * 1e-3, np.radians(rec["std_rot_deg"])]
        z.append(err / std)
        assert np.all(np.abs(err[[0, 2]]) < 0.1)          # x, z within 0.1 mm at 5 µm noise
    z = np.array(z)
    assert np.all(np.sqrt(np.mean(z**2, axis=0)) < 1.5)
    assert load_gauge(path).n_corners == n


def test_random_gauges_respect_the_design_limits():
    for n in (4, 5, 7, 10):
        for seed in range(5):
            g = random_gauge(n, seed, beta_min_deg=55)
            assert g.n_corners == n and g.beta_deg >= 55
            assert g.x_range[1] - g.x_range[0] <= 0.85 * 163.0 + 1e-9
            assert np.ptp(g.ridge_s[:, 0]) >= 0.175
    a, b = random_gauge(5, 7), random_gauge(5, 7)
    np.testing.assert_array_equal(a.normals, b.normals)


def test_random_gauge_bad_limits():
    from posekit.errors import ConfigError
    with pytest.raises(ConfigError, match="expected n_corners >= 4, got 3"):
        random_gauge(3, 0)
    with pytest.raises(ConfigError, match=r"beta_min_deg must lie in \(0, 90\), got 95"):
        random_gauge(5, 0, beta_min_deg=95)
