"""``socket://host:port``: a TCP connection with pyserial's read/write/timeout interface.

pyserial's own socket:// handler works too (pass it to `eyehil.drivers.client.Tracker` directly), but it
sleeps 0.3 s in `close` and its `reset_input_buffer` reads for as long as data keeps arriving (forever,
from a device that streams). This one closes at once and discards only what is already buffered.
"""

from __future__ import annotations

import select
import socket
import time
from urllib.parse import urlsplit

CONNECT_TIMEOUT_S = 5.0
WRITE_TIMEOUT_S = 5.0  # a peer that does not read for this long: write raises TimeoutError
MAX_DISCARD_READS = 64


class TcpPort:
    """A connected TCP socket as a SerialLike (see `eyehil.drivers.links`)."""

    def __init__(self, host: str, port: int, timeout: float | None = 0.0,
                 write_timeout: float = WRITE_TIMEOUT_S) -> None:
        """Connect to `host`:`port`; raise OSError if nobody listens. `write` gives up after `write_timeout` s."""
        self._sock = socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock.setblocking(False)
        self.timeout = timeout
        self.write_timeout = write_timeout
        self.port = f"socket://{host}:{port}"

    def fileno(self) -> int:
        return self._sock.fileno()

    @property
    def in_waiting(self) -> int:
        """1 if bytes are waiting (a socket cannot tell how many), else 0."""
        return len(select.select([self._sock], [], [], 0)[0])

    def read(self, size: int = 1) -> bytes:
        """Up to `size` bytes: returns when `size` arrived or the timeout expired (pyserial semantics);
        OSError if the peer closed."""
        out = bytearray()
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        while len(out) < size:
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            if not select.select([self._sock], [], [], wait)[0]:
                break
            chunk = self._sock.recv(size - len(out))
            if not chunk:
                raise ConnectionResetError("the device closed the connection")
            out += chunk
        return bytes(out)

    def read_now(self, size: int) -> bytes:
        """Up to `size` bytes already received, without waiting (b"" if none); OSError if the peer closed."""
        try:
            chunk = self._sock.recv(size)
        except BlockingIOError:
            return b""
        if not chunk:
            raise ConnectionResetError("the device closed the connection")
        return chunk

    def write(self, data: bytes) -> int:
        """Send everything; raise `TimeoutError` (an OSError) if the peer takes nothing for `write_timeout` s."""
        view = memoryview(bytes(data))
        deadline = time.monotonic() + self.write_timeout
        while view:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"{self.port}: the peer took no data for {self.write_timeout} s")
            if not select.select([], [self._sock], [], remaining)[1]:
                continue
            try:
                sent = self._sock.send(view)
            except BlockingIOError:
                continue
            view = view[sent:]
            deadline = time.monotonic() + self.write_timeout  # progress: the peer reads
        return len(data)

    def reset_input_buffer(self) -> None:
        """Discard the bytes received so far (a bounded amount: a streaming device never pauses)."""
        for _ in range(MAX_DISCARD_READS):
            if not select.select([self._sock], [], [], 0)[0] or not self._sock.recv(65536):
                return

    def flush(self) -> None:
        """Writes are sent immediately."""

    def close(self) -> None:
        """Close the connection; idempotent."""
        self._sock.close()


def open_socket(url: str, timeout: float | None = 0.0) -> TcpPort:
    """Open ``socket://host:port``."""
    parts = urlsplit(url)
    if parts.scheme != "socket" or not parts.hostname or not parts.port:
        raise ValueError(f"expected socket://host:port, got {url!r}")
    return TcpPort(parts.hostname, parts.port, timeout)
