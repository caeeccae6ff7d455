"""Shared fixtures: the bundled gauges and a cached simulation of each."""

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
