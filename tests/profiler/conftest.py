"""Fixtures shared by the profiler tests."""

import pytest

from posekit.profiler.stream.stream_client import RobotInterfaceStub


@pytest.fixture
def stub():
    """A robot interface listening on loopback, stopped after the test."""
    s = RobotInterfaceStub()
    s.start()
    yield s
    s.stop()
