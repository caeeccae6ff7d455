"""Seam configuration: defaults, the example file, one-line errors naming key and file."""

from pathlib import Path

import pytest

from posekit.errors import ConfigError
from posekit.seam.frontend.config import (
    SeamConfig,
    apply_overrides,
    config_from_dict,
    dump_config,
    load_config,
)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "seam" / "default.yaml"


def _write(tmp_path, text):
    p = tmp_path / "cfg.yaml"
    p.write_text(text)
    return p


def test_defaults_are_the_papers_setup():
    c = SeamConfig()
    assert c.trajectory.steps == 500 and c.trajectory.dt_s == 0.01
    assert c.sensors.count == 2 and c.sensors.resolved_distances_mm() == (20.0, 40.0)
    assert c.trajectory.kind == "xy"
    assert c.trajectory.resolved_amplitude_mm() == 20.0
    assert config_from_dict({"trajectory": {"kind": "yz"}}).trajectory.resolved_amplitude_mm() == 100.0
    assert c.filter.resampler == "systematic"


def test_example_file_equals_defaults_except_explicit_distances():
    c = load_config(EXAMPLE)
    assert c.sensors.distances_mm == (20.0, 40.0)
    assert c.model_dump(exclude={"sensors": {"distances_mm"}}) == SeamConfig().model_dump(
        exclude={"sensors": {"distances_mm"}}
    )


def test_dump_load_round_trip(tmp_path):
    c = config_from_dict({"seed": 7, "trajectory": {"kind": "bend", "bend_deg": 20.0},
                          "sensors": {"count": 1, "distances_mm": [35.0]}, "filter": {"particles": 77}})
    again = load_config(_write(tmp_path, dump_config(c)))
    assert again == c


@pytest.mark.parametrize(
    "text, message",
    [
        ("filter:\n  particles: 0\n", "cfg.yaml: filter.particles: expected >= 1, got 0"),
        ("filter:\n  particle: 10\n", "cfg.yaml: unknown key 'filter.particle'"),
        ("colour: red\n", "cfg.yaml: unknown key 'colour'"),
        ("sensors:\n  noise_mm: -0.1\n", "cfg.yaml: sensors.noise_mm: expected >= 0.0, got -0.1"),
        ("robot:\n  joint_noise_deg: -1\n", "cfg.yaml: robot.joint_noise_deg: expected >= 0.0, got -1"),
        ("sensors:\n  count: 2\n  distances_mm: [20, -5]\n",
         "cfg.yaml: sensors.distances_mm: sensor 1 is at -5 mm, expected > 0 mm (ahead of the tool)"),
        ("sensors:\n  count: 1\n  distances_mm: [0]\n",
         "cfg.yaml: sensors.distances_mm: sensor 0 is at 0 mm, expected > 0 mm (ahead of the tool)"),
        ("sensors:\n  count: 1\n  distances_mm: [20, 40]\n",
         "cfg.yaml: sensors: count is 1 but distances_mm has 2 entries"),
        ("filter:\n  resampler: multinomial\n",
         ("cfg.yaml: filter.resampler: expected one of 'systematic', 'stratified' or 'residual', "
         "got 'multinomial'")),
        ("trajectory:\n  kind: circle\n",
         "cfg.yaml: trajectory.kind: expected one of 'xy', 'yz', 'line' or 'bend', got 'circle'"),
        ("trajectory:\n  steps: many\n", "cfg.yaml: trajectory.steps: input should be a valid integer"),
        ("filter: 3\n", "cfg.yaml: filter: expected a mapping, got int"),
        ("- 1\n- 2\n", "cfg.yaml: expected a mapping of sections"),
        ("filter:\n  particles: [1\n", "cfg.yaml: not valid YAML at line"),
        ("filter:\n  ess_threshold: 1.5\n", "cfg.yaml: filter.ess_threshold: expected <= 1.0, got 1.5"),
        ("filter:\n  sigma_t_mm: .inf\n", "cfg.yaml: filter.sigma_t_mm: expected a finite number, got inf"),
        ("sensors:\n  noise_mm: .nan\n", "cfg.yaml: sensors.noise_mm: expected a finite number, got nan"),
        ("trajectory:\n  start_mm: [450, -100]\n",
         "cfg.yaml: trajectory.start_mm: too few values (no item 2), got [450, -100]"),
        ("trajectory:\n  start_mm: [1, 2, 3, 4]\n",
         "cfg.yaml: trajectory.start_mm: expected at most 3 values, got [1, 2, 3, 4]"),
        ("filter:\n  axis_scale_t: [1.0, 2.0]\n",
         "cfg.yaml: filter.axis_scale_t: too few values (no item 2), got [1.0, 2.0]"),
        ("filter:\n  axis_scale_r: [1.0, -2.0, 1]\n",
         "cfg.yaml: filter.axis_scale_r.1: expected >= 0.0, got -2.0 (allowed 0..100)"),
        ("filter:\n  load_axis_scale_r: [1.0, .nan, 1]\n",
         "cfg.yaml: filter.load_axis_scale_r.1: expected a finite number, got nan"),
        ("filter:\n  reacquire_isotropic_steps: -1\n",
         "cfg.yaml: filter.reacquire_isotropic_steps: expected >= 0, got -1"),
        ("filter:\n  walk_adapt_max: 0.5\n", "cfg.yaml: filter.walk_adapt_max: expected >= 1.0, got 0.5"),
        ("filter:\n  plateau_max_force_n: -1\n",
         "cfg.yaml: filter.plateau_max_force_n: expected >= 0.0, got -1 (allowed 0..10000000 N)"),
        ("filter:\n  cloud_floor: .nan\n", "cfg.yaml: filter.cloud_floor: expected a finite number, got nan"),
        ("filter:\n  bound_inflation: 1.5\n", "cfg.yaml: filter.bound_inflation: expected <= 1.0, got 1.5 (allowed 0..1)"),
        ("filter:\n  spread_shrink_reacquire: 1.5\n",
         "cfg.yaml: filter.spread_shrink_reacquire: expected <= 1.0, got 1.5 (allowed 0..1)"),
        ("filter:\n  bound_reacquire_steps: -5\n", "cfg.yaml: filter.bound_reacquire_steps: expected >= 0, got -5"),
    ],
)
def test_bad_config_gives_one_line_error_naming_key_and_file(tmp_path, text, message):
    with pytest.raises(ConfigError) as info:
        load_config(_write(tmp_path, text))
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(str(tmp_path / "cfg.yaml")[: -len("cfg.yaml")])
    assert message in msg


def test_missing_file_and_empty_file(tmp_path):
    with pytest.raises(ConfigError, match=r"nope\.yaml: no such file; expected a seam configuration YAML file"):
        load_config(tmp_path / "nope.yaml")
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"filter:\n  particles: 5\xff\n")
    with pytest.raises(ConfigError, match=r"binary\.yaml: line 2: byte 0xff is not UTF-8; expected a seam configuration YAML file in UTF-8 \(save it as UTF-8\)$"):
        load_config(binary)
    assert load_config(_write(tmp_path, "")) == SeamConfig()


def test_overrides_set_dotted_keys_and_validate():
    c = SeamConfig()
    c1 = apply_overrides(c, {"sensors.count": 1, "filter.particles": 50, "trajectory.kind": None})
    assert c1.sensors.resolved_distances_mm() == (20.0,) and c1.filter.particles == 50
    assert c1.trajectory.kind == "xy"
    explicit = config_from_dict({"sensors": {"count": 2, "distances_mm": [25.0, 50.0]}})
    assert apply_overrides(explicit, {"sensors.count": 1}).sensors.distances_mm == (25.0,)
    with pytest.raises(ConfigError, match=r"^command line: unknown key 'filter\.nope'$"):
        apply_overrides(c, {"filter.nope": 1})
    with pytest.raises(ConfigError, match=r"^command line: filter\.particles: expected >= 1, got 0$"):
        apply_overrides(c, {"filter.particles": 0})
    with pytest.raises(ConfigError, match=r"^command line: sensors: count is 3 but distances_mm has 2"):
        apply_overrides(explicit, {"sensors.count": 3})
