"""Malformed requests and vanishing hosts: the connection is answered or dropped, the server goes on."""

from __future__ import annotations

import struct

import pytest
from usbip_helpers import Collector, RawHost, wait_closed

from eyehil.drivers.links.usbip import UsbipSerial
from eyehil.drivers.links.usbip_client import list_devices
from eyehil.emulator.device.links.usbip.server import UsbipCdcServer
from eyehil.emulator.device.links.usbip.session import MAX_TRANSFER
from eyehil.protocols.usbip.messages import OpCode, OpHeader
from eyehil.protocols.usbip.urb import CmdSubmit, Direction, RetSubmit

DEVID = 0x00010002


def assert_server_serves(server: UsbipCdcServer) -> None:
    """The device is listed and can be imported and used."""
    assert [d.busid for d in list_devices("127.0.0.1", server.port)] == ["1-1"]
    port = UsbipSerial("127.0.0.1", server.port, timeout=5.0)
    try:
        server.send(b"alive")
        assert port.read(5) == b"alive"
    finally:
        port.close()
    assert server.wait_attached(5.0, attached=False)


@pytest.mark.parametrize("request_bytes", [
    OpHeader(OpCode.REQ_DEVLIST, version=0x0106).encode(),  # another protocol version
    OpHeader(0x8004).encode(),  # unknown op code
    b"GET / HTTP/1.1\r\n\r\n",  # not USB/IP at all
    b"\x01\x11",  # truncated header, then the client goes away
])
def test_bad_op_requests_drop_the_connection(server: UsbipCdcServer, raw: RawHost, request_bytes: bytes) -> None:
    raw.sock.sendall(request_bytes)
    if len(request_bytes) < 8:
        raw.sock.shutdown(1)
    assert wait_closed(raw.sock)
    assert_server_serves(server)


@pytest.mark.parametrize("urb_bytes", [
    struct.pack(">5I", 7, 1, DEVID, 0, 0) + bytes(28),  # unknown command
    CmdSubmit(1, 0x00020003, Direction.OUT, 2, 1, data=b"x").encode(),  # another device's devid
    struct.pack(">6Ii", 1, 1, DEVID, 0, 2, 0, MAX_TRANSFER + 1) + bytes(20),  # OUT transfer too large
    struct.pack(">6Ii", 1, 1, DEVID, 1, 2, 0, -5) + bytes(20),  # negative length
    RetSubmit(1, 0, 0).encode(),  # a host does not send replies
])
def test_bad_urbs_drop_the_host_and_free_the_device(server: UsbipCdcServer, raw: RawHost, urb_bytes: bytes) -> None:
    raw.import_device()
    raw.sock.sendall(urb_bytes)
    assert wait_closed(raw.sock)
    assert server.wait_attached(5.0, attached=False)
    assert_server_serves(server)


def test_host_vanishing_mid_out_transfer(server: UsbipCdcServer, collector: Collector, raw: RawHost) -> None:
    raw.import_device()
    raw.sock.sendall(CmdSubmit(1, DEVID, Direction.OUT, 2, 1000, data=bytes(1000)).encode()[:48 + 10])
    raw.sock.close()  # 10 of the 1000 announced bytes sent
    assert server.wait_attached(5.0, attached=False)
    assert collector.data == b""  # a partial transfer is never delivered
    assert_server_serves(server)


def test_host_vanishing_with_data_in_flight(server: UsbipCdcServer, raw: RawHost) -> None:
    raw.import_device()
    for seqnum in range(1, 9):
        raw.sock.sendall(CmdSubmit(seqnum, DEVID, Direction.IN, 2, 65536).encode())
    server.send(bytes(4 << 20))  # 512 KiB answered, the rest queued; the host reads none of it
    raw.sock.close()
    assert server.wait_attached(5.0, attached=False)
    assert_server_serves(server)


def test_idle_connection_does_not_block_others(server: UsbipCdcServer, raw: RawHost) -> None:
    assert_server_serves(server)  # while `raw` is connected and silent


def test_consumer_exceptions_do_not_break_the_link(caplog: pytest.LogCaptureFixture) -> None:
    def broken(*args: object) -> None:
        raise RuntimeError("consumer bug")

    with UsbipCdcServer(broken, on_attach=broken) as server:
        port = UsbipSerial("127.0.0.1", server.port, timeout=5.0)
        try:
            assert port.write(b"one") == 3 and port.write(b"two") == 3
            server.send(b"ok")
            assert port.read(2) == b"ok"
        finally:
            port.close()
    assert "broken callback failed" in caplog.text


def test_close_is_idempotent_and_start_once(collector: Collector) -> None:
    UsbipCdcServer(collector).close()  # never started
    server = UsbipCdcServer(collector, port=0).start()
    assert server.port > 0
    with pytest.raises(RuntimeError):
        server.start()
    server.close()
    server.close()
    assert server.send(b"x") == 0
    with pytest.raises(RuntimeError):
        server.start()
