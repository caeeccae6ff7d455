"""Output safety: a run's folder appears whole or not at all, an existing non-empty --out is an
error unless --overwrite, a failed rerun never mixes two runs, single files are renamed into place."""

import argparse
import os

import pytest

from posekit.cli._common import overwrite_flag, replace_own_flag
from posekit.cli.main import main
from posekit.errors import ConfigError
from posekit.io import MARKER, atomic_file, staged_folder, write_text_atomic


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def names(folder):
    """The files of a run folder without posekit's marker."""
    return sorted(p.name for p in folder.iterdir() if p.name != MARKER)


def test_staged_folder_is_all_or_nothing(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RuntimeError):
        with staged_folder(out) as tmp:
            (tmp / "metrics.json").write_text("{}")
            raise RuntimeError("the run failed half way")
    assert not out.exists() and leftovers(tmp_path) == []
    with staged_folder(out) as tmp:
        (tmp / "a.txt").write_text("first")
    assert (out / "a.txt").read_text() == "first"
    with pytest.raises(ConfigError, match=r"run: the folder exists and is not empty \(an earlier posekit run\); "
                                          r"expected a new or empty folder \(pass --overwrite to replace it\)"):
        with staged_folder(out):
            pass
    with pytest.raises(RuntimeError):
        with staged_folder(out, overwrite=True) as tmp:
            (tmp / "b.txt").write_text("second")
            raise RuntimeError
    assert names(out) == ["a.txt"]  # the old run, untouched
    with staged_folder(out, overwrite=True) as tmp:
        (tmp / "b.txt").write_text("second")
    assert names(out) == ["b.txt"]  # replaced whole, not mixed
    assert leftovers(tmp_path) == []


def test_atomic_file_keeps_the_old_file_on_failure(tmp_path):
    target = tmp_path / "cal.json"
    target.write_text("old")
    with pytest.raises(ValueError):
        with atomic_file(target) as fh:
            fh.write("half of the new")
            raise ValueError
    assert target.read_text() == "old" and leftovers(tmp_path) == []
    write_text_atomic(target, "new")
    assert target.read_text() == "new"
    with pytest.raises(ConfigError, match=r"--out .*: is a folder; expected a file name"):
        write_text_atomic(tmp_path, "x")


def test_seam_simulate_refuses_a_non_empty_out_and_overwrite_replaces_it(tmp_path, capsys):
    argv = ["seam", "simulate", "--steps", "30", "--particles", "20", "--sensors", "0"]
    out = tmp_path / "run"
    out.mkdir()
    (out / "old_figure.png").write_bytes(b"old")
    rc, _, err = run(capsys, *argv, "--out", out)
    assert rc == 1 and err == (f"posekit: error: --out {out}: the folder exists and is not empty and holds 1 entry "
                               "posekit did not write ('old_figure.png'); expected a new or empty folder (pass "
                               "--overwrite to replace it, deleting it)\n")
    rc, stdout, err = run(capsys, *argv, "--out", out, "--overwrite")
    assert rc == 0, err
    names = {p.name for p in out.iterdir()}
    assert "old_figure.png" not in names and "metrics.json" in names
    assert f"wrote {out}:" in stdout and ".partial" not in stdout
    assert leftovers(tmp_path) == []


def test_a_failing_rerun_leaves_the_previous_run_whole(tmp_path, capsys, monkeypatch):
    argv = ["seam", "simulate", "--steps", "30", "--particles", "20", "--sensors", "0", "--out", tmp_path / "run"]
    assert run(capsys, *argv)[0] == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()}
    import posekit.seam.frontend.commands as report  # the seam library's simulate writes through it

    real = report.write_simulation

    def half_then_fail(out, *a, **k):
        (out / "metrics.json").write_text("{new but incomplete}")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(report, "write_simulation", half_then_fail)
    rc, _, err = run(capsys, *argv, "--overwrite")
    assert rc == 1 and err == (f"posekit: error: --out {tmp_path / 'run'}: cannot write the results (No space left "
                               "on device); the previous contents are unchanged\n")
    after = {p.name: p.read_bytes() for p in (tmp_path / "run").iterdir()}
    assert after == before and leftovers(tmp_path) == []
    monkeypatch.setattr(report, "write_simulation", real)


def test_profiler_simulate_does_not_overwrite_silently(tmp_path, capsys):
    argv = ["profiler", "simulate", "--gauge", "demo-5", "--count", "2", "--out", tmp_path / "sim"]
    assert run(capsys, *argv)[0] == 0
    first = (tmp_path / "sim" / "profiles.npz").read_bytes()
    rc, _, err = run(capsys, *argv[:-2], "--seed", "1", "--out", tmp_path / "sim")
    assert rc == 1 and "the folder exists and is not empty" in err
    assert (tmp_path / "sim" / "profiles.npz").read_bytes() == first
    assert run(capsys, *argv[:-2], "--seed", "1", "--out", tmp_path / "sim", "--overwrite")[0] == 0
    assert (tmp_path / "sim" / "profiles.npz").read_bytes() != first


def test_a_verbs_own_default_folder_is_replaced_each_run():
    ns = argparse.Namespace
    assert replace_own_flag(ns(out="posekit-demo", overwrite=False, out_default="posekit-demo"))
    assert not overwrite_flag(ns(out="posekit-demo", overwrite=False, out_default="posekit-demo"))
    assert not replace_own_flag(ns(out="mine", overwrite=False, out_default="posekit-demo"))
    assert overwrite_flag(ns(out="mine", overwrite=True, out_default=None))


@pytest.mark.parametrize("verb", [["profiler", "simulate", "--gauge", "demo-5", "--count", "1"],
                                  ["ceiling", "simulate", "--duration-s", "0.2"]])
def test_simulate_into_a_read_only_folder_is_one_line(tmp_path, capsys, monkeypatch, verb):
    """Root can write anywhere, so the read-only folder is simulated at os.access."""
    import os

    ro = tmp_path / "read_only"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if str(p) == str(ro) else real(p, mode, **kw))
    rc, out, err = run(capsys, *verb, "--out", ro / "run")
    assert rc == 1 and err == f"posekit: error: --out {ro / 'run'}: the folder {ro} is not writable\n"
    assert list(ro.iterdir()) == []


def test_a_permission_error_while_creating_the_run_folder_is_one_line(tmp_path, capsys, monkeypatch):
    real = os.mkdir

    def denied(path, *a, **k):                  # the run's temporary folder only
        if str(path).endswith(".partial"):
            raise PermissionError(13, "Permission denied")
        return real(path, *a, **k)

    monkeypatch.setattr(os, "mkdir", denied)
    rc, out, err = run(capsys, "profiler", "simulate", "--gauge", "demo-5", "--count", "1", "--out", tmp_path / "r")
    assert rc == 1 and err == (f"posekit: error: --out {tmp_path / 'r'}: cannot create a folder in {tmp_path} "
                               "(Permission denied)\n")
