"""The profile file (src/posekit/seam/frontend/profile.py): round trip, one-line errors, and the shipped default
profile reproduced by the command in its header."""

import shlex
from pathlib import Path

import numpy as np
import pytest
import yaml

from posekit.errors import ConfigError
from posekit.seam.frontend.profile import (
    DEFAULT_PROFILE,
    PRIOR_PROFILE,
    dump_profile,
    load_profile,
    merge_profile,
    profile_data,
    write_profile,
)


def test_round_trip_keeps_values_stds_notes_and_provenance(tmp_path):
    p = load_profile(DEFAULT_PROFILE)
    back = load_profile(write_profile(tmp_path / "p.yaml", p, "a header"))
    assert back == p
    assert (tmp_path / "p.yaml").read_text().startswith("# a header\n")
    assert p.fitted.method == "truth" and len(p.fitted.episodes) == 12
    assert all(len(e.sha256) == 64 and e.steps == 500 for e in p.fitted.episodes)
    assert p.walk.x_mm.std is not None and float(p.walk.x_mm) > 0.0
    m = p.to_model()
    assert m.walk.shape == m.jitter.shape == m.spread_scale.shape == (6,)
    assert m.laser_sigma_mm.shape == m.latency_s.shape == (1,)
    # the offset test's calibration, in the filter's units (mm, rad)
    assert m.offset_mean.shape == m.offset_sd.shape == m.offset_samples.shape == (6,)
    assert m.offset_sd[4] == pytest.approx(np.radians(float(p.offset.sd.ry_deg)))
    assert m.offset_samples[4] == p.offset.samples.ry and np.all(m.offset_samples >= 2.0)
    # without the block there is no offset test
    d = profile_data(p)
    d.pop("offset")
    path = tmp_path / "no-offset.yaml"
    path.write_text(yaml.safe_dump(d))
    assert load_profile(path).to_model().offset_sd is None


def test_merge_replaces_values_and_keeps_the_rest():
    p = load_profile(DEFAULT_PROFILE)
    q = merge_profile(p, {"plateau": {"d0_mm": 3.8}, "sensors": [{"latency_s": 0.015}]})
    assert float(q.plateau.d0_mm) == 3.8 and float(q.sensors[0].latency_s) == 0.015
    assert q.walk == p.walk and float(q.sensors[0].sigma_mm) == float(p.sensors[0].sigma_mm)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["walk"].update(x_mm=-1), "walk.x_mm: expected 0..1000 mm, got -1"),
    (lambda d: d.update(format="x"), "format 'x'; expected 'posekit-seam-profile'"),
    (lambda d: d.update(version=2), "version: input should be 1"),
    (lambda d: d.update(bogus=1), "unknown key 'bogus'"),
    (lambda d: d["sensors"][0].update(latency_s={"value": 2.0, "std": 0.1}), "sensors.0.latency_s: expected 0..1 s, got 2"),
    (lambda d: d["spread"].update(rz=0.0), "spread.rz: expected 0.1..100, got 0"),
    (lambda d: d["offset"]["sd"].update(z_mm=-0.1), "offset.sd.z_mm: expected 0..1000 mm, got -0.1"),
    (lambda d: d["offset"]["mean"].update(ry_deg=200), "offset.mean.ry_deg: expected -180..180 deg, got 200"),
    (lambda d: d["offset"]["samples"].update(x=-1), "offset.samples.x: input should be greater than or equal to 0"),
])
def test_bad_profile_is_one_line_naming_file_and_key(tmp_path, edit, message):
    d = profile_data(load_profile(DEFAULT_PROFILE))
    edit(d)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError) as e:
        load_profile(path)
    assert str(e.value) == f"{path}: {message}"


def test_prior_profile_is_hand_set_and_complete():
    p = load_profile(PRIOR_PROFILE)
    assert p.fitted.method == "hand" and not p.fitted.episodes
    assert "walk:" in dump_profile(p) and np.all(p.to_model().spread_scale == 1.0)


def test_the_default_profile_names_the_episodes_its_command_simulates(tmp_path):
    """The cheap half of reproducing the shipped default profile: the command in its header simulates the very
    episodes the file names (same folder names, steps and SHA-256 of each log.csv). The fit itself (~1-2 min) is
    re-run and compared value by value by the test below."""
    from posekit.seam.frontend.config import apply_overrides, config_from_dict
    from posekit.seam.frontend.profile import episode_record
    from posekit.seam.frontend.tune import simulate_episodes

    shipped = load_profile(DEFAULT_PROFILE)
    argv = shlex.split(shipped.fitted.command)
    assert argv[:3] == ["posekit", "seam", "tune"] and "--config" not in argv
    runs, kinds, seed = (int(argv[argv.index("--simulate") + 1]), argv[argv.index("--trajectory") + 1].split(","),
                         int(argv[argv.index("--seed") + 1]))
    cfg = config_from_dict({}, "defaults")
    dirs = []
    for k in kinds:
        dirs += simulate_episodes(apply_overrides(cfg, {"trajectory.kind": k}), runs, seed, tmp_path / k)
    got = [episode_record(d) for d in dirs]
    want = [e.model_dump() for e in shipped.fitted.episodes]
    assert got == want


def _reproduce_script():
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "seam_profile_reproduce.py"
    spec = importlib.util.spec_from_file_location("seam_profile_reproduce", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SHIPPED_PROFILES = [DEFAULT_PROFILE, *sorted((Path(__file__).resolve().parents[2] / "examples" / "seam")
                                             .glob("*-profile.yaml"))]


@pytest.mark.slow
@pytest.mark.parametrize("path", SHIPPED_PROFILES, ids=lambda p: p.name)
def test_the_command_in_a_shipped_profile_writes_that_profile(path):
    """Issue 26: the shipped profiles are made by a command from data, and re-running the command in
    each file's header reproduces every value, 1σ, note and episode hash (the default ~1 min, an
    example ~15 s; ``python benchmarks/seam_profile_reproduce.py`` does the same from the shell)."""
    assert _reproduce_script().reproduce(path) == []
