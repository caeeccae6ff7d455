"""``posekit seam simulate|demo|study`` end to end, in process through ``main(argv)``.

The episodes are tiny (few steps and particles): these tests check files, shapes, the
metrics.json contract and that its numbers are those of estimates.csv, not tracking accuracy
(tests/seam/test_seam_observability.py does that).
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from posekit.cli.main import main
from posekit.seam.frontend.report import ERROR_AXES, read_estimates_csv

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
    rc, _, err = _run(capsys, "seam", "simulate", *argv)
    assert rc == 1
    assert err.strip() == message
    assert "Traceback" not in err


@pytest.mark.parametrize("verb", [["simulate"], ["demo"], ["study", "--scheduler", "serial"]])
def test_unwritable_out_is_an_error_before_any_run(capsys, tmp_path, verb):
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    rc, out, err = _run(capsys, "seam", *verb, "--out", str(a_file))
    assert rc == 1 and out == ""
    assert err == f"posekit: error: --out {a_file}: exists and is not a folder; expected a folder name\n"


def test_simulate_usage_errors_exit_2(capsys, tmp_path):
    rc, _, err = _run(capsys, "seam", "simulate", "--sensors", "5", "--out", str(tmp_path))
    assert rc == 2 and "invalid choice: 5" in err
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
    assert rc == 1 and err.startswith(f"posekit: error: {tmp_path / 'missing.yaml'}: no such file; expected a seam configuration YAML file")
    assert not (tmp_path / "o").exists()


def test_flags_override_the_config_file(capsys, tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("seed: 4\ntrajectory: {kind: yz, steps: 40}\ncell: {sensors: {count: 2, distances_mm: [15, 35]}}\n"
                   "filter: {particles: 100}\n")
    rc, out, _ = _run(capsys, "seam", "simulate", "--config", str(cfg), "--dump-config")
    d = yaml.safe_load(out)
    assert rc == 0
    assert (d["seed"], d["trajectory"]["kind"], d["trajectory"]["steps"], d["filter"]["particles"]) == \
        (4, "yz", 40, 100)
    assert d["cell"]["sensors"]["distances_mm"] == [15.0, 35.0]
    rc, out, _ = _run(capsys, "seam", "simulate", "--config", str(cfg), "--dump-config", "--trajectory", "xy",
                      "--sensors", "1", "--particles", "7", "--seed", "9", "--steps", "30")
    d = yaml.safe_load(out)
    assert (d["seed"], d["trajectory"]["kind"], d["trajectory"]["steps"], d["filter"]["particles"]) == \
        (9, "xy", 30, 7)
    assert d["cell"]["sensors"]["count"] == 1 and d["cell"]["sensors"]["distances_mm"] == [15.0]  # its first sensor


def test_study_bad_flags(capsys, tmp_path):
    rc, _, err = _run(capsys, "seam", "study", "--scheduler", "serial", "--workers", "2", "--out", str(tmp_path))
    assert rc == 1 and err.strip() == ("posekit: error: --workers sets the size of the local cluster; "
                                       "it cannot be combined with --scheduler")
    rc, _, err = _run(capsys, "seam", "study", "--parameters", "filter.nope", "--out", str(tmp_path))
    assert rc == 1 and err.strip() == "posekit: error: study factor 'filter.nope': no such configuration key"
    rc, _, err = _run(capsys, "seam", "study", "--parameters", "profile.plateau.d0_mm=1:x", "--out", str(tmp_path))
    assert rc == 1 and err.strip() == ("posekit: error: --parameters: expected KEY or KEY=LOW:HIGH, got "
                                       "'profile.plateau.d0_mm=1:x'")
    rc, _, err = _run(capsys, "seam", "study", "--parameters", "filter.particles=0:10", "--runs", "3",
                      "--out", str(tmp_path))
    assert rc == 1 and err.strip().startswith(
        "posekit: error: study factor 'filter.particles': range [0, 10] leaves the valid configurations")
    rc, _, err = _run(capsys, "seam", "study", "--scheduler", "nowhere", "--runs", "3", "--out", str(tmp_path))
    assert rc == 1 and "scheduler: expected 'serial' or a Dask address like tcp://HOST:PORT, got 'nowhere'" in err


# --------------------------------------------------------------------------- end to end (tiny episodes)

TINY_YAML = """\
seed: 5
trajectory: {kind: xy, length_mm: 30, steps: 30}
filter: {particles: 80}
"""


@pytest.fixture(scope="module")
def tiny_config(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "tiny.yaml"
    path.write_text(TINY_YAML)
    return path


@pytest.fixture(scope="module")
def simulated(tiny_config, tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    rc = main(["seam", "simulate", "--config", str(tiny_config), "--particles", "60", "--runs", "2",
               "--record-particles", "20", "--out", str(out)])
    assert rc == 0
    return out


def _rotvec_deg(R):
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(R).as_rotvec(degrees=True)


def _quat_matrix(c, prefix):
    from posekit.geometry import matrix_from_quaternion
    q = np.c_[c[f"{prefix}_qw"], c[f"{prefix}_qx"], c[f"{prefix}_qy"], c[f"{prefix}_qz"]]
    return matrix_from_quaternion(q)


def test_simulate_metrics_match_estimates_csv(simulated):
    m = json.loads((simulated / "metrics.json").read_text())
    assert set(m["rmse_mm"]) == {"x", "y", "z"} and set(m["rmse_deg"]) == {"rx", "ry", "rz"}
    assert m["step_ms_median"] > 0
    assert (m["runs"], m["steps"], m["particles"], m["sensors"], m["trajectory"]) == (2, 30, 60, 2, "xy")
    c = read_estimates_csv(simulated / "estimates.csv")
    assert len(c["run"]) == 60
    np.testing.assert_array_equal(np.unique(c["run"]), [0, 1])
    for i, a in enumerate(ERROR_AXES):
        key, unit = ("rmse_mm", "mm") if i < 3 else ("rmse_deg", "deg")
        rmse = np.sqrt(np.mean(c[f"err_{a}_{unit}"] ** 2))
        assert m[key][a] == pytest.approx(rmse, abs=2e-6, rel=1e-6)
        kin = np.sqrt(np.mean(c[f"kin_err_{a}_{unit}"] ** 2))
        assert m[f"kinematic_{key}"][a] == pytest.approx(kin, abs=2e-6, rel=1e-6)
    # the error columns are the tool-pose error in the nominal seam frame (DESIGN/SEAM contract)
    p = {k: np.c_[c[f"{k}_x_mm"], c[f"{k}_y_mm"], c[f"{k}_z_mm"]] for k in ("truth", "estimate", "nominal")}
    R = {k: _quat_matrix(c, k) for k in ("truth", "estimate", "nominal")}
    dp = np.einsum("nji,nj->ni", R["nominal"], p["estimate"] - p["truth"])
    np.testing.assert_allclose(np.c_[c["err_x_mm"], c["err_y_mm"], c["err_z_mm"]], dp, atol=1e-6)
    dr = _rotvec_deg(np.einsum("nji,njk->nik", R["truth"], R["estimate"]))
    np.testing.assert_allclose(np.c_[c["err_rx_deg"], c["err_ry_deg"], c["err_rz_deg"]], dr, atol=1e-6)
    assert np.median(c["step_ms"]) == pytest.approx(m["step_ms_median"], rel=1e-4)


def test_simulate_writes_figures_and_report(simulated, capsys):
    from tests.seam.test_seam_plots import png_size
    names = {"fig5_density.png": (1100, 800), "fig8_errors.png": (1100, 468), "fig9_trajectories.png": (800, 700),
             "errors_time.png": (1100, 800)}
    for name, size in names.items():
        assert png_size(simulated / name) == size
        assert (simulated / name).stat().st_size > 20_000
    text = (simulated / "report.html").read_text()
    assert text.count('src="data:image/png;base64,') == 6   # + ess.png and fig5_hypotheses.png (issue 15)
    for name in names:
        assert f'href="{name}"' in text
    m = json.loads((simulated / "metrics.json").read_text())
    assert f"<td>{m['rmse_mm']['x']:.4g}</td>" in text
    cfg = yaml.safe_load((simulated / "config.yaml").read_text())
    assert cfg["seed"] == 5 and cfg["filter"]["particles"] == 60 and cfg["trajectory"]["length_mm"] == 30


def test_simulate_same_seed_same_numbers(simulated, tiny_config, capsys):
    """The CSV holds the episodes of seeds task_seed(5, r): rerunning them gives the same numbers."""
    from posekit.seam.frontend.compare import run_episodes
    from posekit.seam.frontend.config import apply_overrides, load_config
    cfg = apply_overrides(load_config(tiny_config), {"filter.particles": 60})
    again = run_episodes(cfg, 2)
    c = read_estimates_csv(simulated / "estimates.csv")
    for r, res in enumerate(again):
        rows = c["run"] == r
        for i, col in enumerate(("err_x_mm", "err_y_mm", "err_z_mm", "err_rx_deg", "err_ry_deg", "err_rz_deg")):
            # the library holds radians, the CSV writes degrees (the *_deg columns)
            want = res.error[:, i] if i < 3 else np.degrees(res.error[:, i])
            np.testing.assert_allclose(c[col][rows], want, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(c["estimate_y_mm"][rows], res.estimate[:, 1, 3], rtol=1e-9)


def test_demo_prints_rmse_per_axis(capsys, tmp_path):
    """(The comparison report of ``--out`` is tested on synthetic sets in test_seam_plots.py.)"""
    rc = main(["seam", "demo", "--particles", "30", "--steps", "60"])
    out = capsys.readouterr().out
    assert rc == 0
    lines = [line for line in out.splitlines() if line.startswith(("xy,", "yz,"))]
    rows = {line[:24].strip(): [float(v) for v in line[24:].split()[:6]] for line in lines}
    assert list(rows) == ["xy, 0 sensors", "xy, 1 sensor", "xy, 2 sensors", "yz, 0 sensors", "yz, 1 sensor",
                          "yz, 2 sensors", "xy, FK only"]
    assert all(len(v) == 6 and all(x >= 0 for x in v) for v in rows.values())
    # fixed decimals (mm and deg to 3 places), never a mix of significant-digit widths
    numbers = [t for line in lines for t in line[24:].split()[:6]]
    assert len(numbers) == 42 and all(len(t.split(".")[1]) == 3 for t in numbers)
    # each configuration's steps tracking/degraded/lost (60 steps, one run), their total, and the verdict line
    status = [line[24:].split()[6] for line in lines[:6]]
    assert all(sum(map(int, s.split("/"))) == 60 for s in status), status
    totals = [int(n) for n in re.findall(r"(?:tracking|degraded|lost) (\d+)",
                                         next(x for x in out.splitlines() if x.startswith("status over all")))]
    assert totals == [sum(int(s.split("/")[k]) for s in status) for k in range(3)]
    assert re.search(r"^verdict: two sensors beat the kinematics on xy [0-6]/6, yz [0-6]/6 axes ", out, re.MULTILINE)
    assert out.startswith("seam demo: 1 run(s) × 60 steps, 30 particles")
    step = [line for line in out.splitlines() if line.startswith("filter step median: ")]
    assert len(step) == 1 and step[0].endswith(" ms (xy, 2 sensors, 30 particles; the paper's sensor period is 10 ms)")
    assert float(step[0].split()[3]) > 0
    # the FK-only row is the 0-sensor run's kinematic error; with no laser reading the filter reports the
    # kinematic pose itself (issue 15 item 6: never worse than kinematics where the sensors cannot help)
    assert rows["xy, FK only"] == rows["xy, 0 sensors"]
    assert rows["xy, 2 sensors"][0] < 0.5 * rows["xy, FK only"][0]


EXAMPLES = sorted(p for p in (Path(__file__).resolve().parents[2] / "examples" / "seam").glob("*.yaml")
                  if not p.name.endswith("-profile.yaml"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_configs_load_and_dump(capsys, path):
    """Every bundled example config loads through the CLI and --dump-config gives it back."""
    from posekit.seam.frontend.config import config_from_dict, load_config
    rc, out, err = _run(capsys, "seam", "simulate", "--config", str(path), "--dump-config")
    assert rc == 0 and err == ""
    assert config_from_dict(yaml.safe_load(out)) == load_config(path)


def test_rmse_table_fixed_decimals():
    from posekit.cli.seam_simulate import rmse_table
    text = rmse_table([("xy, 2 sensors", [0.76654, 2.236, 0.0, 10.0, 0.0005, 123.4567]),
                       ("a label longer than twenty-four", [1, 2, 3, 4, 5, 6])])
    assert text.splitlines() == [
        "configuration                         x mm      y mm      z mm    rx deg    ry deg    rz deg",
        "xy, 2 sensors                        0.767     2.236     0.000    10.000     0.001   123.457",
        "a label longer than twenty-four      1.000     2.000     3.000     4.000     5.000     6.000",
    ]
    # a value wider than a column widens every column: they never run together
    wide = rmse_table([("lost", [988093.0381, 1144.74, 1058.25, 80.5, 82.8, 71.4])]).splitlines()
    assert wide[1].split() == ["lost", "988093.038", "1144.740", "1058.250", "80.500", "82.800", "71.400"]
    assert len(wide[0]) == len(wide[1]) == 24 + 6 * 11


def test_cli_trajectory_choices_are_the_config_kinds():
    from posekit.cli.seam_simulate import TRAJECTORIES
    from posekit.seam.frontend.config import TRAJECTORY_KINDS
    assert TRAJECTORIES == TRAJECTORY_KINDS
