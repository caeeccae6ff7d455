"""Seam configuration: the four parts (cell, simulation, filter, profile), the example file, one-line errors naming
key and file, the layout before issue 26 mapped with a one-line note or refused naming what replaced a key."""

import warnings
from pathlib import Path

import pytest

from posekit.errors import ConfigError
from posekit.seam.frontend.config import (
    FilterConfig,
    LayoutNote,
    SeamConfig,
    apply_overrides,
    config_from_dict,
    dump_config,
    load_config,
)
from posekit.seam.frontend.config_legacy import REMOVED_FILTER_KEYS
from posekit.seam.frontend.profile import default_profile

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "seam"


def _write(tmp_path, text, name="cfg.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_defaults_are_the_papers_setup_and_the_default_profile():
    c = config_from_dict({})
    assert c.trajectory.steps == 500 and c.trajectory.dt_s == 0.01 and c.trajectory.kind == "xy"
    assert c.cell.sensors.count == 2 and c.cell.sensors.resolved_distances_mm() == (20.0, 40.0)
    assert c.trajectory.resolved_amplitude_mm() == 20.0
    assert config_from_dict({"trajectory": {"kind": "yz"}}).trajectory.resolved_amplitude_mm() == 100.0
    assert c.filter.resampler == "systematic" and c.profile == default_profile()


def test_the_filter_section_has_at_most_15_keys_each_documented_beside_it():
    src = (Path(__file__).resolve().parents[2] / "src" / "posekit" / "seam" / "frontend" / "config.py").read_text()
    keys = list(FilterConfig.model_fields)
    assert len(keys) <= 15, keys
    for k in keys:  # every key's line carries its meaning after '#'
        line = next(ln for ln in src.splitlines() if ln.strip().startswith(f"{k}:"))
        assert "#" in line and len(line.split("#", 1)[1].strip()) > 15, line


def test_example_file_equals_the_defaults(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the example is in the current layout: no note
        c = load_config(EXAMPLES / "default.yaml")
    assert c == config_from_dict({"cell": {"sensors": {"distances_mm": [20.0, 40.0]}}})


def test_dump_load_round_trip(tmp_path):
    c = config_from_dict({"seed": 7, "trajectory": {"kind": "bend", "bend_deg": 20.0},
                          "cell": {"sensors": {"count": 1, "distances_mm": [35.0], "latency_s": [0.012]}},
                          "filter": {"particles": 77}, "profile": {"plateau": {"d0_mm": 1.5}}})
    again = load_config(_write(tmp_path, dump_config(c)))
    assert again == c and again.profile.plateau.d0_mm.value == 1.5


@pytest.mark.parametrize(
    "text, message",
    [
        ("filter:\n  particles: 0\n", "cfg.yaml: filter.particles: expected >= 1, got 0"),
        ("filter:\n  particle: 10\n", "cfg.yaml: unknown key 'filter.particle'"),
        ("colour: red\n", "cfg.yaml: unknown key 'colour'"),
        ("simulation:\n  laser_noise_mm: -0.1\n", "cfg.yaml: simulation.laser_noise_mm: expected >= 0.0, got -0.1"),
        ("cell:\n  sensors:\n    count: 2\n    distances_mm: [20, -5]\n",
         "cfg.yaml: cell.sensors.distances_mm: sensor 1 is at -5 mm, expected > 0 mm (ahead of the tool)"),
        ("cell:\n  sensors:\n    count: 1\n    distances_mm: [20, 40]\n",
         "cfg.yaml: cell.sensors: count is 1 but distances_mm has 2 entries"),
        ("cell:\n  sensors:\n    count: 2\n    latency_s: [0.01]\n",
         "cfg.yaml: cell.sensors: count is 2 but latency_s has 1 entries"),
        ("cell:\n  sensors:\n    latency_s: [0.01, 2.0]\n",
         "cfg.yaml: cell.sensors.latency_s.1: expected <= 1.0, got 2.0"),
        ("filter:\n  resampler: multinomial\n",
         "cfg.yaml: filter.resampler: expected one of 'systematic', 'stratified' or 'residual', got 'multinomial'"),
        ("trajectory:\n  kind: circle\n",
         "cfg.yaml: trajectory.kind: expected one of 'xy', 'yz', 'line' or 'bend', got 'circle'"),
        ("filter: 3\n", "cfg.yaml: filter: expected a mapping, got int"),
        ("- 1\n- 2\n", "cfg.yaml: expected a mapping of sections"),
        ("filter:\n  particles: [1\n", "cfg.yaml: not valid YAML at line"),
        ("filter:\n  ess_threshold: 1.5\n", "cfg.yaml: filter.ess_threshold: expected <= 1.0, got 1.5"),
        ("filter:\n  integrity_alpha_lost: 0.01\n",
         "cfg.yaml: filter: integrity_alpha_lost 0.01 is above integrity_alpha_degraded 0.001"),
        ("simulation:\n  laser_latency_s: [0.01, 0.02, 0.03]\n",
         "cfg.yaml: simulation.laser_latency_s has 3 values for 2 sensors"),
        ("profile:\n  plateau:\n    d0_mm: 1e308\n", "cfg.yaml: profile.plateau.d0_mm: expected 0..1000 mm, got 1e+308"),
        ("profile:\n  walk:\n    z_mm: {value: 0.1, std: -1}\n", "cfg.yaml: profile.walk.z_mm.std"),
        ("profile:\n  sensors: [{latency_s: 0}, {latency_s: 0}, {latency_s: 0}]\n",
         "cfg.yaml: profile: 3 sensor entries for a cell with 2 sensor(s)"),
        ("profile: nope.yaml\n", "nope.yaml: no such file; expected a seam profile"),
    ],
)
def test_bad_config_gives_one_line_error_naming_key_and_file(tmp_path, text, message):
    with pytest.raises(ConfigError) as info:
        load_config(_write(tmp_path, text))
    msg = str(info.value)
    assert "\n" not in msg
    assert message in msg, msg


def test_missing_file_and_empty_file(tmp_path):
    with pytest.raises(ConfigError, match=r"nope\.yaml: no such file; expected a seam configuration YAML file"):
        load_config(tmp_path / "nope.yaml")
    assert load_config(_write(tmp_path, "")) == config_from_dict({})


def test_overrides_set_dotted_keys_profile_values_and_validate():
    c = config_from_dict({})
    c1 = apply_overrides(c, {"cell.sensors.count": 1, "filter.particles": 50, "trajectory.kind": None,
                             "profile.walk.z_mm": 0.2, "profile.plateau.d0_mm": {"value": 2.5, "std": 0.1}})
    assert c1.cell.sensors.resolved_distances_mm() == (20.0,) and c1.filter.particles == 50
    assert c1.profile.walk.z_mm.value == 0.2 and c1.profile.plateau.d0_mm.std == 0.1
    assert c1.profile.walk.x_mm == c.profile.walk.x_mm  # the other values stay the profile's
    explicit = config_from_dict({"cell": {"sensors": {"count": 2, "distances_mm": [25.0, 50.0]}}})
    assert apply_overrides(explicit, {"cell.sensors.count": 1}).cell.sensors.distances_mm == (25.0,)
    with pytest.raises(ConfigError, match=r"^command line: unknown key 'filter\.nope'$"):
        apply_overrides(c, {"filter.nope": 1})
    with pytest.raises(ConfigError, match=r"^command line: filter\.particles: expected >= 1, got 0$"):
        apply_overrides(c, {"filter.particles": 0})
    with pytest.raises(ConfigError, match=r"^command line: unknown key 'walk\.q_mm'$"):
        apply_overrides(c, {"profile.walk.q_mm": 1.0})


def test_a_profile_path_is_relative_to_the_config_file(tmp_path):
    from posekit.seam.frontend.profile import write_profile

    p = default_profile().model_copy(update={"notes": ("mine",)})
    (tmp_path / "cell").mkdir()
    write_profile(tmp_path / "cell" / "p.yaml", p)
    c = load_config(_write(tmp_path / "cell", "profile: p.yaml\n"))
    assert c.profile.notes == ("mine",)


OLD = """robot:
  model: ur10
  joint_noise_deg: 0.01
process:
  force_n: [0, 0, -3000]
sensors:
  count: 2
  noise_mm: 0.03
filter:
  particles: 300
  d0_mm: 3.8
  laser_sigma_mm: 0.03
  reacquire_transition_scale: 4.0
  axis_scale_r: [1.0, 0.8, 0.07]
  init_offset_mm: [1.0, 0.0, 0.0]
"""


def test_the_layout_before_issue_26_is_mapped_with_a_one_line_note(tmp_path):
    with pytest.warns(LayoutNote) as rec:
        c = load_config(_write(tmp_path, OLD))
    (note,) = [str(w.message) for w in rec]
    assert "\n" not in note and note.startswith(str(tmp_path / "cfg.yaml") + ": the layout before issue 26, mapped: ")
    assert "robot.model -> cell.robot.model" in note and "1 old default(s) dropped" in note
    assert c.cell.robot.model == "ur10" and c.simulation.joint_noise_deg == 0.01
    assert c.simulation.force_n == (0.0, 0.0, -3000.0) and c.simulation.laser_noise_mm == 0.03
    assert c.filter.particles == 300 and c.filter.reacquire_walk_scale == 4.0
    assert c.simulation.start_offset_mm == (1.0, 0.0, 0.0)
    assert c.profile.plateau.d0_mm.value == 3.8 and c.profile.sensors[0].sigma_mm.value == 0.03
    # the rest of the profile is the default's
    assert c.profile.walk == default_profile().walk
    # and it dumps in the new layout, which loads without a note
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_config(_write(tmp_path, dump_config(c), "new.yaml")) == c


def test_an_old_dump_at_its_defaults_loads_a_tuned_removed_key_is_one_line_naming_the_replacement(tmp_path):
    old_filter = "\n".join(f"  {k}: {list(v) if isinstance(v, tuple) else v}" for k, (v, _) in
                           REMOVED_FILTER_KEYS.items())
    with pytest.warns(LayoutNote):
        c = load_config(_write(tmp_path, "filter:\n" + old_filter.replace("True", "true") + "\n"))
    assert c == config_from_dict({})
    with pytest.raises(ConfigError) as info:
        load_config(_write(tmp_path, "filter:\n  axis_scale_r: [1, 1, 1]\n"))
    assert str(info.value) == (f"{tmp_path / 'cfg.yaml'}: filter.axis_scale_r: removed (issue 26); the walk per "
                               "tool axis is fitted from data: profile walk.* (posekit seam tune)")
    with pytest.raises(ConfigError, match="filter.cloud_floor: removed .issue 26.; the spread bound runs"):
        load_config(_write(tmp_path, "filter:\n  cloud_floor: 0.5\n"))
    with pytest.raises(ConfigError, match=r"sections of both layouts \('cell' and robot/process/sensors\)"):
        load_config(_write(tmp_path, "robot: ur10\ncell:\n  compliance_rad_per_nm: 0\n"))


@pytest.mark.parametrize("name", sorted(p.name for p in EXAMPLES.glob("*.yaml") if not p.name.endswith("-profile.yaml")))
def test_every_example_is_in_the_current_layout_and_commented(name):
    path = EXAMPLES / name
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cfg = load_config(path)
    assert isinstance(cfg, SeamConfig)
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.strip().startswith("#")]
    keyed = [ln for ln in lines if ":" in ln and not ln.strip().startswith("-")]
    commented = [ln for ln in keyed if "#" in ln]
    if name == "default.yaml":  # every key of the defaults, each with its meaning
        assert len(commented) >= 0.9 * len([ln for ln in keyed if not ln.rstrip().endswith(":")])
    assert path.read_text().startswith("# posekit seam")
