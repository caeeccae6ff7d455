"""``posekit ceiling simulate`` on a full disk (issue 28 item 9): one line naming the cause, exit 1,
no partial video installed — on a real full file system (a 400 kB tmpfs, where the tests run as
root) and with the failure injected at a write."""

import errno
import os
import subprocess

import pytest

from tests.cli_helpers import assert_one_line_error, run_cli


def test_injected_enospc_is_one_line_and_nothing_installed(capsys, tmp_path, monkeypatch):
    import posekit.ceiling.sim.video as video

    def full(path, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(video, "write_truth_csv", full)
    out = tmp_path / "sim"
    rc, stdout, err = run_cli(capsys, "ceiling", "simulate", "--duration-s", "1", "--out", out)
    assert_one_line_error(rc, stdout, err, "truth.csv", "no space left on device")
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name != "sim"]


def test_real_full_tmpfs(capsys, tmp_path):
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=400k", "tmpfs", str(mnt)],
                                           capture_output=True).returncode != 0:
        pytest.skip("needs root and mount to make a small file system")
    try:
        out = mnt / "sim"
        rc, stdout, err = run_cli(capsys, "ceiling", "simulate", "--duration-s", "10", "--out", out)
        assert_one_line_error(rc, stdout, err, "no space left on device")
        assert not out.exists() and os.listdir(mnt) == []           # no partial video, no staging left
    finally:
        subprocess.run(["umount", str(mnt)], check=False)
