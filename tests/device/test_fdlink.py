"""The descriptor links' writer (emulator/device/links/fdlink.py): output queued and written by a thread of its own
in blocking calls; counted in the backlog while it is written; a host that does not read never stops a close or a
reconnection, and nothing is lost or reordered for a host that does."""

from __future__ import annotations

import socket
import threading

import serial
from waiting import wait_until

from eyehil.emulator.device.links.base import take
from eyehil.emulator.device.links.fdlink import MAX_LINK_BACKLOG
from eyehil.emulator.device.links.pty import PtyLink
from eyehil.emulator.device.links.tcp import TcpLink

BLOCK = 64 * 1024
BLOCKS = 40  # 2.6 MB: far beyond what a pseudo-terminal (about 12 kB) or loopback TCP buffers hold


def _payload(k: int) -> bytes:
    return bytes([k % 251]) * BLOCK


def _attach(link) -> threading.Event:
    """Attach with a receiver that ignores input; return an event set when a new host connects."""
    connected = threading.Event()
    link.attach(lambda data: None, connected.set)
    return connected


def _stuck(link) -> None:
    """Send more than the host's buffers hold to a host that does not read: the writer blocks in the kernel."""
    for k in range(MAX_LINK_BACKLOG // BLOCK):  # until the kernel's buffers are full and output queues
        link.send(_payload(k))
        if link.backlog() > BLOCK:
            break
    wait_until(lambda: link._writing > 0, "the writer to take the queue", 30.0)
    assert link.backlog() == len(link._out) + link._writing > 0


def test_pty_output_arrives_whole_and_in_order() -> None:
    link = PtyLink()
    _attach(link)
    port = serial.Serial(link.url, timeout=0)
    try:
        for k in range(BLOCKS):
            link.send(_payload(k))
        got = bytearray()
        while len(got) < BLOCKS * BLOCK:
            got += port.read(BLOCK)
        assert bytes(got) == b"".join(_payload(k) for k in range(BLOCKS))
        wait_until(lambda: link.backlog() == 0, "the backlog to drain", 30.0)
        assert link.bytes_dropped == 0
    finally:
        port.close()
        link.close()


def test_pty_close_returns_while_the_writer_waits_for_a_host_that_does_not_read() -> None:
    link = PtyLink()
    _attach(link)
    port = serial.Serial(link.url, timeout=0)  # a host that opened the port and reads nothing
    try:
        _stuck(link)
    finally:
        link.close()  # unblocks the writer (the device reads its own end) and joins both threads
        port.close()
    assert not [t for t in threading.enumerate() if t.name.startswith(f"eyehil-{link.name}")]


def test_pty_queue_beyond_its_limit_is_dropped_and_counted() -> None:
    link = PtyLink()
    _attach(link)
    try:
        _stuck(link)  # nobody has the port open: the writer waits, the queue fills
        while len(link._out) + BLOCK <= MAX_LINK_BACKLOG:
            link.send(_payload(0))
        before = link.backlog()
        link.send(_payload(1))
        assert link.bytes_dropped == BLOCK and link.backlog() == before
    finally:
        link.close()


def test_tcp_reconnection_and_close_while_the_writer_waits_for_a_host_that_does_not_read() -> None:
    link = TcpLink()
    connected = _attach(link)
    host, port = link.url.removeprefix("socket://").rsplit(":", 1)
    silent, reader = socket.socket(), None
    silent.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    silent.connect((host, int(port)))
    try:
        assert connected.wait(30.0)
        wait_until(lambda: link.connected, "the link to take the host", 30.0)
        _stuck(link)
        connected.clear()
        reader = socket.socket()  # a new host replaces the silent one
        reader.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        reader.connect((host, int(port)))
        assert connected.wait(30.0)
        wait_until(lambda: link.backlog() == 0, "the old host's bytes to be dropped", 30.0)
        link.send(b"hello")
        reader.settimeout(30.0)
        got = b""
        while len(got) < 5:
            got += reader.recv(5)
        assert got == b"hello"  # only what was sent to the new host reaches it
        _stuck(link)  # the new host does not read any more either: a close must still return
    finally:
        link.close()
        silent.close()
        if reader is not None:
            reader.close()
    assert not [t for t in threading.enumerate() if t.name.startswith(f"eyehil-{link.name}")]


def test_take_hands_over_the_front_of_a_buffer_and_keeps_the_rest() -> None:
    buffer = bytearray(b"abcdef")
    assert take(buffer, 2) == b"ab" and buffer == bytearray(b"cdef")
    assert take(buffer, 0) == b"" and buffer == bytearray(b"cdef")
    assert take(buffer, 100) == b"cdef" and buffer == bytearray()
    buffer += b"xyz"
    whole = take(buffer)
    assert whole == b"xyz" and isinstance(whole, bytes) and buffer == bytearray()
