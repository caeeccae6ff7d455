"""Hostile input to the seam commands of the next round (issue 15): ``seam track LOGDIR`` on
recorded episodes that are malformed, truncated, huge or absurd; ``seam simulate --save-log``;
``seam design`` grids, counts and schedulers.

Each is one line ``posekit: error: FILE line N: what was wrong; what was expected`` (or the
flag), exit 1, no traceback, and no --out folder left behind (DESIGN.md "Safe input and output").
"""

import shutil

import pytest

from posekit.errors import one_line
from posekit.seam.frontend.config import config_from_dict
from posekit.seam.frontend.logs import write_episode_log
from posekit.seam.frontend.simulate import simulate_data
from tests.cli_helpers import assert_one_line_error, run_cli

LOG_WHAT = "one sample per line: time_s, qref_*, q_*, fx_n.., m{k}_x_mm.."
SETUP_WHAT = "the setup of a recorded seam episode (robot, tool, sensors, filter)"
COLUMNS = ("time_s,qref_1,qref_2,qref_3,qref_4,qref_5,qref_6,q_1,q_2,q_3,q_4,q_5,q_6,fx_n,fy_n,fz_n,m1_x_mm,m1_z_mm,"
           "m2_x_mm,m2_z_mm")
#: A "billion laughs" YAML: a few hundred characters that expand to 9^6 values.
BOMB = "".join(f"{a}: &{a} [{', '.join([f'*{p}'] * 9) if p else ', '.join(['1'] * 9)}]\n"
               for p, a in zip(["", "a", "b", "c", "d", "e"], "abcdef"))


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    """A recorded 20-step episode of the default cell (puma560, two sensors)."""
    folder = tmp_path_factory.mktemp("episode") / "log"
    folder.mkdir()
    cfg = config_from_dict({"trajectory": {"steps": 20}, "filter": {"particles": 50}})
    write_episode_log(folder, cfg, simulate_data(cfg, 3), 3)
    return folder


def _variant(episode, tmp_path, name, edit):
    """A copy of the episode with ``name`` replaced by ``edit(text)`` (None: the file removed)."""
    dst = tmp_path / "ep"
    shutil.copytree(episode, dst)
    path = dst / name
    if edit is None:
        path.unlink()
    else:
        path.write_text(edit(path.read_text()))
    return dst


def _line(i, fn):
    def edit(text):
        lines = text.splitlines()
        lines[i] = fn(lines[i])
        return "\n".join(lines) + "\n"
    return edit


def _cells(i, j, value):
    """Row ``i`` of a CSV with cell ``j`` set to ``value``."""
    def fn(s):
        cells = s.split(",")
        cells[j] = value
        return ",".join(cells)
    return _line(i, fn)


def _track_fails(capsys, logdir, message, *extra, global_args=()):
    out = logdir.parent / "out"
    rc, o, e = run_cli(capsys, *global_args, "seam", "track", logdir, "--out", out, *extra)
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: {one_line(message, 284)}\n"          # the line's 300 characters
    assert not out.exists()
    assert [p.name for p in logdir.parent.iterdir() if p.name.startswith(".")] == []


CASES = [
    # setup.yaml
    ("setup.yaml", lambda t: t.replace("- [0.0, 0.0, 1.0, 150.0]", "- [0.0, 0.0, 2.0, 150.0]"),
     "setup.yaml: tool: T_flange_tool: expected a rotation (orthonormal, det +1) in the upper-left 3x3, off by 3"),
    ("setup.yaml", lambda t: t.replace("- [0.0, 0.0, 0.0, 1.0]\nsensors", "- [0.0, 0.0, 1.0, 1.0]\nsensors"),
     "setup.yaml: tool: T_flange_tool: expected the last row [0, 0, 0, 1], got [0.0, 0.0, 1.0, 1.0]"),
    ("setup.yaml", lambda t: t.replace("- - [1.0, 0.0, 0.0, 0.0]\n  - [0.0, 1.0, 0.0, 20.0]",
                                       "- - [1.0, 0.0, 0.0, 0.0]\n  - [0.0, 1.0, 0.5, 20.0]"),
     "setup.yaml: sensors: sensor 1 (T_tool_sensor): expected a rotation (orthonormal, det +1) in the upper-left "
     "3x3, off by 0.5"),
    ("setup.yaml", lambda t: t.replace("puma560", "r2d2"),
     "setup.yaml: robot.model: expected one of ['puma560', 'hiab033', 'abb_irb6640', 'ur10'] (or urdf: PATH), got "
     "'r2d2'"),
    ("setup.yaml", lambda t: "", "setup.yaml: expected a mapping (robot, tool, sensors, filter), got NoneType"),
    ("setup.yaml", lambda t: "[1, 2]\n", "setup.yaml: expected a mapping (robot, tool, sensors, filter), got list"),
    ("setup.yaml", lambda t: t.replace("150.0", ".nan"), "setup.yaml: tool.2.3: expected a finite number, got nan"),
    ("setup.yaml", lambda t: t + "colour: red\n", "setup.yaml: unknown key 'colour'"),
    ("setup.yaml", None, f"setup.yaml: no such file; expected {SETUP_WHAT}"),
    # fixed here: the alias bomb took 7 s (9^7 values walked) before an unrelated message
    ("setup.yaml", lambda t: BOMB,
     f"setup.yaml: expands to more than {2 * len(BOMB) + 64:,} values (YAML aliases); expected a plain document"),
    # log.csv
    ("log.csv", _cells(3, 1, "abc"), "log.csv line 4: qref_1 is 'abc'; expected a number"),
    ("log.csv", _cells(3, 13, "nan"), "log.csv line 4: fx_n is 'nan'; expected a finite number"),
    ("log.csv", _cells(3, 0, "inf"), "log.csv line 4: time_s is 'inf'; expected a finite number"),
    ("log.csv", _cells(5, 0, "0.0"), "log.csv line 6: time_s 0 after 0.03; expected strictly increasing times"),
    ("log.csv", _cells(5, 0, "0.03"), "log.csv line 6: time_s 0.03 after 0.03; expected strictly increasing times"),
    ("log.csv", _line(2, lambda s: s + ",1"), f"log.csv line 3: 21 values; expected 20 ({COLUMNS[:80]})"),
    ("log.csv", lambda t: t.rstrip("\n")[:-25], f"log.csv line 21: 19 values; expected 20 ({COLUMNS[:80]})"),
    ("log.csv", lambda t: "", f"log.csv: file is empty; expected {LOG_WHAT}"),
    ("log.csv", lambda t: t.splitlines()[0] + "\n", "log.csv: no samples; expected one row per sample after the "
                                                    "header"),
    ("log.csv", _line(0, lambda s: s.replace("fz_n", "fq_n")),
     f"log.csv line 1: missing fz_n; expected the columns {COLUMNS} (6 joints of puma560, 2 sensor(s) in "
     "setup.yaml)"),
    ("log.csv", lambda t: "\x00" * 100, f"log.csv: binary data (NUL bytes); expected {LOG_WHAT} (UTF-8 text)"),
    ("log.csv", None, f"log.csv: no such file; expected {LOG_WHAT}"),
    # fixed here: absurd magnitudes were read and tracked ('tracking' with a joint at 1e300 rad)
    ("log.csv", _cells(3, 7, "1e300"), "log.csv line 4: q_1 is 1e+300; expected a magnitude of at most 1000 rad"),
    ("log.csv", _cells(1, 0, "1e300"), "log.csv line 2: time_s is 1e+300; expected a magnitude of at most 1e+09 s"),
    ("log.csv", _cells(3, 14, "-1e12"), "log.csv line 4: fy_n is -1e+12; expected a magnitude of at most 1e+06 N"),
    ("log.csv", _cells(3, 16, "1e9"), "log.csv line 4: m1_x_mm is 1e+09; expected a magnitude of at most 1e+07 mm"),
    # seam.csv, truth.csv
    ("seam.csv", lambda t: "\n".join(t.splitlines()[:2]) + "\n", "seam.csv: 1 seam points; expected at least 2"),
    ("seam.csv", lambda t: "", "seam.csv: file is empty; expected the nominal seam 'x_mm,y_mm,z_mm', one point per "
                               "line"),
    ("seam.csv", _line(3, lambda s: "1e300,0,0"), "seam.csv line 4: x_mm is 1e+300; expected a magnitude of at most "
                                                   "1e+07 mm"),
    ("seam.csv", _line(0, lambda s: "x,y,z"), "seam.csv line 1: expected the header 'x_mm,y_mm,z_mm', got 'x,y,z'"),
    ("truth.csv", lambda t: "\n".join(t.splitlines()[:-3]) + "\n",
     "truth.csv: 17 rows; expected one per log.csv sample (20)"),
    ("truth.csv", _line(3, lambda s: s + ",1"),
     "truth.csv line 4: 9 values; expected 8 (time_s,tx_mm,ty_mm,tz_mm,qw,qx,qy,qz)"),
]


@pytest.mark.parametrize(("name", "edit", "message"), CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_bad_recorded_episode(capsys, episode, tmp_path, name, edit, message):
    logdir = _variant(episode, tmp_path, name, edit)
    _track_fails(capsys, logdir, f"{logdir}/{message}")


def test_huge_files_are_refused_by_the_size_limit(capsys, episode, tmp_path):
    logdir = _variant(episode, tmp_path, "log.csv", lambda t: t + "#" * (2 * 2**20) + "\n")
    _track_fails(capsys, logdir, f"{logdir}/log.csv: 2.01 MiB, above the 1 MiB limit for {LOG_WHAT} (raise it with "
                                 "--max-input-mb)", global_args=("--max-input-mb", 1))
    shutil.rmtree(logdir)
    logdir = _variant(episode, tmp_path, "setup.yaml", lambda t: t + "#" * (2 * 2**20) + "\n")
    _track_fails(capsys, logdir, f"{logdir}/setup.yaml: 2 MiB, above the 1 MiB limit for {SETUP_WHAT} (raise it "
                                 "with --max-input-mb)", global_args=("--max-input-mb", 1))


@pytest.mark.slow
def test_track_outputs(capsys, episode, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    full = tmp_path / "full"
    full.mkdir()
    (full / "old.csv").write_text("x")
    for out, message in [
        (afile, f"--out {afile}: exists and is not a folder; expected a folder name"),
        (full, f"--out {full}: the folder exists and is not empty and holds 1 entry posekit did not write "
               "('old.csv'); expected a new or empty folder (pass --overwrite to replace it, deleting it)"),
    ]:
        rc, o, e = run_cli(capsys, "seam", "track", episode, "--out", out)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: {message}\n"
    assert afile.read_text() == "x" and [p.name for p in full.iterdir()] == ["old.csv"]
    rc, o, e = run_cli(capsys, "seam", "track", afile, "--out", tmp_path / "o")
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: {afile}: not a folder; expected a recorded episode (setup.yaml, seam.csv, log.csv)\n"
    out = tmp_path / "o"
    rc, o, e = run_cli(capsys, "seam", "track", episode, "--out", out, "--jsonl", full)
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: --jsonl {full}: is a folder; expected a file name or -\n"
    assert not out.exists()
    # the good episode with --jsonl: one object per step, the folder complete
    jl = tmp_path / "steps.jsonl"
    rc, o, e = run_cli(capsys, "seam", "track", episode, "--out", out, "--jsonl", jl)
    assert rc == 0, e
    assert len(jl.read_text().splitlines()) == 20
    assert sorted(p.name for p in out.iterdir()) == [".posekit-run.json", "errors_time.png", "ess.png", "estimates.csv",
                                                     "metrics.json"]


def test_simulate_save_log_folder(capsys, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    full = tmp_path / "full"
    full.mkdir()
    (full / "x").write_text("x")
    base = ["seam", "simulate", "--steps", 5, "--particles", 20]
    for save, out, message in [
        (full, tmp_path / "o1", f"--save-log {full}: the folder exists and is not empty and holds 1 entry posekit "
                                "did not write ('x'); expected a new or empty folder (--overwrite replaces it only if "
                                "posekit wrote all of it; remove them or pick another folder)"),
        (afile, tmp_path / "o2", f"--save-log {afile}: exists and is not a folder; expected a folder name"),
        (tmp_path / "same", tmp_path / "same", "--save-log: expected a folder other than --out"),
    ]:
        rc, o, e = run_cli(capsys, *base, "--out", out, "--save-log", save)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: {one_line(message, 284)}\n"
        assert not out.exists()
    assert [p.name for p in full.iterdir()] == ["x"]


# ------------------------------------------------------------------------ seam design

DESIGN = ["seam", "design", "--runs", 1, "--steps", 5, "--particles", 10]


@pytest.mark.parametrize(("extra", "message"), [
    (["--distances-mm", ""], "--distances-mm: expected A:B:STEP or a comma-separated list of mm, got ''"),
    (["--distances-mm", "80:20:20"], "--distances-mm: expected A:B:STEP with A <= B and STEP > 0, got '80:20:20'"),
    (["--distances-mm", "20:80:0"], "--distances-mm: expected A:B:STEP with A <= B and STEP > 0, got '20:80:0'"),
    (["--distances-mm", "20:80:-5"], "--distances-mm: expected A:B:STEP with A <= B and STEP > 0, got '20:80:-5'"),
    (["--distances-mm", "a:b:c"], "--distances-mm: expected A:B:STEP or a comma-separated list of mm, got 'a:b:c'"),
    (["--distances-mm", "nan:80:20"],
     "--distances-mm: expected A:B:STEP or a comma-separated list of mm, got 'nan:80:20'"),
    (["--distances-mm", "1:2:3:4"], "--distances-mm: expected A:B:STEP or a comma-separated list of mm, got '1:2:3:4'"),
    (["--distances-mm", "1:1000:0.001"], "--distances-mm: '1:1000:0.001' gives 999001 distances; expected at most 50"),
    # fixed here: an internal error (OverflowError: cannot convert float infinity to integer)
    (["--distances-mm", "1:1e300:1e-300"],
     "--distances-mm: '1:1e300:1e-300' gives more than 1,000,000 distances; expected at most 50"),
    (["--distances-mm", "20,20"], "--distances-mm: '20,20' repeats a distance"),
    (["--distances-mm", "-20,20"], "--distances-mm: -20 mm is outside (0, 1000] mm (a sensor ahead of the tool)"),
    (["--distances-mm", ",".join(str(i) for i in range(1, 200))], "--distances-mm: 199 distances; expected at most 50"),
    (["--sensors", "4", "--distances-mm", "20,40"], "--sensors 4: only 2 distances on the grid; expected at least 4"),
    (["--sensors", ""], "--sensors: expected comma-separated sensor counts 0..4, got ''"),
    (["--sensors", "5"], "--sensors: expected comma-separated sensor counts 0..4, got '5'"),
    (["--sensors", "one"], "--sensors: expected comma-separated sensor counts 0..4, got 'one'"),
    # counted before the enumeration now (it took 2 s to list half a million configurations first)
    (["--sensors", "0,1,2,3,4", "--distances-mm", "1:50:1", "--angle", "both"],
     "502,351 sensor configurations; expected at most 2,000: fewer --sensors counts or a coarser --distances-mm grid"),
    (["--sensors", "1,2", "--distances-mm", "1:50:1", "--runs", "1000"],
     "1275 configurations × --runs 1000 = 1,275,000 episodes; expected at most 100,000"),
    (["--runs", "0"], "--runs: expected an integer in 1..1000, got 0"),
    (["--lever-mm", "nan"], "--lever-mm: expected a number > 0 and <= 10000 mm, got nan"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:8786"],
     "--workers sets the size of the local cluster; it cannot be combined with --scheduler"),
    # fixed here: these waited 5 s for a connection (or failed inside Dask) instead of saying what is wrong
    (["--scheduler", "localhost"],
     "--scheduler: expected 'serial' or a Dask address tcp://HOST:PORT with a port in 1..65535, got 'localhost'"),
    (["--scheduler", "tcp://localhost"],
     "--scheduler: expected 'serial' or a Dask address tcp://HOST:PORT with a port in 1..65535, got 'tcp://localhost'"),
    (["--scheduler", "tcp://127.0.0.1:99999"], "--scheduler: expected 'serial' or a Dask address tcp://HOST:PORT "
                                                "with a port in 1..65535, got 'tcp://127.0.0.1:99999'"),
])
def test_design_bad_flags(capsys, tmp_path, extra, message):
    out = tmp_path / "design"
    rc, o, e = run_cli(capsys, *DESIGN, *extra, "--out", out)
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: {message}\n"
    assert not out.exists()


def test_design_config_and_out(capsys, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    full = tmp_path / "full"
    full.mkdir()
    (full / "x").write_text("x")
    files = {"bad.yaml": "trajectory: {steps: -1}\n", "nan.yaml": "trajectory: {steps: .nan}\n", "list.yaml": "- 1\n",
             "bomb.yaml": BOMB}
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    for extra, message in [
        (["--out", afile], f"--out {afile}: exists and is not a folder; expected a folder name"),
        (["--out", full], f"--out {full}: the folder exists and is not empty and holds 1 entry posekit did not write "
                          "('x'); expected a new or empty folder (pass --overwrite to replace it, deleting it)"),
        (["--config", tmp_path / "nope.yaml"], f"{tmp_path / 'nope.yaml'}: no such file; expected a seam "
                                               "configuration YAML file"),
        (["--config", tmp_path / "bad.yaml"], f"{tmp_path / 'bad.yaml'}: trajectory.steps: expected >= 2, got -1"),
        (["--config", tmp_path / "nan.yaml"], f"{tmp_path / 'nan.yaml'}: trajectory.steps: expected a finite number, "
                                              "got nan"),
        (["--config", tmp_path / "list.yaml"], f"{tmp_path / 'list.yaml'}: expected a mapping of sections (seed, "
                                               "trajectory, cell, simulation, filter, profile), got list"),
        (["--config", tmp_path / "bomb.yaml"], f"{tmp_path / 'bomb.yaml'}: expands to more than "
                                               f"{2 * len(BOMB) + 64:,} values (YAML aliases); expected a plain "
                                               "document"),
    ]:
        argv = [*DESIGN, *extra] + ([] if "--out" in extra else ["--out", tmp_path / "d"])
        rc, o, e = run_cli(capsys, *argv)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: {message}\n", extra
    assert not (tmp_path / "d").exists() and [p.name for p in full.iterdir()] == ["x"]
