"""Shared fixtures: the bundled gauges and a cached simulation of each; the ``--full-corpus`` option."""

import os
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
