"""The seam system on robots other than the PUMA 560: bundled vendor URDF arms and a user's
URDF file named in the config (path relative to the config file)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from posekit.cli.main import main
from posekit.errors import ConfigError
from posekit.seam import config_from_dict, load_config
from posekit.seam.frontend.trajectories import nominal_trajectory, tool_chain

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _episodes(config, sensors):
    """``metrics.json`` of what ``_simulate`` runs, by the library (no figures)."""
    from posekit.seam.frontend.compare import episode_seeds
    from posekit.seam.frontend.config import apply_overrides
    from posekit.seam.frontend.episode import run_episode
    from posekit.seam.frontend.episode_metrics import metrics

    cfg = apply_overrides(load_config(config), {"cell.sensors.count": sensors, "trajectory.steps": 150,
                                                 "filter.particles": 200})
    return json.loads(json.dumps(metrics([run_episode(cfg, s) for s in episode_seeds(3, 2)])))


def _simulate(tmp_path, config, sensors, out):
    rc = main(["seam", "simulate", "--config", str(config), "--sensors", str(sensors), "--steps", "150",
               "--particles", "200", "--runs", "2", "--seed", "3", "--out", str(tmp_path / out)])
    assert rc == 0
    return json.loads((tmp_path / out / "metrics.json").read_text())


def test_urdf_config_two_sensors_beat_none_on_x_and_z(tmp_path):
    """The UR10 from its URDF file, named by a path relative to a config file in another
    folder: the lasers cut the x and z errors of the kinematics-only estimate."""
    folder = tmp_path / "cell"
    (folder / "robots").mkdir(parents=True)
    shutil.copy(EXAMPLES / "robots" / "ur10.urdf", folder / "robots" / "my_arm.urdf")
    cfg = yaml.safe_load((EXAMPLES / "seam" / "ur10-urdf.yaml").read_text())
    cfg["cell"]["robot"]["urdf"] = "robots/my_arm.urdf"
    cfg["profile"] = str(EXAMPLES / "seam" / "ur10-profile.yaml")
    (folder / "setup.yaml").write_text(yaml.safe_dump(cfg))
    none = _episodes(folder / "setup.yaml", 0)
    two = _simulate(tmp_path, folder / "setup.yaml", 2, "s2")
    for axis in ("x", "z"):
        assert two["rmse_mm"][axis] < 0.4 * none["rmse_mm"][axis], axis
    assert two["rmse_mm"]["x"] < 0.5 and two["rmse_mm"]["z"] < 1.0
    written = yaml.safe_load((tmp_path / "s2" / "config.yaml").read_text())
    assert written["cell"]["robot"]["urdf"] == str((folder / "robots" / "my_arm.urdf").resolve())
    assert written["cell"]["robot"]["model"] is None


def test_bundled_industrial_arm_two_sensors_beat_none(tmp_path):
    none = _episodes(EXAMPLES / "seam" / "abb_irb6640.yaml", 0)
    two = _episodes(EXAMPLES / "seam" / "abb_irb6640.yaml", 2)
    for axis in ("x", "z"):
        assert two["rmse_mm"][axis] < 0.3 * none["rmse_mm"][axis], axis


def test_program_on_every_bundled_arm_reproduces_the_seam():
    starts = {"puma560": None, "ur10": [700.0, -100.0, 0.0], "abb_irb6640": [1700.0, -100.0, 500.0]}
    for robot, start in starts.items():
        traj = {"steps": 100} if start is None else {"steps": 100, "start_mm": start}
        cfg = config_from_dict({"cell": {"robot": robot}, "trajectory": traj})
        nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
        assert nt.q.shape == (100, 6)
        assert np.abs(nt.T_nominal[:, :3, 3] - nt.T_program[:, :3, 3]).max() < 1e-3, robot


def test_robot_config_forms(tmp_path):
    assert config_from_dict({"cell": {"robot": "ur10"}}).cell.robot.model == "ur10"
    assert config_from_dict({}).cell.robot.model == "puma560"
    (tmp_path / "c.yaml").write_text("cell:\n  robot:\n    urdf: arm.urdf\n    tip_link: ee_link\n")
    cfg = load_config(tmp_path / "c.yaml")
    assert cfg.cell.robot.urdf == str(tmp_path / "arm.urdf") and cfg.cell.robot.model is None
    with pytest.raises(ConfigError, match=r"arm\.urdf: no such URDF file"):
        tool_chain(cfg.cell.robot)


@pytest.mark.parametrize(
    ("robot", "match"),
    [
        ({"urdf": "/a.urdf", "model": "ur10"},
         r"^c: cell\.robot: give either model \(a bundled robot\) or urdf \(a file\), not both$"),
        ("kuka", r"^c: cell\.robot\.model: expected one of \['puma560', 'hiab033', 'abb_irb6640', 'ur10'\] \(or urdf: "
                 r"PATH\), got 'kuka'$"),
        ({"tip_link": "tool0"}, r"^c: cell\.robot: base_link and tip_link need urdf: PATH$"),
        ({"model": "ur10", "ik_seed_deg": [0.0, 1.0]}, r"^cell\.robot\.ik_seed_deg: expected 6 values for ur10, got 2$"),
    ],
)
def test_bad_robot_config(robot, match):
    with pytest.raises(ConfigError, match=match):
        cfg = config_from_dict({"cell": {"robot": robot}}, "c")
        nominal_trajectory(cfg.trajectory, cfg.cell.robot)


def test_unreachable_start_names_the_robot_and_the_keys():
    cfg = config_from_dict({"cell": {"robot": "ur10"}, "trajectory": {"start_mm": [5000.0, 0.0, 0.0], "steps": 20}})
    with pytest.raises(Exception, match=r"leaves the ur10 workspace or passes a singularity \(set trajectory\.start_mm or "
                                        r"cell\.robot\.ik_seed_deg\)"):
        nominal_trajectory(cfg.trajectory, cfg.cell.robot)


def test_study_runs_on_a_urdf_robot(tmp_path):
    rc = main(["seam", "study", "--config", str(EXAMPLES / "seam" / "ur10-urdf.yaml"), "--runs", "3",
               "--steps", "60", "--particles", "60", "--scheduler", "serial", "--out", str(tmp_path / "st")])
    assert rc == 0
    import csv

    rows = list(csv.DictReader((tmp_path / "st" / "runs.csv").open()))
    assert [r["status"] for r in rows] == ["ok"] * 3
    assert all(0.0 < float(r["rmse_x_mm"]) < 1.0 for r in rows)
