"""One CLI vocabulary: global flags anywhere, python -m posekit, negative values, the same flag
for the same idea (old spellings kept as deprecated aliases), a description on every verb."""

import argparse
import subprocess
import sys

import numpy as np
import pytest

from posekit.cli.main import _join_negative_values, build_parser, main
from posekit.errors import ConfigError


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_debug_is_accepted_anywhere_on_the_line(capsys, tmp_path):
    argv = ["seam", "simulate", "--steps", "1", "--out", str(tmp_path / "o")]
    rc, _, err = run(capsys, *argv)
    assert rc == 1 and err == "posekit: error: --steps: expected an integer >= 2, got 1\n"
    for where in (0, 2, len(argv)):
        with pytest.raises(ConfigError, match="--steps: expected an integer >= 2, got 1"):
            main([*argv[:where], "--debug", *argv[where:]])


def test_python_dash_m_posekit_is_the_command():
    done = subprocess.run([sys.executable, "-m", "posekit", "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.startswith("posekit ")


def test_negative_values_parse_without_equals():
    argv = _join_negative_values(["profiler", "study", "limits", "--tilts-deg", "-60:60:15", "--noise-um", "-.5"])
    args = build_parser().parse_args(argv)
    assert args.tilts_deg == "-60:60:15" and args.noise_um == -0.5
    assert _join_negative_values(["--out", "-", "--x", "-y"]) == ["--out", "-", "--x", "-y"]  # not numbers


def test_deprecated_spellings_still_work_with_a_note(capsys):
    parser = build_parser()
    args = parser.parse_args(["profiler", "study", "corners", "--poses", "7"])
    assert args.poses == 7
    assert "--poses is deprecated and will be removed; use --count" in capsys.readouterr().err
    assert parser.parse_args(["profiler", "study", "corners", "--count", "9"]).poses == 9
    assert parser.parse_args(["profiler", "loop", "--out", "x", "--runs", "2"]).repeats == 2
    assert parser.parse_args(["ceiling", "demo", "--duration-s", "3"]).seconds == 3.0
    assert parser.parse_args(["profiler", "serve", "--gauge", "demo-5", "--listen", "127.0.0.1:0",
                              "--duration-s", "4"]).duration == 4.0
    assert parser.parse_args(["localcal", "simulate", "--method", "line", "--out", "o", "--workers", "2"]).workers == 2
    # localcal's KITTI frame rate: --rate-hz (as profiler replay's), per input --camera-rate-hz, --kinematic-rate-hz
    capsys.readouterr()
    for old, new, dest in [("--rate", "--rate-hz", "rate"), ("--camera-rate", "--camera-rate-hz", "camera_rate"),
                           ("--kinematic-rate", "--kinematic-rate-hz", "kinematic_rate")]:
        for verb in ("match", "handeye"):
            args = parser.parse_args(["localcal", verb, "c.txt", "k.txt", "--out", "r.json", old, "30"])
            assert getattr(args, dest) == 30.0
            assert capsys.readouterr().err == f"posekit: note: {old} is deprecated and will be removed; use {new}\n"
            assert getattr(parser.parse_args(["localcal", verb, "c.txt", "k.txt", "--out", "r.json", new, "25"]),
                           dest) == 25.0


def test_estimate_out_with_an_unknown_suffix_is_an_error(capsys, tmp_path):
    np.save(tmp_path / "p.npy", np.zeros((10, 2)))
    rc, out, err = run(capsys, "profiler", "estimate", tmp_path / "p.npy", "--gauge", "demo-5", "--out",
                       tmp_path / "poses.txt")
    assert rc == 1 and err == (f"posekit: error: --out {tmp_path / 'poses.txt'}: unknown suffix '.txt'; expected "
                               "FILE.jsonl (JSON lines) or FILE.csv\n")
    assert not (tmp_path / "poses.txt").exists()


def test_global_size_flags_are_validated(capsys):
    rc, _, err = run(capsys, "bench", "profiler", "--max-input-mb", "-3")
    assert rc == 1 and err == "posekit: error: --max-input-mb: expected 1 to 1e+06 MiB, got -3\n"
    rc, _, err = run(capsys, "bench", "profiler", "--max-image-mp")
    assert rc == 2 and err == "posekit: error: --max-image-mp: expected a value\n"


def test_every_verb_has_a_one_line_description():
    missing = []

    def walk(parser, path):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    if not sub.description:
                        missing.append(" ".join([*path, name]))
                    walk(sub, [*path, name])

    walk(build_parser(), ["posekit"])
    assert missing == []


def test_same_idea_same_flag():
    """Items are --count, Monte-Carlo episodes --runs, lengths of time --duration-s, a folder of
    results --out with --overwrite; every verb that runs on Dask takes --scheduler and --workers."""
    seen = {}

    def walk(parser, path):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, [*path, name])
            elif action.option_strings and action.help != argparse.SUPPRESS:
                seen.setdefault(" ".join(path), set()).update(action.option_strings)

    walk(build_parser(), [])
    flags = set().union(*seen.values())
    assert not flags & {"--poses", "--repeats", "--seconds", "--duration"}
    for verb, opts in seen.items():
        if "--scheduler" in opts:
            assert "--workers" in opts, verb
        if "--out" in opts and verb.split()[-1] in ("simulate", "demo", "study", "loop", "corners", "noise", "limits"):
            assert "--overwrite" in opts, verb
