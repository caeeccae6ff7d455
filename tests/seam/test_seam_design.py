"""``posekit seam design``: every sensor configuration simulated and ranked (DESIGN.md, seam)."""

import csv
import math
import re

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.seam.frontend.compare import episode_seeds
from posekit.seam.frontend.config import config_from_dict
from posekit.seam.frontend.design import design_configurations, distance_grid, sensor_design
from posekit.seam.frontend.episode import run_episode
from tests.cli_helpers import assert_one_line_error, run_cli


def test_distance_grid_and_configurations():
    assert distance_grid("20:80:20") == (20.0, 40.0, 60.0, 80.0)
    assert distance_grid("20:70:20") == (20.0, 40.0, 60.0)
    assert distance_grid("45,20") == (20.0, 45.0)
    confs = design_configurations([0, 1, 2, 3, 4], distance_grid("20:80:20"))
    # 1 + C(4,1) + C(4,2) + C(4,3) + C(4,4)
    assert len(confs) == 1 + 4 + 6 + 4 + 1
    assert confs[0].distances_mm == () and confs[-1].distances_mm == (20.0, 40.0, 60.0, 80.0)
    both = design_configurations([0, 1], [20.0, 40.0], angle="both")
    assert [(c.sensors, c.angle) for c in both] == [(0, False), (1, False), (1, True), (1, False), (1, True)]
    for text, msg in (("60:20:10", "A <= B"), ("0:40:20", "0 mm is outside (0, 1000] mm"),
                      ("20:x:5", "expected A:B:STEP"), ("1:100:1", "expected at most 50")):
        with pytest.raises(ConfigError, match=re.escape(msg)):
            distance_grid(text)
    with pytest.raises(ConfigError, match="only 2 distances on the grid; expected at least 3"):
        design_configurations([3], [20.0, 40.0])


def test_ranking_matches_episodes_run_here():
    """Each row's RMSE is that of the configuration's episodes (run here with the design's seeds);
    the score is ‖RMSE_t‖ + lever ‖RMSE_r (rad)‖; rows are sorted by it."""
    cfg = config_from_dict({"trajectory": {"steps": 60}, "filter": {"particles": 100}})
    d = sensor_design(cfg, counts=(0, 1, 2), distances_mm=(20.0, 40.0), runs=1, seed=3, scheduler="serial",
                      progress=False)
    rows = d.rows()
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    assert [r["rank"] for r in rows] == [1, 2, 3, 4]
    assert all(a["score"] <= b["score"] for a, b in zip(rows, rows[1:]))
    seed = episode_seeds(3, 1)[0]
    for r in rows:
        dist = [float(v) for v in r["distances_mm"].split(";")] if r["distances_mm"] else None
        c = config_from_dict({"trajectory": {"steps": 60}, "filter": {"particles": 100},
                              "sensors": {"count": r["sensors"], "distances_mm": dist}})
        e = run_episode(c, seed).error  # mm, rad
        rm = np.sqrt(np.mean(e ** 2, axis=0))
        assert [r["rmse_x_mm"], r["rmse_y_mm"], r["rmse_z_mm"]] == pytest.approx(rm[:3], rel=1e-9)
        assert [r["rmse_rx_deg"], r["rmse_ry_deg"], r["rmse_rz_deg"]] == pytest.approx(np.degrees(rm[3:]), rel=1e-9)
        score = np.linalg.norm(rm[:3]) + 100.0 * np.linalg.norm(rm[3:])
        assert r["score"] == pytest.approx(score, rel=1e-9)
    # two sensors see the seam where none sees nothing: the best has two; without sensors the filter is the kinematics
    # (one sensor over these 60 short, fast steps confuses translation and rotation and may rank below none)
    assert rows[0]["sensors"] == 2
    none = next(r for r in rows if r["sensors"] == 0)
    assert none["score"] < none["kinematic_score"] * 1.2 and rows[0]["score"] < 0.5 * none["score"]


def test_design_cli_writes_ranking_and_figure(tmp_path, capsys):
    rc, out, err = run_cli(capsys, "seam", "design", "--sensors", "0,2", "--distances-mm", "20:40:20", "--runs", "1",
                           "--steps", "40", "--particles", "80", "--scheduler", "serial", "--out", tmp_path / "d")
    assert rc == 0, err
    names = sorted(p.name for p in (tmp_path / "d").iterdir())
    assert names == [".posekit-run.json", "ranking.csv", "ranking.png", "report.html"]   # with posekit's marker
    with (tmp_path / "d" / "ranking.csv").open() as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = list(reader)
    assert header[:9] == ["sensors", "distances_mm", "rmse_x_mm", "rmse_y_mm", "rmse_z_mm", "rmse_rx_deg",
                          "rmse_ry_deg", "rmse_rz_deg", "score"]
    assert [r[:2] for r in rows] == [["2", "20;40"], ["0", ""]]
    assert all(math.isfinite(float(r[8])) for r in rows)
    assert "seam design: 2 configurations × 1 runs" in out


@pytest.mark.parametrize("argv, needle", [
    (["--sensors", "1,5"], "--sensors: expected comma-separated sensor counts 0..4, got '1,5'"),
    (["--distances-mm", "80:20:20"], "--distances-mm: expected A:B:STEP with A <= B and STEP > 0"),
    (["--sensors", "3", "--distances-mm", "20,40"], "--sensors 3: only 2 distances on the grid"),
    (["--workers", "2", "--scheduler", "serial"], "--workers sets the size of the local cluster"),
])
def test_design_cli_bad_flags_are_one_line(tmp_path, capsys, argv, needle):
    rc, out, err = run_cli(capsys, "seam", "design", *argv, "--out", tmp_path / "d")
    assert_one_line_error(rc, out, err, needle)
    assert not (tmp_path / "d").exists()


def test_same_ranking_in_one_process_and_on_a_dask_cluster():
    """The episode seeds are drawn before the tasks leave: a cluster gives the serial ranking."""
    from distributed import Client, LocalCluster

    cfg = config_from_dict({"trajectory": {"steps": 30}, "filter": {"particles": 60}})
    kw = {"counts": (1, 2), "distances_mm": (20.0, 40.0), "runs": 2, "seed": 5, "progress": False}
    serial = sensor_design(cfg, scheduler="serial", **kw)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster, \
            Client(cluster, set_as_default=False) as client:
        dask = sensor_design(cfg, scheduler=client, **kw)
    assert [r["distances_mm"] for r in serial.rows()] == [r["distances_mm"] for r in dask.rows()]
    np.testing.assert_allclose(serial.rmse, dask.rmse, rtol=1e-12)
