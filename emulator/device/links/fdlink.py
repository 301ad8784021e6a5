"""Shared machinery of the file-descriptor links (pseudo-terminal, TCP): one I/O thread per link.

The thread selects on the link's readable descriptors and a wake-up pipe, hands received bytes to the
runner, and writes queued output when the descriptor becomes writable. `send` writes directly when
nothing is queued (the common case: one system call on the runner's thread, no thread hop) and queues
the rest. Subclasses fill four hooks: `_read_fds`, `_write_fd`, `_readable(fd)` and `_release`.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
from collections.abc import Callable

from eyehil.emulator.device.links.base import register_open, unregister

CHUNK = 65536


class FdLink:
    """Base of descriptor links; see the module docstring. Implements `DeviceLink` except `url`."""

    name = "fd link"
    url = ""

    def __init__(self) -> None:
        """Create the wake-up pipe and register the link as open."""
        self._out = bytearray()
        self._lock = threading.Lock()
        self._wake_r, self._wake_w = os.pipe()
        for fd in (self._wake_r, self._wake_w):
            os.set_blocking(fd, False)
        self._receive: Callable[[bytes], None] = lambda data: None
        self._reset: Callable[[], None] = lambda: None
        self._thread: threading.Thread | None = None
        self._closing = False
        register_open(self, self.name)

    # --- hooks -------------------------------------------------------------------------------
    def _read_fds(self) -> list[int]:
        """Descriptors to watch for input."""
        raise NotImplementedError

    def _write_fd(self) -> int | None:
        """Descriptor output goes to, or None when no host is attached (output is discarded)."""
        raise NotImplementedError

    def _readable(self, fd: int) -> None:
        """`fd` is readable: read it and call `self._receive` (or accept a connection ...)."""
        raise NotImplementedError

    def _release(self) -> None:
        """Close the subclass's descriptors."""
        raise NotImplementedError

    # --- DeviceLink ----------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._write_fd() is not None

    def attach(self, receive: Callable[[bytes], None], reset: Callable[[], None]) -> None:
        """Start the I/O thread."""
        self._receive, self._reset = receive, reset
        self._thread = threading.Thread(target=self._loop, name=f"eyehil-{self.name}", daemon=True)
        self._thread.start()

    def send(self, data: bytes) -> None:
        """Write now if possible, queue the rest; discard if no host is attached."""
        with self._lock:
            fd = self._write_fd()
            if fd is None:
                return
            if not self._out:
                data = data[self._write(fd, data):]
            if data:
                self._out += data
                self._poke()

    def backlog(self) -> int:
        return len(self._out)

    def close(self) -> None:
        """Stop the thread and close every descriptor; idempotent."""
        if self._closing:
            return
        self._closing = True
        self._poke()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()
        with self._lock:
            self._release()
            self._out.clear()
        for fd in (self._wake_r, self._wake_w):
            os.close(fd)
        unregister(self)

    # --- internals -----------------------------------------------------------------------------
    def _poke(self) -> None:
        """Wake the I/O thread."""
        with contextlib.suppress(OSError):  # the pipe is full: the thread is awake anyway
            os.write(self._wake_w, b"x")

    def _write(self, fd: int, data: bytes | bytearray) -> int:
        """Non-blocking write; returns bytes taken (all of them if the descriptor failed: they are lost)."""
        try:
            return os.write(fd, data)
        except BlockingIOError:
            return 0
        except OSError:
            return len(data)

    def _drop_output(self) -> None:
        """Forget queued output (the host went away)."""
        with self._lock:
            self._out.clear()

    def _loop(self) -> None:
        while not self._closing:
            fd_out = self._write_fd()
            writing = [fd_out] if fd_out is not None and self._out else []
            readable, writable, _ = select.select([self._wake_r, *self._read_fds()], writing, [], 1.0)
            if self._wake_r in readable:
                os.read(self._wake_r, CHUNK)
            for fd in readable:
                if fd != self._wake_r and not self._closing:
                    self._readable(fd)
            if writable:
                with self._lock:
                    if self._out and self._write_fd() == writable[0]:
                        del self._out[: self._write(writable[0], self._out)]
