"""eyehil's links through plain `serial.serial_for_url`, as users' firmware tests open ports.

`import eyehil` registers the ``eyehil+<scheme>://`` handlers with pyserial (the eyehil pytest plugin imports
eyehil, so in a pytest session they are there without any import). Each scheme gets a START and must deliver
a FEATURES sample, decoded here with the pure codec only.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
import serial
from device_helpers import start_emulator

import eyehil  # noqa: F401  (registers the URL handlers)
from eyehil.protocols.header import MessageType
from eyehil.protocols.messages import Start
from eyehil.protocols.native import encode
from eyehil.protocols.samples import Features
from eyehil.protocols.stream import NativeReceiver, Received


def _first_features(port: serial.SerialBase, deadline_s: float = 60.0) -> Features:
    port.write(encode(Start(), seq=1, timestamp_us=0))
    receiver = NativeReceiver()
    end = time.monotonic() + deadline_s  # a generous bound on a condition, not a timing assertion
    while time.monotonic() < end:
        for item in receiver.feed(port.read(4096)):
            if isinstance(item, Received) and item.header.msg_type == MessageType.FEATURES:
                return item.message
    raise AssertionError("no FEATURES sample arrived")


@pytest.fixture(params=["loop", "usbip", "spy"])
def eyehil_serial_url(request: pytest.FixtureRequest) -> Iterator[str]:
    if request.param == "loop":
        yield "eyehil+loop://?scene=guestrin2006&clock=fast"
        return
    url, close = start_emulator("usbip" if request.param == "usbip" else "tcp")
    try:
        yield f"eyehil+{url}" if request.param == "usbip" else f"eyehil+spy://{url}"
    finally:
        close()


def test_serial_for_url_opens_each_eyehil_scheme_and_reads_a_sample(eyehil_serial_url: str,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    port = serial.serial_for_url(eyehil_serial_url, timeout=0.5)
    try:
        assert port.is_open
        sample = _first_features(port)
    finally:
        port.close()
    assert sample.eyes and sample.eyes[0].axis_a > 0 and sample.eyes[0].glints
    assert not port.is_open


def test_a_closed_port_behind_an_eyehil_url_is_a_serial_exception() -> None:
    with pytest.raises(serial.SerialException, match="cannot open"):
        serial.serial_for_url("eyehil+usbip://127.0.0.1:1/1-1", timeout=0.5)
