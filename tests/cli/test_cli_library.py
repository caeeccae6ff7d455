"""The profiler's CLI only parses and prints: each verb is one library function with the same
arguments (same files, same records), ``--config``/``--dump-config`` on every verb with more than
a few parameters, one spelling per concept (old spellings still work, with one note line)."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from posekit.cli.main import main
from posekit.profiler import NoiseModel, estimate_file, simulate
from posekit.profiler.sim.simulate import read_truth_csv
from posekit.verdict import Verdict, batch_exit_code
from tests.cli.test_cli_library_ceiling_seam import CONFIG_VERBS as CEILING_SEAM_VERBS

CLI = Path(__file__).resolve().parents[2] / "src" / "posekit" / "cli"


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "run"
    assert main(["profiler", "simulate", "--gauge", "demo-5", "--count", "12", "--noise-um", "4", "--seed", "3",
                 "--out", str(out)]) == 0
    return out


def test_simulate_is_one_library_call_with_the_same_arguments(simulated, tmp_path):
    sim = simulate("demo-5", 12, noise_um=4, seed=3, out=tmp_path / "lib")
    with np.load(simulated / "profiles.npz") as cli:
        np.testing.assert_array_equal(cli["profiles"], sim.profiles)        # bit for bit, NaNs included
        np.testing.assert_array_equal(cli["T_G_F"], sim.T_G_F)
    assert (simulated / "truth.csv").read_bytes() == (tmp_path / "lib" / "truth.csv").read_bytes()
    _, t, q = read_truth_csv(tmp_path / "lib" / "truth.csv")
    np.testing.assert_array_equal(t, sim.T_G_F[:, :3, 3])


def test_estimate_is_one_library_call_with_the_same_records(simulated, tmp_path, capsys):
    rc = main(["profiler", "estimate", str(simulated / "profiles.npz"), "--gauge", "demo-5"])
    printed = capsys.readouterr().out
    res = estimate_file(simulated / "profiles.npz", "demo-5", out=tmp_path / "lib.jsonl")
    assert (tmp_path / "lib.jsonl").read_text() == printed
    assert rc == res.exit_code == batch_exit_code(v.status for v in res.verdicts)
    # every record is its profile's Verdict, written out
    for rec, v in zip(map(json.loads, printed.splitlines()), res.verdicts):
        assert isinstance(v, Verdict) and rec["status"] == v.status
        if v.status == "error":
            assert rec["error"] == v.reason
        else:
            assert rec["reason"] == (v.reason or None)
            assert rec["std_t_um"] == [v.std[k] for k in ("tx_um", "ty_um", "tz_um")]
            assert rec["std_rot_deg"] == [v.std[k] for k in ("rx_deg", "ry_deg", "rz_deg")]
    counts = res.status_counts()
    assert list(counts) == ["ok", "suspect", "error"] and sum(counts.values()) == 12


def test_the_noise_rule_lives_in_the_model():
    """x-noise is twice z-noise unless given: NoiseModel.from_z_um, and nowhere in the CLI."""
    assert NoiseModel.from_z_um(5.0) == NoiseModel(sigma_x_um=10.0, sigma_z_um=5.0)
    assert NoiseModel.from_z_um(5.0, 3.0).sigma_x_um == 3.0
    assert NoiseModel.from_z_um(0.0).sigma_x_um == 0.0
    assert NoiseModel.from_z_um(2.0, outlier_rate=0.1).outlier_rate == 0.1
    rule = re.compile(r"2(\.0)?\s*\*\s*(args\.)?(noise_um|z_um|level)")
    offenders = [f"{p.name}:{i}" for p in CLI.glob("*.py")
                 for i, line in enumerate(p.read_text().splitlines(), 1) if rule.search(line)]
    assert not offenders, offenders


def test_help_constants_are_the_librarys():
    """The parsers quote two library numbers without importing the library (startup)."""
    from posekit.cli.profiler_loop import HELP_MAX_STEP_MM
    from posekit.cli.profiler_replay import HELP_RATE_HZ
    from posekit.profiler.loop.closed_loop import MAX_STEP_MM
    from posekit.profiler.stream.replay import DEFAULT_RATE_HZ

    assert (HELP_MAX_STEP_MM, HELP_RATE_HZ) == (MAX_STEP_MM, DEFAULT_RATE_HZ)


#: Every verb that takes more than a few parameters (the profiler's here, ceiling's and seam's in their
#: own test module): its command words and required arguments.
CONFIG_VERBS = {
    "estimate": (["profiler", "estimate"], ["p.npz", "--gauge", "demo-5"]),
    "simulate": (["profiler", "simulate"], ["--gauge", "demo-5", "--out", "d", "--seed", "7"]),
    "study corners": (["profiler", "study", "corners"], ["--seed", "7"]),
    "study noise": (["profiler", "study", "noise"], ["--noise-um", "0:10:5"]),
    "study limits": (["profiler", "study", "limits"], ["--tilts-deg", "-60:60:30"]),
    "loop": (["profiler", "loop"], ["--out", "d", "--runs", "2"]),
    "demo": (["demo"], ["--axes", "x,z"]),
    "serve": (["profiler", "serve"], ["--gauge", "demo-5", "--listen", "127.0.0.1:0", "--filter", "cv"]),
    "replay": (["profiler", "replay"], ["p.npz", "--to", "127.0.0.1:9"]),
    **CEILING_SEAM_VERBS,
}


@pytest.mark.parametrize("verb", CONFIG_VERBS)
def test_dump_config_round_trips(verb, tmp_path, capsys):
    """--dump-config prints YAML that --config reads back to the same parameters."""
    command, required = CONFIG_VERBS[verb]
    assert main([*command, *required, "--dump-config"]) == 0
    dumped = capsys.readouterr().out
    params = yaml.safe_load(dumped)
    assert "config" not in params and "dump_config" not in params and "help" not in params
    (tmp_path / "c.yaml").write_text(dumped)
    assert main([*command, "--config", str(tmp_path / "c.yaml"), "--dump-config"]) == 0
    assert capsys.readouterr().out == dumped


def test_config_precedence_defaults_file_flags(tmp_path, capsys):
    (tmp_path / "c.yaml").write_text("gauge: demo-7\ncount: 3\nnoise-um: 2\nrealistic: true\n")
    assert main(["profiler", "simulate", "--config", str(tmp_path / "c.yaml"), "--count", "5", "--dump-config"]) == 0
    p = yaml.safe_load(capsys.readouterr().out)
    assert (p["gauge"], p["count"], p["noise_um"], p["realistic"], p["seed"]) == ("demo-7", 5, 2.0, True, 0)


@pytest.mark.parametrize("text, message", [
    ("nois_um: 3\n", "unknown key 'nois_um'; expected one of count, dropouts, gauge, noise_um"),
    ("noise_um: -3\n", "'noise_um': expected a number in 0..10000 µm, got -3"),
    ("realistic: 1\n", "'realistic': expected true or false, got 1"),
    ("count: [1, 2]\n", "'count': expected an integer in 1..10000 profiles, got '1,2'"),
    ("- 1\n", "expected a mapping of the command's parameters (key: value), got list"),
])
def test_bad_config_is_one_line_naming_file_and_key(tmp_path, capsys, text, message):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    rc = main(["profiler", "simulate", "--gauge", "demo-5", "--out", str(tmp_path / "o"), "--config", str(path)])
    err = capsys.readouterr().err
    assert rc == 1 and err.startswith(f"posekit: error: {path}: {message}") and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("old, new, argv", [
    ("--rate", "--rate-hz", ["profiler", "replay", "p.npz", "--to", "127.0.0.1:9", "--rate", "50"]),
    ("--status-every", "--status-every-s", ["profiler", "serve", "--gauge", "demo-5", "--listen", "127.0.0.1:0",
                                            "--status-every", "2"]),
    ("--poses", "--count", ["profiler", "study", "corners", "--poses", "4"]),
    ("--repeats", "--runs", ["profiler", "loop", "--out", "d", "--repeats", "2"]),
])
def test_old_spellings_still_work_with_one_note(capsys, old, new, argv):
    assert main([*argv, "--dump-config"]) == 0
    out, err = capsys.readouterr()
    assert err == f"posekit: note: {old} is deprecated and will be removed; use {new}\n"
    assert str(float(argv[-1])) in out or f": {argv[-1]}\n" in out
