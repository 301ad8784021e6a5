"""Helpers of the USB/IP tests: a byte collector for `on_data` and a bare USB/IP host for byte-exact tests."""

from __future__ import annotations

import socket
import threading
import time

from eyehil.protocols.usbip.messages import OP_HEADER, USB_DEVICE, OpHeader, encode_import_request
from eyehil.protocols.usbip.urb import URB_HEADER_SIZE, RetSubmit, UrbMessage, decode_urb_header


class Collector:
    """An `on_data` callback that keeps every byte and lets a test wait for a count."""

    def __init__(self) -> None:
        self.data = bytearray()
        self._cond = threading.Condition()

    def __call__(self, chunk: bytes) -> None:
        with self._cond:
            self.data += chunk
            self._cond.notify_all()

    def wait_for(self, n: int, timeout: float = 10.0) -> bytes:
        with self._cond:
            self._cond.wait_for(lambda: len(self.data) >= n, timeout)
            return bytes(self.data)


def recv_all(sock: socket.socket, size: int, timeout: float = 5.0) -> bytes:
    """`size` bytes, or fewer if the peer closes first (then the result is short)."""
    sock.settimeout(timeout)
    out = bytearray()
    while len(out) < size and (chunk := sock.recv(size - len(out))):
        out += chunk
    return bytes(out)


def wait_closed(sock: socket.socket, timeout: float = 5.0) -> bool:
    """True if the peer closes the connection within `timeout` (anything it sends first is discarded)."""
    deadline = time.monotonic() + timeout
    while (remaining := deadline - time.monotonic()) > 0:
        sock.settimeout(remaining)
        try:
            if not sock.recv(65536):
                return True
        except ConnectionResetError:
            return True
        except TimeoutError:
            return False
    return False


class RawHost:
    """A bare USB/IP host over one TCP connection, for byte-exact and malformed-input tests."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)

    def close(self) -> None:
        self.sock.close()

    def import_device(self, busid: str = "1-1") -> OpHeader:
        self.sock.sendall(encode_import_request(busid))
        header = OpHeader.decode(recv_all(self.sock, OP_HEADER.size))
        if header.status == 0:
            recv_all(self.sock, USB_DEVICE.size)
        return header

    def reply(self, in_direction: bool = False) -> UrbMessage:
        """The next URB reply; with `in_direction`, its data too."""
        message = decode_urb_header(recv_all(self.sock, URB_HEADER_SIZE))
        if in_direction and isinstance(message, RetSubmit) and message.actual_length:
            return RetSubmit(message.seqnum, message.status, message.actual_length,
                             recv_all(self.sock, message.actual_length))
        return message
