"""Seam configuration bounds (issue 11): every number has a documented range, so no value that
passes validation overflows or allocates absurdly later; YAML booleans are no numbers.

Regressions through ``main(argv)`` for the values that used to pass validation and crash the
run, and a bounded hypothesis property over every numeric key of ``SeamConfig``.
"""

import math
import typing
from pathlib import Path

import annotated_types
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from posekit.errors import ConfigError
from posekit.seam.frontend.config import (
    MAX_PARTICLE_STEPS,
    MAX_PARTICLES,
    MAX_STEP_SEAM_POINTS,
    MAX_STEPS,
    SEED_MAX,
    SeamConfig,
    config_from_dict,
    load_config,
)
from posekit.seam.frontend.trajectories import SEAM_SPACING_MM
from tests.cli_helpers import assert_one_line_error, run_cli

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "seam" / "default.yaml"




# --------------------------------------------------------------------------- the crashes of issue 11

CRASHES = [
    # (section, key, YAML value, needles: key, range with unit, what arrived)
    ("profile.plateau", "d0_mm", "1e308", ["profile.plateau.d0_mm", "0..1000 mm", "1e+308"]),
    ("profile.plateau", "d0_deg", "1e308", ["profile.plateau.d0_deg", "0..180 deg", "1e+308"]),
    ("profile.joints", "sigma_deg", "1e308", ["profile.joints.sigma_deg", "0..180 deg", "1e+308"]),
    ("profile.plateau", "tail_mm", "1e308", ["profile.plateau.tail_mm", "1e-09..1000 mm", "1e+308"]),
    ("profile.plateau", "tail_deg", "1e308", ["profile.plateau.tail_deg", "1e-09..180 deg", "1e+308"]),
    ("trajectory", "seam_extension_mm", "1e308", ["trajectory.seam_extension_mm", "0..1000 mm", "1e308"]),
    ("profile.plateau", "tail_mm", "1e-320", ["profile.plateau.tail_mm", "1e-09..1000 mm", "e-321"]),
    ("trajectory", "steps", str(2**63), ["trajectory.steps", "2..100000", str(2**63)]),
    ("trajectory", "steps", "1e30", ["trajectory.steps", "2..100000", "1e30"]),
    ("trajectory", "steps", "1000000000", ["trajectory.steps", "2..100000", "1000000000"]),
    ("filter", "particles", str(2**63), ["filter.particles", "1..1000000", str(2**63)]),
    ("filter", "particles", "1e30", ["filter.particles", "1..1000000", "1e30"]),
    ("filter", "particles", "1000000000", ["filter.particles", "1..1000000", "1000000000"]),
    ("simulation", "laser_noise_mm", "true", ["simulation.laser_noise_mm", "expected a number, got the boolean true",
                                               "0..1000 mm"]),
]


def _yaml(section: str, body: str) -> str:
    """``a.b`` and ``key: value`` as nested YAML."""
    parts = section.split(".")
    return "".join(f"{'  ' * i}{p}:\n" for i, p in enumerate(parts)) + "  " * len(parts) + body + "\n"


@pytest.mark.parametrize("section, key, value, needles", CRASHES, ids=[f"{c[1]}={c[2]}" for c in CRASHES])
def test_values_that_crashed_the_run_are_one_line_errors(capsys, tmp_path, section, key, value, needles):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(_yaml(section, f"{key}: {value}"))
    out = tmp_path / "out"
    rc, stdout, err = run_cli(capsys, "seam", "simulate", "--config", cfg, "--steps", 20, "--particles", 20,
                           "--out", out)
    assert_one_line_error(rc, stdout, err, str(cfg), *needles)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [cfg]                     # no temporary folder left either


@pytest.mark.parametrize("yaml_value", ["true", "false", "yes", "on"])
@pytest.mark.parametrize("key", ["simulation.laser_noise_mm", "filter.particles", "seed", "trajectory.start_mm.0",
                                 "simulation.force_n.2", "cell.sensors.count", "profile.plateau.d0_mm"])
def test_yaml_booleans_are_never_numbers(tmp_path, key, yaml_value):
    parts = key.split(".")
    if parts[-1].isdigit():                                     # an item of a tuple key
        base = {"trajectory": {"start_mm": [450, -100, 0]}, "simulation": {"force_n": [100, -1000, -5000]}}
        section, name, i = parts
        items = [str(v) for v in base[section][name]]
        items[int(i)] = yaml_value
        text = f"{section}:\n  {name}: [{', '.join(items)}]\n"
    elif len(parts) >= 2:
        text = _yaml(".".join(parts[:-1]), f"{parts[-1]}: {yaml_value}")
    else:
        text = f"{parts[0]}: {yaml_value}\n"
    path = tmp_path / "cfg.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"expected a number(, got the boolean (true|false) \(allowed | or)") as info:
        load_config(path)
    assert key in str(info.value) and "\n" not in str(info.value)


def test_the_example_file_and_dump_config_still_load(capsys, tmp_path):
    assert load_config(EXAMPLE) == load_config(EXAMPLE)
    rc, out, err = run_cli(capsys, "seam", "simulate", "--config", EXAMPLE, "--dump-config")
    assert rc == 0 and err == ""
    dumped = tmp_path / "dumped.yaml"
    dumped.write_text(out)
    assert load_config(dumped) == load_config(EXAMPLE)


@pytest.mark.parametrize("data, needles", [
    ({"trajectory": {"steps": 10_000}, "filter": {"particles": 1_000_000}},
     ["trajectory.steps × filter.particles = 10000 × 1000000", "at most 1e+09"]),
    ({"trajectory": {"steps": 100_000}},
     ["trajectory.steps × seam points = 100000 × 522", "at most 1e+07"]),
    ({"trajectory": {"steps": 1000, "length_mm": 1e4}}, ["trajectory.steps × seam points", "10060 mm"]),
])
def test_episode_size_is_bounded(data, needles):
    with pytest.raises(ConfigError) as info:
        config_from_dict(data, "cfg.yaml")
    msg = str(info.value)
    assert msg.startswith("cfg.yaml: ") and "\n" not in msg
    for needle in needles:
        assert needle in msg


def test_range_messages_name_key_range_unit_and_value():
    cases = {
        ("simulation", "angle_noise_deg", 1e9): "cfg.yaml: simulation.angle_noise_deg: expected <= 180.0, got "
                                                "1000000000.0 (allowed 0..180 deg)",
        ("trajectory", "dt_s", 0): "cfg.yaml: trajectory.dt_s: expected >= 1e-05, got 0 (allowed 1e-05..10 s)",
        ("filter", "ess_threshold", 0): "cfg.yaml: filter.ess_threshold: expected > 0.0, got 0 (allowed > 0 and <= 1)",
        ("trajectory", "bend_deg", 91): "cfg.yaml: trajectory.bend_deg: expected <= 90.0, got 91 "
                                        "(allowed -90..90 deg)",   # a right-angle corner is allowed
        ("filter", "particles", 0): "cfg.yaml: filter.particles: expected >= 1, got 0",   # a count: the bound says it
        ("filter", "particles", 1e30): "cfg.yaml: filter.particles: expected an integer, got 1e+30 "
                                       "(allowed 1..1000000)",
    }
    for (section, key, value), message in cases.items():
        with pytest.raises(ConfigError) as info:
            config_from_dict({section: {key: value}}, "cfg.yaml")
        assert str(info.value) == message
    with pytest.raises(ConfigError) as info:
        config_from_dict({"trajectory": {"start_mm": [1e9, 0, 0]}}, "cfg.yaml")
    assert str(info.value) == ("cfg.yaml: trajectory.start_mm.0: expected <= 100000.0, got 1000000000.0 "
                               "(allowed -100000..100000 mm)")
    with pytest.raises(ConfigError) as info:
        config_from_dict({"cell": {"robot": {"ik_seed_deg": list(range(1000))}}}, "cfg.yaml")
    msg = str(info.value)
    assert msg.startswith("cfg.yaml: cell.robot.ik_seed_deg: expected at most 64 values, got [0, 1, 2")
    assert len(msg) < 200


def test_cli_limits_equal_the_configs():
    from posekit.cli import _flags, seam_simulate
    assert (seam_simulate.MAX_STEPS, seam_simulate.MAX_PARTICLES) == (MAX_STEPS, MAX_PARTICLES)
    assert _flags.SEED_MAX == SEED_MAX


# --------------------------------------------------------------------------- property: any number, any key


def _numeric(annotation) -> bool:
    if annotation in (int, float):
        return True
    return any(_numeric(a) for a in typing.get_args(annotation) if a is not Ellipsis)


def _is_tuple(annotation) -> bool:
    return typing.get_origin(annotation) is tuple or any(_is_tuple(a) for a in typing.get_args(annotation))


def _numeric_keys(model=SeamConfig, section=None):
    """``[(section or None, key, is_tuple)]`` for every number of SeamConfig (sections dotted: ``cell.robot``;
    the profile is a model of its own, checked in tests/seam/test_seam_profile.py)."""
    keys = []
    for name, field in model.model_fields.items():
        ann = field.annotation
        if name == "profile":
            continue
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            keys += _numeric_keys(ann, name if section is None else f"{section}.{name}")
        elif ann is not bool and _numeric(ann):
            keys.append((section, name, _is_tuple(ann)))
    return keys


#: The 4x4 matrices (cell.robot.tool, cell.sensors.mounts: rows of four numbers each within ±1e5, and a rigid
#: transform) are nested tuples; tests/seam/test_seam_config_mounts.py checks them.
MATRIX_KEYS = {("cell.robot", "tool"), ("cell.sensors", "mounts")}
NUMERIC_KEYS = [k for k in _numeric_keys() if k[:2] not in MATRIX_KEYS]

NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1e6, max_value=1e6),
    st.integers(-(2**70), 2**70),
    st.integers(-10, 2_000_000),
    st.floats(min_value=0.0, max_value=1.0),                  # most keys accept something in 0..1
    st.integers(0, 600),
    st.sampled_from([0, -0.0, 1e-320, 5e-324, 1e-9, 1e308, 2**63, 2**63 - 1, 1e30, 1e9, 100_000, 1_000_000]),
    st.booleans(),
    st.floats(allow_nan=False).map(repr),                      # a YAML 1.1 float written as '1e-3' is a string
)


def _bounds(field, item: bool):
    meta = field.metadata
    if item:
        def walk(t):
            if typing.get_origin(t) is typing.Annotated:
                yield t
            for a in typing.get_args(t):
                if a is not Ellipsis:
                    yield from walk(a)

        for inner in walk(field.annotation):
            meta = [m for x in typing.get_args(inner)[1:] for m in getattr(x, "metadata", [x])]
            break
    lo = hi = None
    for m in meta:
        lo = m.ge if isinstance(m, annotated_types.Ge) else m.gt if isinstance(m, annotated_types.Gt) else lo
        hi = m.le if isinstance(m, annotated_types.Le) else m.lt if isinstance(m, annotated_types.Lt) else hi
    return lo, hi


def _field(section, key):
    model = SeamConfig
    for part in ([] if section is None else section.split(".")):
        model = model.model_fields[part].annotation
    return model.model_fields[key]


def _node(root, section):
    for part in ([] if section is None else section.split(".")):
        root = root.setdefault(part, {}) if isinstance(root, dict) else getattr(root, part)
    return root


@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(st.lists(st.tuples(st.sampled_from(NUMERIC_KEYS), st.data()), min_size=1, max_size=6))
def test_any_number_for_any_key_is_a_one_line_error_or_a_bounded_config(picks):
    doc, sent = {}, {}
    for (section, key, is_tuple), data in picks:
        value = data.draw(st.lists(NUMBERS, max_size=8) if is_tuple else NUMBERS)
        _node(doc, section)[key] = value
        sent[(section, key)] = value              # a key picked twice keeps its last value
    try:
        cfg = config_from_dict(doc, "fuzz.yaml")
    except ConfigError as exc:
        msg = str(exc)
        assert msg.startswith("fuzz.yaml: ") and "\n" not in msg and len(msg) < 500, msg
        return
    flat = [v for s in sent.values() for v in (s if isinstance(s, list) else [s])]
    assert not any(isinstance(v, bool) for v in flat), "a boolean was read as a number"
    steps, particles = cfg.trajectory.steps, cfg.filter.particles
    assert 2 <= steps <= MAX_STEPS and 1 <= particles <= MAX_PARTICLES
    assert steps * particles <= MAX_PARTICLE_STEPS
    seam_points = math.ceil((cfg.trajectory.length_mm + cfg.trajectory.seam_extension_mm) / SEAM_SPACING_MM) + 2
    assert steps * seam_points <= MAX_STEP_SEAM_POINTS
    assert 0 <= cfg.seed <= SEED_MAX
    for section, key, is_tuple in NUMERIC_KEYS:
        value = getattr(_node(cfg, section), key)
        values = ([] if value is None else list(value)) if is_tuple else [value]
        lo, hi = _bounds(_field(section, key), is_tuple)
        for v in values:
            if v is None:
                continue
            assert math.isfinite(v), (section, key, v)
            assert (lo is None or v >= lo) and (hi is None or v <= hi), (section, key, v, lo, hi)


def test_every_number_has_an_upper_bound():
    """No numeric key is left open-ended (the point of issue 11)."""
    for section, key, is_tuple in NUMERIC_KEYS:
        _, hi = _bounds(_field(section, key), is_tuple)
        assert hi is not None, f"{section}.{key} has no upper bound"


def test_dumped_defaults_are_within_bounds():
    data = yaml.safe_load(yaml.safe_dump(SeamConfig().model_dump(mode="json")))
    assert config_from_dict(data) == SeamConfig()
