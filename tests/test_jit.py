"""posekit._jit: where compiled kernels go, for every user, and the first-compile note.

The cache tests install posekit read-only into a temporary folder and run a kernel as an
unprivileged user (made with ``useradd``) twice: the second run must load, not compile. They
need root (to make the user and a private mount namespace in which the interpreter under
root's home is reachable); elsewhere they are skipped.
"""

import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import numba
import numpy as np
import pytest

import posekit
from posekit import _jit

USER = "posekit-cachetest"
SRC = Path(posekit.__file__).resolve().parent

# Run as the user: one kernel (RDP), then report whether it was compiled or loaded and where.
PROBE = r"""
import json, os, sys
import numpy as np
from posekit import _jit
from posekit.geometry import rdp
from posekit.geometry._simplify import rdp_mask_kernel
t = np.linspace(0.0, 10.0, 60)
rdp(np.c_[t, np.sin(t)], 0.05)
st = rdp_mask_kernel.stats
print(json.dumps({"hits": sum(st.cache_hits.values()), "misses": sum(st.cache_misses.values()),
                  "path": st.cache_path, "posekit": _jit.__file__}))
"""


def _can_run_as_user() -> str | None:
    """Why the unprivileged-user tests cannot run here, or None."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return "needs root (to create a user and a mount namespace)"
    for tool in ("useradd", "runuser", "unshare", "mount"):
        if shutil.which(tool) is None:
            return f"needs {tool}"
    if subprocess.run(["unshare", "-m", "true"], capture_output=True).returncode != 0:
        return "cannot make a mount namespace"
    return None


@pytest.fixture(scope="module")
def install():
    """A read-only copy of posekit (no compiled kernels in it) and a way to run Python in it as
    the unprivileged user: ``run(env, as_root=False) -> (dict, stderr)``."""
    reason = _can_run_as_user()
    if reason:
        pytest.skip(reason)
    made_user = subprocess.run(["id", USER], capture_output=True).returncode != 0
    if made_user:
        subprocess.run(["useradd", "-m", USER], check=True, capture_output=True)
    home = Path(os.path.expanduser(f"~{USER}"))
    top = Path(tempfile.mkdtemp(prefix="posekit-jit-", dir="/tmp"))
    top.chmod(0o755)
    site = top / "site"
    shutil.copytree(SRC, site / "posekit", ignore=shutil.ignore_patterns("__pycache__"))
    _read_only(site)
    prefix = Path(sys.base_prefix)
    py = top / "py"                     # the interpreter, reachable by the user in the namespace
    py.mkdir()
    exe = py / "bin" / Path(sys.executable).name

    def run(env, as_root=False):
        env = {"PATH": "/usr/bin:/bin", "LD_LIBRARY_PATH": str(py / "lib"), "PYTHONPATH": str(site),
               "HOME": str(home), "POSEKIT_COMPILE_NOTICE": "1", **env}
        user = [] if as_root else ["runuser", "-u", USER, "--"]
        cmd = ["unshare", "-m", "sh", "-c", 'mount --bind "$1" "$2" && shift 2 && exec "$@"', "sh", str(prefix), str(py),
               *user, "env", "-i", *(f"{k}={v}" for k, v in env.items()), str(exe), "-c", PROBE]
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        return json.loads(out.stdout.strip().splitlines()[-1]), out.stderr

    yield {"run": run, "site": site, "home": home, "top": top}
    shutil.rmtree(top, ignore_errors=True)
    shutil.rmtree(home / ".cache" / "posekit", ignore_errors=True)
    if made_user:
        subprocess.run(["userdel", "-r", USER], capture_output=True)


def _read_only(folder: Path) -> None:
    for path in [folder, *folder.rglob("*")]:
        mode = path.stat().st_mode
        path.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH) | stat.S_IRGRP | stat.S_IROTH
                   | (stat.S_IXGRP | stat.S_IXOTH if path.is_dir() else 0))


def _tree_files(site: Path) -> set:
    return {p for p in site.rglob("*") if p.is_file()}


def test_read_only_install_caches_in_the_users_folder(install):
    before = _tree_files(install["site"])
    first, err1 = install["run"]({})
    second, err2 = install["run"]({})
    user_dir = install["home"] / ".cache" / "posekit" / "numba"
    assert first["posekit"].startswith(str(install["site"]))          # the read-only copy ran
    assert (first["hits"], first["misses"]) == (0, 1)
    assert (second["hits"], second["misses"]) == (1, 0)               # loaded: no recompilation
    assert first["path"].startswith(str(user_dir)) and second["path"] == first["path"]
    assert _tree_files(install["site"]) == before                     # nothing written into the install
    assert err1 == err2 == ""


def test_posekit_cache_dir_chooses_the_folder(install):
    chosen = install["top"] / "chosen"
    chosen.mkdir()
    shutil.chown(chosen, USER)
    first, _ = install["run"]({"POSEKIT_CACHE_DIR": str(chosen)})
    second, _ = install["run"]({"POSEKIT_CACHE_DIR": str(chosen)})
    assert first["path"].startswith(str(chosen)) and (first["misses"], second["misses"], second["hits"]) == (1, 0, 1)


def test_no_writable_home_falls_back_to_a_private_temp_folder(install):
    first, _ = install["run"]({"HOME": "/nonexistent", "XDG_CACHE_HOME": "/nonexistent/.cache"})
    second, _ = install["run"]({"HOME": "/nonexistent", "XDG_CACHE_HOME": "/nonexistent/.cache"})
    top = Path(first["path"]).parents[1]
    try:
        assert top.name.startswith("posekit-") and top.parent == Path(tempfile.gettempdir())
        assert top.stat().st_mode & 0o077 == 0                           # closed to other users
        assert (first["misses"], second["misses"], second["hits"]) == (1, 0, 1)
    finally:
        shutil.rmtree(top, ignore_errors=True)


def test_a_cache_compiled_into_the_install_serves_every_user(install):
    """An administrator's ``posekit warmup`` into the read-only package's own __pycache__ (done
    here as root, who can write there): the user loads it and compiles nothing."""
    pycache = install["site"] / "posekit" / "geometry" / "__pycache__"
    try:
        admin, _ = install["run"]({"HOME": "/root"}, as_root=True)
        assert admin["path"] == str(pycache) and admin["misses"] == 1
        user_dir = install["home"] / ".cache" / "posekit"
        shutil.rmtree(user_dir, ignore_errors=True)
        user, err = install["run"]({})
        assert (user["hits"], user["misses"]) == (1, 0) and err == ""
    finally:
        shutil.rmtree(pycache, ignore_errors=True)


# --- in-process -------------------------------------------------------------------------------

def _fresh_kernel(body_value: float):
    """A new posekit kernel (a module name under posekit, so the note counts it)."""
    def probe(x):
        return x * body_value
    probe.__module__ = "posekit.testprobe"
    return numba.njit(probe)            # not cached: it must compile on every run of the test


def test_first_compile_prints_one_line_and_counts(monkeypatch, capsys):
    monkeypatch.setenv("POSEKIT_COMPILE_NOTICE", "1")
    monkeypatch.setattr(_jit, "_LISTENER", None)
    _jit.enable_compile_notice("profiler")
    listener = _jit._LISTENER
    try:
        k1, k2 = _fresh_kernel(2.0), _fresh_kernel(3.0)
        assert k1(2.0) == 4.0 and k2(2.0) == 6.0
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(
            f"posekit: compiling the profiler numba kernels on first use (about {_jit.FIRST_COMPILE_S['profiler']} s "
            "on an idle core, once per install or upgrade; cached in ")
        assert err.endswith("); `posekit warmup` does it ahead of time\n")
        assert len(err) <= 300
        assert _jit.compile_count() == 2
    finally:
        from numba.core import event
        event.unregister("numba:compile", listener)


def test_notice_can_be_silenced(monkeypatch, capsys):
    monkeypatch.setenv("POSEKIT_COMPILE_NOTICE", "0")
    monkeypatch.setattr(_jit, "_LISTENER", None)
    _jit.enable_compile_notice()
    listener = _jit._LISTENER
    try:
        assert _fresh_kernel(5.0)(1.0) == 5.0
        assert capsys.readouterr().err == "" and _jit.compile_count() == 1      # counted, not told
    finally:
        from numba.core import event
        event.unregister("numba:compile", listener)


def test_slice_assignment_of_the_wrong_size_still_raises():
    def assign(a, b):
        a[0:3] = b
        return a
    kernel = _jit.njit(assign)
    assert np.array_equal(kernel(np.zeros(4), np.ones(3)), [1, 1, 1, 0])
    with pytest.raises(ValueError, match="^cannot assign slice from input of different size$"):
        kernel(np.zeros(4), np.ones(2))


def test_every_kernel_module_uses_the_one_helper():
    """No kernel module calls numba's njit directly: the cache policy lives in one place."""
    offenders = [str(p.relative_to(SRC)) for p in SRC.rglob("*.py") if p.name != "_jit.py"
                 and ("from numba import njit" in (text := p.read_text(encoding="utf-8"))
                      or "nb.njit" in text or "numba.njit" in text)]
    assert offenders == []
