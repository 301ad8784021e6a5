"""Fixtures of the Open Gaze tests: a leak check on every test and a factory of started servers."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from leaks import leak_check
from opengaze_helpers import start_server

from eyehil.emulator.device.opengaze.server import OpenGazeServer


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaves an emulator thread, server or listening socket behind."""
    with leak_check("eyehil", listening=True):
        yield


@pytest.fixture
def server() -> Iterator[Callable[..., OpenGazeServer]]:
    """A factory: server(scene=..., **OpenGazeOptions fields) -> a started server on a free port; each one is
    closed after the test."""
    started: list[OpenGazeServer] = []

    def make(**options: object) -> OpenGazeServer:
        started.append(start_server(**options))
        return started[-1]

    yield make
    for s in started:
        s.close()
