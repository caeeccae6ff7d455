"""Shared fixtures: the bundled gauges and a cached simulation of each; the ``--slow`` option."""

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


def pytest_addoption(parser):
    parser.addoption("--slow", action="store_true", default=False,
                     help="also run the tests marked slow (the whole fuzz corpus)")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--slow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
