"""Issue 11, findings 7 and 8 on USB/IP: an import lease, total (not per-recv) deadlines, bounded connections and
pending URBs per session, and a host client that retries while the device is briefly busy.

Limits are shrunk with monkeypatch so that the conditions happen at once; every wait has a generous deadline and
only bounds a hang (the result is decided by the condition, not by the clock)."""

from __future__ import annotations

import socket
import threading

from usbip_helpers import RawHost, wait_closed

import eyehil.drivers.links.usbip_client as usbip_client
import eyehil.emulator.device.links.usbip.server as usbip_server
import eyehil.emulator.device.links.usbip.session as usbip_session
from eyehil.drivers.links.usbip_client import UsbipClient
from eyehil.protocols.usbip.messages import OpHeader
from eyehil.protocols.usbip.urb import CmdSubmit, Direction

GENEROUS_S = 30.0


def test_one_byte_at_a_time_does_not_hold_a_connection(server, monkeypatch) -> None:
    monkeypatch.setattr(usbip_server, "OP_TIMEOUT", 0.5)
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=5.0)
    try:
        header = OpHeader(0x8003).encode()
        closed = False
        for byte in header[:-1] * 50:  # never completes the 8-byte header
            try:
                sock.sendall(bytes([byte]))
            except OSError:
                closed = True
                break
            if wait_closed(sock, 0.1):
                closed = True
                break
        assert closed
    finally:
        sock.close()


def test_an_import_that_sends_nothing_loses_the_device(server, monkeypatch) -> None:
    monkeypatch.setattr(usbip_session, "IMPORT_LEASE_S", 0.3)
    raw = RawHost(server.port)
    try:
        assert raw.import_device().status == 0  # attached (waiting to see it attached could miss the 0.3 s lease)
        assert server.wait_attached(GENEROUS_S, attached=False)  # the lease ran out
        assert wait_closed(raw.sock, GENEROUS_S)
    finally:
        raw.close()


def test_connections_at_once_are_bounded(server) -> None:
    socks = [socket.create_connection(("127.0.0.1", server.port), timeout=5.0)
             for _ in range(usbip_server.MAX_CONNECTIONS + 5)]
    try:
        assert server.wait_counted(lambda: server.connections_refused >= 5, GENEROUS_S)
    finally:
        for s in socks:
            s.close()


def test_pending_in_urbs_per_session_are_bounded(server) -> None:
    raw = RawHost(server.port)
    try:
        assert raw.import_device().status == 0
        for seq in range(usbip_session.MAX_PENDING_URBS + 10):
            urb = CmdSubmit(seqnum=seq + 1, devid=server.device.devid, direction=Direction.IN, ep=1,
                            transfer_buffer_length=512)
            try:
                raw.sock.sendall(urb.encode())
            except OSError:
                break
        assert server.wait_attached(GENEROUS_S, attached=False)
    finally:
        raw.close()


def test_client_retries_while_the_device_is_busy(server, monkeypatch) -> None:
    monkeypatch.setattr(usbip_client, "BUSY_WAIT_S", 0.2)
    first = UsbipClient.open("127.0.0.1", server.port, "1-1")
    result: list = []
    second = threading.Thread(target=lambda: result.append(UsbipClient.open("127.0.0.1", server.port, "1-1",
                                                                             timeout=GENEROUS_S)), daemon=True)
    try:
        second.start()
        assert server.wait_counted(lambda: server.imports_busy >= 1, GENEROUS_S)
        first.close()
        second.join(GENEROUS_S)
        assert result, "the second host did not get the device"
    finally:
        first.close()
        for client in result:
            client.close()
