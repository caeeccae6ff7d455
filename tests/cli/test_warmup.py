"""``posekit warmup``: its tasks are real commands, and what they compile is what a command needs."""

import numpy as np

from posekit import _jit
from posekit.cli.main import build_parser, main
from posekit.cli.warmup import SYSTEMS, TASKS


def test_every_task_is_a_valid_command():
    """A renamed flag breaks this test, not a user's warm-up."""
    parser = build_parser()
    for name, system, commands in TASKS:
        assert system in SYSTEMS and name.startswith(system)
        assert len(commands) >= 1
        for argv in commands:
            args = parser.parse_args([a.replace("{tmp}", "/tmp/x") for a in argv])
            assert callable(args.func)
    assert {t[1] for t in TASKS} == set(SYSTEMS)


def test_unknown_system_is_one_line(capsys):
    assert main(["warmup", "profilr"]) == 1
    assert capsys.readouterr().err == ("posekit: error: warmup: unknown system 'profilr'; expected one of "
                                       "profiler, ceiling, localcal, seam\n")


def _signatures():
    return {(k.py_func.__module__, k.py_func.__qualname__, sig) for k in _jit.kernels() for sig in k.overloads}


def test_after_the_estimate_task_an_estimate_compiles_nothing(tmp_path, capsys):
    """The warm-up's estimate task leaves every signature that ``profiler estimate`` on a user's
    CSV needs in the process: the command adds none (whatever the disk cache holds)."""
    commands = next(t[2] for t in TASKS if t[0] == "profiler-estimate")
    for argv in commands:
        assert main([a.replace("{tmp}", str(tmp_path)) for a in argv]) in (0, 1)
    profiles = np.load(tmp_path / "sim" / "profiles.npz")["profiles"]
    csv = tmp_path / "one.csv"
    np.savetxt(csv, profiles[1], delimiter=",", header="x,z", comments="")
    before = _signatures()
    assert main(["profiler", "estimate", str(csv), "--gauge", "demo-5"]) in (0, 1)
    new = _signatures() - before
    capsys.readouterr()
    assert new == set(), f"compiled beyond the warm-up: {sorted(n[:2] for n in new)}"


def test_bad_workers(capsys):
    assert main(["warmup", "--workers", "0"]) == 1
    assert capsys.readouterr().err == "posekit: error: --workers: expected an integer in 1..64 processes, got 0\n"
