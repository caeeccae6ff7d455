"""Shared fixtures: the bundled gauges and a cached simulation of each."""

from pathlib import Path

import pytest

from posekit.profiler import bundled_gauge

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
