"""Look-then-move episodes on the simulated long-reach arm, and the experiment tables.

Kept fast: few camera images (``plot_hz=0``; a coarse camera rate on the circle)."""

import numpy as np
import pytest

from posekit.errors import ConfigError, EstimationError
from posekit.localcal.studies.episode import run_localcal_episode
from posekit.localcal.studies.episode_config import EpisodeConfig
from posekit.localcal.studies.experiments import run_experiment, table_columns

FAST = EpisodeConfig(camera_hz=2.0, plot_hz=0.0)
# the OOI is hidden while the calibration path runs: the trajectory method does not need it
HIDDEN_DURING_CALIBRATION = EpisodeConfig(camera_hz=2.0, plot_hz=0.0, occlude_ooi="calibration")


@pytest.fixture(scope="module")
def trajectory_episode():
    return run_localcal_episode("trajectory", 3, updates=2, config=HIDDEN_DURING_CALIBRATION)


def test_trajectory_method_reaches_sub_centimetre_xy_after_the_second_update(trajectory_episode):
    ep = trajectory_episode
    assert ep.errors_mm.shape == (2, 3)
    # the camera's errors (the paper's Table 4) and the simulator's truth
    assert np.all(np.abs(ep.errors_mm[1, :2]) < 10.0)
    assert np.all(np.abs(ep.true_errors_mm[1, :2]) < 10.0)
    # the second update improves on the first, which is off by about a centimetre or more
    assert np.hypot(*ep.true_errors_mm[1, :2]) < np.hypot(*ep.true_errors_mm[0, :2])
    assert np.hypot(*ep.true_errors_mm[0, :2]) > 5.0
    # depth: the tool marker stops b = 100 mm short of the OOI, within the arm's error
    assert ep.true_errors_mm[1, 2] == pytest.approx(100.0, abs=15.0)
    # the camera agrees with the truth to a few mm at this distance
    np.testing.assert_allclose(ep.errors_mm, ep.true_errors_mm, atol=5.0)


def test_trajectory_matching_errors_are_table3_sized(trajectory_episode):
    m = trajectory_episode.matching
    assert set(m) >= {"R", "t_mm", "rmse_mm", "mean_abs_err_mm", "max_abs_err_mm"}
    assert np.all(np.asarray(m["mean_abs_err_mm"]) < 10.0)
    assert np.all(np.asarray(m["max_abs_err_mm"]) < 60.0)
    R = np.asarray(m["R"])
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_orientation_adjustment_leaves_a_few_degrees_at_most(trajectory_episode):
    ep = trajectory_episode
    assert np.all(ep.rotation_after_deg < 5.0)
    assert np.all(ep.true_rotation_after_deg < 3.0)       # ~1° mount error, camera noise
    assert ep.true_rotation_after_deg.max() < ep.rotation_before_deg.max() + 1.0


def test_same_seed_same_numbers(trajectory_episode):
    again = run_localcal_episode("trajectory", 3, updates=2, config=HIDDEN_DURING_CALIBRATION)
    np.testing.assert_array_equal(again.errors_mm, trajectory_episode.errors_mm)
    np.testing.assert_array_equal(again.true_errors_mm, trajectory_episode.true_errors_mm)


def test_line_method_gets_within_centimetres_but_not_reliably_below_one():
    ep = run_localcal_episode("line", 1, updates=1, config=FAST)
    lateral0 = np.hypot(*ep.timeline["e_C_mm"][0, :2])
    assert lateral0 > 300.0                                # the OOI starts ~0.36 m off
    xy = np.hypot(*ep.true_errors_mm[0, :2])
    assert xy < 60.0
    # with plot_hz = 0 the second image is the look after the orientation adjustment: the centre
    lateral_centre = np.hypot(*ep.timeline["e_C_mm"][1, :2])
    assert ep.logs["d_eps_min_mm"] == pytest.approx(lateral_centre - 200.0, abs=20.0)
    # depth is not adjusted by the line method (it changes only as much as the arm's errors tilt the motion)
    assert ep.true_errors_mm[0, 2] == pytest.approx(ep.timeline["e_C_mm"][1, 2], abs=60.0)
    assert ep.true_errors_mm[0, 2] > 200.0               # ~0.34 m: the paper's Table 2 depth


def test_an_ooi_never_seen_is_a_one_line_error():
    with pytest.raises(EstimationError, match=r"^the OOI \(markers 1, 2, 3\) not seen by the camera at the "
                                              r"start pose$"):
        run_localcal_episode("trajectory", 0, config=EpisodeConfig(plot_hz=0.0, occlude_ooi="always"))


def test_line_method_needs_the_ooi_during_the_circle():
    with pytest.raises(EstimationError, match=r"^line equation: the OOI \(markers 1, 2, 3\) was never seen "
                                              r"during the circular path$"):
        run_localcal_episode("line", 0, config=EpisodeConfig(camera_hz=0.5, plot_hz=0.0, occlude_ooi="calibration"))


def test_bad_options_are_config_errors():
    with pytest.raises(ConfigError, match=r"^method: expected one of line \| trajectory, got 'circle'$"):
        run_localcal_episode("circle", 0)
    with pytest.raises(ConfigError, match=r"^updates must be an integer >= 1, got 0$"):
        run_localcal_episode("line", 0, updates=0)
    with pytest.raises(ConfigError, match=r"^seed: expected an integer >= 0 or a numpy SeedSequence, got -1$"):
        run_localcal_episode("line", -1)
    with pytest.raises(ConfigError, match="occlude_ooi"):
        EpisodeConfig(occlude_ooi="sometimes")
    with pytest.raises(ConfigError, match=r"^runs must be an integer >= 1, got 0$"):
        run_experiment("line", runs=0)


def test_experiment_tables_have_a_row_per_run_and_a_mean_row():
    res = run_experiment("trajectory", runs=2, seed=5, updates=2, config=FAST)
    assert [r["run"] for r in res.tables["table4"]] == ["run 1", "run 2", "mean"]
    assert list(res.tables) == ["table3", "table4", "table4_truth"]
    cols = table_columns("table4", 2)
    assert cols == ["run", "ex_1_mm", "ey_1_mm", "ez_1_mm", "ex_2_mm", "ey_2_mm", "ez_2_mm", "status", "error"]
    rows = res.tables["table4"]
    for c in cols[1:-2]:
        assert rows[2][c] == pytest.approx((rows[0][c] + rows[1][c]) / 2)
    for i, ep in enumerate(res.episodes):
        assert rows[i]["ey_2_mm"] == pytest.approx(abs(ep.errors_mm[1, 1]))
        assert res.tables["table3"][i]["max_z_mm"] == pytest.approx(ep.matching["max_abs_err_mm"][2])
    assert rows[2]["ex_2_mm"] < 10.0 and rows[2]["ey_2_mm"] < 10.0


def test_a_failed_run_keeps_its_row():
    res = run_experiment("trajectory", runs=1, seed=0, config=EpisodeConfig(plot_hz=0.0, occlude_ooi="always"))
    row = res.tables["table4"][0]
    assert row["status"] == "error"
    assert row["error"] == ("EstimationError: the OOI (markers 1, 2, 3) not seen by the camera at the start pose")
    assert np.isnan(row["ex_1_mm"])
    assert res.tables["table4"][1]["status"] == "error"


def test_line_method_spreads_more_than_trajectory_matching():
    """Issue 5, deliverable 5: over the same runs the trajectory method stays sub-centimetre in x, y after two
    updates while the line method, dictated by the direction it measured once, scatters (paper Tables 2 and 4)."""
    xy = {}
    for method in ("line", "trajectory"):
        res = run_experiment(method, runs=4, seed=1, updates=2, config=FAST)
        assert [r["status"] for r in res.tables["table2" if method == "line" else "table4"]] == ["ok"] * 5
        xy[method] = np.array([np.hypot(*ep.true_errors_mm[-1, :2]) for ep in res.episodes])
    assert xy["trajectory"].max() < 10.0
    assert xy["line"].max() > 3.0 * xy["trajectory"].max()
    assert np.std(xy["line"]) > 3.0 * np.std(xy["trajectory"])
