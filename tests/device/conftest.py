"""Fixtures of the device/host tests: a leak check on every test, and one URL factory per link backend.

`no_leaks` (autouse) fails a test that leaves an emulator thread ("eyehil-..."), link, pseudo-terminal,
socket or pipe open (python-can's test/conftest.py idea). `device_url` runs a test once per backend
(loop, pty, tcp, usbip), in the style of python-can's back2back_test.py.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from device_helpers import start_emulator
from host_deadlines import generous
from leaks import leak_check

BACKENDS = ["loop", "pty", "tcp", "usbip"]


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaves an emulator thread, link, pseudo-terminal, socket or pipe behind."""
    with leak_check("eyehil", kinds=("socket:", "pipe:", "/dev/ptmx", "/dev/pts/")):
        yield


@pytest.fixture(autouse=True)
def generous_host_deadlines(monkeypatch: pytest.MonkeyPatch) -> None:
    """The host waits generously for replies and samples (a busy machine; tests/host_deadlines.py)."""
    generous(monkeypatch)


@pytest.fixture(params=BACKENDS)
def device_url(request: pytest.FixtureRequest) -> Iterator[Callable[..., str]]:
    """A factory: device_url(**options) -> the URL of a fresh emulator on this test's backend.

    Options are `eyehil.emulator.device.build.options_from_query` keys (scene, rate, clock, latency, ...);
    the clock defaults to fast. Every emulator started is closed after the test.
    """
    closers: list[Callable[[], None]] = []

    def make(**options: object) -> str:
        url, close = start_emulator(request.param, **options)
        closers.append(close)
        return url

    make.backend = request.param  # type: ignore[attr-defined]
    yield make
    for close in closers:
        close()
