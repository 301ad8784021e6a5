"""Hostile input to the Open Gaze server: every bad line gets a NACK (or the client is dropped), and the
server keeps serving the other clients."""

from __future__ import annotations

import socket
import time

from opengaze_helpers import DEADLINE_S, LineClient

from eyehil.emulator.device.opengaze.server import MAX_CLIENTS, MAX_OUT_BYTES
from eyehil.protocols.opengaze import MAX_LINE_BYTES

BAD_LINES = [
    (b'<GET ID="SCREEN_SIZE">\r\n', "", "MALFORMED"),
    (b'<GET ID="SCREEN_SIZE" \r\n', "", "MALFORMED"),
    (b'<GET ID="NO_SUCH_THING" />\r\n', "NO_SUCH_THING", "UNKNOWN_ID"),
    (b'<SET ID="NO_SUCH_THING" STATE="1" />\r\n', "NO_SUCH_THING", "UNKNOWN_ID"),
    (b'<REC ID="X" />\r\n', "X", "BAD_TAG"),
    (b'<GET ID="\xff\xfe" />\r\n', "", "NOT_UTF8"),
    (b"\x00\x01\x02garbage\r\n", "", "MALFORMED"),
    (b'<SET ID="ENABLE_SEND_DATA" STATE="yes" />\r\n', "ENABLE_SEND_DATA", "BAD_VALUE"),
    (b'<SET ID="CALIBRATE_TIMEOUT" VALUE="1e308" />\r\n', "CALIBRATE_TIMEOUT", "BAD_VALUE"),
    (b'<SET ID="CALIBRATE_ADDPOINT" X="nan" Y="0.5" />\r\n', "CALIBRATE_ADDPOINT", "BAD_VALUE"),
    (b'<SET ID="SCREEN_SIZE" X="0" Y="0" WIDTH="-5" HEIGHT="1080" />\r\n', "SCREEN_SIZE", "BAD_VALUE"),
    (b'<SET ID="CAMERA_SIZE" WIDTH="1" HEIGHT="1" />\r\n', "CAMERA_SIZE", "READ_ONLY"),
    (b'<SET ID="USER_DATA" VALUE="' + b"u" * 300 + b'" />\r\n', "USER_DATA", "TOO_LONG"),
    (b'<GET ID="' + b"x" * (MAX_LINE_BYTES + 10) + b'" />\r\n', "", "TOO_LONG"),
]


def test_every_bad_line_gets_a_nack_and_the_other_client_is_served(server) -> None:
    srv = server()
    good, bad = LineClient(srv.port), LineClient(srv.port)
    try:
        good.send(b'<SET ID="ENABLE_SEND_COUNTER" STATE="1" />\r\n<SET ID="ENABLE_SEND_DATA" STATE="1" />\r\n')
        good.wait_for("ACK", "ENABLE_SEND_DATA")
        for line, rid, code in BAD_LINES:
            bad.send(line)
            r = bad.wait_for("NACK")
            assert (r.id, r.attrs["ERROR"]) == (rid, code), line[:60]
        bad.send(b'<GET ID="SCREEN_SIZE" />\r\n')  # the bad client itself is still answered
        assert bad.wait_for("ACK", "SCREEN_SIZE").attrs["WIDTH"] == "1920"
        counts = [int(good.wait_for("REC").attrs["CNT"]) for _ in range(30)]
        assert counts == sorted(counts)
        assert srv.failure is None and srv.all_counters["records_refused"] == len(BAD_LINES)
    finally:
        good.close()
        bad.close()


def test_a_client_that_floods_without_reading_is_dropped_and_the_server_goes_on(server) -> None:
    srv = server()
    flood = socket.create_connection(("127.0.0.1", srv.port), timeout=DEADLINE_S)
    flood.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    good = LineClient(srv.port)
    try:
        request = b'<GET ID="CALIBRATE_ADDPOINT" />\r\n' * 1000  # each answer ~200 bytes, never read
        end = time.monotonic() + DEADLINE_S
        while srv.all_counters["clients_dropped"] == 0:
            assert time.monotonic() < end, "the flooding client was never dropped"
            try:
                flood.sendall(request)
            except OSError:
                break
        good.send(b'<GET ID="SCREEN_SIZE" />\r\n')
        assert good.wait_for("ACK", "SCREEN_SIZE").attrs["HEIGHT"] == "1080"
        assert srv.failure is None
    finally:
        flood.close()
        good.close()
    assert MAX_OUT_BYTES <= 1 << 20  # the documented bound


def test_clients_beyond_the_limit_are_refused(server) -> None:
    srv = server()
    clients = [LineClient(srv.port) for _ in range(MAX_CLIENTS)]
    try:
        extra = socket.create_connection(("127.0.0.1", srv.port), timeout=DEADLINE_S)
        assert extra.recv(100) == b""  # closed at once
        extra.close()
        clients[0].send(b'<GET ID="SCREEN_SIZE" />\r\n')
        assert clients[0].wait_for("ACK", "SCREEN_SIZE")
        assert srv.all_counters["clients_refused"] == 1
    finally:
        for c in clients:
            c.close()
