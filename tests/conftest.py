"""Shared fixtures: the bundled gauges and a cached simulation of each; the ``--full-corpus`` option."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from posekit.profiler import bundled_gauge

# A kernel compiled during a test (cold cache, as in CI) must not add a line to stderr that the
# tests compare: the CLI's first-compile note is off here (test_jit.py turns it on).
os.environ.setdefault("POSEKIT_COMPILE_NOTICE", "0")

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="session", params=["demo-4", "demo-5", "demo-7", "demo-10"])
def any_gauge(request):
    return bundled_gauge(request.param)


@pytest.fixture(scope="session")
def gauge5():
    return bundled_gauge("demo-5")


@pytest.fixture(scope="session")
def gauge4():
    return bundled_gauge("demo-4")


def pytest_addoption(parser):
    parser.addoption("--full-corpus", action="store_true", default=False,
                     help="also run the tests marked full_corpus (the whole fuzz corpus)")


def pytest_collection_modifyitems(config, items):
    # The long tests first (a stable sort keeps the order otherwise): with pytest-xdist the suite then
    # ends on many short tests spread over the workers, not on one long test started last.
    items.sort(key=lambda item: "slow" not in item.keywords)
    if config.getoption("--full-corpus"):
        return
    skip = pytest.mark.skip(reason="the whole fuzz corpus: run with --full-corpus")
    for item in items:
        if "full_corpus" in item.keywords:
            item.add_marker(skip)


@pytest.hookimpl(trylast=True)
def pytest_configure(config):
    """With a cold kernel cache (a fresh clone, as in CI) and pytest-xdist, compile the kernels once with
    ``posekit warmup`` before the workers start: each worker would otherwise compile the same kernels at the
    same time (on 2 cores about 70 s of CPU twice). A warm or partly warm cache is left to the workers."""
    if hasattr(config, "workerinput") or not config.getoption("numprocesses", default=None):
        return
    import posekit
    from posekit import _jit
    where = _jit.cache_dir()
    # kernels load from the package's own __pycache__ too when the cache is elsewhere (posekit._jit)
    roots = [Path(posekit.__file__).parent] + ([] if where.endswith("**/__pycache__") else [Path(where)])
    if any(next(r.rglob("*.nbi"), None) is not None for r in roots if r.is_dir()):
        return
    try:
        proc = subprocess.run([sys.executable, "-m", "posekit.cli.main", "warmup"], capture_output=True, text=True,
                              timeout=600)
        line = ((proc.stdout.splitlines() or ["posekit warmup: no output"])[0] +
                ("" if proc.returncode == 0 else f" (exit {proc.returncode}: the workers compile the rest)"))
    except (OSError, subprocess.TimeoutExpired) as exc:   # the workers compile what is missing, as before
        line = f"posekit warmup: not run ({type(exc).__name__}): the workers compile the kernels"
    tr = config.pluginmanager.get_plugin("terminalreporter")
    if tr is not None:
        tr.write_line(line)
