"""What ``--out`` names is written into or refused, never replaced (issue 28, deliverables 1 and 2).

- a character device (made with ``mknod`` in the test's folder, as root: a copy of /dev/null and
  of /dev/full) is written into and stays a device; a full one is one line;
- a named pipe gets the output through its reader and stays a pipe; one without a reader is one
  line after a bounded wait;
- a symbolic link is followed: the file it points to gets the output, the link stays a link;
- a socket is refused in one line;
- a run folder carries a marker of what the run wrote; a verb's default folder is replaced only
  while posekit wrote everything in it, ``--overwrite`` says what it would delete, and a folder
  that cannot be replaced (``/``, the current folder) is refused before any work.
"""

import os
import socket
import stat
import threading

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.io import MARKER, atomic_file, open_stream, staged_folder, write_text_atomic
from posekit.io import _output as output
from posekit.profiler import bundled_gauge, nominal_pose, render_profiles
from tests.cli_helpers import assert_one_line_error, run_cli

ROOT = os.geteuid() == 0


@pytest.fixture(scope="module")
def profile_npy(tmp_path_factory):
    gauge = bundled_gauge("demo-5")
    path = tmp_path_factory.mktemp("profile") / "p.npy"
    np.save(path, render_profiles(gauge, nominal_pose(gauge), rng=0))
    return path


def _estimate(capsys, profile, out):
    return run_cli(capsys, "profiler", "estimate", profile, "--gauge", "demo-5", "--out", out)


def _device(tmp_path, name, minor):
    path = tmp_path / name
    try:
        os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, minor))
    except PermissionError:
        pytest.skip("mknod needs root (CAP_MKNOD)")
    return path


# --- devices ------------------------------------------------------------------------------------

@pytest.mark.skipif(not ROOT, reason="mknod needs root")
def test_out_on_a_character_device_is_written_into_never_replaced(tmp_path, capsys, profile_npy):
    null = _device(tmp_path, "null.csv", 3)                      # a /dev/null made here
    rc, out, err = _estimate(capsys, profile_npy, null)
    assert rc == 0, err
    assert stat.S_ISCHR(os.stat(null).st_mode) and os.stat(null).st_rdev == os.makedev(1, 3)
    write_text_atomic(null, "anything")
    assert stat.S_ISCHR(os.stat(null).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["null.csv"]   # no temporary file beside it


@pytest.mark.skipif(not ROOT, reason="mknod needs root")
def test_a_full_device_is_one_line(tmp_path, capsys, profile_npy):
    full = _device(tmp_path, "full.jsonl", 7)                    # a /dev/full: every write is ENOSPC
    rc, out, err = _estimate(capsys, profile_npy, full)
    assert_one_line_error(rc, out, err, f"--out {full}: cannot write (No space left on device)")
    assert stat.S_ISCHR(os.stat(full).st_mode)


def test_dev_null_itself_stays_a_device(capsys, profile_npy):
    rc, out, err = _estimate(capsys, profile_npy, "/dev/null")
    assert rc == 0, err
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


# --- named pipes --------------------------------------------------------------------------------

def _reader(path, sink):
    def run():
        with open(path, "rb") as fh:
            sink.append(fh.read())
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_out_on_a_named_pipe_goes_to_its_reader(tmp_path, capsys, profile_npy):
    fifo = tmp_path / "poses.csv"
    os.mkfifo(fifo)
    got = []
    reader = _reader(fifo, got)
    rc, out, err = _estimate(capsys, profile_npy, fifo)
    reader.join(10)
    assert rc == 0, err
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    regular = tmp_path / "regular.csv"
    assert _estimate(capsys, profile_npy, regular)[0] == 0
    assert got == [regular.read_bytes()] and got[0].startswith(b"index,status,")


def test_a_named_pipe_without_a_reader_is_one_line(tmp_path, capsys, profile_npy, monkeypatch):
    monkeypatch.setattr(output, "FIFO_WAIT_S", 0.3)
    fifo = tmp_path / "nobody.jsonl"
    os.mkfifo(fifo)
    rc, out, err = _estimate(capsys, profile_npy, fifo)
    assert_one_line_error(rc, out, err)
    assert err == f"posekit: error: --out {fifo}: a named pipe that nobody reads (waited 0.3 s); start its reader first\n"
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_a_jsonl_stream_into_a_named_pipe(tmp_path):
    fifo = tmp_path / "live.jsonl"
    os.mkfifo(fifo)
    got = []
    reader = _reader(fifo, got)
    stream = open_stream(fifo)
    stream.write('{"a": 1}\n')
    stream.flush()
    stream.close()
    reader.join(10)
    assert got == [b'{"a": 1}\n'] and stat.S_ISFIFO(os.stat(fifo).st_mode)


# --- links and sockets --------------------------------------------------------------------------

def test_a_symlink_is_followed_and_stays_a_link(tmp_path, capsys, profile_npy):
    target = tmp_path / "data" / "poses.csv"
    target.parent.mkdir()
    target.write_text("old\n")
    os.chmod(target, 0o640)
    link = tmp_path / "latest.csv"
    link.symlink_to(target)
    rc, out, err = _estimate(capsys, profile_npy, link)
    assert rc == 0, err
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_text().startswith("index,status,")
    assert stat.S_IMODE(os.stat(target).st_mode) == 0o640          # the file keeps its permissions
    # a dangling link: the file it names is created
    dangling = tmp_path / "next.csv"
    dangling.symlink_to(tmp_path / "data" / "new.csv")
    assert _estimate(capsys, profile_npy, dangling)[0] == 0
    assert dangling.is_symlink() and (tmp_path / "data" / "new.csv").read_text().startswith("index,")
    # a link to a run folder: the folder it names is replaced, the link stays
    real = tmp_path / "runs" / "r1"
    real.mkdir(parents=True)
    (tmp_path / "current").symlink_to(real)
    with staged_folder(tmp_path / "current", overwrite=True) as tmp:
        (tmp / "metrics.json").write_text("{}")
    assert (tmp_path / "current").is_symlink() and (real / "metrics.json").exists()
    assert [p.name for p in (tmp_path / "runs").iterdir()] == ["r1"]


def test_a_socket_is_refused(tmp_path, capsys, profile_npy):
    path = tmp_path / "s.csv"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(path))
        rc, out, err = _estimate(capsys, profile_npy, path)
        assert_one_line_error(rc, out, err, f"--out {path}: is a socket; expected a file name")
        with pytest.raises(ConfigError, match="is a socket"):
            open_stream(path)
        assert stat.S_ISSOCK(os.stat(path).st_mode)


def test_a_failed_write_leaves_the_old_file(tmp_path):
    target = tmp_path / "cal.json"
    target.write_text("old")

    with pytest.raises(ConfigError, match=r"--out .*cal.json: cannot write \(No space left on device\); the previous "
                                          r"file is unchanged"):
        with atomic_file(target) as fh:
            fh.write("new")
            raise OSError(28, "No space left on device")
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["cal.json"]


def test_a_stream_empties_an_existing_file_only_when_it_writes(tmp_path):
    path = tmp_path / "live.jsonl"
    path.write_text("yesterday's records\n")
    stream = open_stream(path)
    stream.close(discard=True)                         # the run never started
    assert path.read_text() == "yesterday's records\n"
    stream = open_stream(path)
    stream.write("{}\n")
    stream.close()
    assert path.read_text() == "{}\n"
    new = tmp_path / "new.jsonl"
    open_stream(new).close(discard=True)
    assert not new.exists()


def test_serve_that_cannot_start_keeps_an_existing_jsonl(tmp_path, capsys):
    jsonl = tmp_path / "r.jsonl"
    jsonl.write_text('{"seq": 0}\n')
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        rc, out, err = run_cli(capsys, "profiler", "serve", "--gauge", "demo-5", "--listen", f"127.0.0.1:{port}",
                               "--jsonl", jsonl)
    assert rc == 1 and "cannot bind" in err
    assert jsonl.read_text() == '{"seq": 0}\n'


# --- run folders --------------------------------------------------------------------------------

def _run(out, files, **kw):
    with staged_folder(out, **kw) as tmp:
        for name, text in files.items():
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / name).write_text(text)


def test_a_default_folder_is_replaced_only_while_posekit_wrote_all_of_it(tmp_path):
    out = tmp_path / "posekit-demo"
    _run(out, {"table.csv": "1", "fig/a.png": "png"}, replace_own=True)
    assert (out / MARKER).is_file()
    _run(out, {"table.csv": "2", "fig/a.png": "png2"}, replace_own=True)      # the next run replaces it
    assert (out / "table.csv").read_text() == "2"
    (out / "my_notes.txt").write_text("mine")
    with pytest.raises(ConfigError) as err:
        _run(out, {"table.csv": "3"}, replace_own=True)
    assert str(err.value) == (f"--out {out}: the folder exists and is not empty and holds 1 entry posekit did not "
                              "write ('my_notes.txt'); expected a new or empty folder (pass --overwrite to replace "
                              "it, deleting it)")
    assert (out / "my_notes.txt").read_text() == "mine" and (out / "table.csv").read_text() == "2"
    (out / "my_notes.txt").unlink()
    (out / "table.csv").write_text("2, edited by hand")                    # a posekit file changed: the user's now
    (out / "fig" / "mine").mkdir()
    with pytest.raises(ConfigError, match=r"holds 2 entries posekit did not write \('fig/mine/', 'table.csv'\)"):
        _run(out, {"table.csv": "3"}, replace_own=True)
    _run(out, {"table.csv": "3"}, overwrite=True)                          # the user says so
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "table.csv"]
    assert [p.name for p in tmp_path.iterdir()] == ["posekit-demo"]       # nothing hidden left beside it


def test_a_folder_without_a_marker_is_the_users(tmp_path):
    out = tmp_path / "posekit-demo"
    out.mkdir()
    (out / "table.csv").write_text("from an older posekit, or the user's")
    with pytest.raises(ConfigError, match=r"holds 1 entry posekit did not write \('table.csv'\)"):
        _run(out, {"table.csv": "3"}, replace_own=True)


def test_the_demo_default_folder_from_the_cli(tmp_path, capsys, monkeypatch):
    """``posekit profiler study noise`` writes its default folder ``study_noise`` in the current folder."""
    monkeypatch.chdir(tmp_path)
    argv = ["profiler", "study", "noise", "--noise-um", "1", "--gauges", "1", "--count", "2", "--scheduler", "serial"]
    assert run_cli(capsys, *argv)[0] == 0
    first = (tmp_path / "study_noise" / MARKER).read_text()
    assert run_cli(capsys, *argv, "--seed", "1")[0] == 0                  # replaced without --overwrite
    assert (tmp_path / "study_noise" / MARKER).read_text() != first
    (tmp_path / "study_noise" / "my_notes.txt").write_text("mine")
    rc, out, err = run_cli(capsys, *argv)
    assert_one_line_error(rc, out, err, "--out study_noise: the folder exists and is not empty and holds 1 entry "
                                        "posekit did not write ('my_notes.txt')", "pass --overwrite")
    assert (tmp_path / "study_noise" / "my_notes.txt").read_text() == "mine"


def test_save_log_is_replaced_by_overwrite_only_while_it_is_posekits(tmp_path, capsys):
    log = tmp_path / "log"
    log.mkdir()
    (log / "mine.csv").write_text("x")
    rc, out, err = run_cli(capsys, "seam", "simulate", "--steps", 5, "--particles", 20, "--out", tmp_path / "o",
                           "--save-log", log, "--overwrite")
    assert_one_line_error(rc, out, err, "--save-log", "the folder exists and is not empty and holds 1 entry posekit "
                                        "did not write ('mine.csv'); expected a new or empty folder (--overwrite "
                                        "replaces it only if posekit wrote all of it; remove them or pick another "
                                        "folder)")
    assert [p.name for p in log.iterdir()] == ["mine.csv"] and not (tmp_path / "o").exists()


@pytest.mark.parametrize("where", ["root", "cwd", "parent_of_cwd"])
def test_folders_that_cannot_be_replaced_are_refused_before_any_work(tmp_path, capsys, monkeypatch, where):
    run = tmp_path / "run"
    (run / "sub").mkdir(parents=True)
    (run / "old.txt").write_text("x")
    out, cwd, why = {"root": ("/", tmp_path, "is the root folder"),
                     "cwd": (run, run, "is the current folder"),
                     "parent_of_cwd": (run, run / "sub", "holds the current folder")}[where]
    monkeypatch.chdir(cwd)
    rc, o, e = run_cli(capsys, "profiler", "simulate", "--gauge", "demo-5", "--count", "1", "--out", out,
                       "--overwrite")
    assert_one_line_error(rc, o, e, f"--out {out}: {why} and cannot be replaced by a run's folder; expected a new "
                                    "folder (e.g. a sub-folder of it)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    assert sorted(p.name for p in run.iterdir()) == ["old.txt", "sub"]
