"""``posekit seam simulate|demo|study`` end to end, in process through ``main(argv)``.

The episodes are tiny (few steps and particles): these tests check files, shapes, the
metrics.json contract and that its numbers are those of estimates.csv, not tracking accuracy
(tests/seam/test_seam_observability.py does that).
"""

import json

import numpy as np
import pytest
import yaml

from posekit.cli.main import main
from posekit.seam.report import ERROR_AXES, read_estimates_csv

TINY = ["--steps", "25", "--particles", "60"]


def _run(capsys, *argv):
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


# --------------------------------------------------------------------------- bad input (no episode runs)

@pytest.mark.parametrize("argv, message", [
    (["--particles", "0"], "posekit: error: --particles: expected an integer >= 1, got 0"),
    (["--steps", "1"], "posekit: error: --steps: expected an integer >= 2, got 1"),
    (["--seed", "-3"], "posekit: error: --seed: expected an integer >= 0, got -3"),
    (["--runs", "0"], "posekit: error: --runs: expected an integer >= 1, got 0"),
    ([], "posekit: error: --out: an output folder is required (or use --dump-config)"),
])
def test_simulate_bad_flags(capsys, tmp_path, argv, message):
    if argv:
        argv = [*argv, "--out", str(tmp_path)]
    rc, out, err = _run(capsys, "seam", "simulate", *argv)
    assert rc == 1
    assert err.strip() == message
    assert "Traceback" not in err


def test_simulate_usage_errors_exit_2(capsys, tmp_path):
    rc, _, err = _run(capsys, "seam", "simulate", "--sensors", "3", "--out", str(tmp_path))
    assert rc == 2 and "invalid choice: 3" in err
    rc, _, err = _run(capsys, "seam", "simulate", "--trajectory", "zz", "--out", str(tmp_path))
    assert rc == 2 and "invalid choice: 'zz'" in err


def test_simulate_bad_config_one_line(capsys, tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("filter:\n  particles: 0\n")
    rc, _, err = _run(capsys, "seam", "simulate", "--config", str(cfg), "--out", str(tmp_path / "o"))
    assert rc == 1
    assert err == f"posekit: error: {cfg}: filter.particles: expected >= 1, got 0\n"
    cfg.write_text("filter:\n  particle: 10\n")
    rc, _, err = _run(capsys, "seam", "simulate", "--config", str(cfg), "--out", str(tmp_path / "o"))
    assert rc == 1 and err == f"posekit: error: {cfg}: unknown key 'filter.particle'\n"
    rc, _, err = _run(capsys, "seam", "simulate", "--config", str(tmp_path / "missing.yaml"),
                      "--out", str(tmp_path / "o"))
    assert rc == 1 and err.startswith(f"posekit: error: {tmp_path / 'missing.yaml'}: cannot read config file")
    assert not (tmp_path / "o").exists()


def test_flags_override_the_config_file(capsys, tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("seed: 4\ntrajectory: {kind: yz, steps: 40}\nsensors: {count: 2, distances_mm: [15, 35]}\n"
                   "filter: {particles: 100}\n")
    rc, out, _ = _run(capsys, "seam", "simulate", "--config", str(cfg), "--dump-config")
    d = yaml.safe_load(out)
    assert rc == 0
    assert (d["seed"], d["trajectory"]["kind"], d["trajectory"]["steps"], d["filter"]["particles"]) == \
        (4, "yz", 40, 100)
    assert d["sensors"]["distances_mm"] == [15.0, 35.0]
    rc, out, _ = _run(capsys, "seam", "simulate", "--config", str(cfg), "--dump-config", "--trajectory", "xy",
                      "--sensors", "1", "--particles", "7", "--seed", "9", "--steps", "30")
    d = yaml.safe_load(out)
    assert (d["seed"], d["trajectory"]["kind"], d["trajectory"]["steps"], d["filter"]["particles"]) == \
        (9, "xy", 30, 7)
    assert d["sensors"]["count"] == 1 and d["sensors"]["distances_mm"] == [15.0]   # the file's first sensor


def test_study_bad_flags(capsys, tmp_path):
    rc, _, err = _run(capsys, "seam", "study", "--scheduler", "serial", "--workers", "2", "--out", str(tmp_path))
    assert rc == 1 and err.strip() == ("posekit: error: --workers sets the size of the local cluster; "
                                       "it cannot be combined with --scheduler")
    rc, _, err = _run(capsys, "seam", "study", "--parameters", "filter.nope", "--out", str(tmp_path))
    assert rc == 1 and err.strip() == "posekit: error: study factor 'filter.nope': no such configuration key"
    rc, _, err = _run(capsys, "seam", "study", "--parameters", "filter.d0_mm=1:x", "--out", str(tmp_path))
    assert rc == 1 and err.strip() == "posekit: error: --parameters: expected KEY or KEY=LOW:HIGH, got 'filter.d0_mm=1:x'"
    rc, _, err = _run(capsys, "seam", "study", "--parameters", "filter.particles=0:10", "--runs", "3",
                      "--out", str(tmp_path))
    assert rc == 1 and err.strip().startswith(
        "posekit: error: study factor 'filter.particles': range [0, 10] leaves the valid configurations")
    rc, _, err = _run(capsys, "seam", "study", "--scheduler", "nowhere", "--runs", "3", "--out", str(tmp_path))
    assert rc == 1 and "scheduler: expected 'serial' or a Dask address like tcp://HOST:PORT, got 'nowhere'" in err
