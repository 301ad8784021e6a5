"""Fixtures of the USB/IP tests: a server with a byte collector, a host port, a raw USB/IP host; a leak check.

Helpers live in `usbip_helpers` (importable from the tests, as `spherical_eye` is one level up).

Every test fails if it leaves an `eyehil-usbip-*` thread alive or a socket open (counted in /proc/self/fd).
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from leaks import leak_check
from usbip_helpers import Collector, RawHost

from eyehil.drivers.links.usbip import UsbipSerial
from eyehil.emulator.device.links.usbip.server import UsbipCdcServer


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaves a USB/IP thread running or a socket open."""
    with leak_check("eyehil-usbip", kinds=("socket:",)):
        yield


@pytest.fixture
def collector() -> Collector:
    return Collector()


@pytest.fixture
def server(collector: Collector) -> Iterator[UsbipCdcServer]:
    with UsbipCdcServer(collector) as srv:
        yield srv


@pytest.fixture
def host(server: UsbipCdcServer) -> Iterator[UsbipSerial]:
    port = UsbipSerial.from_url(f"usbip://127.0.0.1:{server.port}/1-1", timeout=5.0)
    yield port
    port.close()


@pytest.fixture
def raw(server: UsbipCdcServer) -> Iterator[RawHost]:
    connection = RawHost(server.port)
    yield connection
    connection.close()
