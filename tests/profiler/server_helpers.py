"""Helpers shared by the pose-server tests (the robot-interface stub fixture is in conftest.py)."""

import time

WAIT_S = 10.0                  # upper bound of every wait for the server to catch up


def wait_until(predicate, timeout_s=WAIT_S):
    """Poll ``predicate`` every 10 ms until it holds or ``timeout_s`` passes; its last value."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()
