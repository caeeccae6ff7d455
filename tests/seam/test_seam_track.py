"""``posekit seam simulate --save-log`` and ``posekit seam track`` (DESIGN.md, seam)."""

import csv
import json
import shutil

import numpy as np
import pytest

from tests.cli_helpers import assert_one_line_error, run_cli


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    root = tmp_path_factory.mktemp("track")
    from posekit.cli.main import main

    rc = main(["seam", "simulate", "--steps", "80", "--particles", "150", "--seed", "4", "--record-particles", "0",
               "--save-log", str(root / "log"), "--out", str(root / "sim")])
    assert rc == 0
    return root


def test_save_log_writes_the_four_files(simulated):
    names = sorted(p.name for p in (simulated / "log").iterdir())
    assert names == [".posekit-run.json", "log.csv", "seam.csv", "setup.yaml", "truth.csv"]   # with posekit's marker
    header = (simulated / "log" / "log.csv").read_text().splitlines()[0]
    assert header == ("time_s,qref_1,qref_2,qref_3,qref_4,qref_5,qref_6,q_1,q_2,q_3,q_4,q_5,q_6,fx_n,fy_n,fz_n,"
                      "m1_x_mm,m1_z_mm,m2_x_mm,m2_z_mm")
    assert (simulated / "log" / "truth.csv").read_text().startswith("time_s,tx_mm,ty_mm,tz_mm,qw,qx,qy,qz\n")


def test_track_reproduces_simulate_and_reports_status(simulated, capsys):
    rc, out, err = run_cli(capsys, "seam", "track", simulated / "log", "--out", simulated / "tr")
    assert rc == 0, err
    m = json.loads((simulated / "tr" / "metrics.json").read_text())
    sim = json.loads((simulated / "sim" / "metrics.json").read_text())
    assert sum(m["status_counts"].values()) == 80
    assert {k: v for k, v in sim["status_counts"].items() if v} == {k: v for k, v in m["status_counts"].items() if v}
    assert m["status_counts"]["tracking"] >= 60
    line = next(x for x in out.splitlines() if x.startswith("status: "))
    assert sorted(line[len("status: "):].split(", ")) == sorted(f"{k} {v}" for k, v in m["status_counts"].items() if v)
    assert sorted(p.name for p in (simulated / "tr").iterdir()) == [".posekit-run.json", "errors_time.png", "ess.png",
                                                                    "estimates.csv", "metrics.json"]
    for a in ("x", "y", "z"):
        assert m["rmse_mm"][a] == pytest.approx(sim["rmse_mm"][a], abs=1e-5)
    for a in ("rx", "ry", "rz"):
        assert m["rmse_deg"][a] == pytest.approx(sim["rmse_deg"][a], abs=1e-5)
    assert set(m["coverage_2sigma"]) == {"x", "y", "z", "rx", "ry", "rz"}
    # the truth against the filter's robot plateau and the confidently wrong steps, as simulate saw them
    assert m["plateau_ratio_max"] == pytest.approx(sim["plateau_ratio_max"], abs=1e-3) and m["plateau_ratio_max"] < 1
    assert m["outside_plateau_steps"] == 0.0
    assert m["confident_wrong"] == pytest.approx(sim["confident_wrong"], abs=1e-9)
    assert "warning" not in err
    with (simulated / "tr" / "estimates.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 80
    assert {"tx_mm", "qw", "status", "std_x_mm", "std_rz_deg", "err_x_mm"} <= set(rows[0])
    # the pose is the tool in the robot base frame: the PUMA's default seam starts at (450, -100, 0)
    assert float(rows[0]["tx_mm"]) == pytest.approx(450.0, abs=3.0)
    assert float(rows[0]["ty_mm"]) == pytest.approx(-100.0, abs=3.0)


def test_track_without_truth_reports_no_errors(simulated, tmp_path, capsys):
    shutil.copytree(simulated / "log", tmp_path / "log")
    (tmp_path / "log" / "truth.csv").unlink()
    rc, out, err = run_cli(capsys, "seam", "track", tmp_path / "log", "--out", tmp_path / "tr")
    assert rc == 0, err
    m = json.loads((tmp_path / "tr" / "metrics.json").read_text())
    assert "rmse_mm" not in m and "coverage_2sigma" not in m and "status_counts" in m
    header = (tmp_path / "tr" / "estimates.csv").read_text().splitlines()[0]
    assert "err_x_mm" not in header and "status" in header
    est = np.loadtxt(tmp_path / "tr" / "estimates.csv", delimiter=",", skiprows=1, usecols=(2, 3, 4))
    assert est.shape == (80, 3)


def test_track_warns_when_the_truth_leaves_the_filter_plateau(simulated, tmp_path, capsys):
    # a recorded episode with a reference (truth.csv) of a robot the filter's plateau does not describe
    import yaml

    shutil.copytree(simulated / "log", tmp_path / "log")
    setup = yaml.safe_load((tmp_path / "log" / "setup.yaml").read_text())
    setup["profile"] = {"plateau": {"d0_mm": 0.2, "kd_mm_per_n": 3e-5}}
    (tmp_path / "log" / "setup.yaml").write_text(yaml.safe_dump(setup))
    rc, out, err = run_cli(capsys, "seam", "track", tmp_path / "log", "--out", tmp_path / "tr")
    assert rc == 0
    m = json.loads((tmp_path / "tr" / "metrics.json").read_text())
    assert m["outside_plateau_steps"] > 0.5 and m["plateau_ratio_max"] > 2.0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning: the true pose left the filter's robot plateau at ")
    assert lines[0].endswith("fit the profile's plateau on episodes of this robot (posekit seam tune --with-truth; "
                             "paper eq. 7)")


def test_track_bad_log_is_one_line(simulated, tmp_path, capsys):
    shutil.copytree(simulated / "log", tmp_path / "log")
    p = tmp_path / "log" / "log.csv"
    lines = p.read_text().splitlines()
    lines[9] = lines[9].replace(",", ",x", 1)
    p.write_text("\n".join(lines) + "\n")
    rc, out, err = run_cli(capsys, "seam", "track", tmp_path / "log", "--out", tmp_path / "tr")
    assert_one_line_error(rc, out, err, "log.csv line 10: qref_1 is 'x", "expected a number")
    assert not (tmp_path / "tr").exists()


def test_save_log_into_out_is_refused(tmp_path, capsys):
    rc, out, err = run_cli(capsys, "seam", "simulate", "--steps", "5", "--particles", "5", "--save-log",
                           tmp_path / "o", "--out", tmp_path / "o")
    assert_one_line_error(rc, out, err, "--save-log: expected a folder other than --out")


def test_track_jsonl_streams_every_step(simulated, tmp_path, capsys):
    rc, out, err = run_cli(capsys, "seam", "track", simulated / "log", "--out", tmp_path / "tr",
                           "--jsonl", tmp_path / "steps.jsonl")
    assert rc == 0, err
    records = [json.loads(line) for line in (tmp_path / "steps.jsonl").read_text().splitlines()]
    assert [r["step"] for r in records] == list(range(80))
    with (tmp_path / "tr" / "estimates.csv").open() as f:
        rows = list(csv.DictReader(f))
    for r, row in zip(records[::20], rows[::20]):
        assert r["t_mm"] == pytest.approx([float(row["tx_mm"]), float(row["ty_mm"]), float(row["tz_mm"])], abs=1e-6)
        assert r["status"] == row["status"]
        assert r["std_deg"][2] == pytest.approx(float(row["std_rz_deg"]), rel=1e-5)
