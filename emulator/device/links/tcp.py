"""Device side of a TCP link: a server a host opens as pyserial ``socket://host:port``.

Bound to 127.0.0.1 by default (pass host="0.0.0.0" to serve other machines, knowingly: the protocol
has no authentication). One host at a time: a new connection replaces the current one (a host that
crashed and reconnects is not locked out by its own half-open socket). A new connection is a new byte
stream, so the device forgets any partial frame and the host's sequence baseline (`reset`). While no
host is connected, output is discarded, as a UART transmits into the void; the device keeps its state.
"""

from __future__ import annotations

import contextlib
import socket

from eyehil.emulator.device.links.fdlink import CHUNK, FdLink
from eyehil.emulator.device.links.listen import create_server


class TcpLink(FdLink):
    """A TCP server for one host at a time; `url` = socket://host:port."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        """Listen on `host`:`port` (0 = any free port)."""
        self._server = create_server("tcp", host, port)
        self._server.setblocking(False)
        self._client: socket.socket | None = None
        bound_host, bound_port = self._server.getsockname()[:2]
        self.url = f"socket://{bound_host}:{bound_port}"
        self.name = f"tcp {bound_host}:{bound_port}"
        super().__init__()

    def _read_fds(self) -> list[int]:
        return [self._server.fileno()] + ([self._client.fileno()] if self._client else [])

    def _write_fd(self) -> int | None:
        client = self._client
        return None if client is None or self._closing else client.fileno()

    def _readable(self, fd: int) -> None:
        if fd == self._server.fileno():
            self._accept()
            return
        try:
            data = self._client.recv(CHUNK) if self._client else b""
        except OSError:
            data = b""
        if data:
            self._receive(data)
        else:
            self._disconnect()

    def _accept(self) -> None:
        try:
            client, _ = self._server.accept()
        except BlockingIOError:
            return
        client.setblocking(True)  # the reader receives only when select says so; the writer's sendall blocks
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._disconnect()
        with self._lock:
            self._client = client
        self._reset()

    def _transmit(self, data: bytes) -> None:
        client = self._client
        if client is None:
            return
        client.sendall(data)

    def _send_now(self, data: bytes) -> int:
        try:
            return self._client.send(data, socket.MSG_DONTWAIT)
        except BlockingIOError:
            return 0
        except OSError:  # the host went away: these bytes are lost
            return len(data)

    def _unblock(self) -> None:
        client = self._client
        if client is not None:
            with contextlib.suppress(OSError):
                client.shutdown(socket.SHUT_RDWR)

    def _disconnect(self) -> None:
        """Forget the current host, if any (a `sendall` to it in progress fails and its bytes are lost)."""
        with self._lock:
            client, self._client = self._client, None
            self._out.clear()
        if client is not None:
            with contextlib.suppress(OSError):
                client.shutdown(socket.SHUT_RDWR)
            client.close()

    def _release(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        self._server.close()
