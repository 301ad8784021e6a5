"""Waiting for a condition about something outside the test's control (another process, a third-party client's
reader thread): poll it until it holds, up to a generous bound that only catches a hang and never decides a
result. Where the test controls the clock or can wait on an event, it does that instead."""

from __future__ import annotations

import time
from collections.abc import Callable

POLL_S = 0.01


def wait_until(condition: Callable[[], object], what: str, timeout_s: float) -> None:
    """Return once `condition()` is true; AssertionError naming `what` if it is still false after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what} ({timeout_s:g} s)")
        time.sleep(POLL_S)
