"""Abuse: requests that are not UTF-8, unknown, bad msgpack, non-string keys, deeply nested, huge or oversized;
garbage on the TCP ports; malformed messages published straight onto the backbone. Each is answered or
dropped, the server keeps serving other clients, and no thread dies."""

from __future__ import annotations

import socket

import msgpack
import pytest
import zmq
from pupil_labs.pupil_core_network_client import Device
from zmq_helpers import eventually, start_server

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.links.listen import ListenError
from eyehil.emulator.device.pupil.server import PupilServer, ServerOptions
from eyehil.protocols.pupil import MAX_PAYLOAD_BYTES


def _nested(depth: int) -> bytes:
    return b"\x91" * depth + b"\xc0"  # [[[...[nil]...]]]


def _deep(depth: int) -> list:
    value: list = []
    for _ in range(depth):
        value = [value]
    return value


@pytest.fixture
def req(server, client_context):
    """(server, a raw REQ socket on it with a 2 s receive timeout)."""
    srv = server()
    sock = client_context.socket(zmq.REQ)
    sock.rcvtimeo = 2000
    sock.connect(f"tcp://127.0.0.1:{srv.port}")
    yield srv, sock
    sock.close(linger=0)


def _still_serving(srv) -> None:
    """A fresh client gets correct answers, and no facade thread died."""
    device = Device("127.0.0.1", srv.port)
    assert device.request_version() == "3.6.0"
    device.disconnect()
    assert srv.remote.failure is None and srv.device.failure is None


@pytest.mark.parametrize(("frames", "reply"), [
    ([b"\xff\xfe\x00"], "Unknown command."),
    ([b""], "Unknown command."),
    ([b"hello"], "Unknown command."),
    ([b"T nan"], "'nan' cannot be converted to float."),
    ([b"T inf"], "'inf' cannot be converted to float."),
    ([b"notify.x", b"\xc1"], "Malformed message: "),
    ([b"notify.x", msgpack.packb({"subject": "x", 1: 2})], "Malformed message: "),
    ([b"notify.x", msgpack.packb([1, 2])], "Malformed message: "),
    ([b"notify.x", _nested(100_000)], "Malformed message: "),
    ([b"notify.x", msgpack.packb({"subject": "x", "a": _deep(40)})], "Malformed message: "),
    ([b"\xff", msgpack.packb({"subject": "x"})], "Malformed message: "),
    ([b"notify.x", msgpack.packb({"subject": "x", "blob": b"\0" * (MAX_PAYLOAD_BYTES + 1)})], "Malformed message: "),
])
def test_malformed_requests_are_answered(req, frames, reply: str) -> None:
    srv, sock = req
    sock.send_multipart(frames)
    assert sock.recv_string().startswith(reply)
    _still_serving(srv)


def test_an_oversized_message_drops_only_its_sender(req) -> None:
    srv, sock = req
    sock.send_multipart([b"notify.x", b"\0" * (33 * 1024 * 1024)])  # beyond the socket's MAXMSGSIZE
    with pytest.raises(zmq.Again):
        sock.recv()  # libzmq dropped this connection: no reply ever comes
    _still_serving(srv)


def test_garbage_on_the_tcp_ports(server) -> None:
    srv = server()
    for port in (srv.port, srv.pub_port, srv.sub_port):
        with socket.create_connection(("127.0.0.1", port), timeout=5) as raw:
            raw.sendall(bytes(range(256)) * 64)
    _still_serving(srv)


def test_malformed_messages_on_the_backbone(server, client_context) -> None:
    srv = server()
    pub = client_context.socket(zmq.PUB)
    pub.connect(f"tcp://127.0.0.1:{srv.pub_port}")
    bad = [[b"notify.x", b"\xc1"], [b"notify.x"], [b"annotation", msgpack.packb({1: 1})],
           [b"notify.x", _nested(50)], [b"\xff", msgpack.packb({"subject": "x"})]]
    def heard() -> bool:  # the PUB connects asynchronously: send until the device has counted them
        for message in bad:
            pub.send_multipart(message)
        return srv.counters["messages_malformed"] >= len(bad)

    try:
        eventually(srv, heard)
    finally:
        pub.close(linger=0)
    _still_serving(srv)


def test_two_clients_interleaved(server) -> None:
    srv = server()
    a, b = Device("127.0.0.1", srv.port), Device("127.0.0.1", srv.port)
    try:
        for i in range(20):
            assert a.request_version() == "3.6.0"
            assert b.send_notification({"subject": "test.x", "i": i}) == "Message forwarded."
    finally:
        a.disconnect()
        b.disconnect()


def test_a_failed_start_leaves_nothing_behind(server) -> None:
    srv = server()
    with pytest.raises(ListenError, match=f"cannot listen on zmq 127.0.0.1:{srv.port}: address already in use"):
        start_server(port=srv.port)  # the port is taken
    with pytest.raises(TypeError, match="AppearanceSolver"):
        PupilServer(build_subject(DeviceOptions(), appearance=False), options=ServerOptions(port=0)).start()
    _still_serving(srv)
