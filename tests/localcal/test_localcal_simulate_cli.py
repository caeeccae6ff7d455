"""``posekit localcal simulate`` and ``posekit localcal demo`` end to end (in-process)."""

import csv
import json

import pytest

from posekit.cli.main import main


def test_simulate_trajectory_writes_tables_figures_and_report(tmp_path, capsys):
    out = tmp_path / "traj"
    rc = main(["localcal", "simulate", "--method", "trajectory", "--runs", "1", "--seed", "2", "--updates", "2",
               "--plot-hz", "0.5", "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "Table 3:" in captured.out and "Table 4:" in captured.out
    assert "runs: 1 ok, 0 suspect, 0 failed (of 1)" in captured.out
    for name in ("table3.csv", "table4.csv", "table4_truth.csv", "results.json", "fig5_orientation.png",
                 "fig8_matching.png", "fig9_errors.png", "report.html"):
        assert (out / name).is_file(), name
    rows = list(csv.DictReader((out / "table4.csv").open()))
    assert [r["run"] for r in rows] == ["run 1", "mean"]
    assert rows[0]["status"] == "ok"
    assert float(rows[0]["ex_2_mm"]) < 10.0 and float(rows[0]["ey_2_mm"]) < 10.0
    assert float(rows[1]["ey_2_mm"]) == pytest.approx(float(rows[0]["ey_2_mm"]))
    record = json.loads((out / "results.json").read_text())
    assert record["method"] == "trajectory" and record["runs"] == 1 and record["updates"] == 2
    assert record["tables"]["table4"][0]["ex_2_mm"] == pytest.approx(float(rows[0]["ex_2_mm"]), rel=1e-5)
    assert set(record["matching"][0]) >= {"R", "t_mm", "rmse_mm", "mean_abs_err_mm", "max_abs_err_mm"}
    report = (out / "report.html").read_text()
    assert report.count('src="data:image/png;base64,') == 3          # Figs. 5, 8, 9
    assert "Table 4" in report and "paper mean (Table 4)" in report


def test_demo_runs_one_episode_of_each_method(tmp_path, capsys):
    rc = main(["localcal", "demo", "--seed", "1", "--camera-hz", "1", "--plot-hz", "0", "--out", str(tmp_path)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "== line method" in captured.out and "== trajectory method" in captured.out
    assert "Table 2:" in captured.out and "Table 4:" in captured.out
    assert (tmp_path / "line" / "fig6_circle_path.png").is_file()
    assert (tmp_path / "trajectory" / "report.html").is_file()
    # the printed tables are the written ones, with the paper's outcome: the trajectory method
    # ends sub-centimetre in x and y, the line method leaves the depth untouched (~0.34 m, Table 2)
    traj = next(csv.DictReader((tmp_path / "trajectory" / "table4.csv").open()))
    line = next(csv.DictReader((tmp_path / "line" / "table2.csv").open()))
    assert traj["status"] == "ok" and line["status"] == "ok"
    assert float(traj["ex_2_mm"]) < 10.0 and float(traj["ey_2_mm"]) < 10.0
    assert float(line["ez_2_mm"]) > 200.0
    assert max(float(line[c]) for c in ("rot_x_deg", "rot_y_deg", "rot_z_deg")) < 5.0
    assert f"{float(traj['ex_2_mm']):.1f}" in captured.out and f"{float(line['ez_2_mm']):.1f}" in captured.out


def test_simulate_with_the_ooi_never_seen_is_a_one_line_error(tmp_path, capsys):
    rc = main(["localcal", "simulate", "--method", "trajectory", "--runs", "1", "--occlude-ooi", "always",
               "--plot-hz", "0", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert rc == 1
    assert err == ("posekit: error: trajectory method: all 1 run(s) failed; run 1: EstimationError: the OOI "
                   "(markers 1, 2, 3) not seen by the camera at the start pose\n")
    rows = list(csv.DictReader((tmp_path / "x" / "table4.csv").open()))   # the failed run keeps its row
    assert [(r["run"], r["status"]) for r in rows] == [("run 1", "error"), ("mean", "error")]
    assert rows[0]["error"] == "EstimationError: the OOI (markers 1, 2, 3) not seen by the camera at the start pose"


def test_bad_method_is_a_usage_error_like_every_choice_flag(tmp_path, capsys):
    rc = main(["localcal", "simulate", "--method", "circle", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "argument --method: invalid choice: 'circle' (choose from" in err


@pytest.mark.parametrize("argv, message", [
    (["--method", "line", "--runs", "0"], "--runs: expected an integer >= 1, got 0"),
    (["--method", "line", "--updates", "0"], "--updates: expected an integer >= 1, got 0"),
    (["--method", "line", "--occlude-ooi", "maybe"],
     "--occlude-ooi: expected one of never | calibration | always, got 'maybe'"),
    (["--method", "line", "--camera-hz", "0"], "--camera-hz: expected a rate > 0, got 0"),
    (["--method", "line", "--camera-hz", "inf"], "--camera-hz: expected a rate > 0, got inf"),
    (["--method", "line", "--plot-hz", "nan"], "--plot-hz: expected a rate >= 0, got nan"),
    (["--method", "line", "--seed", "-1"], "--seed: expected an integer >= 0, got -1"),
    (["--method", "line", "--scheduler", "cluster"],
     "--scheduler: expected serial, local or a Dask address like tcp://HOST:PORT, got 'cluster'"),
])
def test_simulate_bad_options(tmp_path, capsys, argv, message):
    rc = main(["localcal", "simulate", *argv, "--out", str(tmp_path)])
    assert rc == 1
    assert capsys.readouterr().err == f"posekit: error: {message}\n"


@pytest.mark.parametrize("verb", [["simulate", "--method", "line", "--runs", "1"], ["demo"]])
def test_an_unwritable_out_fails_before_any_run(tmp_path, capsys, verb):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    out = blocker / "results"
    rc = main(["localcal", *verb, "--plot-hz", "0", "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 1
    assert captured.out == ""                          # nothing was run
    assert captured.err == f"posekit: error: --out {out}: {blocker} is a file, not a folder; expected a folder path\n"


def test_a_failed_run_keeps_its_row_in_the_written_tables(tmp_path, capsys, monkeypatch):
    """Batch contract: run 1 fails, run 2 succeeds; both have a row, the mean is the good run's."""
    from posekit.errors import EstimationError
    from posekit.localcal.sim import experiments

    real = experiments.run_localcal_episode
    calls = []

    def flaky(method, seed, **kw):
        calls.append(seed)
        if len(calls) == 1:
            raise EstimationError("the tool marker (id 0) not seen by the camera after update 1")
        return real(method, seed, **kw)

    monkeypatch.setattr(experiments, "run_localcal_episode", flaky)
    out = tmp_path / "traj"
    rc = main(["localcal", "simulate", "--method", "trajectory", "--runs", "2", "--plot-hz", "0", "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 1
    assert len(calls) == 2
    assert "runs: 1 ok, 0 suspect, 1 failed (of 2)" in captured.out
    reason = "EstimationError: the tool marker (id 0) not seen by the camera after update 1"
    assert f"run 1 failed: {reason}" in captured.out
    for name, col in (("table3.csv", "max_z_mm"), ("table4.csv", "ey_2_mm")):
        rows = list(csv.DictReader((out / name).open()))
        assert [r["run"] for r in rows] == ["run 1", "run 2", "mean"]
        assert [r["status"] for r in rows] == ["error", "ok", "ok"]
        assert rows[0]["error"] == reason
        assert float(rows[2][col]) == pytest.approx(float(rows[1][col]))
        assert float(rows[1][col]) > 0.0


def test_simulate_correspondence_free_rectified_isotropic(tmp_path, capsys):
    """The paper's correspondence-free matching and the first simulator's camera and VO stay selectable."""
    out = tmp_path / "free"
    rc = main(["localcal", "simulate", "--method", "trajectory", "--runs", "1", "--seed", "3", "--no-timestamps",
               "--matcher", "hybrid", "--no-distortion", "--vo", "isotropic", "--plot-hz", "0", "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    record = json.loads((out / "results.json").read_text())
    assert record["simulation"]["matching"] == "correspondence-free (hybrid)"
    assert record["simulation"]["lens_distortion"] is False and record["simulation"]["vo_model"] == "isotropic"
    assert record["matching"][0]["mode"] == "no-timestamps" and record["matching"][0]["matcher"] == "hybrid"
    assert "paper mean (Table 4)" in captured.out and "paper (Table 3)" in captured.out
    assert "registration verdict (no-timestamps): " in captured.out


def test_simulate_bad_registration_combination_is_one_line(tmp_path, capsys):
    rc = main(["localcal", "simulate", "--method", "trajectory", "--runs", "1", "--no-timestamps",
               "--registration", "handeye", "--out", str(tmp_path / "x")])
    assert rc == 1
    assert capsys.readouterr().err == ("posekit: error: --registration handeye needs timestamps; "
                                       "drop --no-timestamps\n")
    assert not (tmp_path / "x").exists()


def test_matcher_without_no_timestamps_is_one_line(tmp_path, capsys):
    rc = main(["localcal", "simulate", "--method", "trajectory", "--runs", "1", "--matcher", "hybrid",
               "--out", str(tmp_path / "x")])
    assert rc == 1
    assert capsys.readouterr().err == ("posekit: error: --matcher hybrid is the matcher without timestamps; "
                                       "add --no-timestamps\n")


def test_a_suspect_registration_is_counted_and_exits_1(tmp_path, capsys, monkeypatch):
    """Before: "1/1 runs ok" when the run's registration was suspect. Now the run is suspect in the
    summary, the tables' status column and the exit code (a batch: 0 only if every run is ok)."""
    from dataclasses import replace

    from posekit.localcal.sim import experiments

    real = experiments.run_localcal_episode

    def suspect(method, seed, **kw):
        ep = real(method, seed, **kw)
        return replace(ep, matching={**ep.matching, "status": "suspect", "reasons": ["a test reason"]})

    monkeypatch.setattr(experiments, "run_localcal_episode", suspect)
    out = tmp_path / "traj"
    rc = main(["localcal", "simulate", "--method", "trajectory", "--runs", "1", "--plot-hz", "0", "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 1
    assert "runs: 0 ok, 1 suspect, 0 failed (of 1)" in captured.out
    rows = list(csv.DictReader((out / "table4.csv").open()))
    assert rows[0]["status"] == "suspect" and rows[0]["error"] == "registration suspect: a test reason"


def test_a_small_arm_that_loses_the_markers_gets_a_hint(tmp_path, capsys):
    """KUKA iiwa 14 (tests/data/urdf): the crane-sized scene loses the OOI in some runs. Which runs
    lose it is chaotic (a 1-degree change of the start pose, or round-off, flips a run), so six
    runs are made and the hint must count exactly the runs that failed."""
    import re
    from pathlib import Path

    urdf = Path(__file__).resolve().parents[1] / "data" / "urdf" / "kuka_iiwa14_r820.urdf"
    rc = main(["localcal", "simulate", "--method", "line", "--runs", "6", "--plot-hz", "0", "--camera-hz", "2",
               "--robot", str(urdf),
               "--start-q-deg", "0,60,0,-30,0,30,0", "--out", str(tmp_path / "o")])
    captured = capsys.readouterr()
    assert rc == 1
    assert captured.out.startswith("robot kuka_lbr_iiwa_14_r820: base_link → tool0, 7 joints (joint_a1, ")
    summary = re.search(r"runs: (\d) ok, 0 suspect, (\d) failed \(of 6\)", captured.out)
    assert summary and int(summary[2]) >= 1
    hints = [ln for ln in captured.err.splitlines() if ln.startswith("posekit: hint:")]
    assert hints == [f"posekit: hint: {summary[2]} run(s) lost the markers from view; the scene is sized for the 5 m "
                     "crane: bring the object closer (--ooi-distance-mm 500), start with free reach along the camera "
                     "axis (--start-q-deg) or shrink the errors (--error-scale)"]