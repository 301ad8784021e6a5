"""The USB/IP server and our host link end to end over loopback TCP."""

from __future__ import annotations

import random
import time

import pytest
import serial
from usbip_helpers import Collector

from eyehil.drivers.links.usbip import UsbipSerial
from eyehil.drivers.links.usbip_client import UsbipClient, UsbipLinkError, list_devices
from eyehil.emulator.device.links.usbip.server import UsbipCdcServer
from eyehil.protocols.usbip.descriptors import LineCoding

MEGABYTE = random.Random(1).randbytes(1 << 20)


def test_devlist_lists_the_cdc_acm_device(server: UsbipCdcServer) -> None:
    (device,) = list_devices("127.0.0.1", server.port)
    assert (device.busid, device.id_vendor, device.id_product, device.speed) == ("1-1", 0x1209, 0x0001, 3)
    assert [(i.interface_class, i.interface_subclass) for i in device.interfaces] == [(2, 2), (10, 0)]


def test_open_configures_the_device(server: UsbipCdcServer, host: UsbipSerial) -> None:
    assert server.attached and server.control.configuration == 1
    assert server.dtr and server.control.rts and server.line_coding == LineCoding(115200)
    host.baudrate = 921600
    host.dtr = False
    assert server.line_coding.baudrate == 921600 and not server.dtr


def test_host_to_device(collector: Collector, host: UsbipSerial) -> None:
    assert host.write(b"\x00EH hello\x00") == 10
    assert collector.data == b"\x00EH hello\x00"  # write returns once the device has the data


def test_device_to_host(server: UsbipCdcServer, host: UsbipSerial) -> None:
    assert server.send(b"abcdef") == 6
    assert host.read(2) == b"ab"
    assert host.in_waiting == 4  # one send, one URB completion: the rest is buffered already
    assert host.read(4) == b"cdef"


def test_one_megabyte_each_way(server: UsbipCdcServer, collector: Collector, host: UsbipSerial) -> None:
    assert host.write(MEGABYTE) == len(MEGABYTE)
    assert collector.wait_for(len(MEGABYTE)) == MEGABYTE
    assert server.send(MEGABYTE) == len(MEGABYTE)
    assert host.read(len(MEGABYTE)) == MEGABYTE


def test_read_timeout_returns_what_is_there(server: UsbipCdcServer, host: UsbipSerial) -> None:
    host.timeout = 0.2
    server.send(b"xyz")
    start = time.monotonic()
    assert host.read(10) == b"xyz"
    assert 0.2 <= time.monotonic() - start < 2.0
    host.timeout = 0
    start = time.monotonic()
    assert host.read(10) == b""
    assert time.monotonic() - start < 0.1


def test_in_urbs_honour_transfer_buffer_length_and_throttle(server: UsbipCdcServer) -> None:
    port = UsbipSerial("127.0.0.1", server.port, timeout=5.0, read_chunk=7, urbs_in_flight=1, rx_limit=7)
    try:
        server.send(bytes(range(100)))
        assert port.read(7) == bytes(range(7))
        assert port.in_waiting <= 7  # 7 unread bytes stop the host asking: at most one 7-byte URB since
        assert server.tx_pending >= 100 - 14  # the rest waits in the device
        assert port.read(93) == bytes(range(7, 100))
    finally:
        port.close()


def test_read_larger_than_the_receive_limit(server: UsbipCdcServer) -> None:
    port = UsbipSerial("127.0.0.1", server.port, timeout=10.0, read_chunk=512, rx_limit=1024)
    try:
        server.send(MEGABYTE[:65536])
        start = time.monotonic()
        assert port.read(65536) == MEGABYTE[:65536]  # not throttled at rx_limit until the timeout
        assert time.monotonic() - start < 5.0
    finally:
        port.close()


def test_on_attach_runs_once_per_host(collector: Collector) -> None:
    attaches: list[bool] = []
    with UsbipCdcServer(collector, on_attach=lambda: attaches.append(collector.data == b"")) as server:
        for _ in range(2):
            port = UsbipSerial("127.0.0.1", server.port, timeout=5.0)
            port.write(b"x")
            port.close()
            assert server.wait_attached(5.0, attached=False)
    assert attaches == [True, False]  # once per import, before that host's data


def test_detach_and_reattach(server: UsbipCdcServer, collector: Collector) -> None:
    url = f"usbip://127.0.0.1:{server.port}"
    first = UsbipSerial.from_url(url, timeout=5.0)
    server.send(MEGABYTE)
    assert len(first.read(1000)) == 1000
    first.close()  # mid-stream: most of the megabyte is still queued in the device
    assert server.wait_attached(5.0, attached=False)
    assert server.send(b"lost") == 0 and server.bytes_dropped >= 4
    second = UsbipSerial.from_url(url, timeout=0.2)
    try:
        assert server.attached
        assert second.read(10) == b""  # nothing stale from the previous host
        second.write(b"again")
        assert collector.data.endswith(b"again")
        server.send(b"back")
        assert second.read(4) == b"back"
    finally:
        second.close()


def test_second_import_is_refused(server: UsbipCdcServer, host: UsbipSerial) -> None:
    with pytest.raises(UsbipLinkError, match="DEV_BUSY"):
        UsbipClient.open("127.0.0.1", server.port, "1-1")
    with pytest.raises(UsbipLinkError, match="NODEV"):
        UsbipClient.open("127.0.0.1", server.port, "9-9")
    server.send(b"still fine")
    assert host.read(10) == b"still fine"


def test_send_buffer_is_bounded(collector: Collector) -> None:
    with UsbipCdcServer(collector, max_buffer=10) as server:
        port = UsbipSerial("127.0.0.1", server.port, timeout=5.0)
        try:
            assert server.send(bytes(25)) == 10
            assert server.bytes_dropped == 15
            assert port.read(10) == bytes(10)
        finally:
            port.close()


def test_server_close_breaks_the_host_link(collector: Collector) -> None:
    server = UsbipCdcServer(collector).start()
    port = UsbipSerial("127.0.0.1", server.port, timeout=None)
    try:
        server.close()
        with pytest.raises(serial.SerialException):
            port.read(1)
        with pytest.raises(serial.SerialException):
            port.write(b"x")
    finally:
        port.close()
    with pytest.raises(serial.PortNotOpenError):
        port.read(1)


def test_from_url_rejects_other_schemes() -> None:
    with pytest.raises(ValueError):
        UsbipSerial.from_url("socket://127.0.0.1:3240")
