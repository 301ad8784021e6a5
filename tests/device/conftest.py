"""Fixtures of the device/host tests: a leak check on every test, and one URL factory per link backend.

`no_leaks` (autouse) fails a test that leaves an emulator thread ("eyehil-..."), link, pseudo-terminal,
socket or pipe open (python-can's test/conftest.py idea). `device_url` runs a test once per backend
(loop, pty, tcp; usbip to be added by its module), in the style of python-can's back2back_test.py.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator

import pytest
from device_helpers import start_emulator

from emulator.device.links import open_links

BACKENDS = ["loop", "pty", "tcp", "usbip"]


def _descriptors() -> set[str]:
    """Open sockets, pseudo-terminals and pipes of this process (Linux /proc)."""
    found = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith(("socket:", "pipe:", "/dev/ptmx", "/dev/pts/")):
            found.add(f"fd {fd} -> {target}")
    return found


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaves an emulator thread, link or descriptor behind."""
    linux = os.path.isdir("/proc/self/fd")
    before = _descriptors() if linux else set()
    yield
    threads = [t.name for t in threading.enumerate() if t.name.startswith("eyehil")]
    assert not threads, f"emulator threads left running: {threads}"
    assert not open_links(), f"links left open: {open_links()}"
    leaked = (_descriptors() - before) if linux else set()
    assert not leaked, f"descriptors left open: {sorted(leaked)}"


@pytest.fixture(params=BACKENDS)
def device_url(request: pytest.FixtureRequest) -> Iterator[Callable[..., str]]:
    """A factory: device_url(**options) -> the URL of a fresh emulator on this test's backend.

    Options are `emulator.device.build.options_from_query` keys (scene, rate, clock, latency, ...);
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
