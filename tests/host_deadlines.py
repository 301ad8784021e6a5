"""Generous host deadlines for tests that talk to a real device thread or process (issue 17).

`eyehil.drivers.client.Tracker` waits `response_timeout` (0.25 s) for each reply and `timeout` (2 s) for a
sample, on the wall clock: right for a user at a quiet machine, but on a loaded CI machine a device thread or
firmware process descheduled for longer makes a test retry, or fail with "no sample within 2.0 s", for no
fault of the code under test. `generous(monkeypatch)` raises both defaults for one test; they only bound a
hang (a missing reply or sample still fails the test), and tests that mean to exercise a timeout pass their
own values, which are kept.
"""

from __future__ import annotations

import pytest

from eyehil.drivers.client import Tracker

RESPONSE_TIMEOUT_S = 5.0  # a reply the device owes (the host re-sends after this)
SAMPLE_TIMEOUT_S = 60.0  # a sample of a started stream (fixation solves on a loaded machine take seconds)


def generous(monkeypatch: pytest.MonkeyPatch) -> None:
    """Raise `Tracker`'s default reply and sample deadlines for the current test."""
    defaults = Tracker.__init__.__kwdefaults__
    monkeypatch.setitem(defaults, "response_timeout", RESPONSE_TIMEOUT_S)
    monkeypatch.setitem(defaults, "timeout", SAMPLE_TIMEOUT_S)
